"""The design analysis' figures (PNG)."""

from __future__ import annotations

import io
import math
import os
from pathlib import Path
from typing import Any, Optional, Sequence

import numpy as np

from ..._io import atomic_write
from .miscalibration import ErrorReport, paper_errors
from .sensor import DesignReport, Sensor
from .sweep import SweepResult, sweep


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
