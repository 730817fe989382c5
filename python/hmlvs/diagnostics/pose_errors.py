"""Robot pose errors in a calibration's uncertainty, for either model.

A solve that takes the robot poses as exact weights every residual as independent noise. A
robot pose error is not independent: it moves all the points of its view (or pose) together,
and counted as independent noise it makes the covariance claim a precision the data do not
have. Given, per view, the derivative of its residuals with respect to its pose error
(rotation vector and translation in the hand frame, each column scaled by the shape of the
errors' spread), this module estimates the spread's scale from the residuals by the method of
moments (their sum of squares against its expectation: white noise plus pose errors) and
gives the pose errors' part of the solution's covariance,

    s^2 A^-1 (sum_i G_i G_i^T) A^-1,   G_i = J[rows_i]^T J_e,i,   A = J^T J,

which the model adds to its white-noise covariance. The general model's joint solve
(:mod:`hmlvs.calibration.joint_covariance`) and the paper model's uncertainty
(:mod:`hmlvs.diagnostics.uncertainty`) each supply their Jacobians.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

#: The residuals show robot pose errors when their sum of squares exceeds the white noise's
#: expectation by more than this many standard deviations of its chi-square spread. On
#: renders with exact poses the general model's excess is about 1 such standard deviation
#: (its free-pose noise estimate runs a little low), which, counted, would widen every
#: standard deviation by 1.6 times for errors that are not there; on renders with 0.3 mm and
#: 0.1 degree pose errors it is hundreds, on the Blaser sessions 11-17.
EXCESS_SD = 3.0


def pose_error_part(jac: np.ndarray, a_inv: np.ndarray, rows: Sequence[np.ndarray],
                    pose_jac: Sequence[np.ndarray], residuals: np.ndarray,
                    white_expect: float, white_sd: float
                    ) -> tuple[np.ndarray, float] | None:
    """The pose errors' part of the covariance and their spread's estimated scale s, or None
    when the residuals show none beyond the white noise (:data:`EXCESS_SD`).

    jac : the residuals' Jacobian (n x p), weighted as the solve weighted them;
        a_inv : (jac^T jac)^-1 (pseudo-inverse when rank-deficient)
    rows, pose_jac : per view (pose), its rows of ``jac`` and the derivative of those
        residuals with respect to its pose error (len(rows) x 6), each column scaled by the
        shape of the errors' spread
    residuals : the residuals (n), in the units of ``jac``'s rows
    white_expect, white_sd : the white noise's expected sum of squares of the residuals
        (after the fit) and its standard deviation
    Returns ``(s^2 A^-1 (sum_i G_i G_i^T) A^-1, s)``.
    """
    # A^-1 G_i per view: the part is a sum of their outer products, so that its diagonal
    # stays non-negative however the rows' weights differ (a sum of squares, not a
    # difference of large products)
    moved = []
    trace_m = trace_fit = 0.0
    for r, je in zip(rows, pose_jac):
        trace_m += float(np.sum(je ** 2))
        g = jac[r].T @ je
        h = a_inv @ g
        trace_fit += float(np.sum(g * h))
        moved.append(h)
    # the pose errors' expected sum of squares after the fit: tr(P M), P = I - jac A^-1 jac^T,
    # M = blockdiag(J_e,i J_e,i^T)
    pose = trace_m - trace_fit
    excess = float(residuals @ residuals) - white_expect
    # not finite: a residual that cannot be evaluated, nothing to estimate from
    if not (math.isfinite(excess) and math.isfinite(pose)) or pose <= 0 \
            or excess <= EXCESS_SD * white_sd:
        return None
    scale2 = excess / pose
    h_all = np.hstack(moved)
    return scale2 * (h_all @ h_all.T), math.sqrt(scale2)
