"""The verdict on a calibration: can it be trusted, why (or why not), and the likely mistake.

A calibration tool's worst failure is a wrong calibration reported as fine. Residual RMS
alone does not tell: a wrong board square or inverted robot poses are absorbed by the camera
and the hand-eye transform and leave residuals that look merely "large". So every
calibration gets named checks (:mod:`hmlvs.diagnostics.checks`), each with its value, its
limit and why that limit, and a :class:`Verdict`: trustworthy only when every check passes.

One pipeline for both sensor models: :func:`judge_joint` (the general model) and
:func:`judge_paper` (the paper's 14 parameters) run the same model-neutral checks (coverage,
pose variety, the unknowns determined, the cross-validation of two halves of the views) and
the same predicted 3D uncertainty (:mod:`hmlvs.diagnostics.map_sigma`, a
:class:`~hmlvs.diagnostics.map_sigma.PointModel` of either calibration), plus each model's
own: the corners through the robot chain for the general model, the calibration points' fit
for the paper's. When a check fails, :func:`~hmlvs.diagnostics.mistakes.find_mistake` tries
the usual culprits on the views' corners and poses and names the one that explains the data.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math
from typing import Any, Callable, Sequence

import numpy as np

from ..geometry.board import BoardSpec
from ..models.opencv import CLASSIC_DISTORTION, DISTORTION_NAMES
from .chain import chain_checks, chain_of_joint, chain_of_paper, joint_checks, pose_error_mm
from .checks import (
    CROSS_VALIDATION_LIMIT,
    LENS_EXTENSIONS,
    Check,
    as_float,
    coverage_checks,
    cross_validation_check,
    finite_or_none,
    make_check,
    paper_checks,
    stripe_noise_px,
    unknowns_check,
    variety_check,
)
from .map_sigma import PointModel
from .mistakes import find_mistake, reorder_quaternions

__all__ = ["CROSS_VALIDATION_LIMIT", "Check", "Verdict", "reorder_quaternions", "cross_validation",
           "find_mistake", "judge_joint", "judge_paper", "require_check", "stripe_noise_px",
           "verdict_from_checks"]


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
                {k: finite_or_none(v) for k, v in self.map_sigma_mm.items()},
                "cross_validation_mm": None if self.cross_validation_mm is None else
                {k: finite_or_none(v) for k, v in self.cross_validation_mm.items()},
                "likely_mistake": self.likely_mistake}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "Verdict":
        ms = d.get("map_sigma_mm")
        cv = d.get("cross_validation_mm")
        return cls(trustworthy=bool(d["trustworthy"]), reasons=[str(r) for r in
                                                                  d.get("reasons") or []],
                   checks=[Check.from_dict(c) for c in d.get("checks") or []],
                   map_sigma_mm=None if ms is None else {k: as_float(v) for k, v in ms.items()},
                   likely_mistake=d.get("likely_mistake"),
                   cross_validation_mm=None if cv is None else
                   {k: as_float(v) for k, v in cv.items()})

    def advice(self) -> str:
        """What the verdict means for the person about to measure, in a sentence or two."""
        if not self.trustworthy:
            return ("Do not measure with it: fix the first reason and calibrate again. The "
                    "calibration file is marked not trustworthy, and hmlvs measure refuses it "
                    "unless told --accept-untrusted.")
        ms = self.map_sigma_mm
        if ms is None:
            return "It may be used to measure."
        return (f"It may be used to measure: where the stripe was seen while calibrating, 95 % "
                f"of the measured points should lie within about {2 * ms['p95']:.2f} mm of the "
                f"truth (twice the predicted {ms['p95']:.3f} mm at the 95th percentile); "
                "elsewhere in the image they rest on extrapolation.")

    def text(self) -> str:
        """The verdict in words a technician reads first: trusted or not, why (the likely
        mistake first), what to do; then the figures and every check."""
        if self.trustworthy:
            lines = ["VERDICT: this calibration can be trusted: every check passed."]
        else:
            lines = ["VERDICT: this calibration is NOT to be trusted:"]
            lines += [f"  - {r}" for r in self.reasons]
        lines.append(self.advice())
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


def verdict_from_checks(checks: list[Check], likely_mistake: str | None = None,
                        map_sigma_mm: dict[str, float] | None = None) -> Verdict:
    reasons = [c.problem for c in checks if not c.ok]
    if likely_mistake and reasons:
        reasons.insert(0, likely_mistake)
    return Verdict(trustworthy=not reasons, reasons=reasons, checks=checks,
                   map_sigma_mm=map_sigma_mm,
                   likely_mistake=likely_mistake if reasons else None)


def _finish(checks: list[Check], model: PointModel | None,
            refit: Callable[[int], PointModel | None] | None, mistake: Callable[[], Any],
            image_size: tuple[int, int] | None) -> Verdict:
    """The verdict of either model from its own ``checks``: the cross-validation of the two
    halves (``refit(k)``, the point model of half k, when given), the predicted map of
    ``model`` and, when a check fails, ``mistake()`` (the likely mistake's sentence or
    None)."""
    from .map_sigma import predicted_map, summary

    cv = None
    if refit is not None and model is not None:
        cv = cross_validation(model, refit)
        if cv is not None:
            checks.append(cross_validation_check(cv))
    sentence = None if all(c.ok for c in checks) else mistake()
    ms = pm = None
    m = predicted_map(model) if model is not None else None
    if m is not None:
        ms, pm = summary(m[1]), np.c_[m[0], m[1]]
    v = verdict_from_checks(checks, sentence, ms)
    v.cross_validation_mm = None if cv is None else {"rms": cv["rms"], "p95": cv["p95"]}
    v.map_points = pm
    v.image_size = image_size
    return v


def judge_joint(result: Any, views: Sequence[Any], board: Any, *,
                map_sigma: bool = True, mistakes: bool = True,
                cross_validate: bool = True, options: dict[str, Any] | None = None
                ) -> Verdict:
    """The verdict on a general-model calibration (``calibrate_joint``'s result) from the
    views it was given. ``map_sigma``: predict the 3D uncertainty
    (:func:`hmlvs.diagnostics.map_sigma.predicted_map`); ``mistakes``: when a check fails,
    look for the likely mistake (:func:`find_mistake`); ``cross_validate``: calibrate the
    two halves of the views again (``calibrate_joint`` with ``options``, those of the
    calibration judged) and compare their maps (:func:`cross_validation`)."""
    from .map_sigma import of_joint

    board = BoardSpec.of(board)
    size = tuple(result.sensor.image_size)
    checks = joint_checks(result, views, board)
    model = of_joint(result) if (map_sigma or cross_validate) else None
    chain = chain_of_joint(result, views, board)
    if model is not None and chain is not None:
        robot = pose_error_mm(chain)
        model.pose_sigma_mm = robot if math.isfinite(robot) else 0.0
    refit = _joint_halves(result, views, board, options or {}) if cross_validate else None

    def mistake() -> str | None:
        if not mistakes or result.mode != "chain":
            return None
        # the calibration's lens (a held camera's: the five terms and those it holds not 0);
        # one its terms cannot follow (lens_model) would make good data look wrong, so then
        # the lens models that check tries are added
        terms = ({n for n in result.names if n in DISTORTION_NAMES}
                 or {*CLASSIC_DISTORTION, *(n for n, d in zip(DISTORTION_NAMES,
                                                             result.sensor.dist_coeffs) if d)})
        if any(c.name == "lens_model" and not c.ok for c in checks):
            terms.update(*LENS_EXTENSIONS.values())
        return find_mistake(views, board, size,
                            tuple(n for n in DISTORTION_NAMES if n in terms)).sentence

    v = _finish(checks, model, refit, mistake, size)
    if not map_sigma:
        v.map_sigma_mm, v.map_points = None, None
    return v


def _joint_halves(result: Any, views: Sequence[Any], board: BoardSpec,
                  options: dict[str, Any]) -> Callable[[int], PointModel | None] | None:
    """The point models of general-model calibrations on the two halves of the views
    (alternate views, in their order); None when a half has fewer than 3 views with
    corners."""
    from ..calibration.joint import calibrate_joint
    from .map_sigma import of_joint

    used = [v for v in views if v.id in result.per_view]
    halves = [used[0::2], used[1::2]]
    if any(sum(len(v.corner_index) >= 6 for v in h) < 3 for h in halves):
        return None
    size = tuple(result.sensor.image_size)

    def refit(k: int) -> PointModel | None:
        try:
            r = calibrate_joint(halves[k], board, size, **options)
        except ValueError:
            return None
        return of_joint(r) if r.mode == result.mode else None

    return refit


def cross_validation(model: PointModel, refit: Callable[[int], PointModel | None]
                     ) -> dict[str, float] | None:
    """Calibrate on the two halves of the views (``refit(0)``, ``refit(1)``) and map the
    calibration's stripe footprint with both (in the flange frame with robot poses, else the
    camera frame): their difference (``rms``, ``p95`` mm) and the RMS of their combined
    predicted uncertainty (``predicted_rms``, the parameters' alone: the same pixels are
    mapped). None when a half cannot be calibrated."""
    from .map_sigma import footprint, point_sigmas

    px = footprint(model)
    if len(px) == 0:
        return None
    a = refit(0)
    b = refit(1) if a is not None else None
    if a is None or b is None:
        return None
    d = np.linalg.norm(a.at(px) - b.at(px), axis=1)
    sig = np.sqrt(point_sigmas(a, px, 0.0) ** 2 + point_sigmas(b, px, 0.0) ** 2)
    ok = np.isfinite(d) & np.isfinite(sig)
    if not ok.any():
        return None
    return {"rms": float(np.sqrt(np.mean(d[ok] ** 2))), "p95": float(np.percentile(d[ok], 95)),
            "predicted_rms": float(np.sqrt(np.mean(sig[ok] ** 2)))}


def require_check(verdict: Verdict, require_mm: float | None) -> Verdict:
    """``verdict`` with the user's demand on the predicted 95th-percentile 3D uncertainty
    (``hmlvs calibrate --require MM``) as one more check; unchanged without a demand."""
    if require_mm is None:
        return verdict
    if not (math.isfinite(require_mm) and require_mm > 0):
        raise ValueError(f"--require must be a positive number of mm, got {require_mm}")
    p95 = float("inf") if verdict.map_sigma_mm is None else verdict.map_sigma_mm["p95"]
    checks = [*verdict.checks, make_check(
        "map_sigma_p95", p95, require_mm, "mm",
        "the user's demand (--require) on the predicted 95th-percentile 3D uncertainty",
        f"the predicted 3D uncertainty reaches {p95:.3f} mm at the 95th percentile, more "
        f"than the {require_mm:g} mm required")]
    if verdict.cross_validation_mm is not None:
        cv95 = verdict.cross_validation_mm["p95"]
        checks.append(make_check(
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

def judge_paper(result: Any, dataset: Any = None, *, views: Sequence[Any] | None = None,
                map_sigma: bool = True, mistakes: bool = True, cross_validate: bool = True,
                image_size: tuple[int, int] | None = None) -> Verdict:
    """The verdict on a paper-model calibration
    (:class:`hmlvs.calibration.result.CalibrationResult`) and the
    data set it was fitted to: the paper model's own checks (the solve's end, the fit
    against the sensor class's accuracy, held-out points against the fit) and, with the
    data set, the checks both models share (the stripe's coverage of the image when its size
    is known, the variety of the poses, the unknowns determined, the cross-validation of the
    two halves of the poses) and the predicted 3D uncertainty. With the ``views`` of a
    session from images (:attr:`ImageReport.view`) and the board the data set records
    (``meta["board"]``, with its pose in the base), the corner and robot-chain checks too,
    the robot's pose error in the uncertainty and, when a check fails, the likely mistake
    (:func:`find_mistake`)."""
    from .map_sigma import of_paper, pose_groups

    checks = paper_checks(result)
    unc = getattr(result, "uncertainty", None)
    if unc is not None:
        checks.append(unknowns_check(len(unc.free) - len(unc.flat), len(unc.free)))
    if dataset is None:
        return verdict_from_checks(checks)
    model = of_paper(result, dataset) if (map_sigma or cross_validate) else None
    size = image_size or _image_size(dataset)
    board, board_pose = _board_of(dataset)
    chain = (chain_of_paper(result, views, board, board_pose, size)
             if views and board is not None else None)
    if chain is not None:
        checks = checks[:1] + chain_checks(chain) + checks[1:]
        if model is not None:
            robot = pose_error_mm(chain)
            model.pose_sigma_mm = robot if math.isfinite(robot) else 0.0
    if model is not None and size is not None:
        checks += coverage_checks(None, model.pixel_sets, size)
    groups = pose_groups(dataset)
    poses = np.asarray(dataset.poses, float)
    firsts = [int(np.nonzero(groups == g)[0][0]) for g in np.unique(groups)]
    checks.append(variety_check([poses[i][:3, :3].T for i in firsts]))
    refit = _paper_halves(result, dataset, groups) if cross_validate else None

    def mistake() -> str | None:
        if not (mistakes and chain is not None and size is not None):
            return None
        return find_mistake(chain.views, chain.board, size).sentence

    v = _finish(checks, model, refit, mistake, size)
    if not map_sigma:
        v.map_sigma_mm, v.map_points = None, None
    return v


def _board_of(dataset: Any) -> tuple[BoardSpec | None, np.ndarray | None]:
    """The board a data set from images records (``meta["board"]``): its spec and its pose
    in the base, or (None, None)."""
    b = (getattr(dataset, "meta", None) or {}).get("board")
    if not isinstance(b, dict) or "base_from_board" not in b:
        return None, None
    return (BoardSpec(int(b["rows"]), int(b["cols"]), float(b["square"])),
            np.asarray(b["base_from_board"], float))


def _image_size(dataset: Any) -> tuple[int, int] | None:
    size = (getattr(dataset, "meta", None) or {}).get("image_size")
    return (int(size[0]), int(size[1])) if isinstance(size, (list, tuple)) and len(size) == 2 \
        else None


def _paper_halves(result: Any, dataset: Any, groups: np.ndarray
                  ) -> Callable[[int], PointModel | None] | None:
    """The point models of paper-model calibrations (modern LM from the calibration judged,
    its parameters held as it held them) on the two halves of the poses (alternate poses);
    None with fewer than 3 poses a half."""
    from ..calibration.solvers import calibrate
    from ..data.guess import bounds_with
    from .map_sigma import of_paper

    labels = np.unique(groups)
    if len(labels) < 6:
        return None
    halves = [np.nonzero(np.isin(groups, labels[k::2]))[0] for k in (0, 1)]

    def refit(k: int) -> PointModel | None:
        half = dataset.subset(halves[k])
        # the bounds widened to hold the calibration judged (modern LM solves the rotation on
        # SO(3): near the ZYZ gimbal lock its Euler angles may leave Table 2's)
        bounds, _ = bounds_with(result.params, result.bounds)
        try:
            r = calibrate(half, method="lm", initial=result.params, fixed=result.fixed,
                          bounds=bounds, threads=1)
        except ValueError:
            return None
        return of_paper(r, half)

    return refit
