"""The workflow's models on the paper's reference experiment (Sec. 3.5), against its reported figures.

A twin campaign may end with a ``[reference_check]`` table::

    [reference_check]               # Sec. 3.5: C = 1.2 %, eta_o = 0.29 kPa s, kbar = 0.0015 mm², w_i = 50 mm/s
    conditions = { cement = 1.2, eta_o = 0.29, eta_w = 1e-6, kbar = 0.0015, w_i = 50.0 }
    h = 2.0                         # mm
    t_end = 2.0                     # s, the time of the paper's comparison
    dt_max = 0.02                   # s (optional)

After the workflow, three models are run to ``t_end`` at those conditions: the data-generating model
("truth"), the calibrated baseline ("baseline_fit": without the effects the workflow was not told) and the
model the workflow ends with ("named_fit", or "partial_fit" when the accepted effects are only a partial
explanation).  Each run is compared with ``paper_reported.toml [reference_experiment]`` by
:func:`sweep.studies.reference.reference_report` (the same measures as the reference campaign), and the gap to the
paper's figures before (baseline) and after (named) is tabulated.  Units: mm, s, kPa.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["ReferenceCheck", "load_reference_check", "reference_models", "run_reference_check", "GAP_QUANTITIES"]

# rows of sweep.studies.reference.reference_report compared before/after (the paper figure, model value)
GAP_QUANTITIES = ("peak injection pressure (kPa)", "front radius at 2 s, main branches (mm)",
                  "crack length beyond r_i (mm)")


@dataclass(frozen=True)
class ReferenceCheck:
    """conditions : solver.Parameters overrides of the reference experiment; h : mesh size, mm;
    t_end : end time, s; dt_max : largest time step, s (None: the solver's default)."""
    conditions: dict = field(default_factory=dict)
    h: float = 2.0
    t_end: float = 2.0
    dt_max: float | None = None

    def options(self):
        from solver import RunOptions

        d = {"h": self.h, "t_end": self.t_end}
        if self.dt_max is not None:
            d["dt_max"] = self.dt_max
        return RunOptions.from_dict(d)


def load_reference_check(table: dict) -> ReferenceCheck:
    """Validate a ``[reference_check]`` table (errors name the key, its value and the allowed range)."""
    from solver import Parameters

    unknown = set(table) - {"conditions", "h", "t_end", "dt_max"}
    if unknown:
        raise ValueError(f"[reference_check]: unknown key(s) {sorted(unknown)}; allowed: conditions, h, t_end, dt_max")
    cond = table.get("conditions", {})
    if not isinstance(cond, dict):
        raise ValueError(f"[reference_check] conditions={cond!r}: must be a table of solver.Parameters fields")
    Parameters.from_dict(cond)          # names and ranges checked by the solver's own validation
    for key, default in (("h", 2.0), ("t_end", 2.0), ("dt_max", None)):
        v = table.get(key, default)
        if v is not None and not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise ValueError(f"[reference_check] {key}={v!r}: must be a finite number > 0")
    chk = ReferenceCheck(dict(cond), float(table.get("h", 2.0)), float(table.get("t_end", 2.0)),
                         None if table.get("dt_max") is None else float(table["dt_max"]))
    chk.options()                       # RunOptions validation before any run starts
    return chk


def reference_models(spec, rep: dict, truth_overrides: dict, conditions: dict) -> dict:
    """{label: solver.Parameters overrides} of the models to compare at the reference conditions.

    truth_overrides : the data-generating model's overrides (baseline with the hidden effects on; a
    parameter following its law of C is absent); rep : the workflow's report (its calibrated baseline and
    final values)."""
    from .problem import values_to_overrides

    base = spec.baseline_overrides()
    out = {"truth": {**truth_overrides, **conditions},
           "baseline_fit": values_to_overrides(spec, base, conditions, rep["calibrated_baseline"])}
    if rep.get("verdict") == "named":
        out["named_fit"] = values_to_overrides(spec, base, conditions, rep["final_values"])
    elif rep.get("partial_explanation"):
        out["partial_fit"] = values_to_overrides(spec, base, conditions, rep["partial_explanation"]["final_values"])
    return out


def run_reference_check(check: ReferenceCheck, models: dict, out_dir, cache_dir, n_jobs: int = 1,
                        paper_path=None) -> dict:
    """Run ``models`` ({label: overrides}) at the reference experiment, compare each with the paper.

    Writes ``<out_dir>/<label>/`` (sweep.studies.reference.reference_report: comparison.md/json, figures) and
    ``<out_dir>/reference_check.{json,md}``; returns the JSON dict: per quantity the paper's figure and
    each model's value, and per model the gap |model − paper| of :data:`GAP_QUANTITIES`.
    """
    from sweep.studies.reference import paper_reported, reference_report
    from solver.output import atomic_write_text
    from sweep.campaign.store import write_json_atomic

    from .forward import SolverForward, finished

    paper_reported(paper_path)          # fail now, not after the runs, when the figures are missing
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    fw = SolverForward({}, check.options(), cache_dir, n_jobs=n_jobs)
    fw.predict_many([(o, {"p_inj": [check.t_end]}) for o in models.values()])
    rows, status = {}, {}
    for label, o in models.items():
        rd = fw.run_dir(o)
        summ = json.loads((rd / "summary.json").read_text()) if finished(rd) else {}
        status[label] = summ.get("status", "missing")
        if status[label] != "ok":
            continue
        table = reference_report(rd, out / label, paper_path)["table"]
        for _, r in table.iterrows():
            q = rows.setdefault(r["quantity"], {"paper": _num(r["paper"])})
            q[label] = _num(r["dchfrac"])
    gaps = {label: {q: (abs(rows[q][label] - rows[q]["paper"]) if q in rows and label in rows[q] else None)
                    for q in GAP_QUANTITIES} for label in models}
    res = {"conditions": check.conditions, "h": check.h, "t_end": check.t_end, "dt_max": check.dt_max,
           "status": status, "quantities": rows, "gap_to_paper": gaps, "models": models}
    write_json_atomic(out / "reference_check.json", res)
    atomic_write_text(out / "reference_check.md", _markdown(res, list(models)))
    return res


def _num(v):
    try:
        v = float(v)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def _markdown(res: dict, labels: list) -> str:
    fmt = lambda v: "n/a" if v is None else f"{v:.3g}"  # noqa: E731
    md = ["# Reference experiment (Sec. 3.5) with the workflow's models", "",
          f"Conditions {res['conditions']}, h = {res['h']} mm, t_end = {res['t_end']} s; "
          f"run status {res['status']}.  Measures as in results/reference (sweep/studies/reference.py).", "",
          "| quantity | paper | " + " | ".join(labels) + " |", "|---|---|" + "---|" * len(labels)]
    for q, v in res["quantities"].items():
        md.append(f"| {q} | {fmt(v.get('paper'))} | " + " | ".join(fmt(v.get(lb)) for lb in labels) + " |")
    md += ["", "Gap |model − paper|:", "", "| quantity | " + " | ".join(labels) + " |", "|---|" + "---|" * len(labels)]
    for q in GAP_QUANTITIES:
        md.append(f"| {q} | " + " | ".join(fmt(res["gap_to_paper"][lb][q]) for lb in labels) + " |")
    return "\n".join(md) + "\n"
