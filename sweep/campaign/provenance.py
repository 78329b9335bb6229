"""Which code made each committed result: ``results/PROVENANCE.md``, written from the campaign tables.

Every campaign run records the hash of the solver code that made it (``code_hash``, ``python -m solver.codehash``)
and of the classifier that labelled it (``classifier_hash``).  This module reads those columns from every
``table.csv`` under a results folder (run folders aside) and writes one row per campaign: its runs, each code
hash with its run count, the classifier hashes, and the dates its runs finished.  What no table records (folders
made before runs recorded their code, outputs that are not campaign tables) is kept by hand in
``provenance_notes.md`` beside it and copied in whole.  So the file never drifts from the tables: a test
regenerates it byte for byte, and ``dchfrac provenance`` rewrites it after a campaign is committed.

Usage: ``dchfrac provenance [--results results] [--check]``.
"""
from __future__ import annotations

import csv
from collections import Counter
from pathlib import Path

__all__ = ["NOTES", "OUT", "table_row", "provenance_rows", "render", "cmd_provenance"]

NOTES = "provenance_notes.md"  # hand-kept: what no campaign table records
OUT = "PROVENANCE.md"
HEADER = """# Provenance of the committed results

Written by `dchfrac provenance` from the campaign tables; do not edit by hand (the hand-kept part is
`provenance_notes.md`).  Each run records the hash of the solver code that made it (`code_hash`, `python -m
solver.codehash`; `python -m solver.codehash --git <commit>` gives a commit's) and of the classifier that labelled
it (`classifier_hash`).  A campaign rerun with `dchfrac campaign run` reruns every run whose recorded hash differs
from the current code (`dchfrac campaign status` counts them).  Dates are the runs' `finished_at`, the host's clock.

## Campaign tables

| folder | runs | solver code (runs) | classifier (runs) | finished |
|---|---|---|---|---|
"""


def _counts(values) -> str:
    """"`hash` (n), `hash` (n)" by decreasing count, "not recorded (n)" for the runs without a value."""
    c = Counter(values)
    missing = c.pop("", 0)
    parts = [f"`{k}` ({n})" for k, n in sorted(c.items(), key=lambda kv: (-kv[1], kv[0]))]
    return ", ".join(parts + ([f"not recorded ({missing})"] if missing else []))


def _classifiers(rows) -> str:
    """The classifier hashes of a table's runs; a failed run carries no label, so no hash."""
    labelled = [r for r in rows if r.get("status") == "ok"]
    failed = len(rows) - len(labelled)
    text = _counts(r.get("classifier_hash", "") for r in labelled)
    return ", ".join(filter(None, (text, f"failed, no label ({failed})" if failed else "")))


def table_row(table: Path, root: Path) -> dict:
    """One campaign table's provenance: folder (relative to ``root``), runs, code and classifier hash counts and
    the range of dates its runs finished (None where the table has no such column)."""
    with open(table, newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    dates = sorted(r["finished_at"][:10] for r in rows if r.get("finished_at"))
    cols = rows[0].keys() if rows else ()
    return {"folder": table.parent.relative_to(root).as_posix() + "/", "runs": len(rows),
            "code": _counts(r.get("code_hash", "") for r in rows) if "code_hash" in cols else None,
            "classifier": _classifiers(rows) if "classifier_hash" in cols else None,
            "finished": (dates[0] if dates[0] == dates[-1] else f"{dates[0]} – {dates[-1]}") if dates else None}


def provenance_rows(root: Path) -> list[dict]:
    """:func:`table_row` of every ``table.csv`` under ``root`` outside run folders, sorted by folder."""
    root = Path(root)
    tables = [t for t in root.rglob("table.csv") if "runs" not in t.relative_to(root).parts[:-1]]
    return sorted((table_row(t, root) for t in tables), key=lambda r: r["folder"])


def render(rows: list[dict], notes: str) -> str:
    """PROVENANCE.md: the header, one table row per campaign, then the hand-kept notes."""
    def cell(v):
        return "none recorded" if v is None else str(v)

    lines = [f"| `{r['folder']}` | {r['runs']} | {cell(r['code'])} | {cell(r['classifier'])} | {cell(r['finished'])} |"
             for r in rows]
    return HEADER + "\n".join(lines) + "\n\n" + notes.strip() + "\n"


def cmd_provenance(args) -> int:
    """``dchfrac provenance``: write (or with ``--check`` compare) RESULTS/PROVENANCE.md; exit 1 when it is out
    of date under ``--check``, 2 when RESULTS has no notes file."""
    import sys

    from solver.output import atomic_write_text

    root = Path(args.results)
    notes = root / NOTES
    if not notes.is_file():
        print(f"dchfrac provenance: --results {root}: no {NOTES} (allowed: the results folder that holds it)",
              file=sys.stderr)
        return 2
    text = render(provenance_rows(root), notes.read_text(encoding="utf-8"))
    out = root / OUT
    if args.check:
        same = out.is_file() and out.read_text(encoding="utf-8") == text
        print(f"{out}: {'up to date' if same else 'out of date: run dchfrac provenance'}")
        return 0 if same else 1
    atomic_write_text(out, text)
    print(f"wrote {out} ({len(text.splitlines())} lines)")
    return 0
