"""The warnings and errors hmlvs raises, in one place.

Data warnings: every warning about what the data can or cannot determine is an instance of a
subclass of :class:`HmlvsDataWarning` (filter one kind or all). Errors: bad input is a
``ValueError`` naming the problem; the subclasses here let a caller tell a few kinds apart.
"""

from __future__ import annotations


class BoardNotFoundError(ValueError):
    """No (whole) checkerboard was found in the image."""


class NumberingError(ValueError):
    """Corners were found, but which board corners they are cannot be decided safely."""


class SchemaError(ValueError):
    """A document that does not match its schema (a ``ValueError``)."""


class HmlvsDataWarning(UserWarning):
    """The data cannot determine (some of) what is being estimated.

    Every data warning of hmlvs is an instance of one of the subclasses below, so that a
    user can filter one kind (``warnings.simplefilter("ignore", hmlvs.errors.TooFewPointsWarning)``)
    or all of them (``HmlvsDataWarning``). :func:`warning_category` maps a message (as stored
    in ``CalibrationResult.warnings``) to its subclass. The terms are explained in
    ``docs/glossary.md``.
    """

    kind = "data"


class FlatDirectionWarning(HmlvsDataWarning):
    """A combination of free parameters that the data do not determine (flat) or determine
    only weakly; the covariance is then rank-deficient. See "flat direction" in the
    glossary."""

    kind = "flat-direction"


class TooFewPointsWarning(HmlvsDataWarning):
    """Fewer calibration points than three per free parameter."""

    kind = "too-few-points"


class PoseVarietyWarning(HmlvsDataWarning):
    """The points come from nearly one hand pose, or every stripe pixel lies on one image
    line: the data cover too little of the working volume or of the image."""

    kind = "pose-variety"


class GimbalLockWarning(HmlvsDataWarning):
    """phi is at or near 0, where the ZYZ Euler angles omega and varphi turn about the same
    axis: only omega + varphi (and the rotation as a whole) are determined."""

    kind = "gimbal-lock"


class AtBoundWarning(HmlvsDataWarning):
    """A parameter ended at a bound of the search box."""

    kind = "at-bound"


class SetupWarning(HmlvsDataWarning):
    """A simulated set-up (board, stand-off, image size) does not suit the sensor: many views
    would not show enough of the board to be used."""

    kind = "setup"


class DiagnosticsFailedWarning(HmlvsDataWarning):
    """The identifiability or uncertainty analysis could not be computed."""

    kind = "diagnostics"


def warning_category(message: str) -> type[HmlvsDataWarning]:
    """The :class:`HmlvsDataWarning` subclass of a data-warning message.

    The messages come from :func:`data_warnings`, :func:`hmlvs.diagnostics.uncertainty.
    diagnose` and the solvers; anything not recognised is a plain ``HmlvsDataWarning``.
    """
    m = str(message)
    if m.startswith("too few points"):
        return TooFewPointsWarning
    if "nearly the same hand pose" in m or "lie on one image line" in m:
        return PoseVarietyWarning
    if "gimbal lock" in m:
        return GimbalLockWarning
    if "direction among the free parameters" in m or "rank-deficient" in m:
        return FlatDirectionWarning
    if "at a bound" in m or "at the bound" in m:
        return AtBoundWarning
    if "not computed" in m:
        return DiagnosticsFailedWarning
    if "views cannot be used" in m:
        return SetupWarning
    return HmlvsDataWarning


def warn_data(message: str, stacklevel: int = 2) -> None:
    """Issue ``message`` as the :class:`HmlvsDataWarning` subclass of its kind."""
    import warnings

    warnings.warn(message, warning_category(message), stacklevel=stacklevel + 1)
