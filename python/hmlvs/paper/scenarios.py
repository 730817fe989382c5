from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, Sequence

import numpy as np

from .._arrays import as_params
from ..image.stripe_end import locate_stripe_end
from ..models.paper import hand_from_camera
from ..sim.render import RenderedScene, RenderOptions, render_scene
from ..sim.scene import Box, Cylinder, Hole, Scene, Table

# ------------------------------------------------------------------------------------------
# What the scenarios share: the simulated robot readout and an honest calibration

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
    from ..models.params import Parameters
    return Parameters.from_dict(PAPER_SENSOR)


def simulated_calibration(truth: Any = None, *, num_poses: int = 40, pixel_noise: float = 0.1,
                          readout: JointReadout | None = None, robot: Any = None,
                          seed: int = 0) -> Any:
    """Calibrate the way a user would: a simulated checkerboard session of the true sensor
    (:func:`hmlvs.simulate.session`, the paper's set-up) with ``pixel_noise`` px on the stripe
    pixels and the poses computed from noisy joint readings (``readout``), half of the poses
    held out, identified by :func:`hmlvs.calibrate` (PSO + LM from the nominal values, Su
    fixed). Returns the :class:`hmlvs.CalibrationResult`."""
    import warnings

    from ..calibration.solvers import calibrate
    from ..data.dataset import Dataset
    from ..diagnostics.identifiability import HmlvsDataWarning
    from ..geometry.robot import Robot
    from ..sim.sessions import session

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


def _params_and_result(calibration: Any, truth: Any, readout: JointReadout, robot: Any,
                       seed: int) -> tuple[Any, Any]:
    """(parameters used to measure, the CalibrationResult or the given calibration)."""
    from ..measurement.measure import sensor_model
    from ..models.paper import PaperSensor

    if calibration is None:
        calibration = simulated_calibration(truth, readout=readout, robot=robot, seed=seed)
    model = sensor_model(calibration)
    if not isinstance(model, PaperSensor):
        raise ValueError("the paper's scenarios simulate the paper's sensor: give a calibration "
                         f"of the paper's model, not of model {model.model!r}")
    return model.params, calibration


class _Progress:
    """Calls ``progress(done, total)`` if given; a callable returning False stops the work."""

    def __init__(self, progress: Any, total: int) -> None:
        self.progress, self.total, self.done = progress, total, 0

    def step(self) -> None:
        self.done += 1
        if self.progress is not None and self.progress(self.done, self.total) is False:
            raise KeyboardInterrupt


def _rendered_records(frames: list[RenderedScene], readings: np.ndarray, ids: list[str]
                      ) -> list[dict[str, Any]]:
    return [{"id": i, "on": f.on, "off": f.off, "joints": r.tolist()}
            for i, f, r in zip(ids, frames, readings)]


@contextmanager
def _scan_folder(out_dir: Any) -> Iterator[Path | None]:
    """A temporary folder whose files take their places in ``out_dir`` when the block ends
    without an error (:func:`hmlvs._io.atomic_folder`, the manifest last); None without
    ``out_dir``."""
    if out_dir is None:
        yield None
        return
    from .._io import atomic_folder

    with atomic_folder(out_dir, last=("manifest.json", "gauge_block.json")) as tmp:
        yield tmp


def _write_scan(out_dir: Any, ids: list[str], frames: list[RenderedScene],
                readings: np.ndarray, image_size: tuple[int, int], robot: Any,
                **extra: Any) -> Any:
    from ..data.manifest import write_image_manifest
    return write_image_manifest(out_dir, ids, [f.on for f in frames], [f.off for f in frames],
                                readings, image_size, robot.name, **extra)


def _scene_to_dict(scene: Scene) -> dict[str, Any]:
    from dataclasses import asdict
    return {"primitives": [{"type": type(p).__name__, **asdict(p)} for p in scene.primitives],
            "light": list(scene.light), "ambient_fraction": scene.ambient_fraction}


def _surface_normals(params: Any, scene: Scene, pixels: np.ndarray, poses: np.ndarray
                     ) -> np.ndarray:
    """Unit normals of the true surface seen at ``pixels`` from the true ``poses``."""
    from ..models.paper import rays_in_camera
    hfc = hand_from_camera(params)
    bfc = poses @ hfc
    rays = rays_in_camera(params, pixels)
    dirs = np.einsum("nij,nj->ni", bfc[:, :3, :3], rays)
    _, nrm, _ = scene.intersect(bfc[:, :3, 3], dirs)
    return nrm


def _point_jacobians(params: Any, pixels: np.ndarray, readings: np.ndarray, robot: Any
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Measured points and their derivatives: (points (n, 3), dP/d(u, v) (n, 3, 2),
    dP/d(joint readings) (n, 3, dof)), by central differences through the model."""
    from ..models.paper import points_in_base
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


# ------------------------------------------------------------------------------------------
# Fig. 13: a scan of a cylinder with holes


def cylinder_scene(radius: float = 50.0, length: float = 200.0,
                   centre: tuple[float, float] = (500.0, 0.0), bore: float = 42.0,
                   holes: Sequence[Hole] | None = None, table: Table | None = None) -> Scene:
    """A tube lying on the table along base y (axis at ``centre`` = (x, y), height
    ``radius``), 8 mm wall by default, with three holes through the wall of 20, 15 and 25 mm
    diameter: on top, 35 deg to one side and 30 deg to the other."""
    if holes is None:
        holes = (Hole(-55.0, 0.0, 10.0), Hole(0.0, np.radians(35.0), 7.5),
                 Hole(55.0, np.radians(-30.0), 12.5))
    cyl = Cylinder((float(centre[0]), float(centre[1]), float(radius)), radius, length, "y",
                   bore=bore, holes=tuple(holes))
    return Scene((Table() if table is None else table, cyl))


@dataclass(frozen=True)
class HoleCheck:
    """Whether a hole shows as a gap in the scan.

    ``surface_inside``: measured points on the outer surface (within ``tolerance`` mm of
    radius R) whose position lies inside the hole's rim shrunk by ``margin`` mm; 0 for a gap.
    ``below_inside``: points inside the rim but below the surface (the hole's wall, what is
    seen through it). ``ring``: points on the outer surface in a 4 mm ring around the rim
    (beyond ``margin``), showing the scan did cross the hole's surroundings.
    """

    index: int
    hole: Hole
    surface_inside: int
    below_inside: int
    ring: int

    @property
    def is_gap(self) -> bool:
        return self.ring > 0 and self.surface_inside == 0


@dataclass(frozen=True)
class CylinderScan:
    """The result of :func:`cylinder_scan` (all lengths in mm).

    ``rms_mm`` is the RMS distance of every measured point to the true scene surface,
    ``expected_rms_mm`` what the simulated noise predicts for it: per point, the normal
    component of the calibration's own error there (exact, the truth is known), of the
    stripe centre's noise (the extractor's 1-sigma, through the model) and of the joint
    readout noise (through the kinematics); ``expected_parts`` gives each part's RMS.
    """

    cloud: Any
    scene: Scene
    truth: Any
    params: Any
    calibration: Any
    joints: np.ndarray
    readings: np.ndarray
    distance: np.ndarray
    surface: np.ndarray
    rms_mm: float
    rms_cylinder_mm: float
    rms_table_mm: float
    on_cylinder: int
    on_table: int
    outliers: int
    expected_rms_mm: float
    expected_parts: dict[str, float]
    holes: tuple[HoleCheck, ...]
    rejected: dict[str, str]
    files: dict[str, Any] = field(default_factory=dict)
    seconds: float = 0.0

    @property
    def num_points(self) -> int:
        return int(self.cloud.num_valid)

    def to_dict(self) -> dict[str, Any]:
        return {
            "scenario": "cylinder", "images": int(self.joints.shape[0]),
            "points": self.num_points, "rms_mm": self.rms_mm,
            "rms_cylinder_mm": self.rms_cylinder_mm, "rms_table_mm": self.rms_table_mm,
            "expected_rms_mm": self.expected_rms_mm, "expected_parts_mm": self.expected_parts,
            "on_cylinder": self.on_cylinder, "on_table": self.on_table,
            "fraction_cylinder": self.on_cylinder / max(self.num_points, 1),
            "fraction_table": self.on_table / max(self.num_points, 1),
            "outliers_over_1mm": self.outliers,
            "holes": [{"index": h.index, "diameter_mm": 2 * h.hole.radius,
                       "surface_points_inside": h.surface_inside,
                       "points_below_surface_inside": h.below_inside,
                       "surface_points_around": h.ring, "gap": h.is_gap} for h in self.holes],
            "calibration_test_rms_mm": getattr(self.calibration, "test_rms", None),
            "rejected": self.rejected, "files": {k: str(v) for k, v in self.files.items()},
            "seconds": self.seconds,
        }

    def summary(self) -> str:
        n = max(self.num_points, 1)
        p = self.expected_parts
        lines = [
            f"cylinder scan: {self.joints.shape[0]} image pairs, {self.num_points} points "
            f"({100 * self.on_cylinder / n:.1f}% on the cylinder, {100 * self.on_table / n:.1f}%"
            f" on the table)",
            f"RMS distance to the true surface: {self.rms_mm:.3f} mm (cylinder "
            f"{self.rms_cylinder_mm:.3f}, table {self.rms_table_mm:.3f}); "
            f"{self.outliers} points farther than 1 mm",
            f"expected from the simulated noise: {self.expected_rms_mm:.3f} mm (calibration "
            f"{p['calibration']:.3f}, stripe pixels {p['pixels']:.3f}, joint readout "
            f"{p['joints']:.3f})",
        ]
        for h in self.holes:
            lines.append(
                f"hole {h.index} ({2 * h.hole.radius:g} mm): {h.surface_inside} surface points "
                f"inside the rim, {h.below_inside} below it (wall / seen through), {h.ring} "
                f"around it: {'a gap' if h.is_gap else 'NOT a gap' if h.ring else 'not scanned'}")
        if self.rejected:
            lines.append("rejected image pairs: " + "; ".join(f"{k}: {v}" for k, v in
                                                                self.rejected.items()))
        return "\n".join(lines)


def _hole_checks(cyl: Cylinder, points: np.ndarray, margin: float = 1.0,
                 tolerance: float = 1.0) -> tuple[HoleCheck, ...]:
    pl = cyl.local(points)
    rad = np.hypot(pl[:, 0], pl[:, 1])
    surface = np.abs(rad - cyl.radius) < tolerance
    out = []
    for k, (hd, s, r, _) in enumerate(cyl._hole_geometry()):
        a = pl[:, 0] * hd[0] + pl[:, 1] * hd[1]
        q = np.linalg.norm(pl - a[:, None] * hd - np.array([0.0, 0.0, s]), axis=1)
        inside = q < r - margin
        front = a > 0
        out.append(HoleCheck(
            k, cyl.holes[k], int(np.sum(inside & surface & front)),
            int(np.sum(inside & (rad < cyl.radius - tolerance))),
            int(np.sum(front & surface & (q > r + margin) & (q < r + margin + 4.0)))))
    return tuple(out)


def cylinder_scan(calibration: Any = None, truth: Any = None, *, seed: int = 0,
                  out_dir: Any = None, scene: Scene | None = None, step: float = 3.0,
                  standoff: float | None = None, image_size: tuple[int, int] = (640, 480),
                  options: RenderOptions | None = None, readout: JointReadout | None = None,
                  robot: Any = None, span: tuple[float, float] | None = None,
                  progress: Any = None, plot: bool = True) -> CylinderScan:
    """Fig. 13: scan a cylinder with holes lying on the table, measure it from the images.

    The sensor moves along the cylinder's axis, looking straight down from ``standoff`` mm
    above its top (default ``H / tan(theta)``, where the stripe crosses the image centre),
    the stripe across the axis, one laser on/off pair every ``step`` mm. The pairs are
    rendered with the ``truth`` sensor at the true joint angles; the joint readings stored
    with them carry the ``readout`` noise. The scan is measured with
    :func:`hmlvs.measure.measure_images` using ``calibration`` (default: an honest one from
    :func:`simulated_calibration`) and compared with the scene.

    Parameters
    ----------
    calibration : Calibration, CalibrationResult or Parameters to measure with; None
        calibrates a simulated noisy checkerboard session of ``truth``
    truth : the true sensor (default :data:`PAPER_SENSOR`, the paper's identified one)
    seed : seeds the calibration session, the readout noise and the image noise
    out_dir : folder for the images and ``manifest.json``, ``cloud.ply`` and ``cloud.png``
        (Fig. 13); None keeps everything in memory
    scene : a :class:`Scene` with one horizontal :class:`Cylinder` (default
        :func:`cylinder_scene`)
    step : scan step along the axis (mm)
    span : scanned interval along the axis from the cylinder's centre (mm); default the
        whole length plus 5 mm each side
    options : :class:`hmlvs.simulate.RenderOptions` (default: sensor noise 1 grey level)
    progress : callable ``(done, total)`` per rendered pair; returning False stops
    plot : write ``cloud.png`` when ``out_dir`` is given
    """
    from pathlib import Path
    import time

    from ..geometry.robot import Robot
    from ..image.scan import stripes_from_images
    from ..measurement.measure import measure_images
    from ..models.paper import points_in_base
    from ..models.params import Parameters
    from ..sim.sessions import ik_look_at

    start = time.perf_counter()
    truth = default_truth() if truth is None else truth
    q_true = as_params(truth)
    robot = Robot.scorbot_er7() if robot is None else robot
    readout = JointReadout() if readout is None else readout
    options = RenderOptions(noise=1.0) if options is None else options
    scene = cylinder_scene() if scene is None else scene
    cyls = [p for p in scene.primitives if isinstance(p, Cylinder)]
    if len(cyls) != 1:
        raise ValueError(f"cylinder_scan needs a scene with exactly one Cylinder, got "
                         f"{len(cyls)}")
    cyl = cyls[0]
    if cyl.axis == "z":
        raise ValueError("cylinder_scan scans a cylinder lying on the table (axis 'x' or "
                         "'y'); this one stands upright (axis 'z')")
    if not (np.isfinite(step) and step > 0):
        raise ValueError(f"step must be a positive number of mm, got {step}")
    params, cal = _params_and_result(calibration, truth, readout, robot, seed)
    q_plan = as_params(params)
    hfc = hand_from_camera(q_plan)
    if standoff is None:
        standoff = q_plan[6] / np.tan(q_plan[7])
    axis = cyl.frame[:, 2]
    cam_x = np.cross(axis, [0.0, 0.0, 1.0])
    lo, hi = span if span is not None else (-cyl.length / 2 - 5.0, cyl.length / 2 + 5.0)
    if not hi > lo:
        raise ValueError(f"span must be (start, end) with end > start, got {span}")
    s_values = np.arange(lo, hi + 1e-9, step)
    top = np.asarray(cyl.centre) + np.array([0.0, 0.0, cyl.radius])
    joints = []
    prev = HOME
    for s in s_values:
        pos = top + s * axis + np.array([0.0, 0.0, standoff])
        j = ik_look_at(robot, hfc, pos, np.array([0.0, 0.0, -1.0]), [prev, HOME], cam_x=cam_x)
        if j is None:
            raise ValueError(f"the scan position {np.round(pos, 1).tolist()} mm (camera "
                             f"{standoff:.0f} mm above the cylinder) is out of the robot's "
                             "reach; move the cylinder or change standoff")
        joints.append(j)
        prev = j
    joints = np.array(joints)
    rng = np.random.default_rng([seed, 11])
    readings = readout.read(joints, rng)
    poses = robot.poses(joints)
    ids = [f"p{i:03d}" for i in range(len(joints))]
    bar = _Progress(progress, len(joints))
    frames = []
    for pose in poses:
        frames.append(render_scene(q_true, pose, scene, image_size, options, rng))
        bar.step()
    files: dict[str, Any] = {}
    # the images, manifest, cloud and plot as one folder: a run stopped while writing
    # leaves none of them
    with _scan_folder(out_dir) as where:
        if where is not None:
            source = _write_scan(where, ids, frames, readings, image_size, robot,
                                 scene=_scene_to_dict(scene), scenario="cylinder")
            files["manifest"] = Path(out_dir) / "manifest.json"
        else:
            source = _rendered_records(frames, readings, ids)
        measured = measure_images(params, source, robot=robot)
        cloud = measured.cloud
        _, stripes, _, _ = stripes_from_images(source, robot=robot)
        sigma_v = np.concatenate([s_.sigma[s_.found] for s_ in stripes])
        if sigma_v.shape[0] != len(cloud):  # pragma: no cover - the same extraction twice
            raise RuntimeError("stripe centres and measured points do not line up")
        valid = cloud.valid
        pts = cloud.points[valid]
        px = cloud.pixels[valid]
        pidx = cloud.pose_index[valid]
        sigma_v = sigma_v[valid]
        dist_all = scene.distances(pts)
        dist = dist_all.min(axis=1)
        nearest = dist_all.argmin(axis=1)
        icyl = scene.primitives.index(cyl)
        itab = next((i for i, p in enumerate(scene.primitives) if isinstance(p, Table)), -1)
        on_c, on_t = nearest == icyl, nearest == itab

        def rms(x: np.ndarray) -> float:
            return float(np.sqrt(np.mean(np.square(x)))) if x.size else float("nan")

        # what the noise predicts, per point, along the true surface normal
        nrm = _surface_normals(q_true, scene, px, poses[pidx])
        _, jpx, jq = _point_jacobians(params, px, readings[pidx], robot)
        p_cal, _ = points_in_base(params, px, robot.poses(readings[pidx]), on_invalid="mask")
        p_true, _ = points_in_base(q_true, px, robot.poses(readings[pidx]), on_invalid="mask")
        e_cal = np.einsum("ni,ni->n", nrm, p_cal - p_true)
        # the stripe centre's noise is along v (one centre per column)
        e_px = sigma_v * np.abs(np.einsum("ni,ni->n", nrm, jpx[:, :, 1]))
        e_q = np.sqrt(readout.variance * np.sum(np.einsum("ni,nij->nj", nrm, jq) ** 2, axis=1))
        parts = {"calibration": rms(e_cal), "pixels": rms(e_px), "joints": rms(e_q)}
        expected = float(np.sqrt(sum(v ** 2 for v in parts.values())))
        if where is not None:
            cloud.save(where / "cloud.ply")
            files["cloud"] = Path(out_dir) / "cloud.ply"
            if plot:
                plot_cloud(pts, where / "cloud.png", title=f"cylinder scan: {len(pts)} points, "
                           f"RMS to the surface {rms(dist):.3f} mm")
                files["plot"] = Path(out_dir) / "cloud.png"
    return CylinderScan(
        cloud=cloud, scene=scene, truth=Parameters.from_array(q_true),
        params=Parameters.from_array(q_plan), calibration=cal, joints=joints,
        readings=readings, distance=dist, surface=nearest, rms_mm=rms(dist),
        rms_cylinder_mm=rms(dist[on_c]), rms_table_mm=rms(dist[on_t]),
        on_cylinder=int(on_c.sum()), on_table=int(on_t.sum()), outliers=int(np.sum(dist > 1.0)),
        expected_rms_mm=expected, expected_parts=parts, holes=_hole_checks(cyl, pts),
        rejected=measured.rejected_reasons, files=files, seconds=time.perf_counter() - start)


def plot_cloud(points: np.ndarray, path: Any, title: str = "", elev: float = 40.0,
               azim: float = -115.0) -> Any:
    """A 3D scatter of points (mm) coloured by height, like the paper's Fig. 13; PNG."""
    import matplotlib
    matplotlib.use("Agg")
    from pathlib import Path

    import matplotlib.pyplot as plt

    from .._io import atomic_write

    pts = np.asarray(points, float)
    fig = plt.figure(figsize=(8, 6), dpi=110)
    ax = fig.add_subplot(projection="3d")
    sc = ax.scatter(pts[:, 0], pts[:, 1], pts[:, 2], c=pts[:, 2], s=0.3, cmap="jet",
                    linewidths=0)
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_zlabel("z (mm)")
    span = np.ptp(pts, axis=0)
    ax.set_box_aspect(np.maximum(span, 1e-3 + 0.05 * span.max()))
    ax.view_init(elev=elev, azim=azim)
    fig.colorbar(sc, ax=ax, shrink=0.6, label="height z (mm)")
    if title:
        ax.set_title(title, fontsize=9)
    path = Path(path)
    with atomic_write(path, "wb") as fh:
        fig.savefig(fh, format="png", bbox_inches="tight")
    plt.close(fig)
    return path


# ------------------------------------------------------------------------------------------
# Table 3: the gauge-block check

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
    from ..models.paper import pixels_from_points
    from ..sim.sessions import ik_look_at, snap_to_pose_grid

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
    from pathlib import Path
    import time

    from ..geometry.robot import Robot
    from ..models.paper import pixels_from_points, points_in_base, project
    from ..models.params import Parameters

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
    params, cal = _params_and_result(calibration, truth, readout, robot, seed)
    q_plan = as_params(params)
    hfc_plan = hand_from_camera(q_plan)
    if standoff is None:
        standoff = q_plan[6] / np.tan(q_plan[7])
    centre = (np.asarray(block.lo) + np.asarray(block.hi)) / 2
    paper = {row[0]: row for row in PAPER_TABLE3}
    is_paper_block = block == GAUGE_BLOCK
    rng = np.random.default_rng([seed, 23])
    noise_rng = np.random.default_rng([seed, 29])
    bar = _Progress(progress, trials * len(names))
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
            pts, jpx, jq = _point_jacobians(q_plan, end.pixel[None], reading[None], robot)
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
    with _scan_folder(out_dir) as where:
        if where is not None:
            import json

            from .._io import atomic_write

            _write_scan(where, all_ids, all_frames, np.array(all_readings), image_size, robot,
                        scene=_scene_to_dict(scene), scenario="gauge-block")
            files["manifest"] = Path(out_dir) / "manifest.json"
            with atomic_write(where / "gauge_block.json") as fh:
                json.dump(check.to_dict(), fh, indent=1, default=float)
            files["results"] = Path(out_dir) / "gauge_block.json"
    return check

