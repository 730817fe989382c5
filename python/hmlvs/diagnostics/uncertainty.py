"""Uncertainty of identified parameters: linearised (Gauss-Newton) covariance, correlations, and the
combinations the data determine even when a parameter is not (f/Su, f/Sv, k Su^2,
omega + varphi).

The covariance is computed in the range-scaled coordinates of the identifiability analysis
(the rotation as a camera-frame rotation vector when omega, phi and varphi are all free, as
the modern LM solves it) from the SVD of the residual Jacobian, then mapped to the paper's
parameters. It is the covariance of the least-squares estimate caused by noise of the stripe
pixels (px) and of the reference points (mm):

    cov = (J^T J)^+ J^T W J (J^T J)^+,   W_i = pixel_noise^2 G_i G_i^T + point_noise^2 I

with ``G_i = dE_i/d(u, v)`` (exactly ``-dE_i/d(Cu, Cv)``, since the model uses u - Cu and
v - Cv). This sandwich form is needed because ``calibrate`` minimises the plain sum of
squares while pixel noise moves points only within the laser plane, by amounts that grow
with depth: the residuals are neither isotropic nor of equal size. The textbook
Gauss-Newton ``s^2 (J^T J)^-1`` with ``s^2 = SSR / (3m - r)`` assumes they are; on the
paper's data (0.1 px pixel noise) it misstates the standard deviations by factors 0.2 (the
rotation about the camera's z axis) to 2.6 (k) over 200 simulations, so it is not used.

The noise levels are the user's (``pixel_noise``, ``point_noise``) or, by default, estimated
from the residuals by the method of moments (:func:`_estimate_noise`): the residual
components normal to the laser plane carry only point noise, those within it both.

``(J^T J)^+`` is the pseudo-inverse over the singular values above ``null_tol`` times the
largest: with exact null directions among the free parameters the covariance stays finite
(the minimum-norm gauge) and a warning names the flat directions. Standard deviations along
them are not meaningful (:attr:`Uncertainty.determined` is False for those parameters); a
combination whose gradient is orthogonal to every null direction, such as f/Su under the scale
gauge, has a meaningful standard deviation, which is why the combinations are reported.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math
from typing import Any, Iterable

import numpy as np

from ..data.dataset import Dataset
from ..models.paper import hand_from_camera, points_in_camera
from ..models.params import NAMES, Bounds, Parameters, param_index
from .analysis import skew
from .identifiability import (
    EULER_INDEX,
    GIMBAL_PHI,
    NULL_TOL,
    WEAK_TOL,
    Analysis,
    analyse,
    check_inputs,
    report_of,
)
from .pose_errors import pose_error_part

_DETERMINED_TOL = 1e-6  # fraction of a gradient inside the null space still "determined"
#: robot pose errors are counted on data sets whose residuals times the poses' error
#: columns (3 m x 6 poses) stay within this many numbers (160 MB of doubles: e.g. 5,000
#: points from 150 poses); a larger one keeps the white-noise covariance (a memory bound)
MAX_POSE_ENTRIES = 20_000_000


@dataclass(frozen=True)
class Combination:
    """A function of the parameters that the data determine, with its standard deviation.

    Attributes
    ----------
    name : e.g. "f/Su"
    unit : its unit
    value : its value at the parameters
    std : its standard deviation (same unit)
    determined : False when it changes along a null direction (std then not meaningful)
    description : what it is
    """

    name: str
    unit: str
    value: float
    std: float
    determined: bool
    description: str

    def __str__(self) -> str:
        flag = "" if self.determined else " (not determined)"
        return f"{self.name} = {self.value:.8g} +- {self.std:.3g} {self.unit}{flag}"


@dataclass
class Uncertainty:
    """Covariance of the free parameters at a solution (see the module docstring).

    Attributes
    ----------
    free : names of the free parameters, the order of ``covariance`` and ``correlation``
    covariance : (p, p) covariance of the free parameters (paper units)
    std : standard deviation of each free parameter (fixed ones are absent)
    correlation : (p, p) correlation matrix (0 off the diagonal for a zero std; NaN-free)
    determined : per free parameter, False when it moves along a null direction of the data
        or of the Euler chart (gimbal lock): its std is then not meaningful
    combinations : the identifiable combinations (f/Su, f/Sv, k Su^2, and omega + varphi when
        |phi| < GIMBAL_PHI) with their standard deviations
    rotation_std : (3,) std (rad) of the hand_from_camera rotation about the camera's x, y,
        z axes (R_C exp([delta]x)), or None when an Euler angle is held fixed
    noise_model : "estimated" (noise levels from the residuals) or "given" (by the user)
    sigma : sqrt(SSR / dof), the residual standard deviation per component (mm), for
        information
    pixel_noise, point_noise : the noise levels used (px, mm): given or estimated (a level
        not given while the other is counts as 0)
    dof : 3m - rank, the residual degrees of freedom
    rank : numerical rank of the free parameters' Jacobian (rotation on SO(3))
    flat : names of the null directions (empty when the data determine everything)
    warnings : rank deficiency, gimbal lock
    notes : assumptions (e.g. a parameter at its bound)
    """

    free: tuple[str, ...]
    covariance: np.ndarray
    std: dict[str, float]
    correlation: np.ndarray
    determined: dict[str, bool]
    combinations: tuple[Combination, ...]
    rotation_std: np.ndarray | None
    noise_model: str
    sigma: float
    pixel_noise: float | None
    point_noise: float | None
    dof: int
    rank: int
    flat: tuple[str, ...]
    warnings: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    #: the robot pose errors the residuals show (translation mm, rotation deg, RMS per axis),
    #: counted in the covariance (:mod:`hmlvs.diagnostics.pose_errors`); None when they show
    #: none, or the noise levels were given
    pose_errors: tuple[float, float] | None = None

    def combination(self, name: str) -> Combination:
        """The combination called ``name`` ("f/Su", "f/Sv", "k Su^2", "omega + varphi")."""
        for c in self.combinations:
            if c.name == name:
                return c
        raise ValueError(f"no combination {name!r}; available: "
                         f"{', '.join(c.name for c in self.combinations)}")

    def correlated(self, threshold: float = 0.95) -> list[tuple[str, str, float]]:
        """Pairs of free parameters with |correlation| above ``threshold``, strongest first."""
        out = []
        for i in range(len(self.free)):
            for j in range(i + 1, len(self.free)):
                c = float(self.correlation[i, j])
                if abs(c) > threshold:
                    out.append((self.free[i], self.free[j], c))
        return sorted(out, key=lambda t: -abs(t[2]))

    def summary(self) -> str:
        how = "estimated from the residuals" if self.noise_model == "estimated" else "given"
        head = (f"uncertainty from pixel noise {self.pixel_noise or 0:.3g} px and point noise "
                f"{self.point_noise or 0:.3g} mm ({how}; residual std {self.sigma:.3g} mm, "
                f"{self.dof} degrees of freedom)")
        lines = [head]
        if self.pose_errors is not None:
            lines.append(f"  and robot pose errors of about {self.pose_errors[0]:.3g} mm and "
                         f"{self.pose_errors[1]:.3g} deg RMS per axis, which the residuals "
                         "show (the points of a pose move together)")
        for n in self.free:
            flag = "" if self.determined[n] else "  (not determined)"
            lines.append(f"  {n:<7} std {self.std[n]:.3g}{flag}")
        if self.rotation_std is not None:
            lines.append("  rotation about camera x, y, z: std "
                         + ", ".join(f"{s:.3g}" for s in self.rotation_std) + " rad")
        lines += [f"  {c}" for c in self.combinations]
        strong = self.correlated(0.99)
        if strong:
            lines.append("  |correlation| > 0.99: " + ", ".join(
                f"{a}-{b} {c:+.3f}" for a, b, c in strong[:6]))
        lines += [f"warning: {w}" for w in self.warnings]
        lines += [f"note: {n}" for n in self.notes]
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.summary()


def _combination_gradients(q: np.ndarray, near_gimbal: bool
                           ) -> list[tuple[str, str, float, np.ndarray, str]]:
    f, su, sv, k = q[0], q[1], q[2], q[5]
    out = []
    g = np.zeros(len(NAMES))
    g[[0, 1]] = 1.0 / su, -f / su**2
    out.append(("f/Su", "px", f / su, g, "horizontal focal length in pixels"))
    g = np.zeros(len(NAMES))
    g[[0, 2]] = 1.0 / sv, -f / sv**2
    out.append(("f/Sv", "px", f / sv, g, "vertical focal length in pixels"))
    g = np.zeros(len(NAMES))
    g[[5, 1]] = su**2, 2.0 * k * su
    out.append(("k Su^2", "1/px^2", k * su**2, g, "radial distortion in pixel units"))
    if near_gimbal:
        g = np.zeros(len(NAMES))
        g[[EULER_INDEX[0], EULER_INDEX[2]]] = 1.0
        total = math.remainder(q[EULER_INDEX[0]] + q[EULER_INDEX[2]], 2 * math.pi)
        out.append(("omega + varphi", "rad", total, g,
                    "the camera's rotation about the hand's z axis when phi is near 0"))
    return out


def check_noise(pixel_noise: Any, point_noise: Any) -> None:
    """Raise ValueError unless the noise levels are None or finite numbers >= 0, not both 0."""
    for name, v in (("pixel_noise", pixel_noise), ("point_noise", point_noise)):
        if v is None:
            continue
        try:
            ok = math.isfinite(float(v)) and float(v) >= 0
        except (TypeError, ValueError):
            ok = False
        if not ok:
            raise ValueError(f"{name} must be a finite number >= 0 (px for pixels, mm for "
                             f"points), got {v!r}")
    if (pixel_noise is not None or point_noise is not None) and not (pixel_noise or point_noise):
        raise ValueError("pixel_noise and point_noise are both 0: give a noise level > 0, or "
                         "neither to estimate them from the residuals")


def _estimate_noise(an: Analysis, wp: np.ndarray, u: np.ndarray) -> tuple[float, float]:
    """Pixel noise (px) and point noise (mm) from the residuals, by the method of moments.

    Pixel noise moves a point within the laser plane (W_p,i = G_i G_i^T, rank 2), point noise
    in every direction. With r = (I - P) e, P the projector onto the Jacobian's columns and
    e ~ N(0, sp^2 W_p + st^2 I), the sums of squares of the residuals' components normal to
    the laser plane (M_1 = diag(n_i n_i^T)) and within it (M_2 = I - M_1) have expectations
    E[r^T M_k r] = sp^2 tr((I-P) M_k (I-P) W_p) + st^2 tr((I-P) M_k (I-P)): two linear
    equations for sp^2 and st^2 (each clipped at 0). Unbiased for the linearised model.
    ``u``: an orthonormal basis of P's columns (:func:`_basis`): the Jacobian's, or with
    each pose's own pose error beside them (then the levels are the noise without the pose
    errors' share).
    """
    return _solve_moments(*_noise_moments(an, wp, u))


def _basis(a: np.ndarray, rank: int | None = None) -> np.ndarray:
    """An orthonormal basis U of the span of ``a``'s columns (P = U U^T): its leading left
    singular vectors, ``rank`` of them or (None) those above 1e-9 of the largest singular
    value of the column-normalised matrix."""
    if rank is None:
        norms = np.linalg.norm(a, axis=0)
        a = a / np.where(norms > 0, norms, 1.0)
    u, sv, _ = np.linalg.svd(a, full_matrices=False)
    if rank is None:
        rank = int(np.sum(sv > 1e-9 * sv[0])) if sv.size and sv[0] > 0 else 0
    return u[:, :rank]


def _noise_moments(an: Analysis, wp: np.ndarray, u: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The moment equations of :func:`_estimate_noise` for the projector P = U U^T: y_k =
    r^T M_k r (r the residuals projected off U) and
    c[k] = (tr((I-P) M_k (I-P) W_p), tr((I-P) M_k (I-P)))."""
    m = len(an.dataset)
    g = an.jacobian[:, :, [param_index("Cu"), param_index("Cv")]]
    normal = np.cross(g[:, :, 0], g[:, :, 1])
    nn = np.linalg.norm(normal, axis=1, keepdims=True)
    normal = np.divide(normal, nn, out=np.zeros_like(normal), where=nn > 0)
    m1 = np.einsum("mi,mj->mij", normal, normal)
    m2 = np.eye(3)[None] - m1
    eye = np.broadcast_to(np.eye(3), (m, 3, 3))

    def blockmul(b: np.ndarray, x: np.ndarray) -> np.ndarray:  # block-diagonal (m,3,3) @ x
        return np.einsum("mij,mjk->mik", b, x.reshape(m, 3, -1)).reshape(3 * m, -1)

    def expectation(mk: np.ndarray, w: np.ndarray) -> float:
        # tr((I-P) M (I-P) W) = tr(MW) - tr(U^T M W U) - tr(U^T W M U) + tr(U^T M U U^T W U)
        mw = np.einsum("mij,mjk->mik", mk, w)
        t = float(np.einsum("mii->", mw))
        t -= 2.0 * float(np.sum(u * blockmul(mw, u)))
        umu = u.T @ blockmul(mk, u)
        uwu = u.T @ blockmul(w, u)
        return t + float(np.sum(umu * uwu.T))

    # the residuals projected off U as well: at the solution they are already orthogonal to
    # the Jacobian's columns; off U's other columns (``extra``) they are (I - P) e
    r = an.residuals.ravel()
    r = (r - u @ (u.T @ r)).reshape(m, 3)
    y = np.array([np.einsum("mi,mij,mj->", r, mk, r) for mk in (m1, m2)])
    c = np.array([[expectation(mk, w) for w in (wp, eye)] for mk in (m1, m2)])
    return y, c


def _solve_moments(y: np.ndarray, c: np.ndarray) -> tuple[float, float]:
    """Pixel and point noise from the two moment equations c (sp^2, st^2) = y."""
    try:
        sp2, st2 = np.linalg.solve(c, y)
    except np.linalg.LinAlgError:
        sp2, st2 = 0.0, float(y.sum() / max(np.trace(c), 1e-300))
    if sp2 < 0:  # all of it is point noise
        sp2, st2 = 0.0, float(y.sum() / (c[0, 1] + c[1, 1]))
    elif st2 < 0:  # all of it is pixel noise
        sp2, st2 = float(y.sum() / (c[0, 0] + c[1, 0])), 0.0
    return float(np.sqrt(max(sp2, 0.0))), float(np.sqrt(max(st2, 0.0)))


def _noise_levels(an: Analysis, wp: np.ndarray, rank: int, a_inv: np.ndarray
                  ) -> tuple[float, float, np.ndarray | None, tuple[float, float] | None]:
    """The noise levels estimated from the residuals: pixel noise (px), point noise (mm) and,
    when the residuals show robot pose errors, their part of the covariance (scaled data
    coordinates) and spread (:func:`_pose_errors`; else None, None)."""
    moments = _noise_moments(an, wp, _basis(an.scaled, rank))
    counted = _pose_errors(an, wp, a_inv, moments[1])
    if counted is not None:
        return counted
    return (*_solve_moments(*moments), None, None)


def _pose_errors(an: Analysis, wp: np.ndarray, a_inv: np.ndarray, c: np.ndarray
                 ) -> tuple[float, float, np.ndarray, tuple[float, float]] | None:
    """The robot pose errors the residuals show (:mod:`hmlvs.diagnostics.pose_errors`), when
    the data set says which points share a pose (``pose_index``) and some pose has several:
    the pixel and point noise without the pose errors' share (the residuals projected off
    each pose's own pose error as well), the pose errors' part of the covariance (scaled data
    coordinates) and their spread (mm, deg RMS per axis); None when they show none.

    A pose error (rotation vector w, translation t, in the hand frame) moves a point p_h
    (hand frame) of its pose by R_bh (w x p_h + t). With no board poses to give the spread's
    shape, a rotation and a translation that move the points as much count alike: the
    rotation's sigma is the translation's over the points' RMS distance from the flange.
    ``c``: the white noise's moment coefficients for the Jacobian's own projector
    (:func:`_noise_moments`)."""
    ds = an.dataset
    if ds.pose_index is None:
        return None
    index = np.asarray(ds.pose_index)
    groups = [np.flatnonzero(index == k) for k in np.unique(index)]
    if max(len(g) for g in groups) < 2 or 18 * len(ds) * len(groups) > MAX_POSE_ENTRIES:
        return None
    cam, valid = points_in_camera(an.q, ds.pixels, on_invalid="mask")
    if not valid.all():
        return None
    hfc = hand_from_camera(an.q)
    hand = cam @ hfc[:3, :3].T + hfc[:3, 3]
    lever = float(np.sqrt(np.mean(np.sum(hand ** 2, axis=1))))
    rot = np.asarray(ds.poses)[:, :3, :3]
    je = np.concatenate([-np.einsum("mij,mjk->mik", rot, skew(hand)) / lever, rot], axis=2)
    m = len(ds)
    extra = np.zeros((3 * m, 6 * len(groups)))
    rows, pose_jac = [], []
    for k, g in enumerate(groups):
        rw = (3 * g[:, None] + np.arange(3)).ravel()
        rows.append(rw)
        pose_jac.append(je[g].reshape(-1, 6))
        extra[rw, 6 * k:6 * k + 6] = pose_jac[-1]
    sp, st = _estimate_noise(an, wp, _basis(np.c_[an.scaled, extra]))
    white = sp ** 2 * (c[0, 0] + c[1, 0]) + st ** 2 * (c[0, 1] + c[1, 1])
    var = sp ** 2 * wp + st ** 2 * np.eye(3)[None]
    white_sd = math.sqrt(2.0 * float(np.einsum("mij,mji->", var, var)))
    part = pose_error_part(an.scaled, a_inv, rows, pose_jac, an.residuals.ravel(), white,
                           white_sd)
    if part is None:
        return None
    return sp, st, part[0], (part[1], math.degrees(part[1] / lever))


def _uncertainty_warnings(r: int, p: int, names: tuple[str, ...], det: dict[str, bool],
                          combos: list[Combination], flat_names: tuple[str, ...],
                          chart_singular: bool, rotation_free: bool, phi: float,
                          std_arr: np.ndarray) -> list[str]:
    """What the covariance cannot say: a rank deficit (which standard deviations are then
    meaningless, which combinations are determined) and the Euler angles at or near the
    gimbal lock."""
    warnings_: list[str] = []
    if r < p:
        bad = [n for n in names if not det[n]]
        good = [c.name for c in combos if c.determined]
        warnings_.append(
            f"the covariance is rank-deficient ({r} of {p}): the data do not determine "
            f"{p - r} direction(s) among the free parameters"
            + (f" ({'; '.join(flat_names)})" if flat_names else "")
            + "; the standard deviations of " + ", ".join(bad) + " are those of the "
            "minimum-norm pseudo-inverse and are not meaningful"
            + (f"; these combinations are determined: {', '.join(good)}" if good else ""))
    if chart_singular:
        warnings_.append(f"phi = {phi:.3g} rad: the ZYZ Euler angles are at the gimbal lock; "
                         "omega, phi and varphi have no meaningful standard deviations, the "
                         "rotation (rotation_std) and omega + varphi do")
    elif rotation_free and "phi" in det and abs(phi) < 3 * std_arr[names.index("phi")]:
        warnings_.append(f"phi = {phi:.3g} rad is within 3 standard deviations of 0 (std "
                         f"{std_arr[names.index('phi')]:.2g}): the Euler angles are near the "
                         "gimbal lock and their errors are far from Gaussian; read omega + "
                         "varphi and rotation_std")
    return warnings_


def _bound_notes(bounds: Bounds | None, free_idx: np.ndarray, q: np.ndarray) -> list[str]:
    """A note naming the free parameters that ended at a bound (the covariance ignores it)."""
    if bounds is None:
        return []
    at = [NAMES[i] for i in free_idx if q[i] <= bounds.lower[i] or q[i] >= bounds.upper[i]]
    if not at:
        return []
    euler = [n for n in at if n in ("omega", "phi", "varphi")]
    return ["at a bound: " + ", ".join(at) + "; the covariance treats them as unconstrained" + (
        "; Euler angles at a bound near phi = 0 usually mean the ZYZ gimbal lock, not a bad "
        "fit: read the rotation vector (docs/glossary.md#at-a-bound)" if euler else "")]


def _correlation(shape: np.ndarray) -> np.ndarray:
    """The correlation matrix of a covariance (0 where a variance is 0)."""
    d = np.sqrt(np.clip(np.diag(shape), 0.0, None))
    with np.errstate(divide="ignore", invalid="ignore"):
        corr = shape / np.outer(d, d)
    corr[~np.isfinite(corr)] = 0.0
    corr = np.clip(corr, -1.0, 1.0)
    np.fill_diagonal(corr, 1.0)
    return corr


def _to_paper(an: Analysis, scales: np.ndarray) -> tuple[np.ndarray, list[int], bool]:
    """The map from the analysis' scaled data coordinates to the paper parameters (Euler
    rates = B^+ delta where the rotation is free), the Euler angles' positions among the free
    parameters, and whether the Euler chart is singular there (the gimbal lock)."""
    p, free_idx = an.p, an.free_idx
    t = np.eye(p)
    euler_pos = [int(np.nonzero(free_idx == i)[0][0]) for i in EULER_INDEX] if an.rotation_free \
        else []
    bsv = np.linalg.svd(an.B, compute_uv=False)
    chart_singular = bool(an.rotation_free and bsv[-1] < 1e-9 * bsv[0])
    if an.rotation_free:
        t[np.ix_(euler_pos, euler_pos)] = np.linalg.pinv(an.B, rcond=1e-9)
    return t * scales[None, :], euler_pos, chart_singular


def _compute(an: Analysis, pixel_noise: float | None = None,
             point_noise: float | None = None, flat_names: Iterable[str] = (),
             bounds: Bounds | None = None) -> Uncertainty:
    check_noise(pixel_noise, point_noise)
    given = pixel_noise is not None or point_noise is not None
    p, free_idx, q = an.p, an.free_idx, an.q
    a = an.scaled
    sv, vt, r = an.sv, an.vt, an.rank
    m = len(an.dataset)
    dof = 3 * m - r
    if dof <= 0:
        raise ValueError(f"no residual degrees of freedom: {3 * m} residual components for "
                         f"rank {r}; add points")
    vr = vt[:r].T
    pinv_info = (vr / sv[:r] ** 2) @ vr.T  # (A^T A)^+ in scaled coordinates
    sigma = float(np.sqrt(np.sum(an.residuals ** 2) / dof))
    ai = a.reshape(m, 3, p)
    gp = an.jacobian[:, :, [param_index("Cu"), param_index("Cv")]]  # = -dE/d(u, v)
    wp = np.einsum("mik,mjk->mij", gp, gp)  # residual covariance per unit pixel noise
    estimated = not given
    pixel_noise, point_noise, pose_cov_x, pose_errors = _noise_levels(
        an, wp, r, pinv_info) if estimated else (pixel_noise, point_noise, None, None)
    meat = np.zeros((p, p))
    if pixel_noise:
        meat += pixel_noise ** 2 * np.einsum("mip,mij,mjq->pq", ai, wp, ai)
    if point_noise:
        meat += point_noise ** 2 * (a.T @ a)
    cov_x = pinv_info @ meat @ pinv_info + (0.0 if pose_cov_x is None else pose_cov_x)
    # the correlation does not depend on the noise level (noise-free data: every std is 0)
    shape_x = cov_x if np.any(cov_x) else pinv_info
    s = an.scales[free_idx]
    # data coordinates -> paper parameters: Euler rates = B^+ delta
    ts, euler_pos, chart_singular = _to_paper(an, s)
    cov = ts @ cov_x @ ts.T
    cov = (cov + cov.T) / 2
    std_arr = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    shape = ts @ shape_x @ ts.T
    corr = _correlation(shape)

    vnull = vt[r:].T

    def determined(g_paper: np.ndarray) -> bool:
        """Whether a function with this gradient (free paper parameters) is determined."""
        gx = ts.T @ g_paper  # gradient in scaled data coordinates
        n = float(np.linalg.norm(gx))
        if n > 0 and vnull.size and np.linalg.norm(vnull.T @ gx) > _DETERMINED_TOL * n:
            return False
        if chart_singular:  # the gimbal lock: a gradient must not see omega - varphi
            ge = g_paper[euler_pos]
            if abs(ge[0] - ge[2]) > _DETERMINED_TOL * max(float(np.linalg.norm(g_paper)),
                                                          1e-300):
                return False
            if abs(ge[1]) > 0:  # phi = |tilt| is not differentiable at the gimbal lock
                return False
        return True

    names = tuple(NAMES[i] for i in free_idx)
    det = {n: determined(np.eye(p)[k]) for k, n in enumerate(names)}
    phi = q[EULER_INDEX[1]]
    combos = []
    for name, unit, value, g, desc in _combination_gradients(q, abs(phi) < GIMBAL_PHI):
        gf = g[free_idx]
        if not np.any(gf):
            continue
        combos.append(Combination(name, unit, float(value),
                                  float(np.sqrt(max(gf @ cov @ gf, 0.0))), determined(gf),
                                  desc))
    rot_std = np.sqrt(np.clip(np.diag(cov_x)[euler_pos], 0.0, None)) * s[euler_pos] \
        if an.rotation_free else None
    flat_names = tuple(flat_names)
    warnings_ = _uncertainty_warnings(r, p, names, det, combos, flat_names, chart_singular,
                                      an.rotation_free, phi, std_arr)
    notes = _bound_notes(bounds, free_idx, q)
    return Uncertainty(
        free=names, covariance=cov, std={n: float(v) for n, v in zip(names, std_arr)},
        correlation=corr, determined=det, combinations=tuple(combos), rotation_std=rot_std,
        noise_model="estimated" if estimated else "given", sigma=sigma,
        pixel_noise=None if pixel_noise is None else float(pixel_noise),
        point_noise=None if point_noise is None else float(point_noise), dof=int(dof),
        rank=r, flat=flat_names, warnings=warnings_, notes=notes, pose_errors=pose_errors)


def uncertainty(dataset: Dataset, params: Parameters | np.ndarray,
                fixed: Iterable[str] | str = ("Su",),
                pixel_noise: float | None = None, point_noise: float | None = None,
                bounds: Bounds | None = None, null_tol: float = NULL_TOL) -> Uncertainty:
    """Covariance, standard deviations, correlations and identifiable combinations.

    Parameters
    ----------
    dataset : the points the parameters were fitted to (:class:`Dataset` or a simulation)
    params : the fitted parameters (e.g. ``result.params``)
    fixed : the parameters held fixed in the fit (default Su, as :func:`calibrate`)
    pixel_noise : standard deviation of the stripe pixels (px). Give it (or ``point_noise``, or
        both) when known; by default both are estimated from the residuals
    point_noise : standard deviation of each coordinate of the reference points (mm)
    bounds : the fit's bounds (for the column scaling and a note on parameters at a bound)
    null_tol : relative singular value below which a direction is null (see
        :data:`hmlvs.diagnostics.identifiability.NULL_TOL`)

    Returns
    -------
    Uncertainty
    """
    dataset, q = check_inputs(dataset, params)
    an = analyse(dataset, q, fixed, bounds, null_tol, max(WEAK_TOL, 10 * null_tol))
    flat = [d.name for d in report_of(an).directions if d.status == "null"
            and not d.parametrization_only]
    return _compute(an, pixel_noise, point_noise, flat, bounds)


def diagnose(dataset: Any, params: Any, fixed: Iterable[str] | str,
             bounds: Bounds | None = None, pixel_noise: float | None = None,
             point_noise: float | None = None, loss: str | None = None):
    """Identifiability report, uncertainty and the data warnings at a solution.

    Used by :func:`calibrate`. Returns ``(report, uncertainty, warnings)``: the warnings
    name the data's own problems (too few points, one pose, one image line) and every null
    or weak direction among the free parameters with what to do about it.
    """
    dataset, q = check_inputs(dataset, params)
    an = analyse(dataset, q, fixed, bounds)
    rep = report_of(an)
    flat = [d.name for d in rep.directions if d.status == "null" and not d.parametrization_only]
    unc = _compute(an, pixel_noise, point_noise, flat, bounds)
    if loss is not None:
        unc.notes.append(f"computed for plain least squares: the {loss} loss's down-weighting "
                         "of large residuals is not included")
    out = list(rep.warnings)
    for d in rep.directions:
        what = "flat" if d.status == "null" else "weakly determined"
        top = ", ".join(n for n, _ in d.top(5))
        out.append(f"{what} direction among the free parameters: {d.name} (moves {top}); "
                   f"{d.description}; {d.recommendation}")
    if not rep.gimbal_lock:
        out += [w for w in unc.warnings if "gimbal lock" in w]
    return rep, unc, out
