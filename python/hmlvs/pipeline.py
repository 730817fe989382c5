"""Images to calibrations, for either sensor model: the top of the library, over the image
pipeline (:mod:`hmlvs.image`), the identification (:mod:`hmlvs.calibration`) and the verdict
(:mod:`hmlvs.diagnostics.verdict`). Either model's calibration is a :class:`Calibration`:
the calibration file's content, its verdict included, with the solver's outcome
(``calibration.solve``)."""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass
import os
from typing import Any, Callable, Iterator, Sequence, Union

from .calibration.joint import JointCalibration, calibrate_joint
from .calibration.solvers import CalibrationResult
from .calibration.solvers import calibrate as calibrate_paper
from .data.calibration_file import Calibration
from .data.dataset import Dataset, fit_and_test
from .data.views import ViewData
from .diagnostics.verdict import Verdict
from .geometry.board import BoardSpec, Checkerboard
from .geometry.robot import Robot
from .image.accounts import ImageReport
from .models.opencv import CLASSIC_DISTORTION, OpenCvSensor

#: what :func:`calibrate` takes: calibration points (paper model: a data set, or a
#: simulation's fit and test points), an image session's folder or manifest, or views already
#: extracted (opencv model)
CalibrationData = Union[Dataset, str, os.PathLike, Sequence[ViewData]]


def calibrate(data: CalibrationData, *, model: str = "paper", robot: Robot | None = None,
              judge: bool = True, require: float | None = None, **options: Any
              ) -> Calibration:
    """Calibrate a sensor; either model's calibration is a :class:`Calibration` (the
    calibration file's content: ``save``, ``to_dict``; the solver's whole outcome as
    ``calibration.solve``).

    ``model="paper"`` identifies the paper's 14 parameters from calibration points (a
    :class:`hmlvs.Dataset` or a simulation; ``options``:
    :func:`hmlvs.calibration.solvers.calibrate`, whose
    :class:`~hmlvs.calibration.result.CalibrationResult` is ``solve``); ``model="opencv"``
    calibrates the general model from an image session or extracted views
    (:func:`calibrate_views`; ``solve``: a
    :class:`~hmlvs.calibration.joint.JointCalibration`). ``robot``: the arm, kept in the
    calibration (and, for images, the one that took them). ``judge``: give the calibration
    its verdict (:mod:`hmlvs.diagnostics.verdict`, as ``hmlvs calibrate`` does; it
    calibrates two halves of the data again), with ``require`` mm as the most predicted
    95th-percentile 3D uncertainty, if given. Defaults are the command line's: for the same
    data and options, the same file content."""
    if model == "opencv":
        return calibrate_views(data, robot=robot, judge=judge, require=require, **options)
    if model != "paper":
        raise ValueError(f"unknown model {model!r}; the models are opencv and paper")
    result = calibrate_paper(data, **options)
    fit, _ = fit_and_test(data, options.get("test"))
    return judged_paper(result, fit, robot=robot, judge=judge, require=require)


def judged_paper(result: CalibrationResult, dataset: Dataset, *, robot: Robot | None = None,
                 views: Sequence[ViewData] | None = None, judge: bool = True,
                 require: float | None = None) -> Calibration:
    """A paper-model solve (on ``dataset``) as a :class:`Calibration`, with its verdict
    (:func:`~hmlvs.diagnostics.verdict.judge_paper`; ``views``: those of a session from
    images) unless ``judge`` is False."""
    from .diagnostics.verdict import judge_paper, require_check

    cal = Calibration.from_result(result, dataset, robot=robot)
    if judge:
        with _quiet_refits():
            verdict = judge_paper(result, dataset, views=views)
        _set_verdict(cal, require_check(verdict, require))
    return cal


def _set_verdict(cal: Calibration, verdict: Verdict) -> None:
    cal.verdict = verdict.to_dict()
    cal.judged = verdict


@contextmanager
def _quiet_refits() -> Iterator[None]:
    """The verdict's cross-validation calibrates two halves of the data again: what those
    solves warn about is said of the halves, not of the calibration judged (whose own
    warnings were given), so it is not repeated."""
    import warnings

    from .errors import HmlvsDataWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HmlvsDataWarning)
        yield


def calibrate_views(source: str | os.PathLike | Sequence[ViewData], *,
                    board: BoardSpec | Checkerboard | None = None,
                    image_size: tuple[int, int] | None = None,
                    robot: Robot | None = None, test: Sequence[ViewData] | None = None,
                    judge: bool = True, require: float | None = None,
                    **options: Any) -> Calibration:
    """The general model's calibration from an image session (a folder or manifest, see
    docs/file-formats.md) or from views already extracted (a list of :class:`ViewData`, with
    ``board`` and ``image_size``), judged unless ``judge`` is False (see :func:`calibrate`).
    ``options`` go to :func:`hmlvs.calibration.joint.calibrate_joint`; the manifest's
    measured board pose (``board.origin``), if any, is used unless ``base_from_board`` is
    given."""
    reports: list[ImageReport] = []
    if isinstance(source, (list, tuple)):
        if board is None or image_size is None:
            raise ValueError("views given as a list need board= and image_size=")
        views, spec, size = list(source), BoardSpec.of(board), image_size
    else:
        from .image.views import views_from_images

        views, spec, size, board_pose, reports = views_from_images(source, robot=robot,
                                                                   board=board)
        if not views:
            raise ValueError(f"{source}: no view has both the whole board and a stripe")
        options.setdefault("base_from_board", board_pose)
    return _joint(views, spec, size, reports, robot=robot, test=test, judge=judge,
                  require=require, options=options)


def _joint(views: list[ViewData], board: BoardSpec, size: tuple[int, int],
           reports: list[ImageReport], *, robot: Robot | None,
           test: Sequence[ViewData] | None, judge: bool, require: float | None,
           options: dict[str, Any]) -> Calibration:
    """The joint calibration of ``views`` (a failure led by the likely mistake), judged
    (its two halves calibrated again with the same ``options``) unless ``judge`` is False,
    as a :class:`Calibration` (the camera blur of the session's ``reports``, if any)."""
    from .diagnostics.mistakes import explaining
    from .diagnostics.verdict import judge_joint, require_check

    # a failure led by the likely cause
    with explaining(views, board, size, options.get("distortion", CLASSIC_DISTORTION)):
        result = calibrate_joint(views, board, size, test=test, **options)
    cal = Calibration.from_joint(result, robot=robot,
                                 blur_var=next((r.blur_var for r in reports if r.ok), None))
    if judge:
        with _quiet_refits():
            verdict = judge_joint(result, views, board, options=options)
        _set_verdict(cal, require_check(verdict, require))
    return cal


@dataclass
class SessionCalibration:
    """An image session calibrated with the general (opencv) model, judged and ready to save
    (:func:`calibrate_session`)."""

    result: JointCalibration
    verdict: Verdict
    #: the calibration (the file's content, its verdict included: ``calibration.save(path)``;
    #: ``calibration.solve`` is ``result``)
    calibration: Calibration
    #: one account per image pair, in the session's order
    reports: list[ImageReport]
    views: list[ViewData]
    board: BoardSpec
    image_size: tuple[int, int]


def calibrate_session(source: str | os.PathLike, *, robot: Robot | None = None,
                      distortion: Sequence[str] = CLASSIC_DISTORTION, holdout: float = 0.0,
                      seed: int = 0, camera: OpenCvSensor | None = None,
                      require: float | None = None, robot_poses: str = "exact",
                      on_views: Callable[[list[ImageReport]], None] | None = None
                      ) -> SessionCalibration:
    """What ``hmlvs calibrate --model opencv`` does, as a library call: the session's images
    -> views (:func:`~hmlvs.image.views.views_from_images`; ``on_views`` sees their accounts
    before the solve) -> a held-out fraction ``holdout`` of them drawn with ``seed`` -> the
    joint calibration (a failure led by the likely mistake) -> its verdict (with ``require``
    mm as the most predicted 95th-percentile 3D uncertainty, if given) -> the calibration
    file's content. ``camera``: an opencv calibration whose camera and laser plane are held
    (e.g. a bench session's); only the hand-eye transform and the board pose are then
    calibrated. ``robot_poses``: "exact" or "uncertain"
    (:func:`~hmlvs.calibration.joint.calibrate_joint`). :func:`calibrate` with
    ``model="opencv"`` gives the same calibration (without the hold-out)."""
    from .calibration.joint_setup import check_distortion
    from .calibration.joint_solve import robot_poses_uncertain
    from .data.views import split_views
    from .image.views import views_from_images

    robot_poses_uncertain(robot_poses)  # checked before the images are read
    check_distortion(distortion)

    views, board, size, board_pose, reports = views_from_images(source, robot=robot)
    if on_views is not None:
        on_views(reports)
    if not views:
        raise ValueError("no view has both the whole board and a stripe:\n" + "\n".join(
            f"  {r.id}: {r.reason}" for r in reports))
    if robot_poses == "uncertain" and any(v.base_from_hand is None for v in views):
        raise ValueError("robot poses uncertain: this session has views without a robot pose "
                         "(a bench session's board poses are all free already)")
    views, test_views = split_views(views, holdout, seed)
    cal = _joint(views, board, size, reports, robot=robot, test=test_views or None,
                 judge=True, require=require,
                 options={"distortion": tuple(distortion), "base_from_board": board_pose,
                          "camera": camera, "robot_poses": robot_poses})
    assert cal.solve is not None and cal.judged is not None
    return SessionCalibration(cal.solve, cal.judged, cal, reports, views, board, size)


def session_model(data: str | os.PathLike, model: str = "auto") -> str:
    """The sensor model to calibrate ``data`` with: ``model`` as asked (opencv needs images),
    or (``"auto"``) opencv for an image manifest without a measured board pose, paper
    otherwise (a data set of calibration points, or images of a placed board)."""
    from .data.manifest import is_manifest, read_manifest

    if model not in ("auto", "opencv", "paper"):
        raise ValueError(f"--model must be opencv, paper or auto, got {model!r}")
    if model != "auto":
        if model == "opencv" and not is_manifest(data):
            raise ValueError(f"{data}: the opencv model is calibrated from images (a manifest); "
                             "a data set of calibration points is for --model paper")
        return model
    if not is_manifest(data):
        return "paper"
    _, doc, _ = read_manifest(data)
    board = doc.get("board")
    return "paper" if isinstance(board, dict) and "origin" in board else "opencv"


@dataclass
class PaperCalibration:
    """A paper-model calibration of an image session or a data set, judged and ready to save
    (:func:`calibrate_paper_data`)."""

    #: the file's content, its verdict included (``calibration.solve``: the solver's outcome)
    calibration: Calibration
    #: the calibration points fitted, and those held out (None without)
    dataset: Dataset
    test: Dataset | None
    #: one account per image pair (empty for a data set)
    reports: list[ImageReport]
    #: the search bounds widened to hold the initial guess, one sentence each
    notes: list[str]
    #: the calibration points extracted from the images, all of them (None for a data set)
    extracted: Dataset | None = None


def calibrate_paper_data(data: str | os.PathLike, *, mode: str = "corners",
                         robot: Robot | None = None,
                         initial: str | os.PathLike | None = None,
                         bounds: str | os.PathLike | None = None,
                         test: str | os.PathLike | None = None, holdout: float = 0.0,
                         seed: int = 0, require: float | None = None,
                         on_images: Callable[[list[ImageReport]], None] | None = None,
                         **options: Any) -> PaperCalibration:
    """What ``hmlvs calibrate --model paper`` does, as a library call: an image session's
    calibration points (``mode`` corners or homography; the corners numbered with the
    ``initial`` guess, a file of either model, else the nominal values; ``on_images`` sees the
    images' accounts before the solve) or a data set file -> a held-out part (the ``test``
    file, else a fraction ``holdout`` of the poses drawn with ``seed``) -> the solve
    (``options``: :func:`hmlvs.calibration.solvers.calibrate`, within the ``bounds`` file or
    Table 2 widened to hold the guess) -> its verdict (``require``: see :func:`calibrate`)."""
    from .data.guess import bounds_with, initial_board_pose, read_bounds, read_initial
    from .data.manifest import is_manifest
    from .models.params import Parameters

    guess = read_initial(initial) if initial is not None else None
    reports: list[ImageReport] = []
    extracted = None
    if is_manifest(data):
        from .image.paper_session import dataset_from_images

        # a board the manifest does not place sits where an opencv initial guess put it
        ds, reports = dataset_from_images(
            data, mode=mode, robot=robot, params=guess,
            base_from_board=initial_board_pose(initial) if initial is not None else None)
        extracted = ds
        if on_images is not None:
            on_images(reports)
    else:
        ds = Dataset.load(data)
    test_ds = Dataset.load(test) if test is not None else None
    if test_ds is None and holdout > 0:
        ds, test_ds = ds.split(1.0 - holdout, seed=seed, by_pose=True)
    notes: list[str] = []
    if bounds is not None:
        options["bounds"] = read_bounds(bounds, guess or Parameters.nominal())
    elif guess is not None:
        options["bounds"], notes = bounds_with(guess)
    result = calibrate_paper(ds, test=test_ds, initial=guess, seed=seed, **options)
    cal = judged_paper(result, ds, robot=robot, require=require,
                       views=[r.view for r in reports if r.view is not None])
    return PaperCalibration(cal, ds, test_ds, reports, notes, extracted)
