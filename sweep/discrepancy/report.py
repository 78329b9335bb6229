"""The report of a workflow run: its dict (report.json) and report.md, with the figures of
:mod:`sweep.discrepancy.report_figures`; :func:`render_report` rewrites report.md from report.json alone.  Units:
mm, s, kPa; residuals and gaps standardized (dimensionless)."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from . import stats
from .observables import UNITS
from .evidence import bound_sides
from .problem import Fit
from .report_measurements import confounded_lines as _confounded_lines
from .report_measurements import discriminating_lines as _discriminating_lines
from .report_measurements import fmt as _f
from .report_figures import fig_curves, fig_profiles, fig_residuals

__all__ = ["build_report", "write_report", "render_markdown", "render_report", "jsonable", "ROUGH_NOTE"]


def jsonable(o):
    """``o`` with numpy scalars as Python numbers, non-finite floats as None and fitted models dropped."""
    if isinstance(o, dict):
        return {str(k): jsonable(v) for k, v in o.items() if not isinstance(v, Fit)}
    if isinstance(o, (list, tuple)):
        return [jsonable(v) for v in o]
    if isinstance(o, np.floating):
        return float(o)
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.bool_):
        return bool(o)
    if isinstance(o, float) and not math.isfinite(o):
        return None
    return o


def _named_fields(named: dict | None) -> dict:
    """The verdict's headline: the named effect, its strength, interval (rough: the interval's width reflects
    the coarse model's jitter, a lower bound on the uncertainty) and scaling."""
    return {"named_effect": named["effect"] if named else None,
            "strength": named["strength"] if named else None,
            "strength_interval": named["strength_interval"] if named else None,
            "strength_interval_rough": bool(named.get("strength_interval_rough", False)) if named else None,
            "strength_scaling": named["scaling"] if named else None}


def _noise_fields(run) -> dict:
    """The noise model's summary: discretization correction, realization spread and covariance, jitter."""
    problem, fine = run.problem, run.fine
    rc = problem.real_cov
    has_rc = rc is not None and rc.k >= 2
    return {"discretization_error_rms": run.disc_err, "realization_spread_rms": run.spread_rms,
            "discretization_realizations": len(fine) if fine is not None else 0,
            "realization_covariance": ("correlated" if has_rc else "diagonal") if fine is not None else None,
            "realization_correlation_time": rc.tau if has_rc else None,
            "realization_lag1": rc.rho if has_rc else None,
            "realization_lag1_estimator": rc.lag1 if has_rc else None,
            "realization_blocks": rc.mode if has_rc else None,
            # the pooled correlation between conditions of the realizations' deviations and its dof
            "realization_condition_correlation": ({o: [rc.rho_cond[o], rc.rho_cond_dof[o]] for o in rc.rho_cond}
                                                  if has_rc and rc.rho_cond else None),
            "model_jitter": run.jitter or None, "discretization_refresh": run.refresh}


def build_report(run, forward) -> dict:
    """The report dict of a finished :class:`~.workflow.WorkflowRun` (JSON-ready)."""
    named_ok = run.verdict == "named"
    named = run.accepted[0] if run.accepted and named_ok else None
    cands = run.first_candidates or []
    report = {"verdict": run.verdict, **_named_fields(named), "accepted": run.accepted, "tie": run.tie,
              "candidates": cands,
              # by the linear screen (signature inside the calibrated parameters' reach) or by the profile
              "not_identifiable": [c["effect"] for c in cands if not c["identifiable"]]
                                  + [u["effect"] for u in run.profile_unidentified],
              "profile_not_identifiable": run.profile_unidentified,
              "gap_before": run.gap_before, "gap_after": run.gap_cur if named_ok else run.gap_before,
              "calibrated_baseline": run.fit0.values(),
              "calibrated_at_bound": {p.name: side for p, side in zip(run.fit0.params, bound_sides(run.fit0)) if side},
              "final_values": run.current.values() if named_ok else run.fit0.values(),
              "train": run.train, "holdout": run.holdout,
              "condition_columns": list(run.problem.data.conditions.columns),   # set per condition (named_model.py)
              "localization_before": run.loc0, "localization_after": run.loc if named_ok else None,
              "residuals_systematic_after": bool(run.loc["systematic"] if named_ok else run.loc0["systematic"]),
              "rounds": run.rounds, "forward_runs": int(getattr(forward, "n_runs", 0)),
              "forward_runs_by_stage": run.ledger.stages, **_noise_fields(run),
              "profiles": run.profiles, "partial_explanation": run.partial, "rivals": run.rivals,
              "failed_points": run.failed_points, "discriminating_measurements": run.discriminating,
              "confounded_measurements": run.confounded}
    report["independent_estimates"] = independent_comparison(run.accepted, run.spec.independent)
    if run.emulated is not None:
        report["emulated_refits"] = run.emulated.summary()
    report["code"] = code_provenance()
    return jsonable(report)


def independent_comparison(accepted: list, independent: dict) -> dict:
    """Each independent strength estimate (spec ``[candidates] independent``: effect -> (value, σ)) beside the
    fitted one: for an accepted effect its 95 % interval, the fitted sd (the interval's half-width / 1.96),
    z = (fitted − independent)/√(σ² + sd²) and ``disagrees`` when |z| > 2; for one not accepted, the value
    alone.  Strengths in the effect's unit."""
    fitted = {a["effect"]: a for a in accepted}
    out = {}
    for eff, (v, sig) in independent.items():
        row = {"value": float(v), "sigma": float(sig), "fitted": None, "interval": None, "z": None,
               "disagrees": None}
        a = fitted.get(eff)
        if a is not None and a.get("strength_interval") and None not in a["strength_interval"]:
            lo, hi = (float(x) for x in a["strength_interval"])
            sd = 0.5 * (hi - lo) / 1.96
            z = (float(a["strength"]) - v) / math.sqrt(sig * sig + sd * sd)
            row.update({"fitted": float(a["strength"]), "interval": [lo, hi], "fitted_sd": sd, "z": z,
                        "disagrees": bool(abs(z) > 2.0)})
        out[eff] = row
    return out


def _independent_lines(report: dict) -> list[str]:
    """The independent strength estimates beside the fitted intervals, disagreements flagged."""
    ind = report.get("independent_estimates") or {}
    if not ind:
        return []
    L = ["", "## Independent estimates of the strengths", "",
         "| effect | independent (value ± σ) | fitted [95 % interval] | z | |", "|---|---|---|---|---|"]
    for eff, r in ind.items():
        if r["fitted"] is None:
            L.append(f"| {eff} | {r['value']:.4g} ± {r['sigma']:.3g} | not named | – | |")
        else:
            flag = "**disagrees (> 2σ)**" if r["disagrees"] else "agrees"
            L.append(f"| {eff} | {r['value']:.4g} ± {r['sigma']:.3g} | {r['fitted']:.4g} {_f(r['interval'])} | "
                     f"{r['z']:.2f} | {flag} |")
    L += ["", "z = (fitted − independent)/√(σ² + sd²), sd the fitted interval's half-width / 1.96; a disagreement "
              "says the data and the independent measurement do not describe the same strength (a model or "
              "measurement error on one side), not which one is right."]
    return L


def _source_hashes() -> dict:
    from solver.codehash import directory_hash
    from sweep.campaign.store import current_code_hash

    return {"solver": current_code_hash(), "workflow": directory_hash(Path(__file__).parent)}


# taken when the workflow is imported: the files this process runs, even if they change on disk later
_SOURCE = _source_hashes()


def code_provenance() -> dict:
    """The source that made a report: the solver's (the forward runs' cache key) and the workflow's
    (``sweep/discrepancy/*.py``), each as :func:`solver.codehash.directory_hash` of the files as imported."""
    return dict(_SOURCE)

# what a rough profile means for the named strength's interval (report.md verdict line, CLI)
ROUGH_NOTE = "rough profile: a lower bound on the uncertainty"


def _table(d: dict, cols) -> list[str]:
    out = ["| " + " | ".join(["key"] + list(cols)) + " |", "|" + "---|" * (len(cols) + 1)]
    for k, v in d.items():
        out.append("| " + " | ".join([str(k)] + [_f(v.get(c)) for c in cols]) + " |")
    return out


def _verdict_lines(report: dict) -> list[str]:
    """The title and the verdict line."""
    L = ["# Discrepancy report", "",
         f"**Verdict: {report['verdict']}**" + (f" — named effect `{report['named_effect']}`, strength "
                                                f"{report['strength']:.4g} (95 % interval {_f(report['strength_interval'])}"
                                                f"{', scaled by √C' if report.get('strength_scaling') == 'sqrt_cement' else ''}"
                                                f"{'; ' + ROUGH_NOTE if report.get('strength_interval_rough') else ''}"
                                                f"{interval_caveats(report)})"
                                                if report["named_effect"] else ""), ""]
    return L


def interval_caveats(report: dict) -> str:
    """What the named strength's profile says of its interval's ends beyond their values: an end open at the
    strength's range (the data do not bound it there); an end the profile's refinement left off the threshold."""
    pr = (report.get("profiles") or {}).get(report.get("named_effect")) or {}
    return ("".join(f"; open at the {s} end (the range's)" for s in ("lower", "upper") if pr.get(f"{s}_open"))
            + "".join(f"; {s} end unconverged" for s in (pr.get("unconverged") or {})))


def _caveat_lines(report: dict) -> list[str]:
    """Partial explanation, tie, not identifiable, refresh convergence: what qualifies the verdict."""
    L = []
    for stage, failed in (report.get("failed_points") or {}).items():
        L += [f"No verdict: at the {stage} the forward runs did not reach every observation time ("
              + "; ".join(f"condition `{cid}`: {v['failed']} of {v['points']} points"
                          + (", no successful run" if v["failed"] == v["points"] else "") for cid, v in failed.items())
              + "). A verdict needs runs that reach the observation times: check these conditions' parameters "
              "(units, ranges) and the run options (t_end, max_wall_time).", ""]
    pe = report.get("partial_explanation")
    if pe:
        eff = ", ".join(f"`{a['effect']}` {a['strength']:.4g} (95 % interval {_f(a['strength_interval'])})" for a in pe["effects"])
        L += [f"Partial explanation only: {eff} passed every acceptance test and cut the held-out gap from "
              f"{report['gap_before']['total']:.3g} to {pe['gap_after']['total']:.3g} RMS σ, but the model with it still "
              f"misses systematically (series: {[k for k, v in pe['localization_after']['series'].items() if v['systematic']]}), "
              f"so no effect is named: the cause may lie outside the catalogue.", ""]
    if report["tie"]:
        L += [f"Tie between {report['tie']}: the data cannot tell them apart; "
              + ("the measurements that would are listed below." if report.get("discriminating_measurements")
                 else "add a discriminating condition."), ""]
    for r in report.get("rivals") or []:
        L += [f"Rival of {r['candidate']}: the baseline refitted with {r['alternative']} freed ([[alternative]]) "
              f"reaches {r['alternative']} = {r['value']:.4g}, BIC {r['delta_bic']:+.1f} against the candidate's model "
              f"(held-out gap {r['gap']['total']:.3g} RMS σ): "
              + ("it ties, so the effect cannot be told from a change of that parameter." if r["ties"] else
                 "it does not tie."), ""]
    if report["not_identifiable"]:
        L += [f"Not identifiable with these conditions (signature inside the calibrated baseline's reach or null, "
              f"or a profile interval reaching off): {report['not_identifiable']}", ""]
    against = [c for c in report["candidates"] if c["identifiable"] and c.get("amplitude") is not None
               and c["amplitude"] <= 0]
    if against:
        L += ["Identifiable, but the data ask for less than off (the screen's linearized amplitude, in units of the "
              "probe strength, is not positive), so not refitted: "
              + ", ".join(f"{c['effect']} ({c['amplitude']:.3g})" for c in against) + ".", ""]
    for c in report["candidates"]:
        if c.get("confounded_with"):
            L += [f"{c['effect']}: not identifiable against {c['confounded_with']} (held fixed but uncertain, "
                  f"[[alternative]]): only {c['alternative_ratio']:.3g} of its signature lies outside their and the "
                  f"calibrated parameters' directions; a change of {' or '.join(c['confounded_with'])} within its "
                  f"range would explain what it explains"
                  + ("; what would tell them apart is listed below." if c["effect"] in
                     (report.get("confounded_measurements") or {}) else "."), ""]
    for a in report.get("accepted") or []:
        if "refresh_converged" in a:
            traj = " → ".join(f"{v:.4g}" for v in a["refresh_trajectory"])
            L += [f"{a['effect']}: discretization correction re-estimated at the fit, strength {traj}: "
                  + ("converged." if a["refresh_converged"] else
                     "NOT converged (the corrected model is not yet the fine model at the fitted values): the strength "
                     "and its interval are not reliable; raise [noise] disc_refresh."), ""]
    for u in report.get("profile_not_identifiable") or []:
        n = u["nearest_off"]
        L += [f"{u['effect']}: improved the joint fit, but its profile-likelihood interval {_f(u['interval'])} reaches "
              f"off: at strength {_f(n['strength'])} the calibrated parameters ({_f(n['others'])}) refit to within "
              f"Δχ² = {_f(n['delta_chi2'])}.  A discriminating condition (another injection rate, a later time) "
              f"is needed to tell it from them"
              + (": the measurements that would are listed below." if report.get("discriminating_measurements")
                 else "."), ""]
    return L


def _noise_lines(report: dict) -> list[str]:
    """The discretization correction, realization spread and model jitter used."""
    L = []
    if report.get("discretization_error_rms") is not None:
        def units(d):
            return ", ".join(f"{o} {v:.3g} {UNITS.get(o, '')}" for o, v in (d or {}).items())

        L += [f"Discretization correction at the initial baseline (RMS of fine − coarse): "
              f"{units(report['discretization_error_rms'])}; spread over the "
              f"{report.get('discretization_realizations', 1)} fine mesh realization(s) (RMS of their sample std): "
              f"{units(report.get('realization_spread_rms'))}, "
              + (f"a covariance correlated in time (correlation time per observable, s: "
                 f"{_f(report.get('realization_correlation_time'))}; residuals whitened)."
                 if report.get("realization_covariance") == "correlated" else "added in quadrature to σ."), ""]
    for where, mj in (report.get("model_jitter") or {}).items():
        if mj:
            L += [f"Coarse model's jitter in its parameters ({where}, estimated at {_f(mj['at'])} from "
                  f"{len(next(iter(mj['steps'].values())))} runs per parameter of {sorted(mj['steps'])}; "
                  f"sweep/discrepancy/jitter.py): RMS {_f(mj['rms'])} (kPa, mm), correlation time "
                  f"{_f(mj['correlation_time'])} s; added to the covariance the residuals are whitened with.", ""]
    return L


def _candidate_lines(report: dict) -> list[str]:
    """Where the runs went, the calibrated baseline and the first round's candidates."""
    L = []
    by_stage = "; ".join(f"{k} {v['coarse']}" + (f" + {v['fine']} fine" if v.get("fine") else "")
                         for k, v in (report.get("forward_runs_by_stage") or {}).items() if v["coarse"] or v.get("fine"))
    L += [f"Training conditions: {report['train']}; held out: {report['holdout']}; forward runs: {report['forward_runs']}"
          + (f" (by stage: {by_stage})" if by_stage else "") + ".", "",
          "## Calibrated baseline", "", _f(report["calibrated_baseline"]), "",
          *[f"**{k} is at its {b} bound**: the data ask for a value outside its [[calibrate]] range." for k, b in
            (report.get("calibrated_at_bound") or {}).items()], "",
          "## Candidates (first round)", "",
          "| effect | score | ΔBIC | identifiable | tied with | strength | interval | explained | passed |",
          "|---|---|---|---|---|---|---|---|---|"]
    for c in report["candidates"]:
        L.append(f"| {c['effect']} | {_f(c['score'])} | {_f(c['delta_bic'])} | {c['identifiable']} | {c['tied_with']} | "
                 f"{_f(c['strength'])} | {_f(c['strength_interval'])} | {_f(c['explained_fraction'])} | {c['passed']} |")
    common = {c["effect"]: c.get("bic_common") for c in report["candidates"] if c.get("passed") and c.get("bic_common") is not None}
    if len(common) > 1:
        L += ["", "Passing candidates compared under common series weights (the per-series minimum of theirs; each "
                  "ΔBIC above uses its own): BIC " + ", ".join(f"{k} {v:.4g}" for k, v in common.items())
              + "; a tie when they differ by less than tie_bic."]
    return L


def _profile_flags(pr: dict) -> list[str]:
    """A profile's smoothing, open or unconverged ends, roughness and monotony, as report lines."""
    L = []
    qd = pr.get("quadratic")
    if pr.get("smoothing") == "quadratic":
        if qd is None:
            L += ["", "Smoothing (`[profile] smoothing = \"quadratic\"`) not applied: fewer than 5 points in the "
                      "quadratic region; the interval is the raw crossings'."]
        elif qd.get("unbounded"):
            L += ["", f"Smoothed profile (quadratic, MCAP): no minimum inside the points, so none of them is excluded: "
                      f"interval {_f([pr['lower'], pr['upper']])} (their span; raw crossings {_f(pr['raw'])})."]
        else:
            L += ["", f"Smoothed profile (quadratic through {qd['n']} points with the Monte-Carlo-adjusted cutoff, MCAP, "
                      f"Ionides et al. 2017): centre {qd['center']:.4g}, statistical se {qd['se_stat']:.3g}, "
                      f"Monte-Carlo se {qd['se_mc']:.3g} (points' scatter about the quadratic {qd['residual_sd']:.3g} "
                      f"in Δχ²); interval {_f([pr['lower'], pr['upper']])} (raw crossings {_f(pr['raw'])})."]
    opened = [s for s in ("lower", "upper") if pr.get(f"{s}_open")]
    if opened:
        L += ["", f"**Open interval**: Δχ² stays below the threshold out to the strength's range at the "
                  f"{' and '.join(opened)} end, so that end is the range's ({', '.join(f'{pr[s]:.4g}' for s in opened)}): the "
                  "data do not bound the strength there."]
    for side, u in (pr.get("unconverged") or {}).items():
        L += ["", _unconverged_line(side, u, pr)]
    if pr.get("rough"):
        L += ["", f"**Rough profile**: walking away from the fit, Δχ² falls by up to {pr['roughness']:.3g} "
                  f"(more than `[profile] rough_tol` of the threshold {pr['threshold']:.3g}).  A true profile rises "
                  "monotonically; this one jitters with the strength (the coarse model's outputs, typically the "
                  "front radius, are not smooth in it), so the bounds are set by that jitter: read the interval "
                  "as a lower bound on the uncertainty."]
    if pr.get("non_monotone"):
        L += ["", f"**Non-monotone profile**: walking away from its lowest point, Δχ² falls by up to "
                  f"{pr['monotone_fall']:.3g} (more than {100 * stats.MONOTONE_TOL:.0f} % of the threshold): a second "
                  "minimum or a likelihood that is not a smooth function of the strength.  The interval is the "
                  "crossings' as evaluated; it is not smoothed or re-centred away."]
    return L + _pieces_outside_lines(pr)


def _pieces_outside_lines(pr: dict) -> list[str]:
    """The earlier passes' points under the threshold outside the interval (:func:`.recentre.pieces_outside`),
    as report lines (none when there are none)."""
    if not pr.get("pieces_outside"):
        return []
    pts = ", ".join(f"{q['delta_chi2']:.3g} at {q['value']:.4g}" for q in pr["pieces_outside"])
    vals = [q["value"] for q in pr["pieces_outside"]] + [pr["lower"], pr["upper"]]
    return ["", f"**A piece outside the interval**: under the same correction function an earlier pass put Δχ² "
                f"below the threshold outside [{pr['lower']:.4g}, {pr['upper']:.4g}] (re-referenced to this pass's "
                f"minimum: {pts}).  The last pass stops walking at its first crossings, so the confidence set is "
                f"not one interval; its hull is [{min(vals):.4g}, {max(vals):.4g}]."]


def _correction_model_lines(cm: dict | None) -> list[str]:
    """The profile's modelled discretization correction (``[profile] correction = "linear"`` or ``"piecewise"``), as
    report lines."""
    if not cm:
        return []
    if cm.get("model") == "piecewise":
        return ["", f"Discretization correction along the profile: piecewise linear in the strength (`[profile] "
                    f"correction = \"piecewise\"`), through the fine realizations' correction at {_f(cm['anchors'])} "
                    f"({cm['added_anchors']} of them added where the profile went beyond the others); the same function "
                    "for every point and re-centring (common random numbers).  Its change between the outer anchors, "
                    "RMS: " + ", ".join(f"{o} {v:.3g}" for o, v in (cm.get("change_over_anchors_rms") or {}).items())
                    + "."]
    L = []
    follows = cm.get("follows")
    L += ["", f"Discretization correction along the profile: linear in the strength (`[profile] correction = "
              f"\"linear\"`), from the fine realizations at {_f(cm['anchors'])}; the same function for every point "
              f"and re-centring (common random numbers).  "
              + (f"Also linear in {', '.join(n for n in follows if not n.startswith('effect:'))} "
                 "(`correction_follows = \"all\"`, anchors "
                 + "; ".join(f"{n} {_f(v)}" for n, v in cm["parameter_anchors"].items() if not n.startswith("effect:"))
                 + "), evaluated at each refit's own parameters.  " if follows else "")
              + "Its change over the anchors, RMS: "
              + ", ".join(f"{o} {v:.3g}" for o, v in (cm.get("change_over_anchors_rms") or {}).items())
              + f"; the line's residual RMS {cm['line_residual_rms']:.3g}."
              + (f"  The anchors after the first ran {cm['slope_realizations']} of the {cm['realizations']} "
                 "realizations, the first's mean carried to them by those realizations' change "
                 "(`correction_slope_realizations`)." if (cm.get("slope_realizations") or 0)
                 < (cm.get("realizations") or 0) else "")]
    return L


def _unconverged_line(side: str, u: dict, pr: dict) -> str:
    """The report's line on an interval end the profile did not confirm: either no refine evaluation came within
    ``refine_tol`` of the threshold (the bracket the crossing lies in), or the bracket closed but the profile
    evaluated at the interpolated end itself is off the threshold (``delta_chi2_at_end``)."""
    end = (pr.get("raw") or [pr["lower"], pr["upper"]])[side == "upper"]
    head = f"**Unconverged interval end**: the {side} end {end:.4g} is interpolated, not a crossing the profile confirmed"
    at_end = f"Δχ² at the end itself {u['delta_chi2_at_end']:.3g}" if "delta_chi2_at_end" in u else ""
    if "bracket" in u:
        return (f"{head} (the `[profile] refine` evaluations did not bring Δχ² within `refine_tol` of the threshold "
                f"{pr['threshold']:.3g}): the crossing lies in {_f(u['bracket'])}, Δχ² {_f(u['delta_chi2'])} there"
                + (f"; {at_end}" if at_end else "") + ".")
    return (f"{head}: its bracket closed within `refine_tol` of the threshold {pr['threshold']:.3g}, but {at_end} "
            "(the profile is not smooth between the bracket's ends).")


def _profile_lines(report: dict, figures: set[str] = frozenset()) -> list[str]:
    """Each named strength's profile likelihood, with its figure where ``figures`` (file names) holds it."""
    L = []
    for eff, pr in (report.get("profiles") or {}).items():
        L += ["", f"## Profile likelihood of `{eff}` (named model, training conditions)", "",
              f"95 % interval {_f([pr['lower'], pr['upper']])} where Δχ² < {pr['threshold']:.3g}; "
              f"the linearized (Wald) interval was {_f(pr['wald'])}.", "", "| strength | Δχ² |", "|---|---|"]
        L += [f"| {q['value']:.4g} | {q['delta_chi2']:.3g} |" for q in pr["points"]]
        L += _profile_flags(pr)
        L += _correction_model_lines(pr.get("correction_model"))
        if f"profile_{eff}.png" in figures:
            L += ["", f"![Profile likelihood of {eff}](profile_{eff}.png)"]
        L += _emulator_lines(pr.get("emulator"))
        for h in pr.get("recentred", []):
            L += ["", f"**Re-centred**: the profile found Δχ² = {h['min_delta_chi2']:.3g} at {h['at']:.4g} below the fit at "
                      f"{h['strength']:.4g} (the joint fit had stopped short of the minimum); refitted from there and the "
                      "profile evaluated again about the new fit (the points above are the last pass's)."]
    return L


def _emulator_lines(em: dict | None) -> list[str]:
    """How the profile's refits used the emulator (``[profile] emulator = "gp"``) and its real-run checks."""
    if not em:
        return []
    L = ["", f"Emulated profile (`[profile] emulator = \"gp\"`): the refits ran on a Gaussian-process emulator of "
             f"the coarse model from {em['design_points']} design points ({em['forward_runs']} forward runs, "
             f"{em['refinements']} added where a refit's emulator sd exceeded `emulator_tol`), its predictive "
             "covariance in the likelihood.  Interval ends checked with real runs"
             + ("" if em["confirmed"] else " (**not confirmed**: the last check still disagrees beyond the emulator's sd)")
             + ":", "", "| side | strength | Δχ² emulated | Δχ² real | deviation | emulator sd | agrees |",
         "|---|---|---|---|---|---|---|"]
    L += [f"| {c['side']} | {c['value']:.4g} | {c['delta_chi2_emulated']:.3g} | {c['delta_chi2_real']:.3g} | "
          f"{c['deviation']:.3g} | {c['emulator_sd']:.3g} | {'yes' if c['agrees'] else 'no'} |" for c in em["checks"]]
    return L


def _emulated_refit_lines(em: dict | None) -> list[str]:
    """The refits made on emulators (``[profile] emulate_refits``): each emulated optimum's checks with real
    runs and how far the real polish moved it (in the emulated optimum's stated error)."""
    if not em:
        return []
    L = ["", "## Emulated refits", "", "Each refit ran on a Gaussian-process emulator of the model (its predictive "
         "covariance in the likelihood), its optimum checked with a real run and polished with real least squares; "
         "the values reported are the polished ones.", "",
         "| stage | model | checks | confirmed | χ² emulated | χ² real | polish move / stated error |", "|---|---|---|---|---|---|---|"]
    L += [f"| {r['stage']} | {' + '.join(r['model'])} | {len(r['checks'])} | {'yes' if r['confirmed'] else 'no'} | "
          f"{r['chi2_emulated']:.4g} | {r['chi2_real']:.4g} | {r['polish_move_over_error']:.3g} |" for r in em["refits"]]
    return L


def _gap_and_localization_lines(report: dict) -> list[str]:
    """The held-out gap before/after and where the calibrated baseline misses."""
    L = []
    L += ["", "## Held-out gap (RMS standardized residual)", "", "| observable | before | after |", "|---|---|---|"]
    for k, v in report["gap_before"].items():
        L.append(f"| {k} | {v:.4g} | {report['gap_after'].get(k, float('nan')):.4g} |")
    lb = report["localization_before"]
    L += ["", "## Where the calibrated baseline misses (training conditions)", "",
          f"Residuals systematic: {lb['systematic']}; regime misclassifications: {lb['regime_misclassified']}", ""]
    L += _table(lb["per_observable"], ["rms", "mean", "n"]) + [""]
    L += _table(lb["per_phase"], ["rms", "mean", "n"]) + [""]
    cal = any("chi2_excess_z_raw" in v for v in lb["series"].values())
    L += _table(lb["series"], ["n", "rho1", "chi2_excess_z", "mean_z", "systematic"]
                + (["chi2_excess_z_raw", "mean_z_raw"] if cal else [])) + [""]
    if cal:
        L += ["Series statistics calibrated for the estimated mesh-realization covariance (its scale has few "
              "degrees of freedom; `_raw`: taken as known).", ""]
    return L


_METHOD = ["## Method", "",
           "Calibration: scipy least_squares (TRF, bounds, robust loss) on whole training conditions. Evidence is "
           "counted with per-series weights n_eff/n from the lag-1 autocorrelation of the residuals. An effect is "
           "accepted when ΔBIC <= threshold, its likelihood ratio against 'off' (the baseline refit) exceeds 3.84 × the "
           "misfit scale (for the named effect, then also its profile-likelihood interval excludes 'off': the others "
           "refitted at fixed strength), it explains at "
           "least the required fraction of the excess χ², and it shrinks the held-out gap; candidates whose signature "
           "lies in the span of the calibrated parameters' sensitivities (and of the [[alternative]] parameters', "
           "held fixed but uncertain) are not identifiable; candidates with "
           "collinear projected signatures, or passing refits within the tie threshold in ΔBIC, are ties.", ""]


def write_report(report: dict, problem, fit_before, fit_after, out_dir, figures: bool = True) -> Path:
    """Write report.json, report.md and (optionally) the figures into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    from solver.output import atomic_write_text   # a killed run never leaves a truncated report

    atomic_write_text(out / "report.json", json.dumps(report, indent=1) + "\n")
    made, note = set(), None
    if figures:
        try:
            fig_curves(problem, fit_before, fit_after, out / "curves.png")
            made.add("curves.png")
            fig_residuals(problem, fit_before, out / "residuals_before.png", "baseline")
            made.add("residuals_before.png")
            if fit_after is not fit_before:
                fig_residuals(problem, fit_after, out / "residuals_after.png", "with named effect")
                made.add("residuals_after.png")
            made |= fig_profiles(report, out)
        except Exception as exc:  # figures are optional; the verdict is not
            note = f"figures failed: {type(exc).__name__}: {exc}"
    atomic_write_text(out / "report.md", render_markdown(report, made, note))
    return out


#: the figures write_report makes from the forward runs, in report.md's order (caption, file)
RUN_FIGURES = (("Measured vs calibrated baseline and final model", "curves.png"),
               ("Residual map, calibrated baseline", "residuals_before.png"),
               ("Residual map, final model", "residuals_after.png"))


def render_markdown(report: dict, figures: set[str], note: str | None = None) -> str:
    """report.md's text: the report's sections from ``report`` (report.json's content), linking the figure files
    in ``figures`` (file names in the report's folder), and ``note`` (why figures are missing) where given."""
    L = (_verdict_lines(report) + _caveat_lines(report) + _noise_lines(report) + _candidate_lines(report)
         + _discriminating_lines(report) + _confounded_lines(report) + _profile_lines(report, figures)
         + _independent_lines(report) + _emulated_refit_lines(report.get("emulated_refits"))
         + _gap_and_localization_lines(report))
    for cap, f in RUN_FIGURES:
        if f in figures:
            L += [f"![{cap}]({f})", ""]
    if note:
        L += [note, ""]
    return "\n".join(L + _METHOD) + "\n"


def render_report(out_dir, figures: bool = False) -> Path:
    """Rewrite ``out_dir``/report.md from ``out_dir``/report.json, without any forward run, linking the figures whose
    files are in the folder; ``figures`` first redraws the profile figures from the report."""
    out = Path(out_dir)
    src = out / "report.json"
    if not src.is_file():
        raise ValueError(f"report folder {str(out)!r}: no report.json (a discrepancy run's --out folder holds one)")
    report = json.loads(src.read_text())
    if figures:
        fig_profiles(report, out)
    from solver.output import atomic_write_text

    atomic_write_text(out / "report.md", render_markdown(report, {p.name for p in out.glob("*.png")}))
    return out / "report.md"
