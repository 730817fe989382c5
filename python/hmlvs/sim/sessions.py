"""Simulated data: the paper's random-pixel protocol (section 4) and a calibration session.

``hmlvs.simulate(...)`` is this module called as a function (random pixels and poses);
``hmlvs.simulate.session(...)`` simulates the paper's checkerboard data acquisition.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Any

import numpy as np

from .. import _core
from .._arrays import as_params
from ..data.dataset import Dataset
from ..geometry.board import Checkerboard
from ..geometry.robot import Robot
from ..models.paper import (
    hand_from_camera,
    laser_plane_distance,
    points_in_base,
    points_in_camera,
    project,
)
from ..models.params import Parameters

DEFAULT_IMAGE_SIZE = (640, 480)


@dataclass(frozen=True)
class Simulation:
    """Simulated data with its ground truth: ``fit`` and ``test`` sets and all points."""

    truth: Parameters
    dataset: Dataset
    fit: Dataset
    test: Dataset
    pixel_noise: float
    point_noise: float


def _random_valid_pixels(q: np.ndarray, n: int, image_size: tuple[int, int],
                         rng: np.random.Generator) -> np.ndarray:
    w, h = image_size
    out = np.empty((0, 2))
    for _ in range(100):
        cand = rng.uniform([0, 0], [w - 1, h - 1], size=(2 * n, 2))
        _, ok = points_in_camera(q, cand, on_invalid="mask")
        out = np.vstack([out, cand[ok]])
        if len(out) >= n:
            return out[:n]
    raise ValueError("the laser plane is not visible in the image for these parameters "
                     "(no pixel's ray meets it)")


def random_joints(robot: Robot, n: int, rng: np.random.Generator,
                  fraction: float = 0.5) -> np.ndarray:
    """n joint readings drawn uniformly from the middle ``fraction`` of each joint's range."""
    lim = robot.joint_limits if robot.joint_limits is not None else np.tile([-np.pi, np.pi],
                                                                            (robot.dof, 1))
    mid, half = lim.mean(axis=1), (lim[:, 1] - lim[:, 0]) / 2 * fraction
    return rng.uniform(mid - half, mid + half, size=(n, robot.dof))


def simulate(params: Parameters | np.ndarray | None = None, n: int = 100, *,
             robot: Robot | None = None, poses: np.ndarray | None = None,
             image_size: tuple[int, int] = DEFAULT_IMAGE_SIZE,
             pixel_noise: float = 0.0, point_noise: float = 0.0, seed: int = 0,
             fit: float | int = 0.5) -> Simulation:
    """Paper section 4: random stripe pixels and robot poses -> reference points.

    Parameters
    ----------
    params : true sensor parameters (default: Table 2 nominal values)
    n : number of points (default 100, the first half to fit, the second to test)
    robot : arm whose random joint readings give the poses (default SCORBOT ER-VII)
    poses : (n, 4, 4) base_from_hand poses to use instead of random ones
    pixel_noise : standard deviation (px) of Gaussian noise added to the observed pixels
    point_noise : standard deviation (mm) of Gaussian noise added to the reference points
    seed : random seed; the same seed gives the same data
    fit : fraction or number of points in the fit set

    Examples
    --------
    >>> sim = hmlvs.simulate(seed=1, pixel_noise=0.1)
    >>> len(sim.fit), len(sim.test)
    (50, 50)
    """
    q = as_params(Parameters.nominal() if params is None else params)
    if n < 2:
        raise ValueError(f"simulate needs n >= 2 points, got {n}")
    if pixel_noise < 0 or point_noise < 0:
        raise ValueError("noise levels must be >= 0")
    rng = np.random.default_rng(seed)
    robot = Robot.scorbot_er7() if robot is None else robot
    joints = None
    if poses is None:
        joints = random_joints(robot, n, rng)
        poses = robot.poses(joints)
    poses = np.asarray(poses, dtype=float)
    if poses.shape != (n, 4, 4):
        raise ValueError(f"poses must have shape ({n}, 4, 4), got {poses.shape}")
    pixels = _random_valid_pixels(q, n, image_size, rng)
    points, _ = points_in_base(q, pixels, poses)
    observed = pixels + rng.normal(0.0, pixel_noise, pixels.shape) if pixel_noise else pixels
    refs = points + rng.normal(0.0, point_noise, points.shape) if point_noise else points
    ds = Dataset(observed, poses, refs, joints=joints,
                 meta={"simulated": True, "seed": seed, "pixel_noise": pixel_noise,
                       "point_noise": point_noise, "image_size": list(image_size)})
    fit_set, test_set = ds.split(fit)
    return Simulation(Parameters.from_array(q), ds, fit_set, test_set, pixel_noise, point_noise)


# ------------------------------------------------------------------------------------------
# A simulated calibration session (paper section 5)


@dataclass(frozen=True)
class Session:
    """A simulated checkerboard session: the data set (with joint readings) and its truth."""

    truth: Parameters
    dataset: Dataset
    robot: Robot
    board: Checkerboard
    joints: np.ndarray  # (num_poses, dof), rad: one reading per pose
    image_size: tuple[int, int]

    def summary(self) -> str:
        return (f"simulated session: {self.robot.name}, {self.joints.shape[0]} poses, "
                f"{self.board.rows}x{self.board.cols} corners of {self.board.square:g} mm\n"
                + self.dataset.summary())


# Session generation must give the same poses on every CPU. BLAS and LAPACK results differ in
# the last bits between machines (the kernel OpenBLAS picks for the CPU), and a solver's path
# can amplify that into another solution (elbow up on one machine, elbow down on another). So
# the pose solves below use no BLAS: forward kinematics is the C++ core's, the look-at solve is
# the core's too (no fused multiply-add), and the small products, sums and linear solves are
# written out in elementwise IEEE operations, which give the same bits everywhere. In addition
# each pose attempt draws from its own random stream, solves take short steps (no jumps between
# basins), IK solutions are snapped to a grid of 2**-20 rad, ties between equally good
# solutions go to the first start, and the acceptance tests have margins of orders of
# magnitude over the solvers' rounding.
_JOINT_GRID = 2.0 ** -20  # rad (about 1e-6)
_IK_EXACT_MM = 1e-6  # an IK residual below this is an exact solution
_IK_MAX_MM = 20.0  # an IK residual above this is no solution
_SNAP_TOL_MM = 1e-6  # converged snaps reach ~1e-12 mm; failed ones stay far above
_ON_PLANE_MM = 1e-5  # corners on the snapped line lie within ~1e-12 mm; others ~mm away


def _on_grid(robot: Robot, joints: np.ndarray) -> np.ndarray:
    j = np.round(joints / _JOINT_GRID) * _JOINT_GRID
    lim = robot.joint_limits
    return j if lim is None else np.clip(j, lim[:, 0], lim[:, 1])


def _solve(a: np.ndarray, g: np.ndarray) -> np.ndarray:
    """Solve a x = g (small, symmetric positive definite) by Gaussian elimination with
    partial pivoting, in elementwise operations (no LAPACK)."""
    m = np.hstack([a, g[:, None]])
    n = len(g)
    for k in range(n):
        p = k + int(np.argmax(np.abs(m[k:, k])))
        if p != k:
            m[[k, p]] = m[[p, k]]
        m[k + 1:] = m[k + 1:] - (m[k + 1:, k] / m[k, k])[:, None] * m[k]
    x = np.zeros(n)
    for k in range(n - 1, -1, -1):
        acc = m[k, n]
        for j in range(k + 1, n):
            acc = acc - m[k, j] * x[j]
        x[k] = acc / m[k, k]
    return x


def _sumsq(r: np.ndarray) -> float:
    acc = 0.0
    for v in r.tolist():
        acc += v * v
    return acc


def _damped_solve(res, x0: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                  max_step: float = 0.2, iterations: int = 200) -> tuple[np.ndarray, float]:
    """Minimise ||res(x)|| from x0 within [lo, hi] by Levenberg-Marquardt with steps of at
    most ``max_step`` rad, in BLAS-free arithmetic. Short steps keep the solve in the basin of
    its start. ``res`` maps (m, n) points to (m, k) residuals. Returns (x, ||res(x)||)."""
    x = np.clip(np.asarray(x0, dtype=float), lo, hi)
    n = x.size
    h = 1e-6 * np.eye(n)
    r = res(x[None])[0]
    cost = _sumsq(r)
    lam = 1e-3
    for _ in range(iterations):
        rr = res(np.vstack([x + h, x - h]))
        jac = (rr[:n] - rr[n:]) / 2e-6  # (n, k): central differences, accurate to ~1e-10
        a = np.zeros((n, n))
        g = np.zeros(n)
        for k in range(jac.shape[1]):
            a = a + jac[:, k, None] * jac[None, :, k]
            g = g + jac[:, k] * r[k]
        d = np.diag(a) + 1e-9
        while True:
            step = -_solve(a + np.diag(lam * d), g)
            norm = np.sqrt(_sumsq(step))
            if norm > max_step:
                step = step * (max_step / norm)
            xn = np.clip(x + step, lo, hi)
            rn = res(xn[None])[0]
            cn = _sumsq(rn)
            if cn < cost:
                done = cost - cn < 1e-14 * cost or norm < 1e-13
                x, r, cost = xn, rn, cn
                lam = max(lam / 4.0, 1e-12)
                break
            lam *= 8.0
            if lam > 1e10:  # no step lowers the cost: converged to rounding
                return x, float(np.sqrt(cost))
        if done:
            break
    return x, float(np.sqrt(cost))


def ik_look_at(robot: Robot, hfc: np.ndarray, cam_pos: np.ndarray, cam_axis: np.ndarray,
                seeds: list[np.ndarray], cam_x: np.ndarray | None = None) -> np.ndarray | None:
    """Joint readings putting the camera at ``cam_pos`` looking along ``cam_axis`` (and, if
    given, with its x axis, the stripe's direction, as near ``cam_x`` as the arm allows).

    The solution is snapped to a grid of 2**-20 rad so that it is the same on every CPU."""
    lim = robot.joint_limits
    lo = lim[:, 0] if lim is not None else np.full(robot.dof, -np.inf)
    hi = lim[:, 1] if lim is not None else np.full(robot.dof, np.inf)
    native = robot._native()
    axis = np.asarray(cam_axis, dtype=float)
    pos = np.asarray(cam_pos, dtype=float)
    x_axis = None if cam_x is None else np.asarray(cam_x, dtype=float)

    best, best_err = None, np.inf
    for s in seeds:
        # :func:`_damped_solve` on the look-at residual, in C++: the same operations in the
        # same order as NumPy's elementwise ones, so the same bits (tested).
        x, err = _core._solve_look_at(native, hfc, pos, axis, x_axis, np.asarray(s, float),
                                      lo, hi, 0.2, 200)
        if err < _IK_EXACT_MM:
            best, best_err = x, err  # the first exact solution, in the order of the seeds
            break
        if err < best_err * (1.0 - 1e-6):  # clearly better: mirror solutions tie exactly
            best, best_err = x, err
    if best is None or best_err > _IK_MAX_MM:
        return None
    return _on_grid(robot, best)


def snap_to_pose_grid(robot: Robot, q: np.ndarray, joints: np.ndarray, targets: np.ndarray,
          free: list[int]) -> np.ndarray | None:
    """Move the ``free`` joints so that every target point lies exactly on the laser plane."""
    def res(x: np.ndarray) -> np.ndarray:
        j = np.repeat(joints[None], len(x), axis=0)
        j[:, free] = x
        poses = np.repeat(robot.poses(j), len(targets), axis=0)
        d = laser_plane_distance(q, np.tile(targets, (len(x), 1)), poses)
        return np.nan_to_num(d, nan=1e6).reshape(len(x), len(targets))

    lim = robot.joint_limits
    lo = lim[free, 0] if lim is not None else np.full(len(free), -np.inf)
    hi = lim[free, 1] if lim is not None else np.full(len(free), np.inf)
    x, err = _damped_solve(res, joints[free], lo, hi)
    if not err <= _SNAP_TOL_MM:
        return None
    out = joints.copy()
    out[free] = x
    return out


# A view can be used from images when the corner finder sees at least a 3 x 3 block of
# corners with squares it can resolve.
MIN_VIEW_CORNERS = 9
MIN_SQUARE_PX = 8.0


def _check_views(q: np.ndarray, robot: Robot, board: Checkerboard, joints: np.ndarray,
                 image_size: tuple[int, int], standoff: tuple[float, float]) -> int:
    """Warn (``SetupWarning``) when many views would be unusable as images: fewer than
    MIN_VIEW_CORNERS board corners in the image, or squares smaller than MIN_SQUARE_PX.
    Returns the number of such views."""
    import warnings

    from ..diagnostics.identifiability import SetupWarning
    from ..image.corners import predicted_corners

    w, h = image_size
    bad, small = 0, 0
    for pose in robot.poses(joints):
        pix = predicted_corners(q, pose, board)  # NaN where a corner is behind the camera
        inside = np.isfinite(pix).all(axis=1) & (pix[:, 0] >= 0) & (pix[:, 0] <= w - 1) & \
            (pix[:, 1] >= 0) & (pix[:, 1] <= h - 1)
        grid = pix.reshape(board.rows, board.cols, 2)
        step = np.linalg.norm(np.diff(grid, axis=1), axis=2)
        square = float(np.nanmedian(step)) if step.size else 0.0
        if inside.sum() < MIN_VIEW_CORNERS or square < MIN_SQUARE_PX:
            bad += 1
            small += square < MIN_SQUARE_PX
    n = len(joints)
    if n and bad > n // 2:
        why = (f"the board's squares are below {MIN_SQUARE_PX:g} px in {small} of them"
               if small else f"fewer than {MIN_VIEW_CORNERS} board corners are in the image")
        warnings.warn(f"{bad} of {n} views cannot be used from images: {why} (stand-off "
                      f"{standoff[0]:g}-{standoff[1]:g} mm, board {board.rows}x{board.cols} "
                      f"corners of {board.square:g} mm, image {w}x{h}); choose a stand-off and "
                      "board that suit the sensor's field of view", SetupWarning, stacklevel=3)
    return bad


def session(params: Any = None, *, robot: Robot | None = None,
            board: Checkerboard | None = None, num_poses: int = 30,
            image_size: tuple[int, int] = DEFAULT_IMAGE_SIZE, standoff: tuple[float, float] = (
                230.0, 330.0), max_tilt_deg: float = 20.0, row_fraction: float = 0.5,
            pixel_noise: float = 0.0, point_noise: float = 0.0, seed: int = 0) -> Session:
    """Simulate the paper's data acquisition (section 5) on a checkerboard.

    For each pose the robot is placed (by inverse kinematics) so that the camera looks at the
    board from ``standoff`` mm with a tilt up to ``max_tilt_deg``; then joints are adjusted
    until the laser stripe passes exactly through board corners: a whole row of corners
    (fraction ``row_fraction`` of the poses, the paper's "horizontal line overlaps the corner
    points") or a single corner. The data set stores the joint readings, the poses computed
    from them by forward kinematics, the corners' stripe pixels (optionally with Gaussian
    noise in px) and the corners' base-frame coordinates (optionally with noise in mm).
    """
    q = as_params(Parameters.nominal() if params is None else params)
    robot = Robot.scorbot_er7() if robot is None else robot
    board = Checkerboard() if board is None else board
    if num_poses < 1:
        raise ValueError(f"num_poses must be >= 1, got {num_poses}")
    # One stream for the noise, and one per pose attempt: a decision that went differently
    # on another machine could change only its own attempt, never the poses after it.
    noise_stream, attempt_streams = np.random.SeedSequence(seed).spawn(2)
    place = _Placer.of(q, robot, board, image_size, standoff, max_tilt_deg, row_fraction)
    ids = board.corner_ids()
    all_joints, px_list, pt_list, id_list, pidx = [], [], [], [], []
    attempts = 0
    while len(all_joints) < num_poses:
        attempts += 1
        rng = np.random.default_rng(attempt_streams.spawn(1)[0])
        if attempts > 50 * num_poses:
            raise ValueError(f"could place only {len(all_joints)} of {num_poses} poses on the "
                             "board: is it within the robot's reach?")
        placed = place.attempt(rng)
        if placed is None:
            continue
        new, keep, pix = placed
        p = len(all_joints)
        all_joints.append(new)
        for i in keep:
            px_list.append(pix[i])
            pt_list.append(place.corners[i])
            id_list.append(f"p{p:03d}:{ids[i]}")
            pidx.append(p)

    joints_arr = np.array(all_joints)
    _check_views(q, robot, board, joints_arr, image_size, standoff)
    pidx_arr = np.array(pidx, dtype=np.int64)
    pixels = np.array(px_list)
    points = np.array(pt_list)
    rng = np.random.default_rng(noise_stream)
    if pixel_noise:
        pixels = pixels + rng.normal(0.0, pixel_noise, pixels.shape)
    if point_noise:
        points = points + rng.normal(0.0, point_noise, points.shape)
    poses = robot.poses(joints_arr)[pidx_arr]
    ds = Dataset(pixels, poses, points, ids=np.array(id_list), joints=joints_arr[pidx_arr],
                 pose_index=pidx_arr,
                 meta={"simulated": True, "seed": seed, "robot": robot.name,
                       "pixel_noise": pixel_noise, "point_noise": point_noise,
                       "image_size": list(image_size)})
    return Session(Parameters.from_array(q), ds, robot, board, joints_arr, tuple(image_size))


@dataclass
class _Placer:
    """Places the robot for one view of :func:`session`: the camera looking at the board,
    the stripe through board corners."""

    q: np.ndarray
    robot: Robot
    corners: np.ndarray  # the board's corners in the base
    n_rc: np.ndarray  # their (row, column)
    normal: np.ndarray
    e1: np.ndarray  # two directions in the board's plane
    e2: np.ndarray
    image_size: tuple[int, int]
    standoff: tuple[float, float]
    max_tilt_deg: float
    row_fraction: float
    seed_joints: list[np.ndarray]

    @classmethod
    def of(cls, q: np.ndarray, robot: Robot, board: Checkerboard,
           image_size: tuple[int, int], standoff: tuple[float, float], max_tilt_deg: float,
           row_fraction: float) -> "_Placer":
        normal = board.normal
        e1 = np.cross(normal, [1.0, 0, 0] if abs(normal[0]) < 0.9 else [0, 1.0, 0])
        e1 = e1 / math.sqrt(_sumsq(e1))
        dof = robot.dof
        seeds = [np.zeros(dof), np.array([0.1, -0.8, 1.2, 0.0, 0.0][:dof] + [0.0] * (dof - 5)),
                 np.array([0.1, -1.2, 1.6, 0.4, 0.0][:dof] + [0.0] * (dof - 5))]
        return cls(q, robot, board.corners(),
                   np.array([(r, c) for r in range(board.rows) for c in range(board.cols)]),
                   normal, e1, np.cross(normal, e1), image_size, standoff, max_tilt_deg,
                   row_fraction, seeds)

    def _in_image(self, pix: np.ndarray, vis: np.ndarray) -> np.ndarray:
        w, h = self.image_size
        return vis & (pix[:, 0] >= 0) & (pix[:, 0] <= w - 1) & (pix[:, 1] >= 0) & \
            (pix[:, 1] <= h - 1)

    def attempt(self, rng: np.random.Generator
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """One try at a view: (joints, the corners on the stripe and in the image, all
        corners' pixels), or None when it failed."""
        q, robot, corners = self.q, self.robot, self.corners
        lo, hi = corners.min(axis=0), corners.max(axis=0)
        target = rng.uniform(lo, hi)
        tilt = np.radians(rng.uniform(0, self.max_tilt_deg))
        az = rng.uniform(0, 2 * np.pi)
        # math.sin/cos, not numpy's: numpy picks SIMD variants by CPU (e.g. AVX-512)
        view = -(math.cos(tilt) * self.normal + math.sin(tilt) * (
            math.cos(az) * self.e1 + math.sin(az) * self.e2))
        dist = rng.uniform(*self.standoff)
        joints = ik_look_at(robot, hand_from_camera(q), target - dist * view, view,
                            self.seed_joints)
        if joints is None:
            return None
        joints[-1] += rng.uniform(-np.pi, np.pi) if rng.random() < 0.5 else 0.0
        rep = np.repeat(robot.poses(joints), len(corners), axis=0)
        inside = self._in_image(*project(q, corners, rep))
        if inside.sum() < 2:
            return None
        d = np.abs(laser_plane_distance(q, corners, rep))
        d[~inside] = np.inf
        nearest = int(np.argmin(d))
        dof = robot.dof
        if rng.random() < self.row_fraction:
            # a whole row or column of corners on the stripe: two of them fix the line
            r0, c0 = self.n_rc[nearest]
            line = np.nonzero(inside & ((self.n_rc[:, 0] == r0) if rng.random() < 0.5 else
                                        (self.n_rc[:, 1] == c0)))[0]
            if line.size < 2:
                return None
            new = snap_to_pose_grid(robot, q, joints, corners[[line[0], line[-1]]],
                                    free=[0, dof - 1])
        else:
            new = snap_to_pose_grid(robot, q, joints, corners[[nearest]], free=[dof - 1])
        if new is None:
            return None
        rep = np.repeat(robot.poses(new), len(corners), axis=0)
        on = np.abs(laser_plane_distance(q, corners, rep)) < _ON_PLANE_MM
        pix, vis = project(q, corners, rep)
        keep = on & self._in_image(pix, vis)
        if not keep.any():
            return None
        return new, np.nonzero(keep)[0], pix
