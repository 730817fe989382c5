"""What the image pipeline says about each image pair it reads (:class:`ImageReport`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True)
class ImageReport:
    """What the image pipeline found in one image pair (the paper model's
    :func:`~hmlvs.image.paper_session.dataset_from_images`, the opencv model's
    :func:`~hmlvs.image.views.views_from_images`), and what it rejected.

    Attributes
    ----------
    id : the pose id (``"p003"``)
    index : position of the pair in the session (the data set's ``pose_index``)
    on, off : the image files (or ``"<array>"``)
    ok : True when the pair gave at least one calibration point
    reason : why the whole pair was rejected ("" when ok)
    stripe : scan lines per stripe status (``{"FOUND": 612, "MULTIPLE": 3, ...}``)
    corners : corners found and numbered
    points : calibration points contributed
    rejected : candidate points not used, with the reason for each
    blur_var : the camera blur variance (px^2) the stripe was corrected with at albedo steps
        (:func:`~hmlvs.image.session.stripe_from_pair` ``blur_var``, fitted to the session
        unless given); None for a rejected pair
    note : what the pipeline corrected in a pair it used (its board numbered again from the
        robot chain, :mod:`hmlvs.image.whole_check`); "" otherwise
    view : the pair's view when it was used (:class:`hmlvs.data.views.ViewData`: numbered
        corners, the stripe with every scan line's status, robot pose and joints), from
        which the paper model's calibration points were derived
        (:func:`hmlvs.image.paper_session.points_of_views`) and on which the verdict's corner
        and chain checks run; None otherwise
    """

    id: str
    index: int
    on: str
    off: str
    ok: bool
    reason: str = ""
    stripe: dict[str, int] = field(default_factory=dict)
    corners: int = 0
    points: int = 0
    rejected: dict[str, str] = field(default_factory=dict)
    blur_var: float | None = None
    view: Any = field(default=None, repr=False, compare=False)
    note: str = ""

    def to_dict(self) -> dict[str, Any]:
        """The account as plain JSON-ready values (without the view itself)."""
        return {"id": self.id, "index": self.index, "on": self.on, "off": self.off,
                "ok": self.ok, "reason": self.reason, "stripe": dict(self.stripe),
                "corners": self.corners, "points": self.points,
                "rejected": dict(self.rejected), "blur_var": self.blur_var,
                **({"note": self.note} if self.note else {})}

    def __str__(self) -> str:
        if not self.ok:
            return f"{self.id}: rejected: {self.reason}"
        n = len(self.rejected)
        extra = (f"; {n} candidate point{'s' if n > 1 else ''} not used ("
                 + "; ".join(f"{k}: {v}" for k, v in self.rejected.items()) + ")"
                 if self.rejected else "")
        return (f"{self.id}: {self.points} points, {self.corners} corners, stripe in "
                f"{self.stripe.get('FOUND', 0)} scan lines{extra}")
