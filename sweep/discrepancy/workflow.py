"""The discrepancy workflow, stage by stage: calibrate a baseline, localize its misfit, screen and refit the
candidate effects, finalize the named model (noise at its fit, discretization refresh, profile interval,
noise-level rule), report.

Entry point: :func:`run_workflow(data, spec, forward, out_dir)` -> report dict (also written as
``report.json`` and ``report.md`` with figures in ``out_dir``).  The pieces each stage uses live in their own
modules: the fitting problem (problem.py), its noise model (noise.py), the evidence (evidence.py), the profile
likelihood (profile.py) and the report (report.py).  Units: mm, s, kPa; residuals are standardized
(dimensionless) by the measured uncertainties.

The discretization correction (fine − coarse) is a vector during the search: taken at the initial baseline
(``prepare``), re-estimated at the named model's fit by the refresh (:func:`refresh_correction`: a fixed point
of "correct at the fit, then refit", which does not see how the correction moves with the parameters).  With
``[profile] correction = "linear"`` the profile then models it as a linear function of the strength, or with
``correction_follows = "all"`` of every fitted parameter, and its refits and the named model's settling
evaluate that function at their own trial parameters (profile.py): the named model reported is then the
optimum of the likelihood with the correction where the model is.  The refresh stays a vector fixed point
also with "all": its only use there is to put the profile's anchors near the optimum (the model is built from
anchors about the fit, and rebuilt when a re-centred fit leaves their span), and a model of its own would cost
the anchors' fine runs twice.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np

from solver.effects import get_effect

from . import stats
from .checks import check_data_against_model
from .data import MeasuredData
from .discriminate import confounded_measurements, discriminating_measurements
from .emulated import EmulatedRefits
from .heldout import heldout_data
from .evidence import compare_passing, free_columns, gap, localize, refit, rival_refits, screen, wald_bounds
from .ledger import RunLedger
from .noise import add_discretization_error, add_model_jitter, rms_per_observable
from .problem import Fit, Problem, random_starts
from .recentre import profile_recentred
from .realizations import realizations
from .report import build_report, jsonable, write_report
from .spec import DiscrepancySpec

log = logging.getLogger("dchfrac.discrepancy")

__all__ = ["run_workflow", "VERDICTS", "Problem", "Fit"]

#: "inconclusive": the forward runs of a fit the verdict rests on did not reach every observation time (a
#: failed or short run): no verdict is drawn from placeholder residuals (:func:`check_reached`)
VERDICTS = ("named", "tie", "no_missing_effect", "unexplained_discrepancy", "inconclusive")


@dataclass
class WorkflowRun:
    """The state one stage hands to the next: the problem, the split, the baseline and the current model,
    the evidence gathered so far."""

    problem: Problem
    ledger: RunLedger
    fine: list | None
    train: list
    holdout: list
    disc_err: dict | None = None
    spread_rms: dict | None = None
    jitter: dict = field(default_factory=dict)
    fit0: Fit | None = None
    gap_before: dict | None = None
    loc0: dict | None = None
    current: Fit | None = None
    gap_cur: dict | None = None
    loc: dict | None = None
    accepted: list = field(default_factory=list)
    rounds: list = field(default_factory=list)
    first_candidates: list | None = None
    verdict: str | None = None
    tie: list = field(default_factory=list)
    refresh: list = field(default_factory=list)
    profiles: dict = field(default_factory=dict)
    profile_unidentified: list = field(default_factory=list)
    rivals: list = field(default_factory=list)
    partial: dict | None = None
    emulated: EmulatedRefits | None = None
    failed_points: dict = field(default_factory=dict)
    correction_models: dict = field(default_factory=dict)   # effect -> the profile's linear correction or None
    undecided: dict = field(default_factory=dict)   # models the data cannot tell apart: {name: fitted values}
    discriminating: list = field(default_factory=list)   # the measurements that would (discriminate.py)
    confounded: dict = field(default_factory=dict)       # candidate vs its [[alternative]] mimic (discriminate.py)

    @property
    def spec(self) -> DiscrepancySpec:
        return self.problem.spec

    def move_to(self, fit: Fit) -> None:
        """Make ``fit`` the current model: its held-out gap, the baseline's again (the same σ and data for
        both) and where it misses."""
        self.current = fit
        self.gap_before = gap(self.problem, self.fit0.params, self.fit0.x, self.holdout)
        self.gap_cur = gap(self.problem, fit.params, fit.x, self.holdout)
        self.loc = localize(self.problem, fit, self.train)

    def refit(self, params: tuple, starts: list, ref: Fit, stage: str) -> Fit:
        """A model's refit on the training conditions from ``starts``: real runs, or with ``[profile]
        emulate_refits`` and several starts on the model's emulator (built about ``ref``), checked and
        polished with real runs and recorded under ``stage`` (emulated.py).  A single-start refit (a refresh
        pass, the refit under the named model's jitter) runs on real runs: it starts near its optimum, where
        real least squares needs few runs and the emulator's checks and polish would cost as many, and an
        emulated optimum's scatter would keep the refresh's fixed point from settling."""
        if self.emulated is None or len(starts) < 2:
            return self.problem.fit(params, starts, self.train)
        return self.emulated.fit(params, starts, ref, stage)

    def emulator_of(self, params: tuple):
        """The emulator the refits of ``params`` built (None without emulated refits or before one)."""
        return None if self.emulated is None else self.emulated.emulators.get(tuple(p.name for p in params))


def prepare(data: MeasuredData, spec: DiscrepancySpec, forward, fine_forward) -> WorkflowRun:
    """The problem, the training/held-out split, and the noise model before any fit: the discretization
    correction from the fine models and, with ``model_jitter = "estimated"``, the coarse model's jitter at
    the initial baseline (so the baseline's χ² and every candidate's refit see the same jitter term)."""
    data = heldout_data(data, spec)        # [holdout] observables: held-out rows as twin conditions
    problem = Problem(data, spec, forward)
    fine = realizations(fine_forward) or None
    holdout = spec.holdout(data.ids)
    train = [i for i in data.ids if i not in holdout]
    if not train:
        raise ValueError("every condition is held out: nothing left to calibrate on")
    if not holdout:
        raise ValueError("no held-out condition: the gap on unseen conditions cannot be measured")
    run = WorkflowRun(problem, RunLedger(forward, fine or []), fine, train, holdout)
    if spec.profile.emulate_refits:
        run.emulated = EmulatedRefits(problem, train)
    if fine is not None:
        run.disc_err = add_discretization_error(problem, fine)
    run.ledger.mark("discretization_correction")
    if spec.noise.model_jitter == "estimated":
        run.jitter["baseline"] = add_model_jitter(problem, {p.name: p.initial for p in spec.calibrate},
                                                  spec.calibrate)
        run.ledger.mark("model_jitter")
    if fine is not None:
        run.spread_rms = rms_per_observable(problem.layout, problem.realization_spread)
    return run


def calibrate(run: WorkflowRun) -> None:
    """Fit the baseline parameters on the training conditions (the spec's initial values, then random
    starts); its held-out gap and where it misses."""
    spec, params = run.spec, tuple(run.spec.calibrate)
    starts = [np.array([p.to_x(p.initial) for p in params])] + random_starts(params, spec.fit.starts - 1,
                                                                           spec.fit.seed)
    run.fit0 = run.current = run.problem.fit(params, starts, run.train)
    run.gap_before = run.gap_cur = gap(run.problem, run.fit0.params, run.fit0.x, run.holdout)
    run.loc0 = run.loc = localize(run.problem, run.fit0, run.train)
    run.ledger.mark("baseline_calibration")


def _candidate_row(c: str, scr: dict, rf: dict | None) -> dict:
    """One candidate's line of the report: its screen and, if refitted, its evidence."""
    def ev(key):
        return rf[key] if rf else None

    row = {"effect": c, "score": scr["score"], "amplitude": scr["amplitude"], "identifiable": scr["identifiable"],
           "signature_ratio": scr["ratio"],
           "alternative_ratio": scr["alternative_ratio"], "confounded_with": scr["confounded_with"],
           "tied_with": scr["tied_with"], "delta_bic": ev("delta_bic"), "passed": rf["passed"] if rf else False,
           "strength": ev("strength"), "strength_interval": ev("strength_interval"),
           "explained_fraction": ev("explained_fraction"), "excludes_off": ev("interval_excludes_off"),
           "lr_off": ev("lr_off"), "heldout_gap": ev("gap")}
    if rf:
        row["bic_common"] = rf.get("bic_common")
    return row


def screen_and_refit(run: WorkflowRun, remaining: list, rnd: int) -> list:
    """One round: screen the remaining candidates at the current model, refit the best ``max_refits`` (and
    the candidates tied with them in the screen), rank those that pass.  Returns the passing refits."""
    problem, acc = run.problem, run.spec.acceptance
    scr = screen(problem, run.current, remaining, run.train)
    order = sorted([c for c in remaining if scr[c]["identifiable"] and scr[c]["score"] > 0],
                   key=lambda c: -scr[c]["score"])
    chosen = []
    for c in order[: acc.max_refits]:
        chosen += [cc for cc in [c] + scr[c]["tied_with"] if cc not in chosen and cc in order]
    run.ledger.mark("screening")
    fitter = None if run.emulated is None else (lambda params, starts, ref: run.refit(params, starts, ref, "refits"))
    refits = {c: refit(problem, run.current, c, scr[c], run.train, run.holdout, run.gap_cur, fitter)
              for c in chosen}
    run.ledger.mark("refits")
    passing = compare_passing([r for r in refits.values() if r["passed"]], problem, run.train)
    rows = [_candidate_row(c, scr[c], refits.get(c)) for c in remaining]
    if run.first_candidates is None:
        run.first_candidates = rows
    run.rounds.append({"round": rnd + 1, "baseline_values": run.current.values(), "candidates": rows,
                       "pinned_at_bound": [p.name for p, f in zip(run.current.params, free_columns(run.current))
                                           if not f],
                       "systematic_before": run.loc["systematic"]})
    return passing


def accept(run: WorkflowRun, passing: list, remaining: list) -> bool:
    """Name the best passing candidate, or declare a tie with those within ``tie_bic`` of it.  Returns
    whether another round may follow (the named model still misses systematically)."""
    best = passing[0]
    close = [p for p in passing[1:] if p["bic_common"] - best["bic_common"] < run.spec.acceptance.tie_bic]
    tying = [r for r in rivals(run, best) if r["ties"]]
    tied = [p["effect"] for p in close] + [f"alternative:{r['alternative']}" for r in tying]
    if tied:
        run.tie, run.verdict = [best["effect"]] + tied, "tie"
        run.undecided = {**{p["effect"]: p["fit"].values() for p in [best] + close},
                         **{f"alternative:{r['alternative']}": r["values"] for r in tying}}
        return False
    run.accepted.append({"effect": best["effect"], "strength": best["strength"],
                         "strength_interval": best["strength_interval"], "delta_bic": best["delta_bic"],
                         "scaling": run.spec.scaling.get(best["effect"], "none"),
                         "unit": get_effect(best["effect"]).unit})
    run.current, run.gap_cur = best["fit"], best["gap"]
    run.loc = localize(run.problem, run.current, run.train)
    remaining.remove(best["effect"])
    return bool(run.loc["systematic"])


def rivals(run: WorkflowRun, best: dict) -> list:
    """The ``[[alternative]]`` parameters refitted as rivals of the best passing candidate
    (:func:`evidence.rival_refits`), recorded for the report; [] without alternatives."""
    if not run.spec.alternatives:
        return []
    fitter = None if run.emulated is None else (lambda params, starts, ref: run.refit(params, starts, ref, "rivals"))
    rows = rival_refits(run.problem, best, run.current, run.train, run.holdout, fitter)
    run.rivals += rows
    run.ledger.mark("rivals")
    return rows


def search(run: WorkflowRun) -> None:
    """Rounds of screen → refit → accept, at most ``max_rounds``; sets the verdict."""
    remaining = list(run.spec.candidates)
    for rnd in range(run.spec.acceptance.max_rounds):
        if not remaining:
            break
        passing = screen_and_refit(run, remaining, rnd)
        if not passing or not accept(run, passing, remaining):
            break
    if run.verdict is None:
        run.verdict = "named" if run.accepted else _unnamed(run)


def check_reached(run: WorkflowRun, fit: Fit, stage: str) -> bool:
    """Did the forward runs of ``fit`` reach every observation time of every condition (training and held
    out)?  The fit treats a point without a prediction with the ``[fit] nan_residual`` penalty, which steers it
    away from parameters that fail; a verdict drawn from such placeholders would be a number the model never
    gave.  Otherwise the failed points are recorded by condition under ``stage``, the verdict is
    "inconclusive" and False is returned."""
    failed = {**run.problem.failed_points(fit.params, fit.x, run.train),
              **run.problem.failed_points(fit.params, fit.x, run.holdout)}
    if not failed:
        return True
    run.failed_points[stage] = failed
    run.verdict = "inconclusive"
    log.warning("verdict inconclusive: at the %s the forward runs did not reach %s", stage, failed_text(failed))
    return False


def failed_text(failed: dict) -> str:
    """One line naming the failed points of each condition ({cid: {"failed", "points"}})."""
    return "; ".join(f"condition {cid!r}: {v['failed']} of {v['points']} observation points"
                     + (" (no successful run)" if v["failed"] == v["points"] else "") for cid, v in failed.items())


def _unnamed(run: WorkflowRun) -> str:
    return "unexplained_discrepancy" if run.loc0["systematic"] else "no_missing_effect"


def refresh_correction(run: WorkflowRun) -> None:
    """Re-estimate the discretization correction at the named model's fit and refit it, to a fixed point.

    The first correction is made at the baseline, without the effect not yet found; an effect that changes
    the discretization error biases its fitted strength.  Passes (correct at the fit, refit from it) until
    every accepted strength moves by at most ``disc_refresh_tol`` (relative) or, with ``disc_refresh_tol_sd`` > 0,
    by at most that many of its Wald standard errors (a move the data cannot resolve), at most ``disc_refresh``."""
    problem, opts, fit = run.problem, run.spec.noise, run.current
    keys = ["effect:" + a["effect"] for a in run.accepted]
    prev = {k: float(fit.values()[k]) for k in keys}
    converged = False
    for _ in range(opts.disc_refresh):
        err = add_discretization_error(problem, run.fine, fit.values())
        fit = run.refit(fit.params, [fit.x], fit, "discretization_refresh")
        cur = {k: float(fit.values()[k]) for k in keys}
        change = {k: abs(cur[k] - prev[k]) / max(abs(cur[k]), abs(prev[k]), 1e-300) for k in keys}
        sd_change = _moves_in_sd(run, fit, keys, prev, cur)
        converged = all(change[k] <= opts.disc_refresh_tol or sd_change[k] <= opts.disc_refresh_tol_sd for k in keys)
        run.refresh.append({"values": jsonable(fit.values()), "discretization_error_rms": err,
                            "realization_spread_rms": rms_per_observable(problem.layout, problem.realization_spread),
                            "relative_change": change, "sd_change": jsonable(sd_change), "converged": converged})
        prev = cur
        if converged:
            break
    w = _train_weights(run, fit)
    names = [p.name for p in fit.params]
    for i, a in enumerate(run.accepted):
        j = names.index("effect:" + a["effect"])
        lo, hi, _ = wald_bounds(fit, j, w)
        run.accepted[i] = {**a, "strength_before_refresh": a["strength"], "strength": float(fit.x[j]),
                           "strength_interval": [lo, hi], "refresh_converged": converged,
                           "refresh_trajectory": [a["strength"]] + [r["values"]["effect:" + a["effect"]]
                                                                    for r in run.refresh]}
    run.move_to(fit)
    run.ledger.mark("discretization_refresh")


def _train_weights(run: WorkflowRun, fit) -> np.ndarray:
    """The series weights (lag-1 n_eff/n) of ``fit``'s residuals on the training conditions."""
    return stats.series_weights(fit.r, run.problem.series[run.problem.mask(run.train)])


def _moves_in_sd(run: WorkflowRun, fit, keys: list, prev: dict, cur: dict) -> dict:
    """Each strength's move in a refresh pass in units of its Wald standard error at the pass's fit (inf
    when the error is not finite, so that a move is never judged small by an undefined error)."""
    w = _train_weights(run, fit)
    names = [p.name for p in fit.params]
    out = {}
    for k in keys:
        j = names.index(k)
        p = fit.params[j]
        sd = wald_bounds(fit, j, w)[2]
        move = abs(p.to_x(cur[k]) - p.to_x(prev[k]))
        out[k] = float(move / sd) if np.isfinite(sd) and sd > 0 else math.inf
    return out


def noise_at_named_fit(run: WorkflowRun) -> None:
    """The noise model where the named model sits: its jitter (in its strength too; at the baseline the
    effect was off) and, with fine models, the refreshed correction; the model refitted under it."""
    refreshes = run.fine is not None and run.spec.noise.disc_refresh > 0
    if run.spec.noise.model_jitter == "estimated":
        run.jitter["named"] = add_model_jitter(run.problem, run.current.values(), run.current.params)
        run.ledger.mark("model_jitter")
        if not refreshes:
            fit = run.refit(run.current.params, [run.current.x], run.current, "model_jitter")
            for a in run.accepted:      # the strengths reported are the refitted model's
                a["strength"] = float(fit.values()["effect:" + a["effect"]])
            run.move_to(fit)
    if refreshes:
        refresh_correction(run)


def profile_named(run: WorkflowRun) -> None:
    """The named strengths' intervals from the profile likelihood (the Wald ones screened the candidates),
    each re-centred on the profile's minimum when the fit stopped short of it."""
    names = [p.name for p in run.current.params]
    fine = run.fine if run.spec.profile.fine else None
    before = run.current
    for a in run.accepted:
        j = names.index("effect:" + a["effect"])
        run.current, pr = profile_recentred(run.problem, run.current, j, run.train, fine_forward=fine,
                                            emulator=run.emulator_of(run.current.params))
        run.correction_models[a["effect"]] = pr.pop("_correction", None)
        run.profiles[a["effect"]] = pr
        a["strength_interval_wald"] = a["strength_interval"]
        a["strength_interval"] = [pr["lower"], pr["upper"]]
        a["strength_interval_rough"] = pr["rough"]
        if pr.get("smoothing") == "quadratic":
            a["strength_interval_raw"] = pr["raw"]
    if run.current is not before:       # re-centred, or settled under the profile's modelled correction
        final = run.current.values()    # every accepted strength is reported at the final fit
        for a in run.accepted:
            a["strength_before_profile"] = a["strength"]
            a["strength"] = float(final["effect:" + a["effect"]])
        run.move_to(run.current)        # gaps before and after, residual test: under the final correction
    run.ledger.mark("profile_likelihood")


def check_identified(run: WorkflowRun) -> None:
    """A named strength whose profile interval reaches "off" is not identified: along its profile the
    calibrated parameters make up for it all the way to off, so with these conditions the data cannot tell
    the effect from the baseline parameters.  Then nothing is named (not identifiable, not absent)."""
    reach_off = [a for a in run.accepted if a["strength_interval"][0] <= get_effect(a["effect"]).off]
    if not reach_off:
        return
    run.verdict = _unnamed(run)
    for a in reach_off:
        off = get_effect(a["effect"]).off
        at_off = min(run.profiles[a["effect"]]["points"], key=lambda q: abs(q["value"] - off))
        run.profile_unidentified.append({"effect": a["effect"], "interval": a["strength_interval"],
                                         "nearest_off": {"strength": at_off["value"],
                                                         "delta_chi2": at_off["delta_chi2"],
                                                         "others": at_off.get("others", {})}})
        if at_off.get("others"):   # the effect at its fit against the calibrated parameters making up for it
            run.undecided = {a["effect"]: run.current.values(),
                             f"{a['effect']} near off": {**at_off["others"], "effect:" + a["effect"]: at_off["value"]}}


def name_discriminating_measurements(run: WorkflowRun) -> None:
    """When the data cannot tell models apart (a tie, or a named strength the calibrated parameters make up
    for down to off), the measurements that would (:func:`.discriminate.discriminating_measurements`)."""
    if len(run.undecided) < 2:
        return
    run.discriminating = discriminating_measurements(run.problem, run.undecided)
    run.ledger.mark("discriminating_measurements")


def name_confounded_measurements(run: WorkflowRun) -> None:
    """For the candidates the first screen found confounded with ``[[alternative]]`` parameters, the
    measurements that would tell each from its mimic (:func:`.discriminate.confounded_measurements`, at the
    calibrated baseline the screen was taken at); off with ``[acceptance] confounded_measurements = false``."""
    rows = run.first_candidates or []
    confounded = [r["effect"] for r in rows if r.get("confounded_with")]
    if not confounded or not run.spec.acceptance.confounded_measurements:
        return
    run.confounded = confounded_measurements(run.problem, run.fit0, confounded, run.train)
    run.ledger.mark("confounded_measurements")


def check_noise_level(run: WorkflowRun) -> None:
    """A named model that still misses systematically explains part of the discrepancy only: when the true
    cause is outside the catalogue, a catalogue effect sharing part of its signature can pass every
    acceptance test.  It is reported as a partial explanation and nothing is named."""
    if run.verdict == "named" and run.loc["systematic"]:
        run.partial = {"effects": run.accepted, "gap_after": run.gap_cur, "final_values": run.current.values(),
                       "localization_after": run.loc}
        run.verdict = "unexplained_discrepancy"


def finalize(run: WorkflowRun) -> None:
    """The named model's noise, interval and checks (nothing to do without a name)."""
    if run.verdict != "named":
        return
    noise_at_named_fit(run)
    profile_named(run)
    check_identified(run)
    check_noise_level(run)


def run_workflow(data: MeasuredData, spec: DiscrepancySpec, forward, out_dir=None, figures: bool = True,
                 fine_forward=None) -> dict:
    """The workflow's stages; returns the report dict (written to ``out_dir`` when given).

    fine_forward : optional forward model on a finer discretization, or a list of them (realizations of
    the fine mesh and porosity field): the data are corrected by their mean difference to ``forward`` and
    their deviations enter the covariance (noise.add_discretization_error).
    """
    data = heldout_data(data, spec)
    check_data_against_model(data, spec, [forward, *realizations(fine_forward)])  # before any forward run
    run = prepare(data, spec, forward, fine_forward)
    calibrate(run)
    if check_reached(run, run.fit0, "calibrated baseline"):
        search(run)
        finalize(run)
        name_discriminating_measurements(run)
        name_confounded_measurements(run)
        if run.verdict == "named":
            check_reached(run, run.current, "named model")
    named = run.accepted[0] if run.accepted and run.verdict == "named" else None
    log.info("verdict %s%s", run.verdict, f": {named['effect']} = {named['strength']:.5g} "
             f"{named['strength_interval']}" if named else "")
    run.ledger.mark("gaps_and_localization")    # whatever the stages above left (held-out gaps, residual maps)
    report = build_report(run, forward)
    if out_dir is not None:
        after = run.current if run.verdict == "named" else run.fit0
        write_report(report, run.problem, run.fit0, after, out_dir, figures=figures)
    return report
