"""The command line (`hmlvs` and `python -m hmlvs`). Ctrl-C while the command line is still
loading ends as it does during a command: "interrupted" and exit code 130, no traceback."""

import sys


def run() -> None:
    try:
        from .cli import main
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        sys.exit(130)
    main()


if __name__ == "__main__":
    run()
