"""Where the forward runs go, with an option and without: two coverage studies of the same draws
(:mod:`.coverage`, e.g. variants ``fit_correction`` and ``emulator_fit_correction``) compared draw by draw.

Per stage the mean forward runs (coarse and fine), and over the draws both name: the verdicts that differ,
the interval ends' differences relative to the reference interval's width, and each study's coverage.
Units: the strength's (the effect's unit); runs are counts.

    python -m sweep.discrepancy.cost REFERENCE.json CANDIDATE.json [--out TABLE.md]
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

__all__ = ["compare_studies", "markdown"]


def _stage_means(rows: list) -> dict:
    """{stage: (mean coarse runs, mean fine runs)} over ``rows`` (a stage a draw skipped counts 0)."""
    stages = list(dict.fromkeys(k for r in rows for k in r.get("runs_by_stage", {})))
    out = {}
    for st in stages:
        c = [r.get("runs_by_stage", {}).get(st, {}).get("coarse", 0) for r in rows]
        f = [r.get("runs_by_stage", {}).get(st, {}).get("fine", 0) for r in rows]
        out[st] = (float(np.mean(c)), float(np.mean(f)))
    return out


def compare_studies(ref: dict, cand: dict) -> dict:
    """The comparison of study ``cand`` with study ``ref`` over the draws they share (by set-up and draw)."""
    a = {(r["setup"], r["draw"]): r for r in ref["rows"]}
    b = {(r["setup"], r["draw"]): r for r in cand["rows"]}
    keys = [k for k in a if k in b]
    if not keys:
        raise ValueError("cost: the two studies share no draw (set-up and draw index)")
    both = [k for k in keys if "covered" in a[k] and "covered" in b[k]]
    rel = {side: [abs(b[k][side] - a[k][side]) / (a[k]["upper"] - a[k]["lower"]) for k in both]
           for side in ("lower", "upper")}
    return {"reference": ref["variant"], "candidate": cand["variant"], "draws": len(keys), "both_named": len(both),
            "verdicts_differ": [list(k) for k in keys if a[k]["verdict"] != b[k]["verdict"]],
            "stages": {"reference": _stage_means([a[k] for k in keys]), "candidate": _stage_means([b[k] for k in keys])},
            "total_runs": {"reference": float(np.mean([_total(a[k]) for k in keys])),
                           "candidate": float(np.mean([_total(b[k]) for k in keys]))},
            "end_difference_over_width": {s: {"median": float(np.median(v)), "max": float(np.max(v))}
                                          for s, v in rel.items() if v},
            "coverage": {"reference": sum(a[k]["covered"] for k in both), "candidate": sum(b[k]["covered"] for k in both)}}


def _total(row: dict) -> int:
    return sum(v.get("coarse", 0) + v.get("fine", 0) for v in row.get("runs_by_stage", {}).values())


def markdown(c: dict) -> str:
    """The comparison as a Markdown table of runs per stage plus the agreement lines."""
    ra, rb = c["stages"]["reference"], c["stages"]["candidate"]
    lines = [f"| stage | {c['reference']} (coarse + fine) | {c['candidate']} (coarse + fine) |", "|---|---|---|"]
    for st in dict.fromkeys([*ra, *rb]):
        fa, fb = ra.get(st, (0.0, 0.0)), rb.get(st, (0.0, 0.0))
        lines.append(f"| {st} | {fa[0]:.1f} + {fa[1]:.1f} | {fb[0]:.1f} + {fb[1]:.1f} |")
    t = c["total_runs"]
    lines.append(f"| **total** | **{t['reference']:.1f}** | **{t['candidate']:.1f}** |")
    e = c["end_difference_over_width"]
    lines += ["", f"draws {c['draws']}, both named {c['both_named']}, verdicts differing: {c['verdicts_differ'] or 'none'}; "
              f"interval ends' difference / reference width: lower median {e['lower']['median']:.2g} max "
              f"{e['lower']['max']:.2g}, upper median {e['upper']['median']:.2g} max {e['upper']['max']:.2g}; "
              f"truth covered {c['coverage']['reference']} / {c['both_named']} vs {c['coverage']['candidate']} / "
              f"{c['both_named']}"] if e else []
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sweep.discrepancy.cost", description=__doc__.split("\n\n")[0])
    ap.add_argument("reference")
    ap.add_argument("candidate")
    ap.add_argument("--out", help="write the Markdown table here (else print it)")
    a = ap.parse_args(argv)
    try:
        studies = [json.loads(Path(f).read_text()) for f in (a.reference, a.candidate)]
        c = compare_studies(*studies)
    except (OSError, ValueError, KeyError) as e:
        print(f"cost: {type(e).__name__}: {e}", file=sys.stderr)
        return 2
    text = markdown(c)
    if a.out:
        from solver.output import atomic_write_text

        atomic_write_text(Path(a.out), text)
    else:
        print(text, end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
