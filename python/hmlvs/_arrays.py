"""Shape and value checks shared by the public functions (clear ValueErrors, no copies), and
the robust spread several fits use."""

from __future__ import annotations

from typing import Any

import numpy as np

from . import _core
from .models.params import NUM_PARAMS, Parameters


def as_params(params: Any) -> np.ndarray:
    """A parameter vector from a :class:`Parameters`, a sequence or a mapping."""
    if isinstance(params, Parameters):
        return params.to_array()
    if isinstance(params, dict):
        return Parameters.from_dict(params).to_array()
    arr = np.asarray(params, dtype=float).reshape(-1)
    if arr.shape != (NUM_PARAMS,):
        raise ValueError(f"params must have {NUM_PARAMS} values, got {arr.size}")
    return arr


def as_matrix(a: Any, cols: int, name: str, allow_nan: bool = False) -> np.ndarray:
    """A C-contiguous float64 (m x cols) array; a single row may be given as a vector."""
    arr = np.asarray(a, dtype=np.float64)
    if arr.ndim == 1 and arr.shape[0] == cols:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != cols:
        raise ValueError(f"{name} must have shape (m, {cols}), got {arr.shape}")
    if not allow_nan:
        bad = ~np.isfinite(arr).all(axis=1)
        if bad.any():
            raise ValueError(f"{name} row {int(np.argmax(bad))} is not finite (NaN or inf)")
    return np.ascontiguousarray(arr)


def as_poses(a: Any, name: str = "poses") -> np.ndarray:
    """base_from_hand poses as a C-contiguous (m, 16) view of an (m, 4, 4) array."""
    arr = np.asarray(a, dtype=np.float64)
    if arr.ndim == 2 and arr.shape == (4, 4):
        arr = arr[None]
    if arr.ndim != 3 or arr.shape[1:] != (4, 4):
        raise ValueError(f"{name} must have shape (m, 4, 4), got {arr.shape}")
    return np.ascontiguousarray(arr).reshape(-1, 16)


def same_rows(**arrays: np.ndarray) -> int:
    items = list(arrays.items())
    n0, a0 = items[0]
    for n, a in items[1:]:
        if a.shape[0] != a0.shape[0]:
            raise ValueError(f"{n0} has {a0.shape[0]} rows but {n} has {a.shape[0]}")
    return a0.shape[0]


def check_transform(t: Any, name: str, tol: float = _core.RIGID_TOLERANCE) -> np.ndarray:
    """A 4x4 rigid transform (float64 copy): finite, orthonormal rotation with det +1 (to
    ``tol``; by default the C++ core's, 1e-6, which its own checks use), last row [0 0 0 1]; a
    ValueError naming ``name`` otherwise."""
    try:
        m = np.array(t, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a 4x4 matrix of numbers, got {t!r}") from None
    if m.shape != (4, 4):
        raise ValueError(f"{name} must be a 4x4 matrix, got shape {m.shape}")
    if not np.all(np.isfinite(m)):
        raise ValueError(f"{name} is not finite (NaN or inf)")
    r = m[:3, :3]
    if (np.abs(r @ r.T - np.eye(3)).max() > tol or np.linalg.det(r) < 0
            or np.abs(m[3] - [0, 0, 0, 1]).max() > tol):
        raise ValueError(f"{name} is not a rigid transform (its rotation must be orthonormal with "
                         "determinant +1 and its last row [0 0 0 1])")
    return m


def robust_sigma(r: np.ndarray) -> float:
    """1.4826 x the median absolute deviation of the finite values of ``r`` (the standard
    deviation for normal data, unmoved by outliers); NaN if there are none."""
    r = r[np.isfinite(r)]
    if r.size == 0:
        return float("nan")
    return float(1.4826 * np.median(np.abs(r - np.median(r))))
