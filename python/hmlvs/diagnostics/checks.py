"""The named checks of a calibration's verdict, each with its value, its limit and why that
limit (:class:`Check`).

The limits are physical, not tuned to a scene: corner detectors locate corners to a few
hundredths to a few tenths of a pixel; a laser fit is judged against the stripe's own
measured noise carried to millimetres; a robot's absolute accuracy is a fraction of a
millimetre. Each limit's reason is written beside it and travels with the check.

The checks that do not depend on the sensor model (coverage, pose variety, the
cross-validation of two halves, the unknowns determined) are written once and take what
either model's calibration gives them; the corner and chain checks need the views' corners
(the general model's joint calibration); the fit checks of the paper model its calibration
points.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Any, Sequence

import numpy as np

from .._arrays import robust_sigma
from ..calibration.joint import POSE_DISAGREEMENT
from ..calibration.joint_setup import TILT, board_plane_points, initial_intrinsics
from ..geometry.transforms import invert_transform, rotation_to_vector
from ..models.opencv import DISTORTION_NAMES

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
#: the hand-eye equation A X = X B for every pair of views (A: the hand's motion, B: the
#: camera's, from its corners): its residual combines two views' board-pose errors, so
#: sqrt(2) times the board spread's limits (at the flange, mm; its rotation, degrees)
HAND_EYE_MM = BOARD_SPREAD_MM * math.sqrt(2)
HAND_EYE_DEG = BOARD_SPREAD_DEG * math.sqrt(2)
#: the two halves' maps may differ by this many times their combined predicted uncertainty
CROSS_VALIDATION_LIMIT = 4.0
#: the paper model's fit (mm RMS of ||E_i||, the calibration points' 3D error): laser
#: triangulation sensors of this class measure to 0.1-0.3 mm at their working range (the
#: paper's own fit: about 0.2 mm); a fit beyond 1 mm means the data or the model are wrong
PAPER_FIT_LIMIT_MM = 1.0
#: held-out points may lie this many times farther than the fitted ones (noise alone: about
#: 1.1 for the paper's data sizes); beyond it the calibration does not generalise
HELD_OUT_RATIO = 2.0
#: the general model's lens: the rational model's k4, k5, k6 added to the calibrated terms, or
#: the tilted sensor's taux, tauy, must not fit the corners (every view's board pose free)
#: better than this fraction of their RMS. Measured with the rational terms: 0.989-0.999 on
#: every real session at hand (Blaser 640 and 1280, etna, light_stripe; OpenCV's left and right
#: samples, tests/data, 0.989 and 0.998), with the tilt 0.977-0.999 (Blaser 640 and 1280, etna,
#: light_stripe; OpenCV's left sample 0.993), both 0.99-1.0 on renders of a five-term lens;
#: 0.43 on renders of a wide lens of the rational model, where the five-term lens fits the
#: corners to 0.04 px and still maps the stripe 1.9 mm off at the 95th percentile
#: (tests/e2e/test_wide_lens_images.py), 0.16 on renders of a sensor tilted 11.5 degrees
#: (tests/e2e/test_tilted_sensor_images.py)
LENS_RATIO_MIN = 0.8

__all__ = ["POSE_DISAGREEMENT"]

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
        return {"name": self.name, "value": finite_or_none(self.value),
                "limit": finite_or_none(self.limit),
                "ok": bool(self.ok), "unit": self.unit, "kind": self.kind, "why": self.why}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "Check":
        return cls(name=str(d["name"]), value=as_float(d.get("value")),
                   limit=as_float(d.get("limit")), ok=bool(d["ok"]), why=str(d.get("why", "")),
                   unit=str(d.get("unit", "")), kind=str(d.get("kind", "max")))


def finite_or_none(x: float) -> float | None:
    return float(x) if x is not None and math.isfinite(x) else None


def as_float(x: Any) -> float:
    return float("nan") if x is None else float(x)


def make_check(name: str, value: float, limit: float, unit: str, why: str, problem: str,
           kind: str = "max") -> Check:
    ok = bool(value <= limit) if kind == "max" else bool(value >= limit)
    return Check(name, float(value), float(limit), ok, why, unit, problem, kind)


def camera_from_board_of(result: Any, view: Any) -> np.ndarray | None:
    s = result.sensor
    if result.mode == "chain":
        hand = np.asarray(view.base_from_hand, float)
        return invert_transform(s.hand_from_camera) @ invert_transform(hand) @ s.base_from_board
    return result.camera_from_board.get(view.id)


def stripe_noise_px(pixel_sets: Sequence[np.ndarray], degree: int = 5,
                    robust: bool = True) -> float:
    """The stripe's own noise (px, in the row direction): per view, the scatter of its rows
    about a smooth curve (a polynomial of ``degree`` in the column: a straight laser line on
    a flat board, bent by the lens distortion), pooled over the views. It holds the
    detector's noise and its local biases (speckle, albedo steps), not the calibration's.
    ``robust``: the robust scatter (the bulk of the stripe, as the calibration's outlier
    rule sees it); else the RMS, tails and poor views included (what an RMS of measured
    points feels: on independent renders a view's RMS about its curve is within 10 % of
    its stripe's true error, 0.02-0.23 px, where the robust scatter says 0.02-0.09)."""
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
    if r.size < 10:
        return float("nan")
    return robust_sigma(r) if robust else float(np.sqrt(np.mean(r**2)))


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
        cb = camera_from_board_of(result, v)
        if cb is None:
            continue
        p0, _ = board_plane_points(intr, cb, px)
        p1, _ = board_plane_points(intr, cb, px + [0.0, 1.0])
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


def pose_variety_deg(rotations: Sequence[np.ndarray]) -> float:
    """The RMS relative rotation (degrees) about the second best spanned axis over all pairs
    of views: 0 when every view turns about one axis only."""
    rv = [rotation_to_vector(a @ b.T) for k, a in enumerate(rotations) for b in rotations[k + 1:]]
    if not rv:
        return 0.0
    m = np.asarray(rv).T @ np.asarray(rv) / len(rv)
    ev = np.sort(np.linalg.eigvalsh(m))[::-1]
    return math.degrees(math.sqrt(max(ev[1], 0.0)))


def laser_check(result: Any, used: Sequence[Any], laser_sets: Sequence[np.ndarray]
                ) -> list[Check]:
    """The laser residuals against the stripe's own noise carried to mm (none when the
    noise cannot be measured)."""
    sigma_px = stripe_noise_px(laser_sets)
    sens = _laser_sensitivity(result, used)
    if not (sens.size and math.isfinite(sigma_px)):
        return []
    expected = sigma_px * float(np.sqrt(np.mean(sens**2)))
    limit = max(LASER_NOISE_FACTOR * expected, LASER_FLOOR_MM)
    lr = result.laser_rms_mm
    return [make_check(
        "laser_rms", lr, limit, "mm",
        f"the stripe's own noise ({sigma_px:.3f} px, its rows' scatter about a smooth "
        f"curve) carried to mm is {expected:.4f} mm; a correct calibration leaves at most "
        f"{LASER_NOISE_FACTOR:g} times that (board-pose error, stripe bias at albedo "
        f"steps), and never asks less than {LASER_FLOOR_MM:g} mm",
        f"the stripe points lie {lr:.3f} mm RMS from the laser plane, more than the "
        f"{limit:.3f} mm the stripe's own noise explains")]


def coverage_checks(corner_sets: Sequence[np.ndarray] | None,
                    stripe_sets: Sequence[np.ndarray], size: tuple[int, int]) -> list[Check]:
    """Where in the image the corners (when the calibration used any) and the stripe were
    seen."""
    checks = []
    if corner_sets is not None:
        cc = _coverage(corner_sets, size)
        checks.append(make_check(
            "corner_coverage", cc, CORNER_COVERAGE_MIN, "of the image",
            "outside the area the corners cover the lens distortion is extrapolated",
            f"the board corners cover only {cc:.0%} of the image: place the board in the "
            "corners and at the edges of the image too", kind="min"))
    sc = _coverage(stripe_sets, size)
    checks.append(make_check(
        "stripe_coverage", sc, STRIPE_COVERAGE_MIN, "of the image",
        "measurements outside the stripe's calibrated area rest on extrapolation",
        f"the stripe covers only {sc:.0%} of the image: vary the distance to the board",
        kind="min"))
    return checks


def variety_check(rotations: Sequence[np.ndarray]) -> Check:
    """How varied the camera's orientations are (``rotations``: camera_from_board, or
    hand_from_base: the same relative rotations up to one rotation of them all)."""
    pv = pose_variety_deg(rotations)
    return make_check(
        "pose_variety", pv, POSE_VARIETY_MIN_DEG, "deg",
        "the camera must turn about at least two different axes between views, by several "
        "degrees, to separate focal length from distance and to fix the hand-eye rotation",
        f"the views turn the camera by only {pv:.1f} degrees about a second axis: tilt the "
        "board view in another direction too", kind="min")


#: the lens models a calibration's terms are checked against (:func:`lens_check`): OpenCV's
#: rational model (a wide lens) and its tilted sensor (the Scheimpflug arrangement)
LENS_EXTENSIONS: dict[str, tuple[str, ...]] = {
    "the rational model's k4, k5, k6": ("k4", "k5", "k6"),
    "the tilted sensor's taux, tauy": TILT,
}


def lens_ratios(views: Sequence[Any], board: Any, image_size: tuple[int, int],
                terms: Sequence[str]) -> tuple[float, dict[str, float]]:
    """Zhang's method (every view's board pose free) on the ``views``' corners with the
    distortion ``terms``: its RMS (px), and for each of :data:`LENS_EXTENSIONS` that ``terms``
    lack, the RMS with its terms added."""
    now = initial_intrinsics(views, board, image_size, tuple(terms))[2]
    return now, {name: initial_intrinsics(views, board, image_size, (*terms, *extra))[2]
                 for name, extra in LENS_EXTENSIONS.items() if not set(extra) & set(terms)}


def lens_check(result: Any, used: Sequence[Any], board: Any) -> list[Check]:
    """Whether a calibration's distortion terms follow the lens (:func:`lens_terms_check` on
    the ``used`` views)."""
    terms = tuple(n for n in DISTORTION_NAMES if n in result.names)
    return lens_terms_check(used, board, tuple(result.sensor.image_size), terms)


def lens_terms_check(views: Sequence[Any], board: Any, image_size: tuple[int, int],
                     terms: Sequence[str]) -> list[Check]:
    """Whether the distortion ``terms`` follow the lens: no lens model of
    :data:`LENS_EXTENSIONS` added may fit the corners of the ``views`` markedly better
    (:func:`lens_ratios`, :data:`LENS_RATIO_MIN`). None of it (an empty list) when ``terms``
    hold them all already, or no distortion term, or fewer than 3 views have corners."""
    terms = tuple(terms)
    views = [v for v in views if len(v.corner_index) >= 6]
    if not terms or len(views) < 3:
        return []
    now, wider = lens_ratios(views, board, image_size, terms)
    if not wider:
        return []
    best = min(wider, key=wider.__getitem__)
    cure = ",".join(n for n in DISTORTION_NAMES if n in terms or n in LENS_EXTENSIONS[best])
    return [make_check(
        "lens_model", wider[best] / max(now, 1e-12), LENS_RATIO_MIN, "",
        "OpenCV's rational terms (k4, k5, k6) or tilted sensor (taux, tauy) fit the corners of "
        "real lenses 0.98-1.0 times as well as the terms calibrated; below "
        f"{LENS_RATIO_MIN:g} the lens bends in a way they cannot follow, and the other "
        "parameters absorb it",
        f"the lens bends more than its distortion terms ({', '.join(terms)}) follow: with "
        f"{best} the corners fit {wider[best]:.3f} px RMS against {now:.3f} px (each view's "
        f"board pose free): calibrate with --distortion {cure}", kind="min")]


def unknowns_check(determined: int, total: int) -> Check:
    return make_check(
        "unknowns_determined", float(determined), float(total), "unknowns",
        "every estimated quantity must be fixed by the data",
        f"the data determine only {determined} of the {total} unknowns: add views with the "
        "board at other angles", kind="min")


def cross_validation_check(cv: dict[str, float]) -> Check:
    """The two halves' maps' difference against their combined predicted uncertainty."""
    ratio = cv["rms"] / max(cv["predicted_rms"], 1e-9)
    return make_check(
        "cross_validation", ratio, CROSS_VALIDATION_LIMIT, "",
        "two calibrations on the two halves of the views map the same stripe pixels about "
        "their combined predicted uncertainty apart (renders: 0.8-2.2 times); beyond "
        f"{CROSS_VALIDATION_LIMIT:g} times the halves disagree",
        f"calibrated on two halves of the views, the maps differ by {cv['rms']:.3f} mm RMS, "
        f"{ratio:.1f} times their predicted uncertainty: the views disagree with one another "
        "(or the uncertainty is understated)")


def paper_checks(result: Any) -> list[Check]:
    """The paper model's own checks: the solve's end, the fit against the sensor class's
    accuracy and held-out points against the fit."""
    checks = []
    bad = str(result.termination) in ("failed", "cancelled")
    checks.append(make_check(
        "solve_finished", 0.0 if bad else 1.0, 1.0, "",
        "a solve that failed or was cancelled leaves parameters nobody checked",
        f"the solve ended {result.termination}: its parameters are not a calibration",
        kind="min"))
    fr = float(result.fit_rms)
    checks.append(make_check(
        "fit_rms", fr, PAPER_FIT_LIMIT_MM, "mm",
        "laser triangulation sensors of this class measure to 0.1-0.3 mm (the paper: about "
        "0.2 mm); beyond 1 mm the data or the model are wrong",
        f"the calibration points lie {fr:.3f} mm RMS from their reference positions, more "
        f"than the {PAPER_FIT_LIMIT_MM:g} mm a correct calibration leaves"))
    if result.test_rms is not None and math.isfinite(result.test_rms):
        # the fit's RMS floored at 0.01 mm, far below any real sensor's noise: noise-free
        # simulations fit to 1e-13 mm and would make any ratio meaningless
        ratio = float(result.test_rms) / max(fr, 0.01)
        checks.append(make_check(
            "held_out_vs_fit", ratio, HELD_OUT_RATIO, "",
            "held-out points lie about as far as the fitted ones when the calibration "
            "generalises (noise alone: about 1.1)",
            f"held-out points lie {ratio:.1f} times farther than the fitted ones "
            f"({result.test_rms:.3f} against {fr:.3f} mm): the calibration does not "
            "generalise (too few poses, or data that disagree)"))
    return checks
