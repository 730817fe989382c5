"""Joint calibration of the general sensor: hmlvs against vision-calibration (calibration-rs).

Both get the same synthetic data (:func:`hmlvs.sim.features.synthetic_views`, seeds 1..3): per
view the board corners (6 x 9, 25 mm squares), ~800 stripe pixels and the robot pose, 0.1 px
noise on both; 20 views fit, 5 more are held out. Each estimates intrinsics, distortion,
hand-eye transform, the board in the base and the laser plane:

* hmlvs: :func:`hmlvs.calibration.joint.calibrate_joint` (k1 k2 p1 p2 k3 free);
* vision-calibration (optional, the ``bench`` extra), mapped as: metres (board points, robot
  translations; results back to mm), ``base_se3_gripper`` = base_from_hand (``a_se3_b`` maps b
  coordinates into a), quaternions (x, y, z, w), Brown-Conrady (k1 k2 k3 p1 p2 by name, the
  same polynomial as OpenCV's), eye-in-hand; the camera's laser plane is n . p + distance = 0
  (metres), hand_from_camera = gripper_se3_rig inv(cam_se3_rig). Two ways:

  - joint: ``run_rig_handeye_laserline``. Its rig workflows refuse one camera, so the camera is
    listed twice with the same observations;
  - two-step: ``run_laserline_device`` (camera, laser plane) + ``run_single_cam_handeye``.

  Each with its defaults and with settings matched to hmlvs (see :func:`vc_joint_config`,
  :func:`vc_pipeline_configs`).

The map error: the held-out stripe pixels mapped to the base with each calibration, distance
to the exact base points. Every calibration is mapped by the same code (an
:class:`hmlvs.models.opencv.OpenCvSensor` built from its estimate); vision-calibration's own
``pixel_to_gripper_point`` checks that conversion on a few pixels.

    python bench/bench_joint.py [--seeds 3] [--reps 3] [--write bench/RESULTS.md]

prints the Markdown section (``bench/run_bench.py`` puts it into RESULTS.md); ``--write``
replaces the section in an existing RESULTS.md instead. Timing runs in two child processes, one
per thread setting, each running every calibration interleaved (ratios side by side).
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from functools import partial
import json
import math
import os
from pathlib import Path
import statistics
import subprocess
import sys
import time
from typing import Any, Sequence

from hmlvs.calibration.joint import calibrate_joint
from hmlvs.data.views import ViewData
from hmlvs.geometry.board import BoardSpec
from hmlvs.models.opencv import OpenCvSensor
from hmlvs.sim.features import Truth, synthetic_views
import numpy as np

IMAGE_SIZE = (1024, 768)
N_FIT, N_TEST, STRIPE_SAMPLES = 20, 5, 800
METRICS = ("focal_px", "principal_px", "plane_deg", "plane_mm", "handeye_mm", "handeye_deg",
           "map_rms_mm", "map_max_mm")
THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
               "RAYON_NUM_THREADS")

# optional (the bench extra); HMLVS_BENCH_NO_VC=1 runs as if it were not installed
try:
    if os.environ.get("HMLVS_BENCH_NO_VC"):
        raise ImportError("HMLVS_BENCH_NO_VC is set")
    import vision_calibration as vc
except ImportError as exc:
    vc = None
    VC_ERROR = f"{type(exc).__name__}: {exc}"
else:
    VC_ERROR = ""


# ----------------------------------------------------------------------------- data


@dataclass
class Problem:
    fit: list[ViewData]
    test: list[ViewData]
    test_base: list[np.ndarray]  # exact base-frame points of the test views' stripe pixels
    board: BoardSpec
    truth: Truth


def make_problem(seed: int, n_fit: int = N_FIT, n_test: int = N_TEST,
                 stripe_samples: int = STRIPE_SAMPLES,
                 corner_noise: float = 0.1, laser_noise: float = 0.1) -> Problem:
    """n_fit + n_test views from one call; the first n_fit fit, the rest are held out."""
    views, board, truth, base = synthetic_views(seed, n_fit + n_test, corner_noise=corner_noise,
                                                laser_noise=laser_noise,
                                                stripe_samples=stripe_samples)
    return Problem(views[:n_fit], views[n_fit:], base[n_fit:], board, truth)


def truth_sensor(truth: Truth) -> OpenCvSensor:
    return OpenCvSensor(truth.camera_matrix, truth.dist, IMAGE_SIZE, truth.plane,
                        truth.hand_from_camera, truth.base_from_board)


# ----------------------------------------------------------------------------- metrics


def rotation_angle_deg(r: np.ndarray) -> float:
    """Angle of a rotation matrix (deg), accurate near 0."""
    from scipy.spatial.transform import Rotation
    return math.degrees(float(Rotation.from_matrix(r).magnitude()))


def map_errors(sensor: OpenCvSensor, test: Sequence[ViewData],
               test_base: Sequence[np.ndarray]) -> np.ndarray:
    """Distances (mm) of the held-out stripe pixels mapped to the base from the exact points;
    NaN where the mapping fails."""
    px = np.concatenate([v.laser_pixels for v in test])
    poses = np.concatenate([np.repeat(v.base_from_hand[None], len(v.laser_pixels), 0)
                            for v in test])
    pts, valid = sensor.points_in_base(px, poses, on_invalid="mask")
    d = np.linalg.norm(pts - np.concatenate(test_base), axis=1)
    d[~np.asarray(valid, bool)] = np.nan
    return d


def accuracy(sensor: OpenCvSensor, truth: Truth, test: Sequence[ViewData] = (),
             test_base: Sequence[np.ndarray] = ()) -> dict[str, float]:
    """Errors of a calibrated sensor against the truth (see module doc): focal_px is the larger
    of |fx - fx0| and |fy - fy0|, principal_px the distance of (cx, cy) from the truth's, the
    plane's angle between the normals (deg) and the difference of the signed distances from
    the camera centre (mm, normals turned the same way), the hand-eye transform's translation
    (mm) and rotation (deg) errors, and the held-out map error's RMS and maximum (mm)."""
    k, k0 = sensor.camera_matrix, truth.camera_matrix
    n0 = np.asarray(truth.plane, float) / np.linalg.norm(truth.plane[:3])
    n = np.asarray(sensor.laser_plane, float) / np.linalg.norm(sensor.laser_plane[:3])
    if n[:3] @ n0[:3] < 0:
        n = -n
    hfc, hfc0 = sensor.hand_from_camera, truth.hand_from_camera
    out = {
        "focal_px": float(max(abs(k[0, 0] - k0[0, 0]), abs(k[1, 1] - k0[1, 1]))),
        "principal_px": float(np.hypot(k[0, 2] - k0[0, 2], k[1, 2] - k0[1, 2])),
        "plane_deg": math.degrees(math.atan2(float(np.linalg.norm(np.cross(n[:3], n0[:3]))),
                                             float(n[:3] @ n0[:3]))),
        "plane_mm": float(abs(n[3] - n0[3])),
        "handeye_mm": float(np.linalg.norm(hfc[:3, 3] - hfc0[:3, 3])),
        "handeye_deg": rotation_angle_deg(hfc[:3, :3].T @ hfc0[:3, :3]),
    }
    if len(test):
        d = map_errors(sensor, test, test_base)
        out["map_rms_mm"] = float(np.sqrt(np.mean(d ** 2)))
        out["map_max_mm"] = float(np.max(d))
    return out


# ----------------------------------------------------------------------------- hmlvs


def run_hmlvs(p: Problem) -> OpenCvSensor:
    return calibrate_joint(p.fit, p.board, IMAGE_SIZE).sensor


# ----------------------------------------------------------------------------- vision-calibration


def _quat_xyzw(r: np.ndarray) -> tuple[float, float, float, float]:
    """Rotation matrix -> unit quaternion (x, y, z, w)."""
    from scipy.spatial.transform import Rotation
    x, y, z, w = Rotation.from_matrix(r).as_quat()
    return (float(x), float(y), float(z), float(w))


def pose_to_vc(m: np.ndarray) -> Any:
    """4x4 a_from_b (mm) -> vision-calibration ``a_se3_b`` Pose (metres)."""
    return vc.Pose(rotation_xyzw=_quat_xyzw(m[:3, :3]),
                   translation_xyz=tuple(float(t) / 1000.0 for t in m[:3, 3]))


def pose_from_vc(pose: Any) -> np.ndarray:
    """vision-calibration ``a_se3_b`` Pose (metres) -> 4x4 a_from_b (mm)."""
    from scipy.spatial.transform import Rotation
    m = np.eye(4)
    m[:3, :3] = Rotation.from_quat(pose.rotation_xyzw).as_matrix()
    m[:3, 3] = np.asarray(pose.translation_xyz, float) * 1000.0
    return m


def vc_dataset(views: Sequence[ViewData], board: BoardSpec) -> Any:
    """One camera, one frame per view: board points (m) and their pixels, the stripe pixels
    (distorted, as detected) and base_se3_gripper = base_from_hand (m)."""
    out = []
    for v in views:
        pts = board.points(v.corner_index) / 1000.0
        obs = vc.Observation(points_3d=[tuple(p) for p in pts.tolist()],
                             points_2d=[tuple(p) for p in np.asarray(v.corner_pixels).tolist()])
        out.append(vc.RigHandeyeLaserlineView(
            cameras=[obs], laser_pixels=[[tuple(p) for p in np.asarray(v.laser_pixels).tolist()]],
            base_se3_gripper=pose_to_vc(v.base_from_hand)))
    return vc.RigHandeyeLaserlineDataset(num_cameras=1, views=out)


def vc_joint_config(matched: bool = True) -> Any:
    """run_rig_handeye_laserline's defaults, or (matched) p1 p2 free in the joint solve and the
    robot poses held fixed, as hmlvs assumes."""
    cfg = vc.RigHandeyeLaserlineCalibrationConfig()
    if matched:
        cfg.joint_ba.default_camera_fix = vc.CameraFixMask(
            distortion={"k1": False, "k2": False, "k3": True, "p1": False, "p2": False})
        cfg.joint_ba.robot_poses = vc.RobotPoseConfig(refine=False)
        cfg.handeye.handeye_ba.robot_poses = vc.RobotPoseConfig(refine=False)
    return cfg


def vc_joint_dataset(views: Sequence[ViewData], board: BoardSpec) -> Any:
    """The rig workflow needs two cameras or more: the one camera is listed twice, with the
    same observations (every residual counted twice, so the same minimum; the second camera's
    own parameters converge to the first's)."""
    ds = vc_dataset(views, board)
    return vc.RigHandeyeLaserlineDataset(num_cameras=2, views=[
        vc.RigHandeyeLaserlineView(cameras=v.cameras * 2, laser_pixels=v.laser_pixels * 2,
                                   base_se3_gripper=v.base_se3_gripper) for v in ds.views])


def vc_sensor(res: Any) -> OpenCvSensor:
    """The (first) camera of a run_rig_handeye_laserline result as an OpenCvSensor (mm; the
    plane n . p + distance = 0 in metres -> (n, 1000 distance); hand_from_camera =
    gripper_se3_rig inv(cam_se3_rig))."""
    cam = res.cameras[0]
    hfc = pose_from_vc(res.gripper_se3_rig) @ np.linalg.inv(pose_from_vc(res.cam_se3_rig[0]))
    bfb = None if res.base_se3_target is None else pose_from_vc(res.base_se3_target)
    return _sensor(cam.intrinsics, cam.distortion, res.laser_planes_cam[0], hfc, bfb)


def _sensor(i: Any, d: Any, plane: Any, hfc: np.ndarray, bfb: np.ndarray | None
            ) -> OpenCvSensor:
    k = np.array([[i.fx, i.skew, i.cx], [0.0, i.fy, i.cy], [0.0, 0.0, 1.0]])
    return OpenCvSensor(k, [d.k1, d.k2, d.p1, d.p2, d.k3], IMAGE_SIZE,
                        np.r_[plane.normal_xyz, 1000.0 * plane.distance], hfc, bfb)


def run_vc_joint(p: Problem, matched: bool = True, raw: bool = False) -> Any:
    """run_rig_handeye_laserline; raw: also return the raw result payload (what the public
    function parses), which its pixel_to_gripper_point accepts."""
    ds, cfg = vc_joint_dataset(p.fit, p.board), vc_joint_config(matched)
    if not raw:
        return vc.run_rig_handeye_laserline(ds, cfg)
    payload = vc._native.run_rig_handeye_laserline(ds.to_payload(), cfg.to_payload())
    return vc.RigHandeyeLaserlineResult.from_payload(payload), payload


def vc_pipeline_inputs(views: Sequence[ViewData], board: BoardSpec) -> tuple[Any, Any]:
    ds = vc_dataset(views, board)
    laser = vc.LaserlineDataset(views=[
        vc.LaserlineView(observation=v.cameras[0], laser_pixels=v.laser_pixels[0],
                         laser_weights=[1.0] * len(v.laser_pixels[0])) for v in ds.views])
    handeye = vc.SingleCamHandeyeDataset(views=[
        vc.SingleCamHandeyeView(observation=v.cameras[0], base_se3_gripper=v.base_se3_gripper)
        for v in ds.views])
    return laser, handeye


def vc_pipeline_configs(matched: bool = True) -> tuple[Any, Any]:
    """run_laserline_device + run_single_cam_handeye defaults, or (matched) no board pose held
    at its initial estimate (the default holds view 0's), the point-to-plane laser residual
    weighted as in run_rig_handeye_laserline's joint solve, robot poses fixed."""
    laser, handeye = vc.LaserlineDeviceCalibrationConfig(), vc.SingleCamHandeyeCalibrationConfig()
    if matched:
        laser.optimize.fix_poses = []
        laser.optimize.laser_residual_type = "PointToPlane"
        laser.optimize.laser_weight = vc.RigHandeyeLaserlineBaConfig().laser_weight
        handeye.robot_poses = vc.RobotPoseConfig(refine=False)
    return laser, handeye


def run_vc_pipeline(p: Problem, matched: bool = True) -> tuple[Any, Any]:
    (ld, he), (lc, hc) = vc_pipeline_inputs(p.fit, p.board), vc_pipeline_configs(matched)
    return vc.run_laserline_device(ld, lc), vc.run_single_cam_handeye(he, hc)


def vc_pipeline_sensor(res: tuple[Any, Any]) -> OpenCvSensor:
    """Camera and laser plane of run_laserline_device, hand-eye transform (gripper_se3_camera)
    and board (base_se3_target) of run_single_cam_handeye."""
    laser, handeye = res
    q = laser.estimate.params
    bfb = None if handeye.base_se3_target is None else pose_from_vc(handeye.base_se3_target)
    return _sensor(q.intrinsics, q.distortion, q.plane, pose_from_vc(handeye.gripper_se3_camera),
                   bfb)


def vc_native_check(res: Any, payload: Any, p: Problem, n: int = 20) -> float:
    """Largest distance (mm) between vision-calibration's own pixel_to_gripper_point and the
    OpenCvSensor conversion of its estimate on n held-out stripe pixels (hand frame). The
    typed result does not round-trip into pixel_to_gripper_point in 0.9.0 (missing field
    `proj`), so the raw payload is passed."""
    sensor = vc_sensor(res)
    v = p.test[0]
    px = np.asarray(v.laser_pixels)[np.linspace(0, len(v.laser_pixels) - 1, n).astype(int)]
    native = np.array([vc.pixel_to_gripper_point(0, (float(q[0]), float(q[1])), payload,
                                                 payload["laser_planes_rig"]) for q in px])
    ours, _ = sensor.points_in_camera(px)
    ours = ours @ sensor.hand_from_camera[:3, :3].T + sensor.hand_from_camera[:3, 3]
    return float(np.max(np.linalg.norm(1000.0 * native - ours, axis=1)))


# ----------------------------------------------------------------------------- runs


TIMED = ("hmlvs", "vc_joint", "vc_pipeline")


def timed_runs(p: Problem) -> dict[str, Any]:
    """The timed calibrations of one problem (inputs built beforehand)."""
    runs = {"hmlvs": lambda: calibrate_joint(p.fit, p.board, IMAGE_SIZE)}
    if vc:
        jd, jc = vc_joint_dataset(p.fit, p.board), vc_joint_config()
        (ld, hd), (lc, hc) = vc_pipeline_inputs(p.fit, p.board), vc_pipeline_configs()
        runs["vc_joint"] = lambda: vc.run_rig_handeye_laserline(jd, jc)
        runs["vc_pipeline"] = lambda: (vc.run_laserline_device(ld, lc),
                                       vc.run_single_cam_handeye(hd, hc))
    return runs


def timing_worker(seeds: Sequence[int], reps: int) -> dict[str, list[float]]:
    """Median wall time per seed of each calibration, the libraries interleaved within each
    repeat in this process."""
    out: dict[str, list[float]] = {k: [] for k in TIMED}
    for seed in seeds:
        runs = timed_runs(make_problem(seed))
        times: dict[str, list[float]] = {k: [] for k in runs}
        for _ in range(reps):
            for k, fn in runs.items():
                t = time.perf_counter()
                fn()
                times[k].append(time.perf_counter() - t)
        for k, ts in times.items():
            out[k].append(statistics.median(ts))
    return out


def run_timing(seeds: Sequence[int], reps: int, single_thread: bool) -> dict[str, Any]:
    env = dict(os.environ)
    for var in THREAD_VARS:
        env.pop(var, None)
        if single_thread:
            env[var] = "1"
    out = subprocess.run([sys.executable, __file__, "--timing-worker", "--reps", str(reps),
                          "--seed-list", ",".join(map(str, seeds))],
                         env=env, check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def fmt(x: float, digits: int = 3) -> str:
    return "n/a" if x is None or not np.isfinite(x) else f"{x:.{digits}g}"


LABELS = {"hmlvs": "hmlvs `calibrate_joint`",
          "vc_joint": "vision-calibration joint (`run_rig_handeye_laserline`, camera x2)",
          "vc_pipeline": "vision-calibration two-step (`run_laserline_device` + "
                         "`run_single_cam_handeye`)"}


def seed_rows(seed: int, p: Problem, checks: list[float], warnings: list[str]
              ) -> list[tuple[str, dict[str, float]]]:
    """Accuracy rows of one seed; failures become warnings."""
    acc = partial(accuracy, truth=p.truth, test=p.test, test_base=p.test_base)

    def joint(matched: bool) -> dict[str, float]:
        res, payload = run_vc_joint(p, matched, raw=True)
        if matched:
            checks.append(vc_native_check(res, payload, p))
        return acc(vc_sensor(res))

    candidates = [("hmlvs", lambda: acc(run_hmlvs(p)))]
    if vc:
        candidates += [
            ("vc joint", lambda: joint(True)),
            ("vc joint (its defaults)", lambda: joint(False)),
            ("vc two-step", lambda: acc(vc_pipeline_sensor(run_vc_pipeline(p, True)))),
            ("vc two-step (its defaults)",
             lambda: acc(vc_pipeline_sensor(run_vc_pipeline(p, False))))]
    rows = [(f"truth (map error = noise floor), seed {seed}", acc(truth_sensor(p.truth)))]
    for name, fn in candidates:
        try:
            rows.append((f"{name}, seed {seed}", fn()))
        except Exception as exc:  # noqa: BLE001 - report, do not stop the benchmark
            warnings.append(f"{name}, seed {seed} failed: {type(exc).__name__}: {exc}")
    return rows


def accuracy_rows(seeds: Sequence[int]) -> tuple[list[tuple[str, dict[str, float]]], list[float],
                                                 list[str], list[float]]:
    rows: list[tuple[str, dict[str, float]]] = []
    checks: list[float] = []
    warnings: list[str] = []
    npx: list[float] = []
    for seed in seeds:
        p = make_problem(seed)
        npx.append(float(np.mean([len(v.laser_pixels) for v in p.fit])))
        rows += seed_rows(seed, p, checks, warnings)
    return rows, npx, warnings, checks


def report(seeds: Sequence[int], reps: int) -> str:
    print("joint calibration: accuracy ...", file=sys.stderr, flush=True)
    rows, npx, warnings, checks = accuracy_rows(seeds)
    print("joint calibration: timing ...", file=sys.stderr, flush=True)
    timing = {mode: run_timing(seeds, reps, mode == "1 thread")
              for mode in ("1 thread", "default threads")}
    lines = [
        "## Joint calibration: hmlvs against vision-calibration",
        "",
        "Written by `bench/bench_joint.py`. Synthetic general sensor (`hmlvs.sim.features`, "
        f"1024 x 768, k1 -0.165): per seed {N_FIT} views to fit ({np.mean(npx):.0f} stripe "
        "pixels and 54 corners a view, 0.1 px noise on both) and "
        f"{N_TEST} held-out views for the map error. Each calibration estimates intrinsics, "
        "distortion, hand-eye transform, board pose in the base and laser plane.",
        "",
        "- **hmlvs**: `calibrate_joint` (k1 k2 p1 p2 k3 free), one joint solve.",
        f"- **vc joint**: vision-calibration {getattr(vc, '__version__', '(not installed)')} "
        "`run_rig_handeye_laserline`, eye-in-hand, metres, `base_se3_gripper` = base_from_hand. "
        "Its rig workflows refuse one camera (\"need 2, got 1\"), so the camera is listed "
        "twice with the same observations (same minimum, but twice the residuals and a "
        "second camera's unknowns: its time is an upper bound). Its joint solve frees p1 p2 "
        "here (its default frees k1 k2 only; k3 stays 0 = the truth) and holds the robot poses "
        "fixed as hmlvs does; `(its defaults)`: configuration untouched.",
        "- **vc two-step**: `run_laserline_device` (camera, board poses, laser plane) then "
        "`run_single_cam_handeye` (hand-eye); camera and plane from the first, hand-eye from "
        "the second. Here no board pose is held at its initial estimate (its default holds "
        "view 0's), point-to-plane laser residual weighted as in the joint workflow, robot "
        "poses fixed; `(its defaults)`: configuration untouched.",
        "",
        "Errors against the truth: focal = max(|dfx|, |dfy|), principal point = |d(cx, cy)|, "
        "plane = angle between normals and difference of distances from the camera centre, "
        "hand-eye = translation and rotation of hand_from_camera. Map: held-out stripe pixels "
        "to the robot base (pixel, robot pose) with each calibration, distance to the exact "
        "points; the same mapping code for all (an `OpenCvSensor` built from each estimate)"
        + (f"; for vc joint it agrees with vision-calibration's own `pixel_to_gripper_point` "
           f"to {fmt(max(checks))} mm (20 pixels per seed)" if checks else "")
        + ". The truth row's map error is the floor set by the 0.1 px pixel noise.",
        "",
    ]
    if not vc:
        lines += [f"**vision-calibration is not installed** ({VC_ERROR}); `pip install "
                  "'.[bench]'` adds its side of the comparison. hmlvs alone:", ""]
    lines += ["| calibration | focal (px) | principal point (px) | plane angle (deg) | "
              "plane distance (mm) | hand-eye (mm) | hand-eye (deg) | map RMS (mm) | "
              "map max (mm) |", "|---|" + "---:|" * len(METRICS)]
    lines += [f"| {name} | " + " | ".join(fmt(acc[m]) for m in METRICS) + " |"
              for name, acc in rows]
    lines += ["", f"Wall time per calibration (s), median of {reps} repeats per seed; in each "
              "thread setting one process runs all of them interleaved, so the ratios are side "
              f"by side. {os.cpu_count()} hardware threads, shared machine.", "",
              "| calibration | threads | " + " | ".join(f"seed {s}" for s in seeds)
              + " | median | / hmlvs |", "|---|---|" + "---:|" * (len(seeds) + 2)]
    for mode, t in timing.items():
        label = ("OMP/OPENBLAS/MKL/RAYON_NUM_THREADS=1" if mode == "1 thread"
                 else "defaults (variables unset)")
        base = statistics.median(t["hmlvs"])
        for k in TIMED:
            if t.get(k):
                med = statistics.median(t[k])
                lines.append(f"| {LABELS[k]} | {label} | "
                             + " | ".join(f"{x:.3f}" for x in t[k])
                             + f" | {med:.3f} | {med / base:.1f}x |")
    lines += [f"- {w}" for w in warnings]
    return "\n".join(lines) + "\n"


SECTION = "## Joint calibration: hmlvs against vision-calibration"


def replace_section(text: str, section: str, heading: str = SECTION) -> str:
    """text with its section under ``heading`` (up to the next "## " heading) replaced by
    section, or section appended."""
    lines = text.rstrip("\n").split("\n")
    if heading in lines:
        i = lines.index(heading)
        j = next((k for k in range(i + 1, len(lines)) if lines[k].startswith("## ")), len(lines))
        lines[i:j] = section.rstrip("\n").split("\n") + ([""] if j < len(lines) else [])
    else:
        lines += ["", *section.rstrip("\n").split("\n")]
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3, help="seeds 1..N")
    ap.add_argument("--reps", type=int, default=3, help="timing repeats per seed")
    ap.add_argument("--write", type=Path, help="replace the section in this RESULTS.md")
    ap.add_argument("--timing-worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--seed-list", default="", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.timing_worker:
        seeds = [int(s) for s in args.seed_list.split(",")]
        print(json.dumps(timing_worker(seeds, args.reps)))
        return
    section = report(list(range(1, args.seeds + 1)), args.reps)
    if args.write:
        from hmlvs._io import atomic_write
        old = args.write.read_text() if args.write.exists() else ""
        with atomic_write(args.write) as fh:
            fh.write(replace_section(old, section))
    print(section, end="")


if __name__ == "__main__":
    main()
