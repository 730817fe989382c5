"""Rendered scenes of objects on a table, and the paper's measurement scenarios (section 5).

A :class:`Scene` is a list of primitives in the robot base frame (mm): the table plane
(:class:`Table`, optionally textured), axis-aligned boxes (:class:`Box`) and cylinders with
the axis along x, y or z, solid or hollow, with circular holes through the wall
(:class:`Cylinder`, :class:`Hole`). :func:`render_scene` ray-traces it through the sensor
model of MODEL.md exactly as :mod:`hmlvs.render` does for the checkerboard: every
supersample's (distorted) pixel gives an undistorted camera ray
(:func:`hmlvs.model.rays_in_camera`), the camera pose is ``base_from_hand @
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

Supersampling, blur, noise and rounding are :mod:`hmlvs.render`'s (``RenderOptions``:
``supersample``, ``stripe_sigma``, ``blur_sigma``, ``laser``, ``ambient``, ``noise``; the
board albedos, glare and spurious peaks do not apply here).

The scenarios, :func:`cylinder_scan` (Fig. 13) and :func:`gauge_block` (Table 3), render
whole measurements, write them as image manifests (``hmlvs-images``), measure them with a
calibration obtained honestly from a simulated noisy checkerboard session
(:func:`simulated_calibration`), and compare with the truth.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal, Sequence, Union

import numpy as np

from ._arrays import as_params
from .model import hand_from_camera
from .render import (
    RenderOptions,
    _finish_frames,
    _laser_distance,
    _sample_ray_jacobian,
    _sample_rays,
    _soft_sign,
)

Axis = Literal["x", "y", "z"]

_TINY = 1e-12


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
    ok = (disc >= 0) & (a > _TINY)
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
    ``albedo2`` (edges smoothed over the pixel footprint, as :mod:`hmlvs.render` does for the
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
            dist = sq * np.minimum(f, 1.0 - f) / np.maximum(g, _TINY)
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
            di = np.where(np.abs(di) < _TINY, _TINY, di)
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
        par = a <= _TINY  # along the axis: inside the outer radius or not at all
        r1 = np.where(par, np.where(c <= 0, -big, np.nan), r1)
        r2 = np.where(par, np.where(c <= 0, big, np.nan), r2)
        half = self.length / 2
        dz = np.where(np.abs(dl[:, 2]) < _TINY, _TINY, dl[:, 2])
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
        dz = np.where(np.abs(dl[:, 2]) < _TINY, _TINY, dl[:, 2])
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
        for k, (hd, s, r, floor) in enumerate(self._hole_geometry()):
            sel = kind == 3 + 2 * k
            if sel.any():
                a_ = p[sel, 0] * hd[0] + p[sel, 1] * hd[1]
                q = p[sel] - a_[:, None] * hd - np.array([0.0, 0.0, s])
                nl[sel] = -q / np.maximum(np.linalg.norm(q, axis=1, keepdims=True), _TINY)
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


# ------------------------------------------------------------------------------------------
# Rendering


@dataclass(frozen=True)
class RenderedScene:
    """One rendered pose of a scene.

    ``surface[v, u]`` is the index of the primitive seen at the pixel's centre (-1: none);
    ``lit[v, u]`` whether the laser reaches the point seen there (not in laser shadow).
    """

    on: np.ndarray
    off: np.ndarray
    surface: np.ndarray
    lit: np.ndarray


def laser_origin(params: Any, pose: np.ndarray) -> np.ndarray:
    """The laser projector's position in the base frame: the point ``(0, H, 0)`` of the
    camera frame, on the laser plane's baseline."""
    q = as_params(params)
    bfc = np.asarray(pose, float) @ hand_from_camera(q)
    return bfc[:3, :3] @ np.array([0.0, q[6], 0.0]) + bfc[:3, 3]


def render_scene(params: Any, pose: np.ndarray, scene: Scene,
                 image_size: tuple[int, int] = (640, 480),
                 options: RenderOptions | None = None,
                 rng: np.random.Generator | None = None,
                 laser_shadows: bool = True) -> RenderedScene:
    """Render the laser-on and laser-off images of a scene at one base_from_hand pose.

    Parameters
    ----------
    params : the true sensor parameters (:class:`hmlvs.Parameters` or 14-vector)
    pose : (4, 4) base_from_hand transform
    scene : the :class:`Scene`
    image_size : (width, height) px
    options : :class:`hmlvs.simulate.RenderOptions` (supersample, stripe_sigma, blur_sigma,
        laser, ambient, noise are used)
    rng : random generator for the sensor noise (default: seeded with 0)
    laser_shadows : test every stripe point's segment to the projector for occlusion
    """
    q = as_params(params)
    o = RenderOptions() if options is None else options
    rng = np.random.default_rng(0) if rng is None else rng
    w, h = int(image_size[0]), int(image_size[1])
    if w < 8 or h < 8:
        raise ValueError(f"image_size must be at least 8 x 8 pixels, got {image_size}")
    s = o.supersample
    rays = _sample_rays(q, (w, h), s)
    ray_du, ray_dv = _sample_ray_jacobian(q, (w, h), s)
    bfc = np.asarray(pose, float) @ hand_from_camera(q)
    rot, centre = bfc[:3, :3], bfc[:3, 3]
    emitter = laser_origin(q, pose)
    light = np.asarray(scene.light)
    th = q[7]
    lvec = np.array([0.0, np.cos(th), np.sin(th)])  # gradient of the laser-plane distance
    width = 1.5 / s
    cut = 5.0 * o.stripe_sigma  # px: the profile is below 4e-6 beyond
    # only samples this close to the laser plane (mm) get the pixel distance; a surface seen
    # at more than near_mm / cut mm per px (grazing) loses the profile's far tails
    near_mm = 12.0
    ambient = np.empty((h, w))
    laser = np.empty((h, w))
    surface = np.empty((h, w), np.int64)
    lit_map = np.zeros((h, w), bool)
    chunk = 8  # pixel rows per block: small blocks keep the temporaries in the cache
    for r0 in range(0, h, chunk):
        r1 = min(h, r0 + chunk)
        shape = ((r1 - r0) * s, w * s)
        ray = rays[r0 * s:r1 * s].reshape(-1, 3)
        dirs = ray @ rot.T
        t, nrm, which = scene.intersect(centre, dirs)
        hit = np.isfinite(t)
        tt = np.where(hit, t, 0.0)
        pb = centre + dirs * tt[:, None]  # base frame

        def footprint(sel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            """Derivative per pixel (u, v) of the hit point on its tangent plane (camera
            frame) for the samples ``sel``."""
            rr = ray[sel]
            du = ray_du[r0 * s:r1 * s].reshape(-1, 3)[sel]
            dv = ray_dv[r0 * s:r1 * s].reshape(-1, 3)[sel]
            nc = nrm[sel] @ rot
            ndr = np.einsum("ij,ij->i", nc, rr)
            ndr = np.where(np.abs(ndr) > _TINY, ndr, _TINY)
            ts = tt[sel, None]
            return (ts * (du - rr * (np.einsum("ij,ij->i", nc, du) / ndr)[:, None]),
                    ts * (dv - rr * (np.einsum("ij,ij->i", nc, dv) / ndr)[:, None]))

        alb = np.zeros(t.shape[0])
        for i, prim in enumerate(scene.primitives):
            sel = np.nonzero(which == i)[0]
            if not sel.size:
                continue
            if isinstance(prim, Table) and prim.texture is not None:
                gu, gv = footprint(sel)
                gu, gv = gu @ rot.T, gv @ rot.T
                alb[sel] = prim._albedo(pb[sel], np.hypot(gu[:, 0], gv[:, 0]),
                                        np.hypot(gu[:, 1], gv[:, 1]), width)
            else:
                alb[sel] = prim._albedo(pb[sel], None, None, width)
        shade = scene.ambient_fraction + (1 - scene.ambient_fraction) * np.maximum(
            nrm @ light, 0.0)
        amb = np.where(hit, o.ambient * alb * shade, 0.0)
        lz = np.zeros(t.shape[0])
        lit = np.zeros(t.shape[0], bool)
        dist = _laser_distance(q, ray * tt[:, None])
        near = np.nonzero(hit & (np.abs(dist) < near_mm))[0]
        if near.size:
            gu, gv = footprint(near)
            with np.errstate(divide="ignore", invalid="ignore"):
                dpx = dist[near] / np.hypot(gu @ lvec, gv @ lvec)
            bi = near[np.abs(dpx) < cut]
            dpx = dpx[np.abs(dpx) < cut]
            to_laser = emitter - pb[bi]
            cos_inc = np.einsum("ij,ij->i", nrm[bi], to_laser) / np.linalg.norm(to_laser,
                                                                                 axis=1)
            ok = cos_inc > 0
            if laser_shadows and ok.any():
                oi = bi[ok]
                ts, _, _ = scene.intersect(pb[oi] + 1e-4 * nrm[oi], emitter - pb[oi], 1e-9)
                ok[ok] = ~(ts < 1.0 - 1e-6)
            lit[bi] = ok
            lz[bi] = np.where(ok, o.laser * alb[bi] * cos_inc *
                              np.exp(-0.5 * (dpx / o.stripe_sigma) ** 2), 0.0)
        rows = r1 - r0
        ambient[r0:r1] = amb.reshape(shape).reshape(rows, s, w, s).mean(axis=(1, 3))
        laser[r0:r1] = lz.reshape(shape).reshape(rows, s, w, s).mean(axis=(1, 3))
        surface[r0:r1] = which.reshape(shape)[s // 2::s, s // 2::s]
        lit_map[r0:r1] = lit.reshape(shape)[s // 2::s, s // 2::s]
    on, off = _finish_frames(ambient, laser, o, rng)
    return RenderedScene(on, off, surface, lit_map)


# ------------------------------------------------------------------------------------------
# What the scenarios share: the simulated robot readout and an honest calibration

#: The paper's identified sensor (Table 2, best-fit column), used as the simulated truth:
#: a real sensor, off the nominal values the calibration starts from.
PAPER_SENSOR: dict[str, float] = {
    "f": 7.70, "Su": 0.0074, "Sv": 0.0075, "Cu": 323.8, "Cv": 238.3, "k": 4.8e-4,
    "H": 137.3, "theta": 0.47, "omega": -1.8e-3, "phi": -0.05, "varphi": -6.8e-3,
    "tx": 63.2, "ty": -2.3, "tz": -46.2,
}

#: The robot's home position used by the scenarios (rad): upper arm vertical, forearm
#: horizontal, flange pointing down; the SCORBOT ER-VII's flange is then at (400, 0, 407.5) mm.
HOME = np.radians([0.0, -90.0, 90.0, 0.0, 0.0])


@dataclass(frozen=True)
class JointReadout:
    """How the controller reports the joint angles it actually reached.

    A reading is the true angle plus Gaussian noise of ``noise_deg`` (backlash, compliance,
    servo error), quantised to the encoder's ``resolution_deg``. The defaults are
    assumptions for a SCORBOT-class arm (about +-0.2 mm repeatability), not datasheet values.
    """

    resolution_deg: float = 0.01
    noise_deg: float = 0.01

    def __post_init__(self) -> None:
        for name in ("resolution_deg", "noise_deg"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {v}")

    def read(self, joints: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Readings (rad) of the true joint angles ``joints`` (rad)."""
        j = np.asarray(joints, float)
        if self.noise_deg > 0:
            j = j + rng.normal(0.0, np.radians(self.noise_deg), j.shape)
        if self.resolution_deg > 0:
            res = np.radians(self.resolution_deg)
            j = np.round(j / res) * res
        return j

    @property
    def variance(self) -> float:
        """Variance (rad^2) of a reading's error: noise plus uniform quantisation."""
        return np.radians(self.noise_deg) ** 2 + np.radians(self.resolution_deg) ** 2 / 12


def default_truth() -> Any:
    from .params import Parameters
    return Parameters.from_dict(PAPER_SENSOR)


def simulated_calibration(truth: Any = None, *, num_poses: int = 40, pixel_noise: float = 0.1,
                          readout: JointReadout | None = None, robot: Any = None,
                          seed: int = 0) -> Any:
    """Calibrate the way a user would: a simulated checkerboard session of the true sensor
    (:func:`hmlvs.simulate.session`, the paper's set-up) with ``pixel_noise`` px on the stripe
    pixels and the poses computed from noisy joint readings (``readout``), half of the poses
    held out, identified by :func:`hmlvs.calibrate` (PSO + LM from the nominal values, Su
    fixed). Returns the :class:`hmlvs.CalibrationResult`."""
    import warnings

    from ._identifiability import HmlvsDataWarning
    from .dataset import Dataset
    from .identify import calibrate
    from .robot import Robot
    from .simulate import session

    truth = default_truth() if truth is None else truth
    robot = Robot.scorbot_er7() if robot is None else robot
    readout = JointReadout() if readout is None else readout
    rng = np.random.default_rng([seed, 31])
    s = session(truth, robot=robot, num_poses=num_poses, pixel_noise=pixel_noise, seed=seed)
    ds = s.dataset
    readings = readout.read(s.joints, rng)
    noisy = Dataset(ds.pixels, robot.poses(readings)[ds.pose_index], ds.points, ids=ds.ids,
                    joints=readings[ds.pose_index], pose_index=ds.pose_index,
                    meta={**ds.meta, "joint_readout": vars(readout)})
    fit, test = noisy.split(0.5, seed=seed, by_pose=True)
    with warnings.catch_warnings():  # kept in the result's ``warnings``
        warnings.simplefilter("ignore", HmlvsDataWarning)
        return calibrate(fit, test=test, seed=seed)


def _params_and_result(calibration: Any, truth: Any, readout: JointReadout, robot: Any,
                       seed: int) -> tuple[Any, Any]:
    """(parameters used to measure, the CalibrationResult or the given calibration)."""
    from .measure import _params_of
    if calibration is None:
        calibration = simulated_calibration(truth, readout=readout, robot=robot, seed=seed)
    return _params_of(calibration), calibration


class _Progress:
    """Calls ``progress(done, total)`` if given; a callable returning False stops the work."""

    def __init__(self, progress: Any, total: int) -> None:
        self.progress, self.total, self.done = progress, total, 0

    def step(self) -> None:
        self.done += 1
        if self.progress is not None and self.progress(self.done, self.total) is False:
            raise KeyboardInterrupt


def _rendered_records(frames: list[RenderedScene], readings: np.ndarray, ids: list[str]
                      ) -> list[dict[str, Any]]:
    return [{"id": i, "on": f.on, "off": f.off, "joints": r.tolist()}
            for i, f, r in zip(ids, frames, readings)]


def _write_scan(out_dir: Any, ids: list[str], frames: list[RenderedScene],
                readings: np.ndarray, image_size: tuple[int, int], robot: Any,
                **extra: Any) -> Any:
    from .render import write_image_manifest
    return write_image_manifest(out_dir, ids, [f.on for f in frames], [f.off for f in frames],
                                readings, image_size, robot.name, **extra)


def _scene_to_dict(scene: Scene) -> dict[str, Any]:
    from dataclasses import asdict
    return {"primitives": [{"type": type(p).__name__, **asdict(p)} for p in scene.primitives],
            "light": list(scene.light), "ambient_fraction": scene.ambient_fraction}


def _surface_normals(params: Any, scene: Scene, pixels: np.ndarray, poses: np.ndarray
                     ) -> np.ndarray:
    """Unit normals of the true surface seen at ``pixels`` from the true ``poses``."""
    from .model import rays_in_camera
    hfc = hand_from_camera(params)
    bfc = poses @ hfc
    rays = rays_in_camera(params, pixels)
    dirs = np.einsum("nij,nj->ni", bfc[:, :3, :3], rays)
    _, nrm, _ = scene.intersect(bfc[:, :3, 3], dirs)
    return nrm


def _point_jacobians(params: Any, pixels: np.ndarray, readings: np.ndarray, robot: Any
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Measured points and their derivatives: (points (n, 3), dP/d(u, v) (n, 3, 2),
    dP/d(joint readings) (n, 3, dof)), by central differences through the model."""
    from .model import points_in_base
    poses = robot.poses(readings)
    pts, _ = points_in_base(params, pixels, poses, on_invalid="mask")
    jpx = np.empty(pts.shape + (2,))
    for i in range(2):
        step = np.zeros(2)
        step[i] = 0.5
        a, _ = points_in_base(params, pixels + step, poses, on_invalid="mask")
        b, _ = points_in_base(params, pixels - step, poses, on_invalid="mask")
        jpx[:, :, i] = a - b
    dof = readings.shape[1]
    jq = np.empty(pts.shape + (dof,))
    h = 1e-6
    for i in range(dof):
        step = np.zeros(dof)
        step[i] = h
        a, _ = points_in_base(params, pixels, robot.poses(readings + step), on_invalid="mask")
        b, _ = points_in_base(params, pixels, robot.poses(readings - step), on_invalid="mask")
        jq[:, :, i] = (a - b) / (2 * h)
    return pts, jpx, jq


# ------------------------------------------------------------------------------------------
# Fig. 13: a scan of a cylinder with holes


def cylinder_scene(radius: float = 50.0, length: float = 200.0,
                   centre: tuple[float, float] = (500.0, 0.0), bore: float = 42.0,
                   holes: Sequence[Hole] | None = None, table: Table | None = None) -> Scene:
    """A tube lying on the table along base y (axis at ``centre`` = (x, y), height
    ``radius``), 8 mm wall by default, with three holes through the wall of 20, 15 and 25 mm
    diameter: on top, 35 deg to one side and 30 deg to the other."""
    if holes is None:
        holes = (Hole(-55.0, 0.0, 10.0), Hole(0.0, np.radians(35.0), 7.5),
                 Hole(55.0, np.radians(-30.0), 12.5))
    cyl = Cylinder((float(centre[0]), float(centre[1]), float(radius)), radius, length, "y",
                   bore=bore, holes=tuple(holes))
    return Scene((Table() if table is None else table, cyl))


@dataclass(frozen=True)
class HoleCheck:
    """Whether a hole shows as a gap in the scan.

    ``surface_inside``: measured points on the outer surface (within ``tolerance`` mm of
    radius R) whose position lies inside the hole's rim shrunk by ``margin`` mm; 0 for a gap.
    ``below_inside``: points inside the rim but below the surface (the hole's wall, what is
    seen through it). ``ring``: points on the outer surface in a 4 mm ring around the rim
    (beyond ``margin``), showing the scan did cross the hole's surroundings.
    """

    index: int
    hole: Hole
    surface_inside: int
    below_inside: int
    ring: int

    @property
    def is_gap(self) -> bool:
        return self.ring > 0 and self.surface_inside == 0


@dataclass(frozen=True)
class CylinderScan:
    """The result of :func:`cylinder_scan` (all lengths in mm).

    ``rms_mm`` is the RMS distance of every measured point to the true scene surface,
    ``expected_rms_mm`` what the simulated noise predicts for it: per point, the normal
    component of the calibration's own error there (exact, the truth is known), of the
    stripe centre's noise (the extractor's 1-sigma, through the model) and of the joint
    readout noise (through the kinematics); ``expected_parts`` gives each part's RMS.
    """

    cloud: Any
    scene: Scene
    truth: Any
    params: Any
    calibration: Any
    joints: np.ndarray
    readings: np.ndarray
    distance: np.ndarray
    surface: np.ndarray
    rms_mm: float
    rms_cylinder_mm: float
    rms_table_mm: float
    on_cylinder: int
    on_table: int
    outliers: int
    expected_rms_mm: float
    expected_parts: dict[str, float]
    holes: tuple[HoleCheck, ...]
    rejected: dict[str, str]
    files: dict[str, Any] = field(default_factory=dict)
    seconds: float = 0.0

    @property
    def num_points(self) -> int:
        return int(self.cloud.num_valid)

    def to_dict(self) -> dict[str, Any]:
        return {
            "scenario": "cylinder", "images": int(self.joints.shape[0]),
            "points": self.num_points, "rms_mm": self.rms_mm,
            "rms_cylinder_mm": self.rms_cylinder_mm, "rms_table_mm": self.rms_table_mm,
            "expected_rms_mm": self.expected_rms_mm, "expected_parts_mm": self.expected_parts,
            "on_cylinder": self.on_cylinder, "on_table": self.on_table,
            "fraction_cylinder": self.on_cylinder / max(self.num_points, 1),
            "fraction_table": self.on_table / max(self.num_points, 1),
            "outliers_over_1mm": self.outliers,
            "holes": [{"index": h.index, "diameter_mm": 2 * h.hole.radius,
                       "surface_points_inside": h.surface_inside,
                       "points_below_surface_inside": h.below_inside,
                       "surface_points_around": h.ring, "gap": h.is_gap} for h in self.holes],
            "calibration_test_rms_mm": getattr(self.calibration, "test_rms", None),
            "rejected": self.rejected, "files": {k: str(v) for k, v in self.files.items()},
            "seconds": self.seconds,
        }

    def summary(self) -> str:
        n = max(self.num_points, 1)
        p = self.expected_parts
        lines = [
            f"cylinder scan: {self.joints.shape[0]} image pairs, {self.num_points} points "
            f"({100 * self.on_cylinder / n:.1f}% on the cylinder, {100 * self.on_table / n:.1f}%"
            f" on the table)",
            f"RMS distance to the true surface: {self.rms_mm:.3f} mm (cylinder "
            f"{self.rms_cylinder_mm:.3f}, table {self.rms_table_mm:.3f}); "
            f"{self.outliers} points farther than 1 mm",
            f"expected from the simulated noise: {self.expected_rms_mm:.3f} mm (calibration "
            f"{p['calibration']:.3f}, stripe pixels {p['pixels']:.3f}, joint readout "
            f"{p['joints']:.3f})",
        ]
        for h in self.holes:
            lines.append(
                f"hole {h.index} ({2 * h.hole.radius:g} mm): {h.surface_inside} surface points "
                f"inside the rim, {h.below_inside} below it (wall / seen through), {h.ring} "
                f"around it: {'a gap' if h.is_gap else 'NOT a gap' if h.ring else 'not scanned'}")
        if self.rejected:
            lines.append("rejected image pairs: " + "; ".join(f"{k}: {v}" for k, v in
                                                                self.rejected.items()))
        return "\n".join(lines)


def _hole_checks(cyl: Cylinder, points: np.ndarray, margin: float = 1.0,
                 tolerance: float = 1.0) -> tuple[HoleCheck, ...]:
    pl = cyl.local(points)
    rad = np.hypot(pl[:, 0], pl[:, 1])
    surface = np.abs(rad - cyl.radius) < tolerance
    out = []
    for k, (hd, s, r, _) in enumerate(cyl._hole_geometry()):
        a = pl[:, 0] * hd[0] + pl[:, 1] * hd[1]
        q = np.linalg.norm(pl - a[:, None] * hd - np.array([0.0, 0.0, s]), axis=1)
        inside = q < r - margin
        front = a > 0
        out.append(HoleCheck(
            k, cyl.holes[k], int(np.sum(inside & surface & front)),
            int(np.sum(inside & (rad < cyl.radius - tolerance))),
            int(np.sum(front & surface & (q > r + margin) & (q < r + margin + 4.0)))))
    return tuple(out)


def cylinder_scan(calibration: Any = None, truth: Any = None, *, seed: int = 0,
                  out_dir: Any = None, scene: Scene | None = None, step: float = 3.0,
                  standoff: float | None = None, image_size: tuple[int, int] = (640, 480),
                  options: RenderOptions | None = None, readout: JointReadout | None = None,
                  robot: Any = None, span: tuple[float, float] | None = None,
                  progress: Any = None, plot: bool = True) -> CylinderScan:
    """Fig. 13: scan a cylinder with holes lying on the table, measure it from the images.

    The sensor moves along the cylinder's axis, looking straight down from ``standoff`` mm
    above its top (default ``H / tan(theta)``, where the stripe crosses the image centre),
    the stripe across the axis, one laser on/off pair every ``step`` mm. The pairs are
    rendered with the ``truth`` sensor at the true joint angles; the joint readings stored
    with them carry the ``readout`` noise. The scan is measured with
    :func:`hmlvs.measure.measure_images` using ``calibration`` (default: an honest one from
    :func:`simulated_calibration`) and compared with the scene.

    Parameters
    ----------
    calibration : Calibration, CalibrationResult or Parameters to measure with; None
        calibrates a simulated noisy checkerboard session of ``truth``
    truth : the true sensor (default :data:`PAPER_SENSOR`, the paper's identified one)
    seed : seeds the calibration session, the readout noise and the image noise
    out_dir : folder for the images and ``manifest.json``, ``cloud.ply`` and ``cloud.png``
        (Fig. 13); None keeps everything in memory
    scene : a :class:`Scene` with one horizontal :class:`Cylinder` (default
        :func:`cylinder_scene`)
    step : scan step along the axis (mm)
    span : scanned interval along the axis from the cylinder's centre (mm); default the
        whole length plus 5 mm each side
    options : :class:`hmlvs.simulate.RenderOptions` (default: sensor noise 1 grey level)
    progress : callable ``(done, total)`` per rendered pair; returning False stops
    plot : write ``cloud.png`` when ``out_dir`` is given
    """
    import time
    from pathlib import Path

    from .image import stripes_from_images
    from .measure import measure_images
    from .model import points_in_base
    from .params import Parameters
    from .robot import Robot
    from .simulate import _ik_look_at

    start = time.perf_counter()
    truth = default_truth() if truth is None else truth
    q_true = as_params(truth)
    robot = Robot.scorbot_er7() if robot is None else robot
    readout = JointReadout() if readout is None else readout
    options = RenderOptions(noise=1.0) if options is None else options
    scene = cylinder_scene() if scene is None else scene
    cyls = [p for p in scene.primitives if isinstance(p, Cylinder)]
    if len(cyls) != 1:
        raise ValueError(f"cylinder_scan needs a scene with exactly one Cylinder, got "
                         f"{len(cyls)}")
    cyl = cyls[0]
    if cyl.axis == "z":
        raise ValueError("cylinder_scan scans a cylinder lying on the table (axis 'x' or "
                         "'y'); this one stands upright (axis 'z')")
    if not (np.isfinite(step) and step > 0):
        raise ValueError(f"step must be a positive number of mm, got {step}")
    params, cal = _params_and_result(calibration, truth, readout, robot, seed)
    q_plan = as_params(params)
    hfc = hand_from_camera(q_plan)
    if standoff is None:
        standoff = q_plan[6] / np.tan(q_plan[7])
    axis = cyl.frame[:, 2]
    cam_x = np.cross(axis, [0.0, 0.0, 1.0])
    lo, hi = span if span is not None else (-cyl.length / 2 - 5.0, cyl.length / 2 + 5.0)
    if not hi > lo:
        raise ValueError(f"span must be (start, end) with end > start, got {span}")
    s_values = np.arange(lo, hi + 1e-9, step)
    top = np.asarray(cyl.centre) + np.array([0.0, 0.0, cyl.radius])
    joints = []
    prev = HOME
    for s in s_values:
        pos = top + s * axis + np.array([0.0, 0.0, standoff])
        j = _ik_look_at(robot, hfc, pos, np.array([0.0, 0.0, -1.0]), [prev, HOME], cam_x=cam_x)
        if j is None:
            raise ValueError(f"the scan position {np.round(pos, 1).tolist()} mm (camera "
                             f"{standoff:.0f} mm above the cylinder) is out of the robot's "
                             "reach; move the cylinder or change standoff")
        joints.append(j)
        prev = j
    joints = np.array(joints)
    rng = np.random.default_rng([seed, 11])
    readings = readout.read(joints, rng)
    poses = robot.poses(joints)
    ids = [f"p{i:03d}" for i in range(len(joints))]
    bar = _Progress(progress, len(joints))
    frames = []
    for pose in poses:
        frames.append(render_scene(q_true, pose, scene, image_size, options, rng))
        bar.step()
    files: dict[str, Any] = {}
    if out_dir is not None:
        source = _write_scan(out_dir, ids, frames, readings, image_size, robot,
                             scene=_scene_to_dict(scene), scenario="cylinder")
        files["manifest"] = source
    else:
        source = _rendered_records(frames, readings, ids)
    cloud, info = measure_images(params, source, robot=robot)
    _, stripes, _, _ = stripes_from_images(source, robot=robot)
    sigma_v = np.concatenate([s_.sigma[s_.found] for s_ in stripes])
    if sigma_v.shape[0] != len(cloud):  # pragma: no cover - the same extraction twice
        raise RuntimeError("stripe centres and measured points do not line up")
    valid = cloud.valid
    pts = cloud.points[valid]
    px = cloud.pixels[valid]
    pidx = cloud.pose_index[valid]
    sigma_v = sigma_v[valid]
    dist_all = scene.distances(pts)
    dist = dist_all.min(axis=1)
    nearest = dist_all.argmin(axis=1)
    icyl = scene.primitives.index(cyl)
    itab = next((i for i, p in enumerate(scene.primitives) if isinstance(p, Table)), -1)
    on_c, on_t = nearest == icyl, nearest == itab

    def rms(x: np.ndarray) -> float:
        return float(np.sqrt(np.mean(np.square(x)))) if x.size else float("nan")

    # what the noise predicts, per point, along the true surface normal
    nrm = _surface_normals(q_true, scene, px, poses[pidx])
    _, jpx, jq = _point_jacobians(params, px, readings[pidx], robot)
    p_cal, _ = points_in_base(params, px, robot.poses(readings[pidx]), on_invalid="mask")
    p_true, _ = points_in_base(q_true, px, robot.poses(readings[pidx]), on_invalid="mask")
    e_cal = np.einsum("ni,ni->n", nrm, p_cal - p_true)
    # the stripe centre's noise is along v (one centre per column)
    e_px = sigma_v * np.abs(np.einsum("ni,ni->n", nrm, jpx[:, :, 1]))
    e_q = np.sqrt(readout.variance * np.sum(np.einsum("ni,nij->nj", nrm, jq) ** 2, axis=1))
    parts = {"calibration": rms(e_cal), "pixels": rms(e_px), "joints": rms(e_q)}
    expected = float(np.sqrt(sum(v ** 2 for v in parts.values())))
    if out_dir is not None:
        files["cloud"] = cloud.save(Path(out_dir) / "cloud.ply")
        if plot:
            files["plot"] = plot_cloud(pts, Path(out_dir) / "cloud.png",
                                       title=f"cylinder scan: {len(pts)} points, RMS to the "
                                             f"surface {rms(dist):.3f} mm")
    return CylinderScan(
        cloud=cloud, scene=scene, truth=Parameters.from_array(q_true),
        params=Parameters.from_array(q_plan), calibration=cal, joints=joints,
        readings=readings, distance=dist, surface=nearest, rms_mm=rms(dist),
        rms_cylinder_mm=rms(dist[on_c]), rms_table_mm=rms(dist[on_t]),
        on_cylinder=int(on_c.sum()), on_table=int(on_t.sum()), outliers=int(np.sum(dist > 1.0)),
        expected_rms_mm=expected, expected_parts=parts, holes=_hole_checks(cyl, pts),
        rejected=dict(info["rejected"]), files=files, seconds=time.perf_counter() - start)


def plot_cloud(points: np.ndarray, path: Any, title: str = "", elev: float = 40.0,
               azim: float = -115.0) -> Any:
    """A 3D scatter of points (mm) coloured by height, like the paper's Fig. 13; PNG."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from pathlib import Path

    from ._io import atomic_write

    pts = np.asarray(points, float)
    fig = plt.figure(figsize=(8, 6), dpi=110)
    ax = fig.add_subplot(projection="3d")
    sc = ax.scatter(pts[:, 0], pts[:, 1], pts[:, 2], c=pts[:, 2], s=0.3, cmap="jet",
                    linewidths=0)
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_zlabel("z (mm)")
    span = np.ptp(pts, axis=0)
    ax.set_box_aspect(np.maximum(span, 1e-3 + 0.05 * span.max()))
    ax.view_init(elev=elev, azim=azim)
    fig.colorbar(sc, ax=ax, shrink=0.6, label="height z (mm)")
    if title:
        ax.set_title(title, fontsize=9)
    path = Path(path)
    with atomic_write(path, "wb") as fh:
        fig.savefig(fh, format="png", bbox_inches="tight")
    plt.close(fig)
    return path


# ------------------------------------------------------------------------------------------
# Table 3: the gauge-block check

#: The paper's gauge block: 60 x 30 x 55 mm, left-bottom corner at (0, -500, 0) mm.
GAUGE_BLOCK = Box((0.0, -530.0, 0.0), (60.0, -500.0, 55.0))

#: Table 3 of the paper: corner name, true position, measured mean, mean error, std (mm).
PAPER_TABLE3: tuple[tuple[str, tuple[float, float, float], tuple[float, float, float], float,
                          float], ...] = (
    ("left-top", (60.0, -500.0, 55.0), (59.95, -499.56, 55.34), 0.58, 0.15),
    ("right-top", (60.0, -530.0, 55.0), (60.17, -530.01, 54.65), 0.39, 0.14),
    ("right-bottom", (0.0, -530.0, 55.0), (0.17, -529.48, 55.14), 0.61, 0.21),
    ("left-bottom", (0.0, -500.0, 55.0), (-0.51, -499.97, 55.05), 0.71, 0.18),
)


def top_corners(block: Box) -> dict[str, np.ndarray]:
    """The block's four top corners named as in the paper's Table 3 (x towards the robot's
    front is "top", -y is "right")."""
    (x0, y0, _), (x1, y1, z1) = block.lo, block.hi
    return {"left-top": np.array([x1, y1, z1]), "right-top": np.array([x1, y0, z1]),
            "right-bottom": np.array([x0, y0, z1]), "left-bottom": np.array([x0, y1, z1])}


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
       :func:`hmlvs.image.stripes_from_images` extracts them), split into segments where
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
    from .image import _normalized_threshold, difference_image, extract_stripe

    near = np.asarray(near, float)
    d = difference_image(on, off, normalize=True)
    stripe = extract_stripe(d, threshold=_normalized_threshold(on, off, d))
    px = stripe.pixels
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
    s2 = float(np.sum(res ** 2) / max(xs.size - 2, 1))
    sxx = float(np.sum((xs - xs.mean()) ** 2))

    def var_across(xe: float) -> float:
        return s2 * (1.0 / xs.size + (xe - xs.mean()) ** 2 / sxx)

    raw = difference_image(on, off).astype(float)
    h, w = raw.shape
    ks = np.arange(-12, 26)
    cols = np.rint(u_end + inward * ks).astype(int)
    energy = np.full(ks.size, np.nan)
    for i, c in enumerate(cols):
        if 0 <= c < w:
            vc = int(np.rint(a + b * (c - u_end)))
            energy[i] = raw[max(vc - band, 0):min(vc + band + 1, h), c].sum()
    plateau_k = (ks >= 6) & (ks <= min(25.0, float(x.max()) - 2)) & np.isfinite(energy)
    if plateau_k.sum() < 5:
        raise ValueError(f"the stripe end at u = {u_end:g} is too close to the image border")
    plateau = float(np.median(energy[plateau_k]))
    half = plateau / 2
    k_end = None
    for i in range(int(np.nonzero(ks == 6)[0][0]), 0, -1):
        lo_e, hi_e = energy[i - 1], energy[i]
        if np.isfinite(lo_e) and lo_e < half <= hi_e:
            k_end = ks[i - 1] + (half - lo_e) / (hi_e - lo_e)
            slope = hi_e - lo_e
            break
    if k_end is None:
        raise ValueError(f"the stripe near u = {u_end:g} does not end (its energy never drops "
                         "to half the plateau)")
    xe = inward * k_end
    energy_end = np.array([u_end + xe, a + b * xe])
    line_dir = np.array([1.0, b]) / np.hypot(1.0, b)
    if not edges:
        kk = ks[plateau_k]
        trend = np.polyval(np.polyfit(kk, energy[plateau_k], 1), kk)
        var_u = (float(np.std(energy[plateau_k] - trend, ddof=2)) / slope) ** 2
        cov = np.array([[var_u, b * var_u], [b * var_u, b * b * var_u + var_across(xe)]])
        return StripeEnd(energy_end, cov, (float(a), float(b), u_end), int(xs.size), "energy",
                         energy_end)
    hits, var_along = [], []
    p0 = np.array([u_end, a])
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
    pixel = np.mean(hits, axis=0)
    var_u = float(np.sum(var_along)) / len(var_along) ** 2
    xe = pixel[0] - u_end
    cov = np.array([[var_u, b * var_u], [b * var_u, b * b * var_u + var_across(xe)]])
    spread = float(np.linalg.norm(hits[0] - hits[-1]))
    return StripeEnd(pixel, cov, (float(a), float(b), u_end), int(xs.size), "edges",
                     energy_end, spread)


@dataclass(frozen=True)
class CornerResult:
    """One corner of the gauge block over its trials (mm).

    ``measured`` (n, 3) and ``errors`` (n, 3) per trial; ``e`` the mean and ``sigma`` the
    standard deviation (ddof 1) of the error lengths, as in Table 3. ``expected_e`` is what
    the simulated noise predicts for ``e``: the median and a 99% interval of the mean error
    length over the same number of trials, drawn from per-trial Gaussians centred on the
    calibration's own error at that trial and spread by the predicted pixel and joint
    readout noise (``expected_sigma`` the same for ``sigma``). ``parts`` gives the RMS of each
    part: calibration, pixel, joints. ``pixel_error`` (n, 2) is the located corner pixel
    minus the true one, ``pixel_sigma`` (n, 2) the predicted standard deviations;
    ``readout_rms_deg`` the RMS of the joint readings' actual errors (the model assumes
    ``readout_assumed_deg``). ``unexplained`` (n, 3) is what remains of each error after
    subtracting the two parts known exactly in a simulation, the calibration's error at
    the corner and the realised readout error through the kinematics' Jacobian: the
    pixel's share, plus whatever the pipeline gets wrong.
    """

    name: str
    true: np.ndarray
    measured: np.ndarray
    errors: np.ndarray
    e: float
    sigma: float
    expected_e: tuple[float, float, float]
    expected_sigma: tuple[float, float, float]
    parts: dict[str, float]
    pixel_error: np.ndarray
    pixel_sigma: np.ndarray
    joints: np.ndarray
    readings: np.ndarray
    readout_rms_deg: float = 0.0
    readout_assumed_deg: float = 0.0
    unexplained: np.ndarray | None = None
    paper_e: float | None = None
    paper_sigma: float | None = None

    @property
    def mean(self) -> np.ndarray:
        return self.measured.mean(axis=0)

    @property
    def verdict(self) -> str:
        """"within" the expected interval of e, "below" or "above" it."""
        lo, _, hi = self.expected_e
        return "below" if self.e < lo else "above" if self.e > hi else "within"

    @property
    def within_expectation(self) -> bool:
        return self.verdict == "within"


@dataclass(frozen=True)
class GaugeBlockCheck:
    """The result of :func:`gauge_block`: Table 3 simulated end to end.

    ``expected_mean_e`` is the median and 99% interval of the mean of e over the corners
    under the simulated noise (every trial of every corner drawn independently).
    ``within_expectation``: that mean lies in its interval and no corner's e exceeds the
    top of its own interval (a corner below its interval had luckily small errors; the
    per-corner verdicts say so).
    """

    corners: tuple[CornerResult, ...]
    block: Box
    truth: Any
    params: Any
    calibration: Any
    trials: int
    home: np.ndarray
    expected_mean_e: tuple[float, float, float]
    files: dict[str, Any] = field(default_factory=dict)
    seconds: float = 0.0

    @property
    def mean_e(self) -> float:
        return float(np.mean([c.e for c in self.corners]))

    @property
    def within_expectation(self) -> bool:
        lo, _, hi = self.expected_mean_e
        return lo <= self.mean_e <= hi and all(c.verdict != "above" for c in self.corners)

    def table(self) -> str:
        """Table 3's layout, the paper's e and sigma beside ours, and the expectation."""
        head = (f"{'corner':<13}{'x':>7}{'y':>8}{'z':>6} {'mean x':>8}{'mean y':>9}"
                f"{'mean z':>8} {'e':>6}{'sigma':>7} | {'paper e':>7}{'sigma':>6} | "
                f"{'expected e (99%)':>22}{'exp. sigma':>11}  verdict")
        lines = [head, "-" * len(head)]
        for c in self.corners:
            m = c.mean
            pe = f"{c.paper_e:7.2f}{c.paper_sigma:6.2f}" if c.paper_e is not None else \
                f"{'-':>7}{'-':>6}"
            lo, mid, hi = c.expected_e
            lines.append(
                f"{c.name:<13}{c.true[0]:7.0f}{c.true[1]:8.0f}{c.true[2]:6.0f} {m[0]:8.2f}"
                f"{m[1]:9.2f}{m[2]:8.2f} {c.e:6.2f}{c.sigma:7.2f} | {pe} | "
                f"{mid:6.2f} [{lo:5.2f}, {hi:5.2f}]  {c.expected_sigma[1]:9.2f}  {c.verdict}")
        lo, mid, hi = self.expected_mean_e
        lines.append(f"mean e over the corners: {self.mean_e:.3f} mm, expected {mid:.3f} "
                     f"[{lo:.3f}, {hi:.3f}]")
        lines.append(f"({self.trials} trials per corner; e = mean of |error|, sigma = its std; "
                     "expected: median [0.5%, 99.5%] of e under the simulated noise)")
        return "\n".join(lines)

    def summary(self) -> str:
        lines = [self.table()]
        for c in self.corners:
            p = c.parts
            lines.append(
                f"{c.name}: error parts (RMS) calibration {p['calibration']:.3f}, pixel "
                f"{p['pixel']:.3f}, joints {p['joints']:.3f} mm; corner pixel error RMS "
                f"{np.sqrt(np.mean(c.pixel_error ** 2, axis=0)).round(3).tolist()} px "
                f"(predicted {np.sqrt(np.mean(c.pixel_sigma ** 2, axis=0)).round(3).tolist()}); "
                f"joint readings erred by {c.readout_rms_deg:.4f} deg RMS (assumed "
                f"{c.readout_assumed_deg:.4f}); not explained by the calibration error and the "
                f"realised readout error: {np.sqrt(np.mean(np.sum(c.unexplained ** 2, 1))):.3f}"
                " mm RMS")
        off = [f"{c.name} ({c.verdict})" for c in self.corners if not c.within_expectation]
        verdict = ("the mean errors lie within the simulated noise's expectation"
                   if self.within_expectation else
                   "the mean errors are NOT what the simulated noise leads one to expect")
        lines.append(verdict + ("" if not off else "; outside their own 99% interval: "
                                + ", ".join(off)))
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        return {
            "scenario": "gauge-block", "trials": self.trials,
            "block": {"lo": list(self.block.lo), "hi": list(self.block.hi)},
            "home_rad": self.home.tolist(),
            "calibration_test_rms_mm": getattr(self.calibration, "test_rms", None),
            "within_expectation": self.within_expectation, "mean_e": self.mean_e,
            "expected_mean_e": {"low": self.expected_mean_e[0],
                                "median": self.expected_mean_e[1],
                                "high": self.expected_mean_e[2]},
            "corners": [{
                "corner": c.name, "true": c.true.tolist(), "mean": c.mean.tolist(),
                "e": c.e, "sigma": c.sigma, "paper_e": c.paper_e, "paper_sigma": c.paper_sigma,
                "expected_e": {"low": c.expected_e[0], "median": c.expected_e[1],
                               "high": c.expected_e[2]},
                "expected_sigma": {"low": c.expected_sigma[0], "median": c.expected_sigma[1],
                                   "high": c.expected_sigma[2]},
                "parts_rms_mm": c.parts, "verdict": c.verdict,
                "readout_rms_deg": c.readout_rms_deg,
                "unexplained_rms_mm": float(np.sqrt(np.mean(np.sum(c.unexplained ** 2, 1)))),
                "errors": c.errors.tolist()} for c in self.corners],
            "files": {k: str(v) for k, v in self.files.items()}, "seconds": self.seconds,
        }


def _place_on_corner(robot: Any, q_true: np.ndarray, hfc_plan: np.ndarray, scene: Scene,
                     corner: np.ndarray, inward: np.ndarray, standoff: float,
                     image_size: tuple[int, int], rng: np.random.Generator, home: np.ndarray,
                     approach_mm: float, tilt_deg: float, angle_deg: float,
                     hide: float = 25.0, attempts: int = 20) -> np.ndarray:
    """From ``home``, bring the camera over the corner with a randomly varied approach, then
    turn the wrist until the (true) laser plane passes exactly through the corner: the
    operator's "adjust until the stripe overlaps the corner". Returns the true joints.

    The stripe runs into the top face (along ``inward``); past the corner the laser sheet
    goes on down one of the two side faces at the corner (the one facing the projector).
    The camera is placed over the top face, ``hide`` mm inside both side faces' planes, so
    that neither side face is in view: the top face's stripe segment simply ends at the
    corner."""
    from .model import pixels_from_points
    from .simulate import _ik_look_at, _snap

    w, h = image_size
    up = np.array([0.0, 0.0, 1.0])
    reached = 0
    for _ in range(attempts):
        beta = np.radians(45.0 + rng.normal(0.0, angle_deg))
        stripe_dir = np.array([inward[0] * np.cos(beta), inward[1] * np.sin(beta), 0.0])
        faces = [np.array([-inward[0], 0.0, 0.0]), np.array([0.0, -inward[1], 0.0])]
        # a 5-joint arm tilts its tool only in its own vertical plane: tilt radially
        tilt = np.radians(rng.uniform(-tilt_deg, tilt_deg))
        radial = np.array([corner[0], corner[1], 0.0]) / max(np.hypot(*corner[:2]), 1e-9)
        view = -(np.cos(tilt) * up + np.sin(tilt) * radial)
        pos = corner - standoff * view - hide * (faces[0] + faces[1]) + rng.normal(
            0.0, approach_mm, 3)
        j = _ik_look_at(robot, hfc_plan, pos, view, [home], cam_x=stripe_dir)
        if j is None:
            continue
        reached += 1
        snapped = None
        for free in ([3], [0], [2]):
            snapped = _snap(robot, q_true, j, corner[None], free=free)
            if snapped is not None:
                break
        if snapped is None:
            continue
        pose = robot.poses(snapped)
        px, ok = pixels_from_points(q_true, corner[None], pose, plane_tolerance=1e-6,
                                    on_invalid="mask")
        if not ok[0] or not (60 <= px[0, 0] <= w - 61 and 40 <= px[0, 1] <= h - 41):
            continue
        bfc = pose[0] @ hand_from_camera(q_true)
        if max((bfc[:3, 3] - corner) @ n for n in faces) > -0.2 * hide:
            continue  # a side face would be in view
        t, _, _ = scene.intersect(bfc[:3, 3], (corner - bfc[:3, 3])[None])
        if not t[0] > 1 - 1e-5:  # something hides the corner from the camera
            continue
        return snapped
    if reached == 0:
        raise ValueError(f"the corner at {corner.tolist()} mm is out of the robot's reach with "
                         f"the camera {standoff:.0f} mm above it")
    raise ValueError(f"the laser stripe could not be brought onto the corner at "
                     f"{corner.tolist()} mm with the corner in view ({attempts} attempts)")


def gauge_block(calibration: Any = None, truth: Any = None, *, trials: int = 10, seed: int = 0,
                out_dir: Any = None, block: Box | None = None,
                corners: Sequence[str] | None = None, home: Any = None,
                image_size: tuple[int, int] = (640, 480), options: RenderOptions | None = None,
                readout: JointReadout | None = None, robot: Any = None,
                standoff: float | None = None, approach_mm: float = 5.0, tilt_deg: float = 3.0,
                angle_deg: float = 5.0, table: Table | None = None, progress: Any = None,
                draws: int = 4000) -> GaugeBlockCheck:
    """Table 3: measure the four top corners of a gauge block, ``trials`` times each.

    Each trial starts from the robot's ``home`` (default :data:`HOME`) and moves (inverse
    kinematics) the camera ``standoff`` mm above the top face (default ``H / tan(theta)``,
    the stripe's depth at the image centre), 25 mm inside both side faces at the corner so
    that neither is in view, looking down, with random approach differences: position
    N(0, ``approach_mm``) per axis, a tilt in the arm's plane up to +-``tilt_deg``, the
    stripe at 45 + N(0, ``angle_deg``) deg to the block's edges, running into the top face.
    Then the wrist turns until the true laser plane passes through the corner (the
    operator's "adjust until the stripe overlaps the corner", done exactly). The laser on/off pair is rendered with the ``truth`` sensor at the
    true joints; the joint readings carry the ``readout`` noise. The corner's pixel is the
    end of the top face's stripe segment (:func:`locate_stripe_end` with the two top edges,
    their directions from the nominal block projected with the calibration at the
    readings), triangulated with ``calibration``
    (default: :func:`simulated_calibration`) at the readings, compared with the true corner.

    The expectation (``CornerResult.expected_e``): per trial, the calibration's own error at
    the corner (its measurement of the exact corner pixel at the true pose, known here
    because the truth is) plus Gaussian noise with covariance ``J_px C_px J_px^T + J_q C_q
    J_q^T``: the corner pixel's predicted covariance (:class:`StripeEnd`) and the readout's
    variance per joint, through the model's and the kinematics' Jacobians. ``draws`` Monte
    Carlo sets of ``trials`` give the interval of e.

    Returns a :class:`GaugeBlockCheck`; ``.table()`` prints it in Table 3's layout.
    """
    import time
    from pathlib import Path

    from .model import pixels_from_points, points_in_base, project
    from .params import Parameters
    from .robot import Robot

    start = time.perf_counter()
    if not (isinstance(trials, (int, np.integer)) and trials >= 2):
        raise ValueError(f"trials must be an integer >= 2, got {trials}")
    truth = default_truth() if truth is None else truth
    q_true = as_params(truth)
    robot = Robot.scorbot_er7() if robot is None else robot
    readout = JointReadout() if readout is None else readout
    options = RenderOptions(noise=1.0) if options is None else options
    block = GAUGE_BLOCK if block is None else block
    if not isinstance(block, Box):
        raise ValueError(f"block must be a hmlvs.scenes.Box, got {type(block).__name__}")
    home = HOME if home is None else np.asarray(home, float)
    if home.shape != (robot.dof,):
        raise ValueError(f"home must hold {robot.dof} joint angles (rad), got {home.shape}")
    named = top_corners(block)
    names = list(named) if corners is None else list(corners)
    for n in names:
        if n not in named:
            raise ValueError(f"unknown corner {n!r}; the corners are {', '.join(named)}")
    scene = Scene((Table() if table is None else table, block))
    params, cal = _params_and_result(calibration, truth, readout, robot, seed)
    q_plan = as_params(params)
    hfc_plan = hand_from_camera(q_plan)
    if standoff is None:
        standoff = q_plan[6] / np.tan(q_plan[7])
    centre = (np.asarray(block.lo) + np.asarray(block.hi)) / 2
    paper = {row[0]: row for row in PAPER_TABLE3}
    is_paper_block = block == GAUGE_BLOCK
    rng = np.random.default_rng([seed, 23])
    noise_rng = np.random.default_rng([seed, 29])
    bar = _Progress(progress, trials * len(names))
    results, all_ids, all_frames, all_readings, e_pool = [], [], [], [], []
    for index, name in enumerate(names):
        corner = named[name]
        inward = np.sign(centre[:2] - corner[:2])
        meas, errs, pix_err, pix_sig, js, rs = [], [], [], [], [], []
        bias, covs, unexplained = [], [], []
        for k in range(trials):
            j = _place_on_corner(robot, q_true, hfc_plan, scene, corner, inward, standoff,
                                 image_size, rng, home, approach_mm, tilt_deg, angle_deg)
            reading = readout.read(j, rng)
            pose_true, pose_read = robot.poses(j), robot.poses(reading)
            frame = render_scene(q_true, pose_true[0], scene, image_size, options, noise_rng)
            # the operator's knowledge: the nominal corner and its two top edges, projected
            ends = corner + 10.0 * np.array([[0.0, 0.0, 0.0], [inward[0], 0.0, 0.0],
                                             [0.0, inward[1], 0.0]])
            near, _ = project(q_plan, ends, np.repeat(pose_read, 3, axis=0))
            end = locate_stripe_end(frame.on, frame.off, near[0],
                                    edges=[near[1] - near[0], near[2] - near[0]])
            pts, jpx, jq = _point_jacobians(q_plan, end.pixel[None], reading[None], robot)
            px_true, _ = pixels_from_points(q_true, corner[None], pose_true)
            p_cal, _ = points_in_base(q_plan, px_true, pose_true)
            explained = p_cal[0] - corner + jq[0] @ (reading - j)
            cov_px = jpx[0] @ end.cov @ jpx[0].T
            cov_q = readout.variance * jq[0] @ jq[0].T
            meas.append(pts[0])
            errs.append(pts[0] - corner)
            bias.append(p_cal[0] - corner)
            unexplained.append(pts[0] - corner - explained)
            covs.append((cov_px, cov_q))
            pix_err.append(end.pixel - px_true[0])
            pix_sig.append(np.sqrt(np.diag(end.cov)))
            js.append(j)
            rs.append(reading)
            all_ids.append(f"{name}-{k:02d}")
            all_frames.append(frame)
            all_readings.append(reading)
            bar.step()
        errs_a, bias_a = np.array(errs), np.array(bias)
        cov_px_a, cov_q_a = np.array([c[0] for c in covs]), np.array([c[1] for c in covs])
        norms = np.linalg.norm(errs_a, axis=1)
        # Monte Carlo of e and sigma under the predicted per-trial error distributions
        chol = np.linalg.cholesky(cov_px_a + cov_q_a + 1e-12 * np.eye(3))
        z = np.random.default_rng([seed, 37, index]).standard_normal((draws, trials, 3))
        sim_n = np.linalg.norm(bias_a[None] + np.einsum("tij,dtj->dti", chol, z), axis=2)
        e_draws, s_draws = sim_n.mean(axis=1), sim_n.std(axis=1, ddof=1)
        e_pool.append(e_draws)
        q_e = tuple(float(x) for x in np.percentile(e_draws, [0.5, 50, 99.5]))
        q_s = tuple(float(x) for x in np.percentile(s_draws, [0.5, 50, 99.5]))
        parts = {"calibration": float(np.sqrt(np.mean(np.sum(bias_a ** 2, axis=1)))),
                 "pixel": float(np.sqrt(np.mean(np.trace(cov_px_a, axis1=1, axis2=2)))),
                 "joints": float(np.sqrt(np.mean(np.trace(cov_q_a, axis1=1, axis2=2))))}
        row = paper.get(name) if is_paper_block else None
        results.append(CornerResult(
            name=name, true=corner, measured=np.array(meas), errors=errs_a,
            e=float(norms.mean()), sigma=float(norms.std(ddof=1)), expected_e=q_e,
            expected_sigma=q_s, parts=parts, pixel_error=np.array(pix_err),
            pixel_sigma=np.array(pix_sig), joints=np.array(js), readings=np.array(rs),
            readout_rms_deg=float(np.degrees(np.sqrt(np.mean(
                (np.array(rs) - np.array(js)) ** 2)))),
            readout_assumed_deg=float(np.degrees(np.sqrt(readout.variance))),
            unexplained=np.array(unexplained),
            paper_e=row[3] if row else None, paper_sigma=row[4] if row else None))
    files: dict[str, Any] = {}
    if out_dir is not None:
        files["manifest"] = _write_scan(
            out_dir, all_ids, all_frames, np.array(all_readings), image_size, robot,
            scene=_scene_to_dict(scene), scenario="gauge-block")
    pooled = tuple(float(x) for x in np.percentile(np.mean(e_pool, axis=0), [0.5, 50, 99.5]))
    check = GaugeBlockCheck(tuple(results), block, Parameters.from_array(q_true),
                            Parameters.from_array(q_plan), cal, trials, home, pooled, files,
                            time.perf_counter() - start)
    if out_dir is not None:
        import json

        from ._io import atomic_write
        path = Path(out_dir) / "gauge_block.json"
        with atomic_write(path) as fh:
            json.dump(check.to_dict(), fh, indent=1, default=float)
        files["results"] = path
    return check
