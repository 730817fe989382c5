"""Image-path benchmark: stripe extraction with the quality checks (640 x 480, 1280 x 1024),
board detection per view, and a whole 20-view session from images to a calibration file, with
a per-stage breakdown. Each figure beside its anchor measured in the same run: NumPy's
per-column argmax + centroid for stripes, OpenCV's findChessboardCornersSB for boards.

Run by `make bench` (bench/run_bench.py); alone: python bench/bench_images.py [--write FILE];
the stripe and Measurer rows alone: python bench/bench_images.py --only stripes.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from bench_joint import replace_section  # noqa: E402
from run_bench import median_time  # noqa: E402

SECTION = "## Image path: stripes, boards, a whole session"


def _median_ms(fn, reps: int) -> float:
    return 1000.0 * median_time(fn, reps)[0]


def _numpy_centres(on: np.ndarray, off: np.ndarray) -> np.ndarray:
    """The anchor: difference image, per-column peak and a 5-pixel centroid, in NumPy."""
    d = on.astype(np.float32) - off.astype(np.float32)
    v = np.argmax(d, axis=0)
    rows = np.clip(v[None, :] + np.arange(-2, 3)[:, None], 0, d.shape[0] - 1)
    w = np.clip(np.take_along_axis(d, rows, axis=0), 0, None)
    return (w * rows).sum(axis=0) / np.maximum(w.sum(axis=0), 1e-9)


def _view(size: tuple[int, int], seed: int = 0):
    from hmlvs.sim.general import example_sensor, general_session, render_general_view

    sensor = example_sensor(size)
    s = general_session(sensor=sensor, views=1, seed=seed)
    return render_general_view(s, 0)


def stripe_rows(reps: int) -> list[str]:
    """stripe_from_pair (one C++ call per frame) beside the NumPy composition of the same
    pipeline it replaced (tests/oracles/reference_frames.py) and NumPy's argmax + centroid."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "oracles"))
    from hmlvs.image.session import stripe_from_pair
    import reference_frames

    rows = []
    for size in ((640, 480), (1280, 1024)):
        on, off = _view(size)
        for what, o in (("laser on/off pair", off), ("laser-on frame alone", None)):
            ours = _median_ms(lambda on=on, o=o: stripe_from_pair(on, o), reps)
            ref = _median_ms(lambda on=on, o=o: reference_frames.stripe_from_pair(on, o),
                             max(3, reps // 2))
            anchor = _median_ms(lambda on=on, off=off: _numpy_centres(on, off), reps)
            rows.append(f"| stripe centres, {size[0]} x {size[1]}, {what} (difference image, "
                        f"albedo fit, Steger, refinement, quality checks; C++) | {ours:.1f} ms "
                        f"({1000 / ours:.0f} fps) | the same pipeline in NumPy "
                        f"(tests/oracles/reference_frames.py) {ref:.1f} ms: {ref / ours:.1f}x "
                        f"faster; "
                        f"NumPy argmax + centroid {anchor:.1f} ms: {ours / anchor:.2f}x |")
    return rows


def board_rows(reps: int, views: int = 10) -> list[str]:
    """detect_board against findChessboardCornersSB alone (its default flags), per view of a
    rendered session: the median over the views of each view's median time."""
    import cv2
    from hmlvs.geometry.board import Checkerboard
    from hmlvs.image.corners import detect_board
    from hmlvs.sim.general import example_sensor, general_session, render_general_view

    s = general_session(example_sensor((1024, 768)), views=views, seed=0)
    board = Checkerboard(rows=s.board.rows, cols=s.board.cols, square=s.board.square)
    ours, anchor = [], []
    for i in range(views):
        off = render_general_view(s, i)[1]
        ours.append(_median_ms(lambda off=off: detect_board(off, board), reps))
        anchor.append(_median_ms(lambda off=off: cv2.findChessboardCornersSB(
            off, (board.cols, board.rows)), reps))
    a, b = float(np.median(ours)), float(np.median(anchor))
    ratio = float(np.median(np.array(ours) / np.array(anchor)))
    return [f"| board detection, 1024 x 768, median over {views} views (detect_board: SB "
            f"detector, sub-pixel refinement, numbering) | {a:.1f} ms | "
            f"cv2.findChessboardCornersSB alone {b:.1f} ms: {ratio:.2f}x (median per view) |"]


def measurer_rows(frames: int = 160, rounds: int = 3) -> list[str]:
    """hmlvs.Measurer.points at 1280 x 1024: frames per second on one thread (and its CPU
    time a frame), laser on/off pairs and laser-on frames alone, and on two threads; the
    median of ``rounds`` rounds of ``frames`` frames, one and two threads alternating (the
    machine is shared: one short round can fall on another job's burst)."""
    from concurrent.futures import ThreadPoolExecutor

    import hmlvs
    from hmlvs.sim.general import example_sensor, general_session, render_general_view

    s = general_session(example_sensor((1280, 1024)), views=4, seed=0)
    m = hmlvs.Measurer(s.sensor)
    pairs = [render_general_view(s, i) for i in range(len(s))]
    jobs = [(pairs[k % len(s)], s.base_from_hand[k % len(s)]) for k in range(frames)]
    rows = []
    for what, use_off in (("laser on/off pairs", True), ("laser-on frames alone", False)):
        def one(job, use_off=use_off):
            (on, off), pose = job
            return m.points(on, pose, off if use_off else None)
        one(jobs[0])
        fps1, cpu, fps2 = [], [], []
        with ThreadPoolExecutor(max_workers=2) as pool:
            for _ in range(rounds):
                t, c = time.perf_counter(), time.process_time()
                for j in jobs:
                    one(j)
                fps1.append(frames / (time.perf_counter() - t))
                cpu.append(1000 * (time.process_time() - c) / frames)
                t = time.perf_counter()
                list(pool.map(one, jobs))
                fps2.append(frames / (time.perf_counter() - t))
        f1, c1, f2 = (float(np.median(x)) for x in (fps1, cpu, fps2))
        rows.append(f"| Measurer.points, 1280 x 1024, {what} (stripe + triangulation) | "
                    f"{f1:.0f} frames/s on 1 thread ({c1:.2f} ms CPU a frame) | {f2:.0f} "
                    f"frames/s on 2 threads (median of {rounds} rounds of {frames} frames, "
                    f"alternating; target >= 300 on 1, >= 500 on 2) |")
    return rows


def session_rows(views: int) -> list[str]:
    from hmlvs.calibration.joint import calibrate_joint
    from hmlvs.data.calibration_file import Calibration
    from hmlvs.image.reading import worker_threads
    import hmlvs.image.views as iv
    from hmlvs.sim.general import general_session, render_general_session

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "session"
        render_general_session(general_session(views=views, seed=3), folder)
        stages = {"detect": 0.0}
        real = iv.detect_corners if hasattr(iv, "detect_corners") else iv.detect_board
        name = "detect_corners" if hasattr(iv, "detect_corners") else "detect_board"

        def timed(*a, **k):
            t = time.perf_counter()
            try:
                return real(*a, **k)
            finally:
                stages["detect"] += time.perf_counter() - t

        setattr(iv, name, timed)
        try:
            t0 = time.perf_counter()
            v, board, size, pose, _ = iv.views_from_images(folder)
            t1 = time.perf_counter()
        finally:
            setattr(iv, name, real)
        r = calibrate_joint(v, board, size, base_from_board=pose)
        t2 = time.perf_counter()
        Calibration.from_joint(r).save(Path(tmp) / "cal.yaml")
        t3 = time.perf_counter()
    total = t3 - t0
    return [f"| whole session, {views} views 1024 x 768, images -> calibration file "
            f"({worker_threads(None, views)} threads) | {total:.2f} s | images -> views "
            f"{t1 - t0:.2f} s (boards {stages['detect']:.2f} s summed over the threads), "
            f"joint calibration {t2 - t1:.2f} s ({r.iterations} LM iterations), file "
            f"{1000 * (t3 - t2):.0f} ms (target < 3 s) |"]


def report(reps: int, views: int, only: str | None = None) -> str:
    if only == "stripes":  # the per-frame path alone (a few seconds)
        rows = [*stripe_rows(reps), *measurer_rows()]
    else:
        rows = [*stripe_rows(reps), *board_rows(reps), *measurer_rows(), *session_rows(views)]
    return "\n".join([
        SECTION, "",
        f"Rendered by `hmlvs.sim.general` (general sensor); {os.cpu_count()} cores; medians of "
        f"{reps} runs; rendering is not timed.", "",
        "| what | time | anchor in the same run |", "|---|---|---|", *rows, ""])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=7)
    ap.add_argument("--views", type=int, default=20)
    ap.add_argument("--write", type=Path, help="replace the section in this RESULTS.md")
    ap.add_argument("--only", choices=["stripes"],
                    help="only the stripe and Measurer rows (prints them; --write refused)")
    args = ap.parse_args()
    if args.only and args.write:
        ap.error("--only prints a partial section: it does not --write")
    section = report(args.reps, args.views, args.only)
    if args.write:
        from hmlvs._io import atomic_write

        old = args.write.read_text() if args.write.exists() else ""
        with atomic_write(args.write) as fh:
            fh.write(replace_section(old, section, SECTION))
    print(section, end="")


if __name__ == "__main__":
    main()
