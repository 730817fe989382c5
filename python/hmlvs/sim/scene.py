"""Rendered scenes of objects on a table, and the paper's measurement scenarios (section 5).

A :class:`Scene` is a list of primitives in the robot base frame (mm): the table plane
(:class:`Table`, optionally textured), axis-aligned boxes (:class:`Box`) and cylinders with
the axis along x, y or z, solid or hollow, with circular holes through the wall
(:class:`Cylinder`, :class:`Hole`). :func:`render_scene` ray-traces it through the sensor
model of docs/model.md exactly as :mod:`hmlvs.sim.render` does for the checkerboard: every
supersample's (distorted) pixel gives an undistorted camera ray
(:func:`hmlvs.models.paper.rays_in_camera`), the camera pose is ``base_from_hand @
hand_from_camera``, the nearest surface along the ray gives the point, its normal and albedo.

- Laser-off frame: ``ambient * albedo * (a + (1 - a) max(0, n . l))`` with a fixed light
  direction ``l`` and ambient fraction ``a`` (the room light casts no shadows).
- Laser-on frame: the off frame plus ``laser * albedo * cos(incidence)`` times a Gaussian
  (``RenderOptions.stripe_sigma`` px) of the pixel distance to the stripe, where the pixel
  distance is the point's distance to the laser plane divided by its gradient per pixel,
  computed on the surface's tangent plane from the ray's derivative (so the stripe stays
  sharp where neighbouring samples see different surfaces). It is evaluated within 12 mm
  of the plane only: on surfaces seen at more than about 2 mm per pixel (grazing) the
  profile's far tails are cut. The laser's irradiance does not fall off with distance.
- Laser shadows are modelled: the laser is a fan from the point ``(0, H, 0)`` of the camera
  frame (the projector on the laser plane's baseline); a point gets laser light only if it
  faces the projector and the segment to the projector meets no surface. Light travelling
  further after a surface (reflections, inter-reflections) is not modelled.

Supersampling, blur, noise and rounding are :mod:`hmlvs.sim.render`'s (``RenderOptions``:
``supersample``, ``stripe_sigma``, ``blur_sigma``, ``laser``, ``ambient``, ``noise``; the
board albedos, glare and spurious peaks do not apply here).

The scenarios, :func:`cylinder_scan` (Fig. 13) and :func:`gauge_block` (Table 3), render
whole measurements, write them as image manifests (``hmlvs-images``), measure them with a
calibration obtained honestly from a simulated noisy checkerboard session
(:func:`simulated_calibration`), and compare with the truth.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal, Sequence, Union

import numpy as np

Axis = Literal["x", "y", "z"]

TINY = 1e-12


def _soft_sign(t_px: np.ndarray, width: float) -> np.ndarray:
    """-1 -> 1 across an edge at signed pixel distance 0: a cubic (C1) ramp over +-width px,
    a cheap stand-in for a Gaussian-smoothed step."""
    t = np.clip(t_px / width, -1.0, 1.0)
    return t * (1.5 - 0.5 * t * t)


def _unit(v: Sequence[float], name: str) -> np.ndarray:
    a = np.asarray(v, dtype=float)
    n = np.linalg.norm(a)
    if a.shape != (3,) or not np.isfinite(n) or n == 0:
        raise ValueError(f"{name} must be a non-zero 3-vector, got {v}")
    return a / n


def _vec3(v: Sequence[float], name: str) -> np.ndarray:
    a = np.asarray(v, dtype=float)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be three finite numbers (mm), got {v}")
    return a


def _albedo_ok(a: float, name: str) -> None:
    if not 0 <= a <= 1:
        raise ValueError(f"{name} must lie in [0, 1], got {a}")


def _quadratic(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Roots t1 <= t2 of a t^2 + b t + c (a >= 0); NaN where there are none or a ~ 0."""
    disc = b * b - 4 * a * c
    ok = (disc >= 0) & (a > TINY)
    sq = np.sqrt(np.where(ok, disc, 0.0))
    a2 = np.where(ok, 2 * a, 1.0)
    t1 = np.where(ok, (-b - sq) / a2, np.nan)
    t2 = np.where(ok, (-b + sq) / a2, np.nan)
    return t1, t2


# ------------------------------------------------------------------------------------------
# Primitives


@dataclass(frozen=True)
class Table:
    """The table plane ``z = height`` of the base frame, seen from above.

    ``texture="checker"`` paints squares of ``square`` mm alternating between ``albedo`` and
    ``albedo2`` (edges smoothed over the pixel footprint, as :mod:`hmlvs.sim.render` does for the
    board); None paints it uniformly with ``albedo``.
    """

    height: float = 0.0
    albedo: float = 0.45
    texture: Literal["checker"] | None = None
    square: float = 20.0
    albedo2: float = 0.25

    def __post_init__(self) -> None:
        _albedo_ok(self.albedo, "table albedo")
        _albedo_ok(self.albedo2, "table albedo2")
        if self.texture not in (None, "checker"):
            raise ValueError(f"table texture must be None or 'checker', got {self.texture!r}")
        if not self.square > 0:
            raise ValueError(f"table square must be > 0 mm, got {self.square}")

    def _hit(self, o: np.ndarray, d: np.ndarray, tmin: float
             ) -> tuple[np.ndarray, np.ndarray]:
        dz = d[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (self.height - o[..., 2]) / dz
        t = np.where(np.isfinite(t) & (t > tmin), t, np.inf)
        n = np.zeros_like(d)
        n[:, 2] = 1.0
        return t, n

    def _distance(self, p: np.ndarray) -> np.ndarray:
        return np.abs(p[:, 2] - self.height)

    def _albedo(self, p: np.ndarray, gx: np.ndarray, gy: np.ndarray, width: float
                ) -> np.ndarray:
        if self.texture is None:
            return np.full(p.shape[0], self.albedo)
        sq = self.square

        def soft_sign(c: np.ndarray, g: np.ndarray) -> np.ndarray:
            k = np.floor(c / sq)
            f = c / sq - k
            dist = sq * np.minimum(f, 1.0 - f) / np.maximum(g, TINY)
            return np.where(k % 2 == 0, 1.0, -1.0) * _soft_sign(dist, width)

        s = soft_sign(p[:, 0], gx) * soft_sign(p[:, 1], gy)
        return self.albedo2 + (self.albedo - self.albedo2) * (0.5 + 0.5 * s)


@dataclass(frozen=True)
class Box:
    """An axis-aligned box ``lo <= p <= hi`` (mm) of uniform albedo."""

    lo: tuple[float, float, float]
    hi: tuple[float, float, float]
    albedo: float = 0.7

    def __post_init__(self) -> None:
        lo, hi = _vec3(self.lo, "box lo"), _vec3(self.hi, "box hi")
        if np.any(hi <= lo):
            raise ValueError(f"box hi {list(hi)} must exceed lo {list(lo)} on every axis")
        _albedo_ok(self.albedo, "box albedo")
        object.__setattr__(self, "lo", tuple(lo.tolist()))
        object.__setattr__(self, "hi", tuple(hi.tolist()))

    def _hit(self, o: np.ndarray, d: np.ndarray, tmin: float
             ) -> tuple[np.ndarray, np.ndarray]:
        tn = np.full(d.shape[0], -np.inf)
        tf = np.full(d.shape[0], np.inf)
        ax = np.zeros(d.shape[0], np.int64)
        sgn = np.zeros(d.shape[0])
        for i in range(3):  # slabs one axis at a time: reductions over a short axis are slow
            di = d[:, i]
            di = np.where(np.abs(di) < TINY, TINY, di)
            oi = o[..., i]
            t1, t2 = (self.lo[i] - oi) / di, (self.hi[i] - oi) / di
            near, far = np.minimum(t1, t2), np.maximum(t1, t2)
            later = near > tn
            tn = np.where(later, near, tn)
            ax = np.where(later, i, ax)
            sgn = np.where(later, -np.sign(di), sgn)
            tf = np.minimum(tf, far)
        hit = (tn <= tf) & (tn > tmin)
        t = np.where(hit, tn, np.inf)
        n = np.zeros_like(d)
        n[np.arange(d.shape[0]), ax] = sgn
        return t, n

    def _distance(self, p: np.ndarray) -> np.ndarray:
        lo, hi = np.asarray(self.lo), np.asarray(self.hi)
        c, h = (lo + hi) / 2, (hi - lo) / 2
        q = np.abs(p - c) - h
        outside = np.linalg.norm(np.maximum(q, 0.0), axis=1)
        inside = np.minimum(q.max(axis=1), 0.0)
        return outside + np.abs(inside)

    def _albedo(self, p: np.ndarray, gx: np.ndarray, gy: np.ndarray, width: float
                ) -> np.ndarray:
        return np.full(p.shape[0], self.albedo)


@dataclass(frozen=True)
class Hole:
    """A circular hole drilled radially into a :class:`Cylinder`.

    Attributes
    ----------
    s : position of the hole's axis along the cylinder's axis, from the cylinder's centre (mm)
    angle : direction of the hole about the cylinder's axis (rad); 0 is straight up (+z) for
        a horizontal cylinder and +x for a vertical one, positive turning towards
        ``axis x reference``
    radius : hole radius (mm)
    depth : drilled depth from the outer surface (mm); None drills down to the axis: through
        one wall of a hollow cylinder, half way into a solid one
    """

    s: float
    angle: float
    radius: float
    depth: float | None = None


@dataclass(frozen=True)
class Cylinder:
    """A cylinder with its axis along base x, y or z (``centre`` is the axis' midpoint).

    ``bore > 0`` makes it a tube (inner radius ``bore``, open ends); ``holes`` are radial
    holes through (or into) its wall.
    """

    centre: tuple[float, float, float]
    radius: float
    length: float
    axis: Axis = "y"
    bore: float = 0.0
    holes: tuple[Hole, ...] = ()
    albedo: float = 0.6

    def __post_init__(self) -> None:
        object.__setattr__(self, "centre", tuple(_vec3(self.centre, "cylinder centre")))
        if self.axis not in ("x", "y", "z"):
            raise ValueError(f"cylinder axis must be 'x', 'y' or 'z', got {self.axis!r}")
        if not (self.radius > 0 and self.length > 0):
            raise ValueError(f"cylinder radius and length must be > 0 mm, got {self.radius}, "
                             f"{self.length}")
        if not 0 <= self.bore < self.radius:
            raise ValueError(f"cylinder bore must lie in [0, radius = {self.radius}), got "
                             f"{self.bore}")
        _albedo_ok(self.albedo, "cylinder albedo")
        holes = tuple(h if isinstance(h, Hole) else Hole(**h) for h in self.holes)
        for i, h in enumerate(holes):
            if not 0 < h.radius < self.radius:
                raise ValueError(f"hole {i}: radius must lie in (0, {self.radius}), got "
                                 f"{h.radius}")
            if abs(h.s) + h.radius > self.length / 2:
                raise ValueError(f"hole {i} at s = {h.s} mm with radius {h.radius} mm does "
                                 f"not fit on the cylinder of length {self.length} mm")
            if h.depth is not None and not 0 < h.depth <= self.radius:
                raise ValueError(f"hole {i}: depth must lie in (0, {self.radius}] mm or be "
                                 f"None, got {h.depth}")
        object.__setattr__(self, "holes", holes)

    # local frame: columns e1 (hole angle 0), e2, e3 (the axis)
    @property
    def frame(self) -> np.ndarray:
        e3 = {"x": [1.0, 0, 0], "y": [0, 1.0, 0], "z": [0, 0, 1.0]}[self.axis]
        e1 = [1.0, 0, 0] if self.axis == "z" else [0, 0, 1.0]
        e3, e1 = np.array(e3), np.array(e1)
        return np.stack([e1, np.cross(e3, e1), e3], axis=1)

    def _hole_geometry(self) -> list[tuple[np.ndarray, float, float, float]]:
        """Per hole: direction h (local, in the e1-e2 plane), s, radius, floor (the hole is
        the set ``p . h >= floor`` within ``radius`` of its axis)."""
        out = []
        for h in self.holes:
            hd = np.array([np.cos(h.angle), np.sin(h.angle), 0.0])
            floor = self.radius - h.depth if h.depth is not None else 0.0
            out.append((hd, float(h.s), float(h.radius), float(floor)))
        return out

    def local(self, p: np.ndarray) -> np.ndarray:
        """Base-frame points -> the cylinder's frame (x, y across, z along the axis)."""
        return (np.asarray(p, float) - np.asarray(self.centre)) @ self.frame

    def _hole_membership(self, pl: np.ndarray) -> np.ndarray:
        """(n, holes) bool: the local points lie in the removed volume of each hole."""
        out = np.zeros((pl.shape[0], len(self.holes)), bool)
        for k, (hd, s, r, floor) in enumerate(self._hole_geometry()):
            a = pl[:, 0] * hd[0] + pl[:, 1] * hd[1]
            qx, qy, qz = pl[:, 0] - a * hd[0], pl[:, 1] - a * hd[1], pl[:, 2] - s
            out[:, k] = (qx * qx + qy * qy + qz * qz < r * r) & (a >= floor)
        return out

    def _solid(self, pl: np.ndarray) -> np.ndarray:
        r2 = pl[:, 0] ** 2 + pl[:, 1] ** 2
        m = (r2 <= self.radius ** 2) & (np.abs(pl[:, 2]) <= self.length / 2)
        if self.bore > 0:
            m &= r2 >= self.bore ** 2
        if self.holes:
            m &= ~self._hole_membership(pl).any(axis=1)
        return m

    def _hit(self, o: np.ndarray, d: np.ndarray, tmin: float
             ) -> tuple[np.ndarray, np.ndarray]:
        m = self.frame
        ol = np.broadcast_to((o - np.asarray(self.centre)) @ m, d.shape)
        dl = d @ m
        n = d.shape[0]
        big = np.inf
        # entry into the convex hull (outer cylinder within the two end planes)
        a = dl[:, 0] ** 2 + dl[:, 1] ** 2
        b = 2 * (ol[:, 0] * dl[:, 0] + ol[:, 1] * dl[:, 1])
        c = ol[:, 0] ** 2 + ol[:, 1] ** 2 - self.radius ** 2
        r1, r2 = _quadratic(a, b, c)
        par = a <= TINY  # along the axis: inside the outer radius or not at all
        r1 = np.where(par, np.where(c <= 0, -big, np.nan), r1)
        r2 = np.where(par, np.where(c <= 0, big, np.nan), r2)
        half = self.length / 2
        dz = np.where(np.abs(dl[:, 2]) < TINY, TINY, dl[:, 2])
        z1, z2 = (-half - ol[:, 2]) / dz, (half - ol[:, 2]) / dz
        zn, zf = np.minimum(z1, z2), np.maximum(z1, z2)
        entry = np.fmax(r1, zn)
        exit_ = np.fmin(r2, zf)
        hull = ~np.isnan(r1) & (entry < exit_) & (exit_ > tmin)
        t = np.full(n, np.inf)
        nl = np.zeros((n, 3))
        if not hull.any():
            return t, nl @ m.T
        idx = np.nonzero(hull)[0]
        te = entry[idx]
        step = np.minimum(1e-3, 0.5 * (exit_[idx] - te)) / np.sqrt(
            np.einsum("ij,ij->i", dl[idx], dl[idx]))
        pin = ol[idx] + (te + step)[:, None] * dl[idx]
        fast = (te > tmin) & self._solid(pin)
        fi = idx[fast]
        t[fi] = te[fast]
        pe = ol[fi] + te[fast, None] * dl[fi]
        radial = r1[fi] >= zn[fi]
        nl[fi, 0] = np.where(radial, pe[:, 0] / self.radius, 0.0)
        nl[fi, 1] = np.where(radial, pe[:, 1] / self.radius, 0.0)
        nl[fi, 2] = np.where(radial, 0.0, -np.sign(dz[fi]))
        slow = idx[~fast]
        if slow.size:
            ts, ns = self._hit_csg(ol[slow], dl[slow], tmin)
            t[slow] = ts
            nl[slow] = ns
        return t, nl @ m.T

    def _hit_csg(self, ol: np.ndarray, dl: np.ndarray, tmin: float
                 ) -> tuple[np.ndarray, np.ndarray]:
        """First entry into the solid for rays that start inside the hull or enter it through
        a hole or the bore: every surface crossing is a candidate, the solid's membership
        is tested between consecutive candidates."""
        n = ol.shape[0]
        cands, kinds = [], []  # kind: 0 outer, 1 cap, 2 bore, 3 + 2k hole wall, 4 + 2k floor

        def add(tv: np.ndarray, kind: int) -> None:
            cands.append(tv)
            kinds.append(np.full(n, kind))

        a = dl[:, 0] ** 2 + dl[:, 1] ** 2
        b = 2 * (ol[:, 0] * dl[:, 0] + ol[:, 1] * dl[:, 1])
        c0 = ol[:, 0] ** 2 + ol[:, 1] ** 2
        for t_ in _quadratic(a, b, c0 - self.radius ** 2):
            add(t_, 0)
        dz = np.where(np.abs(dl[:, 2]) < TINY, TINY, dl[:, 2])
        for zc in (-self.length / 2, self.length / 2):
            add((zc - ol[:, 2]) / dz, 1)
        if self.bore > 0:
            for t_ in _quadratic(a, b, c0 - self.bore ** 2):
                add(t_, 2)
        for k, (hd, s, r, floor) in enumerate(self._hole_geometry()):
            # ray vs the hole's infinite cylinder: remove the component along hd
            oa = ol[:, 0] * hd[0] + ol[:, 1] * hd[1]
            da = dl[:, 0] * hd[0] + dl[:, 1] * hd[1]
            oq = ol - oa[:, None] * hd - np.array([0.0, 0.0, s])
            dq = dl - da[:, None] * hd
            for t_ in _quadratic(np.einsum("ij,ij->i", dq, dq), 2 * np.einsum("ij,ij->i", oq, dq),
                                 np.einsum("ij,ij->i", oq, oq) - r * r):
                add(t_, 3 + 2 * k)
            with np.errstate(divide="ignore", invalid="ignore"):
                add((floor - oa) / da, 4 + 2 * k)
        tc = np.stack(cands, axis=1)
        kc = np.stack(kinds, axis=1)
        tc = np.where(np.isfinite(tc), tc, np.inf)
        order = np.argsort(tc, axis=1)
        tc = np.take_along_axis(tc, order, axis=1)
        kc = np.take_along_axis(kc, order, axis=1)
        mid = 0.5 * (tc[:, :-1] + tc[:, 1:])
        ok = np.isfinite(mid) & (tc[:, :-1] > tmin)
        inside = np.zeros_like(ok)
        rows, cols = np.nonzero(ok)
        pts = ol[rows] + mid[rows, cols, None] * dl[rows]
        inside[rows, cols] = self._solid(pts)
        has = inside.any(axis=1)
        first = np.argmax(inside, axis=1)
        t = np.where(has, tc[np.arange(n), first], np.inf)
        kind = kc[np.arange(n), first]
        p = ol + np.where(has, t, 0.0)[:, None] * dl
        nl = np.zeros((n, 3))
        rad = np.hypot(p[:, 0], p[:, 1])
        rad = np.where(rad > 0, rad, 1.0)
        sel = kind == 0
        nl[sel, 0], nl[sel, 1] = p[sel, 0] / rad[sel], p[sel, 1] / rad[sel]
        sel = kind == 1
        nl[sel, 2] = np.sign(p[sel, 2])
        sel = kind == 2
        nl[sel, 0], nl[sel, 1] = -p[sel, 0] / rad[sel], -p[sel, 1] / rad[sel]
        for k, (hd, s, _r, _floor) in enumerate(self._hole_geometry()):
            sel = kind == 3 + 2 * k
            if sel.any():
                a_ = p[sel, 0] * hd[0] + p[sel, 1] * hd[1]
                q = p[sel] - a_[:, None] * hd - np.array([0.0, 0.0, s])
                nl[sel] = -q / np.maximum(np.linalg.norm(q, axis=1, keepdims=True), TINY)
            nl[kind == 4 + 2 * k] = hd
        nl[~has] = 0.0
        return t, nl

    def _distance(self, p: np.ndarray) -> np.ndarray:
        """Distance to the nearest surface piece (outer wall outside the holes, end faces,
        bore, hole walls and floors), each piece's distance taken as the hypot of the
        normal offset and how far the point lies beyond the piece's extent."""
        pl = self.local(p)
        R, half = self.radius, self.length / 2
        rad = np.hypot(pl[:, 0], pl[:, 1])
        za = np.abs(pl[:, 2])
        beyond_z = np.maximum(za - half, 0.0)
        rim = np.zeros(pl.shape[0])  # how far inside a hole's rim the point's projection is
        pieces = []
        geo = self._hole_geometry()
        walls = []
        for hd, s, r, floor in geo:
            a = pl[:, 0] * hd[0] + pl[:, 1] * hd[1]
            q = np.linalg.norm(pl - a[:, None] * hd - np.array([0.0, 0.0, s]), axis=1)
            rim = np.maximum(rim, np.where(a > 0, r - q, 0.0))
            # hole wall: |q - r| over a in [floor, R]; floor disc: |a - floor| within q <= r
            walls.append(np.hypot(q - r, np.maximum(np.maximum(floor - a, a - R), 0.0)))
            if self.bore == 0 or floor > self.bore:  # else the floor lies in the bore
                walls.append(np.hypot(a - floor, np.maximum(q - r, 0.0)))
        pieces.append(np.hypot(rad - R, np.maximum(beyond_z, rim)))
        pieces.append(np.hypot(za - half, np.maximum(np.maximum(rad - R, self.bore - rad), 0.0)))
        if self.bore > 0:
            pieces.append(np.hypot(rad - self.bore, np.maximum(beyond_z, rim)))
        pieces.extend(walls)
        return np.min(np.stack(pieces, axis=1), axis=1)

    def _albedo(self, p: np.ndarray, gx: np.ndarray, gy: np.ndarray, width: float
                ) -> np.ndarray:
        return np.full(p.shape[0], self.albedo)


Primitive = Union[Table, Box, Cylinder]


@dataclass(frozen=True)
class Scene:
    """Primitives in the robot base frame and the room light of the laser-off frame.

    ``light`` is the direction towards the (distant) room light, ``ambient_fraction`` the
    part of the room light that reaches every surface regardless of its orientation.
    """

    primitives: tuple[Primitive, ...]
    light: tuple[float, float, float] = (0.3, 0.2, 1.0)
    ambient_fraction: float = 0.4

    def __post_init__(self) -> None:
        prims = tuple(self.primitives)
        if not prims:
            raise ValueError("a scene needs at least one primitive")
        for i, p in enumerate(prims):
            if not isinstance(p, (Table, Box, Cylinder)):
                raise ValueError(f"scene primitive {i} is a {type(p).__name__}, not a Table, "
                                 "Box or Cylinder")
        object.__setattr__(self, "primitives", prims)
        object.__setattr__(self, "light", tuple(_unit(self.light, "light").tolist()))
        if not 0 <= self.ambient_fraction <= 1:
            raise ValueError(f"ambient_fraction must lie in [0, 1], got {self.ambient_fraction}")

    def intersect(self, origins: Any, directions: Any, tmin: float = 1e-9
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Nearest surface along rays ``origins + t directions``, t > tmin.

        Returns (t (n,), inf where nothing is hit; unit normals (n, 3) facing the ray's
        origin; index (n,) of the primitive hit, -1 for none). Directions need not be unit;
        t is in units of their length. Rays starting inside a solid are not supported.
        """
        d = np.asarray(directions, float).reshape(-1, 3)
        o = np.asarray(origins, float)
        o = o.reshape(-1, 3) if o.ndim > 1 else o
        t = np.full(d.shape[0], np.inf)
        nrm = np.zeros_like(d)
        which = np.full(d.shape[0], -1)
        for i, prim in enumerate(self.primitives):
            ti, ni = prim._hit(o, d, tmin)
            closer = ti < t
            t = np.where(closer, ti, t)
            nrm = np.where(closer[:, None], ni, nrm)
            which = np.where(closer, i, which)
        return t, nrm, which

    def distance(self, points: Any) -> np.ndarray:
        """Distance (mm) of base-frame points to the nearest surface of the scene."""
        return self.distances(points).min(axis=1)

    def distances(self, points: Any) -> np.ndarray:
        """(n, primitives) distance of each point to each primitive's surface (mm)."""
        p = np.asarray(points, float).reshape(-1, 3)
        return np.stack([prim._distance(p) for prim in self.primitives], axis=1)

    def nearest(self, points: Any) -> np.ndarray:
        """Index of the primitive whose surface is nearest to each point."""
        return np.argmin(self.distances(points), axis=1)


