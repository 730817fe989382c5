"""Repeatability: how much a calibration changes from run to run, by the bootstrap.

:func:`repeatability` re-runs :func:`hmlvs.calibrate` on bootstrap resamples of the data
(points drawn with replacement, or whole poses when the data set has a ``pose_index``) and
reports the spread of each parameter, of the identifiable combinations and of the held-out
RMS. Along a flat direction the raw parameters wander from run to run while the
combinations and the held-out RMS stay put: that is the signature of a degeneracy, not of a
bad calibration.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math
from typing import Any, Iterable
import warnings

import numpy as np

from ..calibration.solvers import CalibrationResult, calibrate
from ..data.dataset import Dataset, fit_and_test
from ..models.params import NAMES
from .identifiability import EULER_INDEX, GIMBAL_PHI, HmlvsDataWarning


@dataclass(frozen=True)
class Spread:
    """Summary of one quantity over the runs: mean, standard deviation (ddof 1), min, max."""

    mean: float
    std: float
    min: float
    max: float

    @classmethod
    def of(cls, values: Iterable[float]) -> "Spread":
        v = np.asarray(list(values), dtype=float)
        v = v[np.isfinite(v)]
        if v.size == 0:
            return cls(math.nan, math.nan, math.nan, math.nan)
        std = float(v.std(ddof=1)) if v.size > 1 else 0.0
        return cls(float(v.mean()), std, float(v.min()), float(v.max()))

    def __str__(self) -> str:
        return (f"mean {self.mean:.7g} std {self.std:.3g} "
                f"[{self.min:.7g}, {self.max:.7g}]")


@dataclass
class RepeatabilityReport:
    """The outcome of :func:`repeatability`.

    Attributes
    ----------
    runs : number of bootstrap runs that succeeded
    method, seed, fixed : the calibration's settings
    by_pose : True when whole poses were resampled
    heldout_kind : "test" (the given held-out set) or "out-of-bag" (each run's points not
        drawn)
    params : (runs, 14) the parameters of each run
    fit_rms, heldout_rms : (runs,) RMS of ||E|| (mm) on each run's fitting and held-out points
    parameters : spread of each free parameter over the runs
    combinations : spread of f/Su, f/Sv, k Su^2 (and omega + varphi when |phi| is small)
    heldout : spread of the held-out RMS
    reference : the calibration on the whole data set (its ``uncertainty`` holds the
        predicted standard deviations to compare with)
    failures : messages of runs that failed (they are not counted in ``runs``)
    """

    runs: int
    method: str
    seed: int
    fixed: tuple[str, ...]
    by_pose: bool
    heldout_kind: str
    params: np.ndarray
    fit_rms: np.ndarray
    heldout_rms: np.ndarray
    parameters: dict[str, Spread]
    combinations: dict[str, Spread]
    heldout: Spread
    reference: CalibrationResult
    failures: list[str] = field(default_factory=list)

    def summary(self) -> str:
        unc = self.reference.uncertainty
        lines = [f"repeatability: {self.runs} bootstrap runs of {self.method} (seed "
                 f"{self.seed}, resampling {'poses' if self.by_pose else 'points'}), "
                 f"fixed: {', '.join(self.fixed) or 'none'}",
                 f"held-out RMS ({self.heldout_kind}): {self.heldout}",
                 f"{'param':<14} {'mean':>14} {'run std':>10} {'predicted':>10} "
                 f"{'min':>14} {'max':>14}"]

        def row(name: str, s: Spread, pred: float | None, flag: str = "") -> str:
            p = f"{pred:>10.3g}" if pred is not None else f"{'-':>10}"
            return (f"{name:<14} {s.mean:>14.7g} {s.std:>10.3g} {p} {s.min:>14.7g} "
                    f"{s.max:>14.7g}{flag}")

        for n, s in self.parameters.items():
            pred = unc.std.get(n) if unc is not None else None
            flag = "" if unc is None or unc.determined.get(n, True) else "  (not determined)"
            lines.append(row(n, s, pred, flag))
        for n, s in self.combinations.items():
            c = next((c for c in unc.combinations if c.name == n), None) if unc else None
            flag = "" if c is None or c.determined else "  (not determined)"
            lines.append(row(n, s, c.std if c else None, flag))
        if self.failures:
            lines.append(f"{len(self.failures)} runs failed, e.g.: {self.failures[0]}")
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.summary()


def _combinations(q: np.ndarray, near_gimbal: bool) -> dict[str, float]:
    out = {"f/Su": q[0] / q[1], "f/Sv": q[0] / q[2], "k Su^2": q[5] * q[1] ** 2}
    if near_gimbal:
        out["omega + varphi"] = math.remainder(q[EULER_INDEX[0]] + q[EULER_INDEX[2]], 2 * math.pi)
    return out


def _resample(ds: Dataset, idx: np.ndarray) -> Dataset:
    """The points at ``idx`` (with repetitions), with fresh unique ids."""
    return ds._rows(idx, np.array([f"{ds.ids[i]}#{k}" for k, i in enumerate(idx)]))


def repeatability(dataset: Dataset | Any, runs: int = 50, method: str = "lm", seed: int = 0,
                  test: Dataset | None = None, by_pose: bool | None = None,
                  **calibrate_kwargs: Any) -> RepeatabilityReport:
    """Re-run the calibration on bootstrap resamples; report the spread of the results.

    Parameters
    ----------
    dataset : the calibration points (:class:`Dataset`, or a simulation: its ``fit`` set,
        with its ``test`` set as the held-out data unless ``test`` is given)
    runs : number of bootstrap resamples (>= 2)
    method : the calibration method (default "lm", started from ``initial``, by default the
        nominal values, in every run, so that the runs differ by their data only)
    seed : random seed of the resampling; run i calibrates with seed ``seed + 1 + i``. The
        report is the same for the same seed
    test : held-out points for each run's RMS; without it each run's out-of-bag points (those
        not drawn) are its held-out set
    by_pose : resample whole poses (all points of a pose together); default: when the data
        set has a ``pose_index``
    **calibrate_kwargs : passed to :func:`hmlvs.calibrate` (fixed, initial, bounds, threads,
        options, ...)

    Returns
    -------
    RepeatabilityReport
    """
    dataset, test = fit_and_test(dataset, test)
    if isinstance(runs, bool) or not isinstance(runs, (int, np.integer)) or runs < 2:
        raise ValueError(f"runs must be an integer >= 2, got {runs!r}")
    if "test" in calibrate_kwargs or "seed" in calibrate_kwargs:
        raise ValueError("pass test and seed to repeatability itself, not as calibrate options")
    if by_pose is None:
        by_pose = dataset.pose_index is not None
    if by_pose and dataset.pose_index is None:
        raise ValueError("by_pose=True needs a data set with a pose_index")
    m = len(dataset)
    reference = calibrate(dataset, method=method, seed=seed, test=test, **calibrate_kwargs)
    fixed = reference.fixed
    rng = np.random.default_rng(seed)
    groups = np.unique(dataset.pose_index) if by_pose else None
    params, fit_rms, held_rms, failures = [], [], [], []
    for i in range(int(runs)):
        if by_pose:
            chosen = rng.choice(groups, size=groups.size, replace=True)
            idx = np.concatenate([np.nonzero(dataset.pose_index == g)[0] for g in chosen])
        else:
            idx = rng.integers(0, m, size=m)
        held = test
        if held is None:
            oob = np.setdiff1d(np.arange(m), idx)
            held = dataset.subset(oob) if oob.size else None
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", HmlvsDataWarning)
                r = calibrate(_resample(dataset, idx), method=method, seed=seed + 1 + i,
                              test=held, **calibrate_kwargs)
        except ValueError as e:
            failures.append(f"run {i}: {e}")
            continue
        params.append(r.params.to_array())
        fit_rms.append(r.fit_rms)
        held_rms.append(math.nan if r.test_rms is None else r.test_rms)
    if not params:
        raise ValueError(f"every bootstrap run failed, e.g. {failures[0]}")
    p = np.array(params)
    free = [n for n in NAMES if n not in fixed]
    near = abs(reference.params.phi) < GIMBAL_PHI
    comb_runs = [_combinations(q, near) for q in p]
    combos = {k: Spread.of(c[k] for c in comb_runs) for k in comb_runs[0]}
    return RepeatabilityReport(
        runs=len(params), method=method, seed=int(seed), fixed=tuple(fixed),
        by_pose=bool(by_pose), heldout_kind="test" if test is not None else "out-of-bag",
        params=p, fit_rms=np.array(fit_rms), heldout_rms=np.array(held_rms),
        parameters={n: Spread.of(p[:, NAMES.index(n)]) for n in free}, combinations=combos,
        heldout=Spread.of(held_rms), reference=reference, failures=failures)

