"""`make bench`: the C++ benchmark plus side-by-side comparisons in one run -> bench/RESULTS.md.

Compares, on the same data and machine in the same run:
  * hmlvs' C++ PSO (via the Python binding) against the same PSO vectorised with NumPy,
  * hmlvs' modern LM (Ceres) against scipy.optimize.least_squares (method="lm"),
  * model evaluation of 1e6 points from Python,
and runs the C++ benchmark executable (kernel rate, PSO on 1 and all threads, LM solves), the
stripe extraction benchmark (bench_stripe.py), the joint calibration of the general sensor
against vision-calibration (bench_joint.py; that library is optional) and a tilted sensor's
camera against vision-calibration's Scheimpflug intrinsics (bench_tilt.py).
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
from pathlib import Path
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

import hmlvs  # noqa: E402
from hmlvs._io import atomic_write  # noqa: E402
import numpy_pso  # noqa: E402


def median_time(fn, reps: int) -> tuple[float, object]:
    times, out = [], None
    for _ in range(reps):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times), out


def session_times(reps: int) -> tuple[float, float, bool]:
    """Median seconds of ``hmlvs.simulate.session(num_poses=12)`` with the C++ look-at solve
    and with the NumPy one (the tests' reference), interleaved, and whether both gave the
    same joints."""
    from hmlvs import _core

    sys.path.insert(0, str(ROOT / "tests" / "oracles"))
    from reference_ik import solve_look_at  # the tests' NumPy reference of the solve

    native = _core._solve_look_at
    robot = hmlvs.Robot.scorbot_er7()

    def numpy_solve(_native_robot, hfc, pos, axis, cam_x, start, lo, hi, max_step, iters):
        return solve_look_at(robot, hfc, pos, axis, cam_x, start, lo, hi, max_step, iters)

    times: dict[str, list[float]] = {"c++": [], "numpy": []}
    joints: dict[str, list[np.ndarray]] = {"c++": [], "numpy": []}
    try:
        for seed in range(reps):
            for name, solve in (("c++", native), ("numpy", numpy_solve)):
                _core._solve_look_at = solve
                t = time.perf_counter()
                joints[name].append(hmlvs.simulate.session(num_poses=12, seed=seed).joints)
                times[name].append(time.perf_counter() - t)
    finally:
        _core._solve_look_at = native
    same = all(np.array_equal(a, b) for a, b in zip(joints["c++"], joints["numpy"]))
    return statistics.median(times["c++"]), statistics.median(times["numpy"]), same


def render_times(reps: int) -> tuple[float, float, int, int]:
    """Median seconds of ``hmlvs.simulate.render_session`` (4 poses, 640 x 480, noise and
    speckle) with the C++ board shading and with the NumPy one (the tests' reference),
    interleaved, and how many of how many 8-bit pixels differ between the two."""
    from hmlvs.sim import render as R

    sys.path.insert(0, str(ROOT / "tests" / "oracles"))
    # the tests' NumPy reference of the shading
    from reference_render import board_exposures_of_plane as numpy_shading

    native = R.board_exposures

    options = R.RenderOptions(noise=1.0, speckle=0.1)
    session = hmlvs.simulate.session(num_poses=4, seed=0)
    times: dict[str, list[float]] = {"c++": [], "numpy": []}
    frames: dict[str, list[np.ndarray]] = {}
    try:
        for _ in range(reps):
            for name, shade in (("c++", native), ("numpy", numpy_shading)):
                R.board_exposures = shade
                t = time.perf_counter()
                r = R.render_session(session, options=options)
                times[name].append(time.perf_counter() - t)
                frames[name] = [*r.on, *r.off]
    finally:
        R.board_exposures = native
    differ = sum(int(np.count_nonzero(a != b)) for a, b in zip(frames["c++"], frames["numpy"]))
    pixels = sum(a.size for a in frames["c++"])
    return statistics.median(times["c++"]), statistics.median(times["numpy"]), differ, pixels


def machine() -> str:
    model = "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return (f"{model}, {os.cpu_count()} hardware threads, {platform.system()} "
            f"{platform.release()}, Python {platform.python_version()}, NumPy {np.__version__}")


def build_cpp_bench() -> Path:
    build = ROOT / "build" / "bench"
    # the CMake of the environment running the bench (make installs it into .venv)
    cmake = shutil.which("cmake", path=str(Path(sys.executable).parent)) or "cmake"
    subprocess.run([cmake, "-S", str(ROOT), "-B", str(build), "-DCMAKE_BUILD_TYPE=Release",
                    "-DHMLVS_BUILD_BENCH=ON", "-DHMLVS_BUILD_PYTHON=OFF"], check=True,
                   stdout=subprocess.DEVNULL)
    subprocess.run([cmake, "--build", str(build), "--target", "hmlvs_bench", "-j2"],
                   check=True, stdout=subprocess.DEVNULL)
    return build / "bench" / "hmlvs_bench"


def _study_figures(markdown: str) -> list[str]:
    """The lines of a study.md that hold results: everything but the times."""
    return [ln for ln in markdown.splitlines()
            if not ln.startswith("Wall time") and "| time (s) |" not in ln
            and not ln.startswith("Written by")]


def study_section(threads: int) -> list[str]:
    """The full simulation study (paper Table 1): wall time, and its figures against the
    committed docs/study/study.md, written by the same command."""
    import tempfile

    print("full simulation study (hmlvs study) ...", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        r = hmlvs.paper.study.study(progress=False, threads=threads, out_dir=tmp)
        ours = (Path(tmp) / "study.md").read_text()
    committed = ROOT / "docs" / "study" / "study.md"
    mine, theirs = _study_figures(ours), _study_figures(committed.read_text())
    differing = [a for a, b in zip(mine, theirs) if a != b] + mine[len(theirs):]
    same = not differing and len(mine) == len(theirs)
    per = {m: r.method_seconds(m) for m in ("lm-paper", "lm", "pso", "pso+lm", "random")}
    lines = [
        "## Simulation study (paper Table 1)",
        "",
        f"`hmlvs.paper.study.study()` in full ({r.settings.describe()}): **{r.seconds:.0f} s** "
        "wall time "
        f"(target < 180 s), CPU {r.cpu_seconds:.0f} s. Per method (s): "
        + ", ".join(f"{m} {t:.1f}" for m, t in per.items()) + ".",
        "",
        ("Every figure (tables, success counts, iteration caps; not the times) is identical to "
         "`docs/study/study.md`." if same else
         f"{len(differing)} result lines differ from `docs/study/study.md`; the first: "
         f"`{differing[0] if differing else 'a line count'}`"),
    ]
    return lines


def _pyswarms_row(rows: list, u, v, h, b, args) -> float | None:
    """pyswarms' GlobalBestPSO on the same workload and the same NumPy fitness (swarm 50, 5000
    iterations, c1 = c2 = 2, w from 0.9 to 0.4 as Eq. 20, positions held at the bounds with
    zero velocity). Its velocity clamp takes one interval for all dimensions, so it runs
    without the paper's per-parameter vmax. The time scaled to 5000 iterations, or None when
    pyswarms is not installed (a row says so)."""
    # pyswarms' reporter writes a report.log into the working directory: keep it out of ours
    here = os.getcwd()
    with tempfile.TemporaryDirectory() as tmp:
        os.chdir(tmp)
        try:
            return _pyswarms_timed(rows, u, v, h, b, args)
        finally:
            os.chdir(here)


def _pyswarms_timed(rows: list, u, v, h, b, args) -> float | None:
    try:
        import pyswarms
    except ImportError:
        rows.append(("pyswarms GlobalBestPSO", "not installed", "`pip install pyswarms`"))
        return None
    print(f"pyswarms PSO ({args.numpy_iterations} iterations) ...", flush=True)

    def run():
        np.random.seed(0)  # pyswarms draws from NumPy's global generator
        opt = pyswarms.single.GlobalBestPSO(
            n_particles=50, dimensions=b.lower.size, options={"c1": 2.0, "c2": 2.0, "w": 0.9},
            bounds=(b.lower, b.upper), bh_strategy="nearest", vh_strategy="zero",
            oh_strategy={"w": "lin_variation"})
        return opt.optimize(lambda q: numpy_pso.fitness(q, u, v, h),
                            iters=args.numpy_iterations, verbose=False)

    t, (cost, _) = median_time(run, max(1, min(3, args.reps)))
    t_full = t * 5000 / args.numpy_iterations
    rows.append((f"pyswarms {pyswarms.__version__} GlobalBestPSO, same workload and fitness",
                 f"{t_full * 1e3:.0f} ms", f"best RMS {np.sqrt(2 * cost / len(u)):.3g} mm"
                 + ("" if args.numpy_iterations == 5000 else
                    f" (timed {args.numpy_iterations} iterations, scaled to 5000)")))
    return t_full


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--numpy-iterations", type=int, default=5000,
                    help="iterations of the NumPy PSO (5000 = the paper's workload)")
    ap.add_argument("--out", type=Path, default=HERE / "RESULTS.md")
    ap.add_argument("--no-images", dest="images", action="store_false",
                    help="skip the image-path benchmark (bench_images.py)")
    ap.add_argument("--no-joint", dest="joint", action="store_false",
                    help="skip the joint calibration against vision-calibration (minutes)")
    ap.add_argument("--no-study", dest="study", action="store_false",
                    help="skip the full simulation study (about 3 minutes on 2 cores)")
    args = ap.parse_args()
    rows: list[tuple[str, str, str]] = []
    ratios: list[str] = []

    print("building and running the C++ benchmark ...", flush=True)
    exe = build_cpp_bench()
    cpp = [json.loads(line) for line in subprocess.run(
        [str(exe), str(args.reps)], check=True, capture_output=True, text=True).stdout.splitlines()]
    for r in cpp:
        rows.append((f"C++: {r['name']}", f"{r['value']:.4g} {r['unit']}",
                     f"median of {r['repetitions']}"))

    # Same data for both PSOs: the paper's 50 fitting points, Table 2 bounds.
    sim = hmlvs.simulate(seed=1)
    fit = sim.fit
    b = hmlvs.Bounds.table2()
    h = np.einsum("mji,mj->mi", fit.poses[:, :3, :3], fit.points - fit.poses[:, :3, 3])
    u, v = fit.pixels[:, 0], fit.pixels[:, 1]

    threads = os.cpu_count() or 1
    print("PSO through the Python binding ...", flush=True)
    t_pso_all, r_all = median_time(lambda: hmlvs.calibrate(fit, method="pso", fixed=(),
                                                           threads=threads, analyze=False,
                                                           judge=False),
                                   args.reps)
    t_pso_1, _ = median_time(lambda: hmlvs.calibrate(fit, method="pso", fixed=(), threads=1,
                                                         analyze=False, judge=False),
                             args.reps)
    rows.append((f"hmlvs PSO, paper workload, {threads} threads", f"{t_pso_all * 1e3:.1f} ms",
                 f"best RMS {r_all.fit_rms:.3g} mm"))
    rows.append(("hmlvs PSO, paper workload, 1 thread", f"{t_pso_1 * 1e3:.1f} ms", ""))

    print(f"NumPy PSO ({args.numpy_iterations} iterations) ...", flush=True)
    t_np, (q_np, f_np) = median_time(
        lambda: numpy_pso.pso(u, v, h, b.lower, b.upper, iterations=args.numpy_iterations),
        max(1, min(3, args.reps)))
    t_np_full = t_np * 5000 / args.numpy_iterations
    rows.append(("NumPy PSO (vectorised over the swarm), same workload",
                 f"{t_np_full * 1e3:.0f} ms", f"best RMS {np.sqrt(2 * f_np / len(fit)):.3g} mm"
                 + ("" if args.numpy_iterations == 5000 else
                    f" (timed {args.numpy_iterations} iterations, scaled to 5000)")))
    ratios.append(f"PSO: hmlvs ({threads} threads) is **{t_np_full / t_pso_all:.0f}x** faster "
                  f"than NumPy; on 1 thread {t_np_full / t_pso_1:.0f}x")
    t_ps = _pyswarms_row(rows, u, v, h, b, args)
    if t_ps is not None:
        ratios.append(f"PSO: hmlvs ({threads} threads) is **{t_ps / t_pso_all:.0f}x** faster "
                      f"than pyswarms; on 1 thread {t_ps / t_pso_1:.0f}x")
    cpp_of = {r["name"]: r["value"] for r in cpp}
    cpp_extra = {r["name"]: r for r in cpp}
    cpp_all = cpp_of.get(f"pso_run_{threads}_threads")
    if cpp_all:
        ratios.append(f"PSO in the C++ executable on {threads} threads: {cpp_all:.1f} ms "
                      f"(target < 100 ms; the paper reports about 30 s)")
    for n in sorted({1, threads}):
        pso, bare = cpp_of.get(f"pso_run_{n}_threads"), cpp_of.get(f"bare_loop_{n}_threads")
        paired = cpp_extra.get(f"pso_over_bare_loop_{n}_threads")
        if pso and bare and paired:
            evals = cpp_extra[f"bare_loop_{n}_threads"]["evaluations"]
            ratios.append(f"PSO against the bare loop (the same {evals:,} fitness evaluations "
                          f"on the same {n} thread{'s' if n > 1 else ''}, no swarm update, no "
                          f"synchronisation; median over {paired['repetitions']} interleaved "
                          f"pairs of each run's ratio): **{paired['value']:.2f}x** (pairs "
                          f"{paired['lowest']:.2f}-{paired['highest']:.2f}x; medians {pso:.1f} "
                          f"ms against {bare:.1f} ms; target at most 1.3x)")
    modern, paper = cpp_of.get("lm_modern_solve"), cpp_of.get("lm_paper_solve")
    paper_ref = cpp_of.get("lm_paper_solve_numericdiff")
    if modern:
        ratios.append(f"Modern LM (C++): **{modern:.3f} ms** a solve, 50 points from s = 0.01 "
                      "(target < 0.4 ms)")
    if paper and paper_ref:
        ratios.append(f"Paper-mode LM (C++): {paper:.1f} ms a solve, **{paper_ref / paper:.2f}x** "
                      f"faster than Ceres' NumericDiffCostFunction over the same residual "
                      f"({paper_ref:.1f} ms), which it matches bit for bit")

    print("LM: hmlvs (Ceres) against scipy.optimize.least_squares ...", flush=True)
    from scipy.optimize import least_squares

    starts = hmlvs.calibration.solvers.initial_candidates(sim.truth, 0.01, 20, seed=3, bounds=b)
    lm_opts = {"method": "lm", "fixed": (), "analyze": False,  # time the solve alone
               "judge": False}
    t_lm, _ = median_time(lambda: [hmlvs.calibrate(fit, initial=s, threads=1, **lm_opts)
                                   for s in starts], args.reps)
    t_lm /= len(starts)

    # SciPy's LM has no bounds and may step to parameters with no measurement (f < 0, a ray
    # that misses the plane): those get a large residual so it backs off, as MINPACK expects.
    scipy_fun, scipy_jac = hmlvs.models.paper.least_squares_functions(fit)

    t_sp, sp = median_time(lambda: [least_squares(scipy_fun, s, jac=scipy_jac, method="lm")
                                    for s in starts], args.reps)
    t_sp /= len(starts)
    t_sp_fd, _ = median_time(lambda: [least_squares(scipy_fun, s, method="lm") for s in starts],
                             max(1, min(3, args.reps)))
    t_sp_fd /= len(starts)
    rows.append(("hmlvs modern LM (Ceres, analytic Jacobian), per solve from s = 0.01",
                 f"{t_lm * 1e3:.2f} ms", "through the Python API"))
    rows.append(("scipy least_squares(method='lm'), hmlvs residuals + autodiff Jacobian",
                 f"{t_sp * 1e3:.2f} ms", f"final cost {sp[-1].cost:.2g}"))
    rows.append(("scipy least_squares(method='lm'), finite differences", f"{t_sp_fd * 1e3:.2f} ms",
                 ""))
    ratios.append(f"LM: hmlvs is {t_sp / t_lm:.1f}x faster than SciPy with the same Jacobian and "
                  f"{t_sp_fd / t_lm:.1f}x faster than SciPy with finite differences")

    print("model evaluation, 1e6 points ...", flush=True)
    rng = np.random.default_rng(0)
    m = 1_000_000
    px = rng.uniform([0, 0], [639, 479], (m, 2))
    poses = hmlvs.Robot.scorbot_er7().poses(rng.uniform(-1, 1, (m, 5)))
    t_model, _ = median_time(lambda: hmlvs.models.paper.points_in_base(sim.truth, px, poses),
                             args.reps)
    sys.path.insert(0, str(ROOT / "tests" / "oracles"))
    from reference_model import base_points  # the tests' independent NumPy oracle
    t_model_np, _ = median_time(lambda: base_points(sim.truth.to_array(), px, poses), 2)
    rows.append(("hmlvs.models.paper.points_in_base, 1e6 points (pixels + poses -> base frame)",
                 f"{t_model * 1e3:.0f} ms", "includes pose validation"))
    rows.append(("NumPy oracle of the same model, 1e6 points", f"{t_model_np * 1e3:.0f} ms", ""))
    ratios.append(f"Model: 1e6 points in {t_model * 1e3:.0f} ms from Python "
                  f"({t_model_np / t_model:.1f}x the NumPy oracle)")

    print("session simulation ...", flush=True)
    t_ses, t_ses_np, same = session_times(reps=3)
    rows.append(("hmlvs.simulate.session, 12 poses (look-at IK in C++)", f"{t_ses * 1e3:.0f} ms",
                 "median of 3, interleaved"))
    rows.append(("the same with the NumPy look-at solve", f"{t_ses_np * 1e3:.0f} ms",
                 "the same joints" if same else "OTHER JOINTS"))
    ratios.append(f"Session simulation: the C++ look-at IK makes a 12-pose session "
                  f"{t_ses_np / t_ses:.0f}x faster than the NumPy solve "
                  f"({t_ses * 1e3:.0f} against {t_ses_np * 1e3:.0f} ms), "
                  + ("with the same joints to the last bit" if same else "BUT OTHER JOINTS"))

    print("rendering ...", flush=True)
    t_ren, t_ren_np, differ, pixels = render_times(reps=3)
    rows.append(("hmlvs.simulate.render_session, 4 poses of 640 x 480 (shading in C++)",
                 f"{t_ren * 1e3:.0f} ms", "median of 3, interleaved; noise, speckle, blur"))
    rows.append(("the same with the NumPy shading", f"{t_ren_np * 1e3:.0f} ms",
                 f"{differ} of {pixels} pixels differ"))
    ratios.append(f"Rendering: the C++ board shading renders a 4-pose session "
                  f"{t_ren_np / t_ren:.1f}x faster than the NumPy shading "
                  f"({t_ren * 1e3:.0f} against {t_ren_np * 1e3:.0f} ms), with {differ} of "
                  f"{pixels} pixels different")

    print("import time ...", flush=True)

    def import_seconds(module: str) -> float:
        code = (f"import time; t = time.perf_counter(); import {module}; "
                "print(time.perf_counter() - t)")
        return statistics.median(
            float(subprocess.run([sys.executable, "-c", code], check=True, capture_output=True,
                                 text=True).stdout) for _ in range(7))

    t_imp, t_imp_np = import_seconds("hmlvs"), import_seconds("numpy")
    rows.append(("import hmlvs (fresh process)", f"{t_imp * 1e3:.0f} ms", "median of 7"))
    rows.append(("import numpy (fresh process)", f"{t_imp_np * 1e3:.0f} ms", "median of 7"))
    ratios.append(f"`import hmlvs`: **{t_imp * 1e3:.0f} ms** (target < 300 ms), "
                  f"{t_imp / t_imp_np:.1f}x `import numpy` ({t_imp_np * 1e3:.0f} ms)")

    study_lines: list[str] = []
    if args.study:
        study_lines = study_section(threads)

    extra = HERE / "bench_stripe.py"
    stripe_lines: list[str] = []
    if extra.exists():
        print("stripe extraction ...", flush=True)
        out = subprocess.run([sys.executable, str(extra), "--markdown"], check=True,
                             capture_output=True, text=True).stdout
        stripe_lines = [out.strip()]

    def section(script: str, wanted: bool, what: str, reps: int) -> list[str]:
        """The markdown section a benchmark script prints (stderr goes to the terminal)."""
        path = HERE / script
        if not (path.exists() and wanted):
            return []
        print(f"{what} ...", flush=True)
        out = subprocess.run([sys.executable, str(path), "--reps", str(reps)], check=True,
                             stdout=subprocess.PIPE, text=True).stdout
        return [out.strip()]

    joint_lines = section("bench_joint.py", args.joint,
                          "joint calibration against vision-calibration", min(args.reps, 3))
    tilt_lines = section("bench_tilt.py", args.joint,
                         "tilted sensor's camera against vision-calibration", 1)
    image_lines = section("bench_images.py", args.images,
                          "image path: stripes, boards, a whole session", max(args.reps, 5))

    text = [
        "# hmlvs benchmark results",
        "",
        f"Written by `make bench` on {datetime.date.today().isoformat()}.",
        "",
        f"Machine: {machine()}.",
        "",
        "All comparisons ran side by side in the same run on the same data (the paper's "
        "workload: 50 fitting points from `hmlvs.simulate(seed=1)`, swarm 50, 5000 iterations, "
        "Table 2 bounds). Times are medians; the machine is shared, so ratios matter more "
        "than absolute figures.",
        "",
        "## Ratios",
        "",
        *[f"- {r}" for r in ratios],
        "",
        "## Measurements",
        "",
        "| what | time / rate | note |",
        "|---|---|---|",
        *[f"| {a} | {b_} | {c} |" for a, b_, c in rows],
        "",
        *study_lines,
        "",
        *stripe_lines,
        "",
        *joint_lines,
        "",
        *tilt_lines,
        "",
        *image_lines,
        "",
    ]
    text += _kept_sections(args.out, text)
    with atomic_write(args.out) as fh:
        fh.write("\n".join(text))
    print("\n".join(text))


def _kept_sections(path: Path, written: list[str]) -> list[str]:
    """The sections of the existing RESULTS.md that this run does not write (e.g. the real
    sensor's, written by examples/blaser/run.py where that data is at hand), as they were."""
    if not path.exists():
        return []
    # the sections written: a benchmark script's section is one multi-line entry
    ours = {ln for block in written for ln in block.splitlines() if ln.startswith("## ")}
    kept: list[str] = []
    keep = False
    for ln in path.read_text().splitlines():
        if ln.startswith("## "):
            keep = ln not in ours
        if keep:
            kept.append(ln)
    return kept + [""] if kept else []


if __name__ == "__main__":
    main()
