"""hmlvs calibrate: images or a data set -> a calibration file, with its verdict."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional

import typer

from ..calibration.options import LmOptions, PsoOptions
from ..models.opencv import CLASSIC_DISTORTION
from .common import (
    GLOSSARY_URL,
    app,
    check_suffix,
    command,
    exit_untrusted,
    finish,
    guard,
    inputs_of,
    load_robot,
    outputs,
    resolve_fixed,
    rotation_text,
    session_of,
    show_warnings,
    solve_progress,
    without_warning_lines,
)
from .options import JSON_OPTION, ROBOT_OPTION, out_option

_INITIAL_OPTION = typer.Option(
    None, help="opencv model: a calibration whose camera and laser plane are held (e.g. a "
    "bench session's), so that only the hand-eye transform and the board pose are "
    "calibrated. paper model: initial guess, a calibration file of either model (an opencv "
    "one is converted) or a YAML/JSON mapping of parameter names to values "
    "(docs/file-formats.md).")

_MODEL_OPTION = typer.Option(
    "auto", help="Sensor model: opencv (OpenCV intrinsics and distortion, a 3-DoF laser "
    "plane, any hand-eye rotation; calibrated from the board's corners and the stripe "
    "together, no guess needed) or paper (the paper's 14 parameters, from calibration "
    "points). auto: opencv for images whose manifest gives no board pose, else paper.")

_ROBOT_POSES_OPTION = typer.Option(
    "exact", help="opencv model: exact (every view's board pose follows from its robot pose) "
    "or uncertain (each view keeps its own board pose, tied to the chain's by the robot pose "
    "error it implies, whose spread is estimated: for robots whose poses disagree with the "
    "images; the verdict's checks tell).")

_BOUNDS_OPTION = typer.Option(
    None, help="paper model: search bounds, a YAML/JSON mapping of parameter names to "
    "[lower, upper] or {plus_minus: h} around the initial guess; others keep Table 2.")


def _paper_only_options(**given: bool) -> None:
    """Refuse options that the opencv model does not use (an option that does nothing would
    be an error the user never hears of)."""
    names = [k.replace("_", "-") for k, v in given.items() if v]
    if names:
        raise ValueError("--" + ", --".join(names) + (" applies" if len(names) == 1 else
                                                        " apply") +
                         " to the paper model only (--model paper); the opencv model takes "
                         "--distortion, --holdout, --initial, --robot, --robot-poses, "
                         "--report, --require and --seed")


def _held_camera(initial: Optional[Path]) -> Any:
    """The sensor of an opencv-model --initial calibration (its camera and laser plane are
    held), or None."""
    if initial is None:
        return None
    from ..data.calibration_file import load_calibration

    cal = load_calibration(initial)
    if cal.model != "opencv" or cal.sensor is None:
        raise ValueError(f"{initial}: --initial with the opencv model holds the camera and "
                         "laser plane of an opencv-model calibration (e.g. a bench session's); "
                         f"this is a {cal.model}-model calibration")
    return cal.sensor


def _calibrate_opencv(data: Path, out: Path, holdout: float, seed: int, robot: Optional[Path],
                      distortion: str, report: Optional[Path], quiet: bool,
                      as_json: bool, initial: Optional[Path] = None,
                      require: Optional[float] = None, robot_poses: str = "exact") -> None:
    """hmlvs calibrate --model opencv: images -> views -> joint calibration -> verdict ->
    file. With ``initial`` (an opencv calibration, e.g. of a bench session) its camera and
    laser plane are held and the hand-eye transform and board pose calibrated. Exits 3 when
    the verdict is not trustworthy (the file is still written, marked so)."""
    from ..pipeline import calibrate_session

    with command(as_json) as caught:
        run = calibrate_session(
            data, robot=load_robot(robot), camera=_held_camera(initial), holdout=holdout,
            seed=seed, require=require, robot_poses=robot_poses,
            distortion=[t.strip() for t in distortion.split(",") if t.strip()],
            on_views=None if (as_json or quiet) else _echo_views)
        result, verdict, reports = run.result, run.verdict, run.reports
        path, report_path = _save(run.calibration, out, report, image_reports=reports)
    warns = finish(caught, as_json, _summary(path, report_path, run.calibration, reports),
                   result.warnings, quiet=True)
    if warns is None:
        exit_untrusted(verdict)
        return
    typer.echo(verdict.text())
    typer.echo(result.summary())
    _written(path, report_path, verdict, warns, quiet)


def _echo_views(reports: list) -> None:
    """One line per image pair of an opencv-model session, before the solve."""
    for r in reports:
        found = f"stripe in {r.stripe.get('FOUND', 0)} scan lines"
        note = f" ({r.note})" if getattr(r, "note", "") else ""
        typer.echo(f"{r.id}: rejected: {r.reason}" if not r.ok else
                   f"{r.id}: {r.corners} corners, {found}{note}" if r.corners else
                   f"{r.id}: laser only (no board seen), {found}")


def _save(cal: Any, out: Path, report: Optional[Path], **report_options: Any
          ) -> tuple[Path, Optional[Path]]:
    """Write the calibration file and, if asked, its report (either model,
    :func:`hmlvs.report.calibration.write_calibration_report`); neither is left without
    the other."""
    report_path = None
    with outputs(out) as made:
        path = cal.save(out)
        made.append(path)
        if report is not None:
            from ..report.calibration import write_calibration_report

            report_path = write_calibration_report(cal, report, **report_options).path
    return path, report_path


def _summary(path: Path, report_path: Optional[Path], cal: Any,
             reports: list) -> dict[str, Any]:
    """hmlvs calibrate --json, either model: the files written, the calibration file's
    content (:meth:`hmlvs.Calibration.to_dict`, its verdict included), the solve's figures
    (``solve``) and the account of every image pair (docs/file-formats.md)."""
    return {"calibration": str(path),
            "report": None if report_path is None else str(report_path),
            **cal.to_dict(), "solve": cal.solve_figures(),
            "images": [r.to_dict() for r in reports or ()]}


@app.command()
def calibrate(
    data: Path = typer.Argument(..., help="Calibration data set (.npz or .json), or an image "
                                "manifest (a folder with manifest.json, or the file)."),
    out: Path = out_option("calibration.yaml", "Calibration file to write (.yaml or .json)."),
    method: str = typer.Option("pso+lm", help="pso+lm, pso, lm, lm-paper or random."),
    test: Optional[Path] = typer.Option(None, help="Held-out data set for the test RMS."),
    holdout: float = typer.Option(0.0, help="Fraction of poses held out for testing when "
                                  "no --test is given (0 = none)."),
    fixed: list[str] = typer.Option(
        [], "--fixed", help="Parameter held at its initial value, in addition to the default "
        "gauge Su, Sv, Cu, Cv (repeat the option); --fixed none frees all."),
    free: list[str] = typer.Option(
        [], "--free", help="Parameter of the default gauge to estimate instead (repeat the "
        "option), e.g. --free Cu."),
    runs: int = typer.Option(1, help="Independent PSO runs (the best is kept)."),
    iterations: int = typer.Option(PsoOptions.iterations, help="PSO iterations."),
    loss: Optional[str] = typer.Option(None, help="Robust loss for LM: huber or cauchy."),
    loss_scale: float = typer.Option(LmOptions.loss_scale, help="Robust loss scale (mm)."),
    seed: int = typer.Option(0, help="Random seed."),
    threads: Optional[int] = typer.Option(None, help="Threads (default: all cores)."),
    report: Optional[Path] = typer.Option(None, help="Also write an HTML report here."),
    mode: str = typer.Option("corners", help="Calibration points from images: corners (the "
                             "paper's) or homography (every stripe point on the board)."),
    save_data: Optional[Path] = typer.Option(None, help="Save the data set extracted from "
                                             "images here (.npz or .json)."),
    robot: Optional[Path] = ROBOT_OPTION,
    model: str = _MODEL_OPTION,
    distortion: str = typer.Option(
        ",".join(CLASSIC_DISTORTION), help="opencv model: the distortion terms to estimate "
        "(the others stay 0), among OpenCV's k1,k2,p1,p2,k3,k4,k5,k6,s1,s2,s3,s4,taux,tauy: e.g. "
        "k1,k2, or k1,k2,p1,p2,k3,k4,k5,k6 (the rational model) for a wide lens, or "
        "k1,k2,p1,p2,k3,taux,tauy for a tilted (Scheimpflug) sensor."),
    initial: Optional[Path] = _INITIAL_OPTION,
    bounds: Optional[Path] = _BOUNDS_OPTION,
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bar, no per-image "
                               "lines and no warnings on the terminal (--json collects them)."),
    as_json: bool = JSON_OPTION,
    require: Optional[float] = typer.Option(
        None, "--require", help="Also call the calibration untrustworthy (exit 3) when its "
        "predicted 95th-percentile 3D uncertainty exceeds this many mm."),
    robot_poses: str = _ROBOT_POSES_OPTION,
) -> None:
    """Calibrate the sensor from laser on/off images (or, paper model, a calibration data set).

    Every calibration gets a verdict, printed first: trustworthy or not, from named checks;
    exit status 3 when it is not (the file is still written, marked so, with the reasons).

    --model opencv (the default for images without a measured board pose) estimates the
    camera, the laser plane, the hand-eye transform and the board's pose from the images and
    robot poses alone.

    Su, Sv, Cu and Cv are held at their initial (datasheet) values by default: laser points
    alone cannot determine them (docs/model.md; docs/glossary.md, "scale gauge", "flat direction").

    Example: hmlvs calibrate session.npz --holdout 0.3 --out calibration.yaml --report report.html
    """
    with guard(as_json):
        data = session_of(data)  # a manifest read and checked once, for every step below
        chosen = _checked(data, out, holdout, mode, test, initial, bounds, robot, report,
                          save_data, model)
        if chosen == "opencv":
            _paper_only_options(
                method=method != "pso+lm", fixed=bool(fixed), free=bool(free), runs=runs != 1,
                iterations=iterations != PsoOptions.iterations, loss=loss is not None,
                loss_scale=loss_scale != LmOptions.loss_scale, threads=threads is not None,
                bounds=bounds is not None, test=test is not None,
                save_data=save_data is not None, mode=mode != "corners")
        if robot_poses not in ("exact", "uncertain"):
            raise ValueError(f"--robot-poses must be exact or uncertain, got {robot_poses!r}")
        if robot_poses == "uncertain" and chosen != "opencv":
            raise ValueError("--robot-poses applies to the opencv model only (--model "
                             "opencv): the paper model maps its points through exact poses")
    if chosen == "opencv":
        _calibrate_opencv(data, out, holdout, seed, robot, distortion, report, quiet, as_json,
                          initial, require, robot_poses)
        return
    _calibrate_paper(_PaperRun(data, out, method, test, holdout, fixed, free, runs, iterations,
                               loss, loss_scale, seed, threads, report, mode, save_data, robot,
                               initial, bounds, quiet, as_json, require))


def _checked(data: Path, out: Path, holdout: float, mode: str, test: Optional[Path],
             initial: Optional[Path], bounds: Optional[Path], robot: Optional[Path],
             report: Optional[Path], save_data: Optional[Path], model: str) -> str:
    """Every option checked before anything is written (ValueError naming the problem); the
    sensor model to calibrate."""
    import math

    if not (math.isfinite(holdout) and 0 <= holdout < 1):
        raise ValueError(f"--holdout must be a fraction in [0, 1), got {holdout}")
    if mode not in ("corners", "homography"):
        raise ValueError(f"--mode must be corners or homography, got {mode!r}")
    from ..guard import refuse_overwrite

    refuse_overwrite([*inputs_of(data), test, initial, bounds, robot],
                     [("--out", out), ("--report", report), ("--save-data", save_data)])
    # every output's kind checked before the first is written
    check_suffix("--out", out, (".yaml", ".yml", ".json"), "a calibration file")
    check_suffix("--report", report, (".html", ".htm"), "an HTML report")
    check_suffix("--save-data", save_data, (".npz", ".json"), "a data set")
    from ..pipeline import session_model

    return session_model(data, model)


@dataclass
class _PaperRun:
    """hmlvs calibrate's options for the paper model."""

    data: Path
    out: Path
    method: str
    test: Optional[Path]
    holdout: float
    fixed: list[str]
    free: list[str]
    runs: int
    iterations: int
    loss: Optional[str]
    loss_scale: float
    seed: int
    threads: Optional[int]
    report: Optional[Path]
    mode: str
    save_data: Optional[Path]
    robot: Optional[Path]
    initial: Optional[Path]
    bounds: Optional[Path]
    quiet: bool
    as_json: bool
    require: Optional[float]


def _calibrate_paper(o: _PaperRun) -> None:
    """hmlvs calibrate --model paper: data set (or images) -> calibration -> verdict ->
    file (and report); exit 3 when the verdict is not trustworthy."""
    from ..pipeline import calibrate_paper_data

    with command(o.as_json) as caught:
        fixed_names, why = resolve_fixed(o.fixed, o.free)
        run = calibrate_paper_data(
            o.data, mode=o.mode, robot=load_robot(o.robot), initial=o.initial, bounds=o.bounds,
            test=o.test, holdout=o.holdout, seed=o.seed, require=o.require,
            on_images=None if (o.as_json or o.quiet) else _echo_images, method=o.method,
            fixed=fixed_names, runs=o.runs, iterations=o.iterations, loss=o.loss,
            loss_scale=o.loss_scale, threads=o.threads,
            progress=solve_progress(o.as_json or o.quiet))
        if o.save_data is not None and run.extracted is not None:
            run.extracted.save(o.save_data)
        path, report_path = _save(run.calibration, o.out, o.report, data=run.dataset,
                                  test=run.test, image_reports=run.reports)
    _paper_output(o, run.calibration, caught, path, report_path, run.notes, why, run.reports)


def _echo_images(reports: list) -> None:
    """One line per image pair of a paper-model session, before the solve."""
    for r in reports:
        typer.echo(str(r))


def _paper_output(o: _PaperRun, cal: Any, caught: list, path: Path,
                  report_path: Optional[Path], widened: list[str],
                  why: list[str], image_reports: list) -> None:
    """What hmlvs calibrate --model paper prints (text or --json)."""
    result, verdict = cal.solve, cal.judged
    summary = result.summary()
    warns = finish(caught, o.as_json, {**_summary(path, report_path, cal, image_reports),
                                       "notes": widened},
                   result.warnings, summary, quiet=True)
    if warns is None:
        exit_untrusted(verdict)
        return
    det, undet = result.determined_split()
    typer.echo(verdict.text())
    typer.echo(without_warning_lines(summary))
    for note in widened:
        typer.echo(f"note: {note}")
    typer.echo(rotation_text(result.params))
    typer.echo("held fixed: " + ("; ".join(why) if why else "nothing (--fixed none)"))
    typer.echo("determined by the data: " + (", ".join(det) or "none")
               + ("; NOT determined: " + ", ".join(undet)
                  + f" (see {GLOSSARY_URL}#flat-direction)" if undet else ""))
    _written(path, report_path, verdict, warns, o.quiet)


def _written(path: Path, report_path: Optional[Path], verdict: Any, warns: list,
             quiet: bool) -> None:
    """The end of calibrate's text output, either model: warnings, what was written, and
    exit 3 when the verdict is not trustworthy."""
    if not quiet:
        show_warnings(warns)
    typer.echo(f"calibration written to {path}"
               + ("" if verdict.trustworthy else " (marked not trustworthy)"))
    if report_path is not None:
        typer.echo(f"report written to {report_path}")
    exit_untrusted(verdict)
