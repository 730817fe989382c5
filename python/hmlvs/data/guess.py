"""A user's initial guess and search bounds for the paper model (``--initial``, ``--bounds``).

Initial guess: a calibration file of either model (an opencv calibration is converted by
:func:`hmlvs.models.convert.paper_params_of`), or a YAML/JSON mapping of parameter names to
values (the others nominal)::

    f: 8.2
    H: 135
    theta: 0.45

Bounds: a YAML/JSON mapping; each named parameter gets an absolute range or a +- half-width
around the initial guess (same unit as the parameter); the others keep Table 2::

    f: [6, 10]                 # absolute range
    tx: {plus_minus: 5}        # initial tx +- 5 mm
    phi: {plus_minus: 0.1}     # initial phi +- 0.1 rad
"""

from __future__ import annotations

import os
from typing import Any

from .._io import read_document
from ..models.params import NAMES, Bounds, Parameters, param_index


def _read_mapping(path: str | os.PathLike, what: str) -> dict[str, Any]:
    d = read_document(path, what)
    if not isinstance(d, dict):
        raise ValueError(f"{path}: the {what} must be a mapping of parameter names, got "
                         f"{type(d).__name__}")
    return d


def read_initial(path: str | os.PathLike, su: float | None = None) -> Parameters:
    """The initial guess in a file (module doc). ``su`` (mm/px) is the pixel pitch used to
    convert an opencv calibration (default: the nominal 0.0074)."""
    d = _read_mapping(path, "initial guess")
    if d.get("format") == "hmlvs-calibration":
        from ..models.convert import paper_params_of
        from .calibration_file import Calibration

        cal = Calibration.from_dict(d, source=str(path))
        if cal.params is not None:
            return cal.params
        assert cal.sensor is not None
        return paper_params_of(cal.sensor) if su is None else paper_params_of(cal.sensor, su)
    values = Parameters.nominal().to_dict()
    for name, v in d.items():
        try:
            param_index(str(name))
        except ValueError as e:
            raise ValueError(f"{path}: {e}") from None
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise ValueError(f"{path}: {name} must be a number, got {v!r}")
        values[str(name)] = float(v)
    bad = [n for n in ("f", "Su", "Sv") if not values[n] > 0]
    if bad:
        raise ValueError(f"{path}: {', '.join(f'{n} = {values[n]:g}' for n in bad)}: the focal "
                         "length f and the pixel pitches Su, Sv scale every pixel to mm and "
                         "must be > 0")
    try:
        return Parameters.from_dict(values)
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from None


def initial_board_pose(path: str | os.PathLike) -> Any:
    """The board's pose in the base (4 x 4) that an opencv calibration used as the initial
    guess estimated, or None (a paper calibration or a parameter mapping holds none): the
    paper model needs the board placed, and a session whose manifest does not place it is
    placed there."""
    import numpy as np

    d = _read_mapping(path, "initial guess")
    if d.get("format") != "hmlvs-calibration":
        return None
    from .calibration_file import Calibration

    cal = Calibration.from_dict(d, source=str(path))
    pose = None if cal.sensor is None else cal.sensor.base_from_board
    return None if pose is None else np.asarray(pose, float)


def bounds_with(guess: Parameters, bounds: Bounds | None = None) -> tuple[Bounds, list[str]]:
    """``bounds`` (default Table 2) widened, where the initial guess lies outside them, to hold
    it with a margin of a tenth of the range: the Table 2 ranges are the paper's camera's (its
    k >= 0 excludes an ordinary barrel lens, whose division-model k is negative), while a guess
    from one's own calibration is the better knowledge. Returns the bounds and one note per
    widened parameter."""
    b = Bounds.table2() if bounds is None else bounds
    lo, hi = b.lower.copy(), b.upper.copy()
    q = guess.to_array()
    notes = []
    for i, name in enumerate(NAMES):
        margin = 0.1 * (hi[i] - lo[i])
        if q[i] < lo[i]:
            lo[i] = q[i] - margin
        elif q[i] > hi[i]:
            hi[i] = q[i] + margin
        else:
            continue
        notes.append(f"the search range of {name} widened to [{lo[i]:.6g}, {hi[i]:.6g}] to "
                     f"hold the initial guess {q[i]:.6g}")
    return Bounds(lo, hi), notes


def read_bounds(path: str | os.PathLike, initial: Parameters) -> Bounds:
    """The search bounds in a file (module doc), +- ranges taken around ``initial``."""
    d = _read_mapping(path, "bounds file")
    q0 = initial.to_array()
    b = Bounds.table2()
    lo, hi = b.lower.copy(), b.upper.copy()
    for name, v in d.items():
        try:
            i = param_index(str(name))
        except ValueError as e:
            raise ValueError(f"{path}: {e}") from None
        if isinstance(v, dict) and set(v) == {"plus_minus"}:
            h = v["plus_minus"]
            if isinstance(h, bool) or not isinstance(h, (int, float)) or not h >= 0:
                raise ValueError(f"{path}: {name}: plus_minus must be a number >= 0, got {h!r}")
            lo[i], hi[i] = q0[i] - h, q0[i] + h
        elif (isinstance(v, list) and len(v) == 2
              and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)):
            lo[i], hi[i] = float(v[0]), float(v[1])
        else:
            raise ValueError(f"{path}: {name} must be [lower, upper] or {{plus_minus: h}}, got "
                             f"{v!r}")
    try:
        bounds = Bounds(lo, hi)
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from None
    outside = [n for k, n in enumerate(NAMES) if not lo[k] <= q0[k] <= hi[k]]
    if outside:
        raise ValueError(f"{path}: the initial value of {', '.join(outside)} lies outside its "
                         "bounds")
    return bounds


__all__ = ["read_initial", "read_bounds"]
