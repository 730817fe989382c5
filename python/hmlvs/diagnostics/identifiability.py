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
from ..models.params import (
    NAMES,
    Bounds,
    Parameters,
)
from .analysis import (  # noqa: F401 (re-exported: the analysis lived here first)
    COLLINEAR_PIXELS,
    EULER_INDEX,
    GIMBAL_PHI,
    IN_FLAT,
    MIN_POINTS_PER_PARAMETER,
    NULL_TOL,
    PRIOR_KNOWN,
    ROTATION_NAMES,
    SAME_POSE_DEGREES,
    SAME_POSE_MM,
    WEAK_TOL,
    Analysis,
    Direction,
    IdentifiabilityReport,
    analyse,
    check_inputs,
    euler_rate_map,
    rotation_jacobian,
)
from .directions import (  # noqa: F401 (re-exported)
    camera_y_tangent,
    gimbal_tangent,
    known_directions,
    scale_gauge_tangent,
    unnamed_directions,
)


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
    order = [n for n in PRIOR_KNOWN if n in rows] + sorted(
        (n for n in rows if n not in PRIOR_KNOWN), key=lambda n: -weight[n])
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
                  if all(n in PRIOR_KNOWN for n in suggested) else "at known values")
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
    known = known_directions(an)
    unnamed = unnamed_directions(an, known)
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
