"""The Blaser UR5e sessions end to end: sessions, `hmlvs calibrate` as a user runs it, the
authors' calibrations, the scores side by side, and the section "Real sensor" of
bench/RESULTS.md.

    python examples/blaser/run.py CHECKOUT WORKDIR [--results bench/RESULTS.md]

CHECKOUT: a git checkout (work tree) of the Blaser repository (no licence: nothing taken or
derived from it is written into this repository but the figures). WORKDIR: a folder of your
own for the sessions, calibrations and logs. Not run in CI (it needs the data).
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
from pathlib import Path
import subprocess
import sys
import time

import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))

import authors  # noqa: E402
import hmlvs  # noqa: E402
from make_session import make_session  # noqa: E402
import score  # noqa: E402

MATS = {"640": "state_finalv2.mat", "1280": "state_1280_laser.mat"}
#: the targets set for hmlvs on these sessions: planarity (mm) and chain reprojection (px),
#: both at once
TARGETS = {"640": (0.22, 1.7), "1280": (0.32, 4.0)}
SECTION = "## Real sensor: the Blaser UR5e sessions"


def hmlvs_command() -> list[str]:
    """The installed command line of the environment running this script."""
    exe = Path(sys.executable).parent / "hmlvs"
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "hmlvs"]


def calibrate(session: Path, out: Path, *options: str) -> tuple[float, list[str]]:
    """`hmlvs calibrate SESSION --out OUT` with its defaults (or ``options``): (wall seconds,
    output lines)."""
    start = time.perf_counter()
    r = subprocess.run([*hmlvs_command(), "calibrate", str(session), "--out", str(out),
                        *options], capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if r.returncode not in (0, 3):
        raise RuntimeError(f"hmlvs calibrate {session} failed ({r.returncode}): {r.stderr}")
    return seconds, r.stdout.splitlines()


def run_resolution(checkout: Path, work: Path, res: str) -> dict:
    session = work / f"bl{res}"
    if not (session / "manifest.yaml").exists():
        make_session(checkout, session, res)
    cal = work / f"hmlvs{res}.yaml"
    seconds, lines = calibrate(session, cal)
    (work / f"hmlvs{res}.log").write_text("\n".join(lines) + "\n")
    sess = score.load_session(session, work / "cache")
    mat = authors.read_mat_bytes(MATS[res], checkout, authors.DEFAULT_COMMIT)
    auth = work / f"authors{res}.yaml"
    authors.authors_calibration(authors.state_from_mat(mat, MATS[res]),
                                sess.image_size, MATS[res]).save(auth)
    scores = [score.score(auth, "the authors' own", sess),
            score.score(cal, "hmlvs calibrate (defaults)", sess)]
    bench = bench_workflow(session, work, res)
    scores += [score.score(bench["robot"], "hmlvs: bench session, then the hand-eye", sess),
               score.score(bench["uncertain"], "hmlvs calibrate --robot-poses uncertain", sess)]
    bench["agreement"] = {name: agreement(bench["bench"], other) for name, other in
                          (("defaults", cal), ("uncertain", bench["uncertain"]))}
    return {"res": res, "seconds": seconds, "lines": lines, "session": sess, "scores": scores,
            "verdict": hmlvs.Calibration.load(cal).verdict, "bench": bench}


def bench_session(session: Path, out: Path) -> Path:
    """The session's frames as a bench session: the same images, the manifest without robot
    poses (the laser-only frames, which need robot poses, are reported and left out)."""
    doc = yaml.safe_load((session / "manifest.yaml").read_text())
    for e in doc["poses"]:
        del e["pose"]
        e["on"] = str((session / e["on"]).resolve())
    doc.pop("pose_format", None)
    out.mkdir(parents=True, exist_ok=True)
    (out / "manifest.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    return out


def bench_workflow(session: Path, work: Path, res: str) -> dict:
    """Issue 36's bench workflow on the real frames: the camera and laser plane from the
    board frames alone (no robot poses), then the robot session holding them for the
    hand-eye (`--initial`); and the full session with uncertain robot poses."""
    bench = bench_session(session, work / f"bl{res}_bench")
    out = {k: work / f"hmlvs{res}_{k}.yaml" for k in ("bench", "robot", "uncertain")}
    calibrate(bench, out["bench"])
    calibrate(session, out["robot"], "--initial", str(out["bench"]))
    calibrate(session, out["uncertain"], "--robot-poses", "uncertain")
    return out


def agreement(a_path: Path, b_path: Path) -> dict:
    """The camera and laser plane of two calibrations: differences, and in units of their
    combined standard deviations (the files' own)."""
    a, b = (hmlvs.Calibration.load(p) for p in (a_path, b_path))
    out = {}
    for name in ("fx", "fy", "cx", "cy"):
        d = getattr(b.sensor, name) - getattr(a.sensor, name)
        sig = math.hypot(a.std.get(name) or 0.0, b.std.get(name) or 0.0)
        out[name] = (d, d / sig if sig else float("nan"))
    na, nb = a.sensor.laser_plane[:3], b.sensor.laser_plane[:3]
    angle = math.acos(min(1.0, abs(float(na @ nb))))
    sig = math.sqrt(sum((c.std.get(k) or 0.0) ** 2 for c in (a, b)
                        for k in ("plane_n1", "plane_n2")))
    out["plane_deg"] = (math.degrees(angle), angle / sig if sig else float("nan"))
    d = abs(b.sensor.laser_plane[3]) - abs(a.sensor.laser_plane[3])
    sig = math.hypot(a.std.get("plane_d") or 0.0, b.std.get("plane_d") or 0.0)
    out["plane_mm"] = (d, d / sig if sig else float("nan"))
    return out


def section(results: list[dict]) -> list[str]:
    out = [SECTION, "",
           f"`python examples/blaser/run.py` on {datetime.date.today().isoformat()}: the public "
           "Blaser sessions (a camera and a red laser line on a UR5e, a static 9 x 6 board of "
           "5 mm squares on a white sheet; laser-on colour frames only, 11 of them laser-only "
           "in the dark), calibrated by `hmlvs calibrate SESSION` with its defaults and scored "
           "beside the authors' own calibration by `examples/blaser/score.py`: stripe "
           "planarity (all stripe points of all views, found by the script's own extractor, "
           "independent of both calibrations, mapped through each calibration and the robot "
           "poses, RMS from their best plane) and chain reprojection (the board corners "
           "through one board pose in the base, the robot poses and the calibration).", "",
           "| session | calibration | planarity mm | chain px | stripe points | board views | "
           "within the targets |",
           "|---|---|---|---|---|---|---|"]
    for r in results:
        plan_t, chain_t = TARGETS[r["res"]]
        for s in r["scores"]:
            chain = f"{s.chain.rms_px:.2f}" if s.chain else "-"
            met = s.chain is not None and s.planarity.rms_mm <= plan_t and \
                s.chain.rms_px <= chain_t
            out.append(f"| {r['res']} | {s.name} | {s.planarity.rms_mm:.3f} | {chain} | "
                       f"{s.planarity.num_points} | {len(r['session'].corners)} | "
                       f"{'yes' if met else 'no'} (<= {plan_t} mm and <= {chain_t} px) |")
    out += ["", "The targets come from the figures another scorer of the same kind (its own "
            "stripe extractor) gave the peers: the authors' 0.288 mm / 5.30 px (640) and "
            "0.360 / 13.7 (1280), plain OpenCV (calibrateCamera, Park-Martin hand-eye, plane "
            "fit) 0.284 / 2.38 and 0.393 / 4.96, vision-calibration 0.9 with its defaults "
            "0.239 / 2.55 and 0.417 / 9.74; the authors' own calibration scores 0.298 / 5.30 "
            "and 0.377 / 13.70 here, so this scorer's planarity runs a few per cent higher."]
    out += ["", "The bench workflow on the same frames (`hmlvs calibrate BENCH` of a manifest "
            "without robot poses: the camera and laser plane from the board frames alone; then "
            "`hmlvs calibrate SESSION --initial BENCH.yaml`: the hand-eye with them held), and "
            "the bench calibration's camera and plane against the full session's, in units of "
            "their combined standard deviations (the files' own):", "",
            "| session | against | fx | fy | cx | cy | plane normal | plane offset |",
            "|---|---|---|---|---|---|---|---|"]
    for r in results:
        for name, a in r["bench"]["agreement"].items():
            cells = [f"{a[k][0]:+.2f} px ({a[k][1]:+.1f} sd)" for k in ("fx", "fy", "cx", "cy")]
            cells += [f"{a['plane_deg'][0]:.3f} deg ({a['plane_deg'][1]:.1f} sd)",
                      f"{a['plane_mm'][0]:+.3f} mm ({a['plane_mm'][1]:+.1f} sd)"]
            label = {"defaults": "hmlvs calibrate (defaults)",
                     "uncertain": "--robot-poses uncertain"}[name]
            out.append(f"| {r['res']} | {label} | " + " | ".join(cells) + " |")
    out += ["", "hmlvs' own verdict on each of its calibrations (`hmlvs calibrate` exits 3 "
            "when it is not trustworthy):", ""]
    for r in results:
        v = r["verdict"]
        if v is None:
            continue
        ms = v.get("map_sigma_mm") or {}
        cv = v.get("cross_validation_mm") or {}
        out.append(f"- {r['res']}: {'trustworthy' if v['trustworthy'] else 'not trustworthy'}; "
                   f"predicted 3D uncertainty {ms.get('rms', float('nan')):.3f} mm RMS, the "
                   f"two halves of the views {cv.get('rms', float('nan')):.3f} mm RMS apart; "
                   + "; ".join(v["reasons"]))
    out += ["", "Per view, as `hmlvs calibrate` printed it:", ""]
    for r in results:
        out.append(f"- {r['res']} ({r['seconds']:.1f} s wall): " + "; ".join(
            ln for ln in r["lines"] if ln.startswith("im")))
    return out


def write_section(results_md: Path, lines: list[str]) -> None:
    """Replace (or append) the section in RESULTS.md, leaving the rest as it is."""
    text = results_md.read_text().splitlines() if results_md.exists() else []
    if SECTION in text:
        start = text.index(SECTION)
        end = next((k for k in range(start + 1, len(text)) if text[k].startswith("## ")),
                   len(text))
        text = text[:start] + lines + ([""] + text[end:] if end < len(text) else [])
    else:
        text = text + [""] + lines
    results_md.write_text("\n".join(text).rstrip() + "\n")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("checkout", type=Path)
    ap.add_argument("work", type=Path)
    ap.add_argument("--results", type=Path,
                    default=Path(__file__).resolve().parents[2] / "bench" / "RESULTS.md")
    a = ap.parse_args(argv)
    a.work.mkdir(parents=True, exist_ok=True)
    results = [run_resolution(a.checkout, a.work, res) for res in ("640", "1280")]
    lines = section(results)
    write_section(a.results, lines)
    print("\n".join(lines))
    (a.work / "scores.json").write_text(json.dumps(
        {r["res"]: score.as_json(r["session"], r["scores"]) for r in results}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
