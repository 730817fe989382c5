"""The report of a calibration of either model: one entry point,
:func:`write_calibration_report` (``hmlvs.report.write_calibration_report``), used by
``hmlvs calibrate --report`` and ``hmlvs report``. It dispatches on the calibration's model
to the paper model's page (:mod:`hmlvs.report.html`) or the general model's
(:mod:`hmlvs.report.joint`)."""

from __future__ import annotations

from dataclasses import dataclass
import os
from pathlib import Path
from typing import Any

from ..data.calibration_file import Calibration, dataset_hash
from ..data.dataset import Dataset, fit_and_test
from ..data.manifest import is_manifest
from ..diagnostics.verdict import Verdict


@dataclass(frozen=True)
class WrittenReport:
    """What :func:`write_calibration_report` wrote: the file, and what the report shows.

    path : the HTML file
    result : the solve shown: the calibration's own (``calibration.solve``) or the
        calibration evaluated on the data given (a
        :class:`~hmlvs.calibration.result.CalibrationResult` or
        :class:`~hmlvs.calibration.joint.JointCalibration`)
    dataset, test : paper model: the calibration points shown (fitting, held out)
    """

    path: Path
    result: Any
    dataset: Dataset | None = None
    test: Dataset | None = None


def write_calibration_report(calibration: Calibration | str | os.PathLike,
                             path: str | os.PathLike, data: Any = None, *,
                             test: Dataset | None = None, robot: Any = None,
                             mode: str = "corners", image_reports: Any = None,
                             verdict: Verdict | None = None, truth: Any = None
                             ) -> WrittenReport:
    """Write the HTML report (atomically) of ``calibration``, a :class:`Calibration` of
    either model (:func:`hmlvs.calibrate`'s, or a file's, or the file's path); its verdict
    comes first (``verdict`` overrides the calibration's).

    paper model: ``data`` are calibration points (a :class:`Dataset`, a simulation with
    ``fit``/``test``, a data set file, or an image session whose points are extracted with
    ``mode`` and ``robot``), ``test`` held-out ones. The report shows the calibration's own
    solve when ``data`` are the points it was fitted to (``data_sha256``) and ``test`` is
    absent or the size of its held-out set; otherwise the calibration evaluated on them.

    opencv model: without ``data``, the calibration's own solve (``image_reports``: its
    session's accounts); with ``data``, an image session, the calibration on that session
    (camera, laser plane and hand-eye held, the board's pose estimated).

    ``truth``: paper model, the true parameters of a simulation, shown beside the result."""
    if isinstance(calibration, (str, os.PathLike)):
        calibration = Calibration.load(calibration)
    if not isinstance(calibration, Calibration):
        raise ValueError("the report is of an hmlvs.Calibration (hmlvs.calibrate's result, or "
                         f"hmlvs.Calibration.load of a file), got {type(calibration).__name__}")
    path = Path(path)
    if path.suffix.lower() not in (".html", ".htm"):
        raise ValueError(f"{path}: the report is an .html file")
    if verdict is None:
        verdict = calibration.judged if calibration.judged is not None else (
            Verdict.from_dict(calibration.verdict) if calibration.verdict else None)
    if calibration.model == "opencv":
        if test is not None or truth is not None:
            raise ValueError("test= and truth= are for paper-model calibrations; this "
                             "calibration is opencv")
        return _opencv(calibration, path, data, robot, image_reports, verdict)
    return _paper(calibration, path, data, test, robot, mode, image_reports, verdict, truth)


def _opencv(cal: Calibration, path: Path, data: Any, robot: Any, image_reports: Any,
            verdict: Verdict | None) -> WrittenReport:
    """The general model's report: its own solve, or its evaluation on an image session."""
    from .joint import write_joint_report

    if data is None:
        if cal.solve is None:
            raise ValueError("an opencv-model calibration read from a file is reported on an "
                             "image session: give data= (a folder with manifest.json/yaml, "
                             "or the manifest file)")
        result = cal.solve
    else:
        from ..calibration.joint import evaluate_sensor
        from ..image.views import views_from_images

        if not is_manifest(data):
            raise ValueError(f"{data}: an opencv-model calibration is reported on an image "
                             "session (a folder with manifest.json/yaml, or the manifest file)")
        views, board, size, _, image_reports = views_from_images(data, robot=robot)
        if not views:
            raise ValueError(f"{data}: no view has a detected board and a stripe")
        result = evaluate_sensor(cal.sensor, views, board, size, std=cal.std)
    return WrittenReport(write_joint_report(result, path, image_reports=image_reports,
                                            verdict=verdict), result)


def _paper(cal: Calibration, path: Path, data: Any, test: Dataset | None, robot: Any,
           mode: str, image_reports: Any, verdict: Verdict | None,
           truth: Any) -> WrittenReport:
    """The paper model's report on calibration points: its own solve on the points it was
    fitted to, else the calibration evaluated on them."""
    from .html import write_report

    if data is None:
        raise ValueError("a paper-model report shows the calibration on calibration points: "
                         "give data= (a Dataset, a data set file or an image session)")
    if isinstance(data, (str, os.PathLike)):
        if is_manifest(data):
            from ..image.paper_session import dataset_from_images

            data, image_reports = dataset_from_images(data, mode=mode, robot=robot)
        else:
            data = Dataset.load(data)
    ds, test = fit_and_test(data, test)
    solve = cal.solve
    own = (solve is not None and cal.data_sha256 == dataset_hash(ds)
           and (test is None or getattr(solve, "test_errors", None) is not None
                and solve.test_errors.size == len(test)))
    if own:
        result, std = solve, None
    else:
        from ..calibration.solvers import evaluate

        assert cal.params is not None
        result = evaluate(cal.params, ds, test, method=cal.method or "loaded", fixed=cal.fixed)
        std = cal.std
    written = write_report(result, ds, path, test=test, truth=truth, std=std,
                           image_reports=image_reports, verdict=verdict)
    return WrittenReport(written, result, ds, test)
