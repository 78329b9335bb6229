"""The Ca*-C separatrix with each run labelled by its longest crack up to the judged time (a sensitivity of the
label, never the protocol's verdict).

The boundary campaigns label a run by its crack at the snapshot where the front reached 45 mm; the cracks close
after about 2 s (crack_closure.md), so that label reads a crack that has shrunk.  This script relabels each run by
the longest crack (mm) at or before the judged time, read two ways:

* ``steps``: every accepted step of the run's time series, phi_open = 0.99 only: the crack length is
  ``open_tip_radius - r_inner`` (the largest radius of the phi >= 0.99 region connected to the inlet, less the
  cavity's radius; solver.metrics.open_tip_radius);
* ``snapshots``: the classifier's crack length (sweep.regimes.classify rule 1) on the stored snapshots (t = 0.5, 1, 2,
  3 s and the judged time; ``crack_history.csv``) at each phi_open of the history.

and fits Ca*_c = A exp(B C) at each (phi_open, L_min) with the protocol's fit
(``sweep.studies.threshold_sensitivity.separatrix_grid``).  Units: mm, s, %.

    python results/archive/fidelity/longest_crack_separatrix.py FOLDER [--table CSV] --l-min 3 4 5 --out FILE.json --md FILE.md

FOLDER: a boundary campaign's results folder with ``runs/`` (each with timeseries.csv and params.toml) and
``crack_history.csv``; ``--table``: its table.csv (default FOLDER/table.csv).
"""
from __future__ import annotations

import argparse
import json
import tomllib
from pathlib import Path

import pandas as pd

from sweep.regimes.classify import longest_open_crack
from sweep.studies.threshold_sensitivity import ThresholdGrid, separatrix_grid, to_markdown


def _finished(folder: Path, table_csv: Path | None) -> pd.DataFrame:
    table = pd.read_csv(table_csv or folder / "table.csv")
    return table[table["status"] == "ok"].set_index("key")


def longest_from_snapshots(folder: Path, table: pd.DataFrame) -> pd.DataFrame:
    """``L@<phi_open>`` (mm) per run key: the longest crack among the snapshots of ``crack_history.csv`` at
    t <= the judged time."""
    hist = pd.read_csv(folder / "crack_history.csv")
    upto = hist[hist["t"] <= hist["t_classified"] * (1 + 1e-9)]
    cols = [c for c in hist.columns if c.startswith("L_")]
    longest = upto.groupby("key")[cols].max()
    missing = sorted(set(table.index) - set(longest.index))
    if missing:
        raise ValueError(f"{folder}: crack_history.csv has no rows for the finished runs {missing}")
    return longest.loc[table.index].rename(columns={c: f"L@{c[2:]}" for c in cols})


def longest_from_steps(folder: Path, table: pd.DataFrame) -> pd.DataFrame:
    """``L@0.99`` (mm) per run key: the largest ``open_tip_radius - r_inner`` over the accepted steps at
    t <= the judged time (``sweep.regimes.classify.longest_open_crack``), and the time it was reached (s)."""
    rows = {}
    for key, run in table.iterrows():
        rd = folder / "runs" / key
        ts = pd.read_csv(rd / "timeseries.csv", usecols=["t", "open_tip_radius"])
        params = tomllib.loads((rd / "params.toml").read_text())
        r_i = float(params.get("parameters", params)["r_inner"])
        t_judged = float(run["t_classified"]) if pd.notna(run.get("t_classified")) else float(ts["t"].iloc[-1])
        upto = ts[ts["t"] <= t_judged * (1 + 1e-9)]
        rows[key] = {"L@0.99": longest_open_crack(rd, t_judged, r_i),
                     "t_longest": float(upto.loc[upto["open_tip_radius"].idxmax(), "t"]), "t_judged": t_judged}
    return pd.DataFrame.from_dict(rows, orient="index")


def _with_axes(lengths: pd.DataFrame, table: pd.DataFrame) -> pd.DataFrame:
    out = lengths.copy()
    out["cement"] = table.loc[out.index, "cement"].astype(float)
    out["Ca_star"] = table.loc[out.index, "Ca_star"].astype(float)
    return out.rename_axis("key").reset_index()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("folder", type=Path)
    ap.add_argument("--table", type=Path, help="the campaign's table.csv (default FOLDER/table.csv)")
    ap.add_argument("--l-min", type=float, nargs="+", required=True, help="crack lengths L_min (mm)")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--md", type=Path)
    a = ap.parse_args(argv)
    table = _finished(a.folder, a.table)
    doc, md = {"label": "the longest crack at or before the judged time"}, []
    for name, lengths in (("steps", longest_from_steps(a.folder, table)),
                          ("snapshots", longest_from_snapshots(a.folder, table))):
        lengths = _with_axes(lengths, table)
        levels = tuple(float(c[2:]) for c in lengths.columns if c.startswith("L@"))
        fits = separatrix_grid(lengths, ThresholdGrid(phi_open=levels, l_min=tuple(a.l_min)))
        doc[name] = {"fits": fits, "lengths": lengths.to_dict(orient="records")}
        md += [f"## Longest crack over the {name}", "", to_markdown(fits, lengths)]
    a.out.write_text(json.dumps(doc, indent=1))
    if a.md:
        a.md.write_text("\n".join(md))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
