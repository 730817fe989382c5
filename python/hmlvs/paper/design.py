"""Sensor design analysis (paper section 2, Figs. 3-6): measurement range, resolution, and
the 3D error caused by a wrong baseline H or projection angle theta.

Everything is computed in the camera frame by the model of docs/model.md (``hmlvs._core``
through :func:`hmlvs.points_in_camera`), at every pixel of the image; this module only
measures the resulting point maps. Units: mm, rad, pixels (angles in degrees only in text).

Definitions (the paper does not give them; these are ours):

- A pixel is *usable* if its ray meets the laser plane in front of the camera
  (``Yu + f tan(theta) > 0``). With k = 0 usability depends on the row only: rows that look
  above the laser plane's horizon see no stripe.
- *z range* = largest minus smallest depth over the usable pixels (the depth of the first,
  farthest usable row minus that of the last, nearest row when k = 0).
- *y range* = largest minus smallest y over the usable pixels. Every point lies on the plane
  ``y + z tan(theta) = H``, so this equals ``tan(theta)`` times the z range.
- x: the stripe on an image row runs from column 0 to column w - 1; its *length* on that row
  is ``x(w - 1, v) - x(0, v)`` (pixel centres, so w - 1 pitches). We report four candidates:
  ``x_extent`` (largest minus smallest x over the usable image: the lateral field of view at
  the far end), the stripe length on the nearest, the mid-depth and the farthest usable
  rows, and ``x_growth`` = far length - near length, i.e. how much the stripe lengthens
  over the depth range. Only ``x_growth`` is near the paper's 155.0 mm (155.55 mm; see the
  docs/paper.md, "Sensor design analysis", for the rest of the difference).
- *Resolution* (the paper: "the displacement in the 3D real space per one pixel"): at pixel
  (u, v), ``res_u = |P(u + 1/2, v) - P(u - 1/2, v)|`` and
  ``res_v = |P(u, v + 1/2) - P(u, v - 1/2)|`` in mm/px, the 3D displacement over a one-pixel
  step centred on the pixel; NaN where a half step leaves the usable region.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from dataclasses import replace as dc_replace
import io
import math
import os
from pathlib import Path
from typing import Any, Iterable, Optional, Sequence

import numpy as np

from .._io import atomic_write
from ..models.paper import points_in_camera
from ..models.params import Parameters

#: The paper's ranges (section 2) for f = 8 mm, 7.4 um pixels, 640 x 480, H = 100 mm,
#: theta = 25 deg, in mm.
PAPER_RANGES = {"x": 155.0, "y": 122.3, "z": 262.3}
#: The paper's Fig. 6 cases: values used in the computation vs the sensor's true values.
PAPER_WRONG_H = (100.0, 99.0)
PAPER_WRONG_THETA_DEG = (25.0, 22.5)
#: Largest image the analysis accepts (it keeps several full-image maps in memory).
MAX_PIXELS = 25_000_000
#: Scalar sensor fields that :func:`sweep` can vary.
SWEEPABLE = ("H", "theta", "f", "k")


# ------------------------------------------------------------------------------------------
# The sensor


def _positive(name: str, value: Any, unit: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"{name} must be a finite number > 0 ({unit}), got {value!r}")
    return v


def _finite(name: str, value: Any) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return v


@dataclass(frozen=True)
class Sensor:
    """A laser-vision sensor design: camera, image and laser plane (camera frame).

    Attributes
    ----------
    f : float
        Effective focal length (mm).
    Su, Sv : float
        Pixel pitch, horizontal and vertical (mm/px).
    width, height : int
        Image size (px); columns u = 0..width-1, rows v = 0..height-1.
    Cu, Cv : float
        Principal point (px); the image centre ((width-1)/2, (height-1)/2) by default.
    H : float
        Laser baseline (mm): the plane is ``y + z tan(theta) = H`` in the camera frame.
    theta : float
        Laser projection angle (rad), in (-pi/2, pi/2).
    k : float
        Radial distortion, division model (1/mm^2); 0 for design unless given.
    """

    f: float
    Su: float
    Sv: float
    width: int
    height: int
    Cu: float
    Cv: float
    H: float
    theta: float
    k: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "f", _positive("f", self.f, "mm"))
        object.__setattr__(self, "Su", _positive("the horizontal pixel pitch Su", self.Su,
                                                 "mm/px"))
        object.__setattr__(self, "Sv", _positive("the vertical pixel pitch Sv", self.Sv,
                                                 "mm/px"))
        for name in ("width", "height"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) \
                    or value < 2:
                raise ValueError(f"image {name} must be an integer >= 2 (px), got {value!r}")
            object.__setattr__(self, name, int(value))
        if self.width * self.height > MAX_PIXELS:
            raise ValueError(f"image of {self.width} x {self.height} px is too large for the "
                             f"design analysis (at most {MAX_PIXELS} pixels)")
        object.__setattr__(self, "Cu", _finite("principal point Cu", self.Cu))
        object.__setattr__(self, "Cv", _finite("principal point Cv", self.Cv))
        object.__setattr__(self, "H", _positive("H", self.H, "mm"))
        theta = _finite("theta", self.theta)
        if not -math.pi / 2 < theta < math.pi / 2:
            raise ValueError(f"theta must lie in (-pi/2, pi/2) rad, i.e. (-90, 90) deg; got "
                             f"{theta:g} rad ({math.degrees(theta):g} deg)")
        object.__setattr__(self, "theta", theta)
        object.__setattr__(self, "k", _finite("k", self.k))

    @classmethod
    def make(cls, f: float = 8.0, pixel_pitch: float | Sequence[float] = 0.0074,
             image_size: Sequence[int] = (640, 480), H: float = 100.0,
             theta: float = math.radians(25.0), k: float = 0.0,
             principal_point: Optional[Sequence[float]] = None) -> "Sensor":
        """A sensor from design quantities; see :func:`analyze` for the arguments."""
        if np.ndim(pixel_pitch) == 0:
            su = sv = pixel_pitch
        else:
            pp = list(np.asarray(pixel_pitch, dtype=object).reshape(-1))
            if len(pp) != 2:
                raise ValueError(f"pixel_pitch must be one number or (Su, Sv), got "
                                 f"{pixel_pitch!r}")
            su, sv = pp
        size = list(image_size) if isinstance(image_size, (tuple, list, np.ndarray)) else None
        if size is None or len(size) != 2:
            raise ValueError(f"image_size must be (width, height) in px, got {image_size!r}")
        w, h = size
        if principal_point is None:
            # the image centre in the pixel-centres-at-integers convention of docs/model.md; a
            # non-integer size gives a nonsense centre, but Sensor() rejects it below
            cu = (w - 1) / 2 if isinstance(w, (int, np.integer)) else 0.0
            cv = (h - 1) / 2 if isinstance(h, (int, np.integer)) else 0.0
        else:
            ppt = list(np.atleast_1d(np.asarray(principal_point, dtype=object)))
            if len(ppt) != 2:
                raise ValueError(f"principal_point must be (Cu, Cv) in px, got "
                                 f"{principal_point!r}")
            cu, cv = ppt
        return cls(f=f, Su=su, Sv=sv, width=w, height=h, Cu=cu, Cv=cv, H=H, theta=theta, k=k)

    def replace(self, **changes: Any) -> "Sensor":
        """A copy with some fields changed (validated again)."""
        return dc_replace(self, **changes)

    def params(self) -> Parameters:
        """The 14 model parameters, with the camera at the hand frame (extrinsics zero)."""
        return Parameters(f=self.f, Su=self.Su, Sv=self.Sv, Cu=self.Cu, Cv=self.Cv, k=self.k,
                          H=self.H, theta=self.theta, omega=0.0, phi=0.0, varphi=0.0,
                          tx=0.0, ty=0.0, tz=0.0)

    def is_paper_design(self) -> bool:
        """True for the paper's section 2 example (8 mm, 7.4 um, 640 x 480, 100 mm, 25 deg)."""
        return (self.f == 8.0 and self.Su == self.Sv == 0.0074
                and (self.width, self.height) == (640, 480) and self.H == 100.0
                and math.isclose(self.theta, math.radians(25.0), abs_tol=1e-12)
                and self.k == 0.0)

    def describe(self) -> str:
        pitch = (f"{self.Su * 1000:g} um" if self.Su == self.Sv
                 else f"{self.Su * 1000:g} x {self.Sv * 1000:g} um")
        return (f"f = {self.f:g} mm, pixel pitch {pitch}, {self.width} x {self.height} px, "
                f"principal point ({self.Cu:g}, {self.Cv:g}) px, H = {self.H:g} mm, "
                f"theta = {math.degrees(self.theta):g} deg, k = {self.k:g} 1/mm^2")

    def to_dict(self) -> dict[str, float | int]:
        return {"f": self.f, "Su": self.Su, "Sv": self.Sv, "width": self.width,
                "height": self.height, "Cu": self.Cu, "Cv": self.Cv, "H": self.H,
                "theta": self.theta, "theta_deg": math.degrees(self.theta), "k": self.k}


def _point_map(sensor: Sensor, du: float = 0.0, dv: float = 0.0) -> np.ndarray:
    """Camera-frame points (height, width, 3) at pixels (u + du, v + dv); NaN = no stripe."""
    u, v = np.meshgrid(np.arange(sensor.width, dtype=float) + du,
                       np.arange(sensor.height, dtype=float) + dv)
    pixels = np.stack([u.ravel(), v.ravel()], axis=1)
    pts, _ = points_in_camera(sensor.params(), pixels, on_invalid="mask")
    return pts.reshape(sensor.height, sensor.width, 3)


# ------------------------------------------------------------------------------------------
# Analysis


@dataclass(frozen=True)
class Ranges:
    """Measurement ranges (mm); see the module docstring for the definitions.

    Attributes
    ----------
    x_extent : largest minus smallest x over the usable image (lateral field of view).
    x_width_near, x_width_mid, x_width_far : stripe length on the nearest, mid-depth
        (mean depth closest to the middle of the depth range) and farthest fully usable row.
    x_growth : ``x_width_far - x_width_near``; the only candidate near the paper's x range.
    y : largest minus smallest y over the usable image.
    z : largest minus smallest depth over the usable image.
    z_near, z_far : smallest and largest depth (mm).
    row_near, row_mid, row_far : the rows used for the stripe lengths (-1 if none).
    """

    x_extent: float
    x_width_near: float
    x_width_mid: float
    x_width_far: float
    x_growth: float
    y: float
    z: float
    z_near: float
    z_far: float
    row_near: int
    row_mid: int
    row_far: int


@dataclass(frozen=True)
class Resolution:
    """Resolution statistics (mm/px) over the pixels where it is defined.

    Attributes
    ----------
    u_min, u_max : range of ``|P(u + 1/2) - P(u - 1/2)|`` (one column step).
    v_min, v_max : range of ``|P(v + 1/2) - P(v - 1/2)|`` (one row step).
    u_center, v_center : both at the pixel nearest the principal point (NaN if unusable).
    dx_du_max, dy_dv_max, dz_dv_max : the worst per-axis steps: |delta x| per column step,
        |delta y| and |delta z| per row step (the paper's per-axis view of Fig. 3).
    limit : the threshold of ``within_limit`` (mm/px).
    within_limit : fraction of the usable pixels where both steps are <= ``limit``.
    """

    u_min: float
    u_max: float
    v_min: float
    v_max: float
    u_center: float
    v_center: float
    dx_du_max: float
    dy_dv_max: float
    dz_dv_max: float
    limit: float
    within_limit: float


def _nan_stat(fn: Any, a: np.ndarray) -> float:
    a = a[np.isfinite(a)]
    return float(fn(a)) if a.size else math.nan


def _json_value(v: Any) -> Any:
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


@dataclass(frozen=True, eq=False)
class DesignReport:
    """Result of :func:`analyze`: ranges, resolution statistics and full-image maps.

    Attributes
    ----------
    sensor : Sensor
        The analysed design.
    points : ndarray, shape (height, width, 3)
        Camera-frame laser point (mm) seen at each pixel; NaN where unusable.
    usable : ndarray of bool, shape (height, width)
        Pixels whose ray meets the laser plane in front of the camera.
    usable_fraction : float
        Fraction of the image that is usable.
    usable_rows : tuple of int or None
        First and last row whose every pixel is usable (None if no row is).
    ranges : Ranges
    resolution_u, resolution_v : ndarray, shape (height, width)
        The resolution maps (mm/px); NaN where undefined.
    resolution : Resolution
        Statistics of the maps.
    """

    sensor: Sensor
    points: np.ndarray = field(repr=False)
    usable: np.ndarray = field(repr=False)
    usable_fraction: float
    usable_rows: Optional[tuple[int, int]]
    ranges: Ranges
    resolution_u: np.ndarray = field(repr=False)
    resolution_v: np.ndarray = field(repr=False)
    resolution: Resolution

    def usable_text(self) -> str:
        """One sentence on which part of the image sees the laser."""
        s, pct = self.sensor, 100 * self.usable_fraction
        if self.usable_fraction == 1.0:
            return f"the whole image ({s.width} x {s.height} px) sees the laser plane"
        if self.usable_rows is None:
            return (f"{pct:.1f}% of the pixels see the laser plane, but no full row does")
        a, b = self.usable_rows
        text = f"{pct:.1f}% of the image sees the laser plane: rows {a}-{b}"
        if self.sensor.k == 0.0:
            text += " (the other rows look past the plane's horizon, Yu + f tan(theta) <= 0)"
        return text

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready summary (no maps); NaN becomes None."""
        r, q = self.ranges, self.resolution
        return {
            "sensor": self.sensor.to_dict(),
            "usable_fraction": self.usable_fraction,
            "usable_rows": list(self.usable_rows) if self.usable_rows else None,
            "ranges_mm": {k: _json_value(v) for k, v in vars(r).items()},
            "resolution_mm_per_px": {k: _json_value(v) for k, v in vars(q).items()},
            "paper_ranges_mm": PAPER_RANGES if self.sensor.is_paper_design() else None,
        }

    def _range_rows(self) -> list[tuple[str, float, Optional[float]]]:
        r = self.ranges
        paper = self.sensor.is_paper_design()
        return [
            ("x, stripe lengthening far - near (x_growth)", r.x_growth,
             PAPER_RANGES["x"] if paper else None),
            ("x, stripe length on the farthest row", r.x_width_far, None),
            ("x, stripe length on the mid-depth row", r.x_width_mid, None),
            ("x, stripe length on the nearest row", r.x_width_near, None),
            ("x, extent over the usable image", r.x_extent, None),
            ("y, extent over the usable image", r.y, PAPER_RANGES["y"] if paper else None),
            ("z, extent over the usable image", r.z, PAPER_RANGES["z"] if paper else None),
        ]

    def __str__(self) -> str:
        r, q = self.ranges, self.resolution
        lines = [f"HMLVS design: {self.sensor.describe()}",
                 f"usable: {self.usable_text()}",
                 f"depth: {r.z_near:.2f} mm (row {r.row_near}) to {r.z_far:.2f} mm "
                 f"(row {r.row_far})",
                 "measurement ranges (mm):"]
        paper = self.sensor.is_paper_design()
        for name, value, ref in self._range_rows():
            line = f"  {name:<45} {value:9.2f}"
            if paper:
                line += f"   paper {ref:.1f}" if ref is not None else ""
            lines.append(line)
        lines += [
            "resolution (mm/px, 3D displacement per one-pixel step):",
            f"  along u (columns): {q.u_min:.3f} .. {q.u_max:.3f}   at the centre "
            f"{q.u_center:.3f}",
            f"  along v (rows):    {q.v_min:.3f} .. {q.v_max:.3f}   at the centre "
            f"{q.v_center:.3f}",
            f"  worst per axis: dx/du {q.dx_du_max:.3f}, dy/dv {q.dy_dv_max:.3f}, "
            f"dz/dv {q.dz_dv_max:.3f}",
            f"  both steps <= {q.limit:g} mm/px on {100 * q.within_limit:.1f}% of the usable "
            "image",
        ]
        return "\n".join(lines)

    def markdown(self, errors: Sequence["ErrorReport"] = (),
                 files: Sequence[os.PathLike | str] = ()) -> str:
        """A Markdown summary, optionally with Fig. 6 error results and the plot files."""
        r, q = self.ranges, self.resolution
        paper = self.sensor.is_paper_design()
        out = ["# HMLVS sensor design analysis", "", f"Sensor: {self.sensor.describe()}.", "",
               f"Usable image: {self.usable_text()}.", "",
               f"Depth from {r.z_near:.2f} mm (row {r.row_near}) to {r.z_far:.2f} mm "
               f"(row {r.row_far}).", "", "## Measurement ranges", ""]
        out += ["| range | this analysis (mm) |" + (" paper (mm) |" if paper else ""),
                "|---|---:|" + ("---:|" if paper else "")]
        for name, value, ref in self._range_rows():
            row = f"| {name} | {value:.2f} |"
            if paper:
                row += f" {ref:.1f} |" if ref is not None else " |"
            out.append(row)
        out += ["", "## Resolution (mm/px)", "",
                "| step | min | max | at the centre |", "|---|---:|---:|---:|",
                f"| one column (u) | {q.u_min:.3f} | {q.u_max:.3f} | {q.u_center:.3f} |",
                f"| one row (v) | {q.v_min:.3f} | {q.v_max:.3f} | {q.v_center:.3f} |", "",
                f"Worst per axis: dx/du {q.dx_du_max:.3f}, dy/dv {q.dy_dv_max:.3f}, "
                f"dz/dv {q.dz_dv_max:.3f} mm/px. Both steps are <= {q.limit:g} mm/px on "
                f"{100 * q.within_limit:.1f}% of the usable image."]
        if errors:
            out += ["", "## 3D error from a wrong H or theta (Fig. 6)", "",
                    "| case | max (mm) | mean (mm) | worst pixel (u, v) |",
                    "|---|---:|---:|---|"]
            for e in errors:
                out.append(f"| {e.label} | {e.max:.3f} | {e.mean:.3f} | "
                           f"({e.worst_pixel[0]}, {e.worst_pixel[1]}) |")
        if files:
            out += ["", "## Plots", ""] + [f"- `{Path(p).name}`" for p in files]
        return "\n".join(out) + "\n"


def _analyze(sensor: Sensor, resolution_limit: float) -> Optional[DesignReport]:
    """The analysis, or None if no pixel sees the laser plane."""
    pts = _point_map(sensor)
    usable = np.isfinite(pts).all(axis=2)
    if not usable.any():
        return None
    x, y, z = pts[..., 0], pts[..., 1], pts[..., 2]

    # one-pixel steps centred on each pixel
    step_u = _point_map(sensor, du=0.5) - _point_map(sensor, du=-0.5)
    step_v = _point_map(sensor, dv=0.5) - _point_map(sensor, dv=-0.5)
    res_u = np.linalg.norm(step_u, axis=2)
    res_v = np.linalg.norm(step_v, axis=2)
    res_u[~usable] = np.nan
    res_v[~usable] = np.nan

    # ranges
    z_near, z_far = float(np.min(z[usable])), float(np.max(z[usable]))
    full_rows = np.nonzero(usable.all(axis=1))[0]
    if full_rows.size:
        widths = x[full_rows, -1] - x[full_rows, 0]
        depth = z[full_rows].mean(axis=1)
        i_near, i_far = int(np.argmin(depth)), int(np.argmax(depth))
        i_mid = int(np.argmin(np.abs(depth - (depth[i_near] + depth[i_far]) / 2)))
        w_near, w_mid, w_far = (float(widths[i]) for i in (i_near, i_mid, i_far))
        rows = tuple(int(full_rows[i]) for i in (i_near, i_mid, i_far))
        usable_rows: Optional[tuple[int, int]] = (int(full_rows[0]), int(full_rows[-1]))
    else:
        w_near = w_mid = w_far = math.nan
        rows = (-1, -1, -1)
        usable_rows = None
    ranges = Ranges(
        x_extent=float(np.max(x[usable]) - np.min(x[usable])),
        x_width_near=w_near, x_width_mid=w_mid, x_width_far=w_far,
        x_growth=w_far - w_near,
        y=float(np.max(y[usable]) - np.min(y[usable])),
        z=z_far - z_near, z_near=z_near, z_far=z_far,
        row_near=rows[0], row_mid=rows[1], row_far=rows[2])

    # resolution statistics
    cu = min(max(int(round(sensor.Cu)), 0), sensor.width - 1)
    cv = min(max(int(round(sensor.Cv)), 0), sensor.height - 1)
    worst = np.fmax(res_u, res_v)
    both = np.isfinite(res_u) & np.isfinite(res_v)
    fine = both & (worst <= resolution_limit)
    resolution = Resolution(
        u_min=_nan_stat(np.min, res_u), u_max=_nan_stat(np.max, res_u),
        v_min=_nan_stat(np.min, res_v), v_max=_nan_stat(np.max, res_v),
        u_center=float(res_u[cv, cu]), v_center=float(res_v[cv, cu]),
        dx_du_max=_nan_stat(np.max, np.abs(step_u[..., 0])),
        dy_dv_max=_nan_stat(np.max, np.abs(step_v[..., 1])),
        dz_dv_max=_nan_stat(np.max, np.abs(step_v[..., 2])),
        limit=resolution_limit,
        within_limit=float(fine.sum() / usable.sum()))
    return DesignReport(sensor=sensor, points=pts, usable=usable,
                        usable_fraction=float(usable.mean()), usable_rows=usable_rows,
                        ranges=ranges, resolution_u=res_u, resolution_v=res_v,
                        resolution=resolution)


def _no_stripe_error(sensor: Sensor) -> ValueError:
    return ValueError(
        f"no pixel of the {sensor.width} x {sensor.height} image sees the laser plane "
        f"(Yu + f tan(theta) <= 0 everywhere) with theta = {math.degrees(sensor.theta):g} deg, "
        f"H = {sensor.H:g} mm")


def analyze(f: float = 8.0, pixel_pitch: float | Sequence[float] = 0.0074,
            image_size: Sequence[int] = (640, 480), H: float = 100.0,
            theta: float = math.radians(25.0), k: float = 0.0,
            principal_point: Optional[Sequence[float]] = None, *,
            resolution_limit: float = 1.0, sensor: Optional[Sensor] = None) -> DesignReport:
    """Measurement ranges and resolution of a sensor design over the whole image.

    Parameters
    ----------
    f : float
        Effective focal length (mm).
    pixel_pitch : float or (float, float)
        Pixel pitch (mm/px): one value for square pixels, or (Su, Sv).
    image_size : (int, int)
        Image (width, height) in px, each >= 2.
    H : float
        Laser baseline (mm), > 0.
    theta : float
        Laser projection angle (rad), in (-pi/2, pi/2).
    k : float
        Radial distortion coefficient, division model (1/mm^2).
    principal_point : (float, float), optional
        (Cu, Cv) in px; the image centre ((width-1)/2, (height-1)/2) by default.
    resolution_limit : float
        Threshold (mm/px) for :attr:`Resolution.within_limit`; the paper's design goal is 1.
    sensor : Sensor, optional
        A ready-made design; the other sensor arguments are then ignored.

    Returns
    -------
    DesignReport
        ``str(report)`` is a text summary.

    Raises
    ------
    ValueError
        On a bad argument, or if no pixel of the image sees the laser plane.

    Examples
    --------
    >>> r = hmlvs.design.analyze(H=100.0, theta=np.radians(25))
    >>> round(r.ranges.z, 1), round(r.ranges.x_growth, 1)
    (263.2, 155.6)
    """
    s = sensor if sensor is not None else Sensor.make(f, pixel_pitch, image_size, H, theta, k,
                                                      principal_point)
    limit = _positive("resolution_limit", resolution_limit, "mm/px")
    report = _analyze(s, limit)
    if report is None:
        raise _no_stripe_error(s)
    return report


# ------------------------------------------------------------------------------------------
# Sweeps (Figs. 4 and 5)


@dataclass(frozen=True, eq=False)
class SweepResult:
    """Ranges and resolution as one design quantity varies (paper Figs. 4 and 5).

    All arrays have the length of ``values``; NaN where no pixel sees the laser plane.

    Attributes
    ----------
    parameter : str
        The varied sensor field ("H", "theta", "f" or "k").
    values : ndarray
        Its values, in the sensor's units (theta in rad).
    base : Sensor
        The design the other quantities are taken from.
    x_growth, x_extent, x_width_near, x_width_far, y, z, z_near, z_far : ndarray
        Ranges (mm), as in :class:`Ranges`.
    res_u_min, res_u_max, res_v_min, res_v_max, res_u_center, res_v_center : ndarray
        Resolution statistics (mm/px), as in :class:`Resolution`.
    usable_fraction : ndarray
        Fraction of the image that sees the laser plane.
    """

    parameter: str
    values: np.ndarray
    base: Sensor
    x_growth: np.ndarray
    x_extent: np.ndarray
    x_width_near: np.ndarray
    x_width_far: np.ndarray
    y: np.ndarray
    z: np.ndarray
    z_near: np.ndarray
    z_far: np.ndarray
    res_u_min: np.ndarray
    res_u_max: np.ndarray
    res_v_min: np.ndarray
    res_v_max: np.ndarray
    res_u_center: np.ndarray
    res_v_center: np.ndarray
    usable_fraction: np.ndarray

    @property
    def display_values(self) -> np.ndarray:
        """``values`` in display units (theta in degrees)."""
        return np.degrees(self.values) if self.parameter == "theta" else self.values

    @property
    def display_unit(self) -> str:
        return {"H": "mm", "theta": "deg", "f": "mm", "k": "1/mm^2"}[self.parameter]

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"parameter": self.parameter, "unit": self.display_unit,
                               "base": self.base.to_dict()}
        for name in ("x_growth", "x_extent", "x_width_near", "x_width_far", "y", "z",
                     "z_near", "z_far", "res_u_min", "res_u_max", "res_v_min", "res_v_max",
                     "res_u_center", "res_v_center", "usable_fraction"):
            out[name] = [_json_value(float(v)) for v in getattr(self, name)]
        out["values"] = [float(v) for v in self.display_values]
        return out


def default_sweep_values(parameter: str, base: Sensor) -> np.ndarray:
    """Sweep values around ``base``: H from 0.5 H to 1.5 H in 21 steps (50..150 mm for the
    paper's design); theta from 15 to 45 deg by 1 deg, plus the design angle."""
    if parameter == "H":
        return np.linspace(0.5 * base.H, 1.5 * base.H, 21)
    if parameter == "theta":
        deg = np.union1d(np.arange(15.0, 45.5, 1.0), [round(math.degrees(base.theta), 9)])
        return np.radians(deg)
    if parameter == "f":
        return np.linspace(0.5 * base.f, 1.5 * base.f, 21)
    if parameter == "k":
        return np.linspace(0.0, 0.1, 21)
    raise ValueError(f"cannot sweep {parameter!r}; choose one of {', '.join(SWEEPABLE)}")


def sweep(parameter: str, values: Optional[Iterable[float]] = None, *,
          sensor: Optional[Sensor] = None, resolution_limit: float = 1.0,
          **design: Any) -> SweepResult:
    """Ranges and resolution as ``parameter`` varies, the rest fixed (Figs. 4 and 5).

    Parameters
    ----------
    parameter : {"H", "theta", "f", "k"}
        The design quantity to vary; Fig. 4 varies H (theta = 25 deg), Fig. 5 theta
        (H = 100 mm).
    values : sequence of float, optional
        Its values (theta in rad); :func:`default_sweep_values` if omitted.
    sensor : Sensor, optional
        The fixed design; otherwise built from ``design`` (the arguments of
        :func:`analyze`, defaults included).
    resolution_limit : float
        As in :func:`analyze`.

    Returns
    -------
    SweepResult
        A value at which no pixel sees the laser plane gets NaN ranges and resolution.

    Examples
    --------
    >>> s = hmlvs.design.sweep("H", [50.0, 100.0, 150.0])
    >>> np.round(s.z / s.values, 4)   # the ranges scale with H
    array([2.6316, 2.6316, 2.6316])
    """
    if parameter not in SWEEPABLE:
        raise ValueError(f"cannot sweep {parameter!r}; choose one of {', '.join(SWEEPABLE)}")
    base = sensor if sensor is not None else Sensor.make(**design)
    vals = (default_sweep_values(parameter, base) if values is None
            else np.asarray(list(values), dtype=float).reshape(-1))
    if vals.size == 0:
        raise ValueError("sweep needs at least one value")
    limit = _positive("resolution_limit", resolution_limit, "mm/px")
    names = ("x_growth", "x_extent", "x_width_near", "x_width_far", "y", "z", "z_near",
             "z_far")
    rnames = ("u_min", "u_max", "v_min", "v_max", "u_center", "v_center")
    cols: dict[str, list[float]] = {n: [] for n in names + rnames + ("usable_fraction",)}
    for value in vals:
        r = _analyze(base.replace(**{parameter: float(value)}), limit)
        for n in names:
            cols[n].append(getattr(r.ranges, n) if r else math.nan)
        for n in rnames:
            cols[n].append(getattr(r.resolution, n) if r else math.nan)
        cols["usable_fraction"].append(r.usable_fraction if r else 0.0)
    arr = {n: np.array(v) for n, v in cols.items()}
    return SweepResult(parameter=parameter, values=vals, base=base,
                       **{n: arr[n] for n in names},
                       **{f"res_{n}": arr[n] for n in rnames},
                       usable_fraction=arr["usable_fraction"])


# ------------------------------------------------------------------------------------------
# 3D error from a wrong H or theta (Fig. 6)


@dataclass(frozen=True, eq=False)
class ErrorReport:
    """3D error of every pixel's point computed with a wrong H and/or theta (Fig. 6).

    The sensor's real laser plane is the one of ``true``; a stripe seen at pixel (u, v) is
    therefore the point ``P_true(u, v)``, but the computation uses ``used`` and gets
    ``P_used(u, v)``. The error is ``P_used - P_true`` (camera frame, mm).

    Attributes
    ----------
    used, true : Sensor
        The design values used in the computation and the sensor's real ones.
    vectors : ndarray, shape (height, width, 3)
        ``P_used - P_true`` (mm); NaN where either computation has no point.
    error : ndarray, shape (height, width)
        ``|P_used - P_true|`` (mm).
    valid : ndarray of bool, shape (height, width)
        Pixels usable under both.
    max, mean : float
        Largest and mean error over the valid pixels (mm).
    worst_pixel : (int, int)
        (u, v) of the largest error.
    """

    used: Sensor
    true: Sensor
    vectors: np.ndarray = field(repr=False)
    error: np.ndarray = field(repr=False)
    valid: np.ndarray = field(repr=False)
    max: float
    mean: float
    worst_pixel: tuple[int, int]

    @property
    def label(self) -> str:
        parts = []
        if self.used.H != self.true.H:
            parts.append(f"H {self.used.H:g} mm used, true {self.true.H:g} mm")
        if self.used.theta != self.true.theta:
            parts.append(f"theta {math.degrees(self.used.theta):g} deg used, true "
                         f"{math.degrees(self.true.theta):g} deg")
        return "; ".join(parts) if parts else "no difference"

    @property
    def slug(self) -> str:
        """A short file-name tag: "H", "theta" or "H_theta"."""
        tags = [t for t, d in (("H", self.used.H != self.true.H),
                               ("theta", self.used.theta != self.true.theta)) if d]
        return "_".join(tags) or "none"

    def to_dict(self) -> dict[str, Any]:
        return {"case": self.label, "used": {"H": self.used.H,
                                             "theta_deg": math.degrees(self.used.theta)},
                "true": {"H": self.true.H, "theta_deg": math.degrees(self.true.theta)},
                "max_mm": self.max, "mean_mm": self.mean,
                "worst_pixel": list(self.worst_pixel),
                "valid_fraction": float(self.valid.mean())}

    def __str__(self) -> str:
        return (f"{self.label}: 3D error max {self.max:.3f} mm at pixel "
                f"{self.worst_pixel}, mean {self.mean:.3f} mm over "
                f"{100 * self.valid.mean():.1f}% of the image")


_DESIGN_ARGS = ("f", "pixel_pitch", "image_size", "H", "theta", "k", "principal_point")


def error_from_wrong(*, H_true: Optional[float] = None, theta_true: Optional[float] = None,
                     sensor: Optional[Sensor] = None, **design: Any) -> ErrorReport:
    """The 3D error over the image when the computation uses H and theta but the sensor's
    real values are ``H_true`` and ``theta_true`` (paper Fig. 6).

    Parameters
    ----------
    f, pixel_pitch, image_size, H, theta, k, principal_point
        The design as used in the computation, by keyword, with :func:`analyze`'s defaults;
        or ``sensor``.
    H_true : float, optional
        The real baseline (mm); the paper's Fig. 6a uses 99 for H = 100.
    theta_true : float, optional
        The real projection angle (rad); the paper's Fig. 6b uses 22.5 deg for 25 deg.
    sensor : Sensor, optional
        The design as used, instead of the separate arguments.

    Returns
    -------
    ErrorReport

    Raises
    ------
    ValueError
        If neither true value is given, a value is out of range, or no pixel sees the
        laser plane under both designs.

    Examples
    --------
    >>> e = hmlvs.design.error_from_wrong(H=100.0, H_true=99.0)
    >>> round(e.max, 2)   # = |P| / 100 at the far image corners
    4.35
    """
    unknown = sorted(set(design) - set(_DESIGN_ARGS))
    if unknown:
        raise ValueError(f"unknown design argument(s) {', '.join(unknown)}; valid: "
                         f"{', '.join(_DESIGN_ARGS)}")
    used = sensor if sensor is not None else Sensor.make(**design)
    if H_true is None and theta_true is None:
        raise ValueError("give H_true and/or theta_true: the sensor's real value(s)")
    changes: dict[str, float] = {}
    if H_true is not None:
        changes["H"] = H_true
    if theta_true is not None:
        changes["theta"] = theta_true
    try:
        true = used.replace(**changes)
    except ValueError as e:
        raise ValueError(f"the true value is invalid: {e}") from None
    p_used, p_true = _point_map(used), _point_map(true)
    vec = p_used - p_true
    err = np.linalg.norm(vec, axis=2)
    valid = np.isfinite(err)
    if not valid.any():
        raise ValueError(f"no pixel sees the laser plane under both the used values and the "
                         f"true ones ({true.describe()})")
    flat = int(np.nanargmax(err))
    v, u = divmod(flat, used.width)
    return ErrorReport(used=used, true=true, vectors=vec, error=err, valid=valid,
                       max=float(err[valid].max()), mean=float(err[valid].mean()),
                       worst_pixel=(int(u), int(v)))


def paper_errors(sensor: Sensor) -> list[ErrorReport]:
    """The paper's two Fig. 6 cases around ``sensor``: real H 1 mm smaller, real theta
    2.5 deg smaller (100 vs 99 mm and 25 vs 22.5 deg for the paper's design)."""
    dH = PAPER_WRONG_H[0] - PAPER_WRONG_H[1]
    dtheta = math.radians(PAPER_WRONG_THETA_DEG[0] - PAPER_WRONG_THETA_DEG[1])
    return [error_from_wrong(sensor=sensor, H_true=sensor.H - dH),
            error_from_wrong(sensor=sensor, theta_true=sensor.theta - dtheta)]


# ------------------------------------------------------------------------------------------
# Plots


def _save(fig: Any, path: Path) -> Path:
    """Render a figure to PNG in memory (Agg), then write it atomically."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=PLOT_DPI)
    with atomic_write(path, "wb") as fh:
        fh.write(buf.getvalue())
    return path


PLOT_DPI = 100


def _norm(data: np.ndarray) -> Any:
    """A logarithmic colour scale for maps spanning more than a factor 20, else None."""
    from matplotlib.colors import LogNorm

    d = data[np.isfinite(data) & (data > 0)]
    if d.size and d.max() > 20 * d.min():
        return LogNorm(vmin=d.min(), vmax=d.max())
    return None


def _image_axes(ax: Any, sensor: Sensor) -> None:
    ax.set_xlabel("u, image column (px)")
    ax.set_ylabel("v, image row (px)")
    ax.set_xlim(-0.5, sensor.width - 0.5)
    ax.set_ylim(sensor.height - 0.5, -0.5)


def _plot_resolution(report: DesignReport, path: Path) -> Path:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(12, 4.6), layout="constrained")
    axes = fig.subplots(1, 2)
    s = report.sensor
    for ax, data, name in ((axes[0], report.resolution_u, "one column step (along u)"),
                           (axes[1], report.resolution_v, "one row step (along v)")):
        im = ax.imshow(data, cmap="viridis", aspect="equal", interpolation="nearest",
                       norm=_norm(data))
        cb = fig.colorbar(im, ax=ax, shrink=0.9)
        cb.set_label("3D displacement per pixel (mm/px)")
        lim = report.resolution.limit
        if np.nanmin(data) < lim < np.nanmax(data):
            cs = ax.contour(data, levels=[lim], colors="white", linewidths=1.2)
            ax.clabel(cs, fmt=f"{lim:g} mm/px", fontsize=8)
        note = ""
        if not report.usable.all():
            ax.contourf(~report.usable, levels=[0.5, 1.5], colors="0.6")
            note = "; grey: no laser"
        _image_axes(ax, s)
        ax.set_title(f"Resolution, {name}\n{np.nanmin(data):.3f} to "
                     f"{np.nanmax(data):.3f} mm/px{note}")
    fig.suptitle(f"Resolution over the image (H = {s.H:g} mm, theta = "
                 f"{math.degrees(s.theta):g} deg, f = {s.f:g} mm)")
    return _save(fig, path)


def _plot_footprint(report: DesignReport, path: Path) -> Path:
    """The measurable region on the laser plane, seen from above (x against depth z)."""
    from matplotlib.figure import Figure

    s, r, pts = report.sensor, report.ranges, report.points
    fig = Figure(figsize=(7.5, 6), layout="constrained")
    ax = fig.subplots()
    sub = pts[::8, ::8][report.usable[::8, ::8]]
    ax.plot(sub[:, 0], sub[:, 2], ".", ms=1.5, color="0.7",
            label="points of every 8th row and column")
    for row, name, color in ((r.row_far, "farthest row", "C3"), (r.row_mid, "mid-depth row",
                                                                  "C2"),
                             (r.row_near, "nearest row", "C0")):
        if row >= 0:
            line = pts[row]
            w = line[-1, 0] - line[0, 0]
            ax.plot(line[:, 0], line[:, 2], "-", color=color, lw=2,
                    label=f"{name} (v = {row}): stripe length {w:.1f} mm")
    if r.row_near >= 0 and r.row_far >= 0:
        ax.annotate("", xy=(pts[r.row_far, -1, 0], r.z_far + 8),
                    xytext=(pts[r.row_far, -1, 0] - r.x_growth, r.z_far + 8),
                    arrowprops=dict(arrowstyle="<->", color="k"))
        ax.text(pts[r.row_far, -1, 0] - r.x_growth / 2, r.z_far + 12,
                f"far - near length = {r.x_growth:.1f} mm", ha="center", va="bottom")
    ax.axhspan(r.z_near, r.z_far, color="C1", alpha=0.08,
               label=f"depth range {r.z:.1f} mm ({r.z_near:.1f} to {r.z_far:.1f})")
    ax.set_xlabel("x, camera frame (mm)")
    ax.set_ylabel("z, depth along the optical axis (mm)")
    ax.set_ylim(0, r.z_far * 1.15)
    ax.set_title(f"Measurable region on the laser plane\n(H = {s.H:g} mm, theta = "
                 f"{math.degrees(s.theta):g} deg; y = H - z tan(theta))")
    ax.legend(loc="lower center", fontsize=8)
    ax.grid(alpha=0.3)
    return _save(fig, path)


def _plot_sweep(sw: SweepResult, path: Path, figure: str) -> Path:
    from matplotlib.figure import Figure

    x = sw.display_values
    unit = sw.display_unit
    b = sw.base
    fig = Figure(figsize=(12, 4.6), layout="constrained")
    a1, a2 = fig.subplots(1, 2)
    a1.plot(x, sw.x_growth, "-o", ms=3, label="x: stripe lengthening, far - near")
    a1.plot(x, sw.x_width_far, "--", label="x: stripe length, farthest row")
    a1.plot(x, sw.y, "-s", ms=3, label="y: extent over the image")
    a1.plot(x, sw.z, "-^", ms=3, label="z: depth range")
    a1.set_ylabel("measurement range (mm)")
    a2.plot(x, sw.res_u_max, "-o", ms=3, label="one column step, worst (far rows)")
    a2.plot(x, sw.res_v_max, "-^", ms=3, label="one row step, worst (far rows)")
    a2.plot(x, sw.res_v_center, "--", label="one row step, at the image centre")
    a2.plot(x, sw.res_u_min, ":", label="one column step, best (near rows)")
    a2.axhline(1.0, color="0.5", lw=0.8)
    a2.set_ylabel("resolution (mm/px)")
    fixed = (f"theta = {math.degrees(b.theta):g} deg" if sw.parameter != "theta"
             else f"H = {b.H:g} mm")
    design = math.degrees(b.theta) if sw.parameter == "theta" else getattr(b, sw.parameter)
    for ax in (a1, a2):
        ax.axvline(design, color="k", lw=0.8, ls="--")
        ax.set_xlabel(f"{sw.parameter} ({unit})")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    a1.set_title(f"Measurement range vs {sw.parameter} ({fixed})")
    a2.set_title(f"Resolution vs {sw.parameter} ({fixed})")
    for ax, data in ((a1, np.concatenate([sw.z, sw.y, sw.x_growth])),
                     (a2, np.concatenate([sw.res_v_max, sw.res_u_min]))):
        data = data[np.isfinite(data) & (data > 0)]
        if data.size and data.max() > 100 * data.min():
            ax.set_yscale("log")  # a range over decades (e.g. theta near the horizon)
    fig.suptitle(f"{figure}: f = {b.f:g} mm, {b.Su * 1000:g} um pixels, "
                 f"{b.width} x {b.height} px; dashed line = analysed design")
    return _save(fig, path)


def _plot_error(e: ErrorReport, path: Path, figure: str) -> Path:
    from matplotlib.figure import Figure

    s = e.used
    fig = Figure(figsize=(12, 4.6), layout="constrained")
    a1, a2 = fig.subplots(1, 2, width_ratios=[1.3, 1])
    im = a1.imshow(e.error, cmap="magma", aspect="equal", interpolation="nearest",
                   norm=_norm(e.error))
    cb = fig.colorbar(im, ax=a1, shrink=0.9)
    cb.set_label("3D error |P_used - P_true| (mm)")
    _image_axes(a1, s)
    note = "" if e.valid.all() else "\n(white: no point with the used or the true values)"
    a1.set_title(f"3D error over the image: max {e.max:.2f} mm, mean {e.mean:.2f} mm{note}")
    rows = np.arange(s.height)
    for col, name in ((0, "column 0 (edge)"), (s.width // 2, f"column {s.width // 2} "
                                                              "(centre)")):
        a2.plot(rows, e.error[:, col], label=name)
    a2.set_xlabel("v, image row (px); row 0 is the farthest")
    a2.set_ylabel("3D error (mm)")
    a2.set_title("3D error along image columns")
    if _norm(e.error) is not None:
        a2.set_yscale("log")
    a2.grid(alpha=0.3)
    a2.legend(fontsize=8)
    fig.suptitle(f"{figure}: {e.label}")
    return _save(fig, path)


def plot(report: DesignReport, out_dir: str | os.PathLike, *,
         sweeps: Optional[Sequence[SweepResult]] = None,
         errors: Optional[Sequence[ErrorReport]] = None) -> list[Path]:
    """Write the design plots as PNG files into ``out_dir`` (created if needed).

    Files: ``design_resolution.png`` (resolution maps), ``design_footprint.png`` (the
    measurable region on the laser plane), ``design_sweep_<param>.png`` (Figs. 4-5: ranges
    and resolution vs H and vs theta), ``design_error_<case>.png`` (Fig. 6 error maps).

    Parameters
    ----------
    report : DesignReport
        From :func:`analyze`.
    out_dir : path
        Folder for the PNGs.
    sweeps : sequence of SweepResult, optional
        Default: :func:`sweep` over H and theta around ``report.sensor``.
    errors : sequence of ErrorReport, optional
        Default: :func:`paper_errors` (real H 1 mm smaller; real theta 2.5 deg smaller).

    Returns
    -------
    list of Path
        The files written, each atomically (rendered in memory with Agg first).
    """
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ValueError(f"{out} exists and is not a folder")
    s = report.sensor
    if sweeps is None:
        sweeps = [sweep("H", sensor=s, resolution_limit=report.resolution.limit),
                  sweep("theta", sensor=s, resolution_limit=report.resolution.limit)]
    if errors is None:
        errors = paper_errors(s)
    files = [_plot_resolution(report, out / "design_resolution.png"),
             _plot_footprint(report, out / "design_footprint.png")]
    figs = {"H": "Fig. 4", "theta": "Fig. 5"}
    for sw in sweeps:
        files.append(_plot_sweep(sw, out / f"design_sweep_{sw.parameter}.png",
                                 f"{figs.get(sw.parameter, 'Sweep')} (paper)"))
    for i, e in enumerate(errors):
        name = f"design_error_{e.slug}.png"
        if any(p.name == name for p in files):
            name = f"design_error_{e.slug}_{i}.png"
        files.append(_plot_error(e, out / name, "Fig. 6 (paper)"))
    return files
