"""The coarse model's jitter in its parameters, as an error term of the likelihood.

A forward model on a mesh that barely resolves the front is not a smooth function of its parameters: the
S = 0.5 contour jumps from node to node, fingers connect or not, and the outputs move by a mesh-scale amount
when a parameter moves a little.  Measured with the solver at h = 4 mm (twins_tie, w65, fixed mesh): the front
radius at 0.3 s for c_v = 0.9, 0.96, ..., 1.4 is 14.70, 15.47, 15.29, 15.22, 16.29, 16.21, 14.72, 15.55,
15.29 mm, not monotone, ±0.6 mm against a measurement σ of 0.2 mm, while the injection pressure is smooth.
A least-squares fit on such a model settles in whichever dip of the jitter lies nearest; its χ² carries the
jitter (Δχ² floor 13–20 per condition around the fit there), so profile intervals come out falsely narrow and
the BIC margin between two candidates can be pure jitter (a confident wrong name, measured in
twins_tie/coupling_vs_compliance_front_rates).

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
parameters (as :class:`~.realizations.RealizationCovariance`).  Units: v in kPa², mm²; τ in s.

Cost: (m − 1) coarse runs per condition and stepped parameter (the centre run is usually cached).

Measured with the solver (results/discrepancy/twins_tie_jitter, h = 4 mm, t ≤ 0.3 s): RMS 0.26 mm in the front
radius (0.68 mm late at w65) and 0.58 kPa in p_inj at the baseline (E stepped), 0.29–0.31 mm and 0.29–0.99 kPa at
the named fits; correlation times 0.03–0.10 s.  Beside the mesh-realization spread already in the covariance
(0.49 mm, 3.85 kPa) it changed no verdict by itself; it widened the named coupling's interval (with the smoothed
profile, 1.130 [1.088, 1.250] against 1.199 [1.183, 1.215]) without reaching the truth 1.0.  A jitter that is white
in time is not tamed by any covariance: χ² then fluctuates by ~√(2n)·v/(σ² + v) between neighbouring parameter
values (see tests/test_discrepancy_jitter.py); the profile smoothing (stats.quadratic_profile_interval) is the
answer there.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from . import stats

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

    def blocks(self, problem) -> dict:
        """series -> (rows in time order, C_j) on the rows of ``problem`` (a workflow ``Problem``)."""
        out = {}
        for s in np.unique(problem.series):
            rows = np.flatnonzero(problem.series == s)
            rows = rows[np.argsort(problem.t[rows], kind="stable")]
            v = self.variance[rows]
            ta = self.tau.get(str(problem.obs[rows[0]]), 0.0)
            lag = np.abs(problem.t[rows][:, None] - problem.t[rows][None, :])
            corr = np.exp(-lag / ta) if ta > 0 else np.eye(rows.size)
            out[int(s)] = (rows, np.sqrt(np.outer(v, v)) * corr)
        return out

    def rms(self, problem) -> dict:
        """RMS jitter (√ mean v) per observable, kPa / mm."""
        return {str(o): float(math.sqrt(np.mean(self.variance[problem.obs == o])))
                for o in np.unique(problem.obs)}

    def summary(self, problem) -> dict:
        return {"rms": self.rms(problem), "correlation_time": self.tau, "lag1": self.rho,
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


def estimate_model_jitter(problem, values: dict, params, n_steps: int = 7, rel_step: float = 0.05,
                          degree: int = 2, window: int = 5) -> ModelJitter | None:
    """Jitter of ``problem``'s forward model at ``values`` ({name: value}, names as the fit's: calibrated
    Parameters fields and 'effect:<name>'; units theirs) in the directions of ``params`` (CalibParam: name,
    lower, upper).  Parameters at 0 are not stepped (an effect off).  None when nothing can be stepped.
    Runs every condition of the data (training and held out: the held-out gap is measured with the same σ)."""
    ids = problem.data.ids
    allm = np.ones(problem.y.size, bool)
    before = int(getattr(problem.forward, "n_runs", 0))
    per_q, by_obs, per_rms, steps, dofs = {}, {}, {}, {}, {}
    series_rows = {}
    for s in np.unique(problem.series):
        rows = np.flatnonzero(problem.series == s)
        series_rows[int(s)] = rows[np.argsort(problem.t[rows], kind="stable")]
    for p in params:
        v0 = float(values[p.name])
        if v0 == 0.0:
            continue
        u = step_values(v0, n_steps, rel_step, p.lower, p.upper)
        runs = problem.predict([{**values, p.name: float(x)} for x in u], ids)
        Y = np.vstack([problem.model_vector(pr, allm) for pr in runs])
        res, rss, dof = _residuals(u, Y, degree)
        raw = np.where(np.isfinite(rss), rss / dof, 0.0)
        vq = np.zeros_like(raw)
        for rows in series_rows.values():
            vq[rows] = stats.moving_average(raw[rows], window)
            by_obs.setdefault(str(problem.obs[rows[0]]), []).append(res[:, rows])
        per_q[p.name] = vq
        per_rms[p.name] = {str(o): float(math.sqrt(np.mean(raw[problem.obs == o]))) for o in np.unique(problem.obs)}
        steps[p.name] = [float(x) for x in u]
        dofs[p.name] = dof
    if not per_q:
        return None
    var = np.max(np.vstack(list(per_q.values())), axis=0)
    tau, rho = {}, {}
    for o, curves in by_obs.items():
        rho[o] = stats.pooled_lag1(curves)
        steps_t = np.concatenate([np.diff(problem.t[rows]) for rows in series_rows.values()
                                  if problem.obs[rows[0]] == o])
        dt = float(np.median(steps_t)) if steps_t.size else 0.0
        tau[o] = -dt / math.log(rho[o]) if rho[o] > 0 and dt > 0 else 0.0
    return ModelJitter(var, tau, rho, per_rms, {k_: float(v) for k_, v in values.items()}, steps, dofs,
                       int(getattr(problem.forward, "n_runs", 0)) - before)
