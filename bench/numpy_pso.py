"""The same PSO (paper Eq. 19-21) vectorised with NumPy over the swarm: the comparison point
for the C++ optimizer in `make bench`. Same fitness F(q) = 1/2 sum ||E_i||^2."""

from __future__ import annotations

import numpy as np


def rot_zyz(w: np.ndarray, p: np.ndarray, v: np.ndarray) -> np.ndarray:
    cw, sw, cp, sp, cv, sv = np.cos(w), np.sin(w), np.cos(p), np.sin(p), np.cos(v), np.sin(v)
    return np.stack([
        np.stack([cw * cp * cv - sw * sv, -cw * cp * sv - sw * cv, cw * sp], -1),
        np.stack([sw * cp * cv + cw * sv, -sw * cp * sv + cw * cv, sw * sp], -1),
        np.stack([-sp * cv, sp * sv, cp], -1)], -2)


def fitness(q: np.ndarray, u: np.ndarray, v: np.ndarray, h: np.ndarray) -> np.ndarray:
    """F for a swarm q (n, 14) over points (u, v, reference in hand frame h (m, 3))."""
    f, su, sv, cu, cv, k, hh, th = (q[:, i:i + 1] for i in range(8))
    xd = su * (u - cu)
    yd = sv * (v - cv)
    inv = 1.0 / (1.0 + k * (xd * xd + yd * yd))
    xu, yu = xd * inv, yd * inv
    denom = yu + f * np.tan(th)
    rho = hh / denom
    cam = np.stack([rho * xu, rho * yu, rho * f], -1)  # (n, m, 3)
    r = rot_zyz(q[:, 8], q[:, 9], q[:, 10])  # (n, 3, 3)
    hand = np.einsum("nij,nmj->nmi", r, cam) + q[:, None, 11:14]
    out = 0.5 * np.sum((h[None] - hand) ** 2, axis=(1, 2))
    out[np.any(denom <= 0, axis=1)] = np.inf
    return out


def pso(u, v, h, lower, upper, swarm=50, iterations=5000, w_max=0.9, w_min=0.4, c1=2.0,
        c2=2.0, vmax=0.1, seed=0):
    rng = np.random.default_rng(seed)
    n = lower.size
    vlim = vmax * (upper - lower)
    x = rng.uniform(lower, upper, (swarm, n))
    vel = rng.uniform(-vlim, vlim, (swarm, n))
    fit = fitness(x, u, v, h)
    pbest, pfit = x.copy(), fit.copy()
    g = int(np.argmin(pfit))
    gbest, gfit = pbest[g].copy(), pfit[g]
    for t in range(iterations):
        w = w_max - (w_max - w_min) * t / iterations
        r1, r2 = rng.random((swarm, n)), rng.random((swarm, n))
        vel = np.clip(w * vel + c1 * r1 * (pbest - x) + c2 * r2 * (gbest - x), -vlim, vlim)
        x = x + vel
        out = (x < lower) | (x > upper)
        x = np.clip(x, lower, upper)
        vel[out] = 0.0
        fit = fitness(x, u, v, h)
        better = fit < pfit
        pbest[better], pfit[better] = x[better], fit[better]
        g = int(np.argmin(pfit))
        if pfit[g] < gfit:
            gbest, gfit = pbest[g].copy(), pfit[g]
    return gbest, gfit
