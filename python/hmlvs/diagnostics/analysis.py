"""The identifiability analysis' core: the residual Jacobian (paper parameters, or the
camera rotation on SO(3) in place of the Euler angles), its SVD, and the report types.
:mod:`hmlvs.diagnostics.identifiability` names the directions and writes the report."""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Any, Iterable

import numpy as np

from ..data.dataset import Dataset
from ..models.paper import hand_from_camera, points_in_camera, residual_jacobian
from ..models.params import (
    NAMES,
    NUM_PARAMS,
    TABLE2_LOWER,
    TABLE2_UPPER,
    Bounds,
    Parameters,
    fixed_mask,
    param_index,
)

#: A singular value below NULL_TOL times the largest one spans a null direction. The
#: Jacobian is exact (automatic differentiation), so the known exact degeneracies come out at
#: 1e-16..1e-18 relative, while on the paper's data the smallest determined singular value is
#: about 1e-3 relative: 1e-9 separates them with many decades to spare either way.
NULL_TOL = 1e-9
#: A singular value below WEAK_TOL times the largest one (and above NULL_TOL) spans a weak
#: direction: a unit-range change along it moves the residuals 10,000 times less than the
#: best determined direction. With k = 0.002 the directions that are exact at k = 0 sit at
#: 1e-5..1e-4; the determined ones on the paper's data at >= 1.7e-3.
WEAK_TOL = 1e-4
#: A known direction (exact only at k = 0, say) whose unit vector lies this much inside the
#: null/weak subspace is reported as weak even if its own gain is above WEAK_TOL. With
#: k = 0.002 the camera-y shift is 0.999 inside the two weak directions (gain 5e-4 itself).
IN_FLAT = 0.99
#: omega + varphi is reported as an identifiable combination when |phi| is below this (rad).
GIMBAL_PHI = 0.1
#: Data checks (see :func:`data_warnings`).
MIN_POINTS_PER_PARAMETER = 3
SAME_POSE_DEGREES = 2.0
SAME_POSE_MM = 10.0
COLLINEAR_PIXELS = 1.0

ROTATION_NAMES = ("rot_x", "rot_y", "rot_z")
EULER_INDEX = (param_index("omega"), param_index("phi"), param_index("varphi"))
ROTATION_DESCRIPTION = {"rot_x": "rotation of the camera about its x axis",
                         "rot_y": "rotation of the camera about its y axis",
                         "rot_z": "rotation of the camera about its z axis"}
# What a user can know before calibrating, in the order they are worth fixing.
PRIOR_KNOWN = ("Su", "Sv", "Cu", "Cv", "f", "k")



GLOSSARY = "docs/glossary.md"


@dataclass(frozen=True)
class Direction:
    """A direction in parameter space along which the residuals (nearly) do not change.

    Attributes
    ----------
    name : a human-readable name ("scale gauge", "ZYZ gimbal lock", ...)
    kind : "scale_gauge", "gimbal_lock", "camera_y_shift", a "+"-joined mix of these when
        fixing a parameter leaves only their combination, or "unnamed" (found by the SVD)
    status : "null" (exact), "weak", "determined" or "removed" (a parameter it needs is held
        fixed); only null and weak directions are listed in
        :attr:`IdentifiabilityReport.directions`
    gain : how much a unit step along the direction (in range-scaled coordinates) changes the
        residuals, relative to the best determined direction (a relative singular value)
    loadings : the unit direction in range-scaled coordinates, by coordinate name; rotation
        coordinates are ``rot_x, rot_y, rot_z`` (camera axes) or the Euler angles
    tangent : the direction in the coordinates' own units (14 values, zero for fixed ones,
        in the order of :attr:`IdentifiabilityReport.coordinates`), scaled so that its
        largest scaled component is 1
    parametrization_only : True for the gimbal lock: the data determine the rotation, only
        its split into ZYZ Euler angles is undetermined
    in_flat : the fraction of the unit direction inside the span of the null and weak
        right singular vectors (1 for an exact null direction; a known direction whose own
        gain is above weak_tol still counts as weak when this is >= IN_FLAT)
    description : what the direction means
    recommendation : what to hold fixed or what data to add
    """

    name: str
    kind: str
    status: str
    gain: float
    loadings: dict[str, float]
    tangent: np.ndarray
    parametrization_only: bool
    in_flat: float
    description: str
    recommendation: str

    def top(self, n: int = 4) -> list[tuple[str, float]]:
        """The n largest loadings, largest first."""
        items = sorted(self.loadings.items(), key=lambda kv: -abs(kv[1]))
        return [(k, v) for k, v in items[:n] if abs(v) > 1e-3]

    def __str__(self) -> str:
        load = ", ".join(f"{k} {v:+.2f}" for k, v in self.top(5))
        return f"{self.name} ({self.status}, gain {self.gain:.2g}): {load}"


@dataclass
class IdentifiabilityReport:
    """What the data determine at a parameter vector, from the residual Jacobian's SVD.

    Attributes
    ----------
    params : where the Jacobian was evaluated
    free, fixed : parameter names estimated and held fixed
    coordinates : the 14 names of the data analysis: the parameters, with
        ``rot_x, rot_y, rot_z`` in place of omega, phi, varphi when all three are free
    scales : the column scale of each free coordinate (its range: the bounds' width; pi/8
        rad for a rotation-vector component, the Euler angles' Table 2 width)
    singular_values : of the range-scaled Jacobian of the 3m residual components with
        respect to the free coordinates (largest first): what the data determine
    rank, condition_number : numerical rank (singular values >= null_tol times the largest)
        and largest / smallest singular value (inf when the smallest is exactly 0)
    euler_singular_values, euler_rank : the same in the paper's parameters (ZYZ Euler
        angles); lower than ``rank`` by one at the gimbal lock
    directions : the null and weak directions, named (see :class:`Direction`)
    known : each known degeneracy of docs/model.md with its status here, including those
        removed by fixing a parameter or determined by the data
    suggested_fixed : parameters to hold fixed as well (the ones a datasheet or a prior
        camera calibration gives first) so that the data determine every other one; empty
        when the data already do (the gimbal lock aside, which is not a data problem)
    recommendations : what to hold fixed or what data to add
    warnings : problems with the data itself (too few points, one pose, one image line)
    null_tol, weak_tol : the relative thresholds used
    num_points, num_poses : size of the data set
    """

    params: Parameters
    free: tuple[str, ...]
    fixed: tuple[str, ...]
    coordinates: tuple[str, ...]
    scales: np.ndarray
    singular_values: np.ndarray
    rank: int
    condition_number: float
    euler_singular_values: np.ndarray
    euler_rank: int
    directions: tuple[Direction, ...]
    known: tuple[Direction, ...]
    suggested_fixed: tuple[str, ...]
    recommendations: tuple[str, ...]
    warnings: tuple[str, ...]
    null_tol: float
    weak_tol: float
    num_points: int
    num_poses: int

    @property
    def num_free(self) -> int:
        return len(self.free)

    @property
    def full_rank(self) -> bool:
        """True when the data determine every free parameter (the rotation as a whole)."""
        return self.rank == self.num_free

    @property
    def relative_singular_values(self) -> np.ndarray:
        s = self.singular_values
        return s / s[0] if s.size and s[0] > 0 else s.copy()

    @property
    def gimbal_lock(self) -> bool:
        return any(d.kind == "gimbal_lock" for d in self.directions)

    def direction(self, kind: str) -> Direction | None:
        """The flat direction of a kind ("scale_gauge", ...), or None if it is not flat."""
        return next((d for d in self.directions if d.kind == kind), None)

    def summary(self) -> str:
        rel = self.relative_singular_values
        lines = [f"identifiability of {self.num_free} free parameters from {self.num_points} "
                 f"points ({self.num_poses} poses); fixed: {', '.join(self.fixed) or 'none'}",
                 "relative singular values (range-scaled): "
                 + " ".join(f"{x:.2g}" for x in rel),
                 f"rank {self.rank} of {self.num_free}, condition number "
                 f"{self.condition_number:.3g}"]
        if self.full_rank:
            lines.append("full rank: the data determine every free parameter")
        if self.euler_rank != self.rank:
            lines.append(f"in ZYZ Euler angles: rank {self.euler_rank} of {self.num_free}")
        for d in self.directions:
            lines.append(f"{d.status} direction: {d}")
            lines.append(f"  {d.description}")
        removed = [d for d in self.known if d.status in ("removed", "determined")]
        for d in removed:
            lines.append(f"{d.name}: {d.status}" + (f" ({d.description})"
                                                   if d.status == "removed" else ""))
        lines += [f"recommendation: {r}" for r in self.recommendations]
        lines += [f"warning: {w}" for w in self.warnings]
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.summary()


# ------------------------------------------------------------------------------------------
# The shared analysis (also used by the uncertainty and by calibrate)


def skew(v: np.ndarray) -> np.ndarray:
    """Row-wise cross-product matrices [v]x of an (m, 3) array."""
    z = np.zeros(len(v))
    return np.stack([np.stack([z, -v[:, 2], v[:, 1]], -1),
                     np.stack([v[:, 2], z, -v[:, 0]], -1),
                     np.stack([-v[:, 1], v[:, 0], z], -1)], 1)


def euler_rate_map(params: Any) -> np.ndarray:
    """B (3 x 3): the camera-frame angular velocity of each ZYZ Euler-angle rate.

    With R_C = Rz(omega) Ry(phi) Rz(varphi) and R_C' = R_C exp([delta]x), a change
    d(omega, phi, varphi) of the angles is the rotation vector delta = B d(angles).
    Its columns are R_C^T e_z, Rz(-varphi) e_y and e_z; at phi = 0 the first and the last
    coincide (the gimbal lock).
    """
    q = params.to_array() if isinstance(params, Parameters) else np.asarray(params, float)
    r = hand_from_camera(q)[:3, :3]
    c, s = math.cos(q[EULER_INDEX[2]]), math.sin(q[EULER_INDEX[2]])
    return np.column_stack([r[2, :], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rotation_jacobian(params: Any, dataset: Dataset) -> np.ndarray:
    """dE/d(delta) (m, 3, 3) for the rotation R_C exp([delta]x) (camera-frame rotation vector).

    E = P - R_N (R_C cP + t) - P_N, so dE/d(delta) = R_N R_C [cP]x.
    """
    q = params.to_array() if isinstance(params, Parameters) else np.asarray(params, float)
    cp, _ = points_in_camera(q, dataset.pixels)
    r = hand_from_camera(q)[:3, :3]
    return np.einsum("mij,jk,mkl->mil", dataset.poses[:, :3, :3], r, skew(cp))


def free_mask(fixed: Iterable[str] | str) -> tuple[tuple[str, ...], np.ndarray]:
    names, mask = fixed_mask(fixed)
    if mask.all():
        raise ValueError("every parameter is fixed: nothing to analyse")
    return names, mask


def column_scales(bounds: Bounds | None) -> np.ndarray:
    width = Bounds.table2().width if bounds is None else bounds.width
    return np.where(width > 0, width, TABLE2_UPPER - TABLE2_LOWER)


def check_inputs(dataset: Any, params: Any) -> tuple[Dataset, np.ndarray]:
    if hasattr(dataset, "fit") and not isinstance(dataset, Dataset):
        dataset = dataset.fit
    if not isinstance(dataset, Dataset):
        raise ValueError(f"dataset must be an hmlvs.Dataset, got {type(dataset).__name__}")
    if len(dataset) == 0:
        raise ValueError("the data set is empty")
    if isinstance(params, Parameters):
        q = params.to_array()
    elif isinstance(params, dict):
        q = Parameters.from_dict(params).to_array()
    else:
        q = np.asarray(params, dtype=float).reshape(-1)
        if q.shape != (NUM_PARAMS,) or not np.all(np.isfinite(q)):
            raise ValueError(f"params must be {NUM_PARAMS} finite values")
    return dataset, q


@dataclass
class Analysis:
    """Jacobians and SVD at one parameter vector, shared by the report and the uncertainty."""

    dataset: Dataset
    q: np.ndarray
    fixed: tuple[str, ...]
    fixed_mask: np.ndarray
    free_idx: np.ndarray
    residuals: np.ndarray          # (m, 3)
    jacobian: np.ndarray           # (m, 3, 14) dE/dq, paper parameters
    data_jacobian: np.ndarray      # (m, 3, 14) rotation columns replaced when rotation_free
    rotation_free: bool
    coordinates: tuple[str, ...]
    scales: np.ndarray             # (14,) for the data coordinates
    euler_scales: np.ndarray       # (14,) for the paper parameters
    B: np.ndarray                  # (3, 3) euler_rate_map
    sv: np.ndarray
    vt: np.ndarray                 # right singular vectors (rows), scaled data coordinates
    euler_sv: np.ndarray
    euler_vt: np.ndarray
    null_tol: float
    weak_tol: float

    @property
    def p(self) -> int:
        return int(self.free_idx.size)

    @property
    def scaled(self) -> np.ndarray:
        """The range-scaled data Jacobian of the free coordinates (3m, p)."""
        j = self.data_jacobian[:, :, self.free_idx].reshape(-1, self.p)
        return j * self.scales[self.free_idx]

    def rank_of(self, sv: np.ndarray) -> int:
        return int(np.sum(sv > self.null_tol * sv[0])) if sv.size and sv[0] > 0 else 0

    @property
    def rank(self) -> int:
        return self.rank_of(self.sv)

    def null_basis(self) -> np.ndarray:
        """Right null vectors (p, d) of the scaled data Jacobian."""
        return self.vt[self.rank:].T

    def flat_basis(self) -> np.ndarray:
        """Right singular vectors (p, d) of the null and weak singular values."""
        keep = self.sv < self.weak_tol * self.sv[0] if self.sv[0] > 0 else np.ones_like(
            self.sv, bool)
        return self.vt[keep].T


def analyse(dataset: Dataset, q: np.ndarray, fixed: Iterable[str] | str,
             bounds: Bounds | None = None, null_tol: float = NULL_TOL,
             weak_tol: float = WEAK_TOL) -> Analysis:
    if not 0 < null_tol < weak_tol < 1:
        raise ValueError(f"need 0 < null_tol < weak_tol < 1, got null_tol={null_tol}, "
                         f"weak_tol={weak_tol}")
    fixed_names, mask = free_mask(fixed)
    free_idx = np.nonzero(~mask)[0]
    e, j = residual_jacobian(q, dataset.pixels, dataset.poses, dataset.points)
    rotation_free = not mask[list(EULER_INDEX)].any()
    jd = j.copy()
    coords = list(NAMES)
    euler_scales = column_scales(bounds)
    scales = euler_scales.copy()
    if rotation_free:
        jd[:, :, list(EULER_INDEX)] = rotation_jacobian(q, dataset)
        for k, i in enumerate(EULER_INDEX):
            coords[i] = ROTATION_NAMES[k]
        # A rotation-vector component gets the Euler angles' mean range (pi/8 for Table 2).
        scales[list(EULER_INDEX)] = float(np.mean(euler_scales[list(EULER_INDEX)]))
    p = free_idx.size
    a = jd[:, :, free_idx].reshape(-1, p) * scales[free_idx]
    _, sv, vt = np.linalg.svd(a, full_matrices=False)
    ae = j[:, :, free_idx].reshape(-1, p) * euler_scales[free_idx]
    _, esv, evt = np.linalg.svd(ae, full_matrices=False)
    if a.shape[0] < p:  # fewer residuals than unknowns: pad the spectrum with exact zeros
        sv = np.concatenate([sv, np.zeros(p - sv.size)])
        esv = np.concatenate([esv, np.zeros(p - esv.size)])
        vt = np.linalg.svd(a)[2]
        evt = np.linalg.svd(ae)[2]
    return Analysis(dataset, q, fixed_names, mask, free_idx, e, j, jd, rotation_free,
                     tuple(coords), scales, euler_scales, euler_rate_map(q), sv, vt, esv, evt,
                     null_tol, weak_tol)


# ------------------------------------------------------------------------------------------
# Known directions (docs/model.md), in the data coordinates' own units (14 values)
