"""The verdict on a calibration: can it be trusted, why (or why not), and the likely mistake.

A calibration tool's worst failure is a wrong calibration reported as fine. Residual RMS
alone does not tell: a wrong board square or inverted robot poses are absorbed by the camera
and the hand-eye transform and leave residuals that look merely "large". So every
calibration gets named checks, each with its value, its limit and why that limit
(:class:`Check`), and a :class:`Verdict`: trustworthy only when every check passes.

When a check fails, :func:`find_mistake` tries the usual culprits on the observations
(the board square, the robot positions' unit, inverted poses, the quaternion order, views
whose board pose disagrees with the rest) by re-running a cheap chain fit under each
hypothesis (the free-pose board estimates of Zhang's calibration, the closed-form hand-eye
transform and the board's mean pose in the base) and says which one explains the data, with
the next action.

The limits are physical, not tuned to a scene: corner detectors locate corners to a few
hundredths to a few tenths of a pixel; a laser fit is judged against the stripe's own
measured noise carried to millimetres; a robot's absolute accuracy is a fraction of a
millimetre. Each limit's reason is written beside it and travels with the check.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math
from typing import Any, Callable, Sequence

import numpy as np

from .. import _core
from .._arrays import robust_sigma
from ..calibration.joint import (
    POSE_DISAGREEMENT,
    _board_plane_points,
    _inv,
    _rotation_angle,
    consistent_numbering,
    initial_intrinsics,
)
from ..geometry.board import BoardSpec, board_pose_from_corners

#: corners through the robot chain (px RMS): detectors reach 0.02-0.3 px on sharp boards, so a
#: correct model and correct poses stay well below 1 px; beyond it the poses, the board or the
#: model do not fit the images
CORNER_RMS_LIMIT_PX = 1.0
#: the laser residual RMS may exceed the stripe's own noise carried to mm by this factor (the
#: laser residuals also carry the board-pose error and the stripe's bias at albedo steps)
LASER_NOISE_FACTOR = 3.0
#: floor of the laser limit (mm): below it the stripe noise estimate itself is unreliable
LASER_FLOOR_MM = 0.02
#: per-view board-in-base estimates (through the chain, each from its own corners) may
#: scatter by this RMS: a robot's absolute accuracy (0.1-1 mm for industrial arms) plus the
#: board pose from one view's corners; the board must not move
BOARD_SPREAD_MM = 2.0
BOARD_SPREAD_DEG = 0.5
#: the image is cut into this many cells (columns, rows) to measure coverage
COVERAGE_GRID = (8, 6)
#: fraction of the cells with a corner: outside the corners' area the distortion is
#: extrapolated (a quarter of the image is the least that keeps the distortion terms bound)
CORNER_COVERAGE_MIN = 0.25
#: fraction of the cells crossed by the stripe: outside them measurements rest on the
#: extrapolated plane and distortion
STRIPE_COVERAGE_MIN = 0.10
#: the camera's rotations must vary about at least two axes (hand-eye needs two
#: non-parallel rotation axes, Tsai and Lenz); the RMS rotation about the second best
#: spanned axis, degrees
POSE_VARIETY_MIN_DEG = 5.0


@dataclass(frozen=True)
class Check:
    """One named check: its value, its limit, whether it passed and why that limit."""

    name: str
    value: float
    limit: float
    ok: bool
    why: str
    unit: str = ""
    #: the sentence a technician reads when the check fails
    problem: str = ""
    #: "max" (value must stay at or below the limit) or "min" (at or above)
    kind: str = "max"

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "value": _num(self.value), "limit": _num(self.limit),
                "ok": bool(self.ok), "unit": self.unit, "kind": self.kind, "why": self.why}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "Check":
        return cls(name=str(d["name"]), value=_float(d.get("value")),
                   limit=_float(d.get("limit")), ok=bool(d["ok"]), why=str(d.get("why", "")),
                   unit=str(d.get("unit", "")), kind=str(d.get("kind", "max")))


def _num(x: float) -> float | None:
    return float(x) if x is not None and math.isfinite(x) else None


def _float(x: Any) -> float:
    return float("nan") if x is None else float(x)


@dataclass
class Verdict:
    """trustworthy: every check passed; reasons: one sentence per failed check, the likely
    mistake first; map_sigma_mm: the predicted 3D uncertainty over the laser line's image
    footprint ({"rms", "p95"}, mm), None when not computed."""

    trustworthy: bool
    reasons: list[str]
    checks: list[Check]
    map_sigma_mm: dict[str, float] | None = None
    likely_mistake: str | None = None
    #: the two halves' maps' difference ({"rms", "p95"}, mm), None when not computed
    cross_validation_mm: dict[str, float] | None = None
    #: the uncertainty map (k, 3): pixel u, v and predicted 3D standard deviation (mm) over
    #: the laser line's footprint; not stored in files
    map_points: np.ndarray | None = field(default=None, repr=False, compare=False)
    #: the image size (w, h) the map's pixels belong to
    image_size: tuple[int, int] | None = field(default=None, repr=False, compare=False)

    def to_dict(self) -> dict[str, Any]:
        return {"trustworthy": bool(self.trustworthy), "reasons": list(self.reasons),
                "checks": [c.to_dict() for c in self.checks],
                "map_sigma_mm": None if self.map_sigma_mm is None else
                {k: _num(v) for k, v in self.map_sigma_mm.items()},
                "cross_validation_mm": None if self.cross_validation_mm is None else
                {k: _num(v) for k, v in self.cross_validation_mm.items()},
                "likely_mistake": self.likely_mistake}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "Verdict":
        ms = d.get("map_sigma_mm")
        cv = d.get("cross_validation_mm")
        return cls(trustworthy=bool(d["trustworthy"]), reasons=[str(r) for r in
                                                                  d.get("reasons") or []],
                   checks=[Check.from_dict(c) for c in d.get("checks") or []],
                   map_sigma_mm=None if ms is None else {k: _float(v) for k, v in ms.items()},
                   likely_mistake=d.get("likely_mistake"),
                   cross_validation_mm=None if cv is None else
                   {k: _float(v) for k, v in cv.items()})

    def text(self) -> str:
        """The verdict in words a technician reads first."""
        if self.trustworthy:
            lines = ["VERDICT: this calibration can be trusted: every check passed."]
        else:
            lines = ["VERDICT: this calibration is NOT to be trusted:"]
            lines += [f"  - {r}" for r in self.reasons]
        if self.map_sigma_mm is not None:
            lines.append(f"predicted 3D uncertainty of measured points: "
                         f"{self.map_sigma_mm['rms']:.3f} mm RMS, "
                         f"{self.map_sigma_mm['p95']:.3f} mm at the 95th percentile")
        if self.cross_validation_mm is not None:
            lines.append(f"calibrated on two halves of the views, the maps differ by "
                         f"{self.cross_validation_mm['rms']:.3f} mm RMS, "
                         f"{self.cross_validation_mm['p95']:.3f} mm at the 95th percentile")
        for c in self.checks:
            rel = "<=" if c.kind == "max" else ">="
            lines.append(f"  {'ok  ' if c.ok else 'FAIL'} {c.name}: {c.value:.4g} {c.unit} "
                         f"(limit {rel} {c.limit:.4g} {c.unit})".replace("  (", " ("))
        return "\n".join(lines)


def _check(name: str, value: float, limit: float, unit: str, why: str, problem: str,
           kind: str = "max") -> Check:
    ok = bool(value <= limit) if kind == "max" else bool(value >= limit)
    return Check(name, float(value), float(limit), ok, why, unit, problem, kind)


# -- the checks of a joint (opencv-model) calibration ----------------------------------------

def _camera_from_board(result: Any, view: Any) -> np.ndarray | None:
    s = result.sensor
    if result.mode == "chain":
        return _inv(s.hand_from_camera) @ _inv(np.asarray(view.base_from_hand, float)) \
            @ s.base_from_board
    return result.camera_from_board.get(view.id)


def stripe_noise_px(pixel_sets: Sequence[np.ndarray], degree: int = 5) -> float:
    """The stripe's own noise (px, in the row direction): per view, the robust scatter of its
    rows about a smooth curve (a polynomial of ``degree`` in the column: a straight laser
    line on a flat board, bent by the lens distortion), pooled over the views. It holds
    the detector's noise and its local biases (speckle, albedo steps), not the
    calibration's."""
    res = []
    for px in pixel_sets:
        px = np.asarray(px, float).reshape(-1, 2)
        if len(px) < 3 * (degree + 1):
            continue
        u, v = px[:, 0], px[:, 1]
        x = (u - u.mean()) / max(float(np.ptp(u)), 1.0)
        coef = np.polyfit(x, v, degree)
        res.append(v - np.polyval(coef, x))
    r = np.concatenate(res) if res else np.empty(0)
    return robust_sigma(r) if r.size >= 10 else float("nan")


def _laser_sensitivity(result: Any, views: Sequence[Any]) -> np.ndarray:
    """Per used stripe pixel, the change (mm) of its distance from the laser plane when it
    moves by one pixel along the image rows: the stripe noise's effect on a laser residual."""
    s = result.sensor
    intr = s.intrinsics_vector()
    plane = np.asarray(s.laser_plane, float)
    out = []
    for v in views:
        px = result.residuals.get(v.id, {}).get("laser_pixels")
        if px is None or len(px) == 0:
            continue
        cb = _camera_from_board(result, v)
        if cb is None:
            continue
        p0, _ = _board_plane_points(intr, cb, px)
        p1, _ = _board_plane_points(intr, cb, px + [0.0, 1.0])
        d = np.abs((p1 - p0) @ plane[:3])
        out.append(d[np.isfinite(d)])
    return np.concatenate(out) if out else np.empty(0)


def _coverage(pixels: Sequence[np.ndarray], image_size: tuple[int, int]) -> float:
    """Fraction of the image's :data:`COVERAGE_GRID` cells holding at least one pixel."""
    gx, gy = COVERAGE_GRID
    w, h = image_size
    hit = np.zeros((gy, gx), bool)
    for px in pixels:
        px = np.asarray(px, float).reshape(-1, 2)
        px = px[np.isfinite(px).all(axis=1)]
        if len(px) == 0:
            continue
        i = np.clip((px[:, 0] / w * gx).astype(int), 0, gx - 1)
        j = np.clip((px[:, 1] / h * gy).astype(int), 0, gy - 1)
        hit[j, i] = True
    return float(hit.mean())


def _rotation_vector(r: np.ndarray) -> np.ndarray:
    import cv2

    return cv2.Rodrigues(np.asarray(r, float))[0].ravel()


def pose_variety_deg(rotations: Sequence[np.ndarray]) -> float:
    """The RMS relative rotation (degrees) about the second best spanned axis over all pairs
    of views: 0 when every view turns about one axis only."""
    rv = [_rotation_vector(a @ b.T) for k, a in enumerate(rotations) for b in rotations[k + 1:]]
    if not rv:
        return 0.0
    m = np.asarray(rv).T @ np.asarray(rv) / len(rv)
    ev = np.sort(np.linalg.eigvalsh(m))[::-1]
    return math.degrees(math.sqrt(max(ev[1], 0.0)))


def _flip_index(board: BoardSpec, idx: np.ndarray, flipped: bool) -> np.ndarray:
    return board.rows * board.cols - 1 - idx if flipped else idx


def board_spread(result: Any, views: Sequence[Any], board: BoardSpec
                 ) -> dict[str, tuple[float, float]]:
    """Per view with corners: how far its own board-in-base estimate (its corners'
    ``solvePnP`` with the calibrated camera, carried through its robot pose and the hand-eye
    transform) lies from the calibration's one board pose: (mm at the board's centre,
    degrees)."""
    s = result.sensor
    centre = np.array([(board.rows - 1) * board.square / 2, (board.cols - 1) * board.square / 2,
                       0.0, 1.0])
    out = {}
    for v in views:
        if v.id not in result.per_view or len(v.corner_index) < 6 or v.base_from_hand is None:
            continue
        idx = _flip_index(board, np.asarray(v.corner_index, int), v.id in result.flipped)
        cb = board_pose_from_corners(board.points(idx), v.corner_pixels, s.camera_matrix,
                                     s.dist_coeffs)
        if cb is None:
            continue
        bib = np.asarray(v.base_from_hand, float) @ s.hand_from_camera @ cb
        dt = float(np.linalg.norm((bib @ centre - s.base_from_board @ centre)[:3]))
        da = math.degrees(_rotation_angle(bib[:3, :3] @ s.base_from_board[:3, :3].T))
        out[v.id] = (dt, da)
    return out


def joint_checks(result: Any, views: Sequence[Any], board: Any) -> list[Check]:
    """The checks of a general-model calibration (:class:`JointCalibration`) on the views it
    was given (rejected ones included, to count them)."""
    board = BoardSpec.of(board)
    checks: list[Check] = []
    chain = result.mode == "chain"
    cr = result.corner_rms_px
    where = "through the robot chain" if chain else "with each view's board pose free"
    checks.append(_check(
        "corner_rms", cr, CORNER_RMS_LIMIT_PX, "px",
        "corner detectors locate corners to a few hundredths to a few tenths of a pixel; "
        "beyond 1 px the poses, the board or the camera model do not fit the images",
        f"the board corners lie {cr:.2f} px RMS from their detections {where}, more than "
        f"the {CORNER_RMS_LIMIT_PX:g} px a correct calibration leaves"))
    free = getattr(result, "free_rms_px", None)
    if chain and free is not None and math.isfinite(free):
        ratio = cr / max(free, 0.05)
        checks.append(_check(
            "chain_vs_free_corner_rms", ratio, POSE_DISAGREEMENT, "",
            "with correct robot poses the chain fits the corners about as well as Zhang's "
            "calibration with every view's board pose free (renders: within 10 %)",
            f"the robot chain fits the corners {ratio:.1f} times worse than each view's own "
            f"board pose ({cr:.2f} against {free:.2f} px): the robot poses disagree with the "
            "images"))
    used = [v for v in views if v.id in result.per_view]
    laser_sets = [result.residuals[v.id]["laser_pixels"] for v in used
                  if v.id in result.residuals]
    sigma_px = stripe_noise_px(laser_sets)
    sens = _laser_sensitivity(result, used)
    if sens.size and math.isfinite(sigma_px):
        expected = sigma_px * float(np.sqrt(np.mean(sens**2)))
        limit = max(LASER_NOISE_FACTOR * expected, LASER_FLOOR_MM)
        lr = result.laser_rms_mm
        checks.append(_check(
            "laser_rms", lr, limit, "mm",
            f"the stripe's own noise ({sigma_px:.3f} px, its rows' scatter about a smooth "
            f"curve) carried to mm is {expected:.4f} mm; a correct calibration leaves at most "
            f"{LASER_NOISE_FACTOR:g} times that (board-pose error, stripe bias at albedo "
            f"steps), and never asks less than {LASER_FLOOR_MM:g} mm",
            f"the stripe points lie {lr:.3f} mm RMS from the laser plane, more than the "
            f"{limit:.3f} mm the stripe's own noise explains"))
    if chain:
        spread = board_spread(result, used, board)
        if spread:
            dt = np.array([a for a, _ in spread.values()])
            da = np.array([b for _, b in spread.values()])
            rt, ra = float(np.sqrt(np.mean(dt**2))), float(np.sqrt(np.mean(da**2)))
            worst = sorted(spread, key=lambda k: -spread[k][0])[:3]
            checks.append(_check(
                "board_spread_mm", rt, BOARD_SPREAD_MM, "mm",
                "each view's board pose carried to the base must land on the one board: a "
                "robot's absolute accuracy (0.1-1 mm) plus one view's pose error",
                f"the views put the board {rt:.2f} mm RMS apart in the robot base (most: "
                f"{', '.join(worst)}): the board moved or the poses do not match the images"))
            checks.append(_check(
                "board_spread_deg", ra, BOARD_SPREAD_DEG, "deg",
                "as board_spread_mm, for the board's orientation (a robot's orientation "
                "accuracy is a few hundredths of a degree)",
                f"the views turn the board {ra:.2f} degrees RMS apart in the robot base"))
        n_rej = len(result.rejected)
        checks.append(_check(
            "views_rejected", n_rej, 0, "views",
            "a view is rejected when its board's orientation fits its robot pose under neither "
            "corner numbering: its image and its pose disagree",
            f"{n_rej} view(s) were left out because their images disagree with their robot "
            f"poses ({', '.join(result.rejected)})"))
    corner_sets = [result.residuals[v.id]["corner_pixels"] for v in used
                   if v.id in result.residuals]
    size = tuple(result.sensor.image_size)
    cc = _coverage(corner_sets, size)
    checks.append(_check(
        "corner_coverage", cc, CORNER_COVERAGE_MIN, "of the image",
        "outside the area the corners cover the lens distortion is extrapolated",
        f"the board corners cover only {cc:.0%} of the image: place the board in the corners "
        "and at the edges of the image too", kind="min"))
    sc = _coverage(laser_sets, size)
    checks.append(_check(
        "stripe_coverage", sc, STRIPE_COVERAGE_MIN, "of the image",
        "measurements outside the stripe's calibrated area rest on extrapolation",
        f"the stripe covers only {sc:.0%} of the image: vary the distance to the board",
        kind="min"))
    rots = []
    for v in used:
        cb = _camera_from_board(result, v) if chain else result.camera_from_board.get(v.id)
        if cb is not None:
            rots.append(cb[:3, :3])
    pv = pose_variety_deg(rots)
    checks.append(_check(
        "pose_variety", pv, POSE_VARIETY_MIN_DEG, "deg",
        "the camera must turn about at least two different axes between views, by several "
        "degrees, to separate focal length from distance and to fix the hand-eye rotation",
        f"the views turn the camera by only {pv:.1f} degrees about a second axis: tilt the "
        "board view in another direction too", kind="min"))
    checks.append(_check(
        "unknowns_determined", float(result.rank), float(result.num_unknowns), "unknowns",
        "every estimated quantity must be fixed by the data",
        f"the data determine only {result.rank} of the {result.num_unknowns} unknowns: add "
        "views with the board at other angles", kind="min"))
    return checks


def verdict_from_checks(checks: list[Check], likely_mistake: str | None = None,
                        map_sigma_mm: dict[str, float] | None = None) -> Verdict:
    reasons = [c.problem for c in checks if not c.ok]
    if likely_mistake and reasons:
        reasons.insert(0, likely_mistake)
    return Verdict(trustworthy=not reasons, reasons=reasons, checks=checks,
                   map_sigma_mm=map_sigma_mm,
                   likely_mistake=likely_mistake if reasons else None)


def judge_joint(result: Any, views: Sequence[Any], board: Any, *,
                map_sigma: bool = True, mistakes: bool = True,
                cross_validate: bool = True, options: dict[str, Any] | None = None
                ) -> Verdict:
    """The verdict on a general-model calibration (``calibrate_joint``'s result) from the
    views it was given. ``map_sigma``: predict the 3D uncertainty
    (:func:`hmlvs.diagnostics.map_sigma.map_sigma_mm`); ``mistakes``: when a check fails,
    look for the likely mistake (:func:`find_mistake`); ``cross_validate``: calibrate the
    two halves of the views again (``calibrate_joint`` with ``options``, those of the
    calibration judged) and compare their maps (:func:`cross_validation`)."""
    board = BoardSpec.of(board)
    checks = joint_checks(result, views, board)
    cv = None
    if cross_validate:
        cv = cross_validation(result, views, board, options or {})
        if cv is not None:
            ratio = cv["rms"] / max(cv["predicted_rms"], 1e-9)
            checks.append(_check(
                "cross_validation", ratio, CROSS_VALIDATION_LIMIT, "",
                "two calibrations on the two halves of the views map the same stripe pixels "
                "about their combined predicted uncertainty apart (renders: 0.8-2.2 times); "
                f"beyond {CROSS_VALIDATION_LIMIT:g} times the halves disagree",
                f"calibrated on two halves of the views, the maps differ by "
                f"{cv['rms']:.3f} mm RMS, {ratio:.1f} times their predicted uncertainty: the "
                "views disagree with one another (or the uncertainty is understated)"))
    mistake = None
    if mistakes and result.mode == "chain" and not all(c.ok for c in checks):
        mistake = find_mistake(views, board, tuple(result.sensor.image_size)).sentence
    ms = pm = None
    if map_sigma:
        from .map_sigma import predicted_map, summary

        m = predicted_map(result)
        if m is not None:
            ms, pm = summary(m[1]), np.c_[m[0], m[1]]
    v = verdict_from_checks(checks, mistake, ms)
    v.cross_validation_mm = None if cv is None else {"rms": cv["rms"], "p95": cv["p95"]}
    v.map_points = pm
    v.image_size = tuple(result.sensor.image_size)
    return v


#: the two halves' maps may differ by this many times their combined predicted uncertainty
CROSS_VALIDATION_LIMIT = 4.0


def cross_validation(result: Any, views: Sequence[Any], board: BoardSpec,
                     options: dict[str, Any]) -> dict[str, float] | None:
    """Calibrate on the two halves of the views (alternate views, in their order) and map
    the calibration's stripe footprint with both (in the flange frame with robot poses,
    else the camera frame): their difference (``rms``, ``p95`` mm) and the RMS of their
    combined predicted uncertainty (``predicted_rms``, the parameters' alone: the same
    pixels are mapped). None when a half has fewer than 3 views with corners or cannot be
    calibrated."""
    from ..calibration.joint import calibrate_joint
    from .map_sigma import _points, footprint, point_sigmas

    used = [v for v in views if v.id in result.per_view]
    halves = [used[0::2], used[1::2]]
    if any(sum(len(v.corner_index) >= 6 for v in h) < 3 for h in halves):
        return None
    size = tuple(result.sensor.image_size)
    try:
        a, b = (calibrate_joint(h, board, size, **options) for h in halves)
    except ValueError:
        return None
    if a.mode != result.mode or b.mode != result.mode:
        return None
    chain = result.mode == "chain"
    px = footprint(result)
    if len(px) == 0:
        return None
    d = np.linalg.norm(_points(a.sensor, px, chain) - _points(b.sensor, px, chain), axis=1)
    sig = np.sqrt(point_sigmas(a, px, 0.0) ** 2 + point_sigmas(b, px, 0.0) ** 2)
    ok = np.isfinite(d) & np.isfinite(sig)
    if not ok.any():
        return None
    return {"rms": float(np.sqrt(np.mean(d[ok] ** 2))), "p95": float(np.percentile(d[ok], 95)),
            "predicted_rms": float(np.sqrt(np.mean(sig[ok] ** 2)))}


# -- the likely mistake --------------------------------------------------------------------

def _quat_xyzw(r: np.ndarray) -> np.ndarray:
    from ..data.poses import rotation_to_quaternion

    return rotation_to_quaternion(r, "xyzw")


def _rot_xyzw(q: np.ndarray) -> np.ndarray:
    from ..data.poses import rotation_from_quaternion

    return rotation_from_quaternion(q / np.linalg.norm(q), "xyzw")


def _reorder(m: np.ndarray, order: tuple[int, int, int, int]) -> np.ndarray:
    q = _quat_xyzw(m[:3, :3])
    out = m.copy()
    out[:3, :3] = _rot_xyzw(q[list(order)])
    return out


#: the pose hypotheses: name -> the base_from_hand the given pose would be under it
_POSE_HYPOTHESES: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "as given": lambda m: m,
    "inverted": _inv,
    # written x y z w but read as w x y z: the read (x', y', z', w') = (y, z, w, x)
    "xyzw read as wxyz": lambda m: _reorder(m, (3, 0, 1, 2)),
    # written w x y z but read as x y z w: the read (x', y', z', w') = (w, x, y, z)
    "wxyz read as xyzw": lambda m: _reorder(m, (1, 2, 3, 0)),
}


@dataclass
class ChainFit:
    """A cheap chain fit: corner RMS (px) through the robot chain and per view."""

    rms: float
    per_view: dict[str, float] = field(default_factory=dict)
    scale: float = 1.0


@dataclass
class Mistake:
    """What :func:`find_mistake` found: ``sentence`` (None when no usual mistake explains
    the data), the fits it compared (hypothesis -> corner RMS px) and its best guess."""

    sentence: str | None
    fits: dict[str, float]
    hypothesis: str
    scale: float
    free_rms_px: float
    views: list[str] = field(default_factory=list)


class _Obs:
    """The observations the hypotheses are tried on: Zhang's intrinsics and free board
    poses, the corners and the robot poses of the views with corners and poses."""

    def __init__(self, views: Sequence[Any], board: BoardSpec, image_size: tuple[int, int]):
        self.views = [v for v in views if len(v.corner_index) >= 6
                      and v.base_from_hand is not None]
        self.board = board
        intr, poses, rms = initial_intrinsics(self.views, board, image_size)
        self.k = np.array([[intr[0], 0, intr[2]], [0, intr[1], intr[3]], [0, 0, 1.0]])
        self.dist = intr[4:]
        self.cams = poses
        self.free_rms = rms
        self.bfh = [np.asarray(v.base_from_hand, float) for v in self.views]


def _chain_rms(obs: _Obs, bfh: list[np.ndarray], flips: list[bool | None], scale: float,
               fit_on: list[int], evaluate: list[int]) -> ChainFit:
    """Hand-eye (Park and Martin) and the mean board pose from the views ``fit_on`` with the
    board scaled by ``scale``; the corners' RMS (px) through the chain over ``evaluate``
    (views of undecided numbering take the better of the two)."""
    import cv2

    b = obs.board
    f = b.flip()
    cams = []
    for i, c in enumerate(obs.cams):
        c = c @ f if flips[i] else c.copy()
        c[:3, 3] *= scale
        cams.append(c)
    try:
        x = _core._hand_eye_park_martin([bfh[i] for i in fit_on], [cams[i] for i in fit_on])
        bfb = _core._mean_transform([bfh[i] @ x @ cams[i] for i in fit_on])
    except ValueError:
        return ChainFit(float("inf"), scale=scale)
    x_inv = _inv(x)
    per_view, sq = {}, []
    n = b.rows * b.cols
    for i in evaluate:
        v = obs.views[i]
        cb = x_inv @ _inv(bfh[i]) @ bfb
        idx0 = np.asarray(v.corner_index, int)
        best = None
        options = [flips[i]] if flips[i] is not None else [False, True]
        for fl in options:
            idx = n - 1 - idx0 if fl else idx0
            pts = b.points(idx) * scale
            cam = pts @ cb[:3, :3].T + cb[:3, 3]
            if not (cam[:, 2] > 0).all():
                e = np.full(len(pts), 1e6)
            else:
                proj, _ = cv2.projectPoints(cam, np.zeros(3), np.zeros(3), obs.k, obs.dist)
                e = np.sum((proj.reshape(-1, 2) - np.asarray(v.corner_pixels, float)) ** 2,
                           axis=1)
            if best is None or e.mean() < best.mean():
                best = e
        assert best is not None
        per_view[v.id] = float(np.sqrt(best.mean()))
        sq.append(best)
    e = np.concatenate(sq) if sq else np.empty(0)
    return ChainFit(float(np.sqrt(e.mean())) if e.size else float("inf"), per_view, scale)


def _best_scale(obs: _Obs, bfh: list[np.ndarray], flips: list[bool | None],
                fit_on: list[int]) -> ChainFit:
    """The board scale that fits the chain best: a log grid from 1e-4 to 1e4, then golden
    section around the best grid point."""
    grid = 10.0 ** np.linspace(-4, 4, 161)
    fits = [_chain_rms(obs, bfh, flips, s, fit_on, fit_on) for s in grid]
    k = int(np.argmin([f.rms for f in fits]))
    lo = math.log10(grid[max(k - 1, 0)])
    hi = math.log10(grid[min(k + 1, len(grid) - 1)])
    g = (math.sqrt(5) - 1) / 2
    a, b = hi - g * (hi - lo), lo + g * (hi - lo)

    def rms(x: float) -> float:
        return _chain_rms(obs, bfh, flips, 10.0 ** x, fit_on, fit_on).rms

    fa, fb = rms(a), rms(b)
    for _ in range(30):
        if fa < fb:
            hi, b, fb = b, a, fa
            a = hi - g * (hi - lo)
            fa = rms(a)
        else:
            lo, a, fa = a, b, fb
            b = lo + g * (hi - lo)
            fb = rms(b)
    best = _chain_rms(obs, bfh, flips, 10.0 ** ((lo + hi) / 2), fit_on, fit_on)
    return best if best.rms <= fits[k].rms else fits[k]


def _good(rms: float, free: float) -> bool:
    """A chain fit as good as a correct one: within the corner limit and twice the free
    poses' RMS."""
    return rms <= max(CORNER_RMS_LIMIT_PX, POSE_DISAGREEMENT * max(free, 0.05))


def _split_views(obs: _Obs, bfh: list[np.ndarray], flips: list[bool | None], scale: float
                 ) -> tuple[list[int], ChainFit]:
    """Views whose board pose disagrees with the rest, by consensus: the chain is fitted to
    every triple of views of decided numbering (at most 300 triples drawn), each view is
    judged by its corner RMS through that chain (either numbering), and the largest set
    within the corner limit (and twice the free poses' RMS) wins; the chain is fitted again
    on it. Returns the other views and the final fit (over all views)."""
    all_i = list(range(len(obs.views)))
    decided = [i for i in all_i if flips[i] is not None]
    limit = max(CORNER_RMS_LIMIT_PX, POSE_DISAGREEMENT * max(obs.free_rms, 0.05))
    triples = [(a, b, c) for ai, a in enumerate(decided) for bi, b in enumerate(decided[ai + 1:])
               for c in decided[ai + bi + 2:]]
    if len(triples) > 300:
        pick = np.random.default_rng(0).choice(len(triples), 300, replace=False)
        triples = [triples[k] for k in sorted(pick)]
    best: list[int] = []
    for t in triples:
        fit = _chain_rms(obs, bfh, [flips[i] if i in t else None for i in all_i], scale,
                         list(t), all_i)
        ins = [i for i in all_i if fit.per_view.get(obs.views[i].id, np.inf) <= limit]
        if len(ins) > len(best):
            best = ins
    fit_on = [i for i in best if flips[i] is not None]
    if len(fit_on) < 3:
        return [], _chain_rms(obs, bfh, flips, scale, decided, all_i)
    fit = _chain_rms(obs, bfh, [flips[i] if i in fit_on else None for i in all_i], scale,
                     fit_on, all_i)
    if not fit.per_view:  # the chain cannot be fitted on the consensus (e.g. too little turn)
        return [], fit
    bad = [i for i in all_i if fit.per_view.get(obs.views[i].id, np.inf) > limit]
    return bad, fit


def find_mistake(views: Sequence[Any], board: Any, image_size: tuple[int, int]) -> Mistake:
    """Try the usual mistakes on the observations and name the one that explains them.

    Each hypothesis on the robot poses (as given, inverted, either quaternion order read as
    the other) is fitted with the board's scale free (a one-dimensional search: a wrong
    square and positions in metres read as millimetres both scale the board against the
    robot's translations), by the cheap chain fit of :func:`_chain_rms`. The best fit names
    the mistake when it is as good as a correct calibration's and the poses as given are
    not; else views whose board pose disagrees with the rest are looked for."""
    board = BoardSpec.of(board)
    obs = _Obs(views, board, image_size)
    free = obs.free_rms
    n = len(obs.views)
    if n < 3:
        return Mistake(None, {}, "as given", 1.0, free)
    fits: dict[str, ChainFit] = {}
    flips_of: dict[str, list[bool | None]] = {}
    for name, fn in _POSE_HYPOTHESES.items():
        bfh = [fn(m) for m in obs.bfh]
        flips = consistent_numbering(bfh, obs.cams, board)
        decided = [i for i in range(n) if flips[i] is not None]
        flips_of[name] = flips
        if len(decided) < 3:
            fits[name] = ChainFit(float("inf"))
            continue
        fits[name] = _best_scale(obs, bfh, flips, decided)
    given_bfh = obs.bfh
    given_flips = flips_of["as given"]
    decided = [i for i in range(n) if given_flips[i] is not None]
    as_given = (_chain_rms(obs, given_bfh, given_flips, 1.0, decided, decided).rms
                if len(decided) >= 3 else float("inf"))
    table = {"as given": as_given, **{f"{k} (scale {f.scale:.4g})": f.rms
                                      for k, f in fits.items()}}
    best = min(fits, key=lambda k: fits[k].rms)
    bf = fits[best]
    s = bf.scale
    sq = board.square
    if _good(bf.rms, free) and not _good(as_given, free):
        parts = []
        if best == "inverted":
            parts.append("the robot poses fit the images only when inverted: they are "
                         "hand_from_base, not base_from_hand; invert them")
        elif best != "as given":
            written, read = best.split(" read as ")
            parts.append(f"the robot poses fit the images only with the other quaternion "
                         f"order: their quaternions are written {written}, not {read}; set "
                         f"the poses' quaternion_order to {written}")
        # positions in metres read as millimetres are 1000 times too small against the
        # board: the board must shrink by 1000 to fit them
        for factor, unit_said, unit in ((0.001, "metres read as millimetres", "m"),
                                        (1000.0, "millimetres read as metres", "mm")):
            if abs(math.log(s / factor)) < math.log(1.15):
                parts.append(f"the robot positions are {unit_said}: set the poses' unit "
                             f"to {unit}")
                s = s / factor
                break
        if abs(math.log(s)) > math.log(1.02):
            parts.append(f"the robot motion implies squares of {s * sq:.1f} mm, not "
                         f"{sq:g}: check `board.square`")
        if parts:
            sentence = (f"likely mistake: {'; '.join(parts)} (the corners then fit the "
                        f"robot chain to {bf.rms:.2f} px RMS, against {as_given:.2f} px as "
                        "given)")
            return Mistake(sentence, table, best, bf.scale, free)
    bad, fit = _split_views(obs, given_bfh, given_flips, 1.0)
    # a minority of the views: when most views disagree with the rest, it is the poses or
    # the chain that are wrong, not a few views
    if bad and len(bad) < n / 2 and _good(
            _rms_over(fit, [obs.views[i].id for i in range(n) if i not in bad]), free):
        names = [obs.views[i].id for i in bad]
        sentence = (f"likely mistake: view(s) {', '.join(names)} put the board elsewhere "
                    "than the others do: the board moved, or their images do not belong "
                    "to their robot poses; leave them out or capture them again (the other "
                    f"views fit the robot chain to "
                    f"{_rms_over(fit, [v.id for v in obs.views if v.id not in names]):.2f} "
                    "px RMS)")
        return Mistake(sentence, table, "views", 1.0, free, names)
    if not _good(as_given, free):
        sentence = (f"no usual mistake explains the data (square size, metres or "
                    f"millimetres, inverted poses, quaternion order, a few moved views: best "
                    f"{bf.rms:.2f} px RMS against {as_given:.2f} px as given): check the robot "
                    "poses' accuracy and timing (taken when the robot stood still?), that the "
                    "images belong to these poses and that the board stayed put")
        return Mistake(sentence, table, best, bf.scale, free)
    return Mistake(None, table, "as given", 1.0, free)


def _rms_over(fit: ChainFit, ids: list[str]) -> float:
    e = [fit.per_view[i] for i in ids if i in fit.per_view]
    return float(np.sqrt(np.mean(np.square(e)))) if e else float("inf")


def require_check(verdict: Verdict, require_mm: float | None) -> Verdict:
    """``verdict`` with the user's demand on the predicted 95th-percentile 3D uncertainty
    (``hmlvs calibrate --require MM``) as one more check; unchanged without a demand."""
    if require_mm is None:
        return verdict
    if not (math.isfinite(require_mm) and require_mm > 0):
        raise ValueError(f"--require must be a positive number of mm, got {require_mm}")
    p95 = float("inf") if verdict.map_sigma_mm is None else verdict.map_sigma_mm["p95"]
    checks = [*verdict.checks, _check(
        "map_sigma_p95", p95, require_mm, "mm",
        "the user's demand (--require) on the predicted 95th-percentile 3D uncertainty",
        f"the predicted 3D uncertainty reaches {p95:.3f} mm at the 95th percentile, more "
        f"than the {require_mm:g} mm required")]
    if verdict.cross_validation_mm is not None:
        cv95 = verdict.cross_validation_mm["p95"]
        checks.append(_check(
            "cross_validation_p95", cv95, require_mm, "mm",
            "the user's demand (--require) on the 95th percentile of the difference between "
            "the two halves' maps",
            f"calibrations on two halves of the views map points up to {cv95:.3f} mm apart "
            f"(95th percentile), more than the {require_mm:g} mm required"))
    out = verdict_from_checks(checks, verdict.likely_mistake, verdict.map_sigma_mm)
    out.cross_validation_mm = verdict.cross_validation_mm
    out.map_points, out.image_size = verdict.map_points, verdict.image_size
    return out


# -- the paper model ------------------------------------------------------------------------

#: the paper model's fit (mm RMS of ||E_i||, the calibration points' 3D error): laser
#: triangulation sensors of this class measure to 0.1-0.3 mm at their working range (the
#: paper's own fit: about 0.2 mm); a fit beyond 1 mm means the data or the model are wrong
PAPER_FIT_LIMIT_MM = 1.0
#: held-out points may lie this many times farther than the fitted ones (noise alone: about
#: 1.1 for the paper's data sizes); beyond it the calibration does not generalise
HELD_OUT_RATIO = 2.0


def judge_paper(result: Any) -> Verdict:
    """The verdict on a paper-model calibration (:class:`hmlvs.CalibrationResult`): fewer
    checks than the general model's (no corners, no chain): the solve's end, the fit
    against the sensor class's accuracy and held-out points against the fit. No 3D
    uncertainty map and no mistake finder yet (``map_sigma_mm`` None)."""
    checks = []
    bad = str(result.termination) in ("failed", "cancelled")
    checks.append(_check(
        "solve_finished", 0.0 if bad else 1.0, 1.0, "",
        "a solve that failed or was cancelled leaves parameters nobody checked",
        f"the solve ended {result.termination}: its parameters are not a calibration",
        kind="min"))
    fr = float(result.fit_rms)
    checks.append(_check(
        "fit_rms", fr, PAPER_FIT_LIMIT_MM, "mm",
        "laser triangulation sensors of this class measure to 0.1-0.3 mm (the paper: about "
        "0.2 mm); beyond 1 mm the data or the model are wrong",
        f"the calibration points lie {fr:.3f} mm RMS from their reference positions, more "
        f"than the {PAPER_FIT_LIMIT_MM:g} mm a correct calibration leaves"))
    if result.test_rms is not None and math.isfinite(result.test_rms):
        # the fit's RMS floored at 0.01 mm, far below any real sensor's noise: noise-free
        # simulations fit to 1e-13 mm and would make any ratio meaningless
        ratio = float(result.test_rms) / max(fr, 0.01)
        checks.append(_check(
            "held_out_vs_fit", ratio, HELD_OUT_RATIO, "",
            "held-out points lie about as far as the fitted ones when the calibration "
            "generalises (noise alone: about 1.1)",
            f"held-out points lie {ratio:.1f} times farther than the fitted ones "
            f"({result.test_rms:.3f} against {fr:.3f} mm): the calibration does not "
            "generalise (too few poses, or data that disagree)"))
    # No check on every parameter being determined: near the ZYZ gimbal (phi ~ 0) omega and
    # varphi are not determined one by one though the rotation is (their sum is), and the
    # identifiability report already names them.
    return verdict_from_checks(checks)
