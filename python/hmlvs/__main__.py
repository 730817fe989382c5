"""The command line (`hmlvs` and `python -m hmlvs`). Ctrl-C while the command line is still
loading ends as it does during a command: "interrupted" and exit code 130, no traceback;
SIGTERM likewise, "terminated" and exit code 143."""

import signal
import sys


def run() -> None:
    from ._io import Terminated, check_terminated, on_sigterm

    # a file name that is not UTF-8 is printed as the bytes it is, not an encoding error
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.reconfigure(errors="surrogateescape")  # type: ignore[union-attr]
        except (AttributeError, ValueError):
            pass
    try:
        signal.signal(signal.SIGTERM, on_sigterm)
    except ValueError:  # not the main thread: leave the default
        pass
    try:
        from .cli import main

        check_terminated()  # a SIGTERM whose exception an import swallowed
    except KeyboardInterrupt as e:
        terminated = isinstance(e, Terminated)
        print("terminated" if terminated else "interrupted", file=sys.stderr)
        sys.exit(143 if terminated else 130)
    main()


if __name__ == "__main__":
    run()
