"""The re-centring of a fit on its profile's minimum, and the named model settled under the profile's correction.

A profile point below the fit (Δχ² < 0) means the joint fit stopped short of the minimum (a budget-limited
least squares in a curved valley): the fit is redone there and the profile recomputed about it
(:func:`profile_recentred`), never silently: each re-centring is recorded in the profile's ``recentred``.  With
``[profile] correction = "linear"`` the correction's model is kept through the passes (common random numbers)
and the named model is settled under it at its own strength (:func:`settled_fit`).  Units: each parameter's
own; Δχ² dimensionless.
"""
from __future__ import annotations

import numpy as np

from .emulated import emulated_fit
from .emulator import CurveEmulator
from .noise import correction_at
from .problem import Fit, Problem
from .profile import _Profile, _profile_run, emulator_for

__all__ = ["recentre_target", "profile_recentred", "settled_fit", "pieces_outside"]


def recentre_target(pr: dict, tol: float = 1e-2) -> dict | None:
    """The profile point a fit should be re-centred on, or None: the lowest point, if it lies below the fit by
    more than ``tol`` × the threshold and, for a smoothed profile (``smoothing = "quadratic"``), by more than
    twice the points' scatter about the quadratic.  With a jittering model every point is a noisy evaluation,
    and the lowest of ~15 points with scatter σ lies about 2σ below the smooth curve by chance alone: a point
    below the fit by less than that is the noise, not a fit that stopped short, and chasing it re-runs the
    whole profile about a luckier point.  The scatter is taken about the quadratic, so it also holds the
    profile's departure from a quadratic: over a wide, saturating profile the rule re-centres less."""
    best = min(pr["points"], key=lambda q: q["delta_chi2"])
    floor = tol * pr["threshold"]
    q = pr.get("quadratic")
    if q and q.get("residual_sd") is not None:
        floor = max(floor, 2.0 * float(q["residual_sd"]))
    return best if best["delta_chi2"] < -floor else None


def pieces_outside(earlier: list, pr: dict) -> list:
    """Points of earlier passes, evaluated under the same correction function as the last pass ``pr``, whose
    Δχ² re-referenced to ``pr``'s minimum (χ²_point − χ²_ref of ``pr``, from each pass's "reference_chi2") is
    under ``pr``'s threshold while they lie outside [lower, upper]: a second piece of the confidence set that
    the last pass, which stops walking at its first crossings, does not see.  A value evaluated more than once
    (again after the correction gained an anchor or the emulator a design point) counts by its latest evaluation,
    the one nearest the last pass's state.  Returns them sorted by value (strength units; Δχ² dimensionless),
    each {"value", "delta_chi2"}."""
    ref, lo, hi = pr["reference_chi2"], pr["lower"], pr["upper"]
    latest = {q["value"]: q["delta_chi2"] + old["reference_chi2"] - ref for old in earlier for q in old["points"]}
    return [{"value": float(v), "delta_chi2": float(d)} for v, d in sorted(latest.items())
            if d < pr["threshold"] and not lo <= v <= hi]


def _profile_minimum(problem: Problem, fit: Fit, j: int, ids, pr: dict, fine_forward, em, cm) -> Fit:
    """The minimum of the profile under the modelled correction (:class:`StrengthCorrection`), found by a
    bounded scalar minimization of Δχ²(x) between the lowest evaluated point's neighbours, and the model there
    as a Fit (the others' refit, residuals and Jacobian under c(x*)).  A joint refit under one correction vector
    would stop at the fixed point of "refit, then correct where it stopped", which is not the profile's minimum
    once the correction depends on the strength: the profile's gradient holds the correction's own derivative."""
    from scipy.optimize import minimize_scalar

    pf = _Profile(problem, fit, j, ids, 3.841, fine_forward, em, cm)
    xs = sorted(pf.p.to_x(q["value"]) for q in pr["points"])
    best = pf.p.to_x(min(pr["points"], key=lambda q: q["delta_chi2"])["value"])
    i = xs.index(best)
    step = min(abs(b - a) for a, b in zip(xs[:-1], xs[1:]) if b != a) if len(xs) > 1 else 0.1 * (pf.x_hi - pf.x_lo)
    lo = xs[i - 1] if i > 0 else max(best - step, pf.x_lo)
    hi = xs[i + 1] if i + 1 < len(xs) else min(best + step, pf.x_hi)
    res = minimize_scalar(pf.dchi2, bounds=(lo, hi), method="bounded",
                          options={"xatol": 1e-3 * (hi - lo), "maxiter": 12})
    xj = float(res.x) if res.fun <= pf.dchi2(best) else best
    with pf.holding(xj):
        held = pf.modelled_refit(xj)
    return settled_fit(problem, fit.params, j, xj, held.x, ids, cm, em, refit=False)


def settled_fit(problem: Problem, params: tuple, j: int, xj: float, x_free, ids, cm, em=None,
                refit: bool = True) -> Fit:
    """The model at strength ``xj`` (fit coordinates, parameter ``j`` of ``params``) under the modelled
    correction for real runs (:meth:`StrengthCorrection.for_real_runs`; its value at the settled point left in
    use as the correction vector), as a Fit of real runs: the others from
    ``x_free`` (an emulated refit's when ``em`` is given, then polished with ``[profile] emulator_polish``
    real least-squares evaluations at the held strength, so that the named model's residuals, held-out gap
    and residual test are those of a real conditional optimum, not of the emulator's), its residuals and
    Jacobian from real runs.  Without ``em`` the others are refitted from ``x_free`` by real least squares (from
    the fit's values that is the profile's own reference refit, its runs cached); ``refit = False``: ``x_free``
    is that real refit already.  The others' refit evaluates the model at each of its trial points
    (:meth:`NoiseModel.following`: with ``correction_follows = "all"`` it sees the correction's derivative in
    them); the Fit's residuals and Jacobian are taken under the vector at the settled point, as every Fit's of
    the workflow is under the correction vector in use.  The polished point joins ``em``'s design."""
    model, p = cm.for_real_runs(), params[j]
    x_free = np.asarray(x_free, float)
    if x_free.size and (refit or em is not None):
        problem.fixed = {p.name: p.from_x(xj)}
        try:
            with problem.noise.following(model):
                x_free = np.asarray(problem.fit(params[:j] + params[j + 1:], [x_free], ids,
                                                max_nfev=problem.spec.profile.emulator_polish if em else None).x,
                                    float)
        finally:
            problem.fixed = {}
    x = np.insert(x_free, j, xj)
    problem.noise.shift_correction(model({q.name: q.from_x(v) for q, v in zip(params, x)}))
    r = problem.residual_batch(params, [x], ids)[0]
    if em is not None and not em.has(x):
        em.add([x])                          # the minimum's own run (cached): the design grows by it
    return Fit(params, x, r, problem.jacobian(params, x, ids), 0.5 * float(r @ r), 0)


def profile_recentred(problem: Problem, fit: Fit, j: int, ids, max_passes: int = 2, fine_forward=None,
                      emulator: CurveEmulator | None = None) -> tuple:
    """Profile interval of parameter ``j``, re-centred when the profile finds a better fit than ``fit``.

    A point with Δχ² < 0 means the joint fit stopped short of the minimum (a budget-limited least squares,
    ``max_nfev``, in a curved valley).  Then the fit is redone from the best profile point
    (:func:`recentre_target`) and the profile recomputed about it, so the strength reported is the profile's
    minimum and the interval is measured from it.  At most ``max_passes`` re-centrings; with
    ``fine_forward`` a re-centring also re-estimates the correction at the new fit; with ``[profile]
    emulate_refits`` the re-centring refit runs on the profile's emulator, checked and polished with real
    runs (:func:`~.emulated.emulated_fit`, its record in the pass's "emulated_refit").
    ``emulator``: with ``[profile] emulator = "gp"``, an emulator of ``fit``'s parameters on ``ids`` to use
    (the named model's from its emulated refits, its design shared); default one built about the fit
    (:func:`emulator_for`).
    With ``[profile] correction = "linear"`` the correction's model is built about ``fit`` and kept for every
    pass (common random numbers): a re-centring moves the reference, not the likelihood, and goes to the
    profile's own minimum (:func:`_profile_minimum`); only a minimum outside the anchors' range in a modelled
    parameter (:meth:`StrengthCorrection.covers`) has the model rebuilt about it for the next pass.  Without a re-centring the fit is settled under that correction at its
    own strength (:func:`settled_fit`): the model reported is always the one the profile measured from.
    Returns (fit, profile dict with "recentred": the earlier strengths and their Δχ² minima, "pieces_outside":
    the earlier passes' points under the threshold outside the last interval when the passes share one correction
    function (:func:`pieces_outside`; empty otherwise), and
    "_correction": the linear correction's model or None, to be popped before the dict is serialized)."""
    history, settled, same_model = [], None, []   # same_model: earlier passes under the current cm
    em = None
    if problem.spec.profile.emulator == "gp":
        em = emulator if emulator is not None else emulator_for(problem, fit, ids)
    pr, cm = _profile_run(problem, fit, j, ids, 3.841, fine_forward, em, None)
    for _ in range(max_passes):
        best = recentre_target(pr)
        if best is None:
            break
        history.append({"strength": float(fit.params[j].from_x(fit.x[j])), "min_delta_chi2": best["delta_chi2"],
                        "at": best["value"]})
        if cm is not None:                   # the same correction function: the profile's own minimum
            fit, settled = _profile_minimum(problem, fit, j, ids, pr, fine_forward, em, cm), cm
            same_model.append(pr)
            if not cm.covers(fit.values()):
                cm, same_model = None, []    # outside the anchors: the next pass models it about the new fit
            pr, cm = _profile_run(problem, fit, j, ids, 3.841, fine_forward, em, cm)
            continue
        vals = {**best.get("others", {}), fit.params[j].name: best["value"]}
        x0 = np.array([p.to_x(vals[p.name]) for p in fit.params])
        if fine_forward is not None:
            problem.noise.shift_correction(correction_at(problem, fine_forward, {**problem.fixed, **{
                q.name: q.from_x(v) for q, v in zip(fit.params, x0)}}))
        if em is not None and problem.spec.profile.emulate_refits:
            fit, history[-1]["emulated_refit"] = emulated_fit(em, [x0])
        else:
            fit = problem.fit(fit.params, [x0], ids)
        if em is not None and not em.has(fit.x):
            em.add([fit.x])                  # the re-centred fit's own run (cached): the design grows by it
        pr, cm = _profile_run(problem, fit, j, ids, 3.841, fine_forward, em, cm)
    if cm is not None and settled is not cm:    # the named model under the profile's correction at its strength
        xj = float(fit.x[j])
        fit = settled_fit(problem, fit.params, j, xj, np.delete(np.asarray(fit.x, float), j), ids, cm, em)
    pr["recentred"] = history
    pr["pieces_outside"] = pieces_outside(same_model, pr)
    pr["_correction"] = cm       # the linear correction's model (not JSON: the caller pops it), None otherwise
    return fit, pr
