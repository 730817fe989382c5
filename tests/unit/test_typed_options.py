"""Typed options and results: bad option values give a sentence naming the option (not a
pybind11 TypeError), unknown names list the valid ones, and a result's termination and
per-stage results agree with what the solve did."""

import math

import hmlvs
from hmlvs import LmOptions, PsoOptions, RandomSearchOptions
from hmlvs.calibration.result import Termination
import numpy as np
import pytest

BAD_COUNTS = ["50", 50.5, math.nan, math.inf, -1, 2**40, None, True]
BAD_REALS = ["0.9", math.nan, math.inf, -math.inf, -1, None]


@pytest.mark.parametrize("bad", BAD_COUNTS)
@pytest.mark.parametrize("cls, prefix, name", [
    (PsoOptions, "pso", "swarm_size"), (PsoOptions, "pso", "iterations"),
    (PsoOptions, "pso", "progress_every"), (RandomSearchOptions, "random", "evaluations")])
def test_bad_counts_name_the_option(cls, prefix, name, bad):
    with pytest.raises(ValueError, match=rf"^{prefix}\.{name} must be "):
        cls(**{name: bad})


@pytest.mark.parametrize("bad", BAD_REALS)
@pytest.mark.parametrize("cls, prefix, name", [
    (PsoOptions, "pso", "vmax"), (PsoOptions, "pso", "c1"), (PsoOptions, "pso", "w_max"),
    (PsoOptions, "pso", "target_fitness"), (LmOptions, "lm", "loss_scale")])
def test_bad_reals_name_the_option(cls, prefix, name, bad):
    with pytest.raises(ValueError, match=rf"^{prefix}\.{name} must be "):
        cls(**{name: bad})


def test_messages_quote_the_value():
    with pytest.raises(ValueError) as e:
        PsoOptions(swarm_size="x")
    assert str(e.value) == "pso.swarm_size must be a positive integer, got 'x'"
    with pytest.raises(ValueError) as e:
        LmOptions(max_iterations=2**31)
    assert str(e.value) == f"lm.max_iterations must be at most {2**31 - 1}, got {2**31}"
    with pytest.raises(ValueError, match=r"pso.w_min \(0.95\) must not exceed pso.w_max"):
        PsoOptions(w_min=0.95)
    with pytest.raises(ValueError, match="lm.use_bounds must be True or False, got 'no'"):
        LmOptions(use_bounds="no")


def test_defaults_are_todays_and_frozen():
    o = PsoOptions()
    assert (o.swarm_size, o.iterations, o.w_max, o.w_min, o.c1, o.c2, o.vmax,
            o.target_fitness, o.progress_every) == (50, 5000, 0.9, 0.4, 2.0, 2.0, 0.1, 0.0, 100)
    assert LmOptions() == LmOptions(max_iterations=0, loss_scale=1.0, use_bounds=True)
    assert RandomSearchOptions().evaluations == 1_000_000
    assert PsoOptions(swarm_size=np.int64(7)).swarm_size == 7  # numpy integers are counts
    with pytest.raises(AttributeError):
        o.swarm_size = 3


@pytest.fixture(scope="module")
def sim():
    return hmlvs.simulate(seed=0)


@pytest.mark.parametrize("bad", ["50", 50.5, math.nan, math.inf, -1, 2**40])
@pytest.mark.parametrize("kwargs, name", [
    ({"method": "pso"}, "pso.swarm_size"), ({"method": "lm"}, "lm.max_iterations"),
    ({"method": "random"}, "random.evaluations"), ({"method": "pso"}, "calibrate.threads"),
    ({"method": "pso"}, "calibrate.runs"), ({"method": "pso"}, "pso.iterations")])
def test_calibrate_keywords_are_validated(sim, kwargs, name, bad):
    """The existing keyword interface gives the sentence before any solve, never a
    pybind11 TypeError."""
    key = name.split(".")[1]
    with pytest.raises(ValueError, match=rf"^{name} must be "):
        hmlvs.calibrate(sim, **kwargs, **{key: bad})


@pytest.mark.parametrize("bad", ["2", math.nan, math.inf, -math.inf])
@pytest.mark.parametrize("name", ["pso.c1", "pso.c2", "pso.w_max", "pso.w_min", "pso.vmax"])
def test_calibrate_coefficients_are_validated(sim, name, bad):
    """A non-finite PSO coefficient is refused, not run (it returned the initial swarm's best
    with termination max_iterations and no warning)."""
    with pytest.raises(ValueError, match=rf"^{name} must be a finite number"):
        hmlvs.calibrate(sim, method="pso", **{name.split(".")[1]: bad})


@pytest.mark.parametrize("bad, message", [(-1, "an integer >= 0, got -1"),
                                          (2**70, "at most 18446744073709551615"),
                                          ("3", "an integer >= 0, got '3'")])
def test_calibrate_seed_is_validated(sim, bad, message):
    with pytest.raises(ValueError, match=rf"^calibrate.seed must be {message}"):
        hmlvs.calibrate(sim, method="pso", seed=bad)


def test_unknown_option_lists_the_valid_ones(sim):
    with pytest.raises(ValueError) as e:
        hmlvs.calibrate(sim, swram=30)
    msg = str(e.value)
    assert msg.startswith("unknown option 'swram'; valid: ")
    valid = msg.split("valid: ")[1].split(", ")
    assert {"swarm_size", "iterations", "max_iterations", "evaluations", "spread"} <= set(valid)
    assert "swram" not in valid


def test_option_objects_and_keywords(sim):
    """calibrate(pso=PsoOptions(...)) runs those options; a keyword overrides a field."""
    kw = dict(method="pso", threads=1, analyze=False)
    a = hmlvs.calibrate(sim, pso=PsoOptions(swarm_size=10, iterations=30), **kw, judge=False).solve
    b = hmlvs.calibrate(sim, swarm_size=10, iterations=30, **kw, judge=False).solve
    c = hmlvs.calibrate(sim, pso=PsoOptions(swarm_size=10, iterations=999), iterations=30,
                        **kw, judge=False).solve
    assert a.iterations == a.pso.iterations == 30 and a.history.size == 30
    np.testing.assert_array_equal(a.params.to_array(), b.params.to_array())
    np.testing.assert_array_equal(a.params.to_array(), c.params.to_array())
    with pytest.raises(ValueError, match="pso must be a PsoOptions"):
        hmlvs.calibrate(sim, pso={"swarm_size": 10})


def _away(sim):
    t = sim.truth
    return t.replace(f=t.f * 1.02, H=t.H + 3.0, theta=t.theta + 0.02, tz=t.tz + 2.0)


def test_lm_iteration_limit_vs_convergence(sim):
    start = _away(sim)
    tiny = hmlvs.calibrate(sim, method="lm", initial=start, max_iterations=1, analyze=False,
                           judge=False).solve
    assert tiny.termination is Termination.MAX_ITERATIONS
    assert tiny.lm.ceres_termination == "NO_CONVERGENCE" and tiny.iterations == 1
    assert tiny.termination_message.startswith("max_iterations (iteration limit reached): ")
    assert "after 1 LM iterations" in tiny.termination_message
    full = hmlvs.calibrate(sim, method="lm", initial=start, analyze=False, judge=False).solve
    assert full.termination is Termination.CONVERGED
    assert full.lm.ceres_termination == "CONVERGENCE"
    assert 1 < full.iterations < 100
    assert full.termination_message.startswith("converged: ")
    assert f"after {full.iterations} LM iterations" in full.termination_message
    assert full.cost < tiny.cost
    # the old spellings still read: a str enum, and the deprecated extra view
    assert full.termination == "converged" and str(full.termination) == "converged"
    assert full.extra["run_iterations"].tolist() == [full.iterations]


def test_pso_lm_stages_agree_with_the_result(sim):
    r = hmlvs.calibrate(sim, swarm_size=20, iterations=150, runs=2, threads=2, seed=3,
                        analyze=False, judge=False).solve
    assert r.pso is not None and r.lm is not None and r.random is None
    assert r.pso.termination is Termination.MAX_ITERATIONS and r.pso.iterations == 150
    assert r.pso.best_fitness == pytest.approx(r.pso.run_fitness.min())
    assert r.pso.best_fitness == pytest.approx(r.pso.histories[r.pso.best_run][-1])
    assert r.lm.improved
    assert r.iterations == r.pso.iterations + r.lm.iterations
    assert r.cost == pytest.approx(r.lm.final_cost, rel=1e-9)
    assert r.cost <= r.pso.best_fitness
    assert r.run_fitness.min() == pytest.approx(r.cost, rel=1e-9)
    np.testing.assert_allclose(r.run_params[int(np.argmin(r.run_fitness))],
                               r.params.to_array())
    assert r.termination is r.lm.termination is Termination.CONVERGED
    assert r.termination_message.endswith(
        f"after {r.lm.iterations} LM iterations (PSO: 150 generations, best fitness "
        f"{r.pso.best_fitness:.6g}, max_iterations)")


def test_pso_target_fitness_and_random_search_stages(sim):
    r = hmlvs.calibrate(sim, method="pso", swarm_size=20, iterations=4000,
                        target_fitness=1e3, threads=1, analyze=False, judge=False).solve
    assert r.termination is r.pso.termination is Termination.TARGET_FITNESS
    assert r.pso.iterations < 4000 and r.cost <= 1e3 and r.lm is None
    assert r.termination_message.startswith("target_fitness (target fitness reached): PSO: "
                                            f"{r.pso.iterations} generations")
    rs = hmlvs.calibrate(sim, method="random", evaluations=500, threads=1, analyze=False,
                         judge=False).solve
    assert rs.termination is Termination.MAX_EVALUATIONS and rs.pso is None and rs.lm is None
    assert rs.random.evaluations == rs.iterations == 500
    assert rs.random.best_fitness == pytest.approx(rs.cost, rel=1e-9)
    assert "500 candidates evaluated" in rs.termination_message


def test_cancelled_termination(sim):
    r = hmlvs.calibrate(sim, method="pso", swarm_size=10, iterations=1000, progress_every=10,
                        threads=1, progress=lambda done, total, best: done < 50,
                        analyze=False, judge=False).solve
    assert r.termination is Termination.CANCELLED and r.pso.iterations < 1000
    assert r.termination_message.startswith("cancelled (stopped by the progress callback)")


@pytest.mark.parametrize("bad", ["2", math.nan, math.inf, None])
@pytest.mark.parametrize("name", ["min_width", "max_width", "steger_sigma", "dominance"])
def test_stripe_options_name_the_option(name, bad):
    img = np.zeros((10, 10), np.uint8)
    with pytest.raises(ValueError, match=rf"^stripe\.{name} must be a (finite )?number"):
        hmlvs.extract_stripe(img, **{name: bad})
    with pytest.raises(ValueError, match=rf"^stripe\.{name} must be"):
        hmlvs.StripeOptions(**{name: bad})


@pytest.mark.parametrize("bad", ["3", -1, math.nan, math.inf])
def test_stripe_threshold_and_noise(bad):
    for name in ("threshold", "noise"):
        with pytest.raises(ValueError, match=rf"^stripe\.{name} must be "):
            hmlvs.StripeOptions(**{name: bad})
    with pytest.raises(ValueError, match=r"^stripe\.channel must be None or an integer"):
        hmlvs.StripeOptions(channel=1.5)


def test_stripe_options_object_gives_the_keyword_result():
    img = np.zeros((40, 30), np.uint8)
    img[18:23, :] = np.array([30, 120, 200, 120, 30])[:, None]  # horizontal, centre row 20
    img = np.ascontiguousarray(img)
    a = hmlvs.extract_stripe(img, method="gaussian", threshold=10)
    b = hmlvs.extract_stripe(img, options=hmlvs.StripeOptions(method="gaussian", threshold=10))
    np.testing.assert_array_equal(a.centre, b.centre)
    assert (a.status == 0).all()
    np.testing.assert_allclose(a.centre, 20.0, atol=1e-6)
    assert b.method == "gaussian" and b.threshold == 10


def test_threads_beyond_the_cores_are_capped_with_a_note():
    import os
    import warnings

    import hmlvs
    from hmlvs import cli

    sim = hmlvs.simulate.session(cli.mounted_truth(cli.MOUNTING_DEG), num_poses=6, seed=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        many = hmlvs.calibrate(sim.dataset, method="pso", iterations=20, threads=20000,
                               analyze=False, judge=False).solve
        one = hmlvs.calibrate(sim.dataset, method="pso", iterations=20, threads=1,
                              analyze=False, judge=False).solve
    cores = os.cpu_count() or 1
    assert many.threads == cores
    assert any(f"threads capped at {cores}" in n for n in many.notes)
    assert many.params.to_dict() == one.params.to_dict()  # deterministic whatever the threads
