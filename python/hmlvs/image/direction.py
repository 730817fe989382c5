"""Which way a frame's stripe runs: along the image's columns (across the image) or its rows
(down it), decided from the stripe each way finds (:func:`either_way`)."""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from .colour import laser_coloured
from .stripe import StripeResult


def either_way(extract: Callable[[dict[str, Any]], tuple[StripeResult, Any, Any]],
               stripe_options: dict[str, Any], on: np.ndarray | None = None,
               off: np.ndarray | None = None) -> tuple[StripeResult, Any, Any]:
    """``extract(options)`` (a tuple led by the stripe) with the options' ``direction``, or
    when none is given (or "auto") the way the stripe runs: along the image's columns when
    their stripe runs across the image (its found centres rise less than 1 px per column);
    else along its rows too, and the way that finds more scan lines wins (a tie: columns).
    On a colour frame ``on`` (laser-off frame ``off``) only the centres in the laser's colour
    count (:func:`~hmlvs.image.colour.laser_coloured`): glare and board edges found as a
    stripe along the other way are not the laser's (a green stripe down the image on a
    hand-held board: 33-85 such centres along the columns, 104-377 green ones along the rows).
    So a sensor whose stripe runs down the image (a laser plane turned, a camera on its side)
    needs no option. Raises the first way's ``ValueError`` when every way raised one."""
    given = stripe_options.get("direction")
    if given is not None and given != "auto":
        return extract(stripe_options)
    best, error, most = None, None, -1
    for way in ("columns", "rows"):
        try:
            got = extract(dict(stripe_options, direction=way))
        except ValueError as e:
            error = error or e
            continue
        coloured = None if on is None else laser_coloured(got[0], on, off)
        count = int(got[0].found.sum()) if coloured is None else coloured
        if count > most:
            best, most = got, count
        if way == "columns" and _runs_across(got[0], count):
            break
    if best is None:
        raise error  # type: ignore[misc]
    return best


def _runs_across(stripe: StripeResult, count: int) -> bool:
    """Whether a stripe found along the image's columns runs across the image: at least 20
    centres that count (found; in the laser's colour on a colour frame), the found ones rising
    less than 1 px per column on their least-squares line."""
    found = stripe.found
    if count < 20:
        return False
    return abs(float(np.polyfit(stripe.position[found].astype(float),
                                stripe.centre[found], 1)[0])) < 1.0
