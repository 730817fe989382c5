"""Scanning a cylinder with holes (a measurement scenario beyond the paper)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ..._arrays import as_params
from ...models.paper import hand_from_camera
from ...sim.render import RenderOptions, render_scene
from ...sim.scene import Cylinder, Hole, Scene, Table
from .common import (
    HOME,
    JointReadout,
    Progress,
    default_truth,
    params_and_result,
    point_jacobians,
    surface_normals,
)
from .files import rendered_records, scan_folder, scene_to_dict, write_scan


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
    import time

    from ...geometry.robot import Robot
    from ...image.scan import stripes_from_images
    from ...measurement.measure import measure_images
    from ...models.paper import points_in_base
    from ...models.params import Parameters
    from ...sim.sessions import ik_look_at

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
    params, cal = params_and_result(calibration, truth, readout, robot, seed)
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
    bar = Progress(progress, len(joints))
    frames = []
    for pose in poses:
        frames.append(render_scene(q_true, pose, scene, image_size, options, rng))
        bar.step()
    files: dict[str, Any] = {}
    # the images, manifest, cloud and plot as one folder: a run stopped while writing
    # leaves none of them
    with scan_folder(out_dir) as where:
        if where is not None:
            source = write_scan(where, ids, frames, readings, image_size, robot,
                                 scene=scene_to_dict(scene), scenario="cylinder")
            files["manifest"] = Path(out_dir) / "manifest.json"
        else:
            source = rendered_records(frames, readings, ids)
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
        nrm = surface_normals(q_true, scene, px, poses[pidx])
        _, jpx, jq = point_jacobians(params, px, readings[pidx], robot)
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

    import matplotlib.pyplot as plt

    from ..._io import atomic_write

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
