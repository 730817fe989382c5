"""The sensor of the design analysis and its point maps: ranges and resolution at every pixel
(:func:`analyze`; the definitions are in :mod:`hmlvs.paper.design`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from dataclasses import replace as dc_replace
import math
import os
from pathlib import Path
from typing import Any, Optional, Sequence

import numpy as np

from ...models.paper import points_in_camera
from ...models.params import Parameters

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


def positive(name: str, value: Any, unit: str) -> float:
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
        object.__setattr__(self, "f", positive("f", self.f, "mm"))
        object.__setattr__(self, "Su", positive("the horizontal pixel pitch Su", self.Su,
                                                 "mm/px"))
        object.__setattr__(self, "Sv", positive("the vertical pixel pitch Sv", self.Sv,
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
        object.__setattr__(self, "H", positive("H", self.H, "mm"))
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


def point_map(sensor: Sensor, du: float = 0.0, dv: float = 0.0) -> np.ndarray:
    """Camera-frame points (height, width, 3) at pixels (u + du, v + dv); NaN = no stripe."""
    u, v = np.meshgrid(np.arange(sensor.width, dtype=float) + du,
                       np.arange(sensor.height, dtype=float) + dv)
    pixels = np.stack([u.ravel(), v.ravel()], axis=1)
    pts, _ = points_in_camera(sensor.params(), pixels, on_invalid="mask")
    return pts.reshape(sensor.height, sensor.width, 3)


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


def json_value(v: Any) -> Any:
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
            "ranges_mm": {k: json_value(v) for k, v in vars(r).items()},
            "resolution_mm_per_px": {k: json_value(v) for k, v in vars(q).items()},
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

    def markdown(self, errors: Sequence[Any] = (),  # ErrorReport (miscalibration)
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


def analyze_sensor(sensor: Sensor, resolution_limit: float) -> Optional[DesignReport]:
    """The analysis, or None if no pixel sees the laser plane."""
    pts = point_map(sensor)
    usable = np.isfinite(pts).all(axis=2)
    if not usable.any():
        return None
    x, y, z = pts[..., 0], pts[..., 1], pts[..., 2]

    # one-pixel steps centred on each pixel
    step_u = point_map(sensor, du=0.5) - point_map(sensor, du=-0.5)
    step_v = point_map(sensor, dv=0.5) - point_map(sensor, dv=-0.5)
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
    >>> r = hmlvs.paper.design.analyze(H=100.0, theta=np.radians(25))
    >>> round(r.ranges.z, 1), round(r.ranges.x_growth, 1)
    (263.2, 155.6)
    """
    s = sensor if sensor is not None else Sensor.make(f, pixel_pitch, image_size, H, theta, k,
                                                      principal_point)
    limit = positive("resolution_limit", resolution_limit, "mm/px")
    report = analyze_sensor(s, limit)
    if report is None:
        raise _no_stripe_error(s)
    return report
