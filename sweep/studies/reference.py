"""Figures and the ours-vs-paper table of a reference run (Sec. 3.5) and of a mesh-convergence set (Sec. 3.4).

    dchfrac report reference RUN_DIR --out results/reference
    dchfrac report convergence RUN_DIR [RUN_DIR ...] --out results/convergence

Paper figures compared (``shared/data/paper_reported.toml``, ``[reference_experiment]``):
peak injection pressure, plateau onset, front radius at 2 s, number of main
cracks and their length.  Units mm, s, kPa.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from sweep.campaign.figures import DIVERGING, save_figure
from sweep.paper import paper_reported

def _figure(nrows=1, ncols=1, size=(6, 4.5)):
    from matplotlib.figure import Figure

    fig = Figure(figsize=size, dpi=110)
    axes = fig.subplots(nrows, ncols, squeeze=False)
    return fig, axes




def plateau_onset(t: np.ndarray, p: np.ndarray, fraction: float = 0.3) -> float:
    """Time (s) after which the injection-pressure rate stays below ``fraction`` of its mid-run slope.

    The paper describes the simulated curve as rising linearly, then a plateau
    from about 1.7 s.  The reference slope is the least-squares slope of p(t)
    over the middle third of the run; NaN when the rate never drops that far.
    """
    t, p = np.asarray(t, float), np.asarray(p, float)
    if len(t) < 6:
        return float("nan")
    mid = (t > t[-1] / 3) & (t < 2 * t[-1] / 3)
    if mid.sum() < 2:
        return float("nan")
    slope = np.polyfit(t[mid], p[mid], 1)[0]
    # smooth the rate over ~0.1 s windows
    grid = np.linspace(t[0], t[-1], 200)
    pg = np.interp(grid, t, p)
    rate = np.gradient(pg, grid)
    k = max(1, int(0.1 / (grid[1] - grid[0])))
    rate = np.convolve(rate, np.ones(k) / k, mode="same")
    below = rate < fraction * slope
    if not below[-1]:
        return float("nan")
    i = len(below) - 1
    while i > 0 and below[i - 1]:
        i -= 1
    return float(grid[i]) if grid[i] < grid[-1] - 1e-9 else float("nan")


def _tri_plot(ax, pts, tri, values, title, cmap="viridis", S=None, vmin=None, vmax=None, r_outer=None):
    """One field map (x, y in mm) with its colorbar; the diverging map is centred at zero."""
    from matplotlib.tri import Triangulation

    T = Triangulation(pts[:, 0], pts[:, 1], tri)
    if cmap == DIVERGING and vmin is None and vmax is None:  # white at zero
        m = float(np.nanmax(np.abs(values))) or 1.0
        vmin, vmax = -m, m
    if len(values) == len(tri):
        im = ax.tripcolor(T, facecolors=values, cmap=cmap, vmin=vmin, vmax=vmax, shading="flat")
    else:
        im = ax.tripcolor(T, values, cmap=cmap, vmin=vmin, vmax=vmax, shading="gouraud")
    if S is not None:
        ax.tricontour(T, S, levels=[0.5], colors="white", linewidths=1.2)
    ax.set_aspect("equal")
    ax.set_title(title, fontsize=9)
    ax.set_xticks([])
    ax.set_yticks([])
    ax.figure.colorbar(im, ax=ax, shrink=0.8)


def reference_report(run_dir, out_dir, paper_path=None) -> dict:
    """Write the reference-run figures and ``comparison.md``/``comparison.json`` into ``out_dir``.

    Returns {"meta": run status, t reached (s), wall time (s), regime; "table": the ours-vs-paper rows}."""
    from solver.output import load_run
    from sweep.regimes.classify import classify_fields

    run_dir, out = Path(run_dir), Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    ts = pd.read_csv(run_dir / "timeseries.csv")
    summary = json.loads((run_dir / "summary.json").read_text())
    pts, tri, snaps = load_run(run_dir)
    paper = paper_reported(paper_path)["reference_experiment"]
    _plot_injection_pressure(ts, paper, out)
    _plot_fields(pts, tri, snaps, out)
    t_last, f_last = snaps[-1]
    c = classify_fields(pts, tri, f_last["S"], f_last["phi"], r_inner=5.0, r_outer=53.0)
    rows = _comparison_rows(ts, c, paper)
    table = pd.DataFrame(rows, columns=["quantity", "paper", "dchfrac", "how measured"])
    table["t_compared_s"] = t_last
    meta = {"run_dir": str(run_dir), "status": summary.get("status"), "t_reached": summary.get("t_reached"),
            "wall_time_s": summary.get("wall_time_s"), "regime": c.regime}
    _write_comparison(out, rows, table, meta, ts)
    return {"meta": meta, "table": table}


def _plot_injection_pressure(ts: pd.DataFrame, paper: dict, out: Path) -> None:
    """injection_pressure.png: p_inj (kPa) against t (s) with the paper's peak and plateau onset, and p_inj
    beside the mean damage, each over its maximum (Fig. injection-pressure, Appendix B)."""
    fig, ax = _figure(1, 2, (11, 4))
    ax[0, 0].plot(ts["t"], ts["p_inj"], "k-", label="dchfrac")
    ax[0, 0].axhline(paper["peak_injection_pressure"], color="tab:red", ls="--", label="paper peak 470 kPa")
    ax[0, 0].axvline(paper["pressure_plateau_onset"], color="tab:red", ls=":", label="paper plateau onset 1.7 s")
    ax[0, 0].set_xlabel("t (s)")
    ax[0, 0].set_ylabel("injection pressure (kPa)")
    ax[0, 0].legend(fontsize=8)
    ax[0, 1].plot(ts["t"], ts["p_inj"] / max(ts["p_inj"].max(), 1e-12), label="p_inj / max")
    ax[0, 1].plot(ts["t"], ts["mean_damage"] / max(ts["mean_damage"].max(), 1e-12), label="mean damage / max")
    ax[0, 1].set_xlabel("t (s)")
    ax[0, 1].set_ylabel("fraction of the run's maximum (-)")
    ax[0, 1].legend(fontsize=8)
    ax[0, 1].set_title("Appendix B: injection pressure vs mean damage", fontsize=9)
    fig.tight_layout()
    save_figure(fig, out / "injection_pressure.png")


def _plot_fields(pts, tri, snaps, out: Path) -> None:
    """fields.png (porosity first and last, damage, saturation, volumetric strain, pressure in kPa) and
    supplementary_fields.png (hoop stress in kPa, log10 permeability in mm², water flux in mm/s), last
    snapshot with the S = 0.5 front in white."""
    t_last, f_last = snaps[-1]
    f_first = snaps[0][1]
    fig, ax = _figure(2, 3, (15, 9.5))
    _tri_plot(ax[0, 0], pts, tri, f_first["phi"], f"porosity φ (-), t = {snaps[0][0]:.2g} s", cmap="cividis", vmin=0, vmax=1)
    _tri_plot(ax[0, 1], pts, tri, f_last["phi"], f"porosity φ (-), t = {t_last:.3g} s (S = 0.5 white)", cmap="cividis", S=f_last["S"], vmin=0, vmax=1)
    _tri_plot(ax[0, 2], pts, tri, f_last["d"], f"damage d (-), t = {t_last:.3g} s", cmap="magma", S=f_last["S"], vmin=0, vmax=1)
    _tri_plot(ax[1, 0], pts, tri, f_last["S"], f"saturation S (-), t = {t_last:.3g} s", cmap="Blues", S=f_last["S"], vmin=0, vmax=1)
    _tri_plot(ax[1, 1], pts, tri, f_last["eps_v"], "volumetric strain ε_v (-)", cmap=DIVERGING, S=f_last["S"])
    _tri_plot(ax[1, 2], pts, tri, f_last["p"], "pressure p (kPa)", cmap="plasma", S=f_last["S"])
    fig.tight_layout()
    save_figure(fig, out / "fields.png")
    fig, ax = _figure(1, 3, (15, 4.8))
    _tri_plot(ax[0, 0], pts, tri, f_last["hoop_stress"], "hoop stress σ'θθ (kPa)", cmap=DIVERGING, S=f_last["S"])
    _tri_plot(ax[0, 1], pts, tri, np.log10(f_last["k"]), "log10 permeability (mm²)", cmap="viridis", S=f_last["S"])
    _tri_plot(ax[0, 2], pts, tri, f_last["w1_mag"], "|w_water| (mm/s)", cmap="inferno", S=f_last["S"])
    fig.tight_layout()
    save_figure(fig, out / "supplementary_fields.png")


def _comparison_rows(ts: pd.DataFrame, c, paper: dict) -> list:
    """(quantity, paper's figure, ours, how measured) for each compared quantity; ``c`` is the last
    snapshot's classification (sweep.regimes.classify.classify_fields).  Units in the quantity names."""
    onset = plateau_onset(ts["t"].values, ts["p_inj"].values)
    fronts = np.asarray(c.finger_radii) if getattr(c, "finger_radii", None) is not None else np.array([])
    return [
        ("peak injection pressure (kPa)", paper["peak_injection_pressure"], float(ts["p_inj"].max()),
         "maximum of the mean inner-circle pressure"),
        ("pressure plateau onset (s)", paper["pressure_plateau_onset"], onset,
         "rate below 30 % of the mid-run slope; NaN = no plateau before the end"),
        ("front radius at 2 s, mean (mm)", paper["front_distance_simulation"], float(c.front_radius_mean),
         "angular mean of the S = 0.5 front connected to the inlet"),
        ("front radius at 2 s, main branches (mm)", paper["front_distance_simulation"],
         float(np.mean(np.sort(fronts)[-3:])) if len(fronts) else float(c.front_radius_max),
         "mean radius of the three farthest front lobes (the paper's measure)"),
        ("number of main cracks", paper["number_of_main_cracks"], int(c.n_cracks), "branches of the phi >= 0.99 region"),
        ("crack tip radius (mm)", paper["mean_crack_length"], float(c.crack_tip_radius),
         "the paper measures 'from the centre to the end of phi = 1 regions'"),
        ("crack length beyond r_i (mm)", paper["mean_crack_length"], float(c.crack_length), "tip radius - 5 mm"),
    ]


def _write_comparison(out: Path, rows: list, table: pd.DataFrame, meta: dict, ts: pd.DataFrame) -> None:
    """comparison.md (the table with the run's status), comparison.csv, comparison.json and the run's
    timeseries.csv beside them."""
    md = ["# Reference run (Sec. 3.5): dchfrac vs paper", "",
          f"Run: status {meta['status']}, t reached {meta['t_reached']} s, wall time {meta['wall_time_s']:.0f} s; "
          f"classified regime: {meta['regime']}.", "",
          "| quantity | paper | dchfrac | how measured |", "|---|---|---|---|"]
    for q, pv, ov, how in rows:
        md.append(f"| {q} | {pv} | {ov:.3g} | {how} |" if isinstance(ov, float) else f"| {q} | {pv} | {ov} | {how} |")
    md += ["", "Figures (PNG, and PDF beside): `injection_pressure.png`, `fields.png`, `supplementary_fields.png`."]
    (out / "comparison.md").write_text("\n".join(md) + "\n")
    table.to_csv(out / "comparison.csv", index=False)
    (out / "comparison.json").write_text(json.dumps({"meta": meta, "rows": table.to_dict(orient="records")}, indent=2, default=float))
    ts.to_csv(out / "timeseries.csv", index=False)


def convergence_report(run_dirs, out_dir) -> pd.DataFrame:
    """Injection pressure and maximum hoop stress against time for several mesh sizes (Fig. mesh-conv).

    Differences are quantified against the finest mesh as the maximum over the
    common time range of |q_h(t) − q_fine(t)| / max |q_fine|.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    curves = []
    for d in run_dirs:
        d = Path(d)
        opts = (d / "options.toml").read_text()
        h = float([l.split("=")[1] for l in opts.splitlines() if l.startswith("h ")][0])
        curves.append((h, pd.read_csv(d / "timeseries.csv")))
    curves.sort(key=lambda c: -c[0])
    rows = []
    fine_h, fine = curves[-1]
    for key, ylabel, fname in (("p_inj", "injection pressure (kPa)", "injection_pressure.png"),
                               ("max_hoop_stress", "maximum hoop stress (kPa)", "max_hoop_stress.png")):
        fig, ax = _figure(1, 1, (6, 4.5))
        for h, ts in curves:
            ax[0, 0].plot(ts["t"], ts[key], label=f"h = {h:g} mm")
        ax[0, 0].set_xlabel("t (s)")
        ax[0, 0].set_ylabel(ylabel)
        ax[0, 0].legend()
        fig.tight_layout()
        save_figure(fig, out / fname)
        for h, ts in curves[:-1]:
            tmax = min(ts["t"].max(), fine["t"].max())
            grid = np.linspace(0.05 * tmax, tmax, 100)
            a = np.interp(grid, ts["t"], ts[key])
            b = np.interp(grid, fine["t"], fine[key])
            rows.append({"quantity": key, "h": h, "h_ref": fine_h, "t_max": tmax,
                         "max_rel_difference": float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-12))})
    df = pd.DataFrame(rows)
    df.to_csv(out / "differences.csv", index=False)
    return df
