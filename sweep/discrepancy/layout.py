"""The layout of the measured curves: which series (condition × observable), observable and time each row
is.  The error-model pieces (mesh realizations, the coarse model's jitter) need only this, not the fitting
problem.  Times in s."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["CurveLayout", "correlation_time"]


@dataclass(frozen=True, eq=False)
class CurveLayout:
    """Per curve row: ``series`` (int index of its condition × observable), ``obs`` (observable name) and
    ``t`` (observation time, s); all arrays of one length n."""

    series: np.ndarray
    obs: np.ndarray
    t: np.ndarray

    @property
    def n(self) -> int:
        return int(self.t.size)

    def series_rows(self) -> dict:
        """{series: its rows in time order} (a stable sort: rows of equal time keep their order)."""
        out = {}
        for s in np.unique(self.series):
            rows = np.flatnonzero(self.series == s)
            out[int(s)] = rows[np.argsort(self.t[rows], kind="stable")]
        return out

    def exp_correlation(self, rows: np.ndarray, tau: float) -> np.ndarray:
        """exp(−|t_i − t_j| / τ) between ``rows`` (identity when τ <= 0: no correlation in time)."""
        if tau <= 0:
            return np.eye(rows.size)
        return np.exp(-np.abs(self.t[rows][:, None] - self.t[rows][None, :]) / tau)


def correlation_time(rho: float, layout: CurveLayout, obs: str) -> float:
    """τ = −Δt / ln ρ (s) of observable ``obs`` from a lag-1 autocorrelation ρ of its curves, Δt the median
    time step of its series in ``layout``; 0 (no correlation in time) when ρ <= 0 or Δt = 0."""
    steps = [np.diff(layout.t[rows]) for rows in layout.series_rows().values() if layout.obs[rows[0]] == obs]
    steps = np.concatenate(steps) if steps else np.zeros(0)
    dt = float(np.median(steps)) if steps.size else 0.0
    return -dt / math.log(rho) if rho > 0 and dt > 0 else 0.0
