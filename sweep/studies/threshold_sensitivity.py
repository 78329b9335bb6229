"""How the Ca*–C separatrix depends on the crack thresholds of the classifier (rule 1 of ``sweep.regimes.classify``).

Rule 1 labels a run fracturing when its crack (the connected region of porosity phi >= ``phi_open`` that
touches the cavity) reaches farther than ``min_crack_length`` (L_min) from the inner radius.  Porosity is
constant per element (P1 displacements give a constant volumetric strain, Eq. (phi)), so the crack tip moves
by whole elements, and a label can hinge on whether one element ahead of the tip passes phi_open.  This module
re-classifies the stored runs of a campaign on a grid of (phi_open, L_min) fixed by the caller, fits the
separatrix Ca*_c = A exp(B C) of each grid point (``sweep.regimes.separatrix.separatrix_profile_interval``) and reports
every grid point: nothing is chosen from the grid.

Units: lengths mm, C in %, Ca* dimensionless, porosity dimensionless.  Usage::

    python -m sweep.studies.threshold_sensitivity results/ca_star_boundary_h2_floor \
        --phi-open 0.95 0.97 0.98 0.99 0.995 --l-min 3 4 5 --out sensitivity.json [--md sensitivity.md]
"""
from __future__ import annotations

import argparse
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import pandas as pd

from sweep.regimes.classify import classify_run
from sweep.regimes.separatrix import interval_text
from solver.output import atomic_write_text
from sweep.campaign.store import write_json_atomic

__all__ = ["ThresholdGrid", "crack_lengths", "lengths_from", "separatrix_grid", "to_markdown", "main"]


@dataclass(frozen=True)
class ThresholdGrid:
    """The (phi_open, L_min) grid of a sensitivity study: porosity levels in (0, 1], lengths in mm (> 0)."""

    phi_open: tuple[float, ...]
    l_min: tuple[float, ...]

    def __post_init__(self) -> None:
        for name, lo, hi in (("phi_open", 0.0, 1.0), ("l_min", 0.0, math.inf)):
            values = getattr(self, name)
            if not values:
                raise ValueError(f"{name}=(): give at least one value")
            for v in values:
                if not (isinstance(v, (int, float)) and lo < v <= hi and math.isfinite(v)):
                    raise ValueError(f"{name} value {v!r}: must be a number in ({lo}, {hi}]")


def _campaign_table(campaign_dir: Path) -> pd.DataFrame:
    """The completed runs of a campaign folder (``sweep.campaign.load.load_campaign``), with the columns this study reads."""
    from sweep.campaign.load import load_campaign

    df = load_campaign(campaign_dir)
    missing = [c for c in ("run_dir", "status", "cement", "Ca_star") if c not in df.columns]
    if missing:
        raise ValueError(f"{campaign_dir}: table columns {missing} missing (need run_dir, status, cement, Ca_star)")
    return df[df["status"] == "ok"].reset_index(drop=True)


def crack_lengths(campaign_dir: str | Path, phi_open: Sequence[float]) -> pd.DataFrame:
    """Crack length (mm) of every completed run of a campaign at each porosity level of ``phi_open``.

    Each run is re-classified on the snapshot its campaign classified (the one at ``t_classified``, else the
    last) with only ``phi_open`` changed.  Returns one row per run: ``key``, ``cement`` (%), ``Ca_star`` and
    ``L@<phi_open>`` columns (mm).
    """
    campaign_dir = Path(campaign_dir)
    df = _campaign_table(campaign_dir)
    rows = []
    for _, run in df.iterrows():
        t = run.get("t_classified")
        at = "last" if pd.isna(t) else float(t)
        row = {"key": run["key"], "cement": float(run["cement"]), "Ca_star": float(run["Ca_star"])}
        for level in phi_open:
            c, _ = classify_run(campaign_dir / run["run_dir"], at, phi_open=level)
            row[f"L@{level:g}"] = float(c.crack_length)
        rows.append(row)
    return pd.DataFrame(rows)


def separatrix_grid(lengths: pd.DataFrame, grid: ThresholdGrid, level: float = 0.95) -> list[dict]:
    """The separatrix fit at every (phi_open, L_min) of ``grid`` from ``crack_lengths`` output.

    Each entry: phi_open, l_min (mm), n_fracturing, n, B (1/%), B_interval, A, excludes_zero (the
    ``level`` profile interval of B lies above 0), or ``error`` when the labels cannot be fitted (one class)."""
    from sweep.regimes.separatrix import separatrix_profile_interval

    out = []
    for po in grid.phi_open:
        col = f"L@{po:g}"
        if col not in lengths.columns:
            raise ValueError(f"phi_open={po}: no column {col!r} in the lengths (run crack_lengths with it)")
        for lm in grid.l_min:
            fr = (lengths[col] > lm).to_numpy()
            entry = {"phi_open": po, "l_min": lm, "n": int(len(fr)), "n_fracturing": int(fr.sum())}
            try:
                s = separatrix_profile_interval(lengths["cement"], lengths["Ca_star"], fr, level=level)
            except ValueError as e:
                entry["error"] = str(e)
            else:
                lo, hi = (float(v) for v in s.B_interval)
                entry.update(B=float(s.B), B_interval=[lo, hi], A=float(s.A), sharpness=float(s.sharpness),
                             excludes_zero=bool(lo > 0.0))
            out.append(entry)
    return out


def lengths_from(path: str | Path) -> pd.DataFrame:
    """The crack lengths (mm) per run and porosity level stored in an earlier output of :func:`main` (its
    ``lengths`` records): the fits redone without the run folders, which a committed campaign may not carry."""
    recs = json.loads(Path(path).read_text()).get("lengths")
    if not recs:
        raise ValueError(f"--lengths {path}: no 'lengths' records (allowed: a JSON this module wrote)")
    return pd.DataFrame.from_records(recs)


def to_markdown(fits: list[dict], lengths: pd.DataFrame) -> str:
    """A table of the grid's fits and the distinct crack lengths at each porosity level (mm)."""
    lines = ["| phi_open | L_min (mm) | fracturing | B (1/%) | 95 % interval | excludes 0 |", "|---|---|---|---|---|---|"]
    for f in fits:
        if "error" in f:
            lines.append(f"| {f['phi_open']:g} | {f['l_min']:g} | {f['n_fracturing']}/{f['n']} | – | {f['error']} | – |")
            continue
        lines.append(f"| {f['phi_open']:g} | {f['l_min']:g} | {f['n_fracturing']}/{f['n']} | {f['B']:.2f} | "
                     f"{interval_text(*f['B_interval'])} | {'yes' if f['excludes_zero'] else 'no'} |")
    lines += ["", "Distinct crack lengths (mm, number of runs):", ""]
    for col in [c for c in lengths.columns if c.startswith("L@")]:
        counts = lengths[col].round(2).value_counts().sort_index()
        lines.append(f"* phi_open = {col[2:]}: " + ", ".join(f"{v:.2f} ({n})" for v, n in counts.items()))
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sweep.studies.threshold_sensitivity", description=__doc__.split("\n\n")[0])
    ap.add_argument("campaign_dir", help="a campaign results folder (table.csv and runs/)")
    ap.add_argument("--lengths", help="take the crack lengths from this earlier output (JSON) instead of the run "
                    "folders: the fits redone on a fresh clone, where runs/ is not committed")
    ap.add_argument("--phi-open", type=float, nargs="+", required=True, help="porosity levels of an open crack (-)")
    ap.add_argument("--l-min", type=float, nargs="+", required=True, help="crack lengths L_min of rule 1 (mm)")
    ap.add_argument("--level", type=float, default=0.95, help="level of the profile intervals (default 0.95)")
    ap.add_argument("--out", required=True, help="JSON file written (atomically)")
    ap.add_argument("--md", help="Markdown table written too")
    a = ap.parse_args(argv)
    grid = ThresholdGrid(tuple(a.phi_open), tuple(a.l_min))
    if not 0.0 < a.level < 1.0:
        ap.error(f"--level {a.level}: must be in (0, 1)")
    lengths = lengths_from(a.lengths) if a.lengths else crack_lengths(a.campaign_dir, grid.phi_open)
    fits = separatrix_grid(lengths, grid, level=a.level)
    write_json_atomic(Path(a.out), {"campaign_dir": str(a.campaign_dir), "grid": {"phi_open": list(grid.phi_open),
                                    "l_min": list(grid.l_min)}, "level": a.level, "fits": fits,
                                    "lengths": lengths.to_dict(orient="records")})
    if a.md:
        atomic_write_text(Path(a.md), to_markdown(fits, lengths))
    print(to_markdown(fits, lengths))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
