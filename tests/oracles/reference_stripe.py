"""An independent NumPy/OpenCV version of the stripe extraction, as a parity oracle.

Written from the definitions in ``cpp/hmlvs/image/image.h`` (not from the C++ code): runs of
pixels above the threshold along each image column, their peak and full width at half
maximum, the choice of one peak, and the three centre methods. Vectorised over columns,
so that it is also a fair NumPy baseline for ``bench/bench_stripe.py``. Rows are handled by
transposing the image.
"""

from __future__ import annotations

import numpy as np

FOUND, NONE, MULTIPLE, TOO_NARROW, TOO_WIDE, FIT_FAILED = range(6)
MAX_RUNS = 8


def difference(on: np.ndarray, off: np.ndarray, normalize: bool = False) -> np.ndarray:
    a = on.astype(np.float64)
    b = off.astype(np.float64)
    if not normalize:
        return np.where(a > b, a - b, 0).astype(on.dtype)
    mean = b.mean()
    d = (a - b) * mean / np.maximum(b, max(1.0, 0.1 * mean))
    top = np.iinfo(on.dtype).max
    return np.where(a > b, np.minimum(top, np.floor(d + 0.5)), 0).astype(on.dtype)
    # (the C++ code computes 8-bit images in single precision: it may round a value lying
    # within ~1e-4 of a half-integer the other way)


def noise_estimate(img: np.ndarray) -> float:
    x = img[::4].ravel().astype(np.int64)
    s0 = int(np.searchsorted(np.cumsum(np.bincount(x)), 0.8413 * x.size))
    cut = max(2, 4 * s0)
    bg = x[x <= cut].astype(float)
    var = 2.0 * np.mean(bg ** 2) if bg.size else 0.0
    return float(np.sqrt(var + 1.0 / 6.0))


def kernels(sigma: float, r: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Gaussian derivative kernels of radius ``r`` (default ceil(3.5 sigma)); radius 0 has
    no derivatives."""
    r = int(np.ceil(3.5 * sigma)) if r is None else r
    x = np.arange(-r, r + 1, dtype=float)
    g0 = np.exp(-x ** 2 / (2 * sigma ** 2))
    g0 /= g0.sum()
    if r == 0:
        return g0, np.zeros(1), np.zeros(1)
    g1 = x * g0 / np.sum(x ** 2 * g0)
    g2 = (x ** 2 - sigma ** 2) * g0
    g2 = g2 - g2.sum() * g0
    g2 *= 2.0 / np.sum(x ** 2 * g2)
    return g0, g1, g2


def extract(image: np.ndarray, direction: str = "columns", method: str = "centroid",
            threshold: float | None = None, min_width: float = 2.0, max_width: float = 40.0,
            noise: float | None = None, steger_sigma: float = 1.5, dominance: float = 0.0,
            steger_sigma_along: float | None = None) -> dict[str, np.ndarray]:
    """Same contract as ``hmlvs.extract_stripe``; returns a dict of arrays."""
    img = image if direction == "columns" else image.T
    noise_v = noise_estimate(image) if noise is None else float(noise)
    if threshold is None:
        threshold = max(5 * noise_v, 0.15 * float(image[::4].max()))
    d = img.astype(np.float64)
    h, w = d.shape
    above = d > np.floor(threshold)
    # runs along each column: flatten column-major so that runs are contiguous segments
    f = np.ascontiguousarray(d.T).ravel()
    a = np.ascontiguousarray(above.T).ravel()
    a_prev = np.concatenate([[False], a[:-1]])
    a_prev[::h] = False  # a run never continues from the previous column
    a_next = np.concatenate([a[1:], [False]])
    a_next[h - 1::h] = False
    b_idx = np.nonzero(a & ~a_prev)[0]
    e_idx = np.nonzero(a & ~a_next)[0] + 1
    col = b_idx // h
    n_runs = np.bincount(col, minlength=w)
    nr = b_idx.size

    # peak value and first position of the maximum in each run
    fpad = np.concatenate([f, [0.0]])
    inter = np.empty(2 * nr, dtype=np.int64)
    inter[0::2] = b_idx
    inter[1::2] = e_idx
    pk = np.maximum.reduceat(fpad, inter)[0::2] if nr else np.zeros(0)
    lengths = e_idx - b_idx
    run_of = np.repeat(np.arange(nr), lengths)
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]]) if nr else np.zeros(0, np.int64)
    flat = b_idx[run_of] + (np.arange(run_of.size) - starts[run_of])
    is_max = f[flat] == pk[run_of]
    big = np.iinfo(np.int64).max
    cand = np.where(is_max, flat, big)
    m_idx = np.minimum.reduceat(cand, starts) if nr else np.zeros(0, np.int64)
    m = m_idx - col * h  # row of the peak

    # FWHM: walk out to the half-maximum crossings (at most limit + 1 steps)
    limit = int(np.ceil(max_width)) + 2
    half = 0.5 * pk
    dcol = d[:, col] if nr else np.zeros((h, 0))
    ar = np.arange(nr)
    i = m.copy()
    for _ in range(limit + 1):
        go = (i > 0) & (m - i <= limit)
        go[go] &= dcol[i[go] - 1, ar[go]] > half[go]
        if not go.any():
            break
        i[go] -= 1
    j = m.copy()
    for _ in range(limit + 1):
        go = (j < h - 1) & (j - m <= limit)
        go[go] &= dcol[j[go] + 1, ar[go]] > half[go]
        if not go.any():
            break
        j[go] += 1
    left = np.full(nr, -0.5)
    lo_ok = i > 0
    lo = dcol[np.maximum(i - 1, 0), ar]
    hi = dcol[i, ar]
    left[lo_ok] = (i - 1 + (half - lo) / np.where(hi != lo, hi - lo, 1))[lo_ok]
    right = np.full(nr, h - 0.5)
    hi_ok = j < h - 1
    hi2 = dcol[j, ar]
    lo2 = dcol[np.minimum(j + 1, h - 1), ar]
    right[hi_ok] = (j + (hi2 - half) / np.where(hi2 != lo2, hi2 - lo2, 1))[hi_ok]
    width = right - left
    width[(m - i > limit) | (j - m > limit)] = np.inf

    # a run whose half-maximum span [i, j] holds a stronger run's peak (ties: the earlier
    # run is stronger) in its column is a shoulder: no peak of its own
    shoulder = np.zeros(nr, bool)
    for off in range(1, MAX_RUNS):
        a = np.arange(max(nr - off, 0))
        b = a + off
        same = col[a] == col[b]
        a, b = a[same], b[same]
        b_wins = pk[b] > pk[a]
        shoulder[a[b_wins & (m[b] >= i[a]) & (m[b] <= j[a])]] = True
        shoulder[b[~b_wins & (m[a] >= i[b]) & (m[a] <= j[b])]] = True
    narrow = (width < min_width) & ~shoulder
    wide = (width > max_width) & ~shoulder
    valid = ~narrow & ~wide & ~shoulder
    n_valid = np.bincount(col, weights=valid, minlength=w).astype(int)
    n_wide = np.bincount(col, weights=wide, minlength=w).astype(int)

    def best_of(mask: np.ndarray) -> np.ndarray:
        """Per column, the run index with the largest peak among mask (first on ties)."""
        out = np.full(w, -1)
        idx = np.nonzero(mask)[0]
        # runs are sorted by column then position: the first of equal peaks wins
        order = np.lexsort((idx, -pk[idx], col[idx]))
        idx = idx[order]
        first = np.ones(idx.size, bool)
        first[1:] = col[idx][1:] != col[idx][:-1]
        out[col[idx][first]] = idx[first]
        return out

    bv, bw, bn = best_of(valid), best_of(wide), best_of(narrow)
    status = np.full(w, NONE, np.uint8)
    centre = np.full(w, np.nan)
    sigma = np.full(w, np.nan)
    intensity = np.full(w, np.nan)
    wid = np.full(w, np.nan)
    num_peaks = n_valid + n_wide
    has = n_runs > 0
    over = n_runs > MAX_RUNS
    none_valid = has & ~over & (n_valid == 0)
    shown = np.where(n_wide > 0, bw, bn)
    status[none_valid] = np.where(n_wide[none_valid] > 0, TOO_WIDE, TOO_NARROW)
    intensity[none_valid] = pk[shown[none_valid]]
    wid[none_valid] = width[shown[none_valid]]
    status[over] = MULTIPLE
    num_peaks = np.where(over, n_runs, num_peaks)
    sel = has & ~over & (n_valid > 0)
    cols = np.nonzero(sel)[0]
    best = bv[cols]
    intensity[cols] = pk[best]
    wid[cols] = width[best]
    # strongest competitor other than the chosen peak
    comp = (width >= min_width) & ~shoulder
    second = np.zeros(w)
    others = comp.copy()
    others[bv[bv >= 0]] = False
    np.maximum.at(second, col[others], pk[others])
    multi = (num_peaks[cols] > 1) & ~((dominance >= 1) & (pk[best] >= dominance * second[cols]))
    status[cols[multi]] = MULTIPLE
    cols, best = cols[~multi], best[~multi]

    if method == "centroid":
        wts = f[flat] - threshold
        rows = (flat - col[run_of] * h).astype(float)
        sw = np.bincount(run_of, weights=wts, minlength=nr)
        swp = np.bincount(run_of, weights=wts * rows, minlength=nr)
        c = swp / np.where(sw > 0, sw, 1)
        m2 = np.bincount(run_of, weights=(rows - c[run_of]) ** 2, minlength=nr)
        s = noise_v * np.sqrt(m2) / np.where(sw > 0, sw, 1)
        ok = sw[best] > 0
        cen, sig = c[best], s[best]
    elif method == "gaussian":
        mm = m[best]
        ok = (mm > 0) & (mm < h - 1) & (pk[best] < np.iinfo(image.dtype).max)
        mc = np.clip(mm, 1, h - 2)
        av = np.maximum(d[mc - 1, cols], 0.5)
        bv_ = np.maximum(d[mc, cols], 0.5)
        cv = np.maximum(d[mc + 1, cols], 0.5)
        la, lb, lc = np.log(av), np.log(bv_), np.log(cv)
        num, den = la - lc, la - 2 * lb + lc
        ok &= den < 0
        dsafe = np.where(den < 0, den, -1.0)
        delta = 0.5 * num / dsafe
        ok &= np.abs(delta) <= 1
        da = (dsafe - num) / (2 * dsafe ** 2) / av
        db = num / dsafe ** 2 / bv_
        dc = (-dsafe - num) / (2 * dsafe ** 2) / cv
        cen = mm + delta
        sig = noise_v * np.sqrt(da ** 2 + db ** 2 + dc ** 2)
    elif method == "steger":
        import cv2
        g0, g1, g2 = kernels(steger_sigma)
        sa = steger_sigma if steger_sigma_along is None else steger_sigma_along
        src = d.astype(np.float64)
        full = int(np.ceil(3.5 * sa))
        # along the stripe (x), the kernel is cut short symmetrically at the image's edges:
        # column c uses radius min(full, c, w - 1 - c)
        radius = np.minimum(full, np.minimum(np.arange(w), w - 1 - np.arange(w)))
        gs, gp, gss, gpp, gsp = (np.empty_like(src) for _ in range(5))
        k0 = np.empty(w)

        def filt(kx: np.ndarray, ky: np.ndarray, c: int | None) -> np.ndarray:
            """The whole image filtered (c None), or column c alone: filtered on the strip
            its cut kernel covers, so that no column is replicated."""
            r = kx.size // 2
            part = src if c is None else src[:, c - r:c + r + 1]
            out = cv2.sepFilter2D(part, cv2.CV_64F, kx, ky, borderType=cv2.BORDER_REPLICATE)
            return out if c is None else out[:, r]

        for c in [None] + np.nonzero(radius < full)[0].tolist():
            a0, a1, a2 = kernels(sa, full if c is None else int(radius[c]))
            at = slice(None) if c is None else c
            gs[:, at], gp[:, at] = filt(a1, g0, c), filt(a0, g1, c)
            gss[:, at], gpp[:, at], gsp[:, at] = filt(a2, g0, c), filt(a0, g2, c), \
                filt(a1, g1, c)
            k0[at] = np.sum(a0 ** 2)
        k1 = np.sum(g1 ** 2)
        # a kernel cut below ceil(steger_sigma) is not fitted
        near_edge = radius[cols] < min(full, int(np.ceil(steger_sigma)))
        mm = m[best].copy()
        ok = ~near_edge
        done = np.zeros(cols.size, bool)
        cen = np.full(cols.size, np.nan)
        sig = np.full(cols.size, np.nan)
        for step in range(3):
            act = ok & ~done
            if not act.any():
                break
            r_, c_ = mm[act], cols[act]
            hss, hpp, hsp = gss[r_, c_], gpp[r_, c_], gsp[r_, c_]
            mean = 0.5 * (hss + hpp)
            rad = np.sqrt(0.25 * (hss - hpp) ** 2 + hsp ** 2)
            lam = mean - rad
            ns, np_ = hsp, lam - hss
            ns2, np2 = lam - hpp, hsp
            swap = ns2 ** 2 + np2 ** 2 > ns ** 2 + np_ ** 2
            ns, np_ = np.where(swap, ns2, ns), np.where(swap, np2, np_)
            norm = np.hypot(ns, np_)
            good = (lam < 0) & (norm > 0)
            ns, np_ = ns / np.where(norm > 0, norm, 1), np_ / np.where(norm > 0, norm, 1)
            good &= np.abs(np_) >= 0.5
            t = -(ns * gs[r_, c_] + np_ * gp[r_, c_]) / np.where(lam < 0, lam, -1)
            c_new = r_ + t / np.where(np_ != 0, np_, 1)
            close = np.abs(c_new - r_) <= 0.5
            last = step == 2
            accept = good & (close | last) & (np.abs(c_new - r_) <= 1.0)
            fail = ~good | ((close | last) & ~(np.abs(c_new - r_) <= 1.0))
            nxt = np.rint(c_new).astype(np.int64)
            fail |= good & ~(close | last) & ((nxt < 0) | (nxt >= h))
            ia = np.nonzero(act)[0]
            cen[ia[accept]] = c_new[accept]
            sig[ia[accept]] = (noise_v * np.sqrt(k0[c_] * k1) / np.abs(lam)
                               / np.abs(np_))[accept]
            done[ia[accept]] = True
            ok[ia[fail]] = False
            move = good & ~(close | last) & ~fail
            mm[ia[move]] = nxt[move]
        ok &= done
    else:
        raise ValueError(method)
    status[cols[~ok]] = FIT_FAILED
    status[cols[ok]] = FOUND
    centre[cols[ok]] = cen[ok]
    sigma[cols[ok]] = sig[ok]
    return {"centre": centre, "intensity": intensity, "width": wid, "sigma": sigma,
            "status": status, "num_peaks": num_peaks, "threshold": threshold, "noise": noise_v}
