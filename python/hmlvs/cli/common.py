"""What every command shares: the Typer app, the error and interrupt policy (`guard`),
warnings, progress bars, JSON output, output-file checks and the robot option."""

from __future__ import annotations

from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator, Optional

import typer

from .._io import Terminated, json_text

app = typer.Typer(
    name="hmlvs",
    help="Calibrate and use a hand-mounted laser-vision sensor.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode="markdown",  # help paragraphs reflow to the terminal's width
)


_DEBUG = False  # --debug: internal errors show their traceback


def fault(e: OSError) -> str:
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


def error_lines(text: str) -> list[str]:
    # A message of several lines (e.g. one per rejected image pair) keeps its lines;
    # whitespace inside a line is collapsed.
    lines = [" ".join(line.split()) for line in text.splitlines()]
    return [line for line in lines if line] or [""]


def fail(lines: list[str], code: int, as_json: bool) -> None:
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


def interrupted(e: BaseException, what: str = "") -> "typer.Exit":
    """Ctrl-C (exit 130) or SIGTERM (exit 143, :class:`hmlvs._io.Terminated`), said on stderr;
    the exit to raise."""
    terminated = isinstance(e, Terminated)
    typer.echo(("terminated" if terminated else "interrupted") + what, err=True)
    return typer.Exit(143 if terminated else 130)


@contextmanager
def guard(as_json: bool = False) -> Iterator[None]:
    """The command line's error policy. Exit 2: bad input or an environment fault (a path,
    a permission, disk space), one line naming the file, entry or option. Exit 1: an internal
    error, a short message (the traceback with --debug). Exit 130: Ctrl-C; exit 143: SIGTERM
    (every clean-up path of Ctrl-C runs for it too)."""
    try:
        yield
    except _PASS_THROUGH:
        raise
    except ValueError as e:
        fail(error_lines(str(e)), 2, as_json)
    except OSError as e:
        fail([fault(e)], 2, as_json)
    except KeyboardInterrupt as e:
        raise interrupted(e) from None
    except Exception as e:
        if _DEBUG:
            raise
        fail([f"internal error ({type(e).__name__}: {' '.join(str(e).split())}); this is a "
               "bug in hmlvs: run again with --debug for the traceback and report it"], 1,
              as_json)


# The simulated true sensor of `demo` and `simulate`: the paper's nominal values (Table 2)
# with the camera mounted a few degrees off the hand's axes, as a real mounting is. At the
# exact nominal (phi = 0) the ZYZ Euler angles sit on their gimbal lock and omega, varphi
# separately mean nothing (docs/glossary.md); a generic mounting gives a determined result.
MOUNTING_DEG = (1.0, 2.0, -1.0)  # omega, phi, varphi (deg)


def mounted_truth(mounting_deg) -> "object":
    import math

    from ..models.params import Parameters

    om, ph, va = (math.radians(float(a)) for a in mounting_deg)
    return Parameters.nominal().replace(omega=om, phi=ph, varphi=va)


GLOSSARY_URL = "docs/glossary.md"


GLOSSARY_ANCHOR = {
    "flat-direction": "flat-direction", "too-few-points": "too-few-points",
    "pose-variety": "pose-variety", "gimbal-lock": "zyz-gimbal-lock",
    "at-bound": "at-a-bound", "diagnostics": "diagnostics", "data": "data-warning",
}


@contextmanager
def collect_warnings() -> Iterator[list]:
    """Record every warning raised inside (instead of printing it with a source line)."""
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield caught


def gather(caught: list, *texts: object) -> list[dict]:
    """Every data warning once: the recorded Python warnings, then the ``warning: ...`` lines
    and warning lists of results; each as {"kind", "message", "see"}."""
    from ..diagnostics.identifiability import HmlvsDataWarning, warning_category

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
        anchor = GLOSSARY_ANCHOR.get(kind)
        out.append({"kind": kind, "message": key,
                    "see": f"{GLOSSARY_URL}#{anchor}" if anchor else None})
    return out


def without_warning_lines(text: str) -> str:
    """A result summary without its ``warning:`` lines (they are shown once, separately)."""
    return "\n".join(line for line in text.splitlines() if not line.startswith("warning: "))


def show_warnings(items: list[dict]) -> None:
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


def _version_callback(value: bool) -> None:
    if value:
        from .. import __version__

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


def is_manifest(path: Path) -> bool:
    """An image manifest (:func:`hmlvs.data.manifest.is_manifest`), its module loaded only
    when asked."""
    from ..data.manifest import is_manifest as is_images

    return is_images(path)


def session_of(path: Path) -> Any:
    """An image session's manifest read and checked once (a
    :class:`hmlvs.data.manifest.Manifest`, taken wherever its path is), or any other data
    argument as it is: every later step of the command reads no manifest again."""
    if not is_manifest(path):
        return path
    from ..data.manifest import load_manifest

    return load_manifest(path)


def solve_progress(quiet: bool):
    """Progress for solves: a bar, or with --json a silent callback. Either way the solver
    calls back into Python periodically, which is where Ctrl-C is noticed."""
    return (lambda *_: True) if quiet else True


def bar(description: str, quiet: bool):
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


@contextmanager
def command(as_json: bool = False) -> Iterator[list]:
    """A command's body: its errors turned into messages and exit codes (:func:`guard`), its
    warnings recorded (:func:`collect_warnings`); yields the warnings caught."""
    with guard(as_json), collect_warnings() as caught:
        yield caught


def finish(caught: list, as_json: bool, summary: Any, *texts: object,
           quiet: bool = False) -> list[dict] | None:
    """The end of a command's output: the warnings caught (and those of ``texts``, see
    :func:`gather`) with --json printed inside the JSON ``summary`` (a mapping, or a list
    printed alone; None then: nothing else to print), else shown on stderr unless ``quiet``
    and returned for the command's own text."""
    warns = gather(caught, *texts)
    if as_json:
        echo_json({**summary, "warnings": warns} if isinstance(summary, dict) else summary)
        return None
    if not quiet:
        show_warnings(warns)
    return warns


def echo_json(obj: object) -> None:
    """Valid JSON on stdout: a figure that is not available (NaN, inf) is ``null``."""
    typer.echo(json_text(obj))


@contextmanager
def outputs(*targets: Path) -> Iterator[list]:
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


def check_suffix(option: str, path: Optional[Path], allowed: tuple[str, ...],
                  what: str) -> None:
    """Refuse an output whose name does not say the kind of file it will be."""
    if path is not None and path.suffix.lower() not in allowed:
        raise ValueError(f"{option} {path}: {what} is written as " + " or ".join(allowed))


def inputs_of(data: Path) -> list[Path]:
    """The files a data argument stands for: an image session's manifest and the files it
    names, or the file itself."""
    from ..guard import session_files

    return session_files(data) if is_manifest(data) else [data]


#: the exit status of a calibration whose verdict is not trustworthy (its file is written)
EXIT_UNTRUSTED = 3


def exit_untrusted(verdict: Any) -> None:
    if not verdict.trustworthy:
        raise typer.Exit(EXIT_UNTRUSTED)


def load_robot(path: Optional[Path]):
    """The --robot file's Robot, or None."""
    if path is None:
        return None
    from ..data.robot_file import load_robot

    return load_robot(path)


def rotation_text(params, truth=None) -> str:
    """The hand-eye rotation in words: a rotation vector, the ZYZ Euler angles as the
    paper's view."""
    rv = rotation_vector(params)
    text = ("hand-eye rotation (hand_from_camera) as a rotation vector (axis x angle, rad): "
            f"[{rv[0]:+.5f}, {rv[1]:+.5f}, {rv[2]:+.5f}], {sum(x * x for x in rv) ** 0.5:.5f} "
            "rad about its axis")
    if truth is not None:
        tv = rotation_vector(truth)
        text += f"; true [{tv[0]:+.5f}, {tv[1]:+.5f}, {tv[2]:+.5f}]"
    return text + ("\n  (omega, phi, varphi in the table are the same rotation as the paper's "
                   "ZYZ Euler angles; near phi = 0 they are not unique, see "
                   f"{GLOSSARY_URL}#zyz-gimbal-lock)")


def determined(result) -> tuple[list[str], list[str]]:
    """Free parameters the data determine, and those they do not (from the uncertainty)."""
    unc = result.uncertainty
    free = list(result.free)
    if unc is None:
        return [], free
    return ([n for n in free if unc.determined.get(n, False)],
            [n for n in free if not unc.determined.get(n, False)])


def resolve_fixed(fixed: list[str], free: list[str]) -> tuple[tuple[str, ...], list[str]]:
    """The parameters to hold fixed: the default gauge plus --fixed, minus --free;
    ``--fixed none`` frees everything. Also one line per fixed parameter saying why."""
    from ..models.params import DEFAULT_FIXED, FIXED_WHY, NAMES

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


def rotation_vector(params) -> "list[float]":
    """hand_from_camera's rotation as a rotation vector (axis times angle, rad)."""
    from ..models.paper import hand_eye_rotation_vector

    return hand_eye_rotation_vector(params)
