"""File access shared by every reader and writer: input files that must exist, and atomic
output (write to a temporary file beside the target, then rename)."""

from __future__ import annotations

from contextlib import contextmanager
import os
from pathlib import Path
import re
import tempfile
from typing import IO, Iterator


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised by the command line's handler (:func:`on_sigterm`) where Python next
    runs: a KeyboardInterrupt, so every clean-up path of Ctrl-C (temporary files and folders
    removed, a half-written output set undone) runs for it too; the command line then exits
    143 (128 + SIGTERM)."""


#: set by :func:`on_sigterm`: a Terminated that something turned into a plain exit (typer
#: ends a KeyboardInterrupt outside a command's body with exit 130, silently) is still told
SIGTERM_RECEIVED = [False]


def on_sigterm(signum: int, frame: object) -> None:
    SIGTERM_RECEIVED[0] = True
    raise Terminated("terminated")


def check_terminated() -> None:
    """Raise :class:`Terminated` if SIGTERM came: its exception may have been raised where
    Python cannot pass it on (a finaliser, a callback from C code: "Exception ignored in"),
    and so lost; every output is committed only after this check."""
    if SIGTERM_RECEIVED[0]:
        raise Terminated("terminated")


# Every temporary name is ".hmlvs-tmp-<pid>-<random>.tmp": the marker and the writing
# process's id make a name no user file has; only such names whose process is gone (and that
# are older than an hour) are ever removed, so a user's file is never touched.
_TMP_PREFIX = ".hmlvs-tmp-"
_STALE_SECONDS = 3600.0
_TMP_NAME = re.compile(r"\.hmlvs-tmp-(\d+)-[A-Za-z0-9_]{6,}\.tmp")


def _tmp_prefix() -> str:
    return f"{_TMP_PREFIX}{os.getpid()}-"


def _pid_running(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # exists but is another user's (EPERM), or cannot tell: keep
        return True
    return True


def _stale_temporaries(folder: Path) -> Iterator[Path]:
    """Our temporary files and folders in ``folder`` that a killed write left behind: a name
    of ours, its process no longer running, older than an hour."""
    import time

    now = time.time()
    try:
        names = os.listdir(folder)
    except OSError:
        return
    for name in names:
        m = _TMP_NAME.fullmatch(name)
        if m is None or _pid_running(int(m.group(1))):
            continue
        p = folder / name
        try:
            if not p.is_symlink() and now - p.stat().st_mtime > _STALE_SECONDS:
                yield p
        except OSError:
            pass


def _remove_stale(folder: Path) -> None:
    """Remove our temporary files that a killed write left behind (:func:`_stale_temporaries`);
    nothing else."""
    for p in _stale_temporaries(folder):
        try:
            if p.is_file():
                p.unlink()
        except OSError:
            pass


def _target(path: Path) -> Path:
    """Where a write to ``path`` lands: through a symbolic link (also a chain, or one to a
    file that does not exist yet) to its target, so the link stays a link."""
    return Path(os.path.realpath(path)) if path.is_symlink() else path


@contextmanager
def atomic_write(path: str | os.PathLike, mode: str = "w", encoding: str | None = "utf-8"
                 ) -> Iterator[IO]:
    """Open a temporary file in the target's folder; on success rename it over ``path``.

    If the block raises, the temporary file is removed and ``path`` is left as it was.
    """
    import errno

    path = _target(Path(path))  # a symbolic link is written through, not replaced
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        raise NotADirectoryError(errno.ENOTDIR, "Not a directory", str(path.parent)) from None
    if path.is_dir():
        raise IsADirectoryError(errno.EISDIR, "Is a directory", str(path))
    _remove_stale(path.parent)
    # A short temporary name (not derived from the target's), so that any legal target name
    # works; marker and pid make it ours (_stale_temporaries).
    fd, tmp = tempfile.mkstemp(prefix=_tmp_prefix(), suffix=".tmp", dir=path.parent)
    try:
        keep = os.stat(path).st_mode & 0o7777  # an existing output keeps its permissions
    except OSError:
        umask = os.umask(0)
        os.umask(umask)
        keep = 0o666 & ~umask  # mkstemp makes 0600; a new file gets the usual permissions
    try:
        os.chmod(tmp, keep)
    except OSError:
        pass
    try:
        with os.fdopen(fd, mode, encoding=None if "b" in mode else encoding) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        check_terminated()
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise


def existing_file(path: str | os.PathLike, what: str) -> Path:
    """``path`` as a Path; ValueError "<path>: no such <what>" unless it is a file."""
    if not isinstance(path, (str, os.PathLike)):
        raise ValueError(f"no {what} given: expected a file name, got {path!r}")
    path = Path(path)
    try:
        is_file = path.is_file()
    except ValueError:  # a name no file system holds (a NUL, an unpaired surrogate)
        is_file = False
    if not is_file:
        raise ValueError(f"{path}: no such {what}")
    return path


def read_image(path: str | os.PathLike) -> object:
    """An image file (any format OpenCV reads, depth and channels unchanged) as an array, or
    None when the file is not an image. The file is opened by Python and decoded from its
    bytes, so any name works, also one that is not UTF-8 (``cv2.imread`` crashes on such a
    name); a name no file system can hold (a lone surrogate) is a ValueError naming it."""
    import cv2
    import numpy as np

    try:
        os.fsencode(path)
    except UnicodeError:
        raise ValueError(f"{os.fspath(path)!r}: the image file's name holds a character no "
                         "file name can (an unpaired surrogate); rename it") from None
    data = np.fromfile(path, dtype=np.uint8)
    if data.size == 0:
        return None
    try:
        return cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    except cv2.error:
        return None


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


#: how deeply a YAML or JSON file's lists and mappings may nest (every file of ours needs 4)
MAX_DEPTH = 32


def parse_text(text: str, as_json: bool, source: object, what: str) -> object:
    """JSON or YAML text as Python objects, nested at most :data:`MAX_DEPTH` deep: a deeper
    document (which Python's parsers and every reader after them would recurse into until
    RecursionError) is a ValueError naming ``source``. Syntax errors are the parser's."""
    import json

    import yaml

    try:
        doc = json.loads(text) if as_json else yaml.safe_load(text)
    except RecursionError:
        doc = None
        deep = True
    else:
        deep = _too_deep(doc)
    if deep:
        raise ValueError(f"{source}: malformed {what}: its lists and mappings nest more than "
                         f"{MAX_DEPTH} levels deep") from None
    return doc


def _too_deep(doc: object) -> bool:
    stack = [(doc, 1)]
    seen: set[int] = set()
    while stack:
        obj, depth = stack.pop()
        if isinstance(obj, (dict, list)):
            if depth > MAX_DEPTH:
                return True
            if id(obj) in seen:  # a YAML alias: the same object again
                continue
            seen.add(id(obj))
            stack.extend((v, depth + 1) for v in (obj.values() if isinstance(obj, dict)
                                                  else obj))
    return False


def read_document(path: str | os.PathLike, what: str) -> object:
    """The YAML (or, for .json, JSON) document in an existing file; ValueError naming the file
    and ``what`` when it is missing or malformed."""
    import json

    import yaml

    path = existing_file(path, what)
    try:
        text = path.read_text(encoding="utf-8")
        return parse_text(text, path.suffix.lower() == ".json", path, what)
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

    path = _target(Path(path))  # a symbolic link to a folder is written through
    if path.exists() and not path.is_dir():
        raise NotADirectoryError(errno.ENOTDIR, "Not a directory", str(path))
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        raise NotADirectoryError(errno.ENOTDIR, "Not a directory", str(path.parent)) from None
    _remove_stale_folders(path.parent)
    tmp = Path(tempfile.mkdtemp(prefix=_tmp_prefix(), suffix=".tmp", dir=path.parent))
    try:
        yield tmp
        check_terminated()
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
    """Our temporary folders of killed multi-file writes (:func:`_stale_temporaries`)."""
    import shutil

    for p in _stale_temporaries(folder):
        if p.is_dir():
            shutil.rmtree(p, ignore_errors=True)
