"""The closing probes (campaigns/studies/wall_seal_h2.toml, wall_open_h2.toml, porosity_ceiling_h2.toml,
wall_compliance_h2.toml, damage_viscosity_closure_h2.toml, broken_skeleton_closure_h2.toml): per run, the quantities
their headers read.

For each finished run of the campaign store: from the time series, the crack (``open_tip_radius - r_inner``, mm)
at its largest and at the judged time, the time of the largest, the largest nodal damage (-) at those two times,
p_inj (kPa) at 1, 2 s and at the end, and the
outflow through r_o as a fraction of the injected volume at 1, 2 s and at the end; from each snapshot, the
pressure (kPa) and the porosity (-) averaged over rings at the radii RADII and r_o - WALL (mm), and the smallest
porosity within 2 mm of r_o.  Units: mm, s, kPa.

    dchfrac closure STORE/wall_seal_h2 --out wall_seal.json [--md wall_seal_tables.md]

The run folders (``runs/<key>`` with ``record.json``, ``timeseries.csv`` and the snapshots) stay in the campaign's
store; the committed JSON and tables of each probe's results folder are this command's output.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from solver.output import atomic_write_text
from sweep.regimes.classify import list_snapshots

__all__ = ["RADII", "WALL", "series_row", "ring_profiles", "run_summary", "campaign_summaries", "to_markdown"]

RADII = (6.0, 10.0, 20.0, 30.0, 40.0, 45.0)   # mm, ring centres (half-width 1 mm)
WALL = ((3.0, 0.5), (1.0, 0.5), (0.2, 0.1))   # mm inside r_o: ring centres near the wall and their half-widths


def _at(ts: pd.DataFrame, col: str, t: float) -> float:
    return float(np.interp(t, ts["t"], ts[col])) if t <= ts["t"].iloc[-1] + 1e-9 else float("nan")


def series_row(ts: pd.DataFrame, r_i: float, t_judged: float) -> dict:
    """The time-series quantities of one run (see the module docstring)."""
    crack = (ts["open_tip_radius"] - r_i).clip(lower=0.0)
    upto = ts["t"] <= t_judged + 1e-9
    i = crack[upto].idxmax()
    out_frac = ts["outflow_volume"] / ts["injected_volume"].where(ts["injected_volume"] > 0)
    row = {"t_judged": t_judged, "crack_longest": float(crack[i]), "t_longest": float(ts.loc[i, "t"]),
           "crack_judged": float(crack[upto].iloc[-1]),
           "max_damage_longest": float(ts.loc[i, "max_damage"]), "max_damage_judged": float(ts["max_damage"][upto].iloc[-1])}
    for t in (1.0, 2.0):
        row[f"p_inj_{t:g}s"] = _at(ts, "p_inj", t)
        row[f"outflow_frac_{t:g}s"] = float(np.interp(t, ts["t"], out_frac.fillna(0.0)))
    row["p_inj_end"] = float(ts["p_inj"].iloc[-1])
    row["outflow_frac_end"] = float(out_frac.iloc[-1])
    return row


def _mean(values: np.ndarray) -> float:
    """Mean of a ring's values; NaN for a ring that holds no node (or element centroid)."""
    return float(values.mean()) if values.size else float("nan")


def ring_profiles(run_dir: Path, r_o: float) -> list[dict]:
    """Per snapshot after t = 0: ring means of p (nodal, kPa) and phi (per element, at its centroid) at RADII and
    at r_o - WALL (mm), and the smallest element phi within 2 mm of r_o."""
    with np.load(run_dir / "snapshots" / "mesh.npz") as m:
        pts, tris = np.asarray(m["points"], float), np.asarray(m["triangles"], np.int64)
    r, r_el = np.hypot(*pts.T), np.hypot(*pts[tris].mean(axis=1).T)
    rows = []
    for t, f in list_snapshots(run_dir):
        if t <= 0.0:
            continue
        with np.load(f) as z:
            p, phi = np.asarray(z["p"], float), np.asarray(z["phi"], float)
        row = {"t": float(t), "phi_min_wall": float(phi[r_el > r_o - 2.0].min())}
        rings = [(rc, 1.0) for rc in RADII] + [(r_o - w, half) for w, half in WALL]
        for rc, half in rings:
            row[f"p@{rc:g}"] = _mean(p[np.abs(r - rc) <= half])
            row[f"phi@{rc:g}"] = _mean(phi[np.abs(r_el - rc) <= half])
        rows.append(row)
    return rows


def run_summary(run_dir: Path) -> dict:
    """One finished run folder of a campaign store: its parameters of the probes, label, time series and rings."""
    rec = json.loads((run_dir / "record.json").read_text())
    p = rec["params"]
    ts = pd.read_csv(run_dir / "timeseries.csv")
    t_judged = (rec.get("classification") or {}).get("t_classified") or float(ts["t"].iloc[-1])
    return {"key": run_dir.name, "porosity_floor": p["porosity_floor"], "permeability_floor": p.get("permeability_floor"),
            "porosity_ceiling": p.get("porosity_ceiling"), "beta": p.get("beta"),
            "outer_compliance": p.get("outer_compliance"),
            "label": (rec.get("classification") or {}).get("regime"),
            **series_row(ts, p["r_inner"], float(t_judged)), "rings": ring_profiles(run_dir, p["r_outer"])}


def to_markdown(runs: list[dict]) -> str:
    """The runs' table and each run's ring table (Markdown)."""
    cols = ["porosity_floor", "permeability_floor", "porosity_ceiling", "beta", "outer_compliance", "label", "t_judged", "crack_longest", "t_longest", "crack_judged", "max_damage_longest", "max_damage_judged", "p_inj_1s",
            "p_inj_2s", "p_inj_end", "outflow_frac_1s", "outflow_frac_2s", "outflow_frac_end"]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    lines += ["| " + " | ".join(f"{r[c]:.3g}" if isinstance(r[c], float) else str(r[c]) for c in cols) + " |"
              for r in runs]
    for r in runs:
        lines += ["", f"Rings, porosity floor {r['porosity_floor']}, permeability floor {r['permeability_floor']} mm², "
                  f"porosity ceiling {r['porosity_ceiling']} "
                  "(p kPa, phi -; ring means at r mm):", ""]
        keys = ["t", "phi_min_wall"] + [k for k in r["rings"][0] if k.startswith("p@")] + \
            [k for k in r["rings"][0] if k.startswith("phi@")]
        lines += ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
        lines += ["| " + " | ".join(f"{row[k]:.3g}" for k in keys) + " |" for row in r["rings"]]
    return "\n".join(lines) + "\n"


def campaign_summaries(campaign_dir: Path) -> list[dict]:
    """:func:`run_summary` of every ok run of a campaign store's ``runs/``, ordered by the probes' parameters."""
    runs = []
    for d in sorted((Path(campaign_dir) / "runs").iterdir()):
        rec = d / "record.json"
        if not d.name.startswith(".") and rec.is_file() and json.loads(rec.read_text()).get("status") == "ok":
            runs.append(run_summary(d))
    runs.sort(key=lambda r: (r["porosity_floor"], r["permeability_floor"] or 0.0, r["porosity_ceiling"] or 0.0,
                             r["outer_compliance"] or 0.0, r["beta"] or 0.0))
    return runs


def cmd_closure(a) -> int:
    if not (Path(a.campaign_dir) / "runs").is_dir():
        print(f"dchfrac closure: {a.campaign_dir}: no runs/ folder (allowed: a campaign store's folder with its run "
              "folders)", file=sys.stderr)
        return 2
    runs = campaign_summaries(a.campaign_dir)
    atomic_write_text(a.out, json.dumps(runs, indent=1))
    if a.md:
        atomic_write_text(a.md, to_markdown(runs))
    return 0
