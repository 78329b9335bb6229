"""Coverage of the named strength's 95 % interval over real-solver twin campaigns, and where each miss sits.

Reads the folders ``python -m sweep.discrepancy.twins`` writes (``summary.json`` and each twin's
``report.json``).  A twin counts when its hidden effect was named (coverage is conditional on the right
name, as in the toy study of :mod:`.coverage`); it is covered when the profile interval holds the hidden
strength.  For each twin the row also keeps what tells a miss's source apart: the side of the miss, the
truth's place in the interval, the Wald interval's verdict, the strength before the discretization
refresh and the refresh's passes and convergence, whether the emulator confirmed both ends, and the
command-line overrides the twin ran with.  Strengths are in the effect's unit (kPa·s for β, mm/kPa for the
outer compliance); times in s.

    python -m sweep.discrepancy.solver_coverage results/discrepancy/coverage/solver_fixed_correction/* \\
        --out results/discrepancy/coverage/solver_fixed_correction/coverage.json
"""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from .coverage import wilson

__all__ = ["twin_rows", "coverage_summary", "coverage_markdown"]


def _truth(entry: dict) -> float | None:
    """The hidden strength of the twin's expected effect (None for a control, or a strength given as a law)."""
    from solver.effects import EFFECTS

    eff = EFFECTS.get(entry.get("expect"))
    v = (entry.get("hidden") or {}).get(eff.parameter) if eff else None
    return float(v) if isinstance(v, (int, float)) else None


def _refresh(report: dict, effect: str) -> dict:
    """The discretization refresh of the named strength: passes, convergence, the strength before it."""
    acc = next((a for a in report.get("accepted") or [] if a.get("effect") == effect), {})
    return {"refresh_passes": len(report.get("discretization_refresh") or []),
            "refresh_converged": acc.get("refresh_converged"),
            "strength_before_refresh": acc.get("strength_before_refresh"),
            "wald": acc.get("strength_interval_wald")}


def _emulator(report: dict, effect: str) -> bool | None:
    """True when the emulated profile's ends were both confirmed by real runs; None without the emulator."""
    em = ((report.get("profiles") or {}).get(effect) or {}).get("emulator")
    return None if em is None else bool(em.get("confirmed"))


def _inside(interval, x: float) -> bool | None:
    return None if not interval or None in interval else bool(interval[0] <= x <= interval[1])


def twin_row(campaign: str, name: str, entry: dict, report: dict | None) -> dict | None:
    """One twin's row (None for a twin without a continuous hidden strength: a control)."""
    truth = _truth(entry)
    if truth is None:
        return None
    named = entry.get("named_effect") == entry["expect"]
    row = {"campaign": campaign, "twin": name, "effect": entry["expect"], "truth": truth, "named": named,
           "verdict": entry.get("verdict"), "passed": entry.get("passed"), "wall_time_s": entry.get("wall_time_s"),
           "overrides": entry.get("overrides", [])}
    if not named or not entry.get("strength_interval"):
        return row
    lo, hi = (float(v) for v in entry["strength_interval"])
    row.update({"strength": entry.get("strength"), "lower": lo, "upper": hi, "covered": lo <= truth <= hi,
                "miss": "" if lo <= truth <= hi else ("low" if hi < truth else "high"),
                "position": (truth - lo) / (hi - lo) if hi > lo else math.nan,
                "relative_width": (hi - lo) / abs(truth) if truth else math.nan,
                "gap_ratio": (entry["gap_after"] / entry["gap_before"]) if entry.get("gap_before") else None})
    if report is not None:
        row.update(_refresh(report, entry["expect"]))
        row["wald_covered"] = _inside(row.pop("wald"), truth)
        b = row.get("strength_before_refresh")
        row["before_refresh_error"] = None if b is None else (b - truth) / abs(truth)
        row["emulator_confirmed"] = _emulator(report, entry["expect"])
    return row


def twin_rows(folders) -> list[dict]:
    """Every twin with a continuous hidden strength in the results ``folders`` (each with a summary.json)."""
    rows = []
    for folder in map(Path, folders):
        summary = json.loads((folder / "summary.json").read_text())
        for name, entry in summary.items():
            rp = folder / name / "report.json"
            report = json.loads(rp.read_text()) if rp.is_file() else None
            row = twin_row(folder.name, name, entry, report)
            if row is not None:
                rows.append(row)
    return rows


def coverage_summary(rows: list) -> dict:
    """Pooled and per-effect coverage: covered / named with the Wilson 95 % interval, misses by side."""
    def one(rs):
        named = [r for r in rs if r["named"] and "covered" in r]
        k, n = sum(r["covered"] for r in named), len(named)
        return {"twins": len(rs), "named": n, "covered": k, "coverage": k / n if n else None,
                "wilson95": list(wilson(k, n)), "miss_low": sum(r["miss"] == "low" for r in named),
                "miss_high": sum(r["miss"] == "high" for r in named),
                "wald_covered": sum(bool(r.get("wald_covered")) for r in named)}
    effects = sorted({r["effect"] for r in rows})
    return {"pooled": one(rows), "by_effect": {e: one([r for r in rows if r["effect"] == e]) for e in effects}}


def coverage_markdown(rows: list, summary: dict) -> str:
    """The twin table and the coverage line, in Markdown."""
    def f(v, fmt="{:.4g}"):
        return "–" if v is None or (isinstance(v, float) and not math.isfinite(v)) else fmt.format(v)
    L = ["| campaign | twin | truth | named | interval | covered | truth's place | Wald covers | "
         "before refresh (rel. error) | refresh passes | ends confirmed | gap after / before |",
         "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        iv = f"[{f(r['lower'])}, {f(r['upper'])}]" if "lower" in r else "–"
        cov = "–" if "covered" not in r else ("yes" if r["covered"] else f"**no ({r['miss']})**")
        L.append(f"| {r['campaign']} | {r['twin']} | {f(r['truth'])} | {'yes' if r['named'] else r['verdict']} | {iv} | "
                 f"{cov} | {f(r.get('position'), '{:.2f}')} | {f(r.get('wald_covered'), '{}')} | "
                 f"{f(r.get('before_refresh_error'), '{:+.1%}')} | {f(r.get('refresh_passes'), '{}')} | "
                 f"{f(r.get('emulator_confirmed'), '{}')} | {f(r.get('gap_ratio'), '{:.2f}')} |")
    p = summary["pooled"]
    lo, hi = p["wilson95"]
    L += ["", f"Covered / named: **{p['covered']} / {p['named']}**"
          + (f" = {p['coverage']:.1%}, Wilson 95 % [{lo:.1%}, {hi:.1%}]" if p["named"] else "")
          + f"; misses low / high {p['miss_low']} / {p['miss_high']}; named {p['named']} of {p['twins']} twins."]
    return "\n".join(L) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sweep.discrepancy.solver_coverage",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("folders", nargs="+", help="twin results folders, each with a summary.json")
    ap.add_argument("--out", default=None, metavar="JSON", help="write rows and summary here (and a .md beside it)")
    a = ap.parse_args(argv)
    missing = [f for f in a.folders if not (Path(f) / "summary.json").is_file()]
    if missing:
        ap.error(f"no summary.json in {missing}")
    rows = twin_rows(a.folders)
    summary = coverage_summary(rows)
    md = coverage_markdown(rows, summary)
    print(md)
    if a.out:
        from solver.output import atomic_write_text
        from sweep.campaign.store import write_json_atomic

        write_json_atomic(Path(a.out), {"rows": rows, **summary})
        atomic_write_text(Path(a.out).with_suffix(".md"), md)
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
