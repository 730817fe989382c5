"""How the ranges and the resolution change with one design parameter (paper Figs. 4-5)."""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Any, Iterable, Optional

import numpy as np

from .sensor import (
    SWEEPABLE,
    Sensor,
    analyze_sensor,
    json_value,
    positive,
)


@dataclass(frozen=True, eq=False)
class SweepResult:
    """Ranges and resolution as one design quantity varies (paper Figs. 4 and 5).

    All arrays have the length of ``values``; NaN where no pixel sees the laser plane.

    Attributes
    ----------
    parameter : str
        The varied sensor field ("H", "theta", "f" or "k").
    values : ndarray
        Its values, in the sensor's units (theta in rad).
    base : Sensor
        The design the other quantities are taken from.
    x_growth, x_extent, x_width_near, x_width_far, y, z, z_near, z_far : ndarray
        Ranges (mm), as in :class:`Ranges`.
    res_u_min, res_u_max, res_v_min, res_v_max, res_u_center, res_v_center : ndarray
        Resolution statistics (mm/px), as in :class:`Resolution`.
    usable_fraction : ndarray
        Fraction of the image that sees the laser plane.
    """

    parameter: str
    values: np.ndarray
    base: Sensor
    x_growth: np.ndarray
    x_extent: np.ndarray
    x_width_near: np.ndarray
    x_width_far: np.ndarray
    y: np.ndarray
    z: np.ndarray
    z_near: np.ndarray
    z_far: np.ndarray
    res_u_min: np.ndarray
    res_u_max: np.ndarray
    res_v_min: np.ndarray
    res_v_max: np.ndarray
    res_u_center: np.ndarray
    res_v_center: np.ndarray
    usable_fraction: np.ndarray

    @property
    def display_values(self) -> np.ndarray:
        """``values`` in display units (theta in degrees)."""
        return np.degrees(self.values) if self.parameter == "theta" else self.values

    @property
    def display_unit(self) -> str:
        return {"H": "mm", "theta": "deg", "f": "mm", "k": "1/mm^2"}[self.parameter]

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"parameter": self.parameter, "unit": self.display_unit,
                               "base": self.base.to_dict()}
        for name in ("x_growth", "x_extent", "x_width_near", "x_width_far", "y", "z",
                     "z_near", "z_far", "res_u_min", "res_u_max", "res_v_min", "res_v_max",
                     "res_u_center", "res_v_center", "usable_fraction"):
            out[name] = [json_value(float(v)) for v in getattr(self, name)]
        out["values"] = [float(v) for v in self.display_values]
        return out


def default_sweep_values(parameter: str, base: Sensor) -> np.ndarray:
    """Sweep values around ``base``: H from 0.5 H to 1.5 H in 21 steps (50..150 mm for the
    paper's design); theta from 15 to 45 deg by 1 deg, plus the design angle."""
    if parameter == "H":
        return np.linspace(0.5 * base.H, 1.5 * base.H, 21)
    if parameter == "theta":
        deg = np.union1d(np.arange(15.0, 45.5, 1.0), [round(math.degrees(base.theta), 9)])
        return np.radians(deg)
    if parameter == "f":
        return np.linspace(0.5 * base.f, 1.5 * base.f, 21)
    if parameter == "k":
        return np.linspace(0.0, 0.1, 21)
    raise ValueError(f"cannot sweep {parameter!r}; choose one of {', '.join(SWEEPABLE)}")


def sweep(parameter: str, values: Optional[Iterable[float]] = None, *,
          sensor: Optional[Sensor] = None, resolution_limit: float = 1.0,
          **design: Any) -> SweepResult:
    """Ranges and resolution as ``parameter`` varies, the rest fixed (Figs. 4 and 5).

    Parameters
    ----------
    parameter : {"H", "theta", "f", "k"}
        The design quantity to vary; Fig. 4 varies H (theta = 25 deg), Fig. 5 theta
        (H = 100 mm).
    values : sequence of float, optional
        Its values (theta in rad); :func:`default_sweep_values` if omitted.
    sensor : Sensor, optional
        The fixed design; otherwise built from ``design`` (the arguments of
        :func:`analyze`, defaults included).
    resolution_limit : float
        As in :func:`analyze`.

    Returns
    -------
    SweepResult
        A value at which no pixel sees the laser plane gets NaN ranges and resolution.

    Examples
    --------
    >>> s = hmlvs.paper.design.sweep("H", [50.0, 100.0, 150.0])
    >>> np.round(s.z / s.values, 4)   # the ranges scale with H
    array([2.6316, 2.6316, 2.6316])
    """
    if parameter not in SWEEPABLE:
        raise ValueError(f"cannot sweep {parameter!r}; choose one of {', '.join(SWEEPABLE)}")
    base = sensor if sensor is not None else Sensor.make(**design)
    vals = (default_sweep_values(parameter, base) if values is None
            else np.asarray(list(values), dtype=float).reshape(-1))
    if vals.size == 0:
        raise ValueError("sweep needs at least one value")
    limit = positive("resolution_limit", resolution_limit, "mm/px")
    names = ("x_growth", "x_extent", "x_width_near", "x_width_far", "y", "z", "z_near",
             "z_far")
    rnames = ("u_min", "u_max", "v_min", "v_max", "u_center", "v_center")
    cols: dict[str, list[float]] = {n: [] for n in names + rnames + ("usable_fraction",)}
    for value in vals:
        r = analyze_sensor(base.replace(**{parameter: float(value)}), limit)
        for n in names:
            cols[n].append(getattr(r.ranges, n) if r else math.nan)
        for n in rnames:
            cols[n].append(getattr(r.resolution, n) if r else math.nan)
        cols["usable_fraction"].append(r.usable_fraction if r else 0.0)
    arr = {n: np.array(v) for n, v in cols.items()}
    return SweepResult(parameter=parameter, values=vals, base=base,
                       **{n: arr[n] for n in names},
                       **{f"res_{n}": arr[n] for n in rnames},
                       usable_fraction=arr["usable_fraction"])
