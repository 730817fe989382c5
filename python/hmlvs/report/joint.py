"""The HTML report of a general-model (opencv) joint calibration: the estimates with their
standard deviations, a per-view account (reprojection error, stripe residuals, rejected
images), the corner residuals drawn over the image and the laser residuals' distribution."""

from __future__ import annotations

import datetime
import html
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from .._io import atomic_write
from ..geometry.transforms import rotation_to_vector
from .page import figures_html, page, png, verdict_html  # noqa: F401 (verdict_html re-exported)


def _figures(result: Any) -> dict[str, str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figs: dict[str, str] = {}
    w, h = result.sensor.image_size
    res = result.residuals
    px = np.concatenate([r["corner_pixels"] for r in res.values()]) if res else np.empty((0, 2))
    e = np.concatenate([r["corner_residuals"] for r in res.values()]) if res else px
    fig, ax = plt.subplots(figsize=(7, 7 * h / w))
    if len(px):
        norm = np.hypot(e[:, 0], e[:, 1])
        scale = 0.05 * w / max(float(np.percentile(norm, 99)), 1e-9)
        ax.quiver(px[:, 0], px[:, 1], e[:, 0] * scale, e[:, 1] * scale, norm, angles="xy",
                  scale_units="xy", scale=1, cmap="viridis", width=0.002)
        ax.set_title(f"Corner residuals over the image (arrows x{scale:.0f}; colour: px)")
    ax.set_xlim(0, w)
    ax.set_ylim(h, 0)
    ax.set_aspect("equal")
    ax.set_xlabel("u (px)")
    ax.set_ylabel("v (px)")
    figs["quiver"] = png(fig)

    fig, ax = plt.subplots(figsize=(7, 3.4))
    # views with corners only: a laser-only view has no reprojection error
    ids = [i for i in res if result.per_view[i]["corners"]]
    c_rms = [result.per_view[i]["corner_rms_px"] for i in ids]
    ax.bar(np.arange(len(ids)), c_rms)
    ax.set_xticks(np.arange(len(ids)), ids, rotation=90, fontsize=7)
    ax.set_ylabel("corner RMS (px)")
    ax.set_title("Reprojection error per view")
    figs["per_view"] = png(fig)

    fig, ax = plt.subplots(figsize=(6, 3.4))
    lr = np.concatenate([r["laser_residuals"] for r in res.values()]) if res else np.empty(0)
    lr = lr[np.isfinite(lr)]
    if lr.size:
        ax.hist(lr, bins=50)
    ax.set_xlabel("stripe point distance from the laser plane (mm)")
    ax.set_ylabel("stripe pixels")
    ax.set_title("Laser residuals")
    figs["laser"] = png(fig)
    return figs


def _fmt(v: float | None, digits: str = ".3g") -> str:
    return "-" if v is None or not math.isfinite(v) else format(v, digits)


def _how(result: Any) -> str:
    """What the shown solve estimated: the calibration, or the board's pose alone when the
    calibration is evaluated on a session."""
    if result.evaluated:
        held = "camera, laser plane and hand-eye" if result.mode == "chain" else \
            "camera and laser plane"
        board = "the board's pose in the base" if result.mode == "chain" else \
            "each view's board pose"
        return f"this calibration on this session: its {held} held, {board} estimated"
    return ("robot poses (hand-eye and board pose estimated)" if result.mode == "chain"
            else "no robot poses (camera and laser plane only)")


def render_joint_report(result: Any, image_reports: Any = None, verdict: Any = None,
                        title: str = "hmlvs calibration report (opencv model)") -> str:
    """The report of a :class:`~hmlvs.calibration.joint.JointCalibration` as an HTML string."""
    s = result.sensor
    std = result.std
    rows = "".join(f"<tr><td>{n}</td><td>{'px' if n in ('fx', 'fy', 'cx', 'cy') else '-'}</td>"
                   f"<td>{v:.8g}</td><td>{_fmt(std.get(n))}</td></tr>"
                   for n, v in s.intrinsics().items())
    a, b, c, d = s.laser_plane
    rv = rotation_to_vector(s.hand_from_camera[:3, :3])
    t = s.hand_from_camera[:3, 3]
    chain = result.mode == "chain"
    extr = (f"<tr><td>laser plane (a, b, c, d), camera frame</td><td>({a:.6f}, {b:.6f}, "
            f"{c:.6f}, {d:.4f} mm); distance std {_fmt(std.get('plane_d'))} mm</td></tr>")
    if chain:
        extr += (f"<tr><td>hand_from_camera translation</td><td>({t[0]:.4f}, {t[1]:.4f}, "
                 f"{t[2]:.4f}) mm, std ({_fmt(std.get('hand_tx'))}, {_fmt(std.get('hand_ty'))}, "
                 f"{_fmt(std.get('hand_tz'))})</td></tr>"
                 f"<tr><td>hand_from_camera rotation vector</td><td>({rv[0]:.6f}, {rv[1]:.6f}, "
                 f"{rv[2]:.6f}) rad, {math.degrees(float(np.linalg.norm(rv))):.3f} deg</td></tr>")
        if s.base_from_board is not None:
            bt = s.base_from_board[:3, 3]
            extr += (f"<tr><td>board origin in the base</td><td>({bt[0]:.3f}, {bt[1]:.3f}, "
                     f"{bt[2]:.3f}) mm</td></tr>")
    view_rows = []
    for vid, pv in result.per_view.items():
        used = "used" if pv["corners"] else "used (laser only, no board seen)"
        view_rows.append(f"<tr><td>{html.escape(str(vid))}</td><td>{used}</td>"
                         f"<td>{pv['corners']}</td><td>{_fmt(pv['corner_rms_px'])}</td>"
                         f"<td>{pv['laser_pixels']}</td><td>{_fmt(pv['laser_rms_mm'], '.4f')}"
                         "</td><td></td></tr>")
    for r in image_reports or ():
        if not r.ok:
            view_rows.append(f"<tr><td>{html.escape(str(r.id))}</td><td>rejected</td><td></td>"
                             f"<td></td><td></td><td></td><td>{html.escape(r.reason)}</td></tr>")
    warn = "".join(f'<li class="warn">{html.escape(w)}</li>' for w in result.warnings)
    test_txt = ("-" if result.test_rms_mm is None else
                f"{result.test_rms_mm:.4f} mm RMS from the board plane over "
                f"{result.test_views} held-out views")
    figs = _figures(result)
    captions = {"quiver": "Corner residuals over the image", "per_view": "Reprojection error "
                "per view", "laser": "Laser residuals"}
    now = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
    how = _how(result)
    return page(title, f"""<h1>{html.escape(title)}</h1>
{verdict_html(verdict)}
<table class="summary">
<tr><td>model, mode</td><td>opencv, {html.escape(how)}</td></tr>
<tr><td>{"solve of the board's pose" if result.evaluated else "solve"}</td><td>{
 html.escape(result.termination.lower())} after {result.iterations}
 Levenberg-Marquardt iterations, {result.seconds:.2f} s</td></tr>
<tr><td>corner residuals</td><td>{result.corner_rms_px:.4f} px RMS (noise weight
 {result.corner_sigma_px:.4f} px per axis)</td></tr>
<tr><td>laser residuals</td><td>{result.laser_rms_mm:.4f} mm RMS (noise weight
 {result.laser_sigma_mm:.4f} mm)</td></tr>
<tr><td>dropped as outliers</td><td>{result.dropped['corners']} corners,
 {result.dropped['laser_pixels']} stripe pixels</td></tr>
<tr><td>held-out check</td><td>{test_txt}</td></tr>
<tr><td>determined</td><td>{"all " + str(result.num_unknowns) + " unknowns" if result.determined
 else f"{result.rank} of {result.num_unknowns} unknowns"} (condition number
 {result.condition:.3g})</td></tr>
<tr><td>written</td><td>{now}</td></tr>
</table>
<h2>Warnings</h2><ul>{warn or "<li>none</li>"}</ul>
<h2>Camera (OpenCV conventions)</h2>
<table><tr><th>name</th><th>unit</th><th>value</th><th>std</th></tr>{rows}</table>
<h2>Laser plane and hand-eye</h2>
<table class="summary">{extr}</table>
<h2>Views</h2>
<table class="views"><tr><th>view</th><th>status</th><th>corners</th><th>corner RMS (px)</th>
<th>stripe pixels</th><th>laser RMS (mm)</th><th>why</th></tr>{"".join(view_rows)}</table>
<h2>Figures</h2>
{figures_html(figs, captions)}
""")


def write_joint_report(result: Any, path: str | os.PathLike, image_reports: Any = None,
                       verdict: Any = None) -> Path:
    """Write the report atomically (``verdict``, a
    :class:`hmlvs.diagnostics.verdict.Verdict`, shown first); returns its path."""
    path = Path(path)
    if path.suffix not in (".html", ".htm"):
        raise ValueError(f"{path}: the report is an .html file")
    text = render_joint_report(result, image_reports, verdict)
    with atomic_write(path) as fh:
        fh.write(text)
    return path
