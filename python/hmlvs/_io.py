"""File access shared by every reader and writer: input files that must exist, and atomic
output (write to a temporary file beside the target, then rename)."""

from __future__ import annotations

from contextlib import contextmanager
import os
from pathlib import Path
import tempfile
from typing import IO, Iterator


@contextmanager
def atomic_write(path: str | os.PathLike, mode: str = "w", encoding: str | None = "utf-8"
                 ) -> Iterator[IO]:
    """Open a temporary file in the target's folder; on success rename it over ``path``.

    If the block raises, the temporary file is removed and ``path`` is left as it was.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the usual permissions
    try:
        with os.fdopen(fd, mode, encoding=None if "b" in mode else encoding) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise


def existing_file(path: str | os.PathLike, what: str) -> Path:
    """``path`` as a Path; ValueError "<path>: no such <what>" unless it is a file."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no such {what}")
    return path


def read_document(path: str | os.PathLike, what: str) -> object:
    """The YAML (or, for .json, JSON) document in an existing file; ValueError naming the file
    and ``what`` when it is missing or malformed."""
    import json

    import yaml

    path = existing_file(path, what)
    try:
        text = path.read_text(encoding="utf-8")
        return json.loads(text) if path.suffix.lower() == ".json" else yaml.safe_load(text)
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, yaml.YAMLError) as e:
        raise ValueError(f"{path}: malformed {what} ({type(e).__name__}: {e})") from None


def write_document(path: str | os.PathLike, d: object, what: str) -> Path:
    """Write ``d`` atomically as YAML (.yaml/.yml) or JSON (.json); other suffixes are refused
    naming ``what``."""
    import json

    import yaml

    path = Path(path)
    if path.suffix.lower() in (".yaml", ".yml"):
        text = yaml.safe_dump(d, sort_keys=False, default_flow_style=None)
    elif path.suffix.lower() == ".json":
        text = json.dumps(d, indent=2)
    else:
        raise ValueError(f"{path}: {what} files are .yaml, .yml or .json")
    with atomic_write(path) as fh:
        fh.write(text)
    return path
