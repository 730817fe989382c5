"""The paper's gauge-block check (Table 3): the block's top corners measured from stripe ends."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ..._arrays import as_params
from ...image.stripe_end import locate_stripe_end
from ...models.paper import hand_from_camera
from ...sim.render import RenderOptions, render_scene
from ...sim.scene import Box, Scene, Table
from .common import HOME, JointReadout, Progress, default_truth, params_and_result, point_jacobians
from .files import scan_folder, scene_to_dict, write_scan

#: The paper's gauge block: 60 x 30 x 55 mm, left-bottom corner at (0, -500, 0) mm.
GAUGE_BLOCK = Box((0.0, -530.0, 0.0), (60.0, -500.0, 55.0))


#: Table 3 of the paper: corner name, true position, measured mean, mean error, std (mm).
PAPER_TABLE3: tuple[tuple[str, tuple[float, float, float], tuple[float, float, float], float,
                          float], ...] = (
    ("left-top", (60.0, -500.0, 55.0), (59.95, -499.56, 55.34), 0.58, 0.15),
    ("right-top", (60.0, -530.0, 55.0), (60.17, -530.01, 54.65), 0.39, 0.14),
    ("right-bottom", (0.0, -530.0, 55.0), (0.17, -529.48, 55.14), 0.61, 0.21),
    ("left-bottom", (0.0, -500.0, 55.0), (-0.51, -499.97, 55.05), 0.71, 0.18),
)


def top_corners(block: Box) -> dict[str, np.ndarray]:
    """The block's four top corners named as in the paper's Table 3 (x towards the robot's
    front is "top", -y is "right")."""
    (x0, y0, _), (x1, y1, z1) = block.lo, block.hi
    return {"left-top": np.array([x1, y1, z1]), "right-top": np.array([x1, y0, z1]),
            "right-bottom": np.array([x0, y0, z1]), "left-bottom": np.array([x0, y1, z1])}


@dataclass(frozen=True)
class CornerResult:
    """One corner of the gauge block over its trials (mm).

    ``measured`` (n, 3) and ``errors`` (n, 3) per trial; ``e`` the mean and ``sigma`` the
    standard deviation (ddof 1) of the error lengths, as in Table 3. ``expected_e`` is what
    the simulated noise predicts for ``e``: the median and a 99% interval of the mean error
    length over the same number of trials, drawn from per-trial Gaussians centred on the
    calibration's own error at that trial and spread by the predicted pixel and joint
    readout noise (``expected_sigma`` the same for ``sigma``). ``parts`` gives the RMS of each
    part: calibration, pixel, joints. ``pixel_error`` (n, 2) is the located corner pixel
    minus the true one, ``pixel_sigma`` (n, 2) the predicted standard deviations;
    ``readout_rms_deg`` the RMS of the joint readings' actual errors (the model assumes
    ``readout_assumed_deg``). ``unexplained`` (n, 3) is what remains of each error after
    subtracting the two parts known exactly in a simulation, the calibration's error at
    the corner and the realised readout error through the kinematics' Jacobian: the
    pixel's share, plus whatever the pipeline gets wrong.
    """

    name: str
    true: np.ndarray
    measured: np.ndarray
    errors: np.ndarray
    e: float
    sigma: float
    expected_e: tuple[float, float, float]
    expected_sigma: tuple[float, float, float]
    parts: dict[str, float]
    pixel_error: np.ndarray
    pixel_sigma: np.ndarray
    joints: np.ndarray
    readings: np.ndarray
    readout_rms_deg: float = 0.0
    readout_assumed_deg: float = 0.0
    unexplained: np.ndarray | None = None
    paper_e: float | None = None
    paper_sigma: float | None = None

    @property
    def mean(self) -> np.ndarray:
        return self.measured.mean(axis=0)

    @property
    def verdict(self) -> str:
        """"within" the expected interval of e, "below" or "above" it."""
        lo, _, hi = self.expected_e
        return "below" if self.e < lo else "above" if self.e > hi else "within"

    @property
    def within_expectation(self) -> bool:
        return self.verdict == "within"


@dataclass(frozen=True)
class GaugeBlockCheck:
    """The result of :func:`gauge_block`: Table 3 simulated end to end.

    ``expected_mean_e`` is the median and 99% interval of the mean of e over the corners
    under the simulated noise (every trial of every corner drawn independently).
    ``within_expectation``: that mean lies in its interval and no corner's e exceeds the
    top of its own interval (a corner below its interval had luckily small errors; the
    per-corner verdicts say so).
    """

    corners: tuple[CornerResult, ...]
    block: Box
    truth: Any
    params: Any
    calibration: Any
    trials: int
    home: np.ndarray
    expected_mean_e: tuple[float, float, float]
    files: dict[str, Any] = field(default_factory=dict)
    seconds: float = 0.0

    @property
    def mean_e(self) -> float:
        return float(np.mean([c.e for c in self.corners]))

    @property
    def within_expectation(self) -> bool:
        lo, _, hi = self.expected_mean_e
        return lo <= self.mean_e <= hi and all(c.verdict != "above" for c in self.corners)

    def table(self) -> str:
        """Table 3's layout, the paper's e and sigma beside ours, and the expectation."""
        head = (f"{'corner':<13}{'x':>7}{'y':>8}{'z':>6} {'mean x':>8}{'mean y':>9}"
                f"{'mean z':>8} {'e':>6}{'sigma':>7} | {'paper e':>7}{'sigma':>6} | "
                f"{'expected e (99%)':>22}{'exp. sigma':>11}  verdict")
        lines = [head, "-" * len(head)]
        for c in self.corners:
            m = c.mean
            pe = f"{c.paper_e:7.2f}{c.paper_sigma:6.2f}" if c.paper_e is not None else \
                f"{'-':>7}{'-':>6}"
            lo, mid, hi = c.expected_e
            lines.append(
                f"{c.name:<13}{c.true[0]:7.0f}{c.true[1]:8.0f}{c.true[2]:6.0f} {m[0]:8.2f}"
                f"{m[1]:9.2f}{m[2]:8.2f} {c.e:6.2f}{c.sigma:7.2f} | {pe} | "
                f"{mid:6.2f} [{lo:5.2f}, {hi:5.2f}]  {c.expected_sigma[1]:9.2f}  {c.verdict}")
        lo, mid, hi = self.expected_mean_e
        lines.append(f"mean e over the corners: {self.mean_e:.3f} mm, expected {mid:.3f} "
                     f"[{lo:.3f}, {hi:.3f}]")
        lines.append(f"({self.trials} trials per corner; e = mean of |error|, sigma = its std; "
                     "expected: median [0.5%, 99.5%] of e under the simulated noise)")
        return "\n".join(lines)

    def summary(self) -> str:
        lines = [self.table()]
        for c in self.corners:
            p = c.parts
            lines.append(
                f"{c.name}: error parts (RMS) calibration {p['calibration']:.3f}, pixel "
                f"{p['pixel']:.3f}, joints {p['joints']:.3f} mm; corner pixel error RMS "
                f"{np.sqrt(np.mean(c.pixel_error ** 2, axis=0)).round(3).tolist()} px "
                f"(predicted {np.sqrt(np.mean(c.pixel_sigma ** 2, axis=0)).round(3).tolist()}); "
                f"joint readings erred by {c.readout_rms_deg:.4f} deg RMS (assumed "
                f"{c.readout_assumed_deg:.4f}); not explained by the calibration error and the "
                f"realised readout error: {np.sqrt(np.mean(np.sum(c.unexplained ** 2, 1))):.3f}"
                " mm RMS")
        off = [f"{c.name} ({c.verdict})" for c in self.corners if not c.within_expectation]
        verdict = ("the mean errors lie within the simulated noise's expectation"
                   if self.within_expectation else
                   "the mean errors are NOT what the simulated noise leads one to expect")
        lines.append(verdict + ("" if not off else "; outside their own 99% interval: "
                                + ", ".join(off)))
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        return {
            "scenario": "gauge-block", "trials": self.trials,
            "block": {"lo": list(self.block.lo), "hi": list(self.block.hi)},
            "home_rad": self.home.tolist(),
            "calibration_test_rms_mm": getattr(self.calibration, "test_rms", None),
            "within_expectation": self.within_expectation, "mean_e": self.mean_e,
            "expected_mean_e": {"low": self.expected_mean_e[0],
                                "median": self.expected_mean_e[1],
                                "high": self.expected_mean_e[2]},
            "corners": [{
                "corner": c.name, "true": c.true.tolist(), "mean": c.mean.tolist(),
                "e": c.e, "sigma": c.sigma, "paper_e": c.paper_e, "paper_sigma": c.paper_sigma,
                "expected_e": {"low": c.expected_e[0], "median": c.expected_e[1],
                               "high": c.expected_e[2]},
                "expected_sigma": {"low": c.expected_sigma[0], "median": c.expected_sigma[1],
                                   "high": c.expected_sigma[2]},
                "parts_rms_mm": c.parts, "verdict": c.verdict,
                "readout_rms_deg": c.readout_rms_deg,
                "unexplained_rms_mm": float(np.sqrt(np.mean(np.sum(c.unexplained ** 2, 1)))),
                "errors": c.errors.tolist()} for c in self.corners],
            "files": {k: str(v) for k, v in self.files.items()}, "seconds": self.seconds,
        }


def _place_on_corner(robot: Any, q_true: np.ndarray, hfc_plan: np.ndarray, scene: Scene,
                     corner: np.ndarray, inward: np.ndarray, standoff: float,
                     image_size: tuple[int, int], rng: np.random.Generator, home: np.ndarray,
                     approach_mm: float, tilt_deg: float, angle_deg: float,
                     hide: float = 25.0, attempts: int = 20) -> np.ndarray:
    """From ``home``, bring the camera over the corner with a randomly varied approach, then
    turn the wrist until the (true) laser plane passes exactly through the corner: the
    operator's "adjust until the stripe overlaps the corner". Returns the true joints.

    The stripe runs into the top face (along ``inward``); past the corner the laser sheet
    goes on down one of the two side faces at the corner (the one facing the projector).
    The camera is placed over the top face, ``hide`` mm inside both side faces' planes, so
    that neither side face is in view: the top face's stripe segment simply ends at the
    corner."""
    from ...models.paper import pixels_from_points
    from ...sim.sessions import ik_look_at, snap_to_pose_grid

    w, h = image_size
    up = np.array([0.0, 0.0, 1.0])
    reached = 0
    for _ in range(attempts):
        beta = np.radians(45.0 + rng.normal(0.0, angle_deg))
        stripe_dir = np.array([inward[0] * np.cos(beta), inward[1] * np.sin(beta), 0.0])
        faces = [np.array([-inward[0], 0.0, 0.0]), np.array([0.0, -inward[1], 0.0])]
        # a 5-joint arm tilts its tool only in its own vertical plane: tilt radially
        tilt = np.radians(rng.uniform(-tilt_deg, tilt_deg))
        radial = np.array([corner[0], corner[1], 0.0]) / max(np.hypot(*corner[:2]), 1e-9)
        view = -(np.cos(tilt) * up + np.sin(tilt) * radial)
        pos = corner - standoff * view - hide * (faces[0] + faces[1]) + rng.normal(
            0.0, approach_mm, 3)
        j = ik_look_at(robot, hfc_plan, pos, view, [home], cam_x=stripe_dir)
        if j is None:
            continue
        reached += 1
        snapped = None
        for free in ([3], [0], [2]):
            snapped = snap_to_pose_grid(robot, q_true, j, corner[None], free=free)
            if snapped is not None:
                break
        if snapped is None:
            continue
        pose = robot.poses(snapped)
        px, ok = pixels_from_points(q_true, corner[None], pose, plane_tolerance=1e-6,
                                    on_invalid="mask")
        if not ok[0] or not (60 <= px[0, 0] <= w - 61 and 40 <= px[0, 1] <= h - 41):
            continue
        bfc = pose[0] @ hand_from_camera(q_true)
        if max((bfc[:3, 3] - corner) @ n for n in faces) > -0.2 * hide:
            continue  # a side face would be in view
        t, _, _ = scene.intersect(bfc[:3, 3], (corner - bfc[:3, 3])[None])
        if not t[0] > 1 - 1e-5:  # something hides the corner from the camera
            continue
        return snapped
    if reached == 0:
        raise ValueError(f"the corner at {corner.tolist()} mm is out of the robot's reach with "
                         f"the camera {standoff:.0f} mm above it")
    raise ValueError(f"the laser stripe could not be brought onto the corner at "
                     f"{corner.tolist()} mm with the corner in view ({attempts} attempts)")


def gauge_block(calibration: Any = None, truth: Any = None, *, trials: int = 10, seed: int = 0,
                out_dir: Any = None, block: Box | None = None,
                corners: Sequence[str] | None = None, home: Any = None,
                image_size: tuple[int, int] = (640, 480), options: RenderOptions | None = None,
                readout: JointReadout | None = None, robot: Any = None,
                standoff: float | None = None, approach_mm: float = 5.0, tilt_deg: float = 3.0,
                angle_deg: float = 5.0, table: Table | None = None, progress: Any = None,
                draws: int = 4000) -> GaugeBlockCheck:
    """Table 3: measure the four top corners of a gauge block, ``trials`` times each.

    Each trial starts from the robot's ``home`` (default :data:`HOME`) and moves (inverse
    kinematics) the camera ``standoff`` mm above the top face (default ``H / tan(theta)``,
    the stripe's depth at the image centre), 25 mm inside both side faces at the corner so
    that neither is in view, looking down, with random approach differences: position
    N(0, ``approach_mm``) per axis, a tilt in the arm's plane up to +-``tilt_deg``, the
    stripe at 45 + N(0, ``angle_deg``) deg to the block's edges, running into the top face.
    Then the wrist turns until the true laser plane passes through the corner (the
    operator's "adjust until the stripe overlaps the corner", done exactly). The laser on/off
    pair is rendered with the ``truth`` sensor at the true joints; the joint readings carry
    the ``readout`` noise. The corner's pixel is the
    end of the top face's stripe segment (:func:`locate_stripe_end` with the two top edges,
    their directions from the nominal block projected with the calibration at the
    readings), triangulated with ``calibration``
    (default: :func:`simulated_calibration`) at the readings, compared with the true corner.

    The expectation (``CornerResult.expected_e``): per trial, the calibration's own error at
    the corner (its measurement of the exact corner pixel at the true pose, known here
    because the truth is) plus Gaussian noise with covariance ``J_px C_px J_px^T + J_q C_q
    J_q^T``: the corner pixel's predicted covariance (:class:`StripeEnd`) and the readout's
    variance per joint, through the model's and the kinematics' Jacobians. ``draws`` Monte
    Carlo sets of ``trials`` give the interval of e.

    Returns a :class:`GaugeBlockCheck`; ``.table()`` prints it in Table 3's layout.
    """
    import time

    from ...geometry.robot import Robot
    from ...models.paper import pixels_from_points, points_in_base, project
    from ...models.params import Parameters

    start = time.perf_counter()
    if not (isinstance(trials, (int, np.integer)) and trials >= 2):
        raise ValueError(f"trials must be an integer >= 2, got {trials}")
    truth = default_truth() if truth is None else truth
    q_true = as_params(truth)
    robot = Robot.scorbot_er7() if robot is None else robot
    readout = JointReadout() if readout is None else readout
    options = RenderOptions(noise=1.0) if options is None else options
    block = GAUGE_BLOCK if block is None else block
    if not isinstance(block, Box):
        raise ValueError(f"block must be a hmlvs.sim.scene.Box, got {type(block).__name__}")
    home = HOME if home is None else np.asarray(home, float)
    if home.shape != (robot.dof,):
        raise ValueError(f"home must hold {robot.dof} joint angles (rad), got {home.shape}")
    named = top_corners(block)
    names = list(named) if corners is None else list(corners)
    for n in names:
        if n not in named:
            raise ValueError(f"unknown corner {n!r}; the corners are {', '.join(named)}")
    scene = Scene((Table() if table is None else table, block))
    params, cal = params_and_result(calibration, truth, readout, robot, seed)
    q_plan = as_params(params)
    hfc_plan = hand_from_camera(q_plan)
    if standoff is None:
        standoff = q_plan[6] / np.tan(q_plan[7])
    centre = (np.asarray(block.lo) + np.asarray(block.hi)) / 2
    paper = {row[0]: row for row in PAPER_TABLE3}
    is_paper_block = block == GAUGE_BLOCK
    rng = np.random.default_rng([seed, 23])
    noise_rng = np.random.default_rng([seed, 29])
    bar = Progress(progress, trials * len(names))
    results, all_ids, all_frames, all_readings, e_pool = [], [], [], [], []
    for index, name in enumerate(names):
        corner = named[name]
        inward = np.sign(centre[:2] - corner[:2])
        meas, errs, pix_err, pix_sig, js, rs = [], [], [], [], [], []
        bias, covs, unexplained = [], [], []
        for k in range(trials):
            j = _place_on_corner(robot, q_true, hfc_plan, scene, corner, inward, standoff,
                                 image_size, rng, home, approach_mm, tilt_deg, angle_deg)
            reading = readout.read(j, rng)
            pose_true, pose_read = robot.poses(j), robot.poses(reading)
            frame = render_scene(q_true, pose_true[0], scene, image_size, options, noise_rng)
            # the operator's knowledge: the nominal corner and its two top edges, projected
            ends = corner + 10.0 * np.array([[0.0, 0.0, 0.0], [inward[0], 0.0, 0.0],
                                             [0.0, inward[1], 0.0]])
            near, _ = project(q_plan, ends, np.repeat(pose_read, 3, axis=0))
            end = locate_stripe_end(frame.on, frame.off, near[0],
                                    edges=[near[1] - near[0], near[2] - near[0]])
            pts, jpx, jq = point_jacobians(q_plan, end.pixel[None], reading[None], robot)
            px_true, _ = pixels_from_points(q_true, corner[None], pose_true)
            p_cal, _ = points_in_base(q_plan, px_true, pose_true)
            explained = p_cal[0] - corner + jq[0] @ (reading - j)
            cov_px = jpx[0] @ end.cov @ jpx[0].T
            cov_q = readout.variance * jq[0] @ jq[0].T
            meas.append(pts[0])
            errs.append(pts[0] - corner)
            bias.append(p_cal[0] - corner)
            unexplained.append(pts[0] - corner - explained)
            covs.append((cov_px, cov_q))
            pix_err.append(end.pixel - px_true[0])
            pix_sig.append(np.sqrt(np.diag(end.cov)))
            js.append(j)
            rs.append(reading)
            all_ids.append(f"{name}-{k:02d}")
            all_frames.append(frame)
            all_readings.append(reading)
            bar.step()
        errs_a, bias_a = np.array(errs), np.array(bias)
        cov_px_a, cov_q_a = np.array([c[0] for c in covs]), np.array([c[1] for c in covs])
        norms = np.linalg.norm(errs_a, axis=1)
        # Monte Carlo of e and sigma under the predicted per-trial error distributions
        chol = np.linalg.cholesky(cov_px_a + cov_q_a + 1e-12 * np.eye(3))
        z = np.random.default_rng([seed, 37, index]).standard_normal((draws, trials, 3))
        sim_n = np.linalg.norm(bias_a[None] + np.einsum("tij,dtj->dti", chol, z), axis=2)
        e_draws, s_draws = sim_n.mean(axis=1), sim_n.std(axis=1, ddof=1)
        e_pool.append(e_draws)
        q_e = tuple(float(x) for x in np.percentile(e_draws, [0.5, 50, 99.5]))
        q_s = tuple(float(x) for x in np.percentile(s_draws, [0.5, 50, 99.5]))
        parts = {"calibration": float(np.sqrt(np.mean(np.sum(bias_a ** 2, axis=1)))),
                 "pixel": float(np.sqrt(np.mean(np.trace(cov_px_a, axis1=1, axis2=2)))),
                 "joints": float(np.sqrt(np.mean(np.trace(cov_q_a, axis1=1, axis2=2))))}
        row = paper.get(name) if is_paper_block else None
        results.append(CornerResult(
            name=name, true=corner, measured=np.array(meas), errors=errs_a,
            e=float(norms.mean()), sigma=float(norms.std(ddof=1)), expected_e=q_e,
            expected_sigma=q_s, parts=parts, pixel_error=np.array(pix_err),
            pixel_sigma=np.array(pix_sig), joints=np.array(js), readings=np.array(rs),
            readout_rms_deg=float(np.degrees(np.sqrt(np.mean(
                (np.array(rs) - np.array(js)) ** 2)))),
            readout_assumed_deg=float(np.degrees(np.sqrt(readout.variance))),
            unexplained=np.array(unexplained),
            paper_e=row[3] if row else None, paper_sigma=row[4] if row else None))
    files: dict[str, Any] = {}
    pooled = tuple(float(x) for x in np.percentile(np.mean(e_pool, axis=0), [0.5, 50, 99.5]))
    check = GaugeBlockCheck(tuple(results), block, Parameters.from_array(q_true),
                            Parameters.from_array(q_plan), cal, trials, home, pooled, files,
                            time.perf_counter() - start)
    # the images, manifest and results as one folder: a run stopped while writing leaves
    # none of them
    with scan_folder(out_dir) as where:
        if where is not None:
            import json

            from ..._io import atomic_write

            write_scan(where, all_ids, all_frames, np.array(all_readings), image_size, robot,
                        scene=scene_to_dict(scene), scenario="gauge-block")
            files["manifest"] = Path(out_dir) / "manifest.json"
            with atomic_write(where / "gauge_block.json") as fh:
                json.dump(check.to_dict(), fh, indent=1, default=float)
            files["results"] = Path(out_dir) / "gauge_block.json"
    return check
