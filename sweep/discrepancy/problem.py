"""The fitting problem of the discrepancy workflow: standardized residuals of a set of conditions as a
function of the fitted parameters, and their bounded robust least-squares fit.

A model is a tuple of :class:`~.spec.CalibParam` (calibrated solver parameters and effect strengths,
named 'effect:<name>') and a point x in their internal coordinates (log10 or linear).  The problem runs the
forward model for every condition at once, aligns its predictions with the measured curve rows and
standardizes the differences with its :class:`~.noise.NoiseModel`.  Units: mm, s, kPa; residuals are
dimensionless.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from solver.effects import get_effect

from . import stats
from .data import MeasuredData
from .layout import CurveLayout
from .noise import NoiseModel
from .observables import CURVES
from .spec import DiscrepancySpec

__all__ = ["Fit", "Problem", "values_to_overrides", "random_starts"]


@dataclass
class Fit:
    """A fitted model: its free parameters, values, residuals on the training conditions."""

    params: tuple          # CalibParam (effects as "effect:<name>")
    x: np.ndarray          # internal coordinates
    r: np.ndarray          # standardized residuals (training)
    J: np.ndarray          # ∂r/∂x at x (training)
    cost: float
    nfev: int

    def values(self) -> dict:
        """{name: value} in each parameter's unit."""
        return {p.name: p.from_x(xi) for p, xi in zip(self.params, self.x)}


def values_to_overrides(spec: DiscrepancySpec, base: dict, condition: dict, values: dict) -> dict:
    """solver.Parameters overrides of one condition for fitted ``values``.

    base : the baseline overrides (effects off); condition : the condition's parameters (they win);
    values : calibrated parameters by name and effect strengths as 'effect:<name>' (strength in the effect's
    units, times √C for an effect with scaling "sqrt_cement", C in %: β = c √C, Sec. 3.6).
    """
    o = dict(base)
    for k, v in values.items():
        if k.startswith("effect:"):
            name = k[7:]
            e = get_effect(name)
            sc = spec.scaling.get(name, "none")
            cem = condition.get("cement", base.get("cement", 1.2))
            o[e.parameter] = v * math.sqrt(cem) if sc == "sqrt_cement" else v
        else:
            o[k] = v
    o.update(condition)
    return o


def random_starts(params, n: int, seed: int) -> list:
    """``n`` (<= 0: none) start points drawn uniformly inside the bounds of ``params`` (internal coordinates),
    from a generator seeded with ``seed``."""
    rng = np.random.default_rng(seed)
    lb = np.array([p.x_bounds[0] for p in params])
    ub = np.array([p.x_bounds[1] for p in params])
    return [lb + rng.random(len(params)) * (ub - lb) for _ in range(max(0, n))]


def _phases(data: MeasuredData, cond, obs, t, y) -> np.ndarray:
    """Phase index (stats.PHASES) of each curve row, per condition from its pressure and crack curves."""
    phase = np.zeros(t.size, int)
    for cid in data.ids:
        m = cond == cid
        pm = m & (obs == "p_inj")
        if pm.any():
            cm = m & (obs == "crack_length")
            phase[m] = stats.phase_of_times(t[m], (t[pm], y[pm]), (t[cm], y[cm]) if cm.any() else None)
    return phase


class Problem:
    """Residual assembly for a set of conditions, with an in-memory cache over x.

    ``fixed``: values held fixed while others are fitted (profile likelihood), e.g. {"effect:x": 3.0}.
    ``noise``: the problem's :class:`~.noise.NoiseModel`; the residual cache follows its ``version``."""

    def __init__(self, data: MeasuredData, spec: DiscrepancySpec, forward):
        self.data, self.spec, self.forward = data, spec, forward
        self.base = spec.baseline_overrides()
        c = data.curves
        self.cond = c.condition.to_numpy(str)
        self.obs = c.observable.to_numpy(str)
        self.t = c.time.to_numpy(float)
        keys = list(zip(self.cond, self.obs))
        uniq = {k: i for i, k in enumerate(dict.fromkeys(keys))}
        self.series = np.array([uniq[k] for k in keys], int)
        self.series_names = [f"{a}/{b}" for a, b in uniq]
        self._series_rows = {k: np.flatnonzero(self.series == i) for k, i in uniq.items()}  # curve rows, in order
        self.layout = CurveLayout(self.series, self.obs, self.t)
        self.times = data.observation_times()
        y = c.value.to_numpy(float)
        self.phase = _phases(data, self.cond, self.obs, self.t, y)
        for cid in data.ids:
            for kind, ps in (("calibrated", spec.calibrate), ("alternative", spec.alternatives)):
                overlap = set(data.condition_params(cid)) & {p.name for p in ps}
                if overlap:
                    raise ValueError(f"condition {cid!r} sets {kind} parameter(s) {sorted(overlap)}")
        self.noise = NoiseModel(y, c.uncertainty.to_numpy(float), self.layout)
        self._cache: dict = {}
        self._cache_version = self.noise.version
        self._preds: dict = {}          # predictions by the same key: the model's, whatever the noise model
        self.fixed: dict = {}

    # the noise model's current state, read-only here
    y = property(lambda self: self.noise.y, doc="the data the model is compared with (kPa, mm)")
    sig = property(lambda self: self.noise.sig, doc="marginal σ of each point (kPa, mm)")
    sig_diag = property(lambda self: self.noise.sig_diag, doc="σ without the covariance terms (kPa, mm)")
    real_cov = property(lambda self: self.noise.real_cov, doc="per-series covariance or None")
    realization_spread = property(lambda self: self.noise.realization_spread, doc="per-point spread (kPa, mm)")

    def overrides(self, cid: str, values: dict) -> dict:
        """Full parameter overrides of condition ``cid`` for fitted ``values`` (effects as 'effect:<name>')."""
        return values_to_overrides(self.spec, self.base, self.data.condition_params(cid), values)

    def predict(self, values_list: list, ids: list) -> list:
        """Predictions [{cid: {obs: array, 'regime': label}}] for each values dict (one batch)."""
        jobs, index = [], []
        for j, values in enumerate(values_list):
            for cid in ids:
                jobs.append((self.overrides(cid, values), self.times[cid]))
                index.append((j, cid))
        preds = self.forward.predict_many(jobs)
        out = [dict() for _ in values_list]
        for (j, cid), pr in zip(index, preds):
            out[j][cid] = pr
        return out

    def model_vector(self, pred: dict, mask: np.ndarray) -> np.ndarray:
        """Predicted values aligned with the curve rows selected by ``mask``."""
        full = np.full(self.cond.size, np.nan)
        for cid in np.unique(self.cond[mask]):
            for obs in CURVES:
                rows = self._series_rows.get((cid, obs))
                if rows is None or not mask[rows].any():
                    continue
                v = np.asarray(pred[cid][obs], float)
                n = min(rows.size, v.size)  # the prediction at the series' observation times, in row order
                full[rows[:n]] = v[:n]
        return full[mask]

    def standardize(self, diff: np.ndarray, mask: np.ndarray, nan_value: float) -> np.ndarray:
        """Standardized residuals of ``diff`` (data − model) on ``mask``'s rows: :meth:`NoiseModel.standardize`."""
        return self.noise.standardize(diff, mask, nan_value)

    def data_at(self, params, x) -> np.ndarray:
        """The data the model at x (internal coordinates of ``params``, with ``fixed``) is compared with, on
        every row (kPa, mm): :meth:`NoiseModel.data_for` its values."""
        return self.noise.data_for(self._values(params, x))

    def residuals_for(self, preds: list, mask: np.ndarray, ys: list) -> list:
        """Standardized residuals of each prediction on ``mask``'s rows against its data ``ys`` (every row,
        :meth:`data_at`; a failed point: nan_residual)."""
        nanr = self.spec.fit.nan_residual
        return [self.standardize(y[mask] - self.model_vector(pred, mask), mask, nanr) for pred, y in zip(preds, ys)]

    def failed_points(self, params, x, ids) -> dict:
        """{condition: {"failed": n, "points": N}} of the conditions ``ids`` at x: the observation points the
        forward runs did not reach (no prediction, a run that failed or stopped early), for those with any."""
        mask = self.mask(ids)
        miss = ~np.isfinite(self.model_vector(self.prediction(params, x, ids), mask))
        cond = self.cond[mask]
        return {cid: {"failed": int(miss[cond == cid].sum()), "points": int((cond == cid).sum())}
                for cid in ids if miss[cond == cid].any()}

    def mask(self, ids) -> np.ndarray:
        """Curve rows of the conditions ``ids``."""
        return np.isin(self.cond, list(ids))

    def _values(self, params, x) -> dict:
        return {**self.fixed, **{p.name: p.from_x(xi) for p, xi in zip(params, x)}}

    def _key(self, params, x, ids) -> tuple:
        return (tuple(p.name for p in params), tuple(np.round(x, 12)), tuple(ids), tuple(sorted(self.fixed.items())))

    def residual_batch(self, params, xs: list, ids) -> list:
        """Residuals at each x of ``xs`` (one batch of forward runs for the uncached ones)."""
        if self._cache_version != self.noise.version:      # data or covariance changed: residuals are stale
            self._cache.clear()
            self._cache_version = self.noise.version
        keys = [self._key(params, x, ids) for x in xs]
        need = [i for i, k in enumerate(keys) if k not in self._cache]
        run = [i for i in dict.fromkeys(need) if keys[i] not in self._preds]
        if run:
            for i, pr in zip(run, self.predict([self._values(params, xs[i]) for i in run], ids)):
                self._preds[keys[i]] = pr
        if need:
            preds = [self._preds[keys[i]] for i in need]
            ys = [self.data_at(params, xs[i]) for i in need]
            for i, r, pr in zip(need, self.residuals_for(preds, self.mask(ids), ys), preds):
                self._cache[keys[i]] = (r, pr)
        return [self._cache[k][0] for k in keys]

    def evaluated(self, params, ids) -> list:
        """The points x (internal coordinates of ``params``) where the model has run on the conditions
        ``ids`` with nothing held fixed: runs an emulator of these parameters can reuse."""
        names, want = tuple(p.name for p in params), tuple(ids)
        return [np.array(k[1], float) for k in self._preds if k[0] == names and k[2] == want and not k[3]]

    def prediction(self, params, x, ids) -> dict:
        """The forward model's predictions {cid: {obs: values}} at x."""
        self.residual_batch(params, [x], ids)
        return self._cache[self._key(params, x, ids)][1]

    @staticmethod
    def jacobian_points(params, x) -> tuple[list, list]:
        """The points of the forward-difference Jacobian at x and their steps (each parameter's step toward
        the interior of its bounds; internal coordinates)."""
        xs, steps = [], []
        for j, p in enumerate(params):
            h = p.inward_step(x[j])
            xp = np.array(x, float)
            xp[j] += h
            xs.append(xp)
            steps.append(h)
        return xs, steps

    def jacobian(self, params, x, ids) -> np.ndarray:
        """Forward-difference ∂r/∂x (steps toward the interior of the bounds), one batch of runs."""
        xs, steps = self.jacobian_points(params, x)
        rs = self.residual_batch(params, [np.asarray(x, float)] + xs, ids)
        r0 = rs[0]
        return np.column_stack([(ri - r0) / h for ri, h in zip(rs[1:], steps)]) if params else np.zeros((r0.size, 0))

    def _ftol(self, params, x0, ids) -> float:
        """scipy's ftol for a start at ``x0``: 1e-8, or with ``[fit] chi2_tol`` > 0 the relative cost change
        chi2_tol / (r0·r0) (r0: the residuals at x0, a run the fit makes first anyway).  scipy stops when a step
        lowers the cost F by less than ftol × F; F never exceeds ½ r0·r0 along the fit (its steps descend; the
        robust loss lies below the quadratic), so it stops only once a step gains less than chi2_tol in χ²."""
        tol = self.spec.fit.chi2_tol
        if tol <= 0.0:
            return 1e-8
        ahead = self.jacobian_points(params, x0)[0] if self.spec.fit.prefetch_jacobian else []
        r0 = self.residual_batch(params, [x0] + ahead, ids)[0]      # with the prefetch: the fit's first batch
        return float(np.clip(tol / max(float(r0 @ r0), 1e-300), np.finfo(float).eps, 0.1))

    def fit(self, params: tuple, x0s: list, ids, max_nfev: int | None = None) -> Fit:
        """Robust bounded least squares (scipy TRF) from each start in ``x0s``; the lowest cost wins.
        ``max_nfev``: evaluations per start (default: ``[fit] max_nfev``; 1: the residuals and Jacobian at
        the start only)."""
        best = None
        nf = 0
        if not params:
            r = self.residual_batch(params, [np.zeros(0)], ids)[0]
            return Fit(params, np.zeros(0), r, np.zeros((r.size, 0)), 0.5 * float(r @ r), 1)
        lb = np.array([p.x_bounds[0] for p in params])
        ub = np.array([p.x_bounds[1] for p in params])
        fo = self.spec.fit

        def fun(x):        # with [fit] prefetch_jacobian the Jacobian's points run in the same batch
            ahead = self.jacobian_points(params, x)[0] if fo.prefetch_jacobian else []
            return self.residual_batch(params, [x] + ahead, ids)[0]

        for x0 in x0s:
            x0 = np.clip(np.asarray(x0, float), lb, ub)
            res = least_squares(fun, x0,
                                jac=lambda x: self.jacobian(params, x, ids), bounds=(lb, ub),
                                loss=fo.loss, f_scale=fo.f_scale, max_nfev=max_nfev or fo.max_nfev, x_scale=ub - lb,
                                ftol=self._ftol(params, x0, ids), method="trf")
            nf += res.nfev
            r = self.residual_batch(params, [res.x], ids)[0]
            cost = 0.5 * float(r @ r)
            if best is None or cost < best[1]:
                best = (res.x, cost, r)
        x, cost, r = best
        return Fit(params, x, r, self.jacobian(params, x, ids), cost, nf)
