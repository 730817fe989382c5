"""The simulation study (paper section 4): the quick study's qualitative findings, in numbers;
its files; determinism; progress and Ctrl-C; the ``hmlvs study`` command; bad input."""

import json

import hmlvs
from hmlvs.cli import app
from hmlvs.paper.study import METHODS, PAPER_S, StudyResult, paper_value
import numpy as np
import pytest
from typer.testing import CliRunner

pytestmark = pytest.mark.slow  # the module's shared sessions take long to make

# Tiny settings for the tests that do not check the findings (one s, a few runs).
TINY = {"s_values": (0.01,), "runs_lm": 4, "runs_pso": 2, "evaluations": 10_000,
        "progress": False}


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    """The quick study (30 LM starts, 5 PSO runs, 200,000 RS evaluations per s), run once."""
    out = tmp_path_factory.mktemp("study")
    return hmlvs.paper.study.study(quick=True, progress=False, out_dir=out), out


def test_quick_settings(quick):
    r, _ = quick
    assert isinstance(r, StudyResult)
    st = r.settings
    assert st.s_values == PAPER_S and st.quick
    assert (st.runs_lm, st.runs_pso, st.evaluations) == (30, 5, 200_000)
    assert (st.fit_points, st.test_points, st.lm_max_iterations) == (50, 50, 4200)
    for m in METHODS:
        for s in PAPER_S:
            runs = r.get(m, s)
            expected = {"random": 1, "lm-paper": 30, "lm": 30, "pso": 5, "pso+lm": 5}[m]
            assert runs.runs == expected and runs.test_rms.shape == (expected,)
            assert runs.params.shape == (expected, 14)


def test_modern_methods_succeed_in_every_run(quick):
    # Noise-free data: the true parameters give 0. Modern LM (from the same starts as the
    # paper-mode LM) and PSO+LM reach machine precision (~1e-13 mm) in every run and at every
    # s; 1e-9 mm leaves four orders of magnitude of margin and is far below the 0.01 mm
    # success threshold.
    r, _ = quick
    for s in PAPER_S:
        for m in ("lm", "pso+lm"):
            runs = r.get(m, s)
            assert runs.success_rate == 1.0, (m, s)
            assert runs.test_rms.max() < 1e-9, (m, s, runs.test_rms.max())
            assert runs.fit_rms.max() < 1e-9, (m, s, runs.fit_rms.max())
    assert r.get("lm", 0.2).capped == 0
    assert r.get("lm", 0.2).iterations.max() < 50  # converges in a handful of iterations


def test_paper_mode_lm_fails_in_some_runs(quick):
    r, _ = quick
    paper = r.get("lm-paper", 0.2)
    # From s = 0.2 (30 starts): 11 failures, 11 runs stopped at the 4200-iteration limit.
    assert paper.successes <= 25 and paper.successes < paper.runs
    assert paper.capped >= 5
    assert paper.test.worst > 0.1  # mm, ten times the threshold
    # ... and more failures as the starts spread: none or one at s <= 0.001
    fails = [r.get("lm-paper", s).runs - r.get("lm-paper", s).successes for s in PAPER_S]
    assert fails[0] <= 1 and fails[-1] >= 5, fails
    # Even its best run stays far from machine precision: the scalar residual ||E_i|| is not
    # differentiable at 0, so forward-difference LM stalls near the solution.
    assert all(r.get("lm-paper", s).fit.best > 1e-6 for s in PAPER_S)


def test_pso_beats_paper_lm_and_random_search(quick):
    r, _ = quick
    pso, paper = r.get("pso", 0.2), r.get("lm-paper", 0.2)
    assert pso.fit.median < paper.fit.median, (pso.fit.median, paper.fit.median)
    assert pso.test.worst < paper.test.worst
    for s in PAPER_S:
        rs = r.get("random", s).fit.best
        assert rs > r.get("pso", s).fit.worst, s  # RS's only run is worse than PSO's worst
    assert r.get("random", 0.2).fit.best > 0.5  # mm: 200,000 random points in 14-D find little


def test_pso_accuracy_degrades_with_the_spread(quick):
    # The paper: "the best fitness value slightly increased as the parameter bounds increased".
    # PSO's final precision scales with its search box (velocity limit 0.1 of each range).
    # Not strictly monotone from one s to the next (the full study's best at s = 0.2 is below
    # its best at s = 0.1), so compare the small spreads with the large ones.
    r, _ = quick
    mean = [r.get("pso", s).fit.mean for s in PAPER_S]
    assert min(mean[3:]) > 5 * max(mean[:3]), mean
    assert r.get("pso", 0.2).fit.best > 100 * r.get("pso", 1e-4).fit.best


def test_fig8_held_out_errors_match_fit(quick):
    # The paper's Fig. 8: the held-out errors of the best and worst PSO solutions are no
    # different in kind from the fit errors (our ratios: 0.9 to 1.2).
    r, _ = quick
    assert [h.s for h in r.held_out] == list(PAPER_S)
    for h in r.held_out:
        pso = r.get("pso", h.s)
        assert h.best_fit_rms == pso.fit.best and h.worst_fit_rms == pso.fit.worst
        assert h.best_errors.shape == h.worst_errors.shape == (50,)
        assert 0.5 < h.best_test_rms / h.best_fit_rms < 2
        assert 0.5 < h.worst_test_rms / h.worst_fit_rms < 2
        assert h.worst_sse == pytest.approx(50 * h.worst_test_rms**2)


def test_files_written(quick):
    r, out = quick
    names = sorted(p.name for p in out.iterdir())
    assert names == ["study.md", "study_fig8.png", "study_table1.png"]
    assert [p.name for p in r.files] == ["study.md", "study_table1.png", "study_fig8.png"]
    md = (out / "study.md").read_text()
    assert md == r.table()
    assert "| method | RMS (mm) | s = 0.0001 | s = 0.001 | s = 0.01 | s = 0.1 | s = 0.2 |" in md
    assert "(2.55e-03)" in md and "(1.11e+03)" in md  # the paper's PSO best, NLSO worst (s=0.2)
    assert "**Quick run**" in md
    pso_row = next(line for line in md.splitlines() if line.startswith("| PSO, 5 runs | best"))
    assert pso_row.count("(") == 5  # a paper value next to each of ours
    total = 0
    for name in ("study_table1.png", "study_fig8.png"):
        data = (out / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000
        total += len(data)
    assert total < 300_000  # small enough to commit


def test_paper_values():
    assert paper_value("pso", "best", 0.2) == 2.55e-3
    assert paper_value("lm-paper", "worst", 0.01) == 1.26e3
    assert paper_value("random", "best", 1e-4) == 1.25e-2
    assert paper_value("lm", "best", 0.2) is None  # modern LM is ours
    assert paper_value("pso", "best", 0.05) is None  # not a paper s


def test_deterministic_across_thread_counts_and_s_subsets():
    one = hmlvs.paper.study.study(threads=1, **TINY)
    two = hmlvs.paper.study.study(threads=2, **TINY)
    # 0.01 runs the same as alone
    both = hmlvs.paper.study.study(**{**TINY, "s_values": (0.2, 0.01)})
    for m in METHODS:
        np.testing.assert_array_equal(one.get(m, 0.01).fit_rms, two.get(m, 0.01).fit_rms)
        np.testing.assert_array_equal(one.get(m, 0.01).params, two.get(m, 0.01).params)
        np.testing.assert_array_equal(one.get(m, 0.01).params, both.get(m, 0.01).params)
    other = hmlvs.paper.study.study(seed=1, **TINY)
    assert not np.array_equal(other.get("pso", 0.01).params, one.get("pso", 0.01).params)


def test_progress_callable_and_interrupt():
    seen = []

    def progress(method, s, done, total):
        seen.append((method, s, done, total))
        if method == "lm-paper" and done >= 2:
            raise KeyboardInterrupt  # as Ctrl-C does, polled from C++ during the solve

    with pytest.raises(KeyboardInterrupt):
        hmlvs.paper.study.study(s_values=(0.2,), runs_lm=200, runs_pso=2, evaluations=10_000,
                    progress=progress)
    methods = list(dict.fromkeys(m for m, *_ in seen))
    assert methods == ["random", "lm-paper"]
    assert seen[-1][0] == "lm-paper" and seen[-1][2] >= 2 and seen[-1][3] == 200
    assert any(m == "random" and total == 10_000 for m, _, _, total in seen)


def test_progress_bar_leaves_results_alone_and_closes():
    """The rich bar changes nothing in the results, and it is stopped when the study ends:
    a bar left running makes the next one fail ("Only one live display may be active")."""
    quiet = hmlvs.paper.study.study(**TINY)
    for _ in range(2):
        r = hmlvs.paper.study.study(**{**TINY, "progress": True})
        for m in ("random", "lm-paper", "pso"):
            a, b = r.get(m, 0.01), quiet.get(m, 0.01)
            np.testing.assert_array_equal(a.fit_rms, b.fit_rms)


def test_study_does_not_warn_about_the_parameters_it_frees_on_purpose():
    """All 14 parameters are free in the study (the paper's set-up, stated in its Notes): the
    flat-direction warnings of each solve would only bury the terminal."""
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        hmlvs.paper.study.study(**TINY)
    assert not [w for w in caught if issubclass(w.category, hmlvs.HmlvsDataWarning)]


def test_progress_bar_counts_runs_of_the_whole_study_with_an_eta(monkeypatch):
    """The overall bar counts runs (each step's share of its runs, whatever unit the step
    reports in: runs, PSO generations or evaluations) and both bars show an ETA."""
    from hmlvs.paper.study import run as study_module

    bars = []
    real = study_module._Reporter

    class Spy(real):
        def __init__(self, *a, **k):
            super().__init__(*a, **k)
            bars.append(self)

        def update(self, done, total, _best=0.0):
            ok = super().update(done, total, _best)
            task = self.bar.tasks[self.overall]
            assert self.runs_before <= task.completed <= self.runs_before + self.runs
            return ok

    monkeypatch.setattr(study_module, "_Reporter", Spy)
    hmlvs.paper.study.study(**{**TINY, "progress": True})
    (rep,) = bars
    task = rep.bar.tasks[rep.overall]
    # TINY: per s, 2 x runs_lm + 2 x runs_pso + 1 random-search run
    per_s = 2 * TINY["runs_lm"] + 2 * TINY["runs_pso"] + 1
    assert task.total == per_s * len(TINY["s_values"]) == task.completed
    names = [type(c).__name__ for c in rep.bar.columns]
    assert "TimeRemainingColumn" in names and "MofNCompleteColumn" in names


@pytest.mark.parametrize(
    "kwargs, match",
    [({"s_values": ()}, "s_values is empty"),
     ({"s_values": (0.0,)}, r"every spread s must lie in \(0, 1\], got 0"),
     ({"s_values": (0.1, 2.0)}, r"every spread s must lie in \(0, 1\], got 2"),
     ({"s_values": (0.1, 0.1)}, "s_values has repeated values: 0.1, 0.1"),
     ({"s_values": ("big",)}, "s_values must be numbers"),
     ({"runs_lm": 0}, "runs_lm must be an integer >= 1, got 0"),
     ({"runs_pso": 2.5}, "runs_pso must be an integer >= 1, got 2.5"),
     ({"evaluations": -1}, "evaluations must be an integer >= 1"),
     ({"threads": 0}, "threads must be an integer >= 1, got 0"),
     ({"seed": -1}, "seed must be an integer >= 0"),
     ({"progress": "yes"}, "progress must be True, False, None or a callable")],
)
def test_bad_input(kwargs, match):
    with pytest.raises(ValueError, match=match):
        hmlvs.paper.study.study(**{**TINY, **kwargs})


def test_out_dir_is_a_file(tmp_path):
    f = tmp_path / "f"
    f.write_text("x")
    with pytest.raises(ValueError, match="exists and is not a folder"):
        hmlvs.paper.study.study(out_dir=f, **TINY)


def test_get_unknown(quick):
    r, _ = quick
    with pytest.raises(ValueError, match="no runs of 'newton' at s = 0.2"):
        r.get("newton", 0.2)
    with pytest.raises(ValueError, match="no runs of 'pso' at s = 0.3"):
        r.get("pso", 0.3)


# ------------------------------------------------------------------------------------------
# hmlvs study

runner = CliRunner()
CLI_TINY = ["study", "--s", "0.01", "--runs-lm", "4", "--runs-pso", "2", "--evaluations",
            "10000", "--no-progress"]


def test_cli_json():
    res = runner.invoke(app, [*CLI_TINY, "--json"])
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    assert d["settings"]["s_values"] == [0.01] and d["settings"]["runs_lm"] == 4
    rows = {m["method"]: m for m in d["methods"]}
    assert set(rows) == set(METHODS)
    assert rows["lm"]["runs"] == 4 and rows["lm"]["successes"] == 4
    assert rows["lm"]["fit_rms"]["worst"] < 1e-9
    assert rows["pso"]["runs"] == 2 and len(d["held_out"]) == 1
    assert len(d["held_out"][0]["best_errors"]) == 50
    assert d["files"] == []


def test_cli_out_writes_table_and_plots(tmp_path):
    out = tmp_path / "s"
    res = runner.invoke(app, [*CLI_TINY, "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in out.iterdir()) == ["study.md", "study_fig8.png",
                                                     "study_table1.png"]
    assert "| PSO+LM, 2 runs | best |" in res.stdout
    assert "written to" in res.stdout


@pytest.mark.parametrize(
    "args, match",
    [(["--s", "0"], "error: every spread s must lie in (0, 1], got 0"),
     (["--runs-lm", "0"], "error: runs_lm must be an integer >= 1, got 0"),
     (["--threads", "0"], "error: threads must be an integer >= 1, got 0")],
)
def test_cli_bad_input_exits_2_with_one_line(args, match):
    res = runner.invoke(app, ["study", *args])
    assert res.exit_code == 2
    assert res.stdout == ""
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(match)
