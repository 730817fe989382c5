"""One pass over an image session's laser on/off pairs, shared by both sensor models.

Each pair is read once (:class:`PairReader`): its images, its stripe and its robot pose
(:func:`~hmlvs.image.session.read_pair`), then its board's corners found and numbered the
model's way (the general model's without any prior model, the paper model's from the corners
its approximate parameters predict), then how its stripe would move under the camera's blur
(:func:`~hmlvs.image.session.edge_shift`), and its images are let go. Then the session's
facts, one board print, one laser, one lens: the pairs' image size (:func:`same_size`), the
albedo offset of the stripes that could not fit their own (:func:`session_offset`) and the
camera's blur (:func:`session_blur`). The models' front ends turn the pairs read into views
(:class:`hmlvs.data.views.ViewData`): :func:`hmlvs.image.views.views_from_images` and
:func:`hmlvs.image.paper_session.paper_views`.

The two read a pair alike but for what each model needs. The paper model numbers a board
from the corners its approximate parameters predict at the pair's pose (the general model
without a model: a whole board, or a partly visible one from a first calibration on three
whole ones), smooths its stripes twice as much along the stripe on the board
(:data:`~hmlvs.image.session.BOARD_SMOOTH_ALONG`) and gives a stripe that cannot fit its
albedo offset the session's. Read the general model's way, the rendered paper-model
sessions of the tests would keep no numbered board (their boards are larger than the view),
and the paper's calibration points would move by up to 0.13 px (the smoothing) and 0.53 px
(a stripe along one level of the board, without the session's offset); the corners of a
whole board agree to 0.0005 px.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, Callable, Sequence

import numpy as np

from .corner_base import Corners
from .partial import corner_image
from .session import (
    Pair,
    PairRejected,
    check_stripe,
    edge_shift,
    read_pair,
    record_id,
    record_names,
    restripe,
    session_blur_var,
    stripe_pending,
    with_blur_var,
)


@dataclass(frozen=True)
class PairRead:
    """One pair as the session's pass read it.

    id, index : the pair's id and place in the session; names : its record's (on, off)
    pair : the pair read (its images let go once its stripe and corners are final); None
        when it could not be read
    found : what the model's numbering gave: the numbered :class:`Corners`, or what the
        model numbers later from the whole session (a partly visible board, a board to
        number by the views' agreement; the pair's images are kept for it); None when the
        pair was rejected before
    edge : per scan line, how far the stripe moves per px^2 of the camera's blur variance
        (:func:`~hmlvs.image.session.edge_shift`), for the session's blur fit; None when
        not measured (a given blur, or a stripe that waits for the session's albedo offset)
    image : the board's image, kept where the model asks for it
    why : why the pair was rejected ("" while it is kept)
    """

    id: str
    index: int
    names: tuple[str, str]
    pair: Pair | None = None
    found: Any = None
    edge: np.ndarray | None = None
    image: np.ndarray | None = None
    why: str = ""

    @property
    def kept(self) -> bool:
        """Whether the pair is still on its way to a view."""
        return not self.why and self.found is not None

    def rejected(self, why: str, loaded: bool = True) -> "PairRead":
        """The pair rejected for ``why``; without ``loaded``, as a pair never read (its
        account names the record's files and no stripe)."""
        pair = None if not loaded or self.pair is None else \
            replace(self.pair, on=None, off=None, board=None)
        return replace(self, pair=pair, found=None, edge=None, image=None, why=why)


@dataclass
class PairReader:
    """Reads one pair of a session (:meth:`read`), on any thread.

    ``number(pid, pair)`` is the model's numbering of the pair's board: numbered
    :class:`Corners`, or anything else the model finishes later from the whole session;
    it raises :class:`PairRejected` for a pair without a usable board. ``keep_board(found)``
    says whether the board's image is kept with numbered corners. With ``defer`` a stripe
    whose albedo offset could not be fitted waits for the session's (:func:`session_offset`);
    with ``fit_blur`` the edge shifts are measured for the session's blur fit."""

    folder: Any
    unit: str
    robot: Any
    size: tuple[int, int] | None  # the manifest's image size, if it gives one
    channel: int | None
    normalize: bool
    min_stripe: int
    stripe_options: dict[str, Any]
    fit_blur: bool
    number: Callable[[str, Pair], Any]
    defer: bool = False
    keep_board: Callable[[Any], bool] | None = None

    def read(self, item: tuple[int, Any]) -> PairRead:
        """The pair of record ``item`` = (index, record), read, numbered and measured."""
        index, rec = item
        read = PairRead(record_id(rec, index), index, record_names(rec))
        try:
            pair = read_pair(rec, index, self.folder, self.unit, self.robot, self.size,
                             self.channel, self.normalize, self.stripe_options,
                             self.min_stripe, defer=self.defer)
        except PairRejected as e:
            return read.rejected(str(e))
        read = replace(read, pair=pair)
        try:
            found = self.number(read.id, pair)
        except PairRejected as e:
            return read.rejected(str(e))
        image = corner_image(pair) if isinstance(found, Corners) and \
            self.keep_board is not None and self.keep_board(found) else None
        return self.measured(replace(read, found=found, image=image))

    def measured(self, read: PairRead, options: dict[str, Any] | None = None,
                 final: bool = False) -> PairRead:
        """A kept pair with its edge shifts (``options``: those its stripe was extracted
        with, by default the reader's) and, once numbered, without its images; unchanged
        while its stripe waits for the session's albedo offset (with ``defer``, unless
        ``final``: it has been given it)."""
        pair = read.pair
        if pair is None or (self.defer and stripe_pending(pair) and not final):
            return read
        edge = read.edge
        if self.fit_blur and edge is None:
            edge = edge_shift(pair, self.normalize,
                              self.stripe_options if options is None else options)
        if isinstance(read.found, Corners):
            pair = replace(pair, on=None, off=None, board=None)
        return replace(read, pair=pair, edge=edge)


def read_pairs(reader: PairReader, records: Sequence[Any], threads: int | None = None
               ) -> list[PairRead]:
    """Every record's pair read by ``reader``, in the session's order, on ``threads``
    threads (default: one per usable core; each pair's work depends on its own images
    alone, OpenCV's random samples included: the result does not depend on the number)."""
    threads = worker_threads(threads, len(records))
    if threads <= 1:
        return [reader.read(item) for item in enumerate(records)]
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(max_workers=threads) as pool:
        return list(pool.map(reader.read, enumerate(records)))


def worker_threads(threads: int | None, jobs: int) -> int:
    """Worker threads for ``jobs`` pairs: ``threads``, by default one per usable core."""
    import os

    if threads is None:
        try:
            threads = len(os.sched_getaffinity(0))
        except AttributeError:  # not on Linux
            threads = os.cpu_count() or 1
    if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
        raise ValueError(f"threads must be a positive integer, got {threads!r}")
    return max(1, min(threads, jobs))


def same_size(reads: list[PairRead], of_loaded: bool = False) -> tuple[int, int] | None:
    """The session's image size, and every pair of another size rejected (in place): the
    size of its first kept pair, or with ``of_loaded`` of its first pair read at all."""
    size = None
    for n, r in enumerate(reads):
        if r.pair is None or not (r.kept or of_loaded):
            continue
        if size is None:
            size = r.pair.size
        elif r.pair.size != size:
            w, h = r.pair.size
            reads[n] = r.rejected(f"the images are {w} x {h} pixels but the session's are "
                                  f"{size[0]} x {size[1]}", loaded=False)
    return size


def session_offset(reads: list[PairRead], reader: PairReader) -> tuple[float | None, set[int]]:
    """The session's albedo offset, the median of its kept pairs' own, given to the pairs
    whose stripe could not fit one (in place: their stripe extracted again, or the pair
    rejected): (the offset or None, the indices of the pairs that took it). One board print
    and one laser: a stripe on one level of the board only (along a row of light squares)
    cannot fit the offset; with 0 instead, it would be lost on the light squares and pulled
    towards the dark ones where it touches them. Nothing waits for it unless the reader
    defers (``defer``): (None, empty set)."""
    if not reader.defer:
        return None, set()
    offsets = [r.pair.offset for r in reads if r.kept and r.pair.offset is not None
               and np.isfinite(r.pair.offset)]
    offset = float(np.median(offsets)) if offsets else None
    taken: set[int] = set()
    for n, r in enumerate(reads):
        if not r.kept or not stripe_pending(r.pair):
            continue
        options = reader.stripe_options
        try:
            if offset is not None:
                pair = restripe(r.pair, offset, reader.normalize, options, reader.min_stripe)
                options = dict(options, albedo_offset=offset)
            else:
                pair = r.pair
                check_stripe(pair, reader.min_stripe)
        except PairRejected as e:
            reads[n] = r.rejected(str(e))
            continue
        if offset is not None:
            taken.add(r.index)
        reads[n] = reader.measured(replace(r, pair=pair), options, final=True)
    return offset, taken


def session_blur(reads: list[PairRead]) -> float | None:
    """The camera's blur variance fitted to the session's kept pairs
    (:func:`~hmlvs.image.session.session_blur_var`) and applied to their stripes (in place);
    None when no edge shift was measured (the blur was given)."""
    kept = [(n, r) for n, r in enumerate(reads) if r.kept and r.edge is not None]
    if not kept:
        return None
    var = session_blur_var([(r.pair.stripe, r.edge) for _, r in kept])
    for n, r in kept:
        reads[n] = replace(r, pair=replace(r.pair, stripe=with_blur_var(r.pair.stripe, r.edge,
                                                                        var)))
    return var
