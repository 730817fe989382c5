"""The 3D error a wrong baseline H or projection angle theta causes (paper Fig. 6)."""

from __future__ import annotations

from dataclasses import dataclass, field
import math
from typing import Any, Optional

import numpy as np

from .sensor import PAPER_WRONG_H, PAPER_WRONG_THETA_DEG, Sensor, point_map


@dataclass(frozen=True, eq=False)
class ErrorReport:
    """3D error of every pixel's point computed with a wrong H and/or theta (Fig. 6).

    The sensor's real laser plane is the one of ``true``; a stripe seen at pixel (u, v) is
    therefore the point ``P_true(u, v)``, but the computation uses ``used`` and gets
    ``P_used(u, v)``. The error is ``P_used - P_true`` (camera frame, mm).

    Attributes
    ----------
    used, true : Sensor
        The design values used in the computation and the sensor's real ones.
    vectors : ndarray, shape (height, width, 3)
        ``P_used - P_true`` (mm); NaN where either computation has no point.
    error : ndarray, shape (height, width)
        ``|P_used - P_true|`` (mm).
    valid : ndarray of bool, shape (height, width)
        Pixels usable under both.
    max, mean : float
        Largest and mean error over the valid pixels (mm).
    worst_pixel : (int, int)
        (u, v) of the largest error.
    """

    used: Sensor
    true: Sensor
    vectors: np.ndarray = field(repr=False)
    error: np.ndarray = field(repr=False)
    valid: np.ndarray = field(repr=False)
    max: float
    mean: float
    worst_pixel: tuple[int, int]

    @property
    def label(self) -> str:
        parts = []
        if self.used.H != self.true.H:
            parts.append(f"H {self.used.H:g} mm used, true {self.true.H:g} mm")
        if self.used.theta != self.true.theta:
            parts.append(f"theta {math.degrees(self.used.theta):g} deg used, true "
                         f"{math.degrees(self.true.theta):g} deg")
        return "; ".join(parts) if parts else "no difference"

    @property
    def slug(self) -> str:
        """A short file-name tag: "H", "theta" or "H_theta"."""
        tags = [t for t, d in (("H", self.used.H != self.true.H),
                               ("theta", self.used.theta != self.true.theta)) if d]
        return "_".join(tags) or "none"

    def to_dict(self) -> dict[str, Any]:
        return {"case": self.label, "used": {"H": self.used.H,
                                             "theta_deg": math.degrees(self.used.theta)},
                "true": {"H": self.true.H, "theta_deg": math.degrees(self.true.theta)},
                "max_mm": self.max, "mean_mm": self.mean,
                "worst_pixel": list(self.worst_pixel),
                "valid_fraction": float(self.valid.mean())}

    def __str__(self) -> str:
        return (f"{self.label}: 3D error max {self.max:.3f} mm at pixel "
                f"{self.worst_pixel}, mean {self.mean:.3f} mm over "
                f"{100 * self.valid.mean():.1f}% of the image")


_DESIGN_ARGS = ("f", "pixel_pitch", "image_size", "H", "theta", "k", "principal_point")


def error_from_wrong(*, H_true: Optional[float] = None, theta_true: Optional[float] = None,
                     sensor: Optional[Sensor] = None, **design: Any) -> ErrorReport:
    """The 3D error over the image when the computation uses H and theta but the sensor's
    real values are ``H_true`` and ``theta_true`` (paper Fig. 6).

    Parameters
    ----------
    f, pixel_pitch, image_size, H, theta, k, principal_point
        The design as used in the computation, by keyword, with :func:`analyze`'s defaults;
        or ``sensor``.
    H_true : float, optional
        The real baseline (mm); the paper's Fig. 6a uses 99 for H = 100.
    theta_true : float, optional
        The real projection angle (rad); the paper's Fig. 6b uses 22.5 deg for 25 deg.
    sensor : Sensor, optional
        The design as used, instead of the separate arguments.

    Returns
    -------
    ErrorReport

    Raises
    ------
    ValueError
        If neither true value is given, a value is out of range, or no pixel sees the
        laser plane under both designs.

    Examples
    --------
    >>> e = hmlvs.paper.design.error_from_wrong(H=100.0, H_true=99.0)
    >>> round(e.max, 2)   # = |P| / 100 at the far image corners
    4.35
    """
    unknown = sorted(set(design) - set(_DESIGN_ARGS))
    if unknown:
        raise ValueError(f"unknown design argument(s) {', '.join(unknown)}; valid: "
                         f"{', '.join(_DESIGN_ARGS)}")
    used = sensor if sensor is not None else Sensor.make(**design)
    if H_true is None and theta_true is None:
        raise ValueError("give H_true and/or theta_true: the sensor's real value(s)")
    changes: dict[str, float] = {}
    if H_true is not None:
        changes["H"] = H_true
    if theta_true is not None:
        changes["theta"] = theta_true
    try:
        true = used.replace(**changes)
    except ValueError as e:
        raise ValueError(f"the true value is invalid: {e}") from None
    p_used, p_true = point_map(used), point_map(true)
    vec = p_used - p_true
    err = np.linalg.norm(vec, axis=2)
    valid = np.isfinite(err)
    if not valid.any():
        raise ValueError(f"no pixel sees the laser plane under both the used values and the "
                         f"true ones ({true.describe()})")
    flat = int(np.nanargmax(err))
    v, u = divmod(flat, used.width)
    return ErrorReport(used=used, true=true, vectors=vec, error=err, valid=valid,
                       max=float(err[valid].max()), mean=float(err[valid].mean()),
                       worst_pixel=(int(u), int(v)))


def paper_errors(sensor: Sensor) -> list[ErrorReport]:
    """The paper's two Fig. 6 cases around ``sensor``: real H 1 mm smaller, real theta
    2.5 deg smaller (100 vs 99 mm and 25 vs 22.5 deg for the paper's design)."""
    dH = PAPER_WRONG_H[0] - PAPER_WRONG_H[1]
    dtheta = math.radians(PAPER_WRONG_THETA_DEG[0] - PAPER_WRONG_THETA_DEG[1])
    return [error_from_wrong(sensor=sensor, H_true=sensor.H - dH),
            error_from_wrong(sensor=sensor, theta_true=sensor.theta - dtheta)]
