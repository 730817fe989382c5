"""The study's result (:class:`StudyResult`), its Markdown table and its figures (Table 1,
Fig. 8)."""

from __future__ import annotations

from dataclasses import dataclass, field
import io
import math
import os
from pathlib import Path
from typing import Any, Optional

import numpy as np

from ..._io import atomic_folder, atomic_write
from .results import (
    LABELS,
    METHODS,
    STATS,
    VALLEY_PARAMS,
    HeldOut,
    MethodRuns,
    StudySettings,
    output_folder,
    paper_value,
)


@dataclass
class StudyResult:
    """The outcome of :func:`study`.

    Attributes
    ----------
    settings : what was run
    runs : per (method, s) the runs of that method (:class:`MethodRuns`)
    held_out : Fig. 8 data per s (:class:`HeldOut`, best and worst PSO run)
    seconds : wall-clock time of the whole study (s)
    cpu_seconds : CPU time of this process over the study, all threads (s)
    """

    settings: StudySettings
    runs: dict[tuple[str, float], MethodRuns]
    held_out: list[HeldOut]
    seconds: float
    cpu_seconds: float
    files: list[Path] = field(default_factory=list)

    def get(self, method: str, s: float) -> MethodRuns:
        """The runs of ``method`` at spread ``s``."""
        for (m, ss), r in self.runs.items():
            if m == method and math.isclose(ss, s, rel_tol=1e-9):
                return r
        raise ValueError(f"no runs of {method!r} at s = {s:g}; methods: {', '.join(METHODS)}; "
                         f"s values: {', '.join(f'{x:g}' for x in self.settings.s_values)}")

    def method_seconds(self, method: str) -> float:
        return float(sum(self.get(method, s).seconds for s in self.settings.s_values))

    def table(self) -> str:
        """Markdown: Table 1's layout (ours with the paper's in parentheses), held-out RMS,
        success rates and run times, and the Fig. 8 numbers."""
        return _markdown(self)

    def __str__(self) -> str:
        return self.table()

    def to_dict(self, include_runs: bool = False) -> dict[str, Any]:
        st = self.settings
        return {
            "settings": {k: (list(v) if isinstance(v, tuple) else v)
                         for k, v in st.__dict__.items()},
            "seconds": self.seconds, "cpu_seconds": self.cpu_seconds,
            "methods": [self.get(m, s).to_dict(include_runs) for m in METHODS
                        for s in st.s_values],
            "method_seconds": {m: self.method_seconds(m) for m in METHODS},
            "held_out": [h.to_dict() for h in self.held_out],
            "files": [str(p) for p in self.files],
        }

    def plot(self, out_dir: str | os.PathLike) -> list[Path]:
        """Write ``study_table1.png`` (RMS of every run per method and s, log scale, with the
        paper's best and worst) and ``study_fig8.png`` (held-out error per point of the best
        and worst PSO run per s) into ``out_dir``; returns the files (written atomically)."""
        out = output_folder(out_dir)
        return [_plot_table1(self, out / "study_table1.png"),
                _plot_fig8(self, out / "study_fig8.png")]

    def write(self, out_dir: str | os.PathLike) -> list[Path]:
        """Write ``study.md`` (:meth:`table`) and the plots (:meth:`plot`) into ``out_dir``."""
        out = output_folder(out_dir)
        # all three files or none (a run stopped while writing leaves the folder as it was)
        with atomic_folder(out, last=("study.md",)) as tmp:
            files = self.plot(tmp)
            with atomic_write(tmp / "study.md") as fh:
                fh.write(self.table())
        self.files = [out / "study.md", *(out / f.name for f in files)]
        return self.files


def _fmt(v: Optional[float]) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "–"
    if math.isinf(v):
        return "inf"
    if v == 0:
        return "0"
    if 1e-2 <= abs(v) < 1e4:
        return f"{v:.3g}"
    return f"{v:.2e}"


def _fmt_paper(v: Optional[float]) -> str:
    return "" if v is None else f" ({_fmt(v)})"


def _s_header(st: StudySettings) -> tuple[str, str]:
    head = "| method | RMS (mm) | " + " | ".join(f"s = {s:g}" for s in st.s_values) + " |"
    sep = "|---|---|" + "---:|" * len(st.s_values)
    return head, sep


def _method_label(r: StudyResult, m: str) -> str:
    st = r.settings
    n = {"random": f"1 run, {st.evaluations:,} evaluations", "lm-paper": f"{st.runs_lm} runs",
         "lm": f"{st.runs_lm} runs", "pso": f"{st.runs_pso} runs",
         "pso+lm": f"{st.runs_pso} runs"}[m]
    return f"{LABELS[m]}, {n}"


def _valley_values(params: np.ndarray, name: str) -> np.ndarray:
    from ...models.params import param_index

    if name == "omega + varphi":
        return params[:, param_index("omega")] + params[:, param_index("varphi")]
    if name == "f / Su":
        return params[:, param_index("f")] / params[:, param_index("Su")]
    return params[:, param_index(name)]


def _valley_lines(r: StudyResult) -> list[str]:
    """Parameter ranges over modern LM's successful runs at the largest s."""
    s = max(r.settings.s_values)
    lm = r.get("lm", s)
    ok = lm.test_rms < lm.threshold
    if ok.sum() < 2:
        return []
    from ...models.params import Parameters

    truth = Parameters.nominal().to_array()[None, :]  # the study simulates at the nominal
    lines = ["", f"## Same RMS, different parameters: modern LM at s = {s:g}", "",
             f"The {int(ok.sum())} successful modern-LM runs at s = {s:g} all fit to a held-out "
             f"RMS of at most {_fmt(float(lm.test_rms[ok].max()))} mm, yet their parameters "
             "differ: the data fix only some combinations of the 14 (docs/model.md, \"What the "
             "data can and cannot determine\").", "",
             "| parameter | smallest | largest | true |", "|---|---:|---:|---:|"]
    for name, unit in VALLEY_PARAMS:
        v = _valley_values(lm.params[ok], name)
        t = float(_valley_values(truth, name)[0])
        lines.append(f"| {name} ({unit}) | {v.min():.6g} | {v.max():.6g} | {t:.6g} |")
    return lines


def _markdown(r: StudyResult) -> str:
    st = r.settings
    head, sep = _s_header(st)
    thr = _fmt(st.threshold)
    lines = [
        "# Simulation study: paper Table 1 and Fig. 8",
        "",
        f"Written by `hmlvs study{' --quick' if st.quick else ''}`: {st.describe()}.",
        f"Wall time {r.seconds:.1f} s, CPU time {r.cpu_seconds:.1f} s (all threads).",
        "",
        "## Table 1: fit RMS over the fitting points, ours (paper)",
        "",
        "RMS of ||E_i|| (mm) over the 50 fitting points per run; in parentheses the paper's "
        "Table 1 entry where it has one.",
        "",
        head, sep,
    ]
    for m in METHODS:
        stats = ("best",) if m == "random" else STATS
        for i, stat in enumerate(stats):
            label = _method_label(r, m) if i == 0 else ""
            cells = [_fmt(r.get(m, s).fit.get(stat)) + _fmt_paper(paper_value(m, stat, s))
                     for s in st.s_values]
            lines.append(f"| {label} | {stat} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "## Held-out RMS over the 50 test points",
        "",
        head, sep,
    ]
    for m in METHODS:
        stats = ("best",) if m == "random" else ("best", "worst", "median", "mean", "std")
        for i, stat in enumerate(stats):
            label = _method_label(r, m) if i == 0 else ""
            cells = [_fmt(r.get(m, s).test.get(stat)) for s in st.s_values]
            lines.append(f"| {label} | {stat} | " + " | ".join(cells) + " |")
    lines += [
        "",
        f"## Success rate (held-out RMS < {thr} mm) and run time",
        "",
        "| method | | " + " | ".join(f"s = {s:g}" for s in st.s_values) + " | total |",
        "|---|---|" + "---:|" * (len(st.s_values) + 1),
    ]
    for m in METHODS:
        rr = [r.get(m, s) for s in st.s_values]
        succ = sum(x.successes for x in rr)
        n = sum(x.runs for x in rr)
        lines.append(f"| {_method_label(r, m)} | successes | "
                     + " | ".join(f"{x.successes}/{x.runs}" for x in rr)
                     + f" | {succ}/{n} |")
        if m in ("lm", "lm-paper"):
            lines.append(f"| | stopped at {st.lm_max_iterations} iterations | "
                         + " | ".join(str(x.capped) for x in rr)
                         + f" | {sum(x.capped or 0 for x in rr)} |")
        lines.append("| | time (s) | " + " | ".join(f"{x.seconds:.2f}" for x in rr)
                     + f" | {r.method_seconds(m):.1f} |")
    lines += [
        "",
        "## Fig. 8: held-out errors of the best and the worst PSO run",
        "",
        "The paper's Fig. 8 evaluates the PSO solutions with the best and the worst fitness on "
        "the 50 held-out points. SSE: sum of squared errors (mm^2).",
        "",
        "| s | best run: fit RMS | held-out RMS | held-out SSE | worst run: fit RMS "
        "| held-out RMS | held-out SSE | max point error (worst run) |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for h in r.held_out:
        lines.append(f"| {h.s:g} | {_fmt(h.best_fit_rms)} | {_fmt(h.best_test_rms)} | "
                     f"{_fmt(h.best_sse)} | {_fmt(h.worst_fit_rms)} | "
                     f"{_fmt(h.worst_test_rms)} | {_fmt(h.worst_sse)} | "
                     f"{_fmt(float(np.max(h.worst_errors)))} |")
    lines += _valley_lines(r)
    lines += [
        "",
        "## Notes",
        "",
        "- Data: noise-free, so the true parameters give RMS 0; no run can do better than 0 "
        "and the differences between methods are optimisation errors only.",
        "- Starts and boxes: Eq. 22, q_i = q_i0 (1 + (rand - 0.5) s); parameters whose nominal "
        "is 0 (k, omega, phi, varphi, ty) are drawn in their Table 2 range scaled by s. RS, "
        "PSO and PSO+LM search this box (PSO+LM's LM is bounded by it). Both LM modes start "
        "from the same candidates and are unbounded, as MINPACK lmdif was: they differ only "
        "in the residual (||E_i|| vs its 3 components), the Jacobian (forward differences vs "
        "exact) and the rotation (Euler angles vs SO(3)). NLSO here is Ceres' LM with the "
        "paper's ingredients and MINPACK's tolerances, not MINPACK itself "
        "(`docs/study/minpack_check.py` runs MINPACK on the same starts).",
        "- All 14 parameters are free for every method, as in the paper. The exact scale gauge "
        "(f, Su, Sv, k) of docs/model.md makes the parameter vector non-unique, but not the RMS: "
        "modern LM's damping handles the null directions.",
        f"- Success: held-out RMS < {thr} mm (13x below the sensor's best resolution, "
        "0.134 mm/px, and 35x below the paper's experimental 0.355 mm).",
        "- Statistics: std is the sample standard deviation (ddof = 1). The paper labels "
        "some Table 1 rows E(q) and others F(q); all are read as RMS (mm) here. Its PSO std at "
        "s = 0.2 (1.13e-3) is inconsistent with its best, worst and mean (it must be at least "
        "~3.8e-3).",
        "- Times: wall clock on a machine that may be shared; the solvers are deterministic "
        "for a seed whatever the thread count.",
        "",
    ]
    if st.quick:
        lines[4:4] = ["", "**Quick run**: fewer runs than the paper; the full study is "
                      "`hmlvs study` (1000 LM runs, 10 PSO runs, 1,000,000 RS evaluations)."]
    return "\n".join(lines)


PLOT_DPI = 90


COLORS = {"random": "C7", "lm-paper": "C3", "pso": "C0", "lm": "C2", "pso+lm": "C1"}


def _save(fig: Any, path: Path) -> Path:
    """Render a figure to PNG in memory (Agg), reduce it to a 128-colour palette (a third of
    the size, for committing the plots), then write it atomically."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from PIL import Image

    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=PLOT_DPI)
    buf.seek(0)
    # method 0: median cut, dither 0: none (integers: the enum names vary across Pillow)
    img = Image.open(buf).convert("RGB").quantize(colors=128, method=0, dither=0)
    small = io.BytesIO()
    img.save(small, format="png", optimize=True)
    with atomic_write(path, "wb") as fh:
        fh.write(small.getvalue())
    return path


def _floor(values: np.ndarray, floor: float) -> np.ndarray:
    v = np.asarray(values, dtype=float)
    return np.where(np.isfinite(v), np.maximum(v, floor), np.nan)


def _plot_table1(r: StudyResult, path: Path) -> Path:
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    st = r.settings
    fig = Figure(figsize=(12, 8.2), layout="constrained")
    axes = fig.subplots(2, 1, sharex=True)
    width = 0.8 / len(METHODS)
    rng = np.random.default_rng(0)  # horizontal jitter only
    floor = 1e-14
    for ax, kind in zip(axes, ("fit", "test")):
        for j, m in enumerate(METHODS):
            for i, s in enumerate(st.s_values):
                mr = r.get(m, s)
                vals = _floor(mr.fit_rms if kind == "fit" else mr.test_rms, floor)
                x = i + (j - (len(METHODS) - 1) / 2) * width
                jit = rng.uniform(-0.35, 0.35, vals.size) * width if vals.size > 1 else 0.0
                ax.plot(x + jit, vals, ".", ms=2.5 if vals.size > 50 else 5, alpha=0.35
                        if vals.size > 50 else 0.8, color=COLORS[m], rasterized=True)
                ax.plot([x - width / 2.2, x + width / 2.2], [np.nanmedian(vals)] * 2, "-",
                        color="k", lw=1.2)
                if kind == "fit":
                    for stat, marker in (("best", "v"), ("worst", "^")):
                        pv = paper_value(m, stat, s)
                        if pv is not None:
                            ax.plot(x, pv, marker, mfc="none", mec=COLORS[m], ms=8, mew=1.5)
        ax.set_yscale("log")
        ax.grid(alpha=0.3, which="major")
        ax.set_ylabel(("fit" if kind == "fit" else "held-out") + " RMS of ||E_i|| (mm)")
    axes[1].axhline(st.threshold, color="k", ls="--", lw=0.8)
    axes[1].text(-0.45, st.threshold * 1.5, f"success threshold {st.threshold:g} mm",
                 ha="left", va="bottom", fontsize=8)
    axes[1].set_xticks(range(len(st.s_values)), [f"s = {s:g}" for s in st.s_values])
    axes[1].set_xlim(-0.5, len(st.s_values) - 0.5)
    handles = [Line2D([], [], ls="none", marker="o", color=COLORS[m], label=_method_label(r, m))
               for m in METHODS]
    handles += [Line2D([], [], color="k", label="median"),
                Line2D([], [], ls="none", marker="v", mfc="none", mec="0.3",
                       label="paper Table 1: best"),
                Line2D([], [], ls="none", marker="^", mfc="none", mec="0.3",
                       label="paper Table 1: worst")]
    fig.legend(handles=handles, fontsize=8, ncol=4, loc="outside lower center")
    axes[0].set_title(f"Table 1: RMS of every run (dots; values below {floor:g} mm drawn at "
                      f"{floor:g}), fitting points (top) and held-out points (bottom)")
    fig.suptitle(f"Simulation study, {'quick' if st.quick else 'full'} run (seed {st.seed}): "
                 "all 14 parameters free, noise-free data")
    return _save(fig, path)


def _plot_fig8(r: StudyResult, path: Path) -> Path:
    from matplotlib.figure import Figure

    n = len(r.held_out)
    panels = n + 1  # one per s, then the held-out RMS against s
    cols = min(panels, 3)
    rows = math.ceil(panels / cols)
    fig = Figure(figsize=(4.4 * cols, 3.4 * rows), layout="constrained")
    axes = np.atleast_1d(fig.subplots(rows, cols)).ravel()
    for ax, h in zip(axes, r.held_out):
        idx = np.arange(1, h.best_errors.size + 1)
        ax.plot(idx, _floor(h.best_errors, 1e-14), "o-", ms=3, lw=0.8, color="C0",
                label=f"best PSO run: held-out RMS {_fmt(h.best_test_rms)}")
        ax.plot(idx, _floor(h.worst_errors, 1e-14), "s-", ms=3, lw=0.8, color="C3",
                label=f"worst PSO run: held-out RMS {_fmt(h.worst_test_rms)}")
        ax.set_yscale("log")
        ax.set_title(f"s = {h.s:g}")
        ax.set_xlabel("held-out point")
        ax.set_ylabel("||E_i|| (mm)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    ax = axes[n]
    s_vals = np.array([h.s for h in r.held_out])
    ax.plot(s_vals, [h.best_test_rms for h in r.held_out], "o-", color="C0",
            label="best PSO run, held-out")
    ax.plot(s_vals, [h.best_fit_rms for h in r.held_out], "o--", color="C0", mfc="none",
            label="best PSO run, fit")
    ax.plot(s_vals, [h.worst_test_rms for h in r.held_out], "s-", color="C3",
            label="worst PSO run, held-out")
    ax.plot(s_vals, [h.worst_fit_rms for h in r.held_out], "s--", color="C3", mfc="none",
            label="worst PSO run, fit")
    ax.plot(s_vals, [_floor(np.array([r.get("pso+lm", s).test.worst]), 1e-14)[0]
                     for s in s_vals], "^-", color="C1", label="worst PSO+LM run, held-out")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("spread s")
    ax.set_ylabel("RMS of ||E_i|| (mm)")
    ax.set_title("RMS against s")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    for extra in axes[panels:]:
        extra.set_visible(False)
    fig.suptitle("Fig. 8: error at each of the 50 held-out points for the PSO solutions with "
                 "the best and the worst fitness")
    return _save(fig, path)
