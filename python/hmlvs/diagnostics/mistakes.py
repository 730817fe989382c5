"""The likely mistake behind a calibration that fails its checks (issue 38).

:func:`find_mistake` tries the usual culprits on the observations (the board square, the
robot positions' unit, inverted poses, the quaternion order, views whose board pose
disagrees with the rest) by re-running a cheap chain fit under each hypothesis (the
free-pose board estimates of Zhang's calibration, the closed-form hand-eye transform and
the board's mean pose in the base) and says which one explains the data, with the next
action. It needs the views' corners and robot poses, whatever the sensor model.
"""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass, field
import math
from typing import Any, Callable, Iterator, Sequence

import numpy as np

from .. import _core
from ..calibration.joint import consistent_numbering, initial_intrinsics
from ..geometry.board import BoardSpec
from ..geometry.transforms import invert_transform, rotation_to_quaternion
from ..models.opencv import CLASSIC_DISTORTION
from .checks import CORNER_RMS_LIMIT_PX, POSE_DISAGREEMENT, lens_terms_check


def _quat_xyzw(r: np.ndarray) -> np.ndarray:
    return rotation_to_quaternion(r, "xyzw")


def _rot_xyzw(q: np.ndarray) -> np.ndarray:
    from ..data.poses import rotation_from_quaternion

    return rotation_from_quaternion(q / np.linalg.norm(q), "xyzw")


def reorder_quaternions(m: np.ndarray, order: tuple[int, int, int, int]) -> np.ndarray:
    q = _quat_xyzw(m[:3, :3])
    out = m.copy()
    out[:3, :3] = _rot_xyzw(q[list(order)])
    return out


#: the pose hypotheses: name -> the base_from_hand the given pose would be under it
_POSE_HYPOTHESES: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "as given": lambda m: m,
    "inverted": invert_transform,
    # written x y z w but read as w x y z: the read (x', y', z', w') = (y, z, w, x)
    "xyzw read as wxyz": lambda m: reorder_quaternions(m, (3, 0, 1, 2)),
    # written w x y z but read as x y z w: the read (x', y', z', w') = (w, x, y, z)
    "wxyz read as xyzw": lambda m: reorder_quaternions(m, (1, 2, 3, 0)),
}


@dataclass
class ChainFit:
    """A cheap chain fit: corner RMS (px) through the robot chain and per view."""

    rms: float
    per_view: dict[str, float] = field(default_factory=dict)
    scale: float = 1.0


@dataclass
class Mistake:
    """What :func:`find_mistake` found: ``sentence`` (None when no usual mistake explains
    the data), the fits it compared (hypothesis -> corner RMS px) and its best guess."""

    sentence: str | None
    fits: dict[str, float]
    hypothesis: str
    scale: float
    free_rms_px: float
    views: list[str] = field(default_factory=list)


class _Obs:
    """The observations the hypotheses are tried on: Zhang's intrinsics and free board
    poses, the corners and the robot poses of the views with corners and poses."""

    def __init__(self, views: Sequence[Any], board: BoardSpec, image_size: tuple[int, int],
                 distortion: Sequence[str]):
        self.views = [v for v in views if len(v.corner_index) >= 6
                      and v.base_from_hand is not None]
        self.board = board
        intr, poses, rms = initial_intrinsics(self.views, board, image_size, distortion)
        self.k = np.array([[intr[0], 0, intr[2]], [0, intr[1], intr[3]], [0, 0, 1.0]])
        self.dist = intr[4:]
        self.cams = poses
        self.free_rms = rms
        self.bfh = [np.asarray(v.base_from_hand, float) for v in self.views]


def _chain_rms(obs: _Obs, bfh: list[np.ndarray], flips: list[bool | None], scale: float,
               fit_on: list[int], evaluate: list[int]) -> ChainFit:
    """Hand-eye (Park and Martin) and the mean board pose from the views ``fit_on`` with the
    board scaled by ``scale``; the corners' RMS (px) through the chain over ``evaluate``
    (views of undecided numbering take the better of the two)."""
    import cv2

    b = obs.board
    f = b.flip()
    cams = []
    for i, c in enumerate(obs.cams):
        c = c @ f if flips[i] else c.copy()
        c[:3, 3] *= scale
        cams.append(c)
    try:
        x = _core._hand_eye_park_martin([bfh[i] for i in fit_on], [cams[i] for i in fit_on])
        bfb = _core._mean_transform([bfh[i] @ x @ cams[i] for i in fit_on])
    except ValueError:
        return ChainFit(float("inf"), scale=scale)
    x_inv = invert_transform(x)
    per_view, sq = {}, []
    n = b.rows * b.cols
    for i in evaluate:
        v = obs.views[i]
        cb = x_inv @ invert_transform(bfh[i]) @ bfb
        idx0 = np.asarray(v.corner_index, int)
        best = None
        options = [flips[i]] if flips[i] is not None else [False, True]
        for fl in options:
            idx = n - 1 - idx0 if fl else idx0
            pts = b.points(idx) * scale
            cam = pts @ cb[:3, :3].T + cb[:3, 3]
            if not (cam[:, 2] > 0).all():
                e = np.full(len(pts), 1e6)
            else:
                proj, _ = cv2.projectPoints(cam, np.zeros(3), np.zeros(3), obs.k, obs.dist)
                e = np.sum((proj.reshape(-1, 2) - np.asarray(v.corner_pixels, float)) ** 2,
                           axis=1)
            if best is None or e.mean() < best.mean():
                best = e
        assert best is not None
        per_view[v.id] = float(np.sqrt(best.mean()))
        sq.append(best)
    e = np.concatenate(sq) if sq else np.empty(0)
    return ChainFit(float(np.sqrt(e.mean())) if e.size else float("inf"), per_view, scale)


def _best_scale(obs: _Obs, bfh: list[np.ndarray], flips: list[bool | None],
                fit_on: list[int]) -> ChainFit:
    """The board scale that fits the chain best: a log grid from 1e-4 to 1e4 (33 points, a
    factor 1.78 apart: the chain's RMS changes smoothly with the scale, so the best grid
    point brackets the best scale), then golden section between its neighbours to 1e-4 of
    a decade."""
    grid = 10.0 ** np.linspace(-4, 4, 33)
    fits = [_chain_rms(obs, bfh, flips, s, fit_on, fit_on) for s in grid]
    k = int(np.argmin([f.rms for f in fits]))
    lo = math.log10(grid[max(k - 1, 0)])
    hi = math.log10(grid[min(k + 1, len(grid) - 1)])
    g = (math.sqrt(5) - 1) / 2
    a, b = hi - g * (hi - lo), lo + g * (hi - lo)

    def rms(x: float) -> float:
        return _chain_rms(obs, bfh, flips, 10.0 ** x, fit_on, fit_on).rms

    fa, fb = rms(a), rms(b)
    for _ in range(20):
        if fa < fb:
            hi, b, fb = b, a, fa
            a = hi - g * (hi - lo)
            fa = rms(a)
        else:
            lo, a, fa = a, b, fb
            b = lo + g * (hi - lo)
            fb = rms(b)
    best = _chain_rms(obs, bfh, flips, 10.0 ** ((lo + hi) / 2), fit_on, fit_on)
    return best if best.rms <= fits[k].rms else fits[k]


def _good(rms: float, free: float) -> bool:
    """A chain fit as good as a correct one: within the corner limit and twice the free
    poses' RMS."""
    return rms <= max(CORNER_RMS_LIMIT_PX, POSE_DISAGREEMENT * max(free, 0.05))


def _split_views(obs: _Obs, bfh: list[np.ndarray], flips: list[bool | None], scale: float
                 ) -> tuple[list[int], ChainFit]:
    """Views whose board pose disagrees with the rest, by consensus: the chain is fitted to
    every triple of views of decided numbering (at most 300 triples drawn), each view is
    judged by its corner RMS through that chain (either numbering), and the largest set
    within the corner limit (and twice the free poses' RMS) wins; the chain is fitted again
    on it. Returns the other views and the final fit (over all views)."""
    all_i = list(range(len(obs.views)))
    decided = [i for i in all_i if flips[i] is not None]
    limit = max(CORNER_RMS_LIMIT_PX, POSE_DISAGREEMENT * max(obs.free_rms, 0.05))
    triples = [(a, b, c) for ai, a in enumerate(decided) for bi, b in enumerate(decided[ai + 1:])
               for c in decided[ai + bi + 2:]]
    if len(triples) > 300:
        pick = np.random.default_rng(0).choice(len(triples), 300, replace=False)
        triples = [triples[k] for k in sorted(pick)]
    best: list[int] = []
    for t in triples:
        fit = _chain_rms(obs, bfh, [flips[i] if i in t else None for i in all_i], scale,
                         list(t), all_i)
        ins = [i for i in all_i if fit.per_view.get(obs.views[i].id, np.inf) <= limit]
        if len(ins) > len(best):
            best = ins
    fit_on = [i for i in best if flips[i] is not None]
    if len(fit_on) < 3:
        return [], _chain_rms(obs, bfh, flips, scale, decided, all_i)
    fit = _chain_rms(obs, bfh, [flips[i] if i in fit_on else None for i in all_i], scale,
                     fit_on, all_i)
    if not fit.per_view:  # the chain cannot be fitted on the consensus (e.g. too little turn)
        return [], fit
    bad = [i for i in all_i if fit.per_view.get(obs.views[i].id, np.inf) > limit]
    return bad, fit


def find_mistake(views: Sequence[Any], board: Any, image_size: tuple[int, int],
                 distortion: Sequence[str] = CLASSIC_DISTORTION) -> Mistake:
    """Try the usual mistakes on the observations and name the one that explains them, with
    the lens of the ``distortion`` terms.

    Each hypothesis on the robot poses (as given, inverted, either quaternion order read as
    the other) is fitted with the board's scale free (a one-dimensional search: a wrong
    square and positions in metres read as millimetres both scale the board against the
    robot's translations), by the cheap chain fit of :func:`_chain_rms`. The best fit names
    the mistake when it is as good as a correct calibration's and the poses as given are
    not; else views whose board pose disagrees with the rest are looked for."""
    board = BoardSpec.of(board)
    obs = _Obs(views, board, image_size, tuple(distortion))
    free = obs.free_rms
    n = len(obs.views)
    if n < 3:
        return Mistake(None, {}, "as given", 1.0, free)
    fits, given_flips = _hypothesis_fits(obs)
    decided = [i for i in range(n) if given_flips[i] is not None]
    as_given = (_chain_rms(obs, obs.bfh, given_flips, 1.0, decided, decided).rms
                if len(decided) >= 3 else float("inf"))
    table = {"as given": as_given, **{f"{k} (scale {f.scale:.4g})": f.rms
                                      for k, f in fits.items()}}
    best = min(fits, key=lambda k: fits[k].rms)
    bf = fits[best]
    if _good(bf.rms, free) and not _good(as_given, free):
        parts = _pose_and_scale_parts(best, bf.scale, board.square)
        if parts:
            sentence = (f"likely mistake: {'; '.join(parts)} (the corners then fit the "
                        f"robot chain to {bf.rms:.2f} px RMS, against {as_given:.2f} px as "
                        "given)")
            return Mistake(sentence, table, best, bf.scale, free)
    moved = _moved_views(obs, given_flips, table)
    if moved is not None:
        return moved
    if not _good(as_given, free):
        fits_txt = (f": best {bf.rms:.2f} px RMS against {as_given:.2f} px as given"
                    if math.isfinite(bf.rms) and math.isfinite(as_given) else "")
        sentence = (f"no usual mistake explains the data (square size, metres or "
                    f"millimetres, inverted poses, quaternion order, a few moved views"
                    f"{fits_txt}): check the robot poses' accuracy and timing (taken when the "
                    "robot stood still?), that the images belong to these poses and that the "
                    "board stayed put")
        return Mistake(sentence, table, best, bf.scale, free)
    return Mistake(None, table, "as given", 1.0, free)


def _hypothesis_fits(obs: _Obs) -> tuple[dict[str, ChainFit], list[bool | None]]:
    """Each pose hypothesis' best chain fit (board scale free), and the corner numbering
    of the poses as given."""
    n = len(obs.views)
    fits: dict[str, ChainFit] = {}
    given: list[bool | None] = []
    for name, fn in _POSE_HYPOTHESES.items():
        bfh = [fn(m) for m in obs.bfh]
        flips = consistent_numbering(bfh, obs.cams, obs.board)
        if name == "as given":
            given = flips
        decided = [i for i in range(n) if flips[i] is not None]
        fits[name] = (_best_scale(obs, bfh, flips, decided) if len(decided) >= 3
                      else ChainFit(float("inf")))
    return fits, given


def _pose_and_scale_parts(best: str, scale: float, square: float) -> list[str]:
    """The sentences naming the pose hypothesis ``best`` and the board ``scale`` that fit
    (a unit read wrongly, else a wrong square)."""
    parts = []
    if best == "inverted":
        parts.append("the robot poses fit the images only when inverted: they are "
                     "hand_from_base, not base_from_hand; invert them")
    elif best != "as given":
        written, read = best.split(" read as ")
        parts.append(f"the robot poses fit the images only with the other quaternion "
                     f"order: their quaternions are written {written}, not {read}; set "
                     f"the poses' quaternion_order to {written}")
    # positions in metres read as millimetres are 1000 times too small against the board:
    # the board must shrink by 1000 to fit them
    s = scale
    for factor, unit_said, unit in ((0.001, "metres read as millimetres", "m"),
                                    (1000.0, "millimetres read as metres", "mm")):
        if abs(math.log(s / factor)) < math.log(1.15):
            parts.append(f"the robot positions are {unit_said}: set the poses' unit to {unit}")
            s = s / factor
            break
    if abs(math.log(s)) > math.log(1.02):
        parts.append(f"the robot motion implies squares of {s * square:.1f} mm, not "
                     f"{square:g}: check `board.square`")
    return parts


def _moved_views(obs: _Obs, flips: list[bool | None], table: dict[str, float]
                 ) -> Mistake | None:
    """The mistake "a minority of the views put the board elsewhere" when it explains the
    data (when most views disagree with the rest, it is the poses or the chain that are
    wrong, not a few views), else None."""
    n = len(obs.views)
    bad, fit = _split_views(obs, obs.bfh, flips, 1.0)
    if not bad or len(bad) >= n / 2:
        return None
    names = [obs.views[i].id for i in bad]
    rest = _rms_over(fit, [v.id for v in obs.views if v.id not in names])
    if not _good(rest, obs.free_rms):
        return None
    sentence = (f"likely mistake: view(s) {', '.join(names)} put the board elsewhere than the "
                "others do: the board moved, or their images do not belong to their robot "
                "poses; leave them out or capture them again (the other views fit the robot "
                f"chain to {rest:.2f} px RMS)")
    return Mistake(sentence, table, "views", 1.0, obs.free_rms, names)


def _rms_over(fit: ChainFit, ids: list[str]) -> float:
    e = [fit.per_view[i] for i in ids if i in fit.per_view]
    return float(np.sqrt(np.mean(np.square(e)))) if e else float("inf")




def explain_failure(error: str, views: Sequence[Any], board: Any,
                    image_size: tuple[int, int],
                    distortion: Sequence[str] = CLASSIC_DISTORTION) -> str:
    """The likely cause when one explains the views, with ``error`` (why a calibration could
    not be made, e.g. a solve run off to a negative focal length under wrong poses) after
    it: a lens the ``distortion`` terms cannot follow (:func:`lens_terms_check`), else the
    likely mistake (:func:`find_mistake`); else ``error`` as it is."""
    try:
        lens = lens_terms_check(views, BoardSpec.of(board), image_size, distortion)
    except ValueError:
        lens = []
    if lens and not lens[0].ok:  # a lens the terms cannot follow spoils every fit after it
        return f"likely cause: {lens[0].problem}\n(the calibration failed: {error})"
    if not any(v.base_from_hand is not None for v in views):
        return error
    try:
        sentence = find_mistake(views, board, image_size, distortion).sentence
    except ValueError:
        return error
    if sentence is None or not sentence.startswith("likely mistake"):
        return error  # "no usual mistake" adds nothing to the error's own account
    return f"{sentence}\n(the calibration failed: {error})"


@contextmanager
def explaining(views: Sequence[Any], board: Any, image_size: tuple[int, int],
               distortion: Sequence[str] = CLASSIC_DISTORTION) -> Iterator[None]:
    """A calibration from ``views`` with the lens of the ``distortion`` terms inside: a
    ``ValueError`` it raises comes out led by the likely cause when one explains the views
    (:func:`explain_failure`)."""
    try:
        yield
    except ValueError as e:
        raise ValueError(explain_failure(str(e), views, board, image_size,
                                         distortion)) from None
