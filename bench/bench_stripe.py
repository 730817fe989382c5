"""Stripe extraction speed: C++ (hmlvs.extract_stripe) against the NumPy reference.

A 1280 x 1024 8-bit difference image with a curved Gaussian stripe (FWHM ~3 px), sensor
noise and a short reflection. Both run single-threaded in this process (the C++ code is
single-threaded; the NumPy reference is vectorised). Prints frames per second per method and
the ratio.

    python bench/bench_stripe.py [--seconds 2]
"""

from __future__ import annotations

import argparse
from pathlib import Path
import sys
import time

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "oracles"))

import hmlvs  # noqa: E402
import reference_stripe  # noqa: E402


def make_image(width: int = 1280, height: int = 1024, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    u = np.arange(width)
    centre = 0.45 * height + 0.08 * height * np.sin(u / width * 3.0) + 0.02 * u
    v = np.arange(height)[:, None]
    img = 180.0 * np.exp(-0.5 * ((v - centre[None, :]) / 1.3) ** 2)
    img[:, 900:1000] += 90.0 * np.exp(-0.5 * ((v - centre[None, 900:1000] - 40) / 1.3) ** 2)
    img += rng.normal(0.0, 2.0, img.shape)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def rate(fn, seconds: float) -> float:
    fn()  # warm up
    n, t0 = 0, time.perf_counter()
    while True:
        fn()
        n += 1
        dt = time.perf_counter() - t0
        if dt >= seconds:
            return n / dt


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=2.0, help="time per measurement")
    ap.add_argument("--markdown", action="store_true", help="print a Markdown section")
    args = ap.parse_args()
    img = make_image()
    md = args.markdown
    if md:
        print("## Stripe extraction\n")
        print(f"One {img.shape[1]} x {img.shape[0]} 8-bit image, single thread, C++ against the "
              "NumPy reference of `tests/oracles/reference_stripe.py` in the same run "
              "(frames/s).\n")
        print("| method | C++ fps | NumPy fps | ratio |\n|---|---:|---:|---:|")
    else:
        print(f"image {img.shape[1]} x {img.shape[0]} uint8, single thread")
        print(f"{'method':24s} {'C++ fps':>10s} {'NumPy fps':>10s} {'ratio':>8s}")
    for method in ("centroid", "gaussian", "steger"):
        for kw, label in (({}, ""), ({"threshold": 40.0, "noise": 2.0}, " (given thr.)")):
            a = hmlvs.extract_stripe(img, method=method, **kw)
            b = reference_stripe.extract(img, method=method, **kw)
            assert np.array_equal(a.status, b["status"]), "C++ and NumPy disagree"
            cpp = rate(lambda m=method, k=kw: hmlvs.extract_stripe(img, method=m, **k),
                       args.seconds)
            ref = rate(lambda m=method, k=kw: reference_stripe.extract(img, method=m, **k),
                       args.seconds)
            if md:
                print(f"| {method + label} | {cpp:.0f} | {ref:.1f} | {cpp / ref:.0f}x |")
            else:
                print(f"{method + label:24s} {cpp:10.0f} {ref:10.1f} {cpp / ref:8.1f}")
    d_on = np.clip(img.astype(int) + 60, 0, 255).astype(np.uint8)
    d_off = np.full_like(img, 60)
    fps = rate(lambda: hmlvs.difference_image(d_on, d_off), args.seconds)
    fpn = rate(lambda: hmlvs.difference_image(d_on, d_off, normalize=True), args.seconds)
    print(f"{chr(10) if md else ''}difference image: {fps:.0f} fps, normalised {fpn:.0f} fps")


if __name__ == "__main__":
    main()
