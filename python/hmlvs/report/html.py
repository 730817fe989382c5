"""A self-contained HTML calibration report (figures embedded as PNG data URIs)."""

from __future__ import annotations

import datetime
import html
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from .._io import atomic_write
from ..data.dataset import Dataset
from ..geometry.transforms import rotation_to_vector
from ..models.paper import points_in_base
from ..models.params import DESCRIPTIONS, NAMES, TABLE2_LOWER, TABLE2_UPPER, UNITS, Parameters
from .page import figures_html, page, png, verdict_html

# The paper's Table 2: nominal values, PSO bounds and its best-fit parameters.
PAPER_TABLE2_BEST = [7.70, 0.0074, 0.0075, 323.8, 238.3, 4.8e-4, 137.3, 0.47, -1.8e-3, -0.05,
                     -6.8e-3, 63.2, -2.3, -46.2]


def _figures(result: Any, ds: Dataset, test: Dataset | None) -> dict[str, str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figs: dict[str, str] = {}
    fig, ax = plt.subplots(figsize=(6, 3.4))
    ax.hist(result.fit_errors, bins=30, alpha=0.75, label="fit points")
    if result.test_errors is not None:
        ax.hist(result.test_errors, bins=30, alpha=0.6, label="held-out points")
    ax.set_xlabel("distance error ||E_i|| (mm)")
    ax.set_ylabel("points")
    ax.set_title("Residual histogram")
    ax.legend()
    figs["hist"] = png(fig)

    fig, ax = plt.subplots(figsize=(7, 3.4))
    ax.plot(np.arange(result.fit_errors.size), result.fit_errors, "o", ms=3, label="fit")
    if result.test_errors is not None:
        ax.plot(result.fit_errors.size + np.arange(result.test_errors.size), result.test_errors,
                "s", ms=3, label="held out")
    ax.set_xlabel("point")
    ax.set_ylabel("||E_i|| (mm)")
    ax.set_title("Per-point distance errors")
    ax.legend()
    figs["points"] = png(fig)

    hist = getattr(result, "extra", {}).get("pso_histories") or (
        [result.history] if result.history.size else [])
    if hist:
        fig, ax = plt.subplots(figsize=(6, 3.4))
        for k, h in enumerate(hist):
            ax.semilogy(np.arange(1, len(h) + 1), h, lw=1, label=f"run {k + 1}" if k < 8 else None)
        ax.set_xlabel("PSO iteration")
        ax.set_ylabel("best fitness F (mm^2)")
        ax.set_title("PSO convergence (paper Fig. 11)")
        if len(hist) <= 8:
            ax.legend(fontsize=7)
        figs["convergence"] = png(fig)

    fig = plt.figure(figsize=(6, 5))
    ax = fig.add_subplot(projection="3d")
    for d, label, mk in ((ds, "fit", "o"), (test, "held out", "s")):
        if d is None or len(d) == 0:
            continue
        meas, ok = points_in_base(result.params, d.pixels, d.poses, on_invalid="mask")
        ax.scatter(*d.points.T, s=14, marker=mk, facecolors="none", edgecolors="k",
                   label=f"reference ({label})")
        ax.scatter(*meas[ok].T, s=5, marker=".", label=f"measured ({label})")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_zlabel("z (mm)")
    ax.set_title("Reference against measured points (base frame)")
    ax.legend(fontsize=7)
    figs["cloud"] = png(fig)
    return figs


# What makes the sensor the paper's: its camera and laser (not the mounting, whose Euler
# angles can leave their bounds at the gimbal lock while the rotation is tiny).
_SENSOR = ("f", "Su", "Sv", "Cu", "Cv", "H", "theta")


def is_paper_sensor(params: Any) -> bool:
    """True when the camera and laser parameters (f, Su, Sv, Cu, Cv, H, theta) lie within the
    paper's Table 2 bounds (the paper's camera: 8 mm lens, 7.4 um pixels, 640 x 480; a
    120-150 mm baseline). Only then are the paper's bounds and best fit worth showing."""
    idx = [NAMES.index(n) for n in _SENSOR]
    q = np.array([getattr(params, n) for n in _SENSOR])
    return bool(np.all(q >= np.asarray(TABLE2_LOWER)[idx] - 1e-12)
                and np.all(q <= np.asarray(TABLE2_UPPER)[idx] + 1e-12))


def _derived(result: Any) -> str:
    """f/Su, f/Sv in pixels, hand_from_camera and its rotation vector, as HTML."""
    from ..models.paper import hand_from_camera

    p = result.params
    t = hand_from_camera(p)
    rv = rotation_to_vector(t[:3, :3])
    mat = "".join("<tr>" + "".join(f"<td>{x:.6g}</td>" for x in row) + "</tr>" for row in t)
    return (f"<table class=\"summary\"><tr><td>f/Su (focal length in pixels, columns)</td>"
            f"<td>{p.f / p.Su:.6g} px</td></tr>"
            f"<tr><td>f/Sv (focal length in pixels, rows)</td><td>{p.f / p.Sv:.6g} px</td></tr>"
            "<tr><td>hand-eye rotation as a rotation vector (axis x angle)</td>"
            f"<td>[{rv[0]:+.6f}, {rv[1]:+.6f}, {rv[2]:+.6f}] rad "
            f"({np.linalg.norm(rv):.6f} rad about its axis)</td></tr></table>"
            "<p>hand_from_camera (4x4, mm; the camera frame in the hand frame; omega, phi, "
            "varphi above are the same rotation as the paper's ZYZ Euler angles):</p>"
            f'<table class="matrix">{mat}</table>')


def _views(image_reports: Any) -> str:
    """One row per image pair: used or rejected, and why."""
    if not image_reports:
        return ""
    rows = []
    for r in image_reports:
        if r.ok:
            status = "used"
            why = f"{r.points} points from {r.corners} corners"
            if r.rejected:
                why += "; candidate points not used: " + "; ".join(
                    f"{k}: {v}" for k, v in r.rejected.items())
        else:
            status, why = "rejected", r.reason
        rows.append(f"<tr><td>{html.escape(str(r.id))}</td><td>{status}</td>"
                    f"<td>{html.escape(why)}</td></tr>")
    used = sum(1 for r in image_reports if r.ok)
    return (f"<h2>Views ({used} of {len(image_reports)} image pairs used)</h2>"
            '<table class="views"><tr><th>view</th><th>status</th><th>why</th></tr>'
            + "".join(rows) + "</table>")


def render_report(result: Any, ds: Dataset, test: Dataset | None = None,
                  truth: Parameters | None = None, title: str = "hmlvs calibration report",
                  std: dict[str, float | None] | None = None, image_reports: Any = None,
                  paper_sensor: bool | None = None, verdict: Any = None) -> str:
    """The report as an HTML string (``verdict``, a
    :class:`hmlvs.diagnostics.verdict.Verdict`, first); ``std`` overrides the result's
    standard deviations (e.g. those stored in a calibration file). "n.d.": not determined
    by the data.

    ``image_reports`` (from :func:`hmlvs.image.paper_session.dataset_from_images`) adds a
    per-view account.
    ``paper_sensor`` shows the paper's Table 2 bounds and best fit beside the result;
    by default only when every parameter lies within those bounds (:func:`is_paper_sensor`).
    """
    figs = _figures(result, ds, test)
    if paper_sensor is None:
        paper_sensor = is_paper_sensor(result.params)
    std = result.parameter_std() if std is None and hasattr(result, "parameter_std") else (
        std or {})
    rows = []
    for i, n in enumerate(NAMES):
        v = getattr(result.params, n)
        s = std.get(n)
        s_txt = "fixed" if n in result.fixed else ("n.d." if s is None or not math.isfinite(s)
                                                    else f"{s:.3g}")
        cells = [n, UNITS[n], html.escape(DESCRIPTIONS[n]), f"{v:.6g}", s_txt]
        if paper_sensor:
            cells += [f"{TABLE2_LOWER[i]:.4g}", f"{TABLE2_UPPER[i]:.4g}",
                      f"{PAPER_TABLE2_BEST[i]:.4g}"]
        if truth is not None:
            cells.append(f"{getattr(truth, n):.6g}")
        rows.append("<tr>" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
    truth_head = "<th>true</th>" if truth is not None else ""
    warn = list(getattr(result, "warnings", []))
    notes = list(getattr(result, "notes", []))
    items = "".join(f'<li class="warn">{html.escape(w)}</li>' for w in warn) + "".join(
        f"<li>{html.escape(n)}</li>" for n in notes)
    test_txt = ("-" if result.test_rms is None else
                f"{result.test_rms:.4g} mm over {result.test_errors.size} points")
    fit_txt = f"{result.fit_rms:.4g} mm over {result.fit_errors.size} points"
    evaluated = result.threads == 0 or result.iterations == 0
    run_txt = ("none: evaluation of a stored calibration on these data (no solve)" if evaluated
               else f"{result.iterations}, {result.seconds:.3f} s on {result.threads} threads "
               f"(seed {result.seed})")
    paper_head = ("<th>lower bound</th><th>upper bound</th><th>paper best fit</th>"
                  if paper_sensor else "")
    paper_note = ("" if paper_sensor else "<p>The paper's Table 2 bounds and best fit are not "
                  "shown: these parameters are not those of the paper's sensor.</p>")
    captions = {"hist": "Residual histogram", "points": "Per-point distance errors",
                "convergence": "PSO convergence (paper Fig. 11)",
                "cloud": "Reference against measured points"}
    img = figures_html(figs, captions)
    now = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
    stopped = getattr(result, "termination_message", "") or str(result.termination)
    return page(title, f"""<h1>{html.escape(title)}</h1>
{verdict_html(verdict)}
<table class="summary">
<tr><td>method</td><td>{html.escape(result.method)}: {html.escape(stopped)}</td></tr>
<tr><td>fit RMS of ||E_i||</td><td>{fit_txt}</td></tr>
<tr><td>held-out RMS</td><td>{test_txt}</td></tr>
<tr><td>{"solve" if evaluated else "iterations, time"}</td><td>{run_txt}</td></tr>
<tr><td>written</td><td>{now}</td></tr>
</table>
<h2>Warnings and notes</h2>
<ul>{items or "<li>none</li>"}</ul>
<h2>Parameters (layout of the paper's Table 2)</h2>
{paper_note}
<table><tr><th>parameter</th><th>unit</th><th>meaning</th><th>identified</th><th>std</th>
{paper_head}{truth_head}</tr>
{"".join(rows)}</table>
<h2>Derived: pixels and the hand-eye transform</h2>
{_derived(result)}
{_views(image_reports)}
<h2>Figures</h2>
{img}
""")


def write_report(result: Any, ds: Dataset, path: str | os.PathLike, test: Dataset | None = None,
                 truth: Parameters | None = None,
                 std: dict[str, float | None] | None = None, image_reports: Any = None,
                 paper_sensor: bool | None = None, verdict: Any = None) -> Path:
    """Write the report atomically; returns its path. See :func:`render_report`."""
    path = Path(path)
    if path.suffix not in (".html", ".htm"):
        raise ValueError(f"{path}: the report is an .html file")
    text = render_report(result, ds, test, truth, std=std, image_reports=image_reports,
                         paper_sensor=paper_sensor, verdict=verdict)
    with atomic_write(path) as fh:
        fh.write(text)
    return path
