"""The crack over a run's life: the classifier's crack at every snapshot, and the separatrix with each run
labelled by its longest crack up to the judged time (a sensitivity of the label, never a protocol's verdict).

``dchfrac cracks history STORE/CAMPAIGN --out crack_history.csv [--summary crack_summary.md]``: for each finished
run of a campaign store with its full snapshots (a run pruned by ``dchfrac campaign prune`` has lost them: its rows
are kept from an earlier pass, if ``--out`` holds them) and each snapshot after t = 0, one row: the run's key and
swept values, the snapshot time t (s), the crack length L (mm, ``sweep.regimes.classify`` rule 1: the
phi >= phi_open region connected to the cavity, beyond r_i) at each phi_open of PHI_OPEN, the number of cracks at
phi_open = 0.99 and L_min = 4 mm, the largest damage d, and, in the elements of the phi >= 0.99 crack region, the
range of the damage (element mean of d) and of the volumetric strain eps_v, the largest porosity, and the time the
run was classified at; ``--summary``: per run, the judged, the 2 s and the longest crack (:func:`summary`).

``dchfrac cracks separatrix FOLDER --l-min 3 4 5 --out F.json [--md F.md]``: the boundary campaigns label a run by
its crack at the snapshot where the front reached 45 mm; the cracks close after about 2 s
(results/fidelity/crack_closure.md).  This relabels each run of a results folder (``runs/`` with each run's
timeseries.csv and params.toml, ``crack_history.csv``, ``table.csv``) by the longest crack (mm) at or before the
judged time, read two ways: ``steps`` (every accepted step, phi_open = 0.99: ``open_tip_radius - r_inner``,
solver.metrics.open_tip_radius) and ``snapshots`` (the classifier's crack on the stored snapshots at each phi_open
of the history), and fits Ca*_c = A exp(B C) at each (phi_open, L_min) with the protocol's fit
(``sweep.studies.threshold_sensitivity.separatrix_grid``).  ``--steps-out F.csv`` also writes the steps' lengths
per run (key, ``L@0.99``, ``t_longest``, ``t_judged``); committed as FOLDER/``longest_crack_steps.csv``
(:data:`STEPS_CSV`), it stands in for ``runs/`` in a results folder that does not keep its runs, so that the fits
regenerate from committed files alone.

Units: mm, s, C in %; d, phi, eps_v dimensionless.
"""
from __future__ import annotations

import json
import sys
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd

from solver.output import atomic_write_text
from sweep.regimes.classify import classify_fields, list_snapshots, longest_open_crack
from sweep.studies.threshold_sensitivity import ThresholdGrid, separatrix_grid, to_markdown

__all__ = ["PHI_OPEN", "L_MIN", "snapshot_row", "run_history", "summary", "summary_markdown",
           "longest_from_snapshots", "longest_from_steps", "longest_crack_separatrix", "STEPS_CSV", "STEPS_COLUMNS"]

PHI_OPEN = (0.95, 0.99, 0.995)
L_MIN = 4.0  # mm, the boundary campaigns' threshold
STEPS_CSV = "longest_crack_steps.csv"  # the steps' longest crack per run, where a results folder keeps no runs/
STEPS_COLUMNS = ["key", "L@0.99", "t_longest", "t_judged"]


def snapshot_row(points, tris, r_i, r_o, z) -> dict:
    """One snapshot ``z`` (fields S, phi, d, eps_v, t) on the mesh (points mm, triangles): the row described in
    the module docstring; r_i, r_o the annulus radii (mm)."""
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
            rows.append({**base, **snapshot_row(points, tris, p["r_inner"], p["r_outer"], z)})
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


def summary_markdown(df: pd.DataFrame) -> str:
    """:func:`summary` as a Markdown table."""
    cell = lambda v: f"{v:.3g}" if isinstance(v, float) else str(v)  # noqa: E731
    lines = ["| " + " | ".join(df.columns) + " |", "|" + "---|" * len(df.columns)]
    lines += ["| " + " | ".join(cell(v) for v in row) + " |" for row in df.itertuples(index=False)]
    return "\n".join(lines) + "\n"


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
    t <= the judged time (``sweep.regimes.classify.longest_open_crack``), and the time it was reached (s).  Read
    from the runs' time series in FOLDER/runs, or, in a folder without runs/, from FOLDER/:data:`STEPS_CSV`."""
    if not (folder / "runs").is_dir():
        return _steps_from_csv(folder / STEPS_CSV, table)
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


def _steps_from_csv(path: Path, table: pd.DataFrame) -> pd.DataFrame:
    """The steps' lengths of every finished run of ``table`` from ``path`` (:data:`STEPS_COLUMNS`)."""
    steps = pd.read_csv(path, dtype={"key": str}).set_index("key")
    missing = sorted(set(table.index) - set(steps.index))
    if missing:
        raise ValueError(f"{path}: no rows for the finished runs {missing}")
    return steps.loc[table.index, STEPS_COLUMNS[1:]]


def _with_axes(lengths: pd.DataFrame, table: pd.DataFrame) -> pd.DataFrame:
    out = lengths.copy()
    out["cement"] = table.loc[out.index, "cement"].astype(float)
    out["Ca_star"] = table.loc[out.index, "Ca_star"].astype(float)
    return out.rename_axis("key").reset_index()


def longest_crack_separatrix(folder: Path, l_min, table_csv: Path | None = None,
                             steps_out: Path | None = None) -> tuple[dict, str]:
    """The separatrix fits with the longest crack read over the steps and over the snapshots: (JSON document,
    Markdown).  ``steps_out``: where to write the steps' lengths per run (CSV, :data:`STEPS_COLUMNS`)."""
    table = _finished(folder, table_csv)
    steps = longest_from_steps(folder, table)
    if steps_out is not None:
        atomic_write_text(steps_out, steps.rename_axis("key").reset_index()[STEPS_COLUMNS]
                          .to_csv(index=False, float_format="%.17g"))
    doc, md = {"label": "the longest crack at or before the judged time"}, []
    for name, lengths in (("steps", steps), ("snapshots", longest_from_snapshots(folder, table))):
        lengths = _with_axes(lengths, table)
        levels = tuple(float(c[2:]) for c in lengths.columns if c.startswith("L@"))
        fits = separatrix_grid(lengths, ThresholdGrid(phi_open=levels, l_min=tuple(l_min)))
        doc[name] = {"fits": fits, "lengths": lengths.to_dict(orient="records")}
        md += [f"## Longest crack over the {name}", "", to_markdown(fits, lengths)]
    return doc, "\n".join(md)


def _history_rows(campaign_dir: Path) -> list[dict]:
    rows = []
    for d in sorted((campaign_dir / "runs").iterdir()):
        rec = d / "record.json"
        if d.name.startswith(".") or not rec.is_file():
            continue
        r = json.loads(rec.read_text())
        if r.get("status") == "ok" and "pruned" not in r:  # a pruned run has lost its history
            rows += run_history(d)
    return rows


def cmd_history(a) -> int:
    if not (a.campaign_dir / "runs").is_dir():
        print(f"dchfrac cracks history: {a.campaign_dir}: no runs/ folder (allowed: a campaign store's folder with "
              "its run folders)", file=sys.stderr)
        return 2
    df = pd.DataFrame(_history_rows(a.campaign_dir))
    if a.out.is_file():  # rows of runs no longer in full (pruned since) are kept from the last pass
        old = pd.read_csv(a.out)
        df = pd.concat([old[~old["key"].isin(set(df.get("key", [])))], df], ignore_index=True)
    atomic_write_text(a.out, df.sort_values(["key", "t"]).to_csv(index=False, float_format="%.6g"))
    print(f"{len(df)} snapshots of {df['key'].nunique()} runs -> {a.out}")
    if a.summary is not None:
        atomic_write_text(a.summary, summary_markdown(summary(df)))
    return 0


def cmd_separatrix(a) -> int:
    missing = [need for need, ok in (("crack_history.csv", (a.folder / "crack_history.csv").is_file()),
                                     (f"runs/ or {STEPS_CSV}",
                                      (a.folder / "runs").is_dir() or (a.folder / STEPS_CSV).is_file())) if not ok]
    for need in missing:
        print(f"dchfrac cracks separatrix: {a.folder}: no {need} (allowed: a boundary campaign's results folder "
              f"with crack_history.csv and runs/ or {STEPS_CSV})", file=sys.stderr)
    if missing:
        return 2
    doc, md = longest_crack_separatrix(a.folder, a.l_min, a.table, a.steps_out)
    atomic_write_text(a.out, json.dumps(doc, indent=1))
    if a.md:
        atomic_write_text(a.md, md)
    return 0
