"""Where a laser stripe ends on an edge of the laser-off image (the gauge-block check)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np


@dataclass(frozen=True)
class StripeEnd:
    """Where a stripe segment ends in the image, located to sub-pixel precision.

    ``pixel`` (u, v); ``cov`` its 2x2 covariance (px^2) from the image noise; ``line`` the
    fitted centre line (v = a + b (u - u_end)) as (a, b, u_end); ``columns`` the number of
    stripe centres the line was fitted to; ``method`` "edges" or "energy";
    ``energy_end`` the end found from the stripe's energy alone; ``edge_spread`` the
    distance (px) between the intersections with the two edges (0 with one edge).
    """

    pixel: np.ndarray
    cov: np.ndarray
    line: tuple[float, float, float]
    columns: int
    method: str
    energy_end: np.ndarray
    edge_spread: float = 0.0


def _bilinear(img: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    h, w = img.shape
    u = np.clip(u, 0, w - 1.000001)
    v = np.clip(v, 0, h - 1.000001)
    u0, v0 = np.floor(u).astype(int), np.floor(v).astype(int)
    fu, fv = u - u0, v - v0
    return ((1 - fv) * ((1 - fu) * img[v0, u0] + fu * img[v0, u0 + 1])
            + fv * ((1 - fu) * img[v0 + 1, u0] + fu * img[v0 + 1, u0 + 1]))


def _edge_line(off: np.ndarray, start: np.ndarray, direction: np.ndarray,
               reach: tuple[float, float] = (8.0, 40.0), half_width: float = 6.0
               ) -> tuple[np.ndarray, np.ndarray, float, int] | None:
    """A straight intensity edge in ``off`` running from near ``start`` along ``direction``:
    per step along it, the sub-pixel point where the profile across it passes half-way
    between the levels on its two sides; a line fitted to those points. Returns (a point on
    the line, its unit direction, the points' scatter across it (px), count) or None."""
    img = off.astype(float)
    e = direction / np.linalg.norm(direction)
    n = np.array([-e[1], e[0]])
    ts = np.arange(-half_width, half_width + 1e-9, 0.25)
    pts = []
    for s in np.arange(reach[0], reach[1] + 1e-9, 1.0):
        c = start + s * e
        prof = _bilinear(img, c[0] + ts * n[0], c[1] + ts * n[1])
        lo_side, hi_side = np.median(prof[ts <= -3]), np.median(prof[ts >= 3])
        if abs(hi_side - lo_side) < 8:
            continue
        mid = 0.5 * (lo_side + hi_side)
        sgn = np.sign(prof - mid)
        cross = np.nonzero(sgn[:-1] * sgn[1:] < 0)[0]
        if cross.size != 1:
            continue
        i = cross[0]
        t = ts[i] + (mid - prof[i]) / (prof[i + 1] - prof[i]) * (ts[i + 1] - ts[i])
        pts.append(c + t * n)
    if len(pts) < 8:
        return None
    pts = np.array(pts)
    centre = pts.mean(axis=0)
    _, sv, vt = np.linalg.svd(pts - centre)
    d = vt[0] * np.sign(vt[0] @ e)
    scatter = float(sv[1] / np.sqrt(max(len(pts) - 2, 1)))
    return centre, d, scatter, len(pts)


def locate_stripe_end(on: np.ndarray, off: np.ndarray, near: Sequence[float], *,
                      edges: Sequence[Sequence[float]] | None = None,
                      search_radius: float = 25.0, band: int = 5, fit_length: int = 60,
                      min_columns: int = 20) -> StripeEnd:
    """Sub-pixel end of the stripe segment that ends nearest to the pixel ``near``.

    Method (for a roughly horizontal stripe, one centre per image column):

    1. stripe centres from the albedo-normalised difference image (as
       :func:`hmlvs.image.scan.stripes_from_images` extracts them), split into segments where
       consecutive columns' centres jump by more than 2 px;
    2. the segment end nearest ``near`` (within ``search_radius`` px) is the candidate;
    3. a straight line is fitted to that segment's centres from 4 to ``4 + fit_length``
       columns inside the end (the last columns are affected by the end itself);
    4. "energy" end: along the line, each column's stripe energy is the sum of the plain
       difference image (paper Eq. 23) over ``2 band + 1`` rows around the line; the end is
       where this drops to half the plateau (median over the 6th to 25th columns inside),
       interpolated between columns. Where a single straight edge cuts the stripe this is
       exactly where the edge crosses the centre line, but at the tip of a wedge (a corner
       of a face, cut by two edges) it lies inside the tip, by 0.674 sigma / tan(a) px for a
       stripe of profile sigma bisecting a tip of angle 2a: 0.85 px (0.24 mm) on the gauge
       block's corners;
    5. "edges" end (when ``edges`` gives the image directions, from the end into the
       surface, of the surface's boundary edges at the end, e.g. predicted from the nominal
       geometry): each edge is located in the laser-off image (sub-pixel half-way crossings
       across it, 8 to 40 px from the energy end, a fitted line) and intersected with the
       stripe's centre line; the end is the mean of the intersections. This has no tip bias;
    6. the covariance: along the line, the edge lines' offset uncertainty over the sine of
       their angle to the stripe (or, for "energy", the plateau's scatter over the drop's
       slope); across it, the line fit's uncertainty at the end.

    Raises ``ValueError`` when no segment of at least ``min_columns`` columns ends near, or an
    edge cannot be found.
    """
    from .stripe import difference_image, extract_stripe, normalized_threshold

    d = difference_image(on, off, normalize=True)
    stripe = extract_stripe(d, threshold=normalized_threshold(on, off, d))
    line = _end_line(stripe.pixels, np.asarray(near, float), search_radius, fit_length,
                     min_columns)
    k_end, slope, plateau_k, ks, energy = _energy_drop(difference_image(on, off), line, band)
    b, u_end = line.b, line.u_end
    xe = line.inward * k_end
    energy_end = np.array([u_end + xe, line.a + b * xe])
    if not edges:
        kk = ks[plateau_k]
        trend = np.polyval(np.polyfit(kk, energy[plateau_k], 1), kk)
        var_u = (float(np.std(energy[plateau_k] - trend, ddof=2)) / slope) ** 2
        return StripeEnd(energy_end, line.cov(var_u, xe), line.params, line.n, "energy",
                         energy_end)
    pixel, var_u, spread = _edges_end(off, line, energy_end, edges)
    return StripeEnd(pixel, line.cov(var_u, pixel[0] - u_end), line.params, line.n, "edges",
                     energy_end, spread)


@dataclass
class _EndLine:
    """The straight line fitted to a stripe segment's centres inside its end:
    v = a + b (u - u_end), ``inward`` the direction of u into the segment."""

    a: float
    b: float
    u_end: float
    inward: int
    xs: np.ndarray  # the fitted columns, u - u_end
    s2: float  # the fit's residual variance (px^2)
    reach: float  # how far the segment reaches inside the end (columns)

    @property
    def n(self) -> int:
        return int(self.xs.size)

    @property
    def params(self) -> tuple[float, float, float]:
        return (float(self.a), float(self.b), self.u_end)

    def cov(self, var_u: float, xe: float) -> np.ndarray:
        """The end's covariance: ``var_u`` along u, the line fit's uncertainty across it at
        u_end + ``xe``."""
        sxx = float(np.sum((self.xs - self.xs.mean()) ** 2))
        across = self.s2 * (1.0 / self.xs.size + (xe - self.xs.mean()) ** 2 / sxx)
        b = self.b
        return np.array([[var_u, b * var_u], [b * var_u, b * b * var_u + across]])


def _end_line(px: np.ndarray, near: np.ndarray, search_radius: float, fit_length: int,
              min_columns: int) -> _EndLine:
    """The segment end of the stripe ``px`` nearest ``near`` and its line (steps 1-3 of
    :func:`locate_stripe_end`)."""
    if px.shape[0] < min_columns:
        raise ValueError(f"no laser stripe in the image ({px.shape[0]} columns found)")
    u, v = px[:, 0], px[:, 1]
    cut = np.nonzero((np.diff(u) > 1.5) | (np.abs(np.diff(v)) > 2.0))[0] + 1
    best = None
    for seg in np.split(np.arange(u.size), cut):
        if seg.size < min_columns:
            continue
        for end, inward in ((seg[0], 1), (seg[-1], -1)):
            dist = float(np.hypot(*(px[end] - near)))
            if best is None or dist < best[0]:
                best = (dist, seg, end, inward)
    if best is None or best[0] > search_radius:
        raise ValueError(f"no stripe segment of {min_columns} or more columns ends within "
                         f"{search_radius:g} px of the expected pixel {np.round(near, 1).tolist()}")
    _, seg, end, inward = best
    u_end = float(u[end])
    x = inward * (u[seg] - u_end)
    sel = (x >= 4) & (x <= 4 + fit_length)
    if sel.sum() < 8:
        raise ValueError(f"the stripe segment ending at u = {u_end:g} is too short to fit")
    xs, vs = u[seg][sel] - u_end, v[seg][sel]
    b, a = np.polyfit(xs, vs, 1)
    res = vs - (a + b * xs)
    return _EndLine(float(a), float(b), u_end, int(inward), xs,
                    float(np.sum(res ** 2) / max(xs.size - 2, 1)), float(x.max()))


def _energy_drop(raw: np.ndarray, line: _EndLine, band: int
                 ) -> tuple[float, float, np.ndarray, np.ndarray, np.ndarray]:
    """Step 4 of :func:`locate_stripe_end`: where the stripe's energy along ``line`` drops
    to half its plateau. Returns (the end in columns inside u_end, the drop's slope, the
    plateau's columns (mask), the columns, their energies)."""
    raw = raw.astype(float)
    h, w = raw.shape
    a, b, u_end, inward = line.a, line.b, line.u_end, line.inward
    ks = np.arange(-12, 26)
    cols = np.rint(u_end + inward * ks).astype(int)
    energy = np.full(ks.size, np.nan)
    for i, c in enumerate(cols):
        if 0 <= c < w:
            vc = int(np.rint(a + b * (c - u_end)))
            energy[i] = raw[max(vc - band, 0):min(vc + band + 1, h), c].sum()
    plateau_k = (ks >= 6) & (ks <= min(25.0, line.reach - 2)) & np.isfinite(energy)
    if plateau_k.sum() < 5:
        raise ValueError(f"the stripe end at u = {u_end:g} is too close to the image border")
    half = float(np.median(energy[plateau_k])) / 2
    for i in range(int(np.nonzero(ks == 6)[0][0]), 0, -1):
        lo_e, hi_e = energy[i - 1], energy[i]
        if np.isfinite(lo_e) and lo_e < half <= hi_e:
            return (ks[i - 1] + (half - lo_e) / (hi_e - lo_e), hi_e - lo_e, plateau_k, ks,
                    energy)
    raise ValueError(f"the stripe near u = {u_end:g} does not end (its energy never drops "
                     "to half the plateau)")


def _edges_end(off: np.ndarray, line: _EndLine, energy_end: np.ndarray,
               edges: Sequence[Sequence[float]]) -> tuple[np.ndarray, float, float]:
    """Step 5 of :func:`locate_stripe_end`: the mean of the stripe line's crossings with the
    surface's edges. Returns (the end, its variance along u, the crossings' spread)."""
    b = line.b
    line_dir = np.array([1.0, b]) / np.hypot(1.0, b)
    hits, var_along = [], []
    p0 = np.array([line.u_end, line.a])
    for e_dir in edges:
        found = _edge_line(off, energy_end, np.asarray(e_dir, float))
        if found is None:
            raise ValueError(f"the edge along {np.round(e_dir, 2).tolist()} from the stripe end "
                             f"{np.round(energy_end, 1).tolist()} is not visible in the laser-off "
                             "image")
        c, de, scatter, count = found
        # stripe line p0 + s line_dir meets edge line c + r de
        m = np.column_stack([line_dir, -de])
        s_r = np.linalg.solve(m, c - p0)
        hits.append(p0 + s_r[0] * line_dir)
        sin = abs(line_dir[0] * de[1] - line_dir[1] * de[0])
        # the edge line's offset at the corner: scatter^2 (1/n + r^2 / sum(r_k^2)), with
        # the fit's points spread uniformly over 32 px
        var_off = scatter ** 2 * (1.0 / count + s_r[1] ** 2 / (count * 32.0 ** 2 / 12))
        var_along.append(var_off / max(sin, 1e-3) ** 2)
    return (np.mean(hits, axis=0), float(np.sum(var_along)) / len(var_along) ** 2,
            float(np.linalg.norm(hits[0] - hits[-1])))
