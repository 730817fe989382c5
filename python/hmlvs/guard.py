"""A command's outputs never overwrite its inputs.

Every file a command reads (the files named on its command line and, for an image session,
the manifest and every file the manifest names) is collected before anything is written; an
output that is one of them, or an output folder that holds one, is refused with a sentence
naming both. Paths are compared resolved (symbolic links followed), so a link to an input
is caught too.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Iterable


def _resolved(p: str | os.PathLike) -> Path:
    try:
        return Path(os.path.realpath(os.fspath(p)))
    except ValueError:  # a name no file system holds (an unpaired surrogate): no file's
        return Path(os.path.abspath(os.fspath(p)))


def session_files(source: str | os.PathLike) -> list[Path]:
    """An image session's manifest and the files it names (images, stripe lists, the pose
    file); a path that is no manifest gives itself."""
    from .data.manifest import read_manifest

    path = Path(source)
    manifest = path / "manifest.json" if path.is_dir() else path
    if path.is_dir() and not manifest.exists():
        for name in ("manifest.yaml", "manifest.yml"):
            if (path / name).exists():
                manifest = path / name
    try:
        entries, doc, folder = read_manifest(source)
    except (OSError, ValueError):
        return [manifest]
    out = [manifest]
    if doc.get("pose_file"):
        out.append(Path(folder) / str(doc["pose_file"]))
    for e in entries:
        for key in ("on", "off", "stripe"):
            v = e.get(key)
            if isinstance(v, (str, os.PathLike)):
                p = Path(v)
                out.append(p if p.is_absolute() else Path(folder) / p)
    return out


def refuse_overwrite(inputs: Iterable[str | os.PathLike | None],
                     outputs: Iterable[tuple[str, str | os.PathLike | None]],
                     folders: Iterable[tuple[str, str | os.PathLike | None]] = ()) -> None:
    """Raise ``ValueError`` when an output file is one of the ``inputs``, or an output folder
    holds one. ``outputs`` and ``folders``: (option name, path or None) pairs."""
    ins = {_resolved(p): Path(p) for p in inputs if p is not None}
    for option, out in outputs:
        if out is None:
            continue
        hit = ins.get(_resolved(out))
        if hit is not None:
            raise ValueError(f"{option} {out} is one of this command's inputs ({hit}): it "
                             "would be overwritten; write to another file")
    for option, folder in folders:
        if folder is None:
            continue
        root = _resolved(folder)
        for r, p in ins.items():
            if root == r or root in r.parents:
                raise ValueError(f"{option} {folder} holds this command's input {p}: its "
                                 "files could be overwritten; write to another folder")
