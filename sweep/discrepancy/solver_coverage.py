"""Coverage of the named strength's 95 % interval over real-solver twin campaigns, and where each miss sits.

Reads the folders ``python -m sweep.discrepancy.twins`` writes (``summary.json`` and each twin's
``report.json``).  A twin counts when its hidden effect was named (coverage is conditional on the right
name, as in the toy study of :mod:`.coverage`); it is covered when the profile interval holds the hidden
strength.  For each twin the row also keeps what tells a miss's source apart: the side of the miss, the
truth's place in the interval, the Wald interval's verdict, the strength before the discretization
refresh and the refresh's passes and convergence, whether the emulator confirmed both ends, how the discretization
correction was carried along the profile (``[profile] correction``, with the calibrated parameters it also
follows) and the command-line overrides the twin ran with.  Coverage is pooled, by effect and by correction.  Strengths are in the effect's unit (kPa·s for β, mm/kPa for the
outer compliance); times in s.

    dchfrac discrepancy coverage results/discrepancy/coverage/solver_fixed_correction/*/ \\
        --out results/discrepancy/coverage/solver_fixed_correction/coverage.json
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

# Light at import (argparse, json): ``dchfrac`` builds its parser from this module before any bad input is
# refused (tests/test_budget.py); the Wilson interval's module loads in coverage_summary.

__all__ = ["add_coverage_arguments", "cmd_coverage", "coverage_markdown", "coverage_summary", "twin_rows"]


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


def _correction(report: dict, effect: str, overrides) -> str | None:
    """How the profile carried the discretization correction: ``[profile] correction`` ("fit", "point",
    "linear", "piecewise"), with "+ <names>" for the calibrated parameters a linear correction also follows
    (``correction_follows = "all"``).  A report written before the profile recorded it says so only through the
    twin's override ``spec.profile.fine=false`` ("fit"); otherwise None."""
    prof = (report.get("profiles") or {}).get(effect) or {}
    kind = prof.get("correction")
    if kind is None:
        return "fit" if "spec.profile.fine=false" in (overrides or []) else None
    also = [n for n in (prof.get("correction_model") or {}).get("follows") or [] if not n.startswith("effect:")]
    return kind + "".join(f" + {n}" for n in also)


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
    row["correction"] = _correction(report or {}, entry["expect"], row["overrides"])
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
    """Pooled, per-effect and per-correction coverage: covered / named with the Wilson 95 % interval, misses by
    side."""
    from .coverage import wilson

    def one(rs):
        named = [r for r in rs if r["named"] and "covered" in r]
        k, n = sum(r["covered"] for r in named), len(named)
        return {"twins": len(rs), "named": n, "covered": k, "coverage": k / n if n else None,
                "wilson95": list(wilson(k, n)), "miss_low": sum(r["miss"] == "low" for r in named),
                "miss_high": sum(r["miss"] == "high" for r in named),
                "wald_covered": sum(bool(r.get("wald_covered")) for r in named)}
    def by(key):
        groups: dict[str, list] = {}
        for r in rows:
            groups.setdefault(str(r.get(key) or "unrecorded"), []).append(r)
        return {v: one(rs) for v, rs in sorted(groups.items())}

    return {"pooled": one(rows), "by_effect": by("effect"), "by_correction": by("correction")}


def coverage_markdown(rows: list, summary: dict) -> str:
    """The twin table and the coverage line, in Markdown."""
    def f(v, fmt="{:.4g}"):
        return "–" if v is None or (isinstance(v, float) and not math.isfinite(v)) else fmt.format(v)
    L = ["| campaign | twin | correction | truth | named | interval | covered | truth's place | Wald covers | "
         "before refresh (rel. error) | refresh passes | ends confirmed | gap after / before |",
         "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        iv = f"[{f(r['lower'])}, {f(r['upper'])}]" if "lower" in r else "–"
        cov = "–" if "covered" not in r else ("yes" if r["covered"] else f"**no ({r['miss']})**")
        L.append(f"| {r['campaign']} | {r['twin']} | {f(r.get('correction'), '{}')} | {f(r['truth'])} | {'yes' if r['named'] else r['verdict']} | {iv} | "
                 f"{cov} | {f(r.get('position'), '{:.2f}')} | {f(r.get('wald_covered'), '{}')} | "
                 f"{f(r.get('before_refresh_error'), '{:+.1%}')} | {f(r.get('refresh_passes'), '{}')} | "
                 f"{f(r.get('emulator_confirmed'), '{}')} | {f(r.get('gap_ratio'), '{:.2f}')} |")
    L += ["", "Covered / named: " + _count_text(summary["pooled"]), "",
          "| correction | covered / named | misses low / high | named of twins |", "|---|---|---|---|"]
    for kind, c in summary["by_correction"].items():
        L.append(f"| {kind} | {c['covered']} / {c['named']} | {c['miss_low']} / {c['miss_high']} | "
                 f"{c['named']} of {c['twins']} |")
    return "\n".join(L) + "\n"


def _count_text(c: dict) -> str:
    lo, hi = c["wilson95"]
    return (f"**{c['covered']} / {c['named']}**"
            + (f" = {c['coverage']:.1%}, Wilson 95 % [{lo:.1%}, {hi:.1%}]" if c["named"] else "")
            + f"; misses low / high {c['miss_low']} / {c['miss_high']}; named {c['named']} of {c['twins']} twins.")


def add_coverage_arguments(p: argparse.ArgumentParser) -> None:
    """The arguments of ``dchfrac discrepancy coverage`` (and of ``python -m sweep.discrepancy.solver_coverage``)."""
    p.add_argument("folders", nargs="+", help="twin results folders, each with a summary.json")
    p.add_argument("--out", default=None, metavar="JSON", help="write rows and summary here (and a .md beside it)")


def cmd_coverage(args) -> int:
    """Print the coverage table of ``args.folders`` (and write it to ``args.out``); exit 2 with one line, before
    anything is read, when a folder holds no summary.json or the output folder is not writable."""
    from solver.output import atomic_write_text, check_writable_dir
    from sweep.campaign.store import write_json_atomic

    missing = [f for f in args.folders if not (Path(f) / "summary.json").is_file()]
    try:
        if missing:
            raise ValueError(f"folders: no summary.json in {missing} (give twin results folders written by "
                             "`python -m sweep.discrepancy.twins`)")
        if args.out:
            check_writable_dir(str(Path(args.out).resolve().parent), "--out folder")
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    rows = twin_rows(args.folders)
    summary = coverage_summary(rows)
    md = coverage_markdown(rows, summary)
    print(md)
    if args.out:
        write_json_atomic(Path(args.out), {"rows": rows, **summary})
        atomic_write_text(Path(args.out).with_suffix(".md"), md)
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sweep.discrepancy.solver_coverage",
                                 description=__doc__.split("\n\n")[0])
    add_coverage_arguments(ap)
    return cmd_coverage(ap.parse_args(argv))


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
