"""What the image pipeline saw in each view of a session, drawn on the image (``hmlvs inspect``).

Per view one PNG: the laser-on frame (gray) with the numbered board corners, the stripe
centres and the scan lines whose stripe was rejected, coloured by
:class:`~hmlvs.image.stripe.StripeStatus`; and one line of text: used or rejected (and why),
corners found, scan lines per stripe status. Used / rejected and the reason are those of the
general model's pipeline (:func:`hmlvs.image.views.views_from_images`), and so are the corners
and the stripe drawn on a used view (a partly visible board's corners numbered from its
robot pose; the centres off the stripe's line marked OFF_LINE); the drawing repeats the
stripe extraction and the corner detection only on the pairs the pipeline rejected, so a
view without a board still shows its stripe and a view without a stripe its corners.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..image.stripe import StripeResult, StripeStatus, as_gray

#: BGR colour of each stripe status (NONE is not drawn: most scan lines miss the stripe)
STATUS_COLOURS: dict[StripeStatus, tuple[int, int, int]] = {
    StripeStatus.FOUND: (0, 200, 0),         # green: a centre
    StripeStatus.MULTIPLE: (0, 0, 255),      # red: two or more peaks (reflections)
    StripeStatus.TOO_NARROW: (255, 160, 0),  # blue: noise, hot pixels
    StripeStatus.TOO_WIDE: (0, 165, 255),    # orange: glare
    StripeStatus.FIT_FAILED: (255, 0, 255),  # magenta: e.g. a saturated flat top
    StripeStatus.SATURATED: (128, 0, 255),   # pink: the laser-on image saturated under the peak
    StripeStatus.CLIPPED: (0, 100, 180),     # brown: the profile runs off the image
    StripeStatus.DOUBLE_PEAK: (180, 80, 255),  # violet-pink: a reflection beside the peak
    StripeStatus.ALBEDO_EDGE: (255, 80, 80),   # light blue: the albedo steps under the profile
    StripeStatus.OFF_LINE: (255, 255, 0),      # cyan: a centre off the view's stripe line
}
CORNER_COLOUR = (0, 255, 255)  # yellow
FIRST_CORNER_COLOUR = (255, 0, 255)  # magenta: corner 0, so the numbering's origin shows
TICK = 10  # px: length of a rejected scan line's mark at the image border


@dataclass
class ViewInspection:
    """One view of :func:`inspect_session`.

    id : the pose id; used : whether the view enters the calibration; reason : why not ("")
    corners : corners found and numbered (also for a rejected view, when its image was read)
    stripe : scan lines per stripe status name (empty when the stripe could not be extracted)
    image : the PNG written, or None (the images could not be read)
    note : what the pipeline corrected in a view it used (its board numbered again from the
        robot chain); "" otherwise
    """

    id: str
    used: bool
    reason: str = ""
    corners: int = 0
    stripe: dict[str, int] = field(default_factory=dict)
    image: Path | None = None
    note: str = ""

    def to_dict(self) -> dict[str, Any]:
        """The view's inspection as plain JSON-ready values."""
        return {"id": self.id, "used": self.used, "reason": self.reason,
                "corners": self.corners, "stripe": dict(self.stripe),
                "image": None if self.image is None else str(self.image),
                **({"note": self.note} if self.note else {})}

    def line(self) -> str:
        """The terminal line: ``v001: used, 63 corners, stripe FOUND 812, MULTIPLE 2``."""
        state = ("used" if self.corners else "used (laser only, no board seen)") if self.used \
            else f"rejected ({self.reason})"
        stripe = ", ".join(f"{k} {v}" for k, v in self.stripe.items() if v) or "none"
        png = f" -> {self.image.name}" if self.image is not None else ""
        note = f" ({self.note})" if self.note else ""
        return f"{self.id}: {state}, {self.corners} corners{note}, stripe {stripe}{png}"


def draw_view(image: np.ndarray, corners: Any = None, stripe: StripeResult | None = None,
              title: str = "") -> np.ndarray:
    """A BGR picture of one view: ``image`` (gray or colour, 8 or 16 bit) with ``corners``
    (a :class:`~hmlvs.image.corners.Corners`: a circle and the board index at each, corner
    0 in magenta), the stripe's found centres (green dots) and its rejected scan lines (a
    mark of the status colour at the image border: the bottom for columns, the right side
    for rows; an OFF_LINE centre also as a dot of its colour), and ``title`` at the top left
    followed by the names of the marks drawn."""
    import cv2

    gray = as_gray(image, "the image", None)
    if gray.dtype == np.uint16:
        gray = (gray >> 8).astype(np.uint8)
    out = cv2.cvtColor(np.ascontiguousarray(gray), cv2.COLOR_GRAY2BGR)
    h, w = gray.shape
    legend: list[tuple[str, tuple[int, int, int]]] = []
    if stripe is not None:
        columns = stripe.direction == "columns"

        def mark(lines: np.ndarray, colour: tuple[int, int, int]) -> None:
            for p in lines.astype(int):
                a, b = ((p, h - TICK), (p, h - 1)) if columns else ((w - TICK, p), (w - 1, p))
                cv2.line(out, a, b, colour, 1)

        status = np.asarray(stripe.status)
        for s, colour in STATUS_COLOURS.items():
            if s in (StripeStatus.FOUND, StripeStatus.OFF_LINE):  # centres: dots
                for px in stripe.pixels_of(status == s):
                    cv2.circle(out, (int(round(px[0])), int(round(px[1]))), 1, colour, -1)
            if s != StripeStatus.FOUND and (status == s).any():
                mark(np.asarray(stripe.position)[status == s], colour)
                legend.append((s.name, colour))
    if corners is not None and len(corners):
        radius = 4 if len(corners) < 200 else 2
        for px, k in zip(np.asarray(corners.pixels), np.asarray(corners.index)):
            c = (int(round(px[0])), int(round(px[1])))
            colour = FIRST_CORNER_COLOUR if k == 0 else CORNER_COLOUR
            cv2.circle(out, c, radius, colour, 1)
            cv2.putText(out, str(int(k)), (c[0] + 4, c[1] - 4), cv2.FONT_HERSHEY_SIMPLEX,
                        0.35, colour, 1, cv2.LINE_AA)
    _draw_header(out, title, legend, "bottom" if stripe is None or
                 stripe.direction == "columns" else "right")
    return out


def _draw_header(out: np.ndarray, title: str, legend: list[tuple[str, tuple[int, int, int]]],
                 border: str) -> None:
    """``title`` in white, then the names of the border marks drawn, each in its colour, on
    black bands at the top left (a line wraps at the image's width)."""
    import cv2

    words = [(title + "   ", (255, 255, 255))] if title else []
    if legend:
        words += [(f"marks at the {border}: ", (255, 255, 255)),
                  *((name + " ", colour) for name, colour in legend)]
    font, scale = cv2.FONT_HERSHEY_SIMPLEX, 0.5
    th = cv2.getTextSize("Ag", font, scale, 1)[0][1]
    lines: list[list[tuple[str, tuple[int, int, int], int]]] = [[]]
    x = 8
    for word, colour in words:
        width = cv2.getTextSize(word, font, scale, 1)[0][0]
        if lines[-1] and x + width > out.shape[1] - 8:
            lines.append([])
            x = 8
        lines[-1].append((word, colour, width))
        x += width
    for k, line in enumerate(ln for ln in lines if ln):
        top, x = k * (th + 10), 8
        cv2.rectangle(out, (0, top), (sum(w for _, _, w in line) + 16, top + th + 12),
                      (0, 0, 0), -1)
        for word, colour, width in line:
            cv2.putText(out, word, (x, top + th + 6), font, scale, colour, 1, cv2.LINE_AA)
            x += width


def inspect_session(source: Any, out_dir: str | os.PathLike, *, robot: Any = None,
                    board: Any = None, channel: int | None = None, normalize: bool = True,
                    **stripe_options: Any) -> list[ViewInspection]:
    """Draw every view of an image session (a manifest, see docs/file-formats.md) into
    ``out_dir`` (``<id>.png``) and say per view whether the general model's pipeline uses it.

    Returns one :class:`ViewInspection` per manifest entry, in order. Raises ``ValueError``
    for a malformed manifest or one without a board (as :func:`views_from_images`).
    """

    from .._io import atomic_folder
    from ..data.manifest import load_manifest, read_manifest, write_png
    from ..image.views import views_from_images

    source = load_manifest(source)  # read once, for the views and the pictures
    used, spec, _, _, reports = views_from_images(source, robot=robot, board=board,
                                                  channel=channel, normalize=normalize,
                                                  **stripe_options)
    # the corners the pipeline numbered: a partly visible board's come from its robot pose
    # and a first calibration, which detecting this image alone cannot repeat
    numbered = {v.id: _Numbered(np.asarray(v.corner_pixels), np.asarray(v.corner_index),
                                v.stripe) for v in used}
    entries, doc, folder = read_manifest(source)
    from ..geometry.board import Checkerboard
    from ..image.session import manifest_direction

    stripe_options = manifest_direction(doc, stripe_options)  # for the views turned away

    detector_board = spec if spec.unambiguous else Checkerboard(rows=spec.rows, cols=spec.cols,
                                                                square=spec.square)
    out = Path(out_dir)
    result: list[ViewInspection] = []
    taken: set[str] = set()
    # all pictures or none (an interrupted or failed run leaves the folder as it was)
    with atomic_folder(out, last=()) as tmp:
        for entry, rep in zip(entries, reports):
            view = ViewInspection(rep.id, rep.ok, rep.reason, rep.corners, dict(rep.stripe),
                                  note=rep.note)
            result.append(view)
            picture = _picture(entry, rep, view, folder, numbered, detector_board, normalize,
                               channel, stripe_options)
            if picture is None:
                continue
            name = _unique(_safe(rep.id), taken)
            view.image = out / name
            write_png(tmp / name, picture)
    return result


def _picture(entry: dict, rep: Any, view: ViewInspection, folder: Path, numbered: dict,
             detector_board: Any, normalize: bool, channel: int | None,
             stripe_options: dict) -> np.ndarray | None:
    """One view's picture (None when its images cannot be read); fills in ``view`` the
    corners and stripe of a view the pipeline rejected."""
    from ..image.colour import board_gray
    from ..image.session import stripe_from_pair
    from ..image.views import detect_corners

    if "on" not in entry:
        return None
    on, off = (_read_image(entry.get(key), folder) for key in ("on", "off"))
    if on is None or ("off" in entry and off is None):
        return None
    corners = numbered.get(rep.id) if rep.ok else None
    stripe = None if corners is None else corners.stripe  # the pipeline's, as it kept it
    if stripe is None:
        try:
            stripe = stripe_from_pair(on, off, normalize=normalize, channel=channel,
                                      **stripe_options)
        except ValueError:
            stripe = None
    if corners is None and not (rep.ok and rep.corners == 0):
        try:
            corners = detect_corners(board_gray(on if off is None else off), detector_board)
        except ValueError:
            corners = None
    if not rep.ok:  # the pipeline stopped early: report what the images show
        view.corners = 0 if corners is None else len(corners)
        view.stripe = {} if stripe is None else stripe.counts()
    if not rep.ok:
        state = f"rejected, {view.corners} corners"
    else:
        state = f"used, {view.corners} corners" if view.corners else "used, laser only (no " \
            "board seen)"
    return draw_view(on, corners, stripe, f"{rep.id}: {state}")


def _unique(stem: str, taken: set[str]) -> str:
    """``<stem>.png``, or ``<stem>-2.png``, ``-3`` ... when another view's id gave that name
    already (ids ``a/b`` and ``a_b`` both make ``a_b``): one picture per view."""
    name, n = f"{stem}.png", 1
    while name.lower() in taken:
        n += 1
        name = f"{stem}-{n}.png"
    taken.add(name.lower())
    return name


def _read_image(name: Any, folder: Path) -> np.ndarray | None:
    """A manifest entry's image (None when not named or unreadable)."""
    from .._io import read_image

    if not isinstance(name, (str, os.PathLike)):
        return None
    path = Path(name)
    try:
        return read_image(path if path.is_absolute() else folder / path)
    except (OSError, ValueError):
        return None


@dataclass(frozen=True)
class _Numbered:
    """Corners as :func:`draw_view` draws them: pixels (k, 2) and board indices (k,); with
    the view's stripe as the pipeline kept it (its OFF_LINE centres marked)."""

    pixels: np.ndarray
    index: np.ndarray
    stripe: StripeResult | None = None

    def __len__(self) -> int:
        return len(self.index)


def _safe(name: str) -> str:
    """A file name for a pose id (path separators and the like replaced)."""
    return "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in name) or "view"

