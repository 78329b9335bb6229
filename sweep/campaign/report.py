"""A campaign's Markdown report (``<root>/<name>/report.md``): counts, code, regimes, failures, figures, runs.

    write_report("campaigns/examples/demo.toml")
"""
from __future__ import annotations

import math
import os
from pathlib import Path

from sweep.campaign.paths import DEFAULT_ROOT, results_root
from sweep.campaign.plan import _archived_text, as_spec, check_intact, check_not_emptier, plan_campaign, provenance_lines
from sweep.campaign.plot import plot_campaign
from sweep.campaign.store import ResultsStore, write_text_atomic
from sweep.campaign.table import build_table

__all__ = ["write_report"]


def write_report(spec, root=DEFAULT_ROOT, *, code_hash: str | None = None, plot: bool = True,
                 allow_damaged: bool = False) -> Path:
    """Markdown summary of a campaign (``<root>/<name>/report.md``): counts, the code that made the runs,
    regimes, failures with their reasons, the run table's main columns, and the figures (drawn first
    when ``plot``). DamagedRunsError names damaged runs unless ``allow_damaged`` (then listed)."""
    spec = as_spec(spec)
    root = results_root(spec, root)
    store = ResultsStore(root, spec.name)
    plan = plan_campaign(spec, root, code_hash=code_hash)
    check_intact(plan, allow_damaged)
    table = build_table(spec, root, plan=plan)
    check_not_emptier(store, table)
    figs = plot_campaign(spec, root, table=table) if plot else sorted(store.figures_dir.glob("*.png"))
    if not table.empty:   # the table and, with [replicates], its per-point table from the same rows
        from sweep.campaign.replicates import write_points

        store.write_table(table, swept=spec.axis_names)
        write_points(spec, table, store)
    L = [f"# Campaign `{spec.name}`", ""]
    if spec.description:
        L += [spec.description.strip(), ""]
    if spec.paper:
        L += [f"Paper: {spec.paper}", ""]
    L += [f"Spec: `{spec.source}`.", "", *provenance_lines(plan), "",
          f"- runs in the grid: {len(plan.points)}",
          f"- done: {len(plan.done)}", f"- failed: {len(plan.failed)}", f"- pending: {len(plan.pending)}"]
    if plan.archived or plan.unmatched_rows:
        L.append(f"- archived (rows of the committed table, run folders not here): {_archived_text(plan)}")
    if plan.damaged:
        L += [f"- damaged (left out): {len(plan.damaged)}", "", "```", plan.damage_text(), "```"]
    L.append("")
    if not table.empty and "wall_time_s" in table.columns:
        L += [f"Total wall time of the runs: {table['wall_time_s'].sum():.1f} s "
              f"(median {table['wall_time_s'].median():.1f} s per run).", ""]
    stored = plan.store.records()  # every run of the folder (a sampler's plan holds only its initial design)
    if stored:
        from sweep.campaign.accounting import campaign_throughput

        acc = campaign_throughput(stored).text()
        L += [f"{acc[0].upper()}{acc[1:]} (`sweep/campaign/accounting.py`).", ""]
    if not table.empty and table["regime"].notna().any():
        L += ["## Regimes", "", "| regime | runs |", "|---|---|"]
        for reg, n in table["regime"].fillna("(none)").value_counts().items():
            L.append(f"| {reg} | {n} |")
        L.append("")
    failed = [(k, plan.records[k].get("reason")) for _, k in plan.failed]
    failed += [(plan.archived_rows[k].get("key"), plan.archived_rows[k].get("reason")) for _, k in
               plan.archived_status("failed")]
    if failed:
        L += ["## Failures", "", "| key | reason |", "|---|---|"]
        for k, reason in failed:
            reason = str(reason).replace("|", "\\|").replace("\n", " ")
            L.append(f"| `{k}` | {reason} |")
        L.append("")
    L += _replicate_lines(spec, table)
    L += _separatrix_lines(spec, table)
    L += _figure_lines(figs, store.dir)
    if not table.empty:
        L += _run_table_lines(spec, table)
    L += [f"Table: `{os.path.relpath(store.table_csv, store.dir)}` (also `table.parquet`); the unit and meaning of "
          f"every column: `columns.csv` (`dchfrac campaign columns SPEC`); load both with "
          f"`sweep.load_campaign` / `sweep.load_timeseries`.", ""]
    write_text_atomic(store.report_md, "\n".join(L))
    return store.report_md


def _replicate_lines(spec, table) -> list[str]:
    """With ``[replicates]``: the points, their replicate counts and where the replicates disagree
    (sweep.campaign.replicates.point_table, the same table as ``points.csv``)."""
    from sweep.campaign.replicates import point_table, replicate_count

    if replicate_count(spec) == 1 or table.empty:
        return []
    pts = point_table(table, list(spec.axis_names))
    n = pts["n_ok"].astype(int)
    rep = n > 1
    counts = ", ".join(f"{c} with {k} run{'s' if k != 1 else ''}" for k, c in sorted(n.value_counts().items()))
    L = ["## Replicates", "", f"{len(pts)} points ({counts}; finished runs with a label).",
         f"The replicates' regimes disagree at {int(pts.loc[rep, 'mixed'].sum())} of the {int(rep.sum())} points "
         "with two or more"]
    if "p_fracturing" in pts.columns:
        p = pts["p_fracturing"]
        L[-1] += f"; their fracturing labels at {int((rep & (p > 0) & (p < 1)).sum())}"
    L[-1] += "."
    if "fracturing" in table.columns:
        ok = table[table["status"] == "ok"] if "status" in table.columns else table
        fr = ok["fracturing"].dropna().astype(bool)     # a finished run without a label (classification failed): out
        L.append(f"{100 * fr.mean():.0f} % of the {len(fr)} finished runs with a label fracture." if len(fr) else
                 "No finished run has a fracturing label.")
    return L + ["Per point: `points.csv` (label probabilities with Wilson 95 % intervals, the continuous measures' "
                "mean and spread).", ""]


def _separatrix_lines(spec, table) -> list[str]:
    """With a Ca*-C diagram: what the finished runs say about the separatrix Ca*_c = A exp(B C) (Sec. 3.6;
    :func:`sweep.regimes.probability.separatrix_summary`), replicates counted as runs."""
    if not any(g["kind"] == "ca_star_vs_cement" for g in spec.diagrams) or table.empty:
        return []
    need = ("cement", "Ca_star", "fracturing")
    ok = table[table["status"] == "ok"] if "status" in table.columns else table
    if any(c not in ok.columns for c in need):
        return []
    from sweep.regimes.diagrams import placed_rows
    from sweep.regimes.probability import separatrix_summary

    placed = placed_rows(ok, "cement", "Ca_star", "fracturing")   # the runs the diagram places: the fit's runs
    left = int((~placed).sum())
    ok = ok[placed]
    s = separatrix_summary(ok["cement"], ok["Ca_star"], ok["fracturing"].astype(bool))
    L = ["## The separatrix", "", f"{s['runs']} finished runs with a label, {s['fracturing']} fracturing"
         + (f" ({left} finished run(s) without a fracturing label or a positive Ca* left out)." if left else ".")]
    if s.get("p_value") is not None:
        L.append(f"Against a constant fracturing probability the penalized likelihood ratio is {s['lr']:.3g} "
                 f"(p = {s['p_value']:.2g}).")
    if s["reason"]:
        return L + [f"No separatrix: {s['reason']}.", ""]
    lo, hi = s["B_interval"]
    lvl = f"{100 * s['level']:g} %"
    return L + [f"Ca*_c = A exp(B C): A = {s['A']:.3g} [{s['A_interval'][0]:.3g}, {s['A_interval'][1]:.3g}], "
                f"B = {s['B']:.3g} [{lo:.3g}, {hi:.3g}] /% ({lvl} profile-likelihood intervals"
                + (", separable labels" if s["separable"] else "") + "); "
                + ("B > 0" if s["B_positive"] else "B > 0 is not established") + f" at {lvl}.",
                f"The simultaneous {lvl} band of Ca*_c: " + "; ".join(
                    f"{_band_text(b, h)} at C = {c:.3g} %" for c, b, h in
                    zip(s["band_C"], s["band_log10"], s["band_half_width_decades"])) + ".",
                ""]


def _band_text(log10_band: list, half: float) -> str:
    """A band's edges as powers of ten and its half-width in decades; an edge the labels do not bound is
    infinite (the profile never reaches its threshold on that side)."""
    lo, hi = (("10^" + format(v, ".3g")) if math.isfinite(v) else ("0" if v < 0 else "∞") for v in log10_band)
    open_sides = sum(not math.isfinite(v) for v in log10_band)
    width = f"±{half:.2g} decades" if math.isfinite(half) else ("unbounded on both sides" if open_sides == 2
                                                                 else "unbounded on one side")
    return f"[{lo}, {hi}] ({width})"



def _figure_lines(figs, folder: Path) -> list[str]:
    """The report's "Figures" section: each PNG inline, its vector copy linked beside it."""
    if not figs:
        return []
    L = ["## Figures", ""]
    pngs = {Path(f).with_suffix("") for f in figs if Path(f).suffix == ".png"}
    for f in figs:
        rel = os.path.relpath(f, folder)
        if Path(f).suffix == ".png":
            L += [f"![{Path(f).stem}]({rel})", ""]
        elif Path(f).with_suffix("") in pngs:
            L[-2] += f" ([{Path(f).suffix[1:]}]({rel}))"
        else:
            L += [f"[{Path(f).name}]({rel})", ""]
    return L


def _run_table_lines(spec, table) -> list[str]:
    """The report's "Runs" section: key, status, regime, swept values, the dimensionless numbers that were
    computed and the wall time; why N_f is empty when the spec gives no dp_cri."""
    cols = [c for c in ["key", "status", "regime", *spec.axis_names] if c in table.columns]
    num_cols = [c for c in table.columns if c.lower().replace("*", "_star") in
                ("ca_star", "n_f", "n_b", "nf", "nb") and c not in cols]
    empty = [c for c in num_cols if table[c].isna().all()]
    cols += [c for c in num_cols if c not in empty] + [c for c in ("wall_time_s",) if c in table.columns]
    L = ["## Runs", ""]
    if "N_f" in empty:
        L += ["N_f = dp_vis / dp_cri is not computed: the spec gives no critical pressure drop dp_cri (an "
              "`nf_vs_nb` diagram's `dp_cri`: a number in kPa, or \"estimate\" from the runs' fracturing "
              "labels); dp_vis (kPa) is in the table.", ""]
    L += ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for _, r in table[cols].iterrows():
        L.append("| " + " | ".join(_fmt(r[c]) for c in cols) + " |")
    return L + [""]


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v).replace("|", "\\|")
