"""Sensor design analysis (paper section 2, Figs. 3-6): measurement range, resolution, and
the 3D error caused by a wrong baseline H or projection angle theta.

Everything is computed in the camera frame by the model of docs/model.md (``hmlvs._core``
through :func:`hmlvs.models.paper.points_in_camera`), at every pixel of the image; this module only
measures the resulting point maps. Units: mm, rad, pixels (angles in degrees only in text).

Definitions (the paper does not give them; these are ours):

- A pixel is *usable* if its ray meets the laser plane in front of the camera
  (``Yu + f tan(theta) > 0``). With k = 0 usability depends on the row only: rows that look
  above the laser plane's horizon see no stripe.
- *z range* = largest minus smallest depth over the usable pixels (the depth of the first,
  farthest usable row minus that of the last, nearest row when k = 0).
- *y range* = largest minus smallest y over the usable pixels. Every point lies on the plane
  ``y + z tan(theta) = H``, so this equals ``tan(theta)`` times the z range.
- x: the stripe on an image row runs from column 0 to column w - 1; its *length* on that row
  is ``x(w - 1, v) - x(0, v)`` (pixel centres, so w - 1 pitches). We report four candidates:
  ``x_extent`` (largest minus smallest x over the usable image: the lateral field of view at
  the far end), the stripe length on the nearest, the mid-depth and the farthest usable
  rows, and ``x_growth`` = far length - near length, i.e. how much the stripe lengthens
  over the depth range. Only ``x_growth`` is near the paper's 155.0 mm (155.55 mm; see the
  docs/paper.md, "Sensor design analysis", for the rest of the difference).
- *Resolution* (the paper: "the displacement in the 3D real space per one pixel"): at pixel
  (u, v), ``res_u = |P(u + 1/2, v) - P(u - 1/2, v)|`` and
  ``res_v = |P(u, v + 1/2) - P(u, v - 1/2)|`` in mm/px, the 3D displacement over a one-pixel
  step centred on the pixel; NaN where a half step leaves the usable region."""

from .miscalibration import ErrorReport, error_from_wrong, paper_errors
from .plots import PLOT_DPI, plot
from .sensor import (
    MAX_PIXELS,
    PAPER_RANGES,
    PAPER_WRONG_H,
    PAPER_WRONG_THETA_DEG,
    SWEEPABLE,
    DesignReport,
    Ranges,
    Resolution,
    Sensor,
    analyze,
)
from .sweep import SweepResult, default_sweep_values, sweep

__all__ = [
    "DesignReport", "ErrorReport", "MAX_PIXELS", "PAPER_RANGES", "PAPER_WRONG_H",
    "PAPER_WRONG_THETA_DEG", "PLOT_DPI", "Ranges", "Resolution", "SWEEPABLE", "Sensor",
    "SweepResult", "analyze", "default_sweep_values", "error_from_wrong", "paper_errors",
    "plot", "sweep"
]
