"""The coarse model's jitter in its parameters, as an error term of the likelihood.

A forward model on a mesh that barely resolves the front is not a smooth function of its parameters: the
S = 0.5 contour jumps from node to node, fingers connect or not, and the outputs move by a mesh-scale amount
when a parameter moves a little.  A least-squares fit on such a model settles in whichever dip of the jitter
lies nearest and its χ² carries the jitter, so profile intervals come out falsely narrow and the BIC margin
between two candidates can be pure jitter.  This module makes the jitter an error term of the comparison.

Model: y_coarse(θ) = m(θ) + ε(θ), with m smooth and ε a random field in θ with a correlation length shorter
than the steps below; the data are compared with m, so ε is an error of the comparison with

    Var ε_i = v_i,   Corr(ε_i, ε_j) = exp(−|t_i − t_j| / τ_o)   (same series; series independent),

added to the covariance the residuals are whitened with (:class:`~.realizations.RealizationCovariance`).

Estimate (:func:`estimate_model_jitter`): at values θ̂, each stepped parameter q in turn takes the values
q̂ (1 + δ j), j = −(m−1)/2 … (m−1)/2 (``n_steps`` = m, ``rel_step`` = δ); per output point a polynomial of
degree ``degree`` in q is fitted to the m runs (the smooth part over ±δ(m−1)/2: a quadratic is exact to
well below the noise for the solver's responses over ±15 %) and v_q,i = RSS_i / (m − degree − 1) is the
jitter variance in that direction, averaged over ``window`` neighbouring points of the series.  A coarse
model jagged in one parameter is jagged for every fit that moves it, so v_i = max_q v_q,i over the stepped
parameters.  τ_o from the lag-1 autocorrelation of the polynomial residuals pooled over series, runs and
parameters (as :class:`~.realizations.RealizationCovariance`, the estimator ``[noise] lag1``).  Units: v in
kPa², mm²; τ in s.

Cost: (m − 1) coarse runs per condition and stepped parameter (the centre run is usually cached).

Measured sizes and their effect on the twins: results/discrepancy/DESIGN_NOTES.md.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from . import stats
from .layout import CurveLayout, correlation_time

__all__ = ["ModelJitter", "estimate_model_jitter", "step_values"]


@dataclass
class ModelJitter:
    """The coarse model's jitter as a covariance per series (see the module docstring).

    variance : per curve row, kPa² / mm² (smoothed, max over the stepped parameters)
    tau, rho : observable -> correlation time (s) and pooled lag-1 autocorrelation of the jitter curves
    per_parameter_rms : parameter -> observable -> RMS jitter (kPa, mm) in that parameter's direction
    at : the values the jitter was estimated at; steps : parameter -> the stepped values
    runs : forward runs spent (new ones; cached runs are free)"""

    variance: np.ndarray
    tau: dict
    rho: dict
    per_parameter_rms: dict
    at: dict
    steps: dict = field(default_factory=dict)
    dof: dict = field(default_factory=dict)
    runs: int = 0

    def blocks(self, layout: CurveLayout) -> dict:
        """series -> (rows in time order, C_j) on the rows of ``layout``."""
        out = {}
        for s, rows in layout.series_rows().items():
            v = self.variance[rows]
            corr = layout.exp_correlation(rows, self.tau.get(str(layout.obs[rows[0]]), 0.0))
            out[s] = (rows, np.sqrt(np.outer(v, v)) * corr)
        return out

    def rms(self, layout: CurveLayout) -> dict:
        """RMS jitter (√ mean v) per observable, kPa / mm."""
        return {str(o): float(math.sqrt(np.mean(self.variance[layout.obs == o])))
                for o in np.unique(layout.obs)}

    def summary(self, layout: CurveLayout) -> dict:
        """The jitter's RMS per observable (kPa, mm), correlation times (s), where and how it was estimated."""
        return {"rms": self.rms(layout), "correlation_time": self.tau, "lag1": self.rho,
                "per_parameter_rms": self.per_parameter_rms, "at": self.at, "steps": self.steps,
                "dof": self.dof, "runs": self.runs}


def step_values(value: float, n_steps: int, rel_step: float, lower: float | None = None,
                upper: float | None = None) -> np.ndarray:
    """value (1 + rel_step j), j = −(n−1)/2 … (n−1)/2, shifted as a block to stay inside [lower, upper]
    (so every step lies on the model's admissible side; the centre then need not be ``value``)."""
    if n_steps < 5 or n_steps % 2 == 0:
        raise ValueError(f"model_jitter_steps = {n_steps}: must be an odd integer >= 5 (a quadratic and dof)")
    if not (0.0 < rel_step < 0.5):
        raise ValueError(f"model_jitter_rel_step = {rel_step}: must be in (0, 0.5)")
    j = np.arange(n_steps) - (n_steps - 1) / 2
    v = value * (1.0 + rel_step * j)
    if lower is not None and v.min() < lower:
        v = v + (lower - v.min())
    if upper is not None and v.max() > upper:
        v = v - (v.max() - upper)
    return v


def _residuals(u: np.ndarray, Y: np.ndarray, degree: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Per column of Y (m runs × n points) the residuals of a degree-``degree`` polynomial in u, with RSS
    per point; columns with a non-finite value get residuals 0 and RSS NaN.  Returns (res, rss, dof)."""
    V = np.vander((u - u.mean()) / max(np.ptp(u), 1e-300), degree + 1)
    ok = np.all(np.isfinite(Y), axis=0)
    Yf = np.where(ok, Y, 0.0)
    coef, *_ = np.linalg.lstsq(V, Yf, rcond=None)
    res = np.where(ok, Yf - V @ coef, 0.0)
    rss = np.where(ok, (res**2).sum(axis=0), np.nan)
    return res, rss, u.size - degree - 1


def estimate_model_jitter(evaluate, layout: CurveLayout, values: dict, params, n_steps: int = 7,
                          rel_step: float = 0.05, degree: int = 2, window: int = 5,
                          lag1: str = "pooled") -> ModelJitter | None:
    """Jitter of a forward model at ``values`` ({name: value}, names as the fit's: calibrated Parameters fields
    and 'effect:<name>'; units theirs) in the directions of ``params`` (CalibParam: name, lower, upper).

    evaluate(list of values dicts) -> array (runs × curve rows): the model on every row of ``layout``.
    Parameters at 0 are not stepped (an effect off).  τ_o from the lag-1 estimator ``lag1`` ([noise] lag1,
    :func:`stats.lag1_estimate`; points a run could not compute left out).  None when nothing can be stepped.
    ``runs`` of the result is left 0: the caller knows what the evaluations cost."""
    series_rows = layout.series_rows()
    per_q, by_obs, per_rms, steps, dofs = {}, {}, {}, {}, {}
    for p in params:
        v0 = float(values[p.name])
        if v0 == 0.0:
            continue
        u = step_values(v0, n_steps, rel_step, p.lower, p.upper)
        Y = np.asarray(evaluate([{**values, p.name: float(x)} for x in u]), float)
        res, rss, dof = _residuals(u, Y, degree)
        raw = np.where(np.isfinite(rss), rss / dof, 0.0)
        vq = np.zeros_like(raw)
        for rows in series_rows.values():
            vq[rows] = stats.moving_average(raw[rows], window)
            by_obs.setdefault(str(layout.obs[rows[0]]), []).append(
                np.where(np.isfinite(rss[rows]), res[:, rows], np.nan))
        per_q[p.name] = vq
        per_rms[p.name] = {str(o): float(math.sqrt(np.mean(raw[layout.obs == o]))) for o in np.unique(layout.obs)}
        steps[p.name] = [float(x) for x in u]
        dofs[p.name] = dof
    if not per_q:
        return None
    var = np.max(np.vstack(list(per_q.values())), axis=0)
    rho = {o: stats.lag1_estimate(curves, lag1) for o, curves in by_obs.items()}
    tau = {o: correlation_time(rho[o], layout, o) for o in rho}
    return ModelJitter(var, tau, rho, per_rms, {k_: float(v) for k_, v in values.items()}, steps, dofs)
