"""What calibration data can and cannot determine: Jacobian SVD with named flat directions.

docs/model.md ("What the data can and cannot determine") lists exact degeneracies of the 14
parameters for laser points. :func:`identifiability` finds them numerically from the residual
Jacobian (automatic differentiation in C++) and names them:

- the scale gauge ``(f, Su, Sv, k) -> (l f, l Su, l Sv, k / l^2)`` (always exact),
- the ZYZ gimbal lock at ``phi = 0`` (only ``omega + varphi`` is determined),
- the camera shift along its own y axis (exact when ``k = 0``),

and any further flat direction the SVD finds, which it names by its largest loadings.

Two coordinate systems are analysed. The paper's parameters (ZYZ Euler angles) are what
the user reads; but at ``phi = 0`` the Euler chart is singular and hides directions that do
exist in the data (a camera rotation about its own x axis cannot be written as a first-order
change of ZYZ angles there). The *data* analysis therefore replaces the three Euler columns
by a rotation vector of the camera about its own axes (``rot_x, rot_y, rot_z``: the rotation
on SO(3), as the modern LM solves it) whenever all three angles are free. The rank there is
what the data determine; the gimbal lock is reported separately as a property of the Euler
angles.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Any, Iterable

import numpy as np

from ..data.dataset import Dataset
from ..errors import (  # noqa: F401 (re-exported: they were defined here first)
    AtBoundWarning,
    DiagnosticsFailedWarning,
    FlatDirectionWarning,
    GimbalLockWarning,
    HmlvsDataWarning,
    PoseVarietyWarning,
    SetupWarning,
    TooFewPointsWarning,
    warn_data,
    warning_category,
)
from ..models.paper import hand_from_camera, points_in_camera, residual_jacobian
from ..models.params import (
    NAMES,
    NUM_PARAMS,
    TABLE2_LOWER,
    TABLE2_UPPER,
    Bounds,
    Parameters,
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
_ROTATION_DESCRIPTION = {"rot_x": "rotation of the camera about its x axis",
                         "rot_y": "rotation of the camera about its y axis",
                         "rot_z": "rotation of the camera about its z axis"}
# What a user can know before calibrating, in the order they are worth fixing.
_PRIOR_KNOWN = ("Su", "Sv", "Cu", "Cv", "f", "k")



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


def _skew(v: np.ndarray) -> np.ndarray:
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
    return np.einsum("mij,jk,mkl->mil", dataset.poses[:, :3, :3], r, _skew(cp))


from ..models.params import fixed_mask  # noqa: E402


def _fixed_mask(fixed: Iterable[str] | str) -> tuple[tuple[str, ...], np.ndarray]:
    names, mask = fixed_mask(fixed)
    if mask.all():
        raise ValueError("every parameter is fixed: nothing to analyse")
    return names, mask


def _column_scales(bounds: Bounds | None) -> np.ndarray:
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
    fixed_names, mask = _fixed_mask(fixed)
    free_idx = np.nonzero(~mask)[0]
    e, j = residual_jacobian(q, dataset.pixels, dataset.poses, dataset.points)
    rotation_free = not mask[list(EULER_INDEX)].any()
    jd = j.copy()
    coords = list(NAMES)
    euler_scales = _column_scales(bounds)
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


def scale_gauge_tangent(params: Any) -> np.ndarray:
    """d/dl of (l f, l Su, l Sv, k / l^2) at l = 1: (f, Su, Sv, 0, 0, -2k, 0, ...)."""
    q = params.to_array() if isinstance(params, Parameters) else np.asarray(params, float)
    t = np.zeros(NUM_PARAMS)
    t[[0, 1, 2, 5]] = q[0], q[1], q[2], -2.0 * q[5]
    return t


def camera_y_tangent(params: Any) -> np.ndarray:
    """Moving the camera by d along its own y axis (exact when k = 0), per unit d (mm).

    H' = H - d, Sv' = Sv (1 - d/H), Cv' = Cv + (f / Sv') (d / H) tan(theta) and the camera
    origin t' = t + d R_C e_y: every point of the laser plane keeps its pixel. The
    rotation is unchanged, so the same vector serves the Euler and the rotation-vector
    coordinates.
    """
    q = params.to_array() if isinstance(params, Parameters) else np.asarray(params, float)
    f, sv, h, theta = q[0], q[2], q[6], q[7]
    t = np.zeros(NUM_PARAMS)
    t[param_index("H")] = -1.0
    t[param_index("Sv")] = -sv / h
    t[param_index("Cv")] = f * math.tan(theta) / (sv * h)
    t[11:14] = hand_from_camera(q)[:3, 1]
    return t


def gimbal_tangent() -> np.ndarray:
    """(omega +1, varphi -1) in the paper's parameters: no rotation at all when phi = 0."""
    t = np.zeros(NUM_PARAMS)
    t[EULER_INDEX[0]], t[EULER_INDEX[2]] = 1.0, -1.0
    return t


_KNOWN_NAMES = {"scale_gauge": "scale gauge (f, Su, Sv, k)",
                "camera_y_shift": "camera shift along its y axis (H, Sv, Cv, t)",
                "gimbal_lock": "ZYZ gimbal lock (omega - varphi)"}
_KNOWN_DESCRIPTIONS = {
    "scale_gauge": "(f, Su, Sv, k) -> (l f, l Su, l Sv, k / l^2) leaves every point unchanged: "
                   "only f/Su, f/Sv and k Su^2 are determined",
    "camera_y_shift": "moving the camera by d along its own y axis with H' = H - d, "
                      "Sv' = Sv (1 - d/H) and a shifted Cv leaves every point unchanged when "
                      "k = 0 (nearly so when k is small)",
    "gimbal_lock": "at phi = 0 omega and varphi rotate about the same axis: only omega + "
                   "varphi is determined (the rotation itself may well be)",
}
_KNOWN_RECOMMENDATIONS = {
    "scale_gauge": "hold Su fixed at the camera's pixel pitch (datasheet; 7.4 um for the "
                   "paper's camera), or read f/Su, f/Sv and k Su^2 instead of f, Su, Sv, k",
    "camera_y_shift": "hold Sv fixed too (square pixels: Sv = Su from the datasheet) or Cv "
                      "(from a prior camera calibration)",
    "gimbal_lock": "read omega + varphi (or the rotation hand_from_camera) instead of omega "
                   "and varphi, or hold varphi fixed at 0",
}


def _unit_scaled(t: np.ndarray, scales: np.ndarray, free_idx: np.ndarray) -> np.ndarray:
    """The free part of a tangent in range-scaled coordinates, as a unit vector."""
    x = t[free_idx] / scales[free_idx]
    n = float(np.linalg.norm(x))
    return x / n if n > 0 else x


def _status(gain: float, null_tol: float, weak_tol: float) -> str:
    return "null" if gain < null_tol else "weak" if gain < weak_tol else "determined"


def _make_direction(kind: str, name: str, x: np.ndarray, a: np.ndarray, smax: float,
                    names: tuple[str, ...], scales: np.ndarray, free_idx: np.ndarray,
                    flat: np.ndarray, null_tol: float, weak_tol: float, description: str,
                    recommendation: str, parametrization_only: bool = False) -> Direction:
    gain = float(np.linalg.norm(a @ x) / smax) if smax > 0 else 0.0
    in_flat = float(np.linalg.norm(flat.T @ x)) if flat.size else 0.0
    status = _status(gain, null_tol, weak_tol)
    if status == "determined" and in_flat >= IN_FLAT:
        status = "weak"
    k = int(np.argmax(np.abs(x)))
    x = x if x[k] >= 0 else -x  # sign convention: the largest loading is positive
    tangent = np.zeros(NUM_PARAMS)
    tangent[free_idx] = x * scales[free_idx] / abs(x[k])
    return Direction(name=name, kind=kind, status=status, gain=gain,
                     loadings={names[i]: float(v) for i, v in zip(free_idx, x)},
                     tangent=tangent, parametrization_only=parametrization_only,
                     in_flat=in_flat, description=description, recommendation=recommendation)


def _known_directions(an: Analysis) -> list[Direction]:
    """docs/model.md's degeneracies, each with its status at this point and these fixed ones."""
    a = an.scaled
    smax = float(an.sv[0])
    flat = an.flat_basis()
    out: list[Direction] = []
    tangents = {"scale_gauge": scale_gauge_tangent(an.q), "camera_y_shift": camera_y_tangent(an.q)}
    if not an.rotation_free:  # Euler data coordinates: the gimbal lock is a data direction
        tangents["gimbal_lock"] = gimbal_tangent()
    fixed = an.fixed_mask
    valid, removed = [], []
    for kind, t in tangents.items():
        tx = t / an.scales
        on_fixed = np.linalg.norm(tx[fixed]) > 1e-12 * np.linalg.norm(tx)
        (removed if on_fixed else valid).append(kind)
    for kind in valid:
        x = _unit_scaled(tangents[kind], an.scales, an.free_idx)
        out.append(_make_direction(kind, _KNOWN_NAMES[kind], x, a, smax, an.coordinates,
                                   an.scales, an.free_idx, flat, an.null_tol, an.weak_tol,
                                   _KNOWN_DESCRIPTIONS[kind], _KNOWN_RECOMMENDATIONS[kind],
                                   parametrization_only=kind == "gimbal_lock"))
    if len(removed) >= 2:  # fixing may leave a combination of removed directions free
        tm = np.column_stack([tangents[k] / an.scales for k in removed])
        _, s, vt = np.linalg.svd(tm[fixed], full_matrices=True)
        r = int(np.sum(s > 1e-12 * max(s[0], 1e-300)))
        for c in vt[r:]:
            kinds = [k for k, w in zip(removed, c) if abs(w) > 1e-9]
            t = sum(w * tangents[k] for k, w in zip(removed, c))
            x = _unit_scaled(t, an.scales, an.free_idx)
            kind = "+".join(kinds)
            out.append(_make_direction(
                kind, " combined with ".join(_KNOWN_NAMES[k].split(" (")[0] for k in kinds),
                x, a, smax, an.coordinates, an.scales, an.free_idx, flat, an.null_tol,
                an.weak_tol, "with " + ", ".join(an.fixed) + " fixed, only a combination of "
                + " and ".join(k.replace("_", " ") for k in kinds) + " remains",
                _KNOWN_RECOMMENDATIONS[kinds[0]]))
    for kind in removed:
        t = tangents[kind]
        by = [NAMES[i] for i in np.nonzero(fixed & (np.abs(t / an.scales) > 1e-12 *
                                                    np.linalg.norm(t / an.scales)))[0]]
        out.append(Direction(name=_KNOWN_NAMES[kind], kind=kind, status="removed",
                             gain=float("nan"), loadings={}, tangent=t,
                             parametrization_only=kind == "gimbal_lock", in_flat=0.0,
                             description="removed by fixing " + ", ".join(by),
                             recommendation=""))
    if an.rotation_free:  # the gimbal lock lives in the Euler chart only
        ev = an.euler_sv
        ae = an.jacobian[:, :, an.free_idx].reshape(-1, an.p) * an.euler_scales[an.free_idx]
        x = _unit_scaled(gimbal_tangent(), an.euler_scales, an.free_idx)
        weak = ev < an.weak_tol * ev[0] if ev[0] > 0 else np.ones_like(ev, bool)
        out.append(_make_direction("gimbal_lock", _KNOWN_NAMES["gimbal_lock"], x, ae,
                                   float(ev[0]), NAMES, an.euler_scales, an.free_idx,
                                   an.euler_vt[weak].T,
                                   an.null_tol, an.weak_tol, _KNOWN_DESCRIPTIONS["gimbal_lock"]
                                   + f" (phi = {an.q[EULER_INDEX[1]]:.3g} rad)",
                                   _KNOWN_RECOMMENDATIONS["gimbal_lock"],
                                   parametrization_only=True))
    return out


def _unnamed_directions(an: Analysis, known: list[Direction]) -> list[Direction]:
    """Flat directions of the data Jacobian that the known ones do not explain."""
    flat = an.flat_basis()
    d = flat.shape[1]
    explained = [d_ for d_ in known if d_.status in ("null", "weak")
                 and not (an.rotation_free and d_.kind == "gimbal_lock")]
    count = d - len(explained)
    if count <= 0:
        return []
    rest = None
    if explained:
        xs = np.column_stack([np.array([d_.loadings[an.coordinates[i]] for i in an.free_idx])
                              for d_ in explained])
        # Representatives that leave each known direction's signature coordinate unchanged
        # (Su for the gauge, Sv for the camera shift: the first coordinate in the order of
        # _PRIOR_KNOWN, then by loading, that it moves and that keeps the signatures
        # independent): with Su free the tilt then comes out as it is with Su and Sv fixed,
        # not mixed with the camera shift as an orthogonal complement would be.
        coords = [an.coordinates[i] for i in an.free_idx]
        order = [coords.index(n) for n in _PRIOR_KNOWN if n in coords]
        sig: list[int] = []
        for c in range(xs.shape[1]):
            cands = order + [k for k in np.argsort(-np.abs(xs[:, c])) if k not in order]
            for k in cands:
                if k in sig or abs(xs[k, c]) < 1e-3:
                    continue
                trial = xs[sig + [k], : c + 1]
                if np.linalg.matrix_rank(trial, tol=1e-6) == c + 1:
                    sig.append(int(k))
                    break
        if len(sig) == xs.shape[1]:
            _, sv_, vt_ = np.linalg.svd(flat[sig], full_matrices=True)
            r_ = int(np.sum(sv_ > 1e-6))
            if flat.shape[1] - r_ == count:
                rest = flat @ vt_[r_:].T
        if rest is None:  # fall back to the orthogonal complement
            qk, _ = np.linalg.qr(flat @ (flat.T @ xs))
            rest = flat - qk @ (qk.T @ flat)
    else:
        rest = flat
    u, _, _ = np.linalg.svd(rest, full_matrices=False)
    a = an.scaled
    out = []
    for c in range(count):
        x = u[:, c] / np.linalg.norm(u[:, c])
        top = sorted(zip(an.free_idx, x), key=lambda t: -abs(t[1]))
        lead = [(an.coordinates[i], v) for i, v in top if abs(v) > 0.05][:4]
        label = ", ".join(f"{_ROTATION_DESCRIPTION.get(n, n)}" for n, _ in lead)
        names_in = [n for n, _ in lead]
        prior = [n for n in _PRIOR_KNOWN if n in names_in]
        rec = "add points over the whole image and more varied poses"
        if prior:
            rec = (f"hold {prior[0]} fixed (from the datasheet or a prior camera calibration), "
                   "or " + rec)
        elif names_in:
            rec = f"{rec}, or hold {names_in[0]} fixed at a known value"
        out.append(_make_direction(
            "unnamed", "flat direction of " + ", ".join(names_in), x, a, float(an.sv[0]),
            an.coordinates, an.scales, an.free_idx, flat, an.null_tol, an.weak_tol,
            f"found by the SVD, not one of the known degeneracies: it mixes {label}", rec))
    return out


# ------------------------------------------------------------------------------------------
# Data checks


def data_warnings(dataset: Dataset, num_free: int) -> list[str]:
    """Problems of the data themselves, before any Jacobian.

    - fewer than MIN_POINTS_PER_PARAMETER (3) points per free parameter;
    - every pose within SAME_POSE_DEGREES (2 deg) of rotation and SAME_POSE_MM (10 mm) of
      position of the first one: the calibration then holds only near that pose;
    - every stripe pixel within COLLINEAR_PIXELS (1 px RMS) of one image line: one stripe seen
      once cannot fix the pixel-to-plane map.
    """
    out = []
    m = len(dataset)
    if m < MIN_POINTS_PER_PARAMETER * num_free:
        out.append(f"too few points: {m} calibration points for {num_free} free parameters "
                   f"(fewer than {MIN_POINTS_PER_PARAMETER} per parameter); the estimate and "
                   f"its uncertainty are unreliable, use at least "
                   f"{MIN_POINTS_PER_PARAMETER * num_free}")
    if m >= 2:
        r = dataset.poses[:, :3, :3]
        cosang = (np.einsum("ij,mij->m", r[0], r) - 1.0) / 2.0
        ang = np.degrees(np.arccos(np.clip(cosang, -1.0, 1.0))).max()
        dist = np.linalg.norm(dataset.poses[:, :3, 3] - dataset.poses[0, :3, 3], axis=1).max()
        if ang < SAME_POSE_DEGREES and dist < SAME_POSE_MM:
            out.append(f"all {m} points were seen from nearly the same hand pose (within "
                       f"{ang:.2g} deg and {dist:.2g} mm): the calibration holds only near "
                       "this pose; take points from more varied poses")
        px = dataset.pixels - dataset.pixels.mean(axis=0)
        s = np.linalg.svd(px, compute_uv=False)
        if s.size > 1 and s[1] / math.sqrt(m) < COLLINEAR_PIXELS:
            out.append(f"all {m} stripe pixels lie on one image line (within "
                       f"{s[1] / math.sqrt(m):.2g} px RMS): the pixel-to-plane map is not "
                       "determined; add points from poses whose stripe crosses other parts "
                       "of the image")
    return out


def _suggest_fixed(an: Analysis) -> list[str]:
    """A small set of parameters whose fixing removes every null and weak data direction.

    Fixing parameter j restricts the flat subspace to x_j = 0, removing one dimension when
    some flat direction moves x_j; a set F removes rank(V_flat[F, :]) of them. Greedy, first
    over what a datasheet or a prior camera calibration gives (Su, Sv, Cu, Cv, f, k), then
    over the other parameters by their loading.
    """
    flat = an.flat_basis()
    d = flat.shape[1]
    if d == 0:
        return []
    free = [NAMES[i] for i in an.free_idx]
    rows = {n: flat[k] for k, n in enumerate(free) if n not in ROTATION_NAMES
            and an.coordinates[an.free_idx[k]] == n}
    weight = {n: float(np.linalg.norm(r)) for n, r in rows.items()}
    order = [n for n in _PRIOR_KNOWN if n in rows] + sorted(
        (n for n in rows if n not in _PRIOR_KNOWN), key=lambda n: -weight[n])
    chosen: list[str] = []
    rank = 0
    for n in order:
        trial = np.array([rows[c] for c in chosen + [n]])
        r = int(np.sum(np.linalg.svd(trial, compute_uv=False) > 1e-6))
        if r > rank:
            chosen.append(n)
            rank = r
        if rank == d:
            break
    return chosen


def _recommendations(directions: list[Direction], warnings_: list[str],
                     suggested: list[str]) -> list[str]:
    recs = []
    if suggested:
        source = ("from the datasheet or a prior camera calibration"
                  if all(n in _PRIOR_KNOWN for n in suggested) else "at known values")
        recs.append("hold " + ", ".join(suggested) + f" fixed as well ({source}): then the data "
                    "determine every other free parameter")
    for d in directions:
        if d.recommendation and d.recommendation not in recs:
            recs.append(d.recommendation)
    if any("pose" in w for w in warnings_):
        recs.append("add more pose variety (orientations and positions of the hand)")
    if any(d.kind == "unnamed" for d in directions) or any(
            d.status in ("null", "weak") and not d.parametrization_only for d in directions):
        recs.append("a prior camera calibration (f/Su, f/Sv, Cu, Cv, k from checkerboard "
                    "images) removes every intrinsic direction at once")
    return recs


def report_of(an: Analysis) -> IdentifiabilityReport:
    known = _known_directions(an)
    unnamed = _unnamed_directions(an, known)
    flat = [d for d in known if d.status in ("null", "weak")] + unnamed
    flat.sort(key=lambda d: d.gain)
    warns = data_warnings(an.dataset, an.p)
    suggested = _suggest_fixed(an)
    sv = an.sv
    cond = float(sv[0] / sv[-1]) if sv[-1] > 0 else math.inf
    return IdentifiabilityReport(
        params=Parameters.from_array(an.q), free=tuple(NAMES[i] for i in an.free_idx),
        fixed=an.fixed, coordinates=an.coordinates, scales=an.scales[an.free_idx].copy(),
        singular_values=sv.copy(), rank=an.rank, condition_number=cond,
        euler_singular_values=an.euler_sv.copy(), euler_rank=an.rank_of(an.euler_sv),
        directions=tuple(flat), known=tuple(known), suggested_fixed=tuple(suggested),
        recommendations=tuple(_recommendations(flat, warns, suggested)), warnings=tuple(warns),
        null_tol=an.null_tol, weak_tol=an.weak_tol, num_points=len(an.dataset),
        num_poses=an.dataset.num_poses)


def identifiability(dataset: Dataset | Any, params: Parameters | Any,
                    fixed: Iterable[str] | str = ("Su",), bounds: Bounds | None = None,
                    null_tol: float = NULL_TOL, weak_tol: float = WEAK_TOL
                    ) -> IdentifiabilityReport:
    """What the data determine at ``params``: Jacobian SVD with named flat directions.

    Parameters
    ----------
    dataset : the calibration points (:class:`Dataset`, or a simulation: its ``fit`` set)
    params : where to evaluate the Jacobian (the truth, a calibration result's ``params``, or
        the values you intend to start from)
    fixed : parameter names held fixed (default Su, as :func:`calibrate`)
    bounds : whose widths scale the Jacobian's columns (default Table 2)
    null_tol, weak_tol : singular values below these fractions of the largest one are null
        (exact degeneracies; default 1e-9) or weak (default 1e-4); see the module constants

    Returns
    -------
    IdentifiabilityReport

    Examples
    --------
    >>> sim = hmlvs.simulate(seed=0)
    >>> rep = hmlvs.identifiability(sim.fit, sim.truth, fixed=())
    >>> [d.kind for d in rep.directions if d.kind != "unnamed"]  # doctest: +SKIP
    ['scale_gauge', 'camera_y_shift', 'gimbal_lock']
    """
    dataset, q = check_inputs(dataset, params)
    return report_of(analyse(dataset, q, fixed, bounds, null_tol, weak_tol))
