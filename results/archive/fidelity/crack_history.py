"""The crack of every snapshot of a campaign's runs: how the classifier's crack length moves with time.

For each finished run of a campaign store with its full snapshots (a run pruned by ``dchfrac campaign prune`` has
lost them: its rows are kept from an earlier pass, if ``--out`` holds them) and each of its snapshots, writes one
row: the run's key and swept values, the snapshot time t (s), the crack length L (mm,
``sweep.regimes.classify`` rule 1: the phi >= phi_open region connected to the cavity, beyond r_i) at each phi_open of
PHI_OPEN, the number of cracks at phi_open = 0.99 and L_min = 4 mm, the largest damage d, and, in the elements of
the phi >= 0.99 crack region, the range of the damage (element mean of d) and of the volumetric strain eps_v, the
largest porosity, and the time the run was classified at.  Units: mm, s; d, phi, eps_v dimensionless.

    python results/archive/fidelity/crack_history.py STORE/CAMPAIGN --out crack_history.csv [--summary summary.md]
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pandas as pd

from sweep.regimes.classify import classify_fields, list_snapshots

PHI_OPEN = (0.95, 0.99, 0.995)
L_MIN = 4.0  # mm, the boundary campaigns' threshold


def _snapshot_row(points, tris, r_i, r_o, z) -> dict:
    S, phi, d, eps_v = (np.asarray(z[k], float) for k in ("S", "phi", "d", "eps_v"))
    row = {"t": float(z["t"])}
    for level in PHI_OPEN:
        c = classify_fields(points, tris, S, phi, r_i, r_o, phi_open=level, min_crack_length=L_MIN)
        row[f"L_{level}"] = float(c.crack_length)
        if level == 0.99:
            row["n_cracks_0.99"] = int(c.n_cracks)
    open_el = phi >= 0.99
    d_el = d[tris].mean(axis=1)
    row["d_max"] = float(d.max())
    row["phi_max"] = float(phi.max())
    for name, v in (("d", d_el), ("eps_v", eps_v)):
        row[f"{name}_open_min"] = float(v[open_el].min()) if open_el.any() else np.nan
        row[f"{name}_open_max"] = float(v[open_el].max()) if open_el.any() else np.nan
    return row


def run_history(run_dir: Path) -> list[dict]:
    """Rows of one run folder (every snapshot after t = 0)."""
    rec = json.loads((run_dir / "record.json").read_text())
    with np.load(run_dir / "snapshots" / "mesh.npz") as m:
        points, tris = np.asarray(m["points"], float), np.asarray(m["triangles"], np.int64)
    p = rec["params"]
    base = {"key": run_dir.name, "cement": p["cement"], "eta_o": p["eta_o"], "w_i": p["w_i"], "l_d": p["l_d"],
            "t_classified": (rec.get("classification") or {}).get("t_classified")}
    rows = []
    for t, f in list_snapshots(run_dir):
        if t <= 0.0:
            continue
        with np.load(f) as z:
            rows.append({**base, **_snapshot_row(points, tris, p["r_inner"], p["r_outer"], z)})
    return rows


def summary(df: pd.DataFrame, level: float = 0.99) -> pd.DataFrame:
    """Per run: the crack length at the judged snapshot, at t = 2 s, and the longest at any snapshot up to the
    judged one (mm, at phi_open = ``level``); the label at L_MIN under the judged and the longest length; the
    largest damage at the judged snapshot."""
    col = f"L_{level}"
    rows = []
    for key, g in df.groupby("key", sort=True):
        g = g.sort_values("t")
        tc = float(g["t_classified"].iloc[0])
        upto = g[g["t"] <= tc + 1e-9]
        judged = upto.iloc[-1]
        at2 = g[np.isclose(g["t"], 2.0)]
        rows.append({"key": key, "cement": judged["cement"], "eta_o": judged["eta_o"], "l_d": judged["l_d"],
                     "t_judged": tc, "L_judged": judged[col], "L_2s": float(at2[col].iloc[0]) if len(at2) else np.nan,
                     "L_longest": float(upto[col].max()), "d_max_judged": judged["d_max"],
                     "fracturing_judged": bool(judged[col] > L_MIN), "fracturing_longest": bool(upto[col].max() > L_MIN)})
    return pd.DataFrame(rows)


def _markdown(df: pd.DataFrame) -> str:
    cell = lambda v: f"{v:.3g}" if isinstance(v, float) else str(v)  # noqa: E731
    lines = ["| " + " | ".join(df.columns) + " |", "|" + "---|" * len(df.columns)]
    lines += ["| " + " | ".join(cell(v) for v in row) + " |" for row in df.itertuples(index=False)]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("campaign_dir", type=Path)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--summary", type=Path, default=None, help="also write the per-run summary (Markdown)")
    a = ap.parse_args(argv)
    rows = []
    for d in sorted((a.campaign_dir / "runs").iterdir()):
        rec = d / "record.json"
        if d.name.startswith(".") or not rec.is_file():
            continue
        r = json.loads(rec.read_text())
        if r.get("status") == "ok" and "pruned" not in r:  # a pruned run has lost its history
            rows += run_history(d)
    df = pd.DataFrame(rows)
    if a.out.is_file():  # rows of runs no longer in full (pruned since) are kept from the last pass
        old = pd.read_csv(a.out)
        df = pd.concat([old[~old["key"].isin(set(df.get("key", [])))], df], ignore_index=True)
    df.sort_values(["key", "t"]).to_csv(a.out, index=False, float_format="%.6g")
    print(f"{len(df)} snapshots of {df['key'].nunique()} runs -> {a.out}")
    if a.summary is not None:
        a.summary.write_text(_markdown(summary(df)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
