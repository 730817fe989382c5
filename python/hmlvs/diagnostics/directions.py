"""The flat directions of the paper's 14 parameters: the known exact ones (scale gauge, camera
y shift, ZYZ gimbal lock) as tangents, and those the SVD finds beyond them, named by their
largest loadings."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..models.paper import hand_from_camera
from ..models.params import (
    NAMES,
    NUM_PARAMS,
    Parameters,
    param_index,
)
from .analysis import (
    EULER_INDEX,
    IN_FLAT,
    PRIOR_KNOWN,
    ROTATION_DESCRIPTION,
    Analysis,
    Direction,
)


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


def known_directions(an: Analysis) -> list[Direction]:
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


def unnamed_directions(an: Analysis, known: list[Direction]) -> list[Direction]:
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
        # PRIOR_KNOWN, then by loading, that it moves and that keeps the signatures
        # independent): with Su free the tilt then comes out as it is with Su and Sv fixed,
        # not mixed with the camera shift as an orthogonal complement would be.
        coords = [an.coordinates[i] for i in an.free_idx]
        order = [coords.index(n) for n in PRIOR_KNOWN if n in coords]
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
        label = ", ".join(f"{ROTATION_DESCRIPTION.get(n, n)}" for n, _ in lead)
        names_in = [n for n, _ in lead]
        prior = [n for n in PRIOR_KNOWN if n in names_in]
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
