"""Reports: the self-contained HTML calibration report of either sensor model,
:func:`write_calibration_report` (in :mod:`hmlvs.report.calibration`)."""

from typing import Any

from .._lazy import submodules

_submodule = submodules(__name__)


def __getattr__(name: str) -> Any:
    if name == "write_calibration_report":
        from .calibration import write_calibration_report

        return write_calibration_report
    return _submodule(name)
