"""The ``hmlvs`` command line: one module per command, each a thin shell over library calls
(``common`` holds what they share). ``main`` runs it."""

from __future__ import annotations

from typing import Any, Optional

import typer

from .._io import Terminated, on_sigterm
from . import (  # noqa: F401 (each module registers its command on the app)
    calibrate,
    demo,
    design,
    export,
    inspect_images,
    measure,
    report,
    scenario,
    simulate,
    study,
)
from .common import MOUNTING_DEG, app, guard, mounted_truth

__all__ = ["app", "main", "MOUNTING_DEG", "mounted_truth"]


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
    from .. import _io

    _io.SIGTERM_RECEIVED[0] = False
    try:
        _command().main(args=argv, prog_name="hmlvs")
    except SystemExit as e:
        # SIGTERM while a command loads (before its guard): typer exits 130 without a word;
        # or its exception was lost where Python could not pass it on (the outputs were not
        # committed: hmlvs._io.check_terminated)
        if e.code in (0, 130) and _io.SIGTERM_RECEIVED[0]:
            print("terminated", file=sys.stderr)
            sys.exit(143)
        raise
    except KeyboardInterrupt as e:  # outside a command's guard, e.g. while parsing the options
        terminated = isinstance(e, Terminated)
        print("terminated" if terminated else "interrupted", file=sys.stderr)
        sys.exit(143 if terminated else 130)
    except Exception as e:  # reached only outside guard, e.g. while printing results
        try:
            with guard():
                raise e
        except typer.Exit as exit_:
            sys.exit(exit_.exit_code)
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
        # the flag speaks of this run only: a later library write in the same process (an
        # embedding application, a test) must not be stopped by it
        _io.SIGTERM_RECEIVED[0] = False
