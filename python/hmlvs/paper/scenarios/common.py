"""What the scenarios share: the simulated robot readout, an honest calibration, scans written
to folders."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ...models.paper import hand_from_camera
from ...sim.scene import Scene

#: The paper's identified sensor (Table 2, best-fit column), used as the simulated truth:
#: a real sensor, off the nominal values the calibration starts from.
PAPER_SENSOR: dict[str, float] = {
    "f": 7.70, "Su": 0.0074, "Sv": 0.0075, "Cu": 323.8, "Cv": 238.3, "k": 4.8e-4,
    "H": 137.3, "theta": 0.47, "omega": -1.8e-3, "phi": -0.05, "varphi": -6.8e-3,
    "tx": 63.2, "ty": -2.3, "tz": -46.2,
}


#: The robot's home position used by the scenarios (rad): upper arm vertical, forearm
#: horizontal, flange pointing down; the SCORBOT ER-VII's flange is then at (400, 0, 407.5) mm.
HOME = np.radians([0.0, -90.0, 90.0, 0.0, 0.0])


@dataclass(frozen=True)
class JointReadout:
    """How the controller reports the joint angles it actually reached.

    A reading is the true angle plus Gaussian noise of ``noise_deg`` (backlash, compliance,
    servo error), quantised to the encoder's ``resolution_deg``. The defaults are
    assumptions for a SCORBOT-class arm (about +-0.2 mm repeatability), not datasheet values.
    """

    resolution_deg: float = 0.01
    noise_deg: float = 0.01

    def __post_init__(self) -> None:
        for name in ("resolution_deg", "noise_deg"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {v}")

    def read(self, joints: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Readings (rad) of the true joint angles ``joints`` (rad)."""
        j = np.asarray(joints, float)
        if self.noise_deg > 0:
            j = j + rng.normal(0.0, np.radians(self.noise_deg), j.shape)
        if self.resolution_deg > 0:
            res = np.radians(self.resolution_deg)
            j = np.round(j / res) * res
        return j

    @property
    def variance(self) -> float:
        """Variance (rad^2) of a reading's error: noise plus uniform quantisation."""
        return np.radians(self.noise_deg) ** 2 + np.radians(self.resolution_deg) ** 2 / 12


def default_truth() -> Any:
    from ...models.params import Parameters
    return Parameters.from_dict(PAPER_SENSOR)


def simulated_calibration(truth: Any = None, *, num_poses: int = 40, pixel_noise: float = 0.1,
                          readout: JointReadout | None = None, robot: Any = None,
                          seed: int = 0) -> Any:
    """Calibrate the way a user would: a simulated checkerboard session of the true sensor
    (:func:`hmlvs.simulate.session`, the paper's set-up) with ``pixel_noise`` px on the stripe
    pixels and the poses computed from noisy joint readings (``readout``), half of the poses
    held out, identified by :func:`hmlvs.calibrate` (PSO + LM from the nominal values, Su
    fixed). Returns the :class:`hmlvs.calibration.result.CalibrationResult`."""
    import warnings

    from ...calibration.solvers import calibrate
    from ...data.dataset import Dataset
    from ...diagnostics.identifiability import HmlvsDataWarning
    from ...geometry.robot import Robot
    from ...sim.sessions import session

    truth = default_truth() if truth is None else truth
    robot = Robot.scorbot_er7() if robot is None else robot
    readout = JointReadout() if readout is None else readout
    rng = np.random.default_rng([seed, 31])
    s = session(truth, robot=robot, num_poses=num_poses, pixel_noise=pixel_noise, seed=seed)
    ds = s.dataset
    readings = readout.read(s.joints, rng)
    noisy = Dataset(ds.pixels, robot.poses(readings)[ds.pose_index], ds.points, ids=ds.ids,
                    joints=readings[ds.pose_index], pose_index=ds.pose_index,
                    meta={**ds.meta, "joint_readout": vars(readout)})
    fit, test = noisy.split(0.5, seed=seed, by_pose=True)
    with warnings.catch_warnings():  # kept in the result's ``warnings``
        warnings.simplefilter("ignore", HmlvsDataWarning)
        return calibrate(fit, test=test, seed=seed)


def params_and_result(calibration: Any, truth: Any, readout: JointReadout, robot: Any,
                       seed: int) -> tuple[Any, Any]:
    """(parameters used to measure, the CalibrationResult or the given calibration)."""
    from ...measurement.measure import sensor_model
    from ...models.paper import PaperSensor

    if calibration is None:
        calibration = simulated_calibration(truth, readout=readout, robot=robot, seed=seed)
    model = sensor_model(calibration)
    if not isinstance(model, PaperSensor):
        raise ValueError("the paper's scenarios simulate the paper's sensor: give a calibration "
                         f"of the paper's model, not of model {model.model!r}")
    return model.params, calibration


class Progress:
    """Calls ``progress(done, total)`` if given; a callable returning False stops the work."""

    def __init__(self, progress: Any, total: int) -> None:
        self.progress, self.total, self.done = progress, total, 0

    def step(self) -> None:
        self.done += 1
        if self.progress is not None and self.progress(self.done, self.total) is False:
            raise KeyboardInterrupt


def surface_normals(params: Any, scene: Scene, pixels: np.ndarray, poses: np.ndarray
                     ) -> np.ndarray:
    """Unit normals of the true surface seen at ``pixels`` from the true ``poses``."""
    from ...models.paper import rays_in_camera
    hfc = hand_from_camera(params)
    bfc = poses @ hfc
    rays = rays_in_camera(params, pixels)
    dirs = np.einsum("nij,nj->ni", bfc[:, :3, :3], rays)
    _, nrm, _ = scene.intersect(bfc[:, :3, 3], dirs)
    return nrm


def point_jacobians(params: Any, pixels: np.ndarray, readings: np.ndarray, robot: Any
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Measured points and their derivatives: (points (n, 3), dP/d(u, v) (n, 3, 2),
    dP/d(joint readings) (n, 3, dof)), by central differences through the model."""
    from ...models.paper import points_in_base
    poses = robot.poses(readings)
    pts, _ = points_in_base(params, pixels, poses, on_invalid="mask")
    jpx = np.empty(pts.shape + (2,))
    for i in range(2):
        step = np.zeros(2)
        step[i] = 0.5
        a, _ = points_in_base(params, pixels + step, poses, on_invalid="mask")
        b, _ = points_in_base(params, pixels - step, poses, on_invalid="mask")
        jpx[:, :, i] = a - b
    dof = readings.shape[1]
    jq = np.empty(pts.shape + (dof,))
    h = 1e-6
    for i in range(dof):
        step = np.zeros(dof)
        step[i] = h
        a, _ = points_in_base(params, pixels, robot.poses(readings + step), on_invalid="mask")
        b, _ = points_in_base(params, pixels, robot.poses(readings - step), on_invalid="mask")
        jq[:, :, i] = (a - b) / (2 * h)
    return pts, jpx, jq
