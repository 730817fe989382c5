"""Robot poses as real controllers export them: CSV or YAML files of base_from_hand poses.

A pose is written as one of three forms (see docs/file-formats.md, "Pose files"):

- ``matrix``: the 4x4 base_from_hand transform, 16 numbers row-major (or nested lists in YAML);
- ``quaternion``: position x, y, z and a unit quaternion, whose order (``xyzw`` or ``wxyz``)
  must be named: it is never guessed;
- ``rotation_vector``: position x, y, z and a rotation vector rx, ry, rz (axis times angle,
  rad), the form Universal Robots controllers export (positions in metres).

The length unit of the positions (``m`` or ``mm``) must be named too. Whatever the file's
unit, poses are returned in mm.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
import os
from pathlib import Path
from typing import Any, Literal, Sequence

import numpy as np
import yaml

from .._io import atomic_write, existing_file, parse_text

# re-exported: hmlvs.data.poses.rotation_* were defined here first
from ..geometry.transforms import (
    rotation_from_vector,  # noqa: F401
    rotation_to_quaternion,
    rotation_to_vector,
)

Rotation = Literal["matrix", "quaternion", "rotation_vector"]
ROTATIONS: tuple[str, ...] = ("matrix", "quaternion", "rotation_vector")
UNITS: dict[str, float] = {"mm": 1.0, "m": 1000.0}
QUATERNION_ORDERS: tuple[str, ...] = ("xyzw", "wxyz")
#: numbers per row of each form (without an id column)
COLUMNS: dict[str, int] = {"matrix": 16, "quaternion": 7, "rotation_vector": 6}
#: a quaternion whose norm differs from 1 by more than this is refused, not normalised
QUATERNION_NORM_TOLERANCE = 5e-3


@dataclass(frozen=True)
class PoseFormat:
    """How the poses of a file or manifest are written: length unit and quaternion order.

    unit : "mm" or "m", the unit of the positions (and of a matrix's translation column)
    quaternion_order : "xyzw" or "wxyz"; None when no quaternion is used (a quaternion then
        is an error: the order is never guessed)
    """

    unit: str = "mm"
    quaternion_order: str | None = None

    def __post_init__(self) -> None:
        if self.unit not in UNITS:
            raise ValueError(f"unknown length unit {self.unit!r} for poses; name 'mm' or 'm'")
        if self.quaternion_order is not None and self.quaternion_order not in QUATERNION_ORDERS:
            raise ValueError(f"unknown quaternion order {self.quaternion_order!r}; name 'xyzw' "
                             "or 'wxyz'")

    @classmethod
    def from_dict(cls, d: Any, source: str) -> "PoseFormat":
        """From a manifest's or pose file's ``pose_format`` mapping (None: the defaults)."""
        if d is None:
            return cls()
        if not isinstance(d, dict):
            raise ValueError(f"{source}: 'pose_format' must be a mapping {{unit: m|mm, "
                             f"quaternion_order: xyzw|wxyz}}, got {d!r}")
        unknown = sorted(set(d) - {"unit", "quaternion_order"})
        if unknown:
            raise ValueError(f"{source}: 'pose_format' has unknown key(s) {unknown}; it takes "
                             "unit and quaternion_order")
        try:
            return cls(unit=d.get("unit", "mm"), quaternion_order=d.get("quaternion_order"))
        except ValueError as e:
            raise ValueError(f"{source}: pose_format: {e}") from None

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"unit": self.unit}
        if self.quaternion_order is not None:
            d["quaternion_order"] = self.quaternion_order
        return d


# ------------------------------------------------------------------------------------------
# rotations


def rotation_from_quaternion(q: Any, order: str) -> np.ndarray:
    """Unit quaternion in ``order`` ("xyzw" or "wxyz") -> 3x3 rotation matrix.

    The quaternion is normalised; a norm far from 1 (more than 0.5 %) raises ValueError.
    """
    if order not in QUATERNION_ORDERS:
        raise ValueError(f"the quaternion order must be named as 'xyzw' or 'wxyz', got "
                         f"{order!r}")
    q = np.asarray(q, dtype=float).reshape(4)
    x, y, z, w = q if order == "xyzw" else (q[1], q[2], q[3], q[0])
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if not abs(n - 1.0) <= QUATERNION_NORM_TOLERANCE:
        raise ValueError(f"the quaternion {q.tolist()} ({order}) has norm {n:.6g}, not 1")
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


# ------------------------------------------------------------------------------------------
# one pose


def _numbers(value: Any, n: int | None, what: str) -> np.ndarray:
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be numbers, got {value!r}") from None
    if n is not None and a.shape != (n,):
        raise ValueError(f"{what} must be {n} numbers, got {np.shape(value)} "
                         f"({a.size} values)")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{what} has a value that is not finite: {a.tolist()}")
    return a


def _check_rigid(pose: np.ndarray) -> np.ndarray:
    if not np.allclose(pose[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
        raise ValueError(f"the last row of a pose must be 0 0 0 1, got {pose[3].tolist()}")
    r = pose[:3, :3]
    err = float(np.abs(r.T @ r - np.eye(3)).max())
    if err > 1e-4 or float(np.linalg.det(r)) < 0:
        raise ValueError(f"the rotation part is not a rotation matrix (R^T R differs from I by "
                         f"{err:.3g}, det {float(np.linalg.det(r)):.3g})")
    # a matrix printed with a few decimals: the nearest rotation, an exact last row
    u, _, vt = np.linalg.svd(r)
    pose = pose.copy()
    pose[:3, :3] = u @ vt
    pose[3] = [0.0, 0.0, 0.0, 1.0]
    return pose


def pose_from_row(values: Any, rotation: str, fmt: PoseFormat) -> np.ndarray:
    """One row of numbers in ``rotation`` form (16, 7 or 6 numbers) -> a 4x4 pose in mm."""
    if rotation not in COLUMNS:
        raise ValueError(f"unknown rotation form {rotation!r}; use one of {', '.join(ROTATIONS)}")
    n = COLUMNS[rotation]
    v = _numbers(values, None, "the pose").reshape(-1)
    if v.size != n:
        raise ValueError(f"a pose in {rotation} form has {n} numbers, got {v.size}")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"the pose has a value that is not finite: {v.tolist()}")
    pose = np.eye(4)
    if rotation == "matrix":
        pose = v.reshape(4, 4)
    elif rotation == "quaternion":
        if fmt.quaternion_order is None:
            raise ValueError("the pose has a quaternion but its order is not named (it is "
                             "never guessed): give quaternion_order xyzw or wxyz (in a "
                             "manifest: pose_format: {quaternion_order: xyzw})")
        pose[:3, :3] = rotation_from_quaternion(v[3:], fmt.quaternion_order)
        pose[:3, 3] = v[:3]
    else:
        pose[:3, :3] = rotation_from_vector(v[3:])
        pose[:3, 3] = v[:3]
    pose = _check_rigid(pose)
    pose[:3, 3] *= UNITS[fmt.unit]
    return pose


# ------------------------------------------------------------------------------------------
# schemas (hmlvs.data.schema): the forms a pose and a YAML pose file take


def _vector(n: int, what: str) -> Any:
    from . import schema as sc

    return sc.Field("list", what, length=n, items=sc.number())


_POSE_FORMS = ("a 4x4 base_from_hand matrix, or a mapping {position: [x, y, z], quaternion: "
               "[4 numbers] | rotation_vector: [rx, ry, rz]}")


def _pose_schema() -> Any:
    """A ``pose`` value: a 4x4 matrix (nested lists) or a position-and-rotation mapping."""
    from . import schema as sc

    mapping = sc.Field("struct", "a pose mapping", extra="error", keys={
        "position": _vector(3, "the position [x, y, z]"),
        "quaternion": _vector(4, "a quaternion of 4 numbers"),
        "rotation_vector": _vector(3, "a rotation vector [rx, ry, rz]")})
    matrix = sc.matrix(4, 4, "a 4x4 base_from_hand matrix")
    return sc.Field("select", _POSE_FORMS, select=lambda v: mapping if isinstance(v, dict)
                    else matrix if isinstance(v, list) else None)


def _file_schema(form: str) -> Any:
    """A YAML pose file: a list of poses (``form="list"``) or a mapping ``{pose_format,
    poses}`` (``form="mapping"``). A pose is a row of numbers, a 4x4 matrix or a mapping
    ``{id, position, quaternion | rotation_vector}`` / ``{id, pose}``."""
    from . import schema as sc

    mapping = sc.Field("struct", "a pose mapping", extra="error", keys={
        "id": sc.identifier(), "pose": _pose_schema(),
        "position": _vector(3, "the position [x, y, z]"),
        "quaternion": _vector(4, "a quaternion of 4 numbers"),
        "rotation_vector": _vector(3, "a rotation vector [rx, ry, rz]")})
    matrix = sc.matrix(4, 4, "a 4x4 base_from_hand matrix")
    row = sc.Field("list", "a row of 16, 7 or 6 numbers", items=sc.number())

    def form_of(v: Any) -> Any:
        if isinstance(v, dict):
            return mapping
        if isinstance(v, list):
            return matrix if v and all(isinstance(x, list) for x in v) else row
        return None

    pose = sc.Field("select", "a pose: a row of 16, 7 or 6 numbers, a 4x4 matrix, or a mapping "
                    "{id, position, quaternion | rotation_vector} or {id, pose}", select=form_of)
    poses = sc.Field("list", "a list of poses", items=pose, check=sc.non_empty("pose"))
    if form == "list":
        return poses
    return sc.Field("struct", "a pose file: a list of poses, or a mapping {pose_format, poses}",
                    required=("poses",), extra="error", keys={
                        "poses": poses,
                        "pose_format": sc.Field("struct", "a mapping {unit: m|mm, "
                                                "quaternion_order: xyzw|wxyz}", extra="error",
                                                nullable=True, keys={
                                                    "unit": sc.text(choices=tuple(UNITS)),
                                                    "quaternion_order": sc.text(
                                                        choices=QUATERNION_ORDERS)})})


def _as_lists(value: Any) -> Any:
    """Arrays and tuples (poses given in code) as the lists a YAML file would hold."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [_as_lists(v) for v in value]
    if isinstance(value, dict):
        return {k: _as_lists(v) for k, v in value.items()}
    if isinstance(value, np.generic):
        return value.item()
    return value


def pose_from_entry(value: Any, fmt: PoseFormat, path: str = "pose") -> np.ndarray:
    """A manifest entry's ``pose`` -> a 4x4 base_from_hand pose in mm.

    ``value`` is a 4x4 matrix (nested lists), or a mapping ``{position: [x, y, z],
    quaternion: [4 numbers]}`` or ``{position: [x, y, z], rotation_vector: [rx, ry, rz]}``;
    positions in ``fmt.unit``. Its form is checked by the schema (``pose.position: must be
    the position [x, y, z] of 3 items``, ``path`` naming the value); then ValueError says
    what else is wrong.
    """
    from .schema import validate

    value = _as_lists(value)
    validate(value, _pose_schema(), "", path)
    if isinstance(value, dict):
        keys = set(value)
        rot_keys = keys & {"quaternion", "rotation_vector"}
        unknown = keys - {"position", "quaternion", "rotation_vector"}
        if unknown or "position" not in keys or len(rot_keys) != 1:
            raise ValueError("a pose mapping is {position: [x, y, z], quaternion: [...]} or "
                             f"{{position: [x, y, z], rotation_vector: [rx, ry, rz]}}, got keys "
                             f"{sorted(keys)}")
        pos = _numbers(value["position"], 3, "'position'")
        if "quaternion" in rot_keys:
            q = _numbers(value["quaternion"], 4, "'quaternion'")
            return pose_from_row(np.concatenate([pos, q]), "quaternion", fmt)
        rv = _numbers(value["rotation_vector"], 3, "'rotation_vector'")
        return pose_from_row(np.concatenate([pos, rv]), "rotation_vector", fmt)
    try:
        m = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        m = None
    if m is None or m.shape != (4, 4):
        raise ValueError("'pose' must be a finite 4x4 base_from_hand matrix, or a mapping "
                         "with position and quaternion (or rotation_vector)")
    return pose_from_row(m.reshape(16), "matrix", fmt)


# ------------------------------------------------------------------------------------------
# files


def _form_of(ncols: int, rotation: str | None, where: str) -> str:
    if rotation is not None:
        if rotation not in COLUMNS:
            raise ValueError(f"unknown rotation form {rotation!r}; use one of "
                             f"{', '.join(ROTATIONS)}")
        if COLUMNS[rotation] != ncols:
            raise ValueError(f"{where} has {ncols} numbers per row, but a pose in {rotation} "
                             f"form has {COLUMNS[rotation]}")
        return rotation
    for name, n in COLUMNS.items():
        if n == ncols:
            return name
    raise ValueError(f"{where} has {ncols} numbers per row; a pose row has 16 (4x4 matrix, row "
                     "major), 7 (x, y, z and a quaternion) or 6 (x, y, z, rx, ry, rz)")


def _column_names(form: str, fmt: PoseFormat) -> list[str]:
    """The header names of a form's columns, in the order :func:`pose_from_row` reads them."""
    if form == "matrix":
        return [f"m{r}{c}" for r in range(4) for c in range(4)]
    if form == "rotation_vector":
        return ["x", "y", "z", "rx", "ry", "rz"]
    return ["x", "y", "z"] + [f"q{a}" for a in (fmt.quaternion_order or "xyzw")]


def _columns_by_name(names: list[str], form: str, fmt: PoseFormat) -> list[int] | None:
    """Where each of the form's columns is in a header of ``names`` (lower case, without the
    id column), when the header names exactly the form's columns; None otherwise (then the
    columns are read in their order)."""
    want = _column_names(form, fmt)
    if sorted(names) != sorted(want) or len(set(names)) != len(names):
        return None
    return [names.index(n) for n in want]


def _is_number(text: str) -> bool:
    try:
        float(text)
        return True
    except ValueError:
        return False


def _read_csv(path: Path, rotation: str | None, fmt: PoseFormat
              ) -> tuple[list[str] | None, np.ndarray]:
    try:
        text = path.read_text(encoding="utf-8-sig")  # a byte-order mark (Excel's) is no text
    except (OSError, UnicodeDecodeError) as e:
        raise ValueError(f"{path}: unreadable pose file ({type(e).__name__}: {e})") from None
    rows: list[tuple[int, list[str]]] = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        rows.append((lineno, [f.strip() for f in s.replace(";", ",").split(",")]))
    if not rows:
        raise ValueError(f"{path}: the pose file holds no poses")
    id_col = None
    header_line = None
    names: list[str] = []
    if not any(_is_number(f) for f in rows[0][1]):  # a header: names, no numbers
        header_line, header = rows.pop(0)
        names = [h.lower() for h in header]
        if names.count("id") > 1:
            raise ValueError(f"{path}: line {header_line}: the header names 'id' twice")
        id_col = names.index("id") if "id" in names else None
        if not rows:
            raise ValueError(f"{path}: the pose file holds a header but no poses")
        quat = [n for n in names if n in ("qx", "qy", "qz", "qw")]
        if len(quat) == 4 and fmt.quaternion_order is not None \
                and "".join(n[1] for n in quat) != fmt.quaternion_order:
            raise ValueError(f"{path}: line {header_line}: the header orders the quaternion "
                             f"{','.join(quat)} but quaternion_order {fmt.quaternion_order} "
                             "was given")
    width = len(rows[0][1])
    ncols = width - (id_col is not None)
    form = _form_of(ncols, rotation, str(path))
    # a header of known names is read by name, in any column order
    order = None if header_line is None else _columns_by_name(
        [n for k, n in enumerate(names) if k != id_col], form, fmt)
    ids: list[str] = []
    poses = []
    for lineno, fields in rows:
        where = f"{path}: line {lineno}"
        if len(fields) != width:
            raise ValueError(f"{where} has {len(fields)} columns, the file's rows have {width}")
        if id_col is not None:
            pid = fields[id_col]
            if not pid:
                raise ValueError(f"{where} has an empty id")
            ids.append(pid)
            fields = fields[:id_col] + fields[id_col + 1:]
        bad = [f for f in fields if not _is_number(f)]
        if bad:
            raise ValueError(f"{where}: {bad[0]!r} is not a number")
        values = np.array([float(f) for f in fields])
        if order is not None:
            values = values[order]
        if not np.all(np.isfinite(values)):
            raise ValueError(f"{where} has a value that is not finite (NaN or inf): "
                             f"{', '.join(fields)}")
        try:
            poses.append(pose_from_row(values, form, fmt))
        except ValueError as e:
            raise ValueError(f"{where}: {e}") from None
    return (ids if id_col is not None else None), np.array(poses).reshape(-1, 4, 4)


def _read_yaml(path: Path, rotation: str | None, fmt: PoseFormat, explicit: dict[str, Any]
               ) -> tuple[list[str] | None, np.ndarray, str]:
    try:
        doc = parse_text(path.read_text(encoding="utf-8-sig"), False, path, "pose file")
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as e:
        raise ValueError(f"{path}: unreadable pose file ({type(e).__name__}: {e})") from None
    from .schema import validate

    if isinstance(doc, list):
        validate(doc, _file_schema("list"), str(path), "poses")
    elif isinstance(doc, dict):
        validate(doc, _file_schema("mapping"), str(path))
    entries = doc
    if isinstance(doc, dict):
        if "pose_format" in doc:
            own = PoseFormat.from_dict(doc["pose_format"], str(path))
            raw = doc["pose_format"] or {}
            for key, value in explicit.items():
                if value is not None and raw.get(key) not in (None, value):
                    raise ValueError(f"{path}: the file's pose_format says {key} "
                                     f"{raw.get(key)!r} but {value!r} was given")
            fmt = PoseFormat(unit=explicit["unit"] or own.unit,
                             quaternion_order=explicit["quaternion_order"]
                             or own.quaternion_order)
        elif explicit["unit"] is None:
            raise ValueError(_NO_UNIT.format(path=path))
        entries = doc.get("poses")
    elif explicit["unit"] is None:
        raise ValueError(_NO_UNIT.format(path=path))
    if not isinstance(entries, list) or not entries:
        raise ValueError(f"{path}: a YAML pose file is a list of poses, or a mapping with a "
                         "'poses' list (and optionally 'pose_format')")
    ids: list[str] = []
    poses = []
    for i, e in enumerate(entries):
        where = f"{path}: pose {i}"
        try:
            if isinstance(e, dict):
                if "id" in e:
                    ids.append(str(e["id"]))
                body = {k: v for k, v in e.items() if k != "id"}
                if set(body) == {"pose"}:
                    body = body["pose"]
                poses.append(pose_from_entry(body, fmt, path=""))
            else:
                arr = _numbers(e, None, "the pose")
                if arr.shape == (4, 4):
                    poses.append(pose_from_row(arr.reshape(16), "matrix", fmt))
                else:
                    poses.append(pose_from_row(arr, _form_of(arr.size, rotation, where), fmt))
        except ValueError as err:
            where += f" (id {e['id']})" if isinstance(e, dict) and "id" in e else ""
            raise ValueError(f"{where}: {err}") from None
    if ids and len(ids) != len(entries):
        raise ValueError(f"{path}: some poses have an id and some do not")
    return (ids or None), np.array(poses).reshape(-1, 4, 4), fmt.unit


_NO_UNIT = ("{path}: the length unit of the positions is not named: pass unit='m' or 'mm' "
            "(pose_format: {{unit: m}} in a manifest)")


def check_plausible(path: Any, poses: np.ndarray, unit: str, how: str = "name unit {u!r}"
                     ) -> None:
    """A hand a few mm from the base in every pose was given in metres, and one kilometres
    away in millimetres: refuse both rather than calibrate with a wrong unit. ``how`` says how
    to name the unit ({u}: the unit to name)."""
    reach = np.linalg.norm(np.asarray(poses, float).reshape(-1, 4, 4)[:, :3, 3], axis=1)
    med = float(np.median(reach)) if reach.size else 0.0
    if unit == "mm" and 0.0 < med < 5.0:
        raise ValueError(f"{path}: the hand positions are {med:.3g} mm from the robot base "
                         f"(median): they look like metres; {how.format(u='m')}")
    if unit == "m" and med > 50_000.0:
        raise ValueError(f"{path}: the hand positions are {med / 1000:.3g} m from the robot "
                         f"base (median): they look like millimetres; {how.format(u='mm')}")


def read_poses(path: str | os.PathLike, *, rotation: str | None = None,
               quaternion_order: str | None = None, unit: str | None = None
               ) -> tuple[list[str] | None, np.ndarray]:
    """Read base_from_hand poses from a CSV (``.csv``, ``.txt``) or YAML (``.yaml``/``.yml``).

    CSV: one pose per line, comma-separated (``#`` comments and a header line are allowed; a
    header column named ``id`` holds pose ids). Each row is 16 numbers (4x4 row-major), 7
    (x, y, z and a quaternion) or 6 (x, y, z, rx, ry, rz: a rotation vector in rad, the
    Universal Robots form). YAML: a list of rows, nested 4x4 lists or mappings ``{id, position,
    quaternion | rotation_vector}`` / ``{id, pose: 4x4}``, or a mapping ``{pose_format: {...},
    poses: [...]}``.

    Parameters
    ----------
    rotation : "matrix", "quaternion" or "rotation_vector"; by default the form follows from
        the number of columns (16, 7, 6), which is unambiguous
    quaternion_order : "xyzw" or "wxyz": required when the rows hold quaternions
    unit : "m" or "mm", the unit of the positions: required (a YAML file may name it in its
        ``pose_format``)

    Returns
    -------
    (ids or None, poses (n, 4, 4) in mm). Every problem raises ValueError naming the file, the
    line (or pose) and what is wrong.
    """
    path = existing_file(path, "pose file")
    explicit = {"unit": unit, "quaternion_order": quaternion_order}
    try:
        fmt = PoseFormat(unit=unit or "mm", quaternion_order=quaternion_order)
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from None
    if rotation is not None and rotation not in COLUMNS:
        raise ValueError(f"{path}: unknown rotation form {rotation!r}; use one of "
                         f"{', '.join(ROTATIONS)}")
    if path.suffix.lower() in (".yaml", ".yml"):
        ids, poses, unit_used = _read_yaml(path, rotation, fmt, explicit)
    else:
        if unit is None:
            raise ValueError(_NO_UNIT.format(path=path))
        ids, poses = _read_csv(path, rotation, fmt)
        unit_used = unit
    if ids is not None:
        seen: dict[str, int] = {}
        for i, pid in enumerate(ids):
            if pid in seen:
                raise ValueError(f"{path}: pose {i} repeats the id {pid!r} of pose {seen[pid]}")
            seen[pid] = i
    check_plausible(path, poses, unit_used)
    return ids, poses


def write_poses(path: str | os.PathLike, poses: Any, ids: Sequence[str] | None = None, *,
                rotation: str = "quaternion", quaternion_order: str = "xyzw",
                unit: str = "mm") -> Path:
    """Write base_from_hand poses (mm) atomically as CSV (``.csv``) or YAML (``.yaml``/``.yml``).

    CSV rows have a header (``id,x,y,z,qx,qy,qz,qw``, ``id,x,y,z,rx,ry,rz`` or ``id,m00..m33``;
    no id column without ``ids``); the YAML form holds its ``pose_format``. Positions are
    written in ``unit``. :func:`read_poses` with the same options reads the file back.
    """
    path = Path(path)
    p = np.asarray(poses, dtype=float)
    if p.ndim == 2:
        p = p[None]
    if p.ndim != 3 or p.shape[1:] != (4, 4):
        raise ValueError(f"poses must have shape (n, 4, 4), got {np.shape(poses)}")
    for i in range(p.shape[0]):
        try:
            _check_rigid(_numbers(p[i], None, "the pose"))
        except ValueError as e:
            raise ValueError(f"pose {i}: {e}") from None
    fmt = PoseFormat(unit=unit, quaternion_order=quaternion_order
                     if rotation == "quaternion" else None)
    if rotation not in COLUMNS:
        raise ValueError(f"unknown rotation form {rotation!r}; use one of {', '.join(ROTATIONS)}")
    if ids is not None:
        ids = [str(x) for x in ids]
        if len(ids) != p.shape[0]:
            raise ValueError(f"{len(ids)} ids for {p.shape[0]} poses")
        if len(set(ids)) != len(ids):
            raise ValueError("pose ids must be unique")
    scale = 1.0 / UNITS[unit]
    rows = []
    for pose in p:
        t = (pose[:3, 3] * scale).tolist()
        if rotation == "matrix":
            m = pose.copy()
            m[:3, 3] *= scale
            rows.append(m.reshape(16).tolist())
        elif rotation == "quaternion":
            rows.append(t + rotation_to_quaternion(pose[:3, :3], quaternion_order).tolist())
        else:
            rows.append(t + rotation_to_vector(pose[:3, :3]).tolist())
    suffix = path.suffix.lower()
    if suffix == ".csv":
        if rotation == "matrix":
            head = [f"m{r}{c}" for r in range(4) for c in range(4)]
        elif rotation == "quaternion":
            head = ["x", "y", "z"] + [f"q{c}" for c in quaternion_order]
        else:
            head = ["x", "y", "z", "rx", "ry", "rz"]
        with atomic_write(path) as fh:
            fh.write(",".join((["id"] if ids is not None else []) + head) + "\n")
            for i, row in enumerate(rows):
                fh.write(",".join(([ids[i]] if ids is not None else [])
                                  + [repr(float(v)) for v in row]) + "\n")
    elif suffix in (".yaml", ".yml"):
        entries: list[Any] = []
        for i, row in enumerate(rows):
            if rotation == "matrix":
                e: dict[str, Any] = {"pose": np.reshape(row, (4, 4)).tolist()}
            elif rotation == "quaternion":
                e = {"position": row[:3], "quaternion": row[3:]}
            else:
                e = {"position": row[:3], "rotation_vector": row[3:]}
            entries.append({"id": ids[i], **e} if ids is not None else e)
        doc = {"pose_format": fmt.to_dict(), "poses": entries}
        with atomic_write(path) as fh:
            yaml.safe_dump(doc, fh, sort_keys=False, default_flow_style=None)
    else:
        raise ValueError(f"{path}: pose files are written as .csv, .yaml or .yml")
    return path
