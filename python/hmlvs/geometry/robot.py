"""Robot forward kinematics from Denavit-Hartenberg tables (paper Eq. 4), evaluated in C++."""

from __future__ import annotations

from dataclasses import dataclass, field
import math
from typing import Any, Literal, Sequence

import numpy as np

from .. import _core

Convention = Literal["standard", "modified"]


@dataclass(frozen=True)
class DHLink:
    """One row of a DH table (lengths in mm, angles in rad).

    In the standard convention the row holds (a_i, alpha_i, d_i) and the link transform is
    ``Rz(theta) Tz(d) Tx(a) Rx(alpha)``; in the modified (Craig) convention it holds
    (a_{i-1}, alpha_{i-1}, d_i) and the transform is ``Rx(alpha) Tx(a) Rz(theta) Tz(d)``.
    A revolute joint has ``theta = reading + offset``; a prismatic one ``d = reading + offset``
    with the fixed angle ``theta``.
    """

    a: float
    alpha: float
    d: float
    offset: float = 0.0
    prismatic: bool = False
    theta: float = 0.0


#: how far a base or tool transform's rotation may be from orthonormal (|R R^T - I|, entry by
#: entry) and its last row from [0 0 0 1]: a rotation written by hand with three or four
#: decimals passes (cos 45 deg as 0.7071: 2e-5), a scale, a mirror or a shear does not
RIGID_TOL = 1e-3


def _as_transform(t: Any, name: str) -> np.ndarray:
    from .._arrays import check_transform

    arr = np.asarray(t, dtype=float)
    if arr.shape != (4, 4) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be a finite 4x4 transform, got shape {arr.shape}")
    try:
        return check_transform(arr, name, tol=RIGID_TOL)
    except ValueError as e:
        raise ValueError(f"{e} to within {RIGID_TOL:g}") from None


@dataclass(frozen=True)
class Robot:
    """A serial arm given by a DH table, with optional base and tool transforms.

    ``poses(joints)`` maps joint readings (m x n) to base_from_hand poses (m x 4 x 4).
    """

    links: tuple[DHLink, ...]
    convention: Convention = "standard"
    base_from_link0: np.ndarray = field(default_factory=lambda: np.eye(4))
    flange_from_hand: np.ndarray = field(default_factory=lambda: np.eye(4))
    joint_limits: np.ndarray | None = None  # (n, 2) in rad (mm for prismatic joints)
    name: str = "robot"

    def __post_init__(self) -> None:
        if self.convention not in ("standard", "modified"):
            raise ValueError(f"convention must be 'standard' or 'modified', got "
                             f"{self.convention!r}")
        links = tuple(lk if isinstance(lk, DHLink) else DHLink(**lk) for lk in self.links)
        if not links:
            raise ValueError("a robot needs at least one DH link")
        for i, lk in enumerate(links):
            vals = (lk.a, lk.alpha, lk.d, lk.offset, lk.theta)
            if not all(math.isfinite(float(v)) for v in vals):
                raise ValueError(f"DH link {i + 1} has a non-finite entry: {lk}")
        object.__setattr__(self, "links", links)
        object.__setattr__(self, "base_from_link0",
                           _as_transform(self.base_from_link0, "base_from_link0"))
        object.__setattr__(self, "flange_from_hand",
                           _as_transform(self.flange_from_hand, "flange_from_hand"))
        if self.joint_limits is not None:
            lim = np.asarray(self.joint_limits, dtype=float)
            if lim.shape != (len(links), 2) or np.any(lim[:, 0] > lim[:, 1]):
                raise ValueError(f"joint_limits must be ({len(links)}, 2) with lower <= upper")
            object.__setattr__(self, "joint_limits", lim)

    @property
    def dof(self) -> int:
        return len(self.links)

    def __getstate__(self) -> dict:
        return {k: v for k, v in self.__dict__.items() if k != "_native_robot"}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)

    def _native(self) -> Any:
        """The C++ robot, built once per Robot (its fields are frozen)."""
        r = self.__dict__.get("_native_robot")
        if r is None:
            r = self._build_native()
            object.__setattr__(self, "_native_robot", r)
        return r

    def _build_native(self) -> Any:
        r = _core._DHRobot()
        joints = []
        for lk in self.links:
            j = _core._DHJoint()
            j.a, j.alpha, j.d, j.offset = lk.a, lk.alpha, lk.d, lk.offset
            j.prismatic, j.theta = lk.prismatic, lk.theta
            joints.append(j)
        r.joints = joints
        r.convention = getattr(_core._DHConvention, self.convention)
        r.base_from_link0 = self.base_from_link0
        r.flange_from_hand = self.flange_from_hand
        return r

    def poses(self, joints: Any, degrees: bool = False) -> np.ndarray:
        """Joint readings (m, n) or (n,) -> base_from_hand poses (m, 4, 4).

        Revolute readings are in rad, or in degrees with ``degrees=True``; prismatic in mm.
        """
        q = np.asarray(joints, dtype=float)
        if q.ndim == 1:
            q = q[None, :]
        if q.ndim != 2 or q.shape[1] != self.dof:
            raise ValueError(f"joint readings must have shape (m, {self.dof}) for this "
                             f"{self.dof}-joint robot, got {np.shape(joints)}")
        if degrees:
            q = q.copy()
            rev = np.array([not lk.prismatic for lk in self.links])
            q[:, rev] = np.radians(q[:, rev])
        out = _core._forward_kinematics(self._native(), np.ascontiguousarray(q))
        return np.asarray(out).reshape(-1, 4, 4)

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "convention": self.convention,
            "links": [lk.__dict__.copy() for lk in self.links],
            "base_from_link0": self.base_from_link0.tolist(),
            "flange_from_hand": self.flange_from_hand.tolist(),
            "joint_limits": None if self.joint_limits is None else self.joint_limits.tolist(),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "Robot":
        try:
            return cls(
                links=tuple(DHLink(**lk) for lk in d["links"]),
                convention=d.get("convention", "standard"),
                base_from_link0=np.asarray(d.get("base_from_link0", np.eye(4))),
                flange_from_hand=np.asarray(d.get("flange_from_hand", np.eye(4))),
                joint_limits=None if d.get("joint_limits") is None else np.asarray(
                    d["joint_limits"]),
                name=d.get("name", "robot"),
            )
        except (KeyError, TypeError) as e:
            raise ValueError(f"malformed robot description: {e}") from None

    @classmethod
    def from_dh(cls, table: Sequence[Sequence[float]], convention: Convention = "standard",
                **kwargs: Any) -> "Robot":
        """From rows ``(a, alpha, d)`` or ``(a, alpha, d, offset)`` (mm, rad)."""
        links = []
        for i, row in enumerate(table):
            if len(row) not in (3, 4):
                raise ValueError(f"DH row {i + 1} must be (a, alpha, d[, offset]), got {row}")
            links.append(DHLink(*[float(x) for x in row]))
        return cls(tuple(links), convention, **kwargs)

    @classmethod
    def scorbot_er7(cls) -> "Robot":
        """The paper's 5-DOF SCORBOT ER-VII (standard DH, mm and rad).

        d1 = 358.5, a1 = 50, a2 = 300, a3 = 350 and 251 mm from the wrist to the flange. These
        numbers come from public motion-controller code for this arm, not from the maker's
        manual; the joint limits are approximate and only bound simulated poses. At zero
        readings the arm is stretched along base x and the flange (hand z axis) points down.
        """
        h = math.pi / 2
        links = (
            DHLink(a=50.0, alpha=-h, d=358.5),   # base yaw
            DHLink(a=300.0, alpha=0.0, d=0.0),   # shoulder
            DHLink(a=350.0, alpha=0.0, d=0.0),   # elbow
            DHLink(a=0.0, alpha=-h, d=0.0),      # wrist pitch
            DHLink(a=0.0, alpha=0.0, d=251.0),   # wrist roll, to the flange
        )
        limits = np.radians([[-155, 155], [-130, 35], [-130, 130], [-130, 130], [-360, 360]])
        return cls(links, "standard", joint_limits=limits, name="SCORBOT ER-VII")
