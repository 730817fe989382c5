"""The session manifest: which images (or stripe list) belong to which joint readings or pose.

Format ``hmlvs-images`` version 1, JSON (``manifest.json``) or YAML (``.yaml``/``.yml``)::

    format: hmlvs-images
    version: 1
    image_size: [640, 480]          # optional; every pair must have this size
    joint_unit: rad                 # or deg
    robot: SCORBOT ER-VII           # optional: a built-in arm's name, or a mapping in the
                                    # hmlvs.Robot.to_dict form (DH table)
    pose_format: {unit: m, quaternion_order: xyzw}   # how 'pose' entries are written
    pose_file: poses.csv            # optional: every pose from a file (see hmlvs.data.poses)
    stripe_direction: auto          # optional: columns (the stripe runs across the image, one
                                    # centre per column), rows (down it) or auto (judged per
                                    # frame)
    board: {rows: 6, cols: 8, square: 30.0, origin: [700, 90, 0], ...}   # for calibration
    poses:
      - id: p000                    # unique: pairs the files with the readings explicitly
        on: p000_on.png             # laser-on frame  } or  stripe: p000.csv  (u, v[, intensity])
        off: p000_off.png           # laser-off frame } (optional: without it the background
                                    #   is estimated from the laser-on frame)
        joints: [0.1, -0.8, ...]    # joint readings, or
        # pose: [[...4x4 base_from_hand...]], or {position: [x, y, z], quaternion: [4]}
        #       or {position: [x, y, z], rotation_vector: [rx, ry, rz]} (rad)

Positions are in ``pose_format``'s unit (default mm; a quaternion needs the order named). With
a ``pose_file`` no entry has joints or pose: the file's ``id`` column pairs its rows with the
entries, or without one its rows pair in order. :func:`read_manifest` returns every entry's
pose as a 4x4 in mm.

File names are relative to the manifest's folder. A malformed manifest (no id, a repeated id,
an entry with neither or both of joints/pose, or neither images nor a stripe list) raises a
ValueError naming the file and the entry; a missing or unreadable image only rejects its own
entry, and the rest of the session goes through.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
import json
import os
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from .._io import atomic_folder, atomic_write, parse_text, read_document
from .dataset import check_format
from .poses import PoseFormat, pose_from_entry, read_poses

FORMAT = "hmlvs-images"
# how the stripe runs: judged per frame (auto), one centre per image column (across the
# image) or one per image row (down it)
STRIPE_DIRECTIONS = ("auto", "columns", "rows")
VERSION = 1
NAME = "manifest.json"


def _board_schema() -> Any:
    from ..data import schema as sc

    vec3 = sc.Field("list", "3 numbers", length=3, items=sc.number())
    return sc.Field("struct", "a board: rows, cols (inner corners), square (mm)",
                    required=("rows", "cols", "square"), extra="error", keys={
                        "rows": sc.integer("a whole number of inner corners", minimum=2),
                        "cols": sc.integer("a whole number of inner corners", minimum=2),
                        "square": sc.number("a size in mm", positive=True),
                        "origin": vec3, "row_direction": vec3, "col_direction": vec3})


def _manifest_schema() -> Any:
    """The manifest's typed keys; ``board``, ``robot`` and ``pose_format`` have their own
    readers (:func:`checkerboard_of`, :func:`~hmlvs.data.robot_file.robot_from_description`,
    :meth:`~hmlvs.data.poses.PoseFormat.from_dict`), and other keys are kept (a renderer's
    notes)."""
    from ..data import schema as sc

    return sc.Field("struct", "an image manifest {format, version, poses, ...}",
                    required=("poses",), keys={
                        "image_size": sc.Field("list", "[width, height] in pixels", length=2,
                                               items=sc.integer("a whole number of pixels",
                                                                minimum=1), nullable=True),
                        "joint_unit": sc.text("an angle unit", choices=("rad", "deg")),
                        "pose_file": sc.text("a file name", nullable=True),
                        "stripe_direction": sc.text("a stripe direction",
                                                    choices=STRIPE_DIRECTIONS),
                        "poses": sc.Field("list", "a list of entries {id, on, off | stripe, "
                                          "joints | pose}")})


def _entry_schema() -> Any:
    """One manifest entry's typed keys (which of them it must have is checked after)."""
    from ..data import schema as sc

    return sc.Field("struct", "an entry {id, on, off | stripe, joints | pose}", keys={
        "id": sc.identifier(), "on": sc.text("an image file name"),
        "off": sc.text("an image file name"), "stripe": sc.text("a stripe list file name"),
        "joints": sc.Field("list", "a list of joint readings", items=sc.number(),
                           check=sc.non_empty("joint reading"))})


def checkerboard_of(spec: Any, source: Any) -> Any:
    """A :class:`~hmlvs.Checkerboard` from a manifest's ``board`` block, validated (rows,
    cols, square, optional origin and directions; any other key is refused by name)."""
    from ..geometry.board import Checkerboard
    from .schema import validate

    if isinstance(spec, dict) and spec.get("type", "checkerboard") == "checkerboard":
        spec = {k: v for k, v in spec.items() if k != "type"}
    elif isinstance(spec, dict):
        raise ValueError(f"{source}: board: this path needs a checkerboard, got type "
                         f"{spec['type']!r} (ChArUco boards calibrate with --model opencv)")
    validate(spec, _board_schema(), str(source), "board")
    try:
        return Checkerboard(**{k: (tuple(v) if isinstance(v, list) else v)
                               for k, v in spec.items()})
    except ValueError as e:
        raise ValueError(f"{source}: board: {e}") from None


def _entry(e: Any, i: int, path: Path, seen: dict[str, int], in_pose_file: bool, bench: bool,
           fmt: PoseFormat, doc: dict[str, Any]) -> dict[str, Any]:
    """One manifest entry checked (id unique, one kind of pose or none in a bench session,
    an image pair or a stripe list), its pose read in the manifest's format."""
    from .schema import validate

    where = f"{path}: entry {i}"
    if not isinstance(e, dict):
        raise ValueError(f"{where} is not a mapping")
    if True in e or False in e:  # YAML 1.1 reads the keys on/off as booleans
        e = {("on" if k is True else "off" if k is False else k): v for k, v in e.items()}
    if "id" not in e or not str(e["id"]).strip():
        raise ValueError(f"{where} has no id; every entry needs a unique id that pairs its "
                         "files with its readings")
    pid = str(e["id"])
    where = f"{path}: entry {i} (id {pid})"
    validate(e, _entry_schema(), where)
    if pid in seen:
        raise ValueError(f"{where} repeats the id of entry {seen[pid]}")
    seen[pid] = i
    e = dict(e)
    if in_pose_file:
        if "joints" in e or "pose" in e:
            raise ValueError(f"{where} has '{'joints' if 'joints' in e else 'pose'}' but "
                             f"the manifest gives every pose in its pose_file "
                             f"{doc['pose_file']}")
    elif "joints" in e and "pose" in e:
        raise ValueError(f"{where} must have either 'joints' or 'pose' (not both)")
    elif not bench and "joints" not in e and "pose" not in e:
        raise ValueError(f"{where} has neither 'joints' nor 'pose', but other entries "
                         "do: give every entry its robot pose, or none (a bench session: "
                         "the camera and laser plane alone)")
    elif bench and ("joints" in e or "pose" in e):
        raise ValueError(f"{where} has '{'joints' if 'joints' in e else 'pose'}', but "
                         "other entries have no robot pose: give every entry its robot "
                         "pose, or none (a bench session: the camera and laser plane "
                         "alone)")
    if "pose" in e:
        try:
            e["pose"] = pose_from_entry(e["pose"], fmt)
        except ValueError as err:
            raise ValueError(f"{where}: {err}") from None
    has_images = "on" in e or "off" in e
    if has_images == ("stripe" in e):
        raise ValueError(f"{where} must name either an image pair ('on' and 'off') or a "
                         "stripe list ('stripe'), not both or neither")
    if has_images and "on" not in e:
        raise ValueError(f"{where} names a laser-off image but no laser-on image ('on')")
    return e


def is_manifest(path: str | os.PathLike) -> bool:
    """An image manifest: a folder, ``manifest.json``/``.yaml``, or a JSON/YAML file of any
    name whose format is ``hmlvs-images`` (wherever the file puts its ``format`` key), or a
    :class:`Manifest` already read."""
    if isinstance(path, Manifest):
        return True
    path = Path(path)
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
    try:
        doc = read_document(path, "manifest")
    except ValueError:
        return False
    return isinstance(doc, dict) and doc.get("format") == "hmlvs-images"


@dataclass(frozen=True)
class Manifest:
    """An image manifest read and checked once (:func:`load_manifest`). It stands for the
    path it was read from wherever a session's path is taken (``os.fspath``, ``str``);
    :func:`read_manifest` of it reads nothing again and gives copies of its entries and
    document, so no reader changes what the next one sees."""

    source: Path
    entries: list[dict[str, Any]]
    doc: dict[str, Any]
    folder: Path

    def __fspath__(self) -> str:
        return os.fspath(self.source)

    def __str__(self) -> str:
        return str(self.source)


def load_manifest(source: Any) -> Manifest:
    """The manifest at ``source`` (a folder or the file) read and checked once, to be passed
    wherever its path would be (:class:`Manifest`); a :class:`Manifest` is returned as is."""
    if isinstance(source, Manifest):
        return source
    entries, doc, folder = read_manifest(source)
    return Manifest(Path(source), entries, doc, folder)


def read_manifest(source: Any) -> tuple[list[dict[str, Any]], dict[str, Any], Path]:
    """Read and validate a manifest (a folder holding manifest.json, or the file itself, or
    a :class:`Manifest` already read).

    Returns (entries, document, folder).
    """
    if isinstance(source, Manifest):
        return copy.deepcopy(source.entries), copy.deepcopy(source.doc), source.folder
    path = Path(source)
    if path.is_dir():
        candidates = [path / n for n in ("manifest.json", "manifest.yaml", "manifest.yml")]
        path = next((c for c in candidates if c.is_file()), candidates[0])
    if not path.is_file():
        raise ValueError(f"{path}: no such manifest (a folder written by "
                         "hmlvs.simulate.render_session, or its manifest.json)")
    try:
        text = path.read_text(encoding="utf-8")
        doc = parse_text(text, path.suffix.lower() not in (".yaml", ".yml"), path, "manifest")
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, yaml.YAMLError) as e:
        raise ValueError(f"{path}: unreadable manifest ({type(e).__name__}: {e})") from None
    from .schema import validate

    check_format(doc, FORMAT, VERSION, path, "image manifest")
    validate(doc, _manifest_schema(), str(path))
    entries = doc["poses"]
    fmt = PoseFormat.from_dict(doc.get("pose_format"), str(path))
    file_poses = _pose_file(doc, fmt, path) if doc.get("pose_file") is not None else None
    out: list[dict[str, Any]] = []
    seen: dict[str, int] = {}
    # a bench session: no entry has a robot pose (the sensor on a bench, the board moved by
    # hand); decided by the first entry, every other must agree
    bench = file_poses is None and bool(entries) and isinstance(entries[0], dict) and \
        "joints" not in entries[0] and "pose" not in entries[0]
    for i, e in enumerate(entries):
        out.append(_entry(e, i, path, seen, file_poses is not None, bench, fmt, doc))
    if file_poses is not None:
        _pair_poses(out, file_poses, doc["pose_file"], path)
    else:  # the entries' own poses: the pose files' units check
        given = [e["pose"] for e in out if "pose" in e]
        if given:
            from .poses import check_plausible

            check_plausible(path, np.array(given), fmt.unit,
                             "name it as the manifest's pose_format: {{unit: {u}}}")
    return out, doc, path.parent


def _pose_file(doc: dict[str, Any], fmt: PoseFormat, path: Path
               ) -> tuple[list[str] | None, np.ndarray]:
    """The manifest's ``pose_file`` read with its ``pose_format``: (ids or None, poses in mm)."""
    name = doc["pose_file"]
    if not isinstance(name, str) or not name.strip():
        raise ValueError(f"{path}: 'pose_file' must be a file name, got {name!r}")
    file = Path(name)
    file = file if file.is_absolute() else path.parent / file
    if not file.is_file():
        raise ValueError(f"{path}: the pose_file {file} does not exist")
    raw = doc.get("pose_format") or {}
    unit = raw.get("unit") if file.suffix.lower() in (".yaml", ".yml") else fmt.unit
    return read_poses(file, quaternion_order=fmt.quaternion_order, unit=unit)


def _pair_poses(entries: list[dict[str, Any]], file_poses: tuple[list[str] | None, np.ndarray],
                name: str, path: Path) -> None:
    """Give every entry its pose from the pose file: by id when the file has an id column,
    else by row order (then the counts must match)."""
    ids, poses = file_poses
    if ids is None:
        if len(poses) != len(entries):
            raise ValueError(f"{path}: the pose_file {name} has {len(poses)} poses but the "
                             f"manifest has {len(entries)} entries; without an id column the "
                             "rows pair with the entries in order, so the counts must match")
        for e, pose in zip(entries, poses):
            e["pose"] = pose
        return
    row = {pid: k for k, pid in enumerate(ids)}
    missing = [str(e["id"]) for e in entries if str(e["id"]) not in row]
    if missing:
        raise ValueError(f"{path}: the pose_file {name} has no pose for the id(s) "
                         f"{', '.join(missing[:5])}{' ...' if len(missing) > 5 else ''}")
    extra = sorted(set(ids) - {str(e["id"]) for e in entries})
    if extra:
        raise ValueError(f"{path}: the pose_file {name} has poses for id(s) no entry has: "
                         f"{', '.join(extra[:5])}{' ...' if len(extra) > 5 else ''}")
    for e in entries:
        e["pose"] = poses[row[str(e["id"])]]


def read_stripe_list(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """A stripe list: CSV with columns u, v and optionally intensity (a header line is allowed).

    Returns (pixels (n, 2), intensity (n,)); raises ValueError naming the file.
    """
    try:
        # ndmin=2: a file of one column stays one column (n x 1), not one row of n pixels
        import warnings

        with warnings.catch_warnings():  # an empty file: said below, in a sentence
            warnings.simplefilter("ignore")
            arr = np.genfromtxt(path, delimiter=",", dtype=float, ndmin=2,
                                encoding="utf-8-sig")
    except (OSError, ValueError) as e:
        raise ValueError(f"the stripe list {path} cannot be read ({e})") from None
    arr = arr[~np.all(np.isnan(arr), axis=1)] if arr.size else arr  # a header reads as NaN
    if arr.ndim != 2 or arr.shape[1] not in (2, 3) or arr.shape[0] == 0:
        raise ValueError(f"the stripe list {path} must hold rows of u, v[, intensity]"
                         + (f"; its rows have {arr.shape[1]} column"
                            f"{'' if arr.shape[1] == 1 else 's'}"
                            if arr.ndim == 2 and arr.shape[0] and arr.shape[1] not in (2, 3)
                            else ""))
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"the stripe list {path} has a non-numeric or missing value")
    inten = arr[:, 2] if arr.shape[1] == 3 else np.zeros(arr.shape[0])
    return arr[:, :2].copy(), inten


def write_png(path: Path, image: np.ndarray) -> None:
    import cv2
    ok, buf = cv2.imencode(".png", image)
    if not ok:
        raise ValueError(f"could not encode {path.name} as PNG")
    with atomic_write(path, "wb") as fh:
        fh.write(buf.tobytes())


def write_image_manifest(out_dir: str | os.PathLike, ids: list[str], on: list[np.ndarray],
                         off: list[np.ndarray], joints: np.ndarray,
                         image_size: tuple[int, int], robot_name: str,
                         files: dict[str, Any] | None = None, **extra: Any) -> Path:
    """Write ``<id>_on.png``, ``<id>_off.png`` per pose and ``manifest.json`` (format
    ``hmlvs-images``: pose ids, image files, joint readings in rad) into ``out_dir``, all of them or
    none (:func:`hmlvs._io.atomic_folder`). ``extra`` entries (JSON-able) go into the manifest's
    top level; ``files`` maps further file names to functions writing them
    (given a binary file). Returns the manifest's path."""
    entries = []
    with atomic_folder(out_dir) as tmp:  # all files or none
        for name, write in (files or {}).items():  # e.g. truth.npz: write(binary file)
            with atomic_write(tmp / name, "wb") as fh:
                write(fh)
        for i, pid in enumerate(ids):
            names = {"on": f"{pid}_on.png", "off": f"{pid}_off.png"}
            write_png(tmp / names["on"], on[i])
            write_png(tmp / names["off"], off[i])
            entries.append({"id": pid, **names,
                            "joints": np.asarray(joints[i], float).tolist()})
        doc = {"format": FORMAT, "version": VERSION,
               "image_size": list(image_size), "joint_unit": "rad", "robot": robot_name,
               **extra, "poses": entries}
        with atomic_write(tmp / NAME, "w") as fh:
            json.dump(doc, fh, indent=1)
    manifest = Path(out_dir) / NAME
    return manifest
