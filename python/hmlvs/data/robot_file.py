"""Robot descriptions from files and manifests: the :meth:`hmlvs.Robot.to_dict` mapping as
YAML or JSON, or the name of a built-in arm."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Callable

from .._io import read_document, write_document
from ..geometry.robot import Robot

#: the arms hmlvs knows by name
BUILTIN: dict[str, Callable[[], Robot]] = {"SCORBOT ER-VII": Robot.scorbot_er7}


def _schema() -> Any:
    """The :meth:`Robot.to_dict` mapping: DH rows (mm, rad), base and tool transforms,
    optional joint limits. Unknown keys are refused by name (a misspelt ``convention`` would
    otherwise leave the default in force)."""
    from . import schema as sc

    link = sc.Field("struct", "a DH row {a, alpha, d[, offset, prismatic, theta]} (mm, rad)",
                    required=("a", "alpha", "d"), extra="error", keys={
                        "a": sc.number("a length in mm"), "alpha": sc.number("an angle in rad"),
                        "d": sc.number("a length in mm"), "offset": sc.number(),
                        "theta": sc.number("an angle in rad"), "prismatic": sc.Field("bool")})
    return sc.Field(
        "struct", "a robot description: a mapping with 'links', a list of DH rows {a, alpha, "
        "d[, offset, prismatic, theta]} (the hmlvs.Robot.to_dict form)",
        required=("links",), extra="error", keys={
            "name": sc.text("a name"),
            "convention": sc.text("the DH convention", choices=("standard", "modified")),
            "links": sc.Field("list", "a list of DH rows", items=link,
                              check=sc.non_empty("DH row")),
            "base_from_link0": sc.matrix(4, 4, "a 4x4 transform"),
            "flange_from_hand": sc.matrix(4, 4, "a 4x4 transform"),
            "joint_limits": sc.Field("list", "a list of [lower, upper] per joint",
                                     nullable=True, items=sc.Field(
                                         "list", "[lower, upper]", length=2,
                                         items=sc.number()))})


def robot_from_dict(d: Any, source: str) -> Robot:
    """A Robot from its ``to_dict`` mapping, validated by its schema; ValueError naming
    ``source`` and the key (``arm.yaml: links[2].d: must be a length in mm, got '350'``)."""
    from .schema import validate

    validate(d, _schema(), str(source))
    try:
        return Robot.from_dict(d)
    except (ValueError, TypeError, AttributeError) as e:
        raise ValueError(f"{source}: malformed robot description ({e})") from None


def robot_from_description(value: Any, source: str) -> Robot:
    """A manifest's ``robot:``: a built-in arm's name or a ``to_dict`` mapping."""
    if isinstance(value, str):
        make = BUILTIN.get(value.strip())
        if make is None:
            raise ValueError(
                f"{source}: the robot {value!r} is not a built-in arm (hmlvs knows "
                f"{', '.join(repr(n) for n in BUILTIN)}); give its DH description: "
                "--robot FILE on the command line, robot=hmlvs.Robot(...) in code, or the "
                "hmlvs.Robot.to_dict mapping under 'robot:' in the manifest")
        return make()
    return robot_from_dict(value, f"{source}: robot")


def load_robot(path: str | os.PathLike) -> Robot:
    """Read a robot description file (YAML or JSON holding what :meth:`Robot.to_dict`
    writes; a document with a ``robot:`` mapping, such as a calibration file, also works)."""
    d = read_document(path, "robot description file")
    if isinstance(d, dict) and "links" not in d and isinstance(d.get("robot"), dict):
        d = d["robot"]
    return robot_from_dict(d, str(path))


def save_robot(robot: Robot, path: str | os.PathLike) -> Path:
    """Write ``robot.to_dict()`` atomically as YAML (.yaml/.yml) or JSON (.json)."""
    return write_document(path, robot.to_dict(), "robot description")
