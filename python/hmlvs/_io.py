"""File access shared by every reader and writer: input files that must exist, and atomic
output (write to a temporary file beside the target, then rename)."""

from __future__ import annotations

from contextlib import contextmanager
import os
from pathlib import Path
import tempfile
from typing import IO, Iterator

_TMP_PREFIX = ".hmlvs-"
_STALE_SECONDS = 3600.0


def _remove_stale(folder: Path) -> None:
    """Remove our temporary files that a killed write left behind (older than an hour: no
    write of ours takes that long)."""
    import time

    now = time.time()
    try:
        for p in folder.glob(f"{_TMP_PREFIX}*.tmp"):
            try:
                if now - p.stat().st_mtime > _STALE_SECONDS:
                    p.unlink()
            except OSError:
                pass
    except OSError:
        pass


@contextmanager
def atomic_write(path: str | os.PathLike, mode: str = "w", encoding: str | None = "utf-8"
                 ) -> Iterator[IO]:
    """Open a temporary file in the target's folder; on success rename it over ``path``.

    If the block raises, the temporary file is removed and ``path`` is left as it was.
    """
    import errno

    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        raise NotADirectoryError(errno.ENOTDIR, "Not a directory", str(path.parent)) from None
    if path.is_dir():
        raise IsADirectoryError(errno.EISDIR, "Is a directory", str(path))
    _remove_stale(path.parent)
    # A short temporary name (not derived from the target's), so that any legal target name
    # works; the prefix marks it as ours for _remove_stale.
    fd, tmp = tempfile.mkstemp(prefix=_TMP_PREFIX, suffix=".tmp", dir=path.parent)
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


def plain(obj: object) -> object:
    """``obj`` with numpy scalars and arrays as Python numbers and lists, tuples as lists, and
    every non-finite float (NaN, inf) as None: what JSON and YAML can hold."""
    import math

    if isinstance(obj, dict):
        return {str(k): plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [plain(v) for v in obj]
    if hasattr(obj, "tolist") and callable(obj.tolist):  # numpy arrays and scalars
        return plain(obj.tolist())
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def json_text(obj: object, indent: int | None = 2) -> str:
    """Valid JSON of ``obj`` (:func:`plain`: ``null`` where a number is not finite, never
    ``NaN``)."""
    import json

    return json.dumps(plain(obj), indent=indent, allow_nan=False, default=str)


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
    import yaml

    path = Path(path)
    if path.suffix.lower() in (".yaml", ".yml"):
        text = yaml.safe_dump(plain(d), sort_keys=False, default_flow_style=None)
    elif path.suffix.lower() == ".json":
        text = json_text(d)
    else:
        raise ValueError(f"{path}: {what} files are .yaml, .yml or .json")
    with atomic_write(path) as fh:
        fh.write(text)
    return path


@contextmanager
def atomic_folder(path: str | os.PathLike, last: tuple[str, ...] = ("manifest.json",)
                  ) -> Iterator[Path]:
    """Write several files as one: yields a temporary folder beside ``path``; on success its
    files take their places in ``path``: a new folder appears whole (one rename); into an
    existing folder (whose other files are kept) the files move one by one, those named in
    ``last`` (the manifest) last. If the block raises, the temporary folder is removed and
    ``path`` is left as it was."""
    import errno
    import shutil

    path = Path(path)
    if path.exists() and not path.is_dir():
        raise NotADirectoryError(errno.ENOTDIR, "Not a directory", str(path))
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        raise NotADirectoryError(errno.ENOTDIR, "Not a directory", str(path.parent)) from None
    _remove_stale_folders(path.parent)
    tmp = Path(tempfile.mkdtemp(prefix=_TMP_PREFIX, suffix=".tmp", dir=path.parent))
    try:
        yield tmp
        if not path.exists():
            os.replace(tmp, path)
            return
        for f in sorted(tmp.iterdir(), key=lambda f: (f.name in last, f.name)):
            os.replace(f, path / f.name)
        tmp.rmdir()
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def _remove_stale_folders(folder: Path) -> None:
    """Temporary folders of killed multi-file writes (older than an hour)."""
    import shutil
    import time

    now = time.time()
    try:
        for p in folder.glob(f"{_TMP_PREFIX}*.tmp"):
            try:
                if p.is_dir() and now - p.stat().st_mtime > _STALE_SECONDS:
                    shutil.rmtree(p, ignore_errors=True)
            except OSError:
                pass
    except OSError:
        pass
