"""The named model of a discrepancy run as a parameter file a campaign's ``[base] model = ...`` takes.

``dchfrac discrepancy model --report OUT/report.json --model SPEC --out named_model.toml`` writes
the model the workflow names, condition-independent: the SPEC's baseline (its off effects at their off values),
each calibrated parameter at its final value and the named effect at its fitted strength, mapped to
solver.Parameters fields by :func:`.problem.values_to_overrides` (the mapping of the workflow's own forward
runs).  Parameters set per condition (the condition columns the report records, or those of ``--measured DIR``
for a report that does not, and an effect scaled by a condition column, e.g. β = c √C with C a column) are left
out and listed in the header.  A verdict that names nothing writes the calibrated baseline; a tie or an
inconclusive run is refused.  Units mm, s, kPa.
"""
from __future__ import annotations

import json
from pathlib import Path

from solver.effects import get_effect
from solver.params import Parameters, field_unit
from solver.tomlio import toml_value

from .problem import values_to_overrides
from .spec import DiscrepancySpec

__all__ = ["read_report", "named_model_parameters", "named_model_text", "write_named_model"]

#: verdicts whose report carries a model to write: the named one, or the calibrated baseline alone
_WRITABLE = ("named", "no_missing_effect", "unexplained_discrepancy")


def read_report(path) -> dict:
    """The report.json of a discrepancy run, with the fields this module reads checked: ValueError naming the
    path and what is missing or refused (a tie names its tied effects)."""
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"--report {str(p)!r} not found (a discrepancy run's OUT/report.json)")
    try:
        rep = json.loads(p.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"--report {str(p)!r} is not JSON: {exc}") from None
    missing = [k for k in ("verdict", "named_effect", "final_values") if not isinstance(rep, dict) or k not in rep]
    if missing:
        raise ValueError(f"--report {str(p)!r} lacks {missing}: not a report.json of dchfrac discrepancy run")
    v = rep["verdict"]
    if v == "tie":
        raise ValueError(f"--report {str(p)!r}: verdict 'tie' between {rep.get('tie')}: the data cannot tell them "
                         "apart, so no model is named (allowed: a report whose verdict is one of "
                         f"{list(_WRITABLE)})")
    if v not in _WRITABLE:
        raise ValueError(f"--report {str(p)!r}: verdict {v!r} carries no model (allowed: one of {list(_WRITABLE)})")
    return rep


def _check_values(values: dict, spec: DiscrepancySpec) -> None:
    """Every final value is a solver.Parameters field or 'effect:<name>' of a candidate of ``spec``."""
    fields = Parameters.__dataclass_fields__
    for k in values:
        if k.startswith("effect:"):
            get_effect(k[7:])
            if k[7:] not in spec.candidates:
                raise ValueError(f"report final_values {k!r}: not a candidate of the model SPEC "
                                 f"(allowed: {list(spec.candidates)}); is --model the SPEC of this report?")
        elif k not in fields:
            raise ValueError(f"report final_values {k!r} is not a solver.Parameters field (allowed: "
                             f"{sorted(fields)})")


def named_model_parameters(spec: DiscrepancySpec, values: dict, columns) -> tuple[dict, dict]:
    """(parameters, varying): the solver.Parameters overrides of the model with fitted ``values`` (calibrated
    parameters by name, effect strengths as 'effect:<name>') that no condition sets, and {name: why} of those
    left out: each condition column, and an effect's parameter scaled by a condition column ("sqrt_cement" with
    C a column: β = c √C per condition).  Units mm, s, kPa."""
    _check_values(values, spec)
    cols = set(columns)
    params = values_to_overrides(spec, spec.baseline_overrides(), {}, values)
    varying = {c: "a condition column (set per condition)" for c in sorted(cols)}
    for k, v in values.items():
        name = k[7:] if k.startswith("effect:") else None
        if name and spec.scaling.get(name, "none") == "sqrt_cement" and "cement" in cols:
            par = get_effect(name).parameter
            varying[par] = f"{par} = {v!r} * sqrt(cement), cement in % (effect {name}, scaling sqrt_cement)"
    return {k: v for k, v in params.items() if k not in varying}, varying


def _unit(name: str) -> str:
    """The declared unit of parameter ``name`` (solver/params.py): "-" dimensionless, "no unit" for labels and
    seeds."""
    return field_unit(name) or "no unit"


def _header(rep: dict, spec: DiscrepancySpec, report_path, spec_path, varying: dict) -> list[str]:
    """The comment lines saying where each value comes from (report, verdict, strength, code)."""
    L = ["# The model named by a discrepancy run (dchfrac discrepancy model); units mm, s, kPa.",
         f"# Report: {report_path}; model SPEC: {spec_path}; verdict: {rep['verdict']}."]
    if rep["verdict"] == "named":
        eff = get_effect(rep["named_effect"])
        iv = rep.get("strength_interval")
        L.append(f"# Named effect: {rep['named_effect']} ({eff.parameter}, {eff.unit}) at its fitted strength "
                 f"{rep['strength']!r}, 95 % interval {iv}" + (" (rough)" if rep.get("strength_interval_rough") else "")
                 + f", scaling {spec.scaling.get(rep['named_effect'], 'none')} (the SPEC's).")
    else:
        L.append("# No effect named: the calibrated baseline only (the SPEC's baseline, its off effects off, the "
                 "calibrated parameters at their final values).")
    code = rep.get("code") or {}
    L.append(f"# Code of the run: solver {code.get('solver', 'not recorded')}, workflow "
             f"{code.get('workflow', 'not recorded')}.")
    L.append("# Fitted (report final_values, calibrated parameters and effect strengths): "
             + ", ".join(f"{k} = {v!r}" for k, v in rep["final_values"].items()))
    off = [f"{e} ({get_effect(e).parameter} = {get_effect(e).off!r})" for e in spec.effects_off
           if "effect:" + e not in rep["final_values"]]
    L.append("# The rest: the SPEC's [baseline]; off there and not named, so off here: " + (", ".join(off) or "none")
             + " (a campaign may set them: a [base] key or a [derived] expression replaces the file's value).")
    L += ["# Left out, set per condition or per run:"] + [f"#   {k}: {why}" for k, why in varying.items()] \
        + (["#   (none)"] if not varying else [])
    return L


def named_model_text(rep: dict, spec: DiscrepancySpec, columns, report_path="report.json",
                     spec_path="SPEC") -> str:
    """The TOML text of the named model of report ``rep`` (:func:`read_report`) under ``spec``: a header, then
    one ``name = value  # unit`` line per parameter (floats written to round-trip exactly)."""
    params, varying = named_model_parameters(spec, dict(rep["final_values"]), columns)
    lines = _header(rep, spec, report_path, spec_path, varying)
    lines += [f"{k} = {toml_value(v)}  # {_unit(k)}" for k, v in sorted(params.items()) if v is not None]
    return "\n".join(lines) + "\n"


def _condition_columns(rep: dict, report, measured) -> list:
    """The condition columns: the measured-data folder's (``measured``), else those the report records."""
    from .data import load_measured

    if measured is not None:
        return list(load_measured(measured).conditions.columns)
    cols = rep.get("condition_columns")
    if not isinstance(cols, list):
        raise ValueError(f"--report {str(report)!r} does not record its condition columns (a report written before "
                         "they were recorded): give --measured DIR, the run's measured-data folder")
    return cols


def write_named_model(report, model, measured, out) -> tuple[Path, str]:
    """Read the report, the SPEC and the condition columns (of the measured-data folder ``measured``, or when
    None of the report), write the named model to ``out`` atomically; (path, verdict).  ValueError (one line)
    on bad input, before anything is written."""
    from solver.output import atomic_write_text

    from .spec import load_spec

    rep = read_report(report)
    spec = load_spec(model)
    columns = _condition_columns(rep, report, measured)
    text = named_model_text(rep, spec, columns, report_path=report, spec_path=model)
    atomic_write_text(out, text)
    return Path(out), rep["verdict"]
