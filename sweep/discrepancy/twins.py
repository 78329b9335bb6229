"""Twin-experiment campaigns with the real solver (``campaigns/discrepancy_twins*.toml``).

Campaign TOML::

    [data]                      # data-generating run options: finer than the workflow's
    h = 5.0; dt_max = 0.01; t_end = 0.05
    times = [0.005, 0.05, 10]   # start, stop, count (s)
    observables = ["p_inj", "front_radius_mean"]
    noise = { p_inj = 2.0, front_radius_mean = 0.2 }
    regime = false              # true: the regime label at the last time is observed too (default false)
    [conditions]                # id -> parameter overrides
    w35 = { w_i = 35.0 }
    [spec]                      # the workflow SPEC (sweep.discrepancy.spec format)
    ...
    [[twin]]                    # one experiment per entry
    name = "damage_viscosity"; hidden = { beta = 60.0 }; expect = "damage_viscosity"
    # hidden = { beta = "law" } lets β follow 65.7 √C in the data; give the fitted strength's truth as
    # truth = 65.7 (with [spec.candidates] scaling = { damage_viscosity = "sqrt_cement" })
    # expect: an effect name, "no_missing_effect", "unexplained_discrepancy", "tie", "not_identifiable"
    # (the hidden effect listed as not identifiable, or in a tie: a confounded case) or "not_named" (any
    # verdict but a name: a hidden change the catalogue should not claim, e.g. of an [[alternative]] parameter)
    # conditions = ["w50", "w65"]: only these of [conditions] (default all; must contain the held-out ids);
    # observables = ["p_inj"]: only these of [data] observables are "measured" in this twin (default all)
    [reference_check]           # optional: the workflow's models on the paper's reference experiment
    conditions = { cement = 1.2, eta_o = 0.29, kbar = 0.0015, w_i = 50.0 }; h = 2.0; t_end = 2.0
    # (sweep.discrepancy.reference_check: truth, baseline fit and named fit against paper_reported.toml)
    # resolved_by = "damage_viscosity": the twin that adds the discriminating condition(s) to this confounded
    # one (the summary records whether it passed)

:func:`run_twins` writes ``<results>/<name>/{data/, report.json, report.md, figures}`` and
``<results>/summary.json`` (per twin: expected, verdict, named effect, hidden strength, interval,
gaps, pass/fail).  Forward runs are cached in ``cache`` (not committed).
"""
from __future__ import annotations

import json
import logging
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

log = logging.getLogger("dchfrac.discrepancy")

__all__ = ["load_twin_campaign", "apply_overrides", "run_twins", "twin_passed", "twin_conditions",
           "twin_observables"]


def load_twin_campaign(path) -> dict:
    from solver.tomlio import read_toml

    d = read_toml(path)
    for key in ("data", "conditions", "spec", "twin"):
        if key not in d:
            raise ValueError(f"twin campaign {path}: missing table [{key}]")
    return d


def apply_overrides(camp: dict, overrides: list[str]) -> dict:
    """A copy of the campaign with ``TABLE.KEY=VALUE`` settings replaced (``spec.profile.fine=false``).

    The value is a TOML literal (``false``, ``8``, ``"gp"``, ``[1, 2]``).  Only settings of tables the campaign
    already has may be set, and only existing keys or keys of its ``[spec]`` option tables, which
    :func:`sweep.discrepancy.spec.spec_from_dict` validates with the rest of the spec before any run.  The
    settings are recorded in every twin's ``summary.json`` entry (``overrides``).  Raises ValueError naming
    the setting and what is allowed."""
    import copy
    import tomllib

    from .options import OPTION_TABLES

    out = copy.deepcopy(camp)
    for item in overrides:
        path, sep, raw = item.partition("=")
        keys = path.strip().split(".")
        if not sep or len(keys) < 2 or not all(keys):
            raise ValueError(f"--set {item!r}: must be TABLE.KEY=VALUE, e.g. spec.profile.fine=false")
        try:
            value = tomllib.loads(f"v = {raw.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            raise ValueError(f"--set {item!r}: the value {raw.strip()!r} is not a TOML literal "
                             "(false, 8, 0.05, \"gp\", [1, 2])") from None
        node = out
        for k in keys[:-1]:
            if not isinstance(node.get(k), dict):
                tables = sorted(k2 for k2, v in node.items() if isinstance(v, dict))
                raise ValueError(f"--set {item!r}: no table {k!r} here; tables: {tables}")
            node = node[k]
        in_options = keys[0] == "spec" and len(keys) == 3 and keys[1] in OPTION_TABLES
        if keys[-1] not in node and not in_options:
            raise ValueError(f"--set {item!r}: no setting {keys[-1]!r} in [{'.'.join(keys[:-1])}]; "
                             f"settings: {sorted(node)}")
        node[keys[-1]] = value
    return out


def hidden_effects(twin: dict) -> list:
    """Catalogue effects whose strength parameter the twin's ``hidden`` sets."""
    from solver.effects import EFFECTS

    return [name for name, e in EFFECTS.items() if e.parameter in twin.get("hidden", {})]


def twin_passed(twin: dict, rep: dict) -> bool:
    """The twin's requirement: hidden effect named with its strength inside the interval and the held-out
    gap halved; the expected verdict for controls; for a confounded twin ("not_identifiable"), the hidden
    effect reported as not identifiable or tied, never named; for "not_named", any verdict but a name."""
    exp = twin["expect"]
    if exp in ("no_missing_effect", "unexplained_discrepancy", "tie"):
        return rep["verdict"] == exp
    if exp == "not_named":
        return rep["verdict"] != "named"
    if exp == "not_identifiable":
        hid = hidden_effects(twin)
        flagged = set(rep.get("not_identifiable") or []) | set(rep.get("tie") or [])
        return bool(hid) and rep["verdict"] != "named" and all(h in flagged for h in hid)
    if rep["named_effect"] != exp:
        return False
    from solver.effects import get_effect

    param = get_effect(exp).parameter
    truth = twin["hidden"].get(param)
    if truth == "law":
        truth = twin.get("truth")
    lo, hi = rep["strength_interval"]
    inside = truth is None or lo <= truth <= hi
    return bool(inside and rep["gap_after"]["total"] <= 0.5 * rep["gap_before"]["total"])


def check_data_realization(camp: dict, spec) -> None:
    """The data's mesh realization must not be one of the workflow's fine check realizations.

    Otherwise the correction would contain the data's own mesh error, which a real experiment never
    offers (its "mesh" is unknown): the twin would test an easier problem than the one it stands for."""
    seeds = (spec.discretization or {}).get("mesh_seeds") or []
    data_seed = camp["data"].get("mesh_seed")
    if data_seed is not None and data_seed in seeds:
        raise ValueError(f"twin campaign: [data] mesh_seed={data_seed} is among [spec.discretization] "
                         f"mesh_seeds={list(seeds)}; the data's mesh realization must not be one the workflow checks")


def twin_conditions(camp: dict, twin: dict, spec) -> dict:
    """The twin's conditions ({id: overrides}): its ``conditions`` subset of the campaign's, or all of them."""
    allc = camp["conditions"]
    ids = twin.get("conditions")
    if ids is None:
        return dict(allc)
    unknown = [i for i in ids if i not in allc]
    if unknown or not ids:
        raise ValueError(f"twin {twin['name']!r}: conditions={ids!r} must be a non-empty list of ids among {list(allc)}")
    held = spec.holdout(list(ids))
    if not held or len(held) == len(ids):
        raise ValueError(f"twin {twin['name']!r}: conditions={ids!r} must contain held-out and training conditions "
                         f"(held out: {held})")
    return {i: allc[i] for i in ids}


def twin_observables(camp: dict, twin: dict) -> tuple:
    """The twin's measured observables: its ``observables`` subset of ``[data] observables``, or all of them."""
    from .observables import CURVES

    allo = tuple(camp["data"].get("observables", ("p_inj", "front_radius_mean")))
    unknown = [o for o in allo if o not in CURVES]
    if unknown:
        raise ValueError(f"twin campaign: [data] observables={list(allo)}: {unknown} not among the registered curve "
                         f"observables {list(CURVES)} (sweep/discrepancy/observables.py)")
    obs = twin.get("observables")
    if obs is None:
        return allo
    if not obs or any(o not in allo for o in obs) or len(set(obs)) != len(obs):
        raise ValueError(f"twin {twin['name']!r}: observables={obs!r} must be a non-empty list of distinct "
                         f"observables among [data] observables {list(allo)}")
    return tuple(obs)


VERDICTS = ("no_missing_effect", "unexplained_discrepancy", "tie", "not_identifiable", "not_named")
# [data] keys that describe the measurement, not the data-generating run's options
DATA_KEYS = ("times", "observables", "noise", "seed", "regime")


def validate_twin_campaign(camp: dict, spec) -> None:
    """Every twin of ``camp`` checked before any run (hours of solver time hang on a typo): names distinct;
    conditions (held-out and training ones) and observables (:func:`twin_conditions`, :func:`twin_observables`);
    ``hidden`` keys are Parameters fields; ``expect`` is a verdict or a candidate effect of the spec; a
    ``resolved_by`` names another twin with the same hidden effect, expecting a catalogue effect, whose
    conditions and observables contain the confounded twin's and add at least one.  Raises ValueError naming
    the twin, the key and the allowed values."""
    import dataclasses

    from solver import Parameters
    from solver.effects import EFFECTS

    check_data_realization(camp, spec)
    if not isinstance(camp["data"].get("regime", False), bool):
        raise ValueError(f"twin campaign: [data] regime={camp['data']['regime']!r} must be true or false "
                         "(the regime label observed at the last time)")
    fields = {f.name for f in dataclasses.fields(Parameters)}
    twins = {}
    for t in camp["twin"]:
        name = t.get("name")
        if not name or name in twins:
            raise ValueError(f"twin name {name!r}: each [[twin]] needs a distinct non-empty name")
        twins[name] = t
    for t in camp["twin"]:
        name = t["name"]
        twin_conditions(camp, t, spec)
        twin_observables(camp, t)
        bad = sorted(set(t.get("hidden", {})) - fields)
        if bad:
            raise ValueError(f"twin {name!r}: hidden={bad} are not solver.Parameters fields")
        exp = t.get("expect")
        if exp not in VERDICTS and exp not in EFFECTS:
            raise ValueError(f"twin {name!r}: expect={exp!r} must be one of {list(VERDICTS)} or an effect of "
                             f"{sorted(EFFECTS)}")
        if exp in EFFECTS and exp not in spec.candidates:
            raise ValueError(f"twin {name!r}: expect={exp!r} is not among the spec's candidates {list(spec.candidates)}")
        rb = t.get("resolved_by")
        if rb:
            r = twins.get(rb)
            if r is None or rb == name:
                raise ValueError(f"twin {name!r}: resolved_by={rb!r} must name another twin among {sorted(twins)}")
            if r.get("hidden") != t.get("hidden") or r.get("expect") not in EFFECTS:
                raise ValueError(f"twin {name!r}: resolved_by={rb!r} must hide the same effect ({t.get('hidden')}) "
                                 f"and expect a catalogue effect (it has hidden={r.get('hidden')}, expect={r.get('expect')!r})")
            c0, o0 = set(twin_conditions(camp, t, spec)), set(twin_observables(camp, t))
            c1, o1 = set(twin_conditions(camp, r, spec)), set(twin_observables(camp, r))
            if not (c0 <= c1 and o0 <= o1) or (c0 == c1 and o0 == o1):
                raise ValueError(f"twin {name!r}: resolved_by={rb!r} must keep its conditions {sorted(c0)} and "
                                 f"observables {sorted(o0)} and add to them (it has {sorted(c1)}, {sorted(o1)})")


def _write_summary_entry(path: Path, name: str, entry: dict) -> None:
    """Merge one twin's entry into ``summary.json`` under an exclusive lock, written atomically: several twin
    processes may share a results folder, and a killed one must never leave a truncated summary."""
    import fcntl

    from solver.output import atomic_write_text

    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path.with_suffix(".lock"), "w") as lk:
        fcntl.flock(lk, fcntl.LOCK_EX)
        summary = json.loads(path.read_text()) if path.is_file() else {}
        summary[name] = entry
        _link_resolutions(summary)
        atomic_write_text(path, json.dumps(summary, indent=1) + "\n")


def _link_resolutions(summary: dict) -> None:
    """Fill each confounded twin's ``resolved_by`` record from its resolving twin's entry, whichever of the
    two finished last (they may run as separate processes, in any order)."""
    for e in summary.values():
        rb = e.get("resolved_by")
        if isinstance(rb, dict) and rb.get("twin"):
            other = summary.get(rb["twin"], {})
            rb.update({k: other.get(k) for k in ("passed", "verdict", "conditions", "observables")})


@dataclass(frozen=True)
class _TwinSetup:
    """What every twin of a campaign shares: the campaign and its SPEC, the observation times (s), the data's
    and the workflow's run options, the output and cache folders, the parallel runs and the optional
    ``[reference_check]``."""
    camp: dict
    spec: object
    times: np.ndarray
    data_opts: object
    wf_opts: object
    results: Path
    cache: Path
    n_jobs: int
    ref: object = None


def run_twins(campaign, results, cache, only=None, n_jobs: int | None = None, overrides=()) -> dict:
    """Run the twin experiments of ``campaign`` (path or dict); returns the summary dict.

    n_jobs : parallel solver runs (default: the spec's ``[fit] n_jobs``).  overrides : ``TABLE.KEY=VALUE``
    settings (:func:`apply_overrides`), recorded in each entry.  Every twin is validated before any run
    starts; each twin's entry is merged into ``<results>/summary.json`` as soon as it ends.  A twin that fails
    (its data cannot be made, or the workflow raises) gets the entry ``verdict = "failed"`` with the reason,
    and the next twin runs.
    """
    if overrides:
        campaign = apply_overrides(campaign if isinstance(campaign, dict) else load_twin_campaign(campaign),
                                   list(overrides))
    setup = _prepare_campaign(campaign, results, cache, n_jobs)
    summary_path = setup.results / "summary.json"
    summary = json.loads(summary_path.read_text()) if summary_path.is_file() else {}
    setup = _check_before_runs(setup, only)
    for twin in setup.camp["twin"]:
        name = twin["name"]
        if only and name not in only:
            continue
        try:
            summary[name] = _run_one_twin(setup, twin)
        except Exception as e:  # noqa: BLE001 - one twin that cannot be made or run does not stop the others
            log.error("twin %s failed: %s: %s", name, type(e).__name__, e)
            summary[name] = {"hidden": twin.get("hidden", {}), "expect": twin["expect"], "verdict": "failed",
                             "passed": False, "reason": f"{type(e).__name__}: {e}"}
        if overrides:
            summary[name]["overrides"] = list(overrides)
        _write_summary_entry(summary_path, name, summary[name])
    return json.loads(summary_path.read_text()) if summary_path.is_file() else summary


def _prepare_campaign(campaign, results, cache, n_jobs) -> _TwinSetup:
    """The campaign (loaded when a path), its SPEC, observation times and run options (validated here)."""
    from solver import RunOptions

    from .spec import spec_from_dict

    camp = load_twin_campaign(campaign) if not isinstance(campaign, dict) else campaign
    spec = spec_from_dict(camp["spec"])
    n_jobs = spec.fit.n_jobs if n_jobs is None else int(n_jobs)
    dat = camp["data"]
    a, b, n = dat["times"]
    data_opts = RunOptions.from_dict({k: v for k, v in dat.items() if k not in DATA_KEYS})
    return _TwinSetup(camp, spec, np.linspace(float(a), float(b), int(n)), data_opts,
                      RunOptions.from_dict(spec.options), Path(results), Path(cache), n_jobs)


def _check_before_runs(setup: _TwinSetup, only) -> _TwinSetup:
    """The ``[reference_check]`` (and the paper's figures it compares with), every twin and ``--only``
    checked before any run starts; returns ``setup`` with the loaded reference check."""
    import dataclasses

    ref = None
    if "reference_check" in setup.camp:
        from sweep.paper import paper_reported

        from .reference_check import load_reference_check
        ref = load_reference_check(setup.camp["reference_check"])
        paper_reported()
    validate_twin_campaign(setup.camp, setup.spec)
    names = [t["name"] for t in setup.camp["twin"]]
    unknown = sorted(set(only or ()) - set(names))
    if unknown:
        raise ValueError(f"--only {unknown}: no such twin among {names}")
    return dataclasses.replace(setup, ref=ref)


def _run_one_twin(setup: _TwinSetup, twin: dict) -> dict:
    """One twin: its synthetic data, the workflow on them, the optional reference check; its summary entry."""
    from .data import load_measured
    from .forward import SolverForward, fine_forwards
    from .workflow import run_workflow

    t0 = time.time()
    name, spec, cache = twin["name"], setup.spec, setup.cache
    log.info("twin %s (hidden %s, expect %s)", name, twin.get("hidden", {}), twin["expect"])
    gen, truth, conds, folder = _make_twin_data(setup, twin)
    fwd = SolverForward(spec.baseline_overrides(), setup.wf_opts, cache / "workflow", n_jobs=setup.n_jobs)
    # one fine model per mesh realization ([spec.discretization] mesh_seeds): the data are one realization
    # (their own mesh_seed) the workflow cannot know; the cache key includes mesh_seed
    fine = fine_forwards(spec, cache / "workflow", setup.n_jobs)
    rep = run_workflow(load_measured(folder), spec, fwd, setup.results / name, fine_forward=fine)
    entry = _summary_entry(setup, twin, rep, conds, gen.n_runs, time.time() - t0)
    if setup.ref is not None:
        entry["reference_check"] = _reference_entry(setup, name, rep, truth)
    if twin.get("resolved_by"):
        entry["resolved_by"] = {"twin": twin["resolved_by"]}    # filled in by _link_resolutions
    return entry


def _make_twin_data(setup: _TwinSetup, twin: dict):
    """Write the twin's synthetic measured data (``<results>/<name>/data``) from the data-generating model.

    Returns (the data's forward model, the data-generating overrides, the twin's conditions, the data folder).  A hidden value
    "law" lets the parameter follow its law of C (β = 65.7 √C): it is left out of the overrides."""
    from .forward import SolverForward
    from .twin import make_twin

    camp, spec, dat = setup.camp, setup.spec, setup.camp["data"]
    hidden = dict(twin.get("hidden", {}))
    law = [k for k, v in hidden.items() if v == "law"]
    gen_base = {k: v for k, v in spec.baseline_overrides().items() if k not in law}
    hidden = {k: v for k, v in hidden.items() if k not in law}
    gen = SolverForward(gen_base, setup.data_opts, setup.cache / "data", n_jobs=setup.n_jobs)
    conds = twin_conditions(camp, twin, spec)
    folder = make_twin(setup.results / twin["name"] / "data", gen, conds, setup.times, hidden,
                       noise=dat.get("noise"), seed=int(dat.get("seed", 0)),
                       observables=twin_observables(camp, twin), regime=bool(dat.get("regime", False)))
    return gen, {**gen_base, **hidden}, conds, folder


def _summary_entry(setup: _TwinSetup, twin: dict, rep: dict, conds: dict, data_runs: int, wall_s: float) -> dict:
    """One twin's row of summary.json from its workflow report (verdict, strength, gaps, cost, pass/fail)."""
    return {"hidden": twin.get("hidden", {}), "expect": twin["expect"], "verdict": rep["verdict"],
            "named_effect": rep["named_effect"], "strength": rep["strength"],
            "strength_interval": rep["strength_interval"],
            "strength_interval_rough": rep.get("strength_interval_rough"), "tie": rep["tie"],
            "not_identifiable": rep["not_identifiable"],
            "gap_before": rep["gap_before"].get("total"), "gap_after": rep["gap_after"].get("total"),
            "passed": twin_passed(twin, rep), "wall_time_s": round(wall_s, 1),
            "forward_runs": rep["forward_runs"], "forward_runs_by_stage": rep.get("forward_runs_by_stage"),
            "data_runs": data_runs,
            "realization_spread_rms": rep["realization_spread_rms"],
            "realization_covariance": rep.get("realization_covariance"), "conditions": list(conds),
            "model_jitter_rms": {k: (v or {}).get("rms") for k, v in (rep.get("model_jitter") or {}).items()} or None,
            "strength_interval_raw": (rep["accepted"][0].get("strength_interval_raw")
                                      if rep["named_effect"] and rep.get("accepted") else None),
            "observables": list(twin_observables(setup.camp, twin)), "code": rep.get("code")}


def _reference_entry(setup: _TwinSetup, name: str, rep: dict, truth: dict) -> dict:
    """Run the workflow's models on the paper's reference experiment; their summary.json record."""
    from .reference_check import reference_models, run_reference_check

    ref = setup.ref
    rc = run_reference_check(ref, reference_models(setup.spec, rep, truth, ref.conditions),
                             setup.results / name / "reference_check", setup.cache / "reference", setup.n_jobs)
    return {"status": rc["status"], "gap_to_paper": rc["gap_to_paper"],
            "quantities": {q: rc["quantities"].get(q) for q in rc["gap_to_paper"]["truth"]}}


def main(argv=None) -> int:
    import argparse

    ap = argparse.ArgumentParser(description="run discrepancy twin experiments with the real solver")
    ap.add_argument("campaign")
    ap.add_argument("--results", required=True)
    ap.add_argument("--cache", required=True)
    ap.add_argument("--only", nargs="*")
    ap.add_argument("--jobs", type=int, default=None, help="parallel solver runs (default: the spec's [fit] n_jobs)")
    ap.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    ap.add_argument("--set", action="append", default=[], metavar="TABLE.KEY=VALUE", dest="overrides",
                    help="replace one campaign setting, a TOML literal (e.g. spec.profile.fine=false); repeatable")
    a = ap.parse_args(argv)
    from .cli import show_progress
    show_progress(a.quiet)
    s = run_twins(a.campaign, a.results, a.cache, a.only, a.jobs, a.overrides)
    print(json.dumps(s, indent=1))
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
