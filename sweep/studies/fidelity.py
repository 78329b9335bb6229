"""Fidelity study of the reference experiment (Sec. 3.5): which model ingredient lets the water bypass the oil.

Runs named variants of the paper's model (``VARIANTS``: parameter changes of one hypothesis each) and measures,
from each run folder, the figures of the root-cause study (``results/fidelity/``):

* outflow through r_o as a fraction of the injected volume at 1 and 2 s (total and invading fluid);
* the fluid-volume budget: stored volume against its grain-compressibility part (1 − φ0) ∫ p/K_s;
* S and p along a ray (θ = 0) at 0.5 and 2 s;
* p_inj(t), the front at 2 s (angular mean and mean of the three main branches), the open-crack tip radius;
* where the invading fluid is at 1 and 2 s (:func:`water_placement`: the radii holding 50 and 90 % of it, the
  fraction in the outer 10 mm, the fraction connected to the inlet);
* d ln p_inj / d ln η_o at 1 s, from a second run with η_o doubled.

Units mm, s, kPa.  Usage::

    python -m sweep.studies.fidelity run --h 2 --out /path/to/runs [--only NAME ...] [--jobs 2]
    python -m sweep.studies.fidelity table --h 2 --out /path/to/runs --json results/fidelity/screen_h2.json \
        --md results/fidelity/screen_h2.md
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np
import pandas as pd

#: The experiment's injection rate (Sec. 3.5: 100 mL/min) as a Darcy velocity on the inner circle of the
#: 2D model: q / (h_cell 2π r_i) with h_cell = 1.96 mm, r_i = 5 mm, mm/s (the paper's model uses 50, tuned).
EXPERIMENT_W_I = 100e3 / 60.0 / (1.96 * 2 * math.pi * 5.0)
_REAL_RATE = {"w_i": round(EXPERIMENT_W_I, 3)}
_OIL = {"ch_mobility": "oil"}
_DEFENDING = {"outer_saturation_bc": "defending_outflow", "mu_outer_bc": "zero_flux"}
_UPWIND = {"transport": "upwind"}
_SUPG = {"transport": "supg"}
_GRADED = {"h_outer": 0.25}  # mm: the boundary layer at the drained outer wall resolved

#: Hypotheses of the study: parameter changes from the paper's model (Sec. 3.5 defaults) and run-option
#: changes (discretization), each ``name: (params, options)``.
VARIANTS: dict[str, tuple[dict, dict]] = {
    "paper": ({}, {}),
    "a_mobility_oil": (_OIL, {}),
    "a_mobility_degenerate": ({"ch_mobility": "degenerate"}, {}),
    "d_mu_zero_flux": ({"mu_outer_bc": "zero_flux"}, {}),
    "d_mu_o_0.006": ({"mu_o": 0.006}, {}),
    "d_defending_outflow": (_DEFENDING, {}),
    "e_kbar_mean_k": ({"kbar": 0.0046}, {}),
    "c_upwind": ({}, _UPWIND),
    "ac_oil_upwind": (_OIL, _UPWIND),
    "c_supg": ({}, _SUPG),
    "ac_oil_supg": (_OIL, _SUPG),
    "dc_defending_upwind": (_DEFENDING, _UPWIND),
    "adc_oil_defending_upwind": ({**_OIL, **_DEFENDING}, _UPWIND),
    "f_graded": ({}, _GRADED),
    "fg_real_rate_graded": (_REAL_RATE, _GRADED),
    "fd_mu_zero_flux_graded": ({"mu_outer_bc": "zero_flux"}, _GRADED),
    "fc_supg_graded": ({}, {**_GRADED, **_SUPG}),
    "g_real_rate": (_REAL_RATE, {}),
    "g_real_rate_mu_zero_flux": ({**_REAL_RATE, "mu_outer_bc": "zero_flux"}, {}),
    "g_real_rate_defending_upwind": ({**_REAL_RATE, **_DEFENDING}, _UPWIND),
}

SNAPSHOT_TIMES = (0.5, 1.0, 2.0)
ETA_FACTOR = 2.0  # η_o multiplier of the elasticity run
ELASTICITY_TIME = 1.0  # s


def run_variant(name: str, h: float, out: Path, eta_factor: float = 1.0, t_end: float = 2.0) -> Path:
    """Run variant ``name`` at mesh size ``h`` (mm) into ``out/<name>[_eta2]``; returns the run folder."""
    from solver import Parameters, RunOptions, simulate

    changes, opts = VARIANTS[name]
    base = Parameters(**changes)
    params = base.replace(eta_o=base.eta_o * eta_factor)
    tag = name if eta_factor == 1.0 else f"{name}_eta{eta_factor:g}"
    run_dir = out / tag
    if (run_dir / "summary.json").exists():
        return run_dir
    times = [t for t in SNAPSHOT_TIMES if t <= t_end]
    simulate(params, RunOptions(h=h, t_end=t_end, snapshot_times=times, write_xdmf=False, **opts), out_dir=run_dir)
    return run_dir


def _snapshots(run_dir: Path) -> dict:
    mesh = np.load(run_dir / "snapshots" / "mesh.npz")
    snaps = {}
    for f in sorted((run_dir / "snapshots").glob("snap_*.npz")):
        s = np.load(f)
        snaps[round(float(s["t"]), 6)] = {k: s[k] for k in s.files}
    return {"points": mesh["points"], "triangles": mesh["triangles"], "snaps": snaps}


def ray_profile(points, triangles, nodal: np.ndarray, r_inner: float, r_outer: float, n: int = 97,
                theta: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """A nodal P1 field along the ray at angle ``theta`` (rad): radii (mm) and interpolated values."""
    import matplotlib.tri as mtri

    tr = mtri.Triangulation(points[:, 0], points[:, 1], triangles)
    r = np.linspace(r_inner, r_outer, n)
    r[-1] -= 1e-9 * r_outer
    vals = mtri.LinearTriInterpolator(tr, nodal)(r * math.cos(theta), r * math.sin(theta))
    return r, np.ma.filled(vals, np.nan)


def volume_budget(snap: dict, points, triangles, params) -> dict:
    """Stored fluid volume (mm²) and its grain-compressibility part (1 − φ0) ∫ p/K_s at one snapshot.

    φ0 is recovered per element from φ = φ0 + (1 − φ0)(ε_v + p/K_s) (Eq. summary_equations_3).
    """
    from solver.fem import geometry

    area = geometry(points, triangles).areas
    pe = snap["p"][triangles].mean(axis=1)
    z = snap["eps_v"] + pe / params.K_s
    phi0 = (snap["phi"] - z) / (1.0 - z)
    return {
        "grain_compressibility": float(np.sum((1 - phi0) * pe / params.K_s * area)),
        "skeleton_strain": float(np.sum((1 - phi0) * snap["eps_v"] * area)),
        "mean_p": float(np.sum(pe * area) / area.sum()),
        "area": float(area.sum()),
    }


def water_placement(snap: dict, points, triangles, r_inner: float, r_outer: float, band: float = 10.0) -> dict:
    """Where the invading fluid is at one snapshot, without a level set or a connectivity rule.

    The invading volume per element is φ S̄ × area (mm², S clipped to [0, 1] so that a Galerkin under- or
    overshoot is not counted as fluid).  Returned: its total; ``r50`` and ``r90``, the radii (mm) inside which
    50 % and 90 % of it lie (elements ordered by centroid radius, the crossing interpolated within the element
    where it falls); ``outer_band_frac``, the fraction beyond ``r_outer − band``; and ``connected_frac``, the
    fraction held by elements whose three nodes belong to the S >= 0.5 region connected to the inlet (the
    region the front measure of the time series reads, ``solver.metrics.invaded_from_inlet``).  Two schemes
    can thus be compared on where they store the water even where their S = 0.5 fronts are not comparable.
    """
    from solver.fem import geometry
    from solver.metrics import invaded_from_inlet, mesh_edges

    x = points[triangles]
    area = geometry(points, triangles).areas
    vol = snap["phi"] * np.clip(snap["S"][triangles].mean(axis=1), 0.0, 1.0) * area
    total = float(vol.sum())
    rc = np.hypot(*x.mean(axis=1).T)
    order = np.argsort(rc)
    cum = np.cumsum(vol[order])

    def radius(q: float) -> float:
        return float(np.interp(q * total, cum, rc[order])) if total > 0 else float("nan")

    r_nodes = np.hypot(points[:, 0], points[:, 1])
    inner = np.flatnonzero(np.isclose(r_nodes, r_inner, rtol=1e-6, atol=1e-9))
    conn = invaded_from_inlet(snap["S"], mesh_edges(triangles), inner)[triangles].all(axis=1)
    frac = (lambda m: float(vol[m].sum() / total) if total > 0 else float("nan"))
    return {"invading_volume": total, "r50": radius(0.5), "r90": radius(0.9),
            "outer_band_frac": frac(rc > r_outer - band), "connected_frac": frac(conn)}


def _at(ts: pd.DataFrame, t: float, col: str) -> float:
    i = int((ts["t"] - t).abs().idxmin())
    return float(ts.at[i, col]) if abs(ts.at[i, "t"] - t) < 0.05 else float("nan")


def measure(run_dir: Path) -> dict:
    """The study's figures of one run folder (see the module docstring)."""
    from solver import Parameters

    params = Parameters.from_toml(run_dir / "params.toml")
    summary = json.loads((run_dir / "summary.json").read_text())
    ts = pd.read_csv(run_dir / "timeseries.csv")
    out = {"status": summary.get("status"), "t_final": float(ts["t"].iloc[-1]),
           "wall_s": summary.get("wall_time_s", summary.get("wall_time"))}
    for t in (1.0, 2.0):
        inj = _at(ts, t, "injected_volume")
        out[f"outflow_frac_{t:g}"] = _at(ts, t, "outflow_volume") / inj
        out[f"water_outflow_frac_{t:g}"] = _at(ts, t, "water_outflow_volume") / inj
        out[f"p_inj_{t:g}"] = _at(ts, t, "p_inj")
        out[f"stored_{t:g}"] = inj - _at(ts, t, "outflow_volume")
    out["p_inj_peak"] = float(ts["p_inj"].max())
    for col in ("front_radius_mean", "front_radius_branches", "open_tip_radius", "mean_damage", "mass_error"):
        if col in ts:
            out[f"{col}_2"] = _at(ts, 2.0, col)
    out["max_mass_error"] = float(ts["mass_error"].max())
    sn = _snapshots(run_dir)
    out["profiles"] = {}
    for t, snap in sn["snaps"].items():
        if t in (0.5, 2.0):
            r, S = ray_profile(sn["points"], sn["triangles"], snap["S"], params.r_inner, params.r_outer)
            _, p = ray_profile(sn["points"], sn["triangles"], snap["p"], params.r_inner, params.r_outer)
            out["profiles"][f"{t:g}"] = {"r": r.round(3).tolist(), "S": np.round(S, 4).tolist(),
                                         "p": np.round(p, 2).tolist()}
        if t in (1.0, 2.0):
            out[f"budget_{t:g}"] = volume_budget(snap, sn["points"], sn["triangles"], params)
            out[f"placement_{t:g}"] = water_placement(snap, sn["points"], sn["triangles"], params.r_inner,
                                                      params.r_outer)
    out["p_inj_series"] = {"t": ts["t"].round(4).tolist(), "p": ts["p_inj"].round(2).tolist()}
    return out


def elasticity(base: dict, doubled: dict, factor: float = ETA_FACTOR) -> float:
    """d ln p_inj / d ln η_o at ``ELASTICITY_TIME`` from two runs (η_o and factor·η_o)."""
    key = f"p_inj_{ELASTICITY_TIME:g}"
    return math.log(doubled[key] / base[key]) / math.log(factor)


def _run_all(args) -> None:
    from joblib import Parallel, delayed

    names = args.only or list(VARIANTS)
    for n in names:
        if n not in VARIANTS:
            raise SystemExit(f"unknown variant {n!r}; allowed: {list(VARIANTS)}")
    jobs = [(n, 1.0, 2.0) for n in names] + [(n, ETA_FACTOR, ELASTICITY_TIME) for n in names]
    Parallel(n_jobs=args.jobs)(delayed(run_variant)(n, args.h, Path(args.out), f, t) for n, f, t in jobs)


def _finished(run_dir: Path) -> bool:
    """A run folder whose run has ended (ok or failed) and wrote its time series."""
    f = run_dir / "summary.json"
    return f.exists() and (run_dir / "timeseries.csv").exists() and json.loads(f.read_text()).get("status") != "running"


def _table(args) -> None:
    out = Path(args.out)
    rows = {}
    for n in VARIANTS:
        a, b = out / n, out / f"{n}_eta{ETA_FACTOR:g}"
        if not _finished(a):
            continue
        m = measure(a)
        if _finished(b):
            m["dlnp_dlneta"] = elasticity(m, measure(b))
        rows[n] = m
    text = json.dumps({"h": args.h, "variants": {n: {"params": v[0], "options": v[1]} for n, v in VARIANTS.items()},
                       "results": rows}, indent=1)
    if args.json:
        from solver.output import atomic_write_text

        atomic_write_text(Path(args.json), text + "\n")
    table = summary_table(rows)
    print(table.to_string())
    if args.md:
        from solver.output import atomic_write_text

        atomic_write_text(Path(args.md), f"Screening at h = {args.h:g} mm (generated by `python -m sweep.studies.fidelity "
                          f"table`; units mm, s, kPa)\n\n" + markdown(table) + "\n")


#: columns of the study's table: (key of :func:`measure`, header)
TABLE_COLUMNS = (
    ("status", "status"), ("t_final", "t reached (s)"), ("outflow_frac_1", "outflow/injected 1 s"),
    ("outflow_frac_2", "outflow/injected 2 s"), ("water_outflow_frac_2", "water outflow/injected 2 s"),
    ("stored_2", "stored 2 s (mm²)"), ("grain_2", "(1-φ0)∫p/K_s 2 s (mm²)"), ("p_inj_1", "p_inj 1 s"),
    ("p_inj_2", "p_inj 2 s"), ("front_radius_mean_2", "front mean 2 s"),
    ("front_radius_branches_2", "front 3 branches 2 s"), ("open_tip_radius_2", "crack tip radius 2 s"),
    ("mean_damage_2", "mean damage 2 s"), ("r50_2", "r50 of the water 2 s"), ("r90_2", "r90 of the water 2 s"),
    ("outer_band_frac_2", "water in the outer 10 mm 2 s"), ("connected_frac_2", "water connected to the inlet 2 s"),
    ("dlnp_dlneta", "d ln p_inj/d ln η_o 1 s"),
    ("max_mass_error", "max mass error"), ("wall_s", "wall (s)"),
)


def markdown(table: pd.DataFrame) -> str:
    """A Markdown table of ``table`` (index = first column), numbers to 3 significant digits."""
    def cell(v):
        if isinstance(v, float):
            return "—" if math.isnan(v) else f"{v:.3g}"
        return "—" if v is None else str(v)

    lines = ["| variant | " + " | ".join(table.columns) + " |", "|---" * (len(table.columns) + 1) + "|"]
    lines += [f"| {i} | " + " | ".join(cell(v) for v in row) + " |" for i, row in zip(table.index, table.values)]
    return "\n".join(lines)


def summary_table(rows: dict) -> pd.DataFrame:
    """One row per variant with :data:`TABLE_COLUMNS`."""
    out = {}
    for n, r in rows.items():
        r = dict(r, grain_2=r.get("budget_2", {}).get("grain_compressibility"),
                 **{f"{k}_2": v for k, v in r.get("placement_2", {}).items()})
        out[n] = {h: r.get(k) for k, h in TABLE_COLUMNS}
    return pd.DataFrame(out).T


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sweep.studies.fidelity", description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    for name in ("run", "table"):
        s = sub.add_parser(name)
        s.add_argument("--h", type=float, default=2.0, help="mesh size, mm")
        s.add_argument("--out", required=True, help="folder of the run folders")
        if name == "run":
            s.add_argument("--only", nargs="*")
            s.add_argument("--jobs", type=int, default=2)
        else:
            s.add_argument("--json", help="write the measured figures to this JSON file")
            s.add_argument("--md", help="write the summary table to this Markdown file")
    args = ap.parse_args(argv)
    (_run_all if args.cmd == "run" else _table)(args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
