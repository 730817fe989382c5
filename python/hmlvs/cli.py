"""The ``hmlvs`` command line."""

from __future__ import annotations

from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator, Optional

import typer

from ._io import Terminated, atomic_write, json_text, on_sigterm
from .calibration.options import LmOptions, PsoOptions
from .models.opencv import DISTORTION_NAMES

app = typer.Typer(
    name="hmlvs",
    help="Calibrate and use a hand-mounted laser-vision sensor.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode="markdown",  # help paragraphs reflow to the terminal's width
)


_DEBUG = False  # --debug: internal errors show their traceback


def _fault(e: OSError) -> str:
    """One line for an environment fault (paths, permissions, disk space): what and where,
    and what to do."""
    import errno

    what = {
        errno.ENOSPC: "the disk is full: free some space or write elsewhere",
        errno.EDQUOT: "the disk quota is exceeded: free some space or write elsewhere",
        errno.EACCES: "permission denied: choose a location you can write to (or read)",
        errno.EPERM: "operation not permitted: choose another location",
        errno.EROFS: "the file system is read-only: choose another location",
        errno.EISDIR: "is a folder: give a file name",
        errno.ENOTDIR: "a part of this path is a file, not a folder",
        errno.ENAMETOOLONG: "the file name is too long: choose a shorter one",
        errno.ENOENT: "no such file or folder",
    }.get(e.errno or 0, e.strerror or str(e))
    where = e.filename if e.filename is not None else ""
    return f"{where}: {what}" if where else what


def _error_lines(text: str) -> list[str]:
    # A message of several lines (e.g. one per rejected image pair) keeps its lines;
    # whitespace inside a line is collapsed.
    lines = [" ".join(line.split()) for line in text.splitlines()]
    return [line for line in lines if line] or [""]


def _fail(lines: list[str], code: int, as_json: bool) -> None:
    if as_json:
        typer.echo(json_text({"error": "\n".join(lines)}))
    typer.echo(f"error: {lines[0]}", err=True)
    for line in lines[1:]:
        typer.echo(f"  {line}", err=True)
    raise typer.Exit(code)


# What a command may raise on purpose: typer's own exits and parameter errors (through
# typer's public names: typer 0.28 and later carry their own click, older ones re-export
# click's classes, so either way these are the classes the command line raises).
_PASS_THROUGH = (typer.Exit, typer.Abort, typer.BadParameter, SystemExit)


def _interrupted(e: BaseException, what: str = "") -> "typer.Exit":
    """Ctrl-C (exit 130) or SIGTERM (exit 143, :class:`hmlvs._io.Terminated`), said on stderr;
    the exit to raise."""
    terminated = isinstance(e, Terminated)
    typer.echo(("terminated" if terminated else "interrupted") + what, err=True)
    return typer.Exit(143 if terminated else 130)


@contextmanager
def _guard(as_json: bool = False) -> Iterator[None]:
    """The command line's error policy. Exit 2: bad input or an environment fault (a path,
    a permission, disk space), one line naming the file, entry or option. Exit 1: an internal
    error, a short message (the traceback with --debug). Exit 130: Ctrl-C; exit 143: SIGTERM
    (every clean-up path of Ctrl-C runs for it too)."""
    try:
        yield
    except _PASS_THROUGH:
        raise
    except ValueError as e:
        _fail(_error_lines(str(e)), 2, as_json)
    except OSError as e:
        _fail([_fault(e)], 2, as_json)
    except KeyboardInterrupt as e:
        raise _interrupted(e) from None
    except Exception as e:
        if _DEBUG:
            raise
        _fail([f"internal error ({type(e).__name__}: {' '.join(str(e).split())}); this is a "
               "bug in hmlvs: run again with --debug for the traceback and report it"], 1,
              as_json)


# The simulated true sensor of `demo` and `simulate`: the paper's nominal values (Table 2)
# with the camera mounted a few degrees off the hand's axes, as a real mounting is. At the
# exact nominal (phi = 0) the ZYZ Euler angles sit on their gimbal lock and omega, varphi
# separately mean nothing (docs/glossary.md); a generic mounting gives a determined result.
MOUNTING_DEG = (1.0, 2.0, -1.0)  # omega, phi, varphi (deg)


def _truth(mounting_deg) -> "object":
    import math

    from .models.params import Parameters

    om, ph, va = (math.radians(float(a)) for a in mounting_deg)
    return Parameters.nominal().replace(omega=om, phi=ph, varphi=va)


GLOSSARY_URL = "docs/glossary.md"


_GLOSSARY_ANCHOR = {
    "flat-direction": "flat-direction", "too-few-points": "too-few-points",
    "pose-variety": "pose-variety", "gimbal-lock": "zyz-gimbal-lock",
    "at-bound": "at-a-bound", "diagnostics": "diagnostics", "data": "data-warning",
}


@contextmanager
def _collect_warnings() -> Iterator[list]:
    """Record every warning raised inside (instead of printing it with a source line)."""
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield caught


def _gather(caught: list, *texts: object) -> list[dict]:
    """Every data warning once: the recorded Python warnings, then the ``warning: ...`` lines
    and warning lists of results; each as {"kind", "message", "see"}."""
    from .diagnostics.identifiability import HmlvsDataWarning, warning_category

    messages: list[tuple[str, str]] = []
    for w in caught:
        if issubclass(w.category, (DeprecationWarning, PendingDeprecationWarning,
                                   ImportWarning, ResourceWarning)):
            continue  # for developers, hidden by Python's default filters too
        if issubclass(w.category, HmlvsDataWarning):
            messages.append((str(w.message), ""))
        else:
            messages.append((str(w.message), w.category.__name__))
    for t in texts:
        if t is None:
            continue
        if isinstance(t, str):
            messages += [(line[len("warning: "):], "") for line in t.splitlines()
                         if line.startswith("warning: ")]
        else:
            messages += [(str(m), "") for m in t]
    out, seen = [], set()
    for msg, other in messages:
        key = " ".join(msg.split())
        if key in seen:
            continue
        seen.add(key)
        kind = warning_category(msg).kind if not other else other
        anchor = _GLOSSARY_ANCHOR.get(kind)
        out.append({"kind": kind, "message": key,
                    "see": f"{GLOSSARY_URL}#{anchor}" if anchor else None})
    return out


def _without_warning_lines(text: str) -> str:
    """A result summary without its ``warning:`` lines (they are shown once, separately)."""
    return "\n".join(line for line in text.splitlines() if not line.startswith("warning: "))


def _show_warnings(items: list[dict]) -> None:
    """Each warning once, on stderr, formatted with rich, without a source-code line."""
    if not items:
        return
    from rich.console import Console
    from rich.markup import escape

    console = Console(stderr=True, highlight=False, soft_wrap=True)
    for w in items:
        see = f" [dim](see {w['see']})[/dim]" if w["see"] else ""
        console.print(f"[bold yellow]warning[/bold yellow] [yellow]{escape(w['kind'])}[/yellow]: "
                      f"{escape(w['message'])}{see}")


def _resolve_fixed(fixed: list[str], free: list[str]) -> tuple[tuple[str, ...], list[str]]:
    """The parameters to hold fixed: the default gauge plus --fixed, minus --free;
    ``--fixed none`` frees everything. Also one line per fixed parameter saying why."""
    from .models.params import DEFAULT_FIXED, FIXED_WHY, NAMES

    names = [f for f in fixed]
    if [n.lower() for n in names] == ["none"]:
        chosen: list[str] = []
    else:
        chosen = list(DEFAULT_FIXED) + [n for n in names if n not in DEFAULT_FIXED]
    for n in chosen + list(free):
        if n not in NAMES:
            raise ValueError(f"unknown parameter {n!r} in --fixed/--free; the parameters are "
                             + ", ".join(NAMES))
    chosen = [n for n in chosen if n not in free]
    why = [f"{n}: {FIXED_WHY.get(n, 'held fixed on request (--fixed)')}" for n in chosen]
    return tuple(chosen), why


def _version_callback(value: bool) -> None:
    if value:
        from . import __version__

        typer.echo(f"hmlvs {__version__}")
        raise typer.Exit()


@app.callback()
def _main(
    version: bool = typer.Option(False, "--version", callback=_version_callback,
                                 is_eager=True, help="Print the version and exit."),
    debug: bool = typer.Option(False, "--debug", help="Show the traceback of an internal "
                               "error (a bug), instead of a one-line message."),
) -> None:
    """Calibrate and use a hand-mounted laser-vision sensor.

    Units: mm and pixels; angles on the command line are in degrees (design --theta),
    angles in results are in radians. Terms used in messages: docs/glossary.md.
    """
    global _DEBUG
    _DEBUG = debug


def _is_manifest(path: Path) -> bool:
    """An image manifest: a folder, ``manifest.json``/``.yaml``, or a JSON/YAML file of any
    name whose format is ``hmlvs-images`` (wherever the file puts its ``format`` key)."""
    if path.is_dir() or path.name in ("manifest.json", "manifest.yaml", "manifest.yml"):
        return True
    if path.suffix.lower() not in (".json", ".yaml", ".yml") or not path.is_file():
        return False
    try:
        with open(path, "rb") as fh:
            head = fh.read(4096)
            if b"hmlvs-images" in head:
                return True
            if b"hmlvs-dataset" in head or b"hmlvs-images" not in fh.read():
                return False
    except OSError:
        return False
    from ._io import read_document

    try:
        doc = read_document(path, "manifest")
    except ValueError:
        return False
    return isinstance(doc, dict) and doc.get("format") == "hmlvs-images"


def _solve_progress(quiet: bool):
    """Progress for solves: a bar, or with --json a silent callback. Either way the solver
    calls back into Python periodically, which is where Ctrl-C is noticed."""
    return (lambda *_: True) if quiet else True


def _bar(description: str, quiet: bool):
    """A rich progress bar as a callback (done, total); None when quiet (--json)."""
    if quiet:
        return None
    from rich.progress import Progress

    bar = Progress(transient=True)
    state: dict = {}

    def update(done: int, total: int, *_: object) -> bool:
        if "task" not in state:
            bar.start()
            state["task"] = bar.add_task(description, total=total)
        bar.update(state["task"], completed=done)
        if done >= total:
            bar.stop()
        return True

    return update


def _echo_json(obj: object) -> None:
    """Valid JSON on stdout: a figure that is not available (NaN, inf) is ``null``."""
    typer.echo(json_text(obj))


@app.command()
def simulate(
    out: Path = typer.Argument(..., help="Data set file to write (.npz or .json)."),
    poses: int = typer.Option(30, help="Number of robot poses in the session."),
    pixel_noise: float = typer.Option(
        0.0, help="Noise added to the stripe pixels of the data set, standard deviation (px). "
        "It does not apply to rendered images (--images): they carry --image-noise instead, "
        "and the pixels extracted from them have the extractor's own error."),
    point_noise: float = typer.Option(0.0, help="Reference-point noise, std (mm)."),
    images: Optional[Path] = typer.Option(
        None, help="Also render laser on/off images of every pose into this folder, with a "
        "manifest.json pairing each image pair with its joint readings."),
    image_noise: float = typer.Option(
        0.0, help="Sensor noise of the rendered images, standard deviation (grey levels of "
        "0-255; default 0: noise-free images)."),
    mounting: tuple[float, float, float] = typer.Option(
        MOUNTING_DEG, help="The true hand-eye rotation as ZYZ Euler angles omega phi varphi "
        "(deg); the rest of the true sensor is the paper's nominal (Table 2)."),
    seed: int = typer.Option(0, help="Random seed."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bar and no warnings "
                               "on the terminal (--json collects them)."),
    as_json: bool = typer.Option(False, "--json", help="Print a JSON summary, warnings included."),
) -> None:
    """Simulate a checkerboard calibration session (SCORBOT ER-VII, paper set-up).

    Example: hmlvs simulate session.npz --poses 60 --images session
    """
    from . import sim
    from .sim.render import RenderOptions

    with _guard(as_json), _collect_warnings() as caught:
        # every refusal before anything is written
        if out.suffix not in (".npz", ".json"):  # as Dataset.save, before any image is made
            raise ValueError(f"{out}: data sets are saved as .npz or .json, not "
                             f"{out.suffix or 'a file without a suffix'}")
        if images is not None and images.is_dir() and any(images.iterdir()):
            raise ValueError(f"--images {images}: the folder exists and is not empty; its "
                             "manifest and images would be replaced: give a new or empty folder")
        s = sim.session(_truth(mounting), num_poses=poses, pixel_noise=pixel_noise,
                        point_noise=point_noise, seed=seed)
        manifest = None
        new_folder = images is not None and not images.exists()
        if images is not None:  # the images first: an interrupted run leaves neither output
            manifest = sim.render_session(
                s, images, options=RenderOptions(noise=image_noise), seed=seed,
                progress=_bar(f"rendering {poses} image pairs", as_json or quiet)).manifest
        try:
            s.dataset.save(out)
        except BaseException:
            if new_folder and images is not None:
                import shutil

                shutil.rmtree(images, ignore_errors=True)
            raise
    warns = _gather(caught)
    if as_json:
        _echo_json({"file": str(out), "points": len(s.dataset), "poses": s.dataset.num_poses,
                    "manifest": None if manifest is None else str(manifest),
                    "warnings": warns})
    else:
        typer.echo(s.summary())
        if not quiet:
            _show_warnings(warns)
        typer.echo(f"written to {out}" + (f" and {manifest}" if manifest else ""))


def _rotation_vector(params) -> "list[float]":
    """hand_from_camera's rotation as a rotation vector (axis times angle, rad)."""
    from .geometry.transforms import rotation_to_vector
    from .models.paper import hand_from_camera

    return [float(x) for x in rotation_to_vector(hand_from_camera(params)[:3, :3])]


def _rotation_text(params, truth=None) -> str:
    """The hand-eye rotation in words: a rotation vector, the ZYZ Euler angles as the
    paper's view."""
    rv = _rotation_vector(params)
    text = ("hand-eye rotation (hand_from_camera) as a rotation vector (axis x angle, rad): "
            f"[{rv[0]:+.5f}, {rv[1]:+.5f}, {rv[2]:+.5f}], {sum(x * x for x in rv) ** 0.5:.5f} "
            "rad about its axis")
    if truth is not None:
        tv = _rotation_vector(truth)
        text += f"; true [{tv[0]:+.5f}, {tv[1]:+.5f}, {tv[2]:+.5f}]"
    return text + ("\n  (omega, phi, varphi in the table are the same rotation as the paper's "
                   "ZYZ Euler angles; near phi = 0 they are not unique, see "
                   f"{GLOSSARY_URL}#zyz-gimbal-lock)")


def _determined(result) -> tuple[list[str], list[str]]:
    """Free parameters the data determine, and those they do not (from the uncertainty)."""
    unc = result.uncertainty
    free = list(result.free)
    if unc is None:
        return [], free
    return ([n for n in free if unc.determined.get(n, False)],
            [n for n in free if not unc.determined.get(n, False)])


def _demo_verdict(result, truth, fixed_why: list[str]) -> tuple[str, dict]:
    """The demo's summary in words, and the same as JSON."""
    det, undet = _determined(result)
    unc = result.uncertainty
    lines = ["", "What the numbers mean:",
             f"- fit RMS {result.fit_rms:.3g} mm: the 3D distance between the reference points "
             "and the points the calibrated model computes from their stripe pixels, on the "
             "points used for fitting;",
             f"- held-out RMS {result.test_rms:.3g} mm: the same on poses the calibration never "
             "saw, the accuracy to expect when measuring;"]
    lines.append("- held fixed (given, not estimated): " + "; ".join(fixed_why))
    worst = []
    if unc is not None:
        for n in det:
            std = unc.std.get(n, 0.0)
            diff = abs(getattr(result.params, n) - getattr(truth, n))
            if std > 0:
                worst.append((diff / std, n))
    if undet:
        lines.append(f"- NOT determined by the data: {', '.join(undet)} (their values are one of "
                     f"many that fit equally well; see {GLOSSARY_URL}#flat-direction)")
    else:
        lines.append(f"- determined by the data: all {len(det)} free parameters "
                     f"({', '.join(det)}); each lies within "
                     f"{max(worst)[0]:.1f} standard deviations of the truth" if worst else
                     f"- determined by the data: all {len(det)} free parameters")
    return "\n".join(lines), {"determined": det, "not_determined": undet,
                               "max_error_in_std": max(worst)[0] if worst else None}


@app.command()
def demo(
    seed: int = typer.Option(0, help="Random seed."),
    poses: int = typer.Option(60, help="Number of robot poses (about 1.8 points each; half "
                              "fit, half held out)."),
    pixel_noise: float = typer.Option(0.1, help="Pixel noise, standard deviation (px)."),
    out: Path = typer.Option(Path("demo-out"), help="Folder for the calibration file."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bar and no warnings "
                               "on the terminal (use --json to get them)."),
    as_json: bool = typer.Option(False, "--json", help="Print a JSON summary, warnings included."),
) -> None:
    """Simulate a SCORBOT ER-VII session, calibrate it (PSO + LM), compare with the truth.

    The true sensor is the paper's nominal one (Table 2) with the camera mounted slightly
    rotated (omega 1, phi 2, varphi -1 deg). Su, Sv, Cu and Cv are held at their
    datasheet values, as docs/model.md says the laser data need; the other ten are estimated.

    Example: hmlvs demo --seed 1 --poses 60
    """
    from . import sim
    from .calibration.solvers import calibrate as run_calibration
    from .data.calibration_file import Calibration
    truth = _truth(MOUNTING_DEG)
    fixed, why = _resolve_fixed([], [])
    with _guard(as_json), _collect_warnings() as caught:
        session = sim.session(truth, num_poses=poses, pixel_noise=pixel_noise, seed=seed)
        fit, test = session.dataset.split(0.5, seed=seed, by_pose=True)
        if not as_json:
            typer.echo(session.summary())
            typer.echo(f"fit: {len(fit)} points from {fit.num_poses} poses; held out: "
                       f"{len(test)} points from {test.num_poses} poses\n")
        result = run_calibration(fit, test=test, seed=seed, fixed=fixed,
                                 progress=_solve_progress(as_json or quiet))
        path = Calibration.from_result(result, fit, robot=session.robot).save(
            out / "calibration.yaml")
    summary = result.summary(session.truth)
    warns = _gather(caught, result.warnings, summary)
    verdict, verdict_json = _demo_verdict(result, session.truth, why)
    if as_json:
        _echo_json({"points": len(session.dataset), "poses": session.dataset.num_poses,
                    "fit_rms_mm": result.fit_rms, "test_rms_mm": result.test_rms,
                    "seconds": result.seconds, "calibration": str(path),
                    "fixed": list(result.fixed), **verdict_json,
                    "rotation_vector_rad": _rotation_vector(result.params),
                    "true_rotation_vector_rad": _rotation_vector(session.truth),
                    "warnings": warns})
        return
    typer.echo(_without_warning_lines(summary))
    typer.echo(_rotation_text(result.params, session.truth))
    typer.echo(verdict)
    if not quiet:
        _show_warnings(warns)
    typer.echo(f"\ncalibration written to {path}")


@contextmanager
def _outputs(*targets: Path) -> Iterator[list]:
    """Several output files as one: the block appends each file it writes; if it fails, the
    files it wrote that did not exist before are removed (a calibration is not left without
    the report asked for, nor a report without its calibration)."""
    import os

    existed = {Path(t) for t in targets if Path(t).exists()}
    made: list = []
    try:
        yield made
    except BaseException:
        for p in made:
            if Path(p) not in existed:  # through a link: the file written, not the link
                Path(os.path.realpath(p)).unlink(missing_ok=True)
        raise


def _check_suffix(option: str, path: Optional[Path], allowed: tuple[str, ...],
                  what: str) -> None:
    """Refuse an output whose name does not say the kind of file it will be."""
    if path is not None and path.suffix.lower() not in allowed:
        raise ValueError(f"{option} {path}: {what} is written as " + " or ".join(allowed))


def _inputs_of(data: Path) -> list[Path]:
    """The files a data argument stands for: an image session's manifest and the files it
    names, or the file itself."""
    from .guard import session_files

    return session_files(data) if _is_manifest(data) else [data]


def _resolve_model(model: str, data: Path) -> str:
    """The sensor model to calibrate: as asked, or (auto) opencv for an image manifest without
    a measured board pose, paper otherwise."""
    if model not in ("auto", "opencv", "paper"):
        raise ValueError(f"--model must be opencv, paper or auto, got {model!r}")
    if model != "auto":
        if model == "opencv" and not _is_manifest(data):
            raise ValueError(f"{data}: the opencv model is calibrated from images (a manifest); "
                             "a data set of calibration points is for --model paper")
        return model
    if not _is_manifest(data):
        return "paper"
    from .data.manifest import read_manifest

    _, doc, _ = read_manifest(data)
    board = doc.get("board")
    return "paper" if isinstance(board, dict) and "origin" in board else "opencv"


def _paper_only_options(**given: bool) -> None:
    """Refuse options that the opencv model does not use (an option that does nothing would
    be an error the user never hears of)."""
    names = [k.replace("_", "-") for k, v in given.items() if v]
    if names:
        raise ValueError("--" + ", --".join(names) + (" applies" if len(names) == 1 else
                                                        " apply") +
                         " to the paper model only (--model paper); the opencv model takes "
                         "--distortion, --holdout, --initial, --robot, --report and --seed")


def _held_camera(initial: Optional[Path]) -> Any:
    """The sensor of an opencv-model --initial calibration (its camera and laser plane are
    held), or None."""
    if initial is None:
        return None
    from .data.calibration_file import load_calibration

    cal = load_calibration(initial)
    if cal.model != "opencv" or cal.sensor is None:
        raise ValueError(f"{initial}: --initial with the opencv model holds the camera and "
                         "laser plane of an opencv-model calibration (e.g. a bench session's); "
                         f"this is a {cal.model}-model calibration")
    return cal.sensor


def _calibrate_opencv(data: Path, out: Path, holdout: float, seed: int, robot: Optional[Path],
                      distortion: str, report: Optional[Path], quiet: bool,
                      as_json: bool, initial: Optional[Path] = None,
                      require: Optional[float] = None) -> None:
    """hmlvs calibrate --model opencv: images -> views -> joint calibration -> verdict ->
    file. With ``initial`` (an opencv calibration, e.g. of a bench session) its camera and
    laser plane are held and the hand-eye transform and board pose calibrated. Exits 3 when
    the verdict is not trustworthy (the file is still written, marked so)."""
    from .calibration.joint import calibrate_joint
    from .data.calibration_file import Calibration
    from .diagnostics.verdict import judge_joint, require_check
    from .image.views import views_from_images

    with _guard(as_json), _collect_warnings() as caught:
        arm = _load_robot(robot)
        camera = _held_camera(initial)
        terms = tuple(t.strip() for t in distortion.split(",") if t.strip())
        views, board, size, board_pose, reports = views_from_images(data, robot=arm)
        if not (as_json or quiet):
            for r in reports:
                typer.echo(f"{r.id}: rejected: {r.reason}" if not r.ok else
                           f"{r.id}: {r.corners} corners, stripe in "
                           f"{r.stripe.get('FOUND', 0)} scan lines" if r.corners else
                           f"{r.id}: laser only (no board seen), stripe in "
                           f"{r.stripe.get('FOUND', 0)} scan lines")
        if not views:
            raise ValueError("no view has both the whole board and a stripe:\n" + "\n".join(
                f"  {r.id}: {r.reason}" for r in reports))
        test_views = []
        if holdout > 0:
            if not 0 < holdout < 1:
                raise ValueError(f"--holdout must be a fraction in (0, 1), got {holdout}")
            import numpy as np

            rng = np.random.default_rng(seed)
            n_test = max(1, int(round(holdout * len(views))))
            pick = set(rng.choice(len(views), n_test, replace=False).tolist())
            test_views = [v for i, v in enumerate(views) if i in pick]
            views = [v for i, v in enumerate(views) if i not in pick]
        result = calibrate_joint(views, board, size, distortion=terms,
                                 base_from_board=board_pose, test=test_views or None,
                                 camera=camera)
        verdict = require_check(judge_joint(
            result, views, board, options={"distortion": terms, "base_from_board": board_pose,
                                           "camera": camera}), require)
        report_path = None
        with _outputs(out) as made:
            blur = next((r.blur_var for r in reports if r.ok), None)
            cal = Calibration.from_joint(result, robot=arm, blur_var=blur)
            cal.verdict = verdict.to_dict()
            path = cal.save(out)
            made.append(path)
            if report is not None:
                from .report.joint import write_joint_report

                report_path = write_joint_report(result, report, image_reports=reports,
                                                 verdict=verdict)
    warns = _gather(caught, result.warnings)
    if as_json:
        s = result.sensor
        _echo_json({"calibration": str(path), "model": "opencv", "mode": result.mode,
                    "verdict": verdict.to_dict(),
                    "report": None if report_path is None else str(report_path),
                    "camera_matrix": s.camera_matrix.tolist(),
                    "dist_coeffs": s.dist_coeffs.tolist(), "image_size": list(s.image_size),
                    "laser_plane": s.laser_plane.tolist(),
                    "hand_from_camera": s.hand_from_camera.tolist(),
                    "base_from_board": None if s.base_from_board is None
                    else s.base_from_board.tolist(),
                    "std": result.std, "corner_rms_px": result.corner_rms_px,
                    "laser_rms_mm": result.laser_rms_mm, "test_rms_mm": result.test_rms_mm,
                    "determined": result.determined, "rank": result.rank,
                    "unknowns": result.num_unknowns, "dropped": result.dropped,
                    "flipped": result.flipped, "termination": result.termination,
                    "iterations": result.iterations, "seconds": result.seconds,
                    "warnings": warns,
                    "images": [{"id": r.id, "ok": r.ok, "reason": r.reason,
                                "corners": r.corners} for r in reports]})
        _exit_untrusted(verdict)
        return
    typer.echo(verdict.text())
    typer.echo(result.summary())
    if not quiet:
        _show_warnings(warns)
    typer.echo(f"calibration written to {path}"
               + ("" if verdict.trustworthy else " (marked not trustworthy)"))
    if report_path is not None:
        typer.echo(f"report written to {report_path}")
    _exit_untrusted(verdict)


#: the exit status of a calibration whose verdict is not trustworthy (its file is written)
EXIT_UNTRUSTED = 3


def _exit_untrusted(verdict: Any) -> None:
    if not verdict.trustworthy:
        raise typer.Exit(EXIT_UNTRUSTED)


_ROBOT_OPTION = typer.Option(
    None, "--robot", help="Robot description (YAML/JSON, what hmlvs.Robot.to_dict writes) "
    "for joint readings; default: the manifest's robot, else SCORBOT ER-VII.")


def _load_robot(path: Optional[Path]):
    """The --robot file's Robot, or None."""
    if path is None:
        return None
    from .data.robot_file import load_robot

    return load_robot(path)


@app.command()
def calibrate(
    data: Path = typer.Argument(..., help="Calibration data set (.npz or .json), or an image "
                                "manifest (a folder with manifest.json, or the file)."),
    out: Path = typer.Option(Path("calibration.yaml"), "--out", "-o",
                             help="Calibration file to write (.yaml or .json)."),
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
    robot: Optional[Path] = _ROBOT_OPTION,
    model: str = typer.Option(
        "auto", help="Sensor model: opencv (OpenCV intrinsics and distortion, a 3-DoF laser "
        "plane, any hand-eye rotation; calibrated from the board's corners and the stripe "
        "together, no guess needed) or paper (the paper's 14 parameters, from calibration "
        "points). auto: opencv for images whose manifest gives no board pose, else paper."),
    distortion: str = typer.Option(
        ",".join(DISTORTION_NAMES), help="opencv model: the distortion terms to estimate (the "
        "others stay 0), e.g. k1,k2."),
    initial: Optional[Path] = typer.Option(
        None, help="opencv model: a calibration whose camera and laser plane are held (e.g. a "
        "bench session's), so that only the hand-eye transform and the board pose are "
        "calibrated. paper model: initial guess, a calibration file of either model (an opencv "
        "one is converted) or a YAML/JSON mapping of parameter names to values "
        "(docs/file-formats.md)."),
    bounds: Optional[Path] = typer.Option(
        None, help="paper model: search bounds, a YAML/JSON mapping of parameter names to "
        "[lower, upper] or {plus_minus: h} around the initial guess; others keep Table 2."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bar, no per-image "
                               "lines and no warnings on the terminal (--json collects them)."),
    as_json: bool = typer.Option(False, "--json", help="Print a JSON summary, warnings included."),
    require: Optional[float] = typer.Option(
        None, "--require", help="Also call the calibration untrustworthy (exit 3) when its "
        "predicted 95th-percentile 3D uncertainty exceeds this many mm."),
) -> None:
    """Calibrate the sensor from laser on/off images (or, paper model, a calibration data set).

    Every calibration gets a verdict, printed first: trustworthy or not, from named checks.
    The exit status is 3 when it is not (the calibration file is still written, marked
    "trustworthy: false" with the reasons).

    --model opencv (the default for images without a measured board pose) estimates the
    camera, the laser plane, the hand-eye transform and the board's pose from the images and
    robot poses alone.

    Su, Sv, Cu and Cv are held at their initial (datasheet) values by default: laser points
    alone cannot determine them (docs/model.md; docs/glossary.md, "scale gauge", "flat direction").

    Example: hmlvs calibrate session.npz --holdout 0.3 --out calibration.yaml --report report.html
    """
    from .calibration.solvers import calibrate as run_calibration
    from .data.calibration_file import Calibration
    from .data.dataset import Dataset

    image_reports = []
    with _guard(as_json):
        import math

        if not (math.isfinite(holdout) and 0 <= holdout < 1):
            raise ValueError(f"--holdout must be a fraction in [0, 1), got {holdout}")
        if mode not in ("corners", "homography"):
            raise ValueError(f"--mode must be corners or homography, got {mode!r}")
        from .guard import refuse_overwrite

        refuse_overwrite([*_inputs_of(data), test, initial, bounds, robot],
                         [("--out", out), ("--report", report), ("--save-data", save_data)])
        # every output's kind checked before the first is written
        _check_suffix("--out", out, (".yaml", ".yml", ".json"), "a calibration file")
        _check_suffix("--report", report, (".html", ".htm"), "an HTML report")
        _check_suffix("--save-data", save_data, (".npz", ".json"), "a data set")
        chosen = _resolve_model(model, data)
        if chosen == "paper" and require is not None:
            raise ValueError("--require judges the predicted 3D uncertainty, which only the "
                             "opencv model computes so far; use --model opencv")
        if chosen == "opencv":
            _paper_only_options(method=method != "pso+lm", fixed=bool(fixed), free=bool(free),
                                runs=runs != 1,
                                iterations=iterations != PsoOptions.iterations,
                                loss=loss is not None,
                                loss_scale=loss_scale != LmOptions.loss_scale,
                                threads=threads is not None, bounds=bounds is not None,
                                test=test is not None, save_data=save_data is not None,
                                mode=mode != "corners")
    if chosen == "opencv":
        _calibrate_opencv(data, out, holdout, seed, robot, distortion, report, quiet, as_json,
                          initial, require)
        return
    with _guard(as_json), _collect_warnings() as caught:
        fixed_names, why = _resolve_fixed(fixed, free)
        arm = _load_robot(robot)
        guess = bounds_obj = board_pose = None
        widened: list[str] = []
        if initial is not None:
            from .data.guess import initial_board_pose, read_initial

            guess = read_initial(initial)
            board_pose = initial_board_pose(initial)
        if _is_manifest(data):
            from .image.session import dataset_from_images

            # the corners are numbered with the given initial guess, else the nominal values;
            # a board the manifest does not place sits where an opencv initial guess put it
            ds, image_reports = dataset_from_images(data, mode=mode, robot=arm, params=guess,
                                                    base_from_board=board_pose)
            if not (as_json or quiet):
                for r in image_reports:
                    typer.echo(str(r))
            if save_data is not None:
                ds.save(save_data)
        else:
            ds = Dataset.load(data)
        test_ds = Dataset.load(test) if test is not None else None
        if test_ds is None and holdout > 0:
            ds, test_ds = ds.split(1.0 - holdout, seed=seed, by_pose=True)
        if bounds is not None:
            from .data.guess import read_bounds
            from .models.params import Parameters

            bounds_obj = read_bounds(bounds, guess or Parameters.nominal())
        elif guess is not None:
            from .data.guess import bounds_with

            bounds_obj, widened = bounds_with(guess)
        result = run_calibration(ds, method=method, test=test_ds, fixed=fixed_names, runs=runs,
                                 initial=guess, bounds=bounds_obj,
                                 iterations=iterations, loss=loss, loss_scale=loss_scale,
                                 seed=seed, threads=threads,
                                 progress=_solve_progress(as_json or quiet))
        from .diagnostics.verdict import judge_paper

        verdict = judge_paper(result)
        report_path = None
        with _outputs(out) as made:
            cal = Calibration.from_result(result, ds, robot=arm)
            cal.verdict = verdict.to_dict()
            path = cal.save(out)
            made.append(path)
            if report is not None:
                from .report.html import write_report

                report_path = write_report(result, ds, report, test=test_ds,
                                           image_reports=image_reports, verdict=verdict)
    summary = result.summary()
    warns = _gather(caught, result.warnings, summary)
    det, undet = _determined(result)
    if as_json:
        _echo_json({"calibration": str(path), "report": None if report_path is None
                    else str(report_path), "verdict": verdict.to_dict(),
                    "fit_rms_mm": result.fit_rms,
                    "test_rms_mm": result.test_rms, "method": method,
                    "parameters": result.params.to_dict(), "fixed": list(result.fixed),
                    "determined": det, "not_determined": undet,
                    "rotation_vector_rad": _rotation_vector(result.params),
                    "termination": result.termination, "seconds": result.seconds,
                    "warnings": warns, "notes": widened,
                    "images": [{"id": r.id, "ok": r.ok, "reason": r.reason,
                                "points": r.points, "rejected": dict(r.rejected)}
                               for r in image_reports]})
        _exit_untrusted(verdict)
        return
    typer.echo(verdict.text())
    typer.echo(_without_warning_lines(summary))
    for note in widened:
        typer.echo(f"note: {note}")
    typer.echo(_rotation_text(result.params))
    typer.echo("held fixed: " + ("; ".join(why) if why else "nothing (--fixed none)"))
    typer.echo("determined by the data: " + (", ".join(det) or "none")
               + ("; NOT determined: " + ", ".join(undet)
                  + f" (see {GLOSSARY_URL}#flat-direction)" if undet else ""))
    if not quiet:
        _show_warnings(warns)
    typer.echo(f"calibration written to {path}"
               + ("" if verdict.trustworthy else " (marked not trustworthy)"))
    if report_path is not None:
        typer.echo(f"report written to {report_path}")
    _exit_untrusted(verdict)


@app.command()
def design(
    f: float = typer.Option(8.0, "--f", help="Effective focal length (mm)."),
    pitch: float = typer.Option(0.0074, help="Pixel pitch (mm/px), square pixels."),
    width: int = typer.Option(640, help="Image width (px)."),
    height: int = typer.Option(480, help="Image height (px)."),
    baseline: float = typer.Option(100.0, "--H", "--baseline", help="Laser baseline H (mm)."),
    theta: float = typer.Option(25.0, help="Laser projection angle (deg; like every angle "
                                "given on the command line; results are in rad)."),
    k: float = typer.Option(0.0, help="Radial distortion k (1/mm^2), division model."),
    true_h: Optional[float] = typer.Option(
        None, "--true-H", help="The real H for the Fig. 6 error (mm); default H - 1."),
    true_theta: Optional[float] = typer.Option(
        None, "--true-theta", help="The real theta for the Fig. 6 error (deg); default "
        "theta - 2.5."),
    out: Optional[Path] = typer.Option(
        None, "--out", help="Folder for the PNG plots and design.md (a Markdown summary)."),
    as_json: bool = typer.Option(False, "--json", help="Print a JSON summary."),
) -> None:
    """Sensor design analysis: measurement ranges, resolution, error from a wrong H or theta.

    Example: hmlvs design --H 100 --theta 25 --out design-out
    """
    import math

    from .paper import design as dsg

    try:
        sensor = dsg.Sensor.make(f=f, pixel_pitch=pitch, image_size=(width, height), H=baseline,
                                 theta=math.radians(theta), k=k)
        report = dsg.analyze(sensor=sensor)
        errors = [
            dsg.error_from_wrong(sensor=sensor, H_true=baseline - 1.0 if true_h is None
                                 else true_h),
            dsg.error_from_wrong(sensor=sensor, theta_true=math.radians(
                theta - 2.5 if true_theta is None else true_theta)),
        ]
        files = []
        if out is not None:
            from contextlib import nullcontext

            from rich.console import Console

            from ._io import atomic_folder

            status = nullcontext() if as_json else Console(stderr=True).status(
                f"writing the design plots to {out} (about 10-30 s)")
            # the plots and design.md as one: a run stopped while writing leaves none of them
            with status, atomic_folder(out, last=("design.md",)) as tmp:
                plots = dsg.plot(report, tmp, errors=errors)
                with atomic_write(tmp / "design.md") as fh:
                    fh.write(report.markdown(errors=errors, files=plots))
            files = [out / p.name for p in plots] + [out / "design.md"]
            if not as_json:
                typer.echo(f"plots written to {out}", err=True)
    except ValueError as e:
        typer.echo(f"error: {' '.join(str(e).split())}", err=True)
        raise typer.Exit(2) from None
    except KeyboardInterrupt as e:
        raise _interrupted(e) from None
    if as_json:
        summary = report.to_dict()
        summary["errors"] = [e.to_dict() for e in errors]
        summary["files"] = [str(p) for p in files]
        _echo_json(summary)
    else:
        typer.echo(str(report))
        for e in errors:
            typer.echo(str(e))
        if files:
            typer.echo(f"written to {out}: " + ", ".join(p.name for p in files))


@app.command()
def report(
    calibration: Path = typer.Argument(..., help="Calibration file (.yaml or .json)."),
    data: Path = typer.Argument(..., help="Data set to evaluate on (.npz or .json), or an "
                                "image manifest (a folder with manifest.json, or the file)."),
    test: Optional[Path] = typer.Option(None, help="Held-out data set."),
    out: Path = typer.Option(Path("report.html"), "--out", "-o", help="HTML file to write."),
    mode: str = typer.Option("corners", help="Calibration points from images: corners or "
                             "homography (as for calibrate)."),
    robot: Optional[Path] = _ROBOT_OPTION,
    as_json: bool = typer.Option(False, "--json", help="Print a JSON summary."),
) -> None:
    """Write a self-contained HTML report for a calibration file on a data set or images.

    A paper-model calibration is evaluated on calibration points (a data set, or those its
    images give); an opencv-model one on an image session: its camera, laser plane and
    hand-eye transform held, the board's pose estimated, its verdict shown first.

    Example: hmlvs report calibration.yaml session.npz --out report.html
    """
    from .calibration.solvers import evaluate
    from .data.calibration_file import Calibration
    from .data.dataset import Dataset
    from .report.html import write_report

    with _guard(as_json), _collect_warnings() as caught:
        from .guard import refuse_overwrite

        refuse_overwrite([calibration, *_inputs_of(data), test, robot], [("--out", out)])
        cal = Calibration.load(calibration)
        if cal.model == "opencv":
            if test is not None:
                raise ValueError("--test takes a data set of calibration points, which only "
                                 "paper-model calibrations use; this calibration is opencv")
            path, ev = _report_opencv(cal, data, out, robot)
    if cal.model == "opencv":
        if as_json:
            _echo_json({"report": str(path), "corner_rms_px": ev.corner_rms_px,
                        "laser_rms_mm": ev.laser_rms_mm, "views": len(ev.per_view)})
            return
        _show_warnings(_gather(caught))
        typer.echo(f"on {data.name}: corners {ev.corner_rms_px:.4g} px RMS, laser "
                   f"{ev.laser_rms_mm:.4g} mm RMS over {len(ev.per_view)} views (camera, "
                   "laser plane and hand-eye held; the board's pose estimated)")
        typer.echo(f"report written to {path}")
        return
    with _guard(as_json), _collect_warnings() as caught:
        image_reports = None
        if _is_manifest(data):
            from .image.session import dataset_from_images

            ds, image_reports = dataset_from_images(data, mode=mode, robot=_load_robot(robot))
        else:
            ds = Dataset.load(data)
        test_ds = Dataset.load(test) if test is not None else None
        if cal.params is None:
            raise ValueError(f"{calibration}: a calibration of the {cal.model} model has no "
                             "paper parameters to report on")
        result = evaluate(cal.params, ds, test_ds, method=cal.method or "loaded",
                          fixed=cal.fixed)
        path = write_report(result, ds, out, test=test_ds, std=cal.std,
                            image_reports=image_reports)
    if not as_json:
        _show_warnings(_gather(caught))
    if as_json:
        _echo_json({"report": str(path), "fit_rms_mm": result.fit_rms,
                    "test_rms_mm": result.test_rms})
        return
    typer.echo(f"RMS on {data.name}: {result.fit_rms:.4g} mm over {len(ds)} points")
    if result.test_rms is not None:
        typer.echo(f"RMS on {test.name}: {result.test_rms:.4g} mm over {len(test_ds)} points")
    typer.echo(f"report written to {path}")


def _report_opencv(cal: Any, data: Path, out: Path, robot: Optional[Path]) -> tuple[Path, Any]:
    """hmlvs report for an opencv-model calibration: the calibration on the session's images
    (camera, laser plane and hand-eye held; the board's pose estimated), its verdict first."""
    from .calibration.joint import evaluate_sensor
    from .diagnostics.verdict import Verdict
    from .image.views import views_from_images
    from .report.joint import write_joint_report

    if not _is_manifest(data):
        raise ValueError(f"{data}: an opencv-model calibration is reported on an image session "
                         "(a folder with manifest.json/yaml, or the manifest file)")
    views, board, size, _, reports = views_from_images(data, robot=_load_robot(robot))
    if not views:
        raise ValueError(f"{data}: no view has a detected board and a stripe")
    result = evaluate_sensor(cal.sensor, views, board, size, std=cal.std)
    verdict = Verdict.from_dict(cal.verdict) if cal.verdict else None
    return write_joint_report(result, out, image_reports=reports, verdict=verdict), result


@app.command()
def measure(
    calibration: Path = typer.Argument(..., help="Calibration file (.yaml or .json)."),
    source: Path = typer.Argument(..., help="A data set (.npz/.json) of stripe pixels and poses, "
                                  "or an image manifest (folder or manifest.json)."),
    out: Path = typer.Option(Path("cloud.ply"), "--out", "-o",
                             help="Point cloud to write (.ply or .csv)."),
    robot: Optional[Path] = _ROBOT_OPTION,
    as_json: bool = typer.Option(False, "--json", help="Print a JSON summary."),
    accept_untrusted: bool = typer.Option(
        False, "--accept-untrusted", help="Measure even with a calibration whose verdict "
        "says not to trust it."),
) -> None:
    """Measure 3D points in the robot base frame with a calibrated sensor.

    A calibration marked not trustworthy (its verdict) is refused unless --accept-untrusted.

    Example: hmlvs measure calibration.yaml scan/ --out cloud.ply
    """
    import numpy as np

    from .data.calibration_file import Calibration
    from .data.dataset import Dataset
    from .measurement.measure import measure as measure_points
    from .measurement.measure import measure_images_to

    with _guard(as_json), _collect_warnings() as caught:
        from .guard import refuse_overwrite

        refuse_overwrite([calibration, *_inputs_of(source), robot], [("--out", out)])
        cal = Calibration.load(calibration)
        if cal.trustworthy is False and not accept_untrusted:
            first = (cal.verdict or {}).get("reasons") or ["no reason recorded"]
            raise ValueError(f"{calibration} is marked not trustworthy ({first[0]}); "
                             "calibrate again, or pass --accept-untrusted to measure with it "
                             "anyway")
        if out.suffix not in (".ply", ".csv"):
            raise ValueError(f"--out {out}: point clouds are written as .ply or .csv")
        if _is_manifest(source):
            # frame by frame into the cloud file: the memory of one frame, whatever the scan
            streamed = measure_images_to(cal, source, out, robot=_load_robot(robot),
                                         image_size_of=f"the calibration {calibration}",
                                         progress=_bar("measuring frames", as_json))
            path, n_valid, n_invalid = streamed.path, streamed.points, streamed.invalid
            info = {**streamed.summary(), "blur_var_px2": cal.blur_var}
        else:
            ds = Dataset.load(source)
            cloud = measure_points(cal, [ds.pixels[i:i + 1] for i in range(len(ds))], ds.poses)
            err = np.linalg.norm(cloud.points - ds.points, axis=1)[cloud.valid]
            info = {"rms_mm": float(np.sqrt(np.mean(err**2))) if err.size else None}
            if cloud.num_valid == 0:
                raise ValueError(f"none of the {len(cloud)} stripe pixels' rays meets the laser "
                                 f"plane of {calibration}: nothing to write (is this "
                                 "calibration of the sensor that took these data?)")
            path = cloud.save(out)
            n_valid, n_invalid = cloud.num_valid, len(cloud) - cloud.num_valid
    warns = _gather(caught)
    summary = {"cloud": str(path), "points": n_valid, "invalid": n_invalid, **info}
    if as_json:
        _echo_json({**summary, "warnings": warns} if warns else summary)
        return
    _show_warnings(warns)
    typer.echo(f"{n_valid} points measured ({n_invalid} stripe "
               "pixels without a measurement: their rays miss the laser plane, meet it at a "
               "grazing angle or lie outside the image)")
    for pid, why in (info.get("rejected") or {}).items():
        typer.echo(f"{pid}: rejected: {why}")
    if info.get("blur_var_px2") is not None:
        typer.echo(f"stripes corrected at albedo steps for the camera blur the calibration "
                   f"fitted ({info['blur_var_px2']:.3g} px^2)")
    if info.get("rms_mm") is not None:
        typer.echo(f"RMS distance to the reference points: {info['rms_mm']:.4g} mm")
    typer.echo(f"point cloud written to {path}")


# -- hmlvs inspect ---------------------------------------------------------------------------
@app.command("inspect")
def inspect_images(
    data: Path = typer.Argument(..., help="An image session: a folder with manifest.json (or "
                                "the manifest), with a board."),
    out: Path = typer.Option(Path("inspect"), "--out", "-o",
                             help="Folder for the pictures: one PNG per view, named by its id."),
    robot: Optional[Path] = _ROBOT_OPTION,
    as_json: bool = typer.Option(False, "--json", help="Print a JSON summary."),
) -> None:
    """Draw what the image pipeline found in each view, and say why a view was dropped.

    One picture per view: the numbered board corners, the stripe centres and the rejected
    scan lines coloured by status. One line per view on the terminal: used or rejected and
    why, corners, scan lines per stripe status.

    Example: hmlvs inspect session/ --out inspect/
    """
    from .report.inspect import inspect_session

    with _guard(as_json), _collect_warnings() as caught:
        from .guard import refuse_overwrite

        refuse_overwrite([*_inputs_of(data), robot], [], [("--out", out)])
        views = inspect_session(data, out, robot=_load_robot(robot))
    if not as_json:
        _show_warnings(_gather(caught))
    if as_json:
        _echo_json([{"id": v.id, "used": v.used, "reason": v.reason, "corners": v.corners,
                     "stripe": v.stripe, "image": None if v.image is None else str(v.image)}
                    for v in views])
        return
    for v in views:
        typer.echo(v.line())
    used = sum(v.used for v in views)
    typer.echo(f"{used} of {len(views)} views used; pictures in {out}")
# -- end hmlvs inspect -----------------------------------------------------------------------


@app.command("export")
def export_calibration(
    calibration: Path = typer.Argument(..., help="Calibration file (.yaml or .json)."),
    fmt: str = typer.Option(..., "--format", "-f", help="opencv (cv::FileStorage YAML), ros "
                            "(camera_info YAML) or json."),
    out: Optional[Path] = typer.Option(None, "--out", "-o", help="File to write (atomically); "
                                       "default: print to stdout."),
    image_size: Optional[tuple[int, int]] = typer.Option(
        None, "--image-size", help="Image width and height (px) for a paper-model "
        "calibration's distortion fit; default 2 Cu x 2 Cv."),
    camera_name: str = typer.Option("hmlvs_camera", help="camera_name of the ros format."),
) -> None:
    """Export a calibration for OpenCV (YAML), ROS (camera_info) or any JSON reader.

    The camera, the laser plane and the hand-eye transform; a paper-model calibration is
    converted to OpenCV's camera model.

    Example: hmlvs export calibration.yaml --format ros --out camera_info.yaml
    """
    from .data.export import export, export_text

    with _guard(), _collect_warnings() as caught:
        from .guard import refuse_overwrite

        refuse_overwrite([calibration], [("--out", out)])
        if out is None:
            text = export_text(calibration, fmt, image_size=image_size,
                               camera_name=camera_name)
        else:
            path = export(calibration, fmt, out, image_size=image_size,
                          camera_name=camera_name)
    _show_warnings(_gather(caught))  # on stderr: stdout may be the export itself
    if out is None:
        typer.echo(text, nl=False)
    else:
        typer.echo(f"{fmt} export written to {path}")


@app.command()
def study(
    quick: bool = typer.Option(
        False, "--quick", help="Fewer runs: 30 LM starts, 5 PSO runs and 200,000 random-search "
        "evaluations per s (about 10 s on 2 cores)."),
    runs_lm: Optional[int] = typer.Option(
        None, "--runs-lm", help="LM starts per s, the same for paper-mode and modern LM "
        "(default 1000, the paper's; quick 30)."),
    runs_pso: Optional[int] = typer.Option(
        None, "--runs-pso", help="PSO runs per s, also polished for PSO+LM (default 10; "
        "quick 5)."),
    evaluations: Optional[int] = typer.Option(
        None, "--evaluations", help="Random-search evaluations per s (default 1,000,000; "
        "quick 200,000)."),
    spreads: Optional[list[float]] = typer.Option(
        None, "--s", help="A spread s of the initial candidates (Eq. 22); repeat for several "
        "(default 0.0001 0.001 0.01 0.1 0.2)."),
    seed: int = typer.Option(0, help="Random seed of the data and of every method."),
    threads: Optional[int] = typer.Option(
        None, help="Worker threads (default: all cores); results do not depend on it."),
    out: Optional[Path] = typer.Option(
        None, "--out", help="Folder for study.md (the tables) and the PNG plots."),
    as_json: bool = typer.Option(False, "--json", help="Print a JSON summary."),
    progress: bool = typer.Option(
        True, "--progress/--no-progress", help="Show a progress bar on stderr."),
) -> None:
    """The paper's simulation study (Table 1, Fig. 8) of the five identification methods.

    RS, paper-mode LM, PSO, modern LM and PSO+LM from the same initial candidates, for each
    spread s.

    Example: hmlvs study --quick --out study-out
    """
    from .paper import study as st

    try:
        result = st.study(s_values=st.PAPER_S if not spreads else spreads, runs_lm=runs_lm,
                          runs_pso=runs_pso, evaluations=evaluations, quick=quick, seed=seed,
                          threads=threads, progress=progress, out_dir=out)
    except ValueError as e:
        typer.echo(f"error: {' '.join(str(e).split())}", err=True)
        raise typer.Exit(2) from None
    except KeyboardInterrupt as e:
        raise _interrupted(e, ": no results written") from None
    if as_json:
        _echo_json(result.to_dict())
    else:
        typer.echo(result.table())
        if result.files:
            typer.echo(f"written to {out}: " + ", ".join(p.name for p in result.files))


@app.command()
def scenario(
    name: str = typer.Argument(..., help="gauge-block (the paper's Table 3) or cylinder "
                               "(Fig. 13, a scan of a tube with holes)."),
    out: Optional[Path] = typer.Option(
        None, "--out", "-o", help="Folder for the rendered images, manifest.json and the "
        "results (gauge_block.json; cloud.ply and cloud.png for the cylinder)."),
    seed: int = typer.Option(0, help="Random seed (calibration session, robot, images)."),
    trials: int = typer.Option(10, help="gauge-block: trials per corner."),
    step: float = typer.Option(3.0, help="cylinder: scan step along the axis (mm)."),
    calibration: Optional[Path] = typer.Option(
        None, help="Calibration file to measure with; default: calibrate a simulated noisy "
        "checkerboard session of the true sensor first."),
    as_json: bool = typer.Option(False, "--json", help="Print a JSON summary."),
) -> None:
    """Simulate a measurement scenario of the paper end to end with rendered images.

    Example: hmlvs scenario gauge-block --out gauge-out --seed 0
    """
    from .data.calibration_file import Calibration
    from .paper import scenarios as scenes

    with _guard(as_json):
        if name not in ("gauge-block", "cylinder"):
            raise ValueError(f"unknown scenario {name!r}; choose gauge-block or cylinder")
        from .guard import refuse_overwrite

        refuse_overwrite([calibration], [], [("--out", out)])
        cal = Calibration.load(calibration) if calibration is not None else None
        bar = None
        if not as_json:
            from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn
            bar = Progress(TextColumn("{task.description}"), BarColumn(),
                           TextColumn("{task.completed}/{task.total}"), TimeRemainingColumn(),
                           transient=True)
        task = None

        def progress(done: int, total: int) -> None:
            nonlocal task
            if bar is not None:
                if task is None:
                    task = bar.add_task("rendering", total=total)
                bar.update(task, completed=done, total=total)

        try:
            if bar is not None:
                bar.start()
            if name == "gauge-block":
                result = scenes.gauge_block(cal, trials=trials, seed=seed, out_dir=out,
                                            progress=progress)
            else:
                result = scenes.cylinder_scan(cal, seed=seed, step=step, out_dir=out,
                                              progress=progress)
        finally:
            if bar is not None:
                bar.stop()
    if as_json:
        _echo_json(result.to_dict())
        return
    typer.echo(result.summary())
    if result.files:
        typer.echo(f"written to {out}: " + ", ".join(Path(str(f)).name
                                                    for f in result.files.values()))


def _command():
    """The command object of ``app`` (``typer.main.get_command``), with flags shown without a
    type placeholder in the help (``--json  Print ...`` rather than ``--json <bool>  Print
    ...``). Only attributes every typer release has are touched (params, is_flag,
    get_help_option, commands), so no import of click is needed."""
    cmd = typer.main.get_command(app)

    def strip(c: Any) -> None:
        for p in c.params:
            if getattr(p, "is_flag", False) or getattr(p, "count", False):
                p.metavar = ""
        original = c.get_help_option

        def help_option(ctx: Any, _original=original):
            opt = _original(ctx)
            if opt is not None:
                opt.metavar = ""
            return opt

        c.get_help_option = help_option  # type: ignore[method-assign]
        for sub in getattr(c, "commands", {}).values():
            strip(sub)

    strip(cmd)
    return cmd


def main(argv: Optional[list[str]] = None) -> None:
    """Run the command line; errors outside a command's own guard follow the same policy."""
    import signal
    import sys

    # SIGTERM as Ctrl-C: temporaries removed, outputs left as they were, exit 143
    try:
        previous = signal.signal(signal.SIGTERM, on_sigterm)
    except ValueError:  # not the main thread (an embedding application): left as it is
        previous = None
    from . import _io

    _io.SIGTERM_RECEIVED[0] = False
    try:
        _command().main(args=argv, prog_name="hmlvs")
    except SystemExit as e:
        # SIGTERM while a command loads (before its guard): typer exits 130 without a word
        if e.code == 130 and _io.SIGTERM_RECEIVED[0]:
            print("terminated", file=sys.stderr)
            sys.exit(143)
        raise
    except KeyboardInterrupt as e:  # outside a command's guard, e.g. while parsing the options
        terminated = isinstance(e, Terminated)
        print("terminated" if terminated else "interrupted", file=sys.stderr)
        sys.exit(143 if terminated else 130)
    except Exception as e:  # reached only outside _guard, e.g. while printing results
        try:
            with _guard():
                raise e
        except typer.Exit as exit_:
            sys.exit(exit_.exit_code)
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
