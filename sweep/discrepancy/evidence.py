"""The evidence the workflow weighs: held-out gaps, where the residuals are systematic, each candidate
effect's signature (screen) and joint refit (ΔBIC, interval, explained fraction, held-out gap), and the
ranking of the passing candidates.  Units: mm, s, kPa; residuals standardized (dimensionless).
"""
from __future__ import annotations

import logging
import math

import numpy as np

from . import stats
from .observables import CURVES
from .problem import Fit, Problem, random_starts

log = logging.getLogger("dchfrac.discrepancy")

__all__ = ["gap", "regime_mismatch", "localize", "screen", "signatures", "alternative_mimic", "free_columns",
           "wald_bounds", "refit", "compare_passing"]


def gap(problem: Problem, params, x, ids) -> dict:
    """Held-out gap: RMS standardized residual per observable and in total (same metric before/after).

    Standardized by the marginal σ of each point (measurement, discretization and realization terms), not
    whitened: a distance to read, in the same units with either realization covariance (whitening is for
    the likelihood, where correlated points must not count as independent evidence)."""
    if not ids:
        return {}
    mask = problem.mask(ids)
    m = problem.model_vector(problem.prediction(params, x, ids), mask)
    r = (problem.data_at(params, x)[mask] - m) / problem.sig[mask]
    r = np.where(np.isfinite(r), r, problem.spec.fit.nan_residual)
    obs = problem.obs[mask]
    g = {o: float(np.sqrt(np.mean(r[obs == o] ** 2))) for o in CURVES if np.any(obs == o)}
    g["total"] = float(np.sqrt(np.mean(r**2)))
    return g


def regime_mismatch(problem: Problem, params, x, ids) -> dict:
    out = {}
    pred = problem.prediction(params, x, ids)
    for cid in ids:
        if cid in problem.data.regimes:
            meas = problem.data.regimes[cid][1]
            mod = pred[cid].get("regime")
            out[cid] = {"measured": meas, "model": mod, "match": (mod == meas) if mod is not None else None}
    return out


def localize(problem: Problem, fit: Fit, ids) -> dict:
    """Where the calibrated model misses: per observable, per phase, per condition, serial correlation."""
    m = problem.mask(ids)
    r = fit.r
    obs, ph, cond, ser = problem.obs[m], problem.phase[m], problem.cond[m], problem.series[m]
    out = {"per_observable": {}, "per_phase": {}, "per_condition": {}}
    for o in CURVES:
        s = obs == o
        if s.any():
            out["per_observable"][o] = {"rms": float(np.sqrt(np.mean(r[s] ** 2))), "mean": float(np.mean(r[s])), "n": int(s.sum())}
    for k, name in enumerate(stats.PHASES):
        s = ph == k
        if s.any():
            out["per_phase"][name] = {"rms": float(np.sqrt(np.mean(r[s] ** 2))), "mean": float(np.mean(r[s])), "n": int(s.sum())}
    for cid in ids:
        s = cond == cid
        out["per_condition"][cid] = {o: float(np.mean(r[s & (obs == o)])) for o in CURVES if np.any(s & (obs == o))}
    # with an estimated realization covariance the series statistics are calibrated for the estimate's
    # degrees of freedom (RealizationCovariance.null_calibration)
    null = problem.noise.null_calibration(m, seed=problem.spec.fit.seed)
    sys_ = stats.systematic_test(r, ser, problem.spec.acceptance.z_crit, problem.spec.acceptance.rho_crit, null=null)
    names = problem.series_names
    out["series"] = {names[int(k)]: v for k, v in sys_["series"].items()}
    out["systematic"] = sys_["systematic"]
    out["regimes"] = regime_mismatch(problem, fit.params, fit.x, ids)
    out["regime_misclassified"] = sum(1 for v in out["regimes"].values() if v["match"] is False)
    return out


def screen(problem: Problem, fit: Fit, candidates, ids) -> dict:
    """Signature of each candidate (one perturbed run per condition at its probe strength), projected off
    the calibrated parameters' directions and, when the SPEC lists ``[[alternative]]`` parameters, off
    theirs too; see :func:`stats.signature_table`."""
    if not candidates:
        return {}
    sig = signatures(problem, fit, candidates, ids)
    return stats.signature_table(fit.r, sig["w"], sig["J"], sig["signatures"],
                                 min_ratio=problem.spec.acceptance.min_ratio,
                                 tie_cos=problem.spec.acceptance.tie_cos, A=sig["A"],
                                 alternatives=tuple(a.name for a in problem.spec.alternatives),
                                 bounds=sig["bounds"])


def signatures(problem: Problem, fit: Fit, candidates, ids) -> dict:
    """The screen's matrices at ``fit`` on the conditions ``ids``: each candidate's signature (the standardized
    model change from off to its probe strength), ``A`` (one column per ``[[alternative]]``: the standardized
    change for its finite-difference step, :func:`alternative_steps`; None without alternatives), ``J`` (the
    model's standardized sensitivity to the free calibrated parameters, per unit of their fit coordinates),
    ``free`` (which calibrated parameters are free, :func:`free_columns`), ``w`` (the series weights) and
    ``bounds`` (lower, upper per column of [J, A]: how far each parameter can move within its range, in the
    column's unit: fit coordinates for J, finite-difference steps for A; :func:`move_bounds`)."""
    vals0 = fit.values()
    alts = problem.spec.alternatives
    vlist = ([vals0] + [{**vals0, "effect:" + c: problem.spec.probe_strength(c)} for c in candidates]
             + [{**vals0, a.name: v} for a, v in zip(alts, alternative_steps(alts))])
    preds = problem.predict(vlist, ids)
    m = problem.mask(ids)
    ms = [problem.model_vector(p, m) for p in preds]
    # the same standardization as the residuals (a signature is a difference of model curves; a point
    # where either run failed carries none)
    diffs = [problem.standardize(mi - ms[0], m, 0.0) for mi in ms[1:]]
    free = free_columns(fit)
    return {"signatures": dict(zip(candidates, diffs[:len(candidates)])),
            "A": np.column_stack(diffs[len(candidates):]) if alts else None,
            "J": -fit.J[:, free], "free": free, "w": stats.series_weights(fit.r, problem.series[m]),
            "bounds": move_bounds(problem, fit, free)}


def _moves(problem: Problem, fit: Fit, free) -> list:
    """(parameter, its starting fit coordinate, the coordinate change of one column unit) for each column of
    [J, A]: the free calibrated parameters (unit: one fit coordinate), then the ``[[alternative]]`` parameters
    (unit: one finite-difference step, :func:`alternative_steps`)."""
    moves = [(p, float(fit.x[j]), 1.0) for j, p in enumerate(fit.params) if free[j]]
    return moves + [(a, a.to_x(a.initial), a.inward_step(a.to_x(a.initial))) for a in problem.spec.alternatives]


def move_bounds(problem: Problem, fit: Fit, free) -> tuple:
    """(lower, upper) of each column's coefficient in [J, A] c that keeps its parameter within its range."""
    lo, hi = [], []
    for p, x0, unit in _moves(problem, fit, free):
        a, b = ((xb - x0) / unit for xb in p.x_bounds)
        lo.append(min(a, b))
        hi.append(max(a, b))
    return np.array(lo), np.array(hi)


def alternative_mimic(problem: Problem, fit: Fit, sig: dict, candidate: str) -> tuple[dict, dict]:
    """The model ``candidate`` is confounded with: the baseline at ``fit`` with its free calibrated parameters
    and its ``[[alternative]]`` parameters moved, to first order, so as to reproduce the candidate's screening
    signature (``sig``: :func:`signatures`) on the conditions it was taken on.  The move is the weighted least
    squares solution of [J, A] c = s in the screen's standardized space (the calibrated parameters by c_J in
    their fit coordinates, each alternative by c_A of its finite-difference steps) within each parameter's
    range (``sig["bounds"]``, :func:`stats.bounded_lstsq`, the screen's own rule).  Returns (values, info): the
    values dict (calibrated parameters and alternatives by name, in their units) and {"linear_misfit":
    ‖[J, A]c − s‖/‖s‖ (weighted), "clipped": the parameters the move leaves at an end of their range}."""
    if not problem.spec.alternatives:
        raise ValueError("alternative_mimic: the SPEC has no [[alternative]] parameter")
    sw = np.sqrt(np.asarray(sig["w"], float))
    s = np.asarray(sig["signatures"][candidate], float) * sw
    M = np.column_stack([sig["J"], sig["A"]]) * sw[:, None]
    lower, upper = sig["bounds"]
    c = stats.bounded_lstsq(M, s, lower, upper)
    misfit = float(np.linalg.norm(M @ c - s) / max(np.linalg.norm(s), 1e-300))
    at_end = np.isclose(c, lower, rtol=1e-9) | np.isclose(c, upper, rtol=1e-9)
    values, moves = fit.values(), _moves(problem, fit, sig["free"])
    for (p, x0, unit), d in zip(moves, c):
        values[p.name] = p.from_x(float(np.clip(x0 + d * unit, *sorted(p.x_bounds))))   # the clip: rounding only
    return values, {"linear_misfit": misfit, "clipped": [p.name for (p, _, _), e in zip(moves, at_end) if e]}


def alternative_steps(alts) -> list:
    """The stepped value of each alternative: its baseline value moved by its finite-difference step
    (``CalibParam.inward_step``: 2 % of its range in its scale unless given, toward the inside of its range)."""
    return [a.from_x(a.to_x(a.initial) + a.inward_step(a.to_x(a.initial))) for a in alts]


def bound_sides(fit: Fit, rtol: float = 1e-4) -> list:
    """Per calibrated parameter of ``fit``: "lower" or "upper" when it is pinned at that bound (within
    ``rtol`` of its range in fit coordinates), else None."""
    sides = []
    for j, p in enumerate(fit.params):
        lo, hi = p.x_bounds
        tol = rtol * (hi - lo)
        sides.append("lower" if fit.x[j] <= lo + tol else "upper" if fit.x[j] >= hi - tol else None)
    return sides


def free_columns(fit: Fit, rtol: float = 1e-4) -> np.ndarray:
    """Columns of the calibrated parameters NOT pinned at a bound: a parameter at its bound cannot absorb
    a signature any further, so projecting it out would hide an effect the data call for."""
    return np.array([s is None for s in bound_sides(fit, rtol)], bool)


def wald_bounds(fit: Fit, j: int, w) -> tuple[float, float, float]:
    """Wald 95 % (lower, upper) of ``fit``'s parameter j in its units, clipped to its bounds, and its sd (x units)."""
    p = fit.params[j]
    lo, hi, sd = stats.wald_interval(fit.J, fit.r, w, j, float(fit.x[j]))
    x_lo, x_hi = p.x_bounds
    return float(p.from_x(max(lo, x_lo))), float(p.from_x(min(hi, x_hi))), sd


def refit(problem: Problem, base_fit: Fit, cand: str, screen_row: dict, train, holdout, gap_base: dict,
          fitter=None) -> dict:
    """Joint fit of the baseline parameters and the candidate's strength; acceptance evidence.  ``fitter``
    (params, starts, base_fit) -> Fit on ``train``: how the joint fit is made (default real runs,
    :meth:`Problem.fit`; the workflow's emulated refits, emulated.py)."""
    spec = problem.spec
    cp = spec.candidate_param(cand)
    params = base_fit.params + (cp,)
    probe = spec.probe_strength(cand)
    a0 = float(np.clip(screen_row.get("amplitude", 1.0) * probe, cp.lower, cp.upper))
    starts = [np.append(base_fit.x, a0)]
    if abs(a0 - probe) > 1e-12 * max(1.0, abs(probe)):
        starts.append(np.append(base_fit.x, probe))
    # the baseline's fit may have bent its parameters (even to a bound) to mimic the missing effect:
    # also start from the spec's initial values with the probe strength
    x_init = np.array([p.to_x(p.initial) for p in base_fit.params] + [probe])
    if not any(np.allclose(x_init, s_) for s_ in starts):
        starts.append(x_init)
    starts += random_starts(params, spec.fit.starts - len(starts), spec.fit.seed)
    f = problem.fit(params, starts, train) if fitter is None else fitter(params, starts, base_fit)
    ser = problem.series[problem.mask(train)]
    w = stats.series_weights(f.r, ser)        # weights from the richer model, applied to both
    k0 = len(base_fit.params)
    b0 = stats.bic(base_fit.r, w, k0)
    b1 = stats.bic(f.r, w, k0 + 1)
    c0, n_eff = stats.effective_chi2(base_fit.r, w)
    c1, _ = stats.effective_chi2(f.r, w)
    explained = (c0 - c1) / max(c0 - n_eff, 1e-12) if c0 > n_eff else 0.0
    lo, hi, sd = wald_bounds(f, len(params) - 1, w)   # lo > off iff the unclipped bound is (off is the lower bound)
    g = gap(problem, params, f.x, holdout)
    gap_ok = bool(holdout) and g["total"] <= (1 - spec.acceptance.min_gap_reduction) * gap_base["total"]
    # Does the interval exclude "off"?  Ask the profile itself at off: the strength held at off with the
    # calibrated parameters refitted is the baseline fit, so the likelihood-ratio statistic χ²(off) − χ²(fit)
    # against 3.84 × the misfit scale costs no run (the Wald bound linearizes at the fit and is wrong both ways
    # in a curved valley).  And the strength must be determined at all: on an exact ridge with a calibrated
    # parameter the Wald sd is infinite (stats.wald_interval), and a χ² drop at off says nothing about it
    k1 = len(params)
    scale = max(1.0, c1 / max(n_eff - k1, 1.0))
    lr_off = float(c0 - c1)
    excludes_off = bool(lr_off > 3.841 * scale and math.isfinite(sd))
    passed = bool(b1 - b0 <= spec.acceptance.delta_bic and excludes_off and gap_ok and explained >= spec.acceptance.min_explained)
    log.info("refit %s: strength %.5g, delta BIC %.1f, held-out gap %.3g -> %.3g, %s", cand, f.x[-1], b1 - b0,
             gap_base["total"], g["total"], "passes" if passed else "fails")
    return {"effect": cand, "fit": f, "delta_bic": float(b1 - b0), "strength": float(f.x[-1]),
            "strength_interval": [lo, hi], "strength_sd": sd,
            "explained_fraction": float(explained), "gap": g, "gap_ok": gap_ok,
            "interval_excludes_off": excludes_off, "lr_off": lr_off, "lr_threshold": 3.841 * scale,
            "passed": passed,
            "values": f.values()}


def rival_refits(problem: Problem, best: dict, base_fit: Fit, train, holdout, fitter=None) -> list:
    """The ``[[alternative]]`` parameters as rivals of the best passing candidate (nonlinear: the screen's
    projection is linear at the baseline, and a parameter far from its book value can mimic an effect that
    its direction there does not).  For each alternative the model without the candidate (``base_fit``'s) is
    refitted with the alternative freed in its range, from the baseline (the alternative at its value) and
    from the candidate's calibrated values with the alternative at the quarter and three-quarter points of
    its range (in its scale), and compared with the candidate's model by BIC under the per-series minimum of
    the two models' weights (as :func:`compare_passing`; both have one parameter more than the baseline).  A
    rival within ``tie_bic`` of the candidate, or better, ties with it: the data cannot tell the effect from a
    change of that parameter.  ``fitter`` as in :func:`refit`.  Returns one row per alternative: its name,
    fitted value, Δ = BIC(rival) − BIC(candidate), whether it ties, its held-out gap."""
    spec = problem.spec
    ser = problem.series[problem.mask(train)]
    xc = best["fit"].x[:-1]                     # the candidate's strength is the last parameter of its refit
    rows = []
    for alt in spec.alternatives:
        params = base_fit.params + (alt,)
        lo, hi = alt.x_bounds
        starts = [np.append(base_fit.x, alt.to_x(alt.initial)),
                  np.append(xc, lo + 0.25 * (hi - lo)), np.append(xc, lo + 0.75 * (hi - lo))]
        f = problem.fit(params, starts, train) if fitter is None else fitter(params, starts, base_fit)
        b_rival, b_best = common_bics([f, best["fit"]], ser)
        delta = float(b_rival - b_best)
        value = float(alt.from_x(f.x[-1]))
        ties = bool(delta < spec.acceptance.tie_bic)
        log.info("rival %s of %s: %s = %.5g, BIC(rival) - BIC(candidate) %.1f, %s", alt.name, best["effect"],
                 alt.name, value, delta, "ties" if ties else "does not tie")
        rows.append({"alternative": alt.name, "candidate": best["effect"], "value": value, "values": f.values(),
                     "delta_bic": delta, "ties": ties, "gap": gap(problem, params, f.x, holdout)})
    return rows


def compare_passing(passing: list, problem: Problem, train) -> list:
    """The passing refits ranked for the tie rule by BIC under weights common to all of them.

    Each refit's ΔBIC against the baseline uses the series weights n_eff/n of its own residuals (the richer
    model's, applied to both); a candidate that leaves less autocorrelated residuals gets larger weights, and
    so a larger |ΔBIC| for the same χ².  Two candidates' ΔBICs are then on different scales, and their
    difference is not evidence (a wrong name, results/discrepancy/DESIGN_NOTES.md).  So candidates are compared with w = the per-series minimum of their
    weights (the fewest effective points any of them leaves: the conservative choice, margins shrink, ties
    are not broken by weighting).  Sets ``bic_common`` on each; returns them sorted by it (one refit: its BIC
    under its own weights)."""
    if not passing:
        return []
    for p, b in zip(passing, common_bics([p["fit"] for p in passing], problem.series[problem.mask(train)])):
        p["bic_common"] = b
    return sorted(passing, key=lambda d: d["bic_common"])


def common_bics(fits: list, series) -> list:
    """The BIC of each fit under the per-series minimum of their series weights (``series``: the series index
    of each training point), so that models are compared on one scale (see :func:`compare_passing`)."""
    w = np.minimum.reduce([stats.series_weights(f.r, series) for f in fits])
    return [float(stats.bic(f.r, w, len(f.params))) for f in fits]
