"""The measurements that would tell apart models the data cannot: what to measure next after a tie.

When the workflow declares a tie (two candidates, or a candidate and an ``[[alternative]]`` rival, within
``tie_bic`` of each other), the data cannot tell them apart; the report then names the measurements that
would.  Each tied model is predicted, at every condition of the data, for every registered observable the
forward model gives (:data:`.observables.REGISTRY`), also those the data do not hold: curve observables on a
grid of ``n_times`` times over the condition's observed span, snapshot curves (the crack count) and the
regime at the condition's last observation time when the data observe that condition there.  A
measurement's separation is the smallest, over every pair of tied models, of the difference of their
predictions in units of the observable's noise: the data's own uncertainty where the data hold that
observable (the median over its rows), else the registry's default noise (one sd).  A differing regime
label separates outright (infinite separation).  The measurements are ranked by separation, each at the
time it is largest.

A candidate the screen finds inside the reach of the calibrated and ``[[alternative]]`` parameters is not
refitted (nothing tells it from them), so there is no tie to predict; :func:`confounded_measurements` pairs
it, at its probe strength, with its *mimic* (the baseline with those parameters moved to first order to
reproduce its signature on the training data, :func:`.evidence.alternative_mimic`), checks how closely the
mimic reproduces it where the data are, and ranks the measurements that would tell the two apart.

The tied models were run at every condition by their fits, so on a cached forward model (the solver's)
the curve observables cost no new run; any run missing is made and counted like any other.  Units: each
observable's own (kPa, mm, mm², -); separations are dimensionless; times in s.
"""
from __future__ import annotations

import logging
import math

import numpy as np

from .evidence import alternative_mimic, signatures
from .observables import LABELS, REGISTRY, SNAPSHOT_CURVES, ObservableUnavailable

log = logging.getLogger("dchfrac.discrepancy")

__all__ = ["discriminating_measurements", "confounded_measurements", "observable_noise"]


def observable_noise(problem, name: str) -> tuple[float, str]:
    """(one sd of observable ``name`` in its unit, where it comes from): the median uncertainty of the data's
    rows of that observable ("data"), else the registry's default noise ("default")."""
    c = problem.data.curves
    sd = c.uncertainty[c.observable == name].to_numpy(float)
    sd = sd[np.isfinite(sd) & (sd > 0)]
    if sd.size:
        return float(np.median(sd)), "data"
    return float(REGISTRY[name].default_noise), "default"


def _times(problem, cid: str, n_times: int) -> dict:
    """The times (s) each registered observable is predicted at for condition ``cid``: curves on ``n_times``
    points over (0, T], T the condition's last observation time; snapshot curves and labels at T when the data
    observe the condition there (their runs are classified at that time)."""
    obs_t = problem.times[cid]
    t_last = max(float(np.max(t)) for t in obs_t.values())
    grid = np.linspace(t_last / n_times, t_last, n_times)
    out = {}
    for name, o in REGISTRY.items():
        if o.kind == "curve" and o.snapshot is None:
            out[name] = grid
        elif any(np.isclose(np.max(t), t_last) for k, t in obs_t.items() if k in SNAPSHOT_CURVES + LABELS):
            out[name] = np.array([t_last])
    return out


def _supported(problem, values: dict, cid: str, times: dict) -> dict:
    """The subset of ``times`` the forward model gives (a model that does not model an observable, or a run
    whose time series lacks its column, raises ValueError / ObservableUnavailable: left out)."""
    ok = {}
    for name, t in times.items():
        try:
            problem.forward.predict_many([(problem.overrides(cid, values), {name: t})])
        except (ObservableUnavailable, ValueError) as exc:
            log.info("discriminating measurements: %s is not available from the forward model (%s)", name, exc)
            continue
        ok[name] = t
    return ok


def _predictions(problem, models: dict, n_times: int) -> dict:
    """{cid: (times, {model: prediction dict})} of every tied model at every condition of the data."""
    first = next(iter(models.values()))
    out = {}
    for cid in problem.data.ids:
        times = _supported(problem, first, cid, _times(problem, cid, n_times))
        preds = problem.forward.predict_many([(problem.overrides(cid, v), times) for v in models.values()])
        out[cid] = (times, dict(zip(models, preds)))
    return out


def _separation(name: str, preds: dict, sd: float) -> tuple[float, int]:
    """(the smallest pairwise separation over the tied models at the time it is largest, that time's index)
    of observable ``name``: |difference| / sd for curves, inf for differing labels (0 for equal ones)."""
    keys = list(preds)
    if REGISTRY[name].kind == "label":
        labels = {preds[k][name] for k in keys}
        return (math.inf if len(labels) > 1 and None not in labels else 0.0), 0
    v = np.vstack([np.asarray(preds[k][name], float) for k in keys])
    pair = np.full(v.shape[1], np.inf)
    for i in range(len(keys)):
        for j in range(i + 1, len(keys)):
            pair = np.minimum(pair, np.abs(v[i] - v[j]) / sd)
    pair = np.where(np.isfinite(pair), pair, -1.0)       # a missing prediction separates nothing
    k = int(np.argmax(pair))
    return max(float(pair[k]), 0.0), k


def discriminating_measurements(problem, models: dict, n_times: int = 8, top: int = 5) -> list[dict]:
    """The ``top`` measurements that best tell the tied ``models`` ({name: fitted values, effects as
    'effect:<name>'}, at least two) apart, best first (module docstring).  Each row: observable, unit,
    condition, time (s), each model's prediction there, separation (in noise sd; inf for a differing regime),
    the sd used and its source ("data" / "default"), and whether the data already hold that observable at
    that condition (``measured``)."""
    if len(models) < 2:
        raise ValueError(f"discriminating_measurements: {len(models)} model(s) given, at least 2 needed")
    rows = []
    for cid, (times, preds) in _predictions(problem, models, n_times).items():
        for name, t in times.items():
            sd, src = observable_noise(problem, name) if REGISTRY[name].kind == "curve" else (math.nan, "label")
            sep, k = _separation(name, preds, sd)
            vals = {m: (p[name] if REGISTRY[name].kind == "label" else float(np.asarray(p[name], float)[k]))
                    for m, p in preds.items()}
            rows.append({"observable": name, "unit": REGISTRY[name].unit, "condition": cid, "time": float(t[k]),
                         "predictions": vals, "separation": sep, "noise_sd": sd, "noise_source": src,
                         "measured": name in problem.times[cid]})
    rows.sort(key=lambda r: -r["separation"])
    return rows[:top]


def confounded_measurements(problem, fit, candidates: list, ids, top: int = 5) -> dict:
    """For each of ``candidates`` (confounded with ``[[alternative]]`` parameters in the screen at ``fit`` on
    the training conditions ``ids``): the candidate at its probe strength against its mimic
    (:func:`.evidence.alternative_mimic`, one forward run per condition), and the ``top`` measurements that
    tell the two apart (:func:`discriminating_measurements`).  Each entry: ``probe`` (strength in the effect's
    unit), ``mimic`` (its values), ``linear_misfit`` and ``clipped`` (the first-order move's), ``training_rms``
    (RMS of the two models' standardized difference on the training rows: how closely the mimic reproduces the
    candidate where the data are) and ``measurements``."""
    sig = signatures(problem, fit, candidates, ids)
    alts = "+".join(a.name for a in problem.spec.alternatives)
    mimics = {c: alternative_mimic(problem, fit, sig, c) for c in candidates}
    problem.predict([m for m, _ in mimics.values()], ids)      # one batch: the runs fill the parallel slots
    out = {}
    for c, (mimic, info) in mimics.items():
        probe = problem.spec.probe_strength(c)
        models = {c: {**fit.values(), "effect:" + c: probe}, f"{alts} mimic": mimic}
        out[c] = {"probe": probe, "mimic": mimic, **info, "training_rms": _training_rms(problem, models, ids),
                  "measurements": discriminating_measurements(problem, models, top=top)}
    return out


def _training_rms(problem, models: dict, ids) -> float:
    """RMS over the rows of conditions ``ids`` of the standardized difference between two models' predictions."""
    preds = problem.predict(list(models.values()), ids)
    m = problem.mask(ids)
    a, b = (problem.model_vector(p, m) for p in preds)
    d = problem.standardize(a - b, m, math.nan)
    d = d[np.isfinite(d)]
    return float(np.sqrt(np.mean(d**2))) if d.size else math.nan
