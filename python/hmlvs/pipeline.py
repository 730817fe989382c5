"""Images to calibrations, for either sensor model: the top of the library, over the image
pipeline (:mod:`hmlvs.image`) and the identification (:mod:`hmlvs.calibration`)."""

from __future__ import annotations

from dataclasses import dataclass
import os
from typing import Any, Callable, Sequence, Union

from .calibration.joint import JointCalibration, calibrate_joint
from .calibration.solvers import CalibrationResult
from .calibration.solvers import calibrate as calibrate_paper
from .data.calibration_file import Calibration
from .data.dataset import Dataset
from .data.views import ViewData
from .diagnostics.verdict import Verdict
from .geometry.board import BoardSpec, Checkerboard
from .geometry.robot import Robot
from .image.accounts import ImageReport
from .models.opencv import DISTORTION_NAMES, OpenCvSensor

#: what :func:`calibrate` takes: calibration points (paper model: a data set, or a
#: simulation's fit and test points), an image session's folder or manifest, or views already
#: extracted (opencv model)
CalibrationData = Union[Dataset, str, os.PathLike, Sequence[ViewData]]


def calibrate(data: CalibrationData, *, model: str = "paper", **options: Any
              ) -> CalibrationResult | JointCalibration:
    """Calibrate a sensor: ``model="paper"`` identifies the paper's 14 parameters from
    calibration points (a :class:`hmlvs.Dataset` or a simulation; options and result:
    :func:`hmlvs.calibration.solvers.calibrate`); ``model="opencv"`` calibrates the general
    model from an image session or extracted views (:func:`calibrate_views`; returns a
    :class:`~hmlvs.calibration.joint.JointCalibration`). Defaults are the command line's."""
    if model == "opencv":
        return calibrate_views(data, **options)
    if model != "paper":
        raise ValueError(f"unknown model {model!r}; the models are opencv and paper")
    return calibrate_paper(data, **options)


def calibrate_views(source: str | os.PathLike | Sequence[ViewData], *,
                    board: BoardSpec | Checkerboard | None = None,
                    image_size: tuple[int, int] | None = None,
                    robot: Robot | None = None, test: Sequence[ViewData] | None = None,
                    **options: Any) -> JointCalibration:
    """The general model's calibration from an image session (a folder or manifest, see
    docs/file-formats.md) or from views already extracted (a list of :class:`ViewData`, with
    ``board`` and ``image_size``). ``options`` go to
    :func:`hmlvs.calibration.joint.calibrate_joint`; the manifest's measured board pose
    (``board.origin``), if any, is used unless ``base_from_board`` is given."""
    if isinstance(source, (list, tuple)):
        if board is None or image_size is None:
            raise ValueError("views given as a list need board= and image_size=")
        return calibrate_joint(source, board, image_size, test=test, **options)
    from .image.views import views_from_images

    views, spec, size, board_pose, _ = views_from_images(source, robot=robot, board=board)
    if not views:
        raise ValueError(f"{source}: no view has both the whole board and a stripe")
    options.setdefault("base_from_board", board_pose)
    return calibrate_joint(views, spec, size, test=test, **options)


@dataclass
class SessionCalibration:
    """An image session calibrated with the general (opencv) model, judged and ready to save
    (:func:`calibrate_session`)."""

    result: JointCalibration
    verdict: Verdict
    #: the calibration file's content, its verdict included (``calibration.save(path)``)
    calibration: Calibration
    #: one account per image pair, in the session's order
    reports: list[ImageReport]
    views: list[ViewData]
    board: BoardSpec
    image_size: tuple[int, int]


def calibrate_session(source: str | os.PathLike, *, robot: Robot | None = None,
                      distortion: Sequence[str] = DISTORTION_NAMES, holdout: float = 0.0,
                      seed: int = 0, camera: OpenCvSensor | None = None,
                      require: float | None = None,
                      on_views: Callable[[list[ImageReport]], None] | None = None
                      ) -> SessionCalibration:
    """What ``hmlvs calibrate --model opencv`` does, as a library call: the session's images
    -> views (:func:`~hmlvs.image.views.views_from_images`; ``on_views`` sees their accounts
    before the solve) -> a held-out fraction ``holdout`` of them drawn with ``seed`` -> the
    joint calibration (a failure led by the likely mistake) -> its verdict (with ``require``
    mm as the most predicted 95th-percentile 3D uncertainty, if given) -> the calibration
    file's content. ``camera``: an opencv calibration whose camera and laser plane are held
    (e.g. a bench session's); only the hand-eye transform and the board pose are then
    calibrated."""
    from .data.views import split_views
    from .diagnostics.mistakes import explaining
    from .diagnostics.verdict import judge_joint, require_check
    from .image.views import views_from_images

    terms = tuple(distortion)
    views, board, size, board_pose, reports = views_from_images(source, robot=robot)
    if on_views is not None:
        on_views(reports)
    if not views:
        raise ValueError("no view has both the whole board and a stripe:\n" + "\n".join(
            f"  {r.id}: {r.reason}" for r in reports))
    views, test_views = split_views(views, holdout, seed)
    with explaining(views, board, size):  # a failure led by the likely mistake
        result = calibrate_joint(views, board, size, distortion=terms,
                                 base_from_board=board_pose, test=test_views or None,
                                 camera=camera)
    verdict = require_check(judge_joint(
        result, views, board, options={"distortion": terms, "base_from_board": board_pose,
                                       "camera": camera}), require)
    cal = Calibration.from_joint(result, robot=robot,
                                 blur_var=next((r.blur_var for r in reports if r.ok), None))
    cal.verdict = verdict.to_dict()
    return SessionCalibration(result, verdict, cal, reports, views, board, size)
