"""Laser on/off images + robot poses -> the views of the general model's joint calibration.

For every pair: the stripe (the same checks, difference image and extraction as the paper
pipeline, :func:`hmlvs.image.session.stripe_from_pair`) and the whole board, found and numbered
without any prior model (:func:`hmlvs.image.corners.detect_board`). Which stripe pixels lie on
the board is decided by the calibration itself, once the board's pose in each view is known.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..data.manifest import checkerboard_of
from ..data.views import ViewData
from ..geometry.board import BoardSpec, CharucoSpec
from .corners import BoardNotFoundError, detect_board, detect_charuco
from .partial import PartialView, add_partial_views, partial_view
from .session import (
    ImageReport,
    _blur_var,
    _edge_shift,
    _opencv_failure,
    _read_manifest,
    _read_pair,
    _record_id,
    _record_names,
    _Reject,
    _with_blur_var,
    session_blur_var,
)

MIN_CORNERS = 6  # a view needs this many numbered corners (calibrate_joint's minimum)


def board_of(doc: dict[str, Any], board: Any, source: Any) -> tuple[BoardSpec, np.ndarray | None]:
    """The board (rows, cols, square; or a ChArUco board, ``type: charuco``) of a manifest or
    the caller, and its measured pose in the base when the manifest gives one (``origin``),
    else None."""
    from ..geometry.board import Checkerboard

    spec = board if board is not None else doc.get("board")
    if spec is None:
        raise ValueError(f"{source}: the manifest has no 'board' (rows, cols, square) and no "
                         "board was given")
    pose = None
    if isinstance(spec, CharucoSpec):
        return spec, None
    if isinstance(spec, (BoardSpec, Checkerboard)):
        return BoardSpec.of(spec), (spec.base_from_board() if isinstance(spec, Checkerboard)
                                    else None)
    if isinstance(spec, dict) and spec.get("type", "checkerboard") != "checkerboard":
        if spec["type"] != "charuco":
            raise ValueError(f"{source}: unknown board type {spec['type']!r}; choose "
                             "checkerboard or charuco")
        try:
            return CharucoSpec.from_dict(spec), None
        except (TypeError, ValueError) as e:
            raise ValueError(f"{source}: {e}") from None
    if isinstance(spec, dict):
        spec = {k: v for k, v in spec.items() if k != "type"}
    checked = checkerboard_of(spec, source)
    if "origin" in spec:
        pose = checked.base_from_board()
    return BoardSpec.of(spec), pose


def views_from_images(source: Any, *, robot: Any = None, board: Any = None,
                      joint_unit: str | None = None, channel: int | None = None,
                      normalize: bool = True, min_stripe: int = 20, **stripe_options: Any
                      ) -> tuple[list[ViewData], BoardSpec, tuple[int, int], np.ndarray | None,
                                 list[ImageReport]]:
    """An image session (a manifest, see docs/file-formats.md) -> joint-calibration views.

    Returns (views, board, image size (w, h), the board's measured base_from_board or None,
    one :class:`ImageReport` per pair). A fully visible checkerboard is numbered by the
    top-left rule (made consistent across views by
    :func:`hmlvs.calibration.joint.calibrate_joint`); a partly visible one from its robot pose
    and a first calibration on the whole-board views (:mod:`hmlvs.image.partial`), or the
    view is rejected with the reason; a ChArUco board may be partly visible, its corners
    numbered by the marker ids. A pair
    without a stripe, without the board or with fewer than 6 numbered corners is reported
    and skipped; the rest of the session goes through. Unless ``blur_var`` is given, the
    stripes' correction at the board's albedo steps uses the camera blur fitted to the
    session (:func:`hmlvs.image.session.session_blur_var`).
    """
    from dataclasses import replace

    import cv2

    from ..geometry.robot import Robot

    records, doc, folder = _read_manifest(source)
    board_spec, board_pose = board_of(doc, board, source)
    unit = doc.get("joint_unit", "rad") if joint_unit is None else joint_unit
    if robot is None:
        name = doc.get("robot")
        needs_robot = any(isinstance(r, dict) and "joints" in r for r in records)
        if needs_robot and name not in (None, Robot.scorbot_er7().name):
            raise ValueError(f"the images were taken with robot {name!r}; pass its DH table "
                             "(robot=hmlvs.Robot(...) or --robot FILE)")
        robot = Robot.scorbot_er7()
    from ..geometry.board import Checkerboard

    detector_board = board_spec if board_spec.unambiguous else Checkerboard(
        rows=board_spec.rows, cols=board_spec.cols, square=board_spec.square)
    views: list[ViewData] = []
    reports: list[ImageReport] = []
    partial: list[tuple[int, PartialView, Any]] = []
    size = None
    stripe_options = dict(stripe_options)
    fit_blur = stripe_options.get("blur_var") is None
    stripe_options["blur_var"] = _blur_var(stripe_options.get("blur_var"))
    edges: dict[str, tuple[Any, np.ndarray]] = {}
    for index, rec in enumerate(records):
        pid = _record_id(rec, index)
        on_name, off_name = _record_names(rec)
        try:
            pair = _read_pair(rec, index, folder, unit, robot, size, channel, normalize,
                              stripe_options, min_stripe)
            size = pair.size
            if fit_blur:
                edges[pid] = (pair.stripe, _edge_shift(pair, normalize, stripe_options))
            try:
                corners = detect_corners(pair.off, detector_board)
            except BoardNotFoundError as e:
                if board_spec.unambiguous:
                    raise _Reject(str(e)) from None
                # a partly visible board: numbered below from a first calibration
                partial.append((len(reports), partial_view(pid, pair, detector_board, e),
                                pair))
                reports.append(None)  # type: ignore[arg-type]
                continue
            except ValueError as e:
                raise _Reject(str(e)) from None
            except cv2.error as e:
                raise _opencv_failure(e, "board", hint="") from None
            if len(corners) < MIN_CORNERS:
                raise _Reject(f"only {len(corners)} board corners found and numbered; a view "
                              f"needs at least {MIN_CORNERS}")
        except _Reject as e:
            reports.append(ImageReport(pid, index, on_name, off_name, False, str(e)))
            continue
        views.append(ViewData(pid, np.asarray(corners.pixels, float),
                              np.asarray(corners.index, int), pair.stripe.pixels, pair.pose))
        reports.append(ImageReport(pid, index, pair.on_name, pair.off_name, True, "",
                                   pair.stripe.counts(), len(corners.index),
                                   int(pair.stripe.found.sum())))
    var = stripe_options["blur_var"]
    if edges:
        var = session_blur_var(list(edges.values()))
        fixed = {pid: _with_blur_var(st, k, var).pixels for pid, (st, k) in edges.items()}
        views = [replace(v, laser_pixels=fixed.get(v.id, v.laser_pixels)) for v in views]
        partial = [(slot, replace(p, stripe=fixed.get(p.id, p.stripe)), pair)
                   for slot, p, pair in partial]
    if partial:
        add_partial_views(partial, views, reports, board_spec, size, detector_board,
                          board_pose, MIN_CORNERS)
    reports = [replace(r, blur_var=var) if r.ok else r for r in reports]
    if size is None:
        raise ValueError("no image pair could be read: " +
                         "; ".join(f"{r.id}: {r.reason}" for r in reports))
    return views, board_spec, size, board_pose, reports


def detect_corners(image: np.ndarray, board: Any) -> Any:
    """The numbered corners of one laser-off image: :func:`detect_charuco` for a ChArUco
    board (``board.unambiguous``), else :func:`detect_board` (a whole checkerboard, numbered
    by the top-left rule)."""
    if getattr(board, "unambiguous", False):
        return detect_charuco(image, board)
    return detect_board(image, board)

