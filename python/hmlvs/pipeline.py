"""Images to calibrations, for either sensor model: the top of the library, over the image
pipeline (:mod:`hmlvs.image`) and the identification (:mod:`hmlvs.calibration`)."""

from __future__ import annotations

import os
from typing import Any, Sequence, Union

from .calibration.joint import JointCalibration, calibrate_joint
from .calibration.solvers import CalibrationResult
from .calibration.solvers import calibrate as calibrate_paper
from .data.dataset import Dataset
from .data.views import ViewData
from .geometry.board import BoardSpec, Checkerboard
from .geometry.robot import Robot

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
