"""``dchfrac discrepancy init``: a commented starting SPEC (TOML) written from a measured-data folder.

The SPEC lists the folder's conditions and observables, makes every catalogue effect (solver.effects.EFFECTS)
a candidate switched off in the baseline, calibrates the stiffness E and the permeability scale k̄ (unless the
conditions set them), holds out the last condition, runs the solver on a coarse mesh up to the last
observation time, and spells out every workflow setting at its default with what it does
(:mod:`.options`).  It loads with :func:`.spec.load_spec` as written; the user edits it from there.
Units: mm, s, kPa.
"""
from __future__ import annotations

import math
from dataclasses import fields
from pathlib import Path

from solver.effects import EFFECTS
from solver.tomlio import toml_value as _toml

from .data import MeasuredData, load_measured
from .observables import REGISTRY
from .options import OPTION_TABLES

__all__ = ["starting_spec", "write_starting_spec", "DEFAULT_CALIBRATE"]

# the baseline parameters calibrated by default: name -> (lower, upper, scale); units those of solver.Parameters
DEFAULT_CALIBRATE = {"E": (150.0, 700.0, "log"), "kbar": (5e-4, 5e-3, "log")}


def _header(data: MeasuredData, folder: Path) -> list[str]:
    """What the folder holds: its conditions (their parameters) and observables (unit, points per condition)."""
    L = [f"# Starting SPEC for the discrepancy workflow, written by `dchfrac discrepancy init` from {folder}.",
         "# Units: mm, s, kPa.  Edit, then: dchfrac discrepancy run --measured DIR --model THIS_FILE --out OUT",
         "#", "# Conditions (conditions.csv):"]
    for cid in data.ids:
        L.append(f"#   {cid}: {data.condition_params(cid) or 'the model defaults'}")
    L.append("# Observables (observations.csv):")
    for name in dict.fromkeys(data.curves.observable):
        n = {cid: int(((data.curves.observable == name) & (data.curves.condition == cid)).sum()) for cid in data.ids}
        L.append(f"#   {name} ({REGISTRY[name].unit}): {REGISTRY[name].doc}; points per condition {n}")
    if data.regimes:
        seen = {cid: f"{label} at {t:g} s" for cid, (t, label) in data.regimes.items()}
        L.append(f"#   regime (label): {seen}")
    return L + [""]


def _model_tables(data: MeasuredData) -> list[str]:
    """[baseline], [[calibrate]], a commented [[alternative]], [candidates], [holdout], [options] and a
    commented [discretization]."""
    names = list(EFFECTS)
    set_by_conditions = set(data.conditions.columns)
    L = ["[baseline]                       # solver.Parameters fields common to every condition (model defaults",
         "                                 # otherwise); the effects listed here are off in the baseline",
         f"effects_off = {_toml(names)}", ""]
    for name, (lo, hi, scale) in DEFAULT_CALIBRATE.items():
        if name in set_by_conditions:
            L.append(f"# {name} is set per condition in conditions.csv: not calibrated")
            continue
        L += ["[[calibrate]]                    # fitted on the training conditions (initial: the model default)",
              f"name = {_toml(name)}", f"lower = {lo!r}", f"upper = {hi!r}", f"scale = {_toml(scale)}", ""]
    L += ["# [[alternative]]                # optional: a baseline parameter held fixed but uncertain in [lower,",
          "# name = \"K_s\"                   # upper]; a candidate whose signature a change of it reproduces is",
          "# lower = 160.0                    # \"not identifiable against\" it and never named",
          "# upper = 16000.0",
          "# scale = \"log\"", ""]
    L += ["[candidates]                     # the effects the workflow may name (off in the baseline):"]
    for n in names:
        e = EFFECTS[n]
        L.append(f"#   {n}: strength {e.parameter} in [{e.off}, {e.upper}] {e.unit}, probe {e.probe}")
    L += [f"effects = {_toml(names)}",
          "# upper = { damage_viscosity = 300.0 }       # optional: a candidate's upper bound / probe strength",
          "# scaling = { damage_viscosity = \"sqrt_cement\" }   # optional: parameter = strength * sqrt(C)", ""]
    L += _holdout_lines(data)
    t_end = float(max(data.curves.time.max() if len(data.curves) else 0.0,
                      max((t for t, _ in data.regimes.values()), default=0.0)))
    t_end = math.ceil(t_end * 100.0) / 100.0
    L += ["[options]                        # solver.RunOptions of the workflow's runs: a coarse mesh keeps a run",
          "h = 4.0                          # to minutes; check it with [discretization]",
          f"t_end = {t_end!r}".ljust(33) + "# s: the last observation time",
          "dt_max = 0.02", "",
          "# [discretization]               # optional: finer check runs correcting the coarse model's mesh error",
          "# h = 3.0",
          "# dt_max = 0.01",
          "# mesh_seeds = [1, 2, 3]         # one fine run per mesh realization (distinct integers >= 0)", ""]
    return L


# Where a starting SPEC departs from the option defaults, and why.  The solver's runs cost seconds each, so the
# emulators pay for themselves (their cost and verdicts: results/discrepancy/COST.md); the library defaults stay
# off, since for a model that costs microseconds (the toy) the emulator's own fitting is what costs.
# The likelihood's own error terms (no fraction of the correction added to σ, the realization covariance's
# scale integrated over its k-run estimate) make the interval's coverage nominal rather than conservative
# (results/discrepancy/coverage/README.md); the library defaults keep the committed twins reproducible.
# The data are one realization for every condition, few realizations know the strength's variance to about
# k − 1 degrees of freedom, and the pooled lag-1 estimator makes τ short: the covariance blocks per observable,
# the F(1, k − 1) threshold and the mean-ratio estimator (results/discrepancy/shared_realization/README.md).
_SR = "results/discrepancy/shared_realization/README.md"
STARTING = {("profile", "emulator"): ("gp", "for solver runs (library default \"none\"):"),
            ("profile", "emulate_refits"): (True, "for solver runs (library default false):"),
            ("noise", "disc_error_fraction"): (0.0, "a calibrated interval (library default 0.5):"),
            ("profile", "likelihood"): ("marginal", "a calibrated interval (library default \"weighted\"):"),
            ("profile", "correction"): ("piecewise", "the correction follows the strength, never extrapolated: a "
                                                     "smooth profile that covered the held-out twin (results/"
                                                     "discrepancy/README.md, \"In words\"; library default "
                                                     "\"point\"):"),
            ("profile", "threshold"): ("f_realizations", f"covers at few realizations ({_SR}, \"Few realizations\"; "
                                                         "library default \"chi2\"):"),
            ("noise", "realization_blocks"): ("observable", f"the data one realization for every condition ({_SR}, "
                                                            "\"Toy\"; library default \"series\"):"),
            ("noise", "lag1"): ("mean_ratio", f"tau not short ({_SR}, \"The lag-1 estimator\"; library default "
                                              "\"pooled\"):")}


def _option_tables() -> list[str]:
    """[fit], [acceptance], [noise], [profile] at their defaults (or the STARTING values), each key with what
    it does."""
    L = []
    for table, cls in OPTION_TABLES.items():
        L.append(f"[{table}]".ljust(33) + "# " + cls.__doc__.splitlines()[0])
        for f in fields(cls):
            value, why = STARTING.get((table, f.name), (f.default, ""))
            L.append(f"{f.name} = {_toml(value)}".ljust(32) + f" # {why + ' ' if why else ''}{f.metadata['doc']}")
        L.append("")
    return L


def held_out_observables(data: MeasuredData) -> list[str]:
    """With a single condition, the observables held out of the fit: every observable but the injection
    pressure, which the fit sees (empty when the data hold nothing else)."""
    observed = set(data.curves["observable"]) | ({"regime"} if data.regimes else set())
    return sorted(observed - {"p_inj"}) if "p_inj" in observed else []


def _holdout_lines(data: MeasuredData) -> list[str]:
    """[holdout]: the last condition with two or more; with one, its observables other than p_inj."""
    if len(data.ids) < 2 and held_out_observables(data):
        return ["[holdout]                        # one condition: the fit sees p_inj, these observables are held out",
                f"observables = {_toml(held_out_observables(data))}", ""]
    return ["[holdout]                        # whole conditions the fit never sees: the held-out gap is measured there",
            f"ids = {_toml(data.ids[-1:])}", ""]


def too_few_conditions(data: MeasuredData, folder) -> str | None:
    """Why ``dchfrac discrepancy run`` cannot use ``data`` (one condition whose only observable is p_inj: nothing
    to hold out), None when it can."""
    if len(data.ids) < 2 and not held_out_observables(data):
        return (f"{folder}: the workflow needs at least 2 conditions (one is held out), or one condition with an "
                f"observable besides p_inj to hold out; conditions.csv has {len(data.ids)}: add one before "
                "`dchfrac discrepancy run`")
    return None


def starting_spec(data: MeasuredData, folder) -> str:
    """The commented starting SPEC (TOML text) for ``data`` (read from ``folder``); with fewer than 2
    conditions its header says that ``run`` needs another one."""
    note = too_few_conditions(data, folder)
    head = _header(data, Path(folder)) + ([f"# NOTE: {note}.", ""] if note else [])
    return "\n".join(head + _model_tables(data) + _option_tables())


def write_starting_spec(measured, out, force: bool = False, strict: bool = False) -> tuple[Path, list[str]]:
    """Validate the measured-data folder ``measured``, write its starting SPEC to ``out`` (atomically; an
    existing file only with ``force``) and check that it loads and that the data pass the checks
    ``discrepancy run`` makes with it (:func:`.checks.check_data_against_model`: the same validator).  Returns
    the path and the warnings (implausible inputs, e.g. observation times in ms making t_end implausible);
    with ``strict`` a warning is refused."""
    from solver.output import atomic_write_text

    from .checks import check_data_against_model, spec_models
    from .spec import spec_from_dict

    out = Path(out)
    if out.exists() and not force:
        raise ValueError(f"{out} exists (use --force to overwrite it)")
    if out.is_dir():
        raise ValueError(f"--out {str(out)!r} is a folder (allowed: a SPEC file name, e.g. spec.toml)")
    data = load_measured(measured)
    few = too_few_conditions(data, measured)
    if few:
        raise ValueError(few)
    text = starting_spec(data, measured)
    import tomllib

    spec = spec_from_dict(tomllib.loads(text))          # what is written loads as written
    from .heldout import heldout_data

    warnings = check_data_against_model(heldout_data(data, spec), spec, spec_models(spec), strict=strict)
    out.parent.mkdir(parents=True, exist_ok=True)     # its writability was checked before any work
    atomic_write_text(out, text)
    return out, warnings
