"""A campaign's figures, drawn from its table into ``<root>/<name>/figures/`` (PNG 200 dpi + PDF).

    plot_campaign("campaigns/examples/demo.toml")

Phase diagrams (``sweep.regimes.diagrams``), scatter plots, time series and field grids.  Diagrams from the
table need no run folder; a figure that needs run folders (time series, field maps) is not redrawn emptier
than the committed one.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Any, Mapping, Sequence

from sweep.campaign.paths import DEFAULT_ROOT, results_root
from sweep.campaign.plan import as_spec, check_intact, plan_campaign
from sweep.campaign.store import ResultsStore
from sweep.campaign.table import build_table

__all__ = ["plot_campaign"]


def _scatter(df, x, y, ax, *, by="regime", logx=False, logy=False):
    import numpy as np

    from sweep.regimes.diagrams import marker_outline, regime_style

    if by not in df.columns:
        ax.plot(df[x], df[y], "o")
    else:
        for g in dict.fromkeys(df[by].astype(object).where(df[by].notna(), None)):
            sub = df[df[by].isna()] if g is None else df[df[by] == g]
            st = regime_style(g) if by in ("regime", "fracturing") else dict(marker="o", color=None, label=str(g))
            ax.scatter(sub[x], sub[y], marker=st["marker"], color=st["color"], label=st["label"], s=45,
                       linewidth=0.4, **marker_outline(st["marker"]))
        ax.legend(fontsize=8)
    if logx:
        ax.set_xscale("log")
    if logy:
        ax.set_yscale("log")
    from sweep.campaign.figures import axis_label

    ax.set_xlabel(axis_label(x))
    ax.set_ylabel(axis_label(y))
    ax.grid(True, which="both", alpha=0.3)
    return np.asarray(df[x]).size


def _timeseries_plot(spec, store, table, g, path) -> list[Path]:
    """One curve per ok run of time-series column ``y`` against ``x``, labelled by its swept values (units)."""
    import matplotlib.pyplot as plt
    import pandas as pd

    from sweep.campaign.figures import axis_label, save_figure, swept_label

    fig, ax = plt.subplots(figsize=(6, 4))
    names = [g["by"]] if g.get("by") else list(spec.axis_names)
    missing = []
    for _, row in table[table["status"] == "ok"].iterrows():
        f = store.run_dir(row["key"]) / "timeseries.csv"
        if not f.exists():
            missing.append(row["key"])
            continue
        ts = pd.read_csv(f)
        if g["x"] in ts.columns and g["y"] in ts.columns:
            ax.plot(ts[g["x"]], ts[g["y"]], label=swept_label(row, names) or row["key"])
    ax.set_xlabel(axis_label(g["x"]))
    ax.set_ylabel(axis_label(g["y"]))
    ax.grid(True, alpha=0.3)
    if ax.lines:
        ax.legend(fontsize=7)
    ax.set_title(g.get("title", spec.name))
    if _keep_committed(path, drawn=len(ax.lines), missing=missing, why="no timeseries.csv"):
        plt.close(fig)
        return []
    paths = save_figure(fig, path)
    plt.close(fig)
    _warn_left_out(path, missing, "no timeseries.csv")
    return paths


def _keep_committed(path: Path, *, drawn: int, missing: Sequence[str], why: str) -> bool:
    """True (with a warning) when a figure would show nothing, or would replace an existing file while
    leaving runs out (their run folders are archived): the existing figure is kept."""
    if drawn and not (missing and path.is_file()):
        return False
    kept = "kept as it is" if path.is_file() else "not drawn"
    print(f"warning: {path.name} {kept}: {len(missing)} of {drawn + len(missing)} run(s) have {why} here "
          f"(pruned or archived run folders)", file=sys.stderr)
    return True


def _warn_left_out(path: Path, keys: Sequence[str], why: str) -> None:
    """Say on stderr which finished runs a figure does not show."""
    if keys:
        print(f"warning: {path.name} leaves out {len(keys)} run(s) ({why}): {' '.join(keys)}", file=sys.stderr)


def _snapshot(run_dir: Path, time_s=None):
    import numpy as np

    snaps = sorted((run_dir / "snapshots").glob("snap_*.npz"))
    mesh = run_dir / "snapshots" / "mesh.npz"
    if not snaps or not mesh.exists():
        return None
    if time_s is not None:
        ts = [float(np.load(s)["t"]) for s in snaps]
        snap = snaps[int(np.argmin([abs(t - time_s) for t in ts]))]
    else:
        snap = snaps[-1]
    m, s = np.load(mesh), np.load(snap)
    return m["points"], m["triangles"], s


def _field_rows(spec, ok, rows_col):
    """[(row label, rows of the table)] of a fields grid: one per spec block, per value of a column, or one."""
    from sweep.campaign.figures import value_label

    if rows_col == "blocks":
        rows = []
        for b in spec.blocks:
            sub = ok[ok["blocks"].fillna("").astype(str).str.split(";").apply(lambda ls, lab=b.label: lab in ls)]
            if b.axes and b.axes[0].name in sub.columns:
                sub = sub.sort_values(b.axes[0].name, kind="stable")
            rows.append((b.label if len(spec.blocks) > 1 else "", sub))
        return rows
    if rows_col in ok.columns:
        return [(value_label(rows_col, v), ok[ok[rows_col] == v]) for v in dict.fromkeys(ok[rows_col])]
    return [("", ok)]


def _fields_plot(spec, store, table, g, path) -> list[Path]:
    """Grid of field maps (last snapshot, or the one nearest ``time`` s) with the S = 0.5 front in white.

    rows: "blocks" (default: one row per spec block, runs ordered by the block's first axis) or a
    table column; cols: a table column giving the column order (default: run order in the row).
    Every panel shares one colour scale (diverging and centred at zero for a field with both signs),
    shown by one colorbar; row labels on the left, panel titles give the other swept values.
    """
    import matplotlib.pyplot as plt

    from solver.output import SNAPSHOT_FIELDS
    from sweep.campaign.figures import axis_label, colour_scale, save_figure, swept_label

    ok = table[table["status"] == "ok"].sort_values("index")
    rows_col, cols_col = g.get("rows", "blocks"), g.get("cols")
    rows = _field_rows(spec, ok, rows_col)
    cvals = sorted(dict.fromkeys(ok[cols_col])) if cols_col and cols_col in ok.columns else None
    ncols = max(1, len(cvals) if cvals else max((len(sub) for _, sub in rows), default=1))
    panels, missing = [], []
    for i, (_, sub) in enumerate(rows):
        for j, (_, row) in enumerate(sub.iterrows()):
            snap = _snapshot(store.run_dir(row["key"]), g.get("time"))
            if snap is not None and g["field"] in snap[2]:
                panels.append((i, cvals.index(row[cols_col]) if cvals else j, row, snap))
            else:
                missing.append(row["key"])
    if _keep_committed(path, drawn=len(panels), missing=missing, why=f"no snapshot with {g['field']}"):
        return []
    cmap, vmin, vmax = colour_scale(g["field"], [s[g["field"]] for *_, (_, _, s) in panels],
                                    fixed=(0.0, 1.0) if g["field"] in ("phi", "d", "S") else None)
    fig, axes = plt.subplots(len(rows), ncols, figsize=(3 * ncols + 0.8, 3 * len(rows)), squeeze=False)
    for ax in axes.ravel():
        ax.set_axis_off()
    others = [a for a in spec.axis_names if a != rows_col]
    im = None
    for i, j, row, (pts, tri, s) in panels:
        ax = axes[i, j]
        vals = s[g["field"]]
        shading = "flat" if len(vals) == len(tri) else "gouraud"
        im = ax.tripcolor(pts[:, 0], pts[:, 1], tri, vals, shading=shading, cmap=cmap, vmin=vmin, vmax=vmax)
        if "S" in s and len(s["S"]) == len(pts):
            ax.tricontour(pts[:, 0], pts[:, 1], tri, s["S"], levels=[0.5], colors="w", linewidths=0.8)
        ax.set_aspect("equal")
        ax.set_title("\n".join(x for x in (swept_label(row, others), f"t = {float(s['t']):.2f} s") if x), fontsize=7)
    for i, (rlabel, _) in enumerate(rows):
        if rlabel:
            axes[i, 0].annotate(rlabel, xy=(-0.08, 0.5), xycoords="axes fraction", rotation=90, ha="right",
                                va="center", fontsize=8)
    if im is not None:
        unit = SNAPSHOT_FIELDS.get(g["field"], ("",))[0]
        fig.colorbar(im, ax=axes.ravel().tolist(), shrink=0.8, label=axis_label(g["field"]) if unit else g["field"])
    fig.suptitle(g.get("title", f"{spec.name}: {g['field']}"))
    paths = save_figure(fig, path)
    plt.close(fig)
    _warn_left_out(path, missing, f"no snapshot with {g['field']}")
    return paths


def _phase_diagram(spec, table, g, path) -> list[Path]:
    """The paper's diagrams through sweep.regimes.diagrams (ok runs only); PNG (+ the diagram's formats)."""
    from sweep.campaign.replicates import point_columns, replicate_count
    from sweep.regimes import diagrams as dg

    ok = table[table["status"] == "ok"]
    kind = g["kind"]
    kw: dict[str, Any] = {"title": g.get("title", f"{spec.name}")}
    kw["formats"] = tuple(g.get("formats", ("pdf",)))  # PNG + PDF, as every campaign figure
    if kind == "ca_star_vs_cement":
        need = ("cement", "Ca_star", "fracturing")
        if "fit" in g:
            kw["fit"] = bool(g["fit"])
        fn = dg.plot_ca_star_vs_cement
    else:
        need = ("N_b", "N_f", "regime")
        for k in ("experimental_range", "shade"):
            if k in g:
                kw[k] = g[k]
        if "dp_cri" in ok.columns and len(ok):
            kw["dp_cri"] = float(ok["dp_cri"].iloc[0])
        fn = dg.plot_nf_vs_nb
    fn, kw = _replicated_diagram(spec, kind, fn, kw)
    if ok.empty or any(c not in ok.columns for c in need):
        return []
    if replicate_count(spec) > 1:   # a point as in points.csv: distinct points can share (C, Ca*) or (N_b, N_f)
        kw["by"] = point_columns(ok, spec.axis_names)[1]
    res = fn(ok.reset_index(drop=True), path, **kw)
    _warn_left_out(path, _run_names(ok, res["dropped"]),
                   f"no value of {'/'.join(need)}: unlabelled, or a number not computed")
    paths = res.get("paths") if isinstance(res, Mapping) else None
    return [Path(p) for p in paths] if paths else [path]


def _run_names(ok, positions) -> list[str]:
    """Keys of the rows at ``positions`` of ``ok`` (the runs a phase diagram left out), else "row i"."""
    if "key" in ok.columns:
        return [str(k) for k in ok["key"].to_numpy()[list(positions)]]
    return [f"row {ok.index[i]}" for i in positions]


def _boundary_figure(spec, store: ResultsStore, table):
    """The boundary sampler's figure (``figures/boundary.png``: classifier, 50 % line, band, runs by
    order) and the table with an ``order`` column (the order the sampler chose each run)."""
    import pandas as pd

    from sweep.regimes import diagrams as dg
    from sweep.campaign.boundary import BoundarySampler
    from sweep.regimes.regime_model import boundary_band
    from sweep.campaign.spec import round_sig

    st = BoundarySampler().replay(spec, table)
    names = list(spec.axis_names)
    pts = pd.DataFrame(st.to_dict(st.model.axes if st.model else ())["points"]) if st.model else None
    if pts is None or len(names) != 2:
        return [], table
    order = {tuple(round_sig(float(v), 10) for v in r[names]): r["order"] for _, r in pts.iterrows()}
    table = table.copy()
    table["order"] = [order.get(tuple(round_sig(float(v), 10) for v in row), math.nan) for row in table[names].to_numpy()]
    unc = "?" if not math.isfinite(st.uncertainty) else f"{st.uncertainty:.2f}"
    title = (f"{spec.name}: {st.runs_used}/{st.budget} runs in {len(st.rounds)} rounds, boundary band "
             f"half-width {unc} x tolerance\n" + (st.reason if st.stopped else "running"))
    from sweep.campaign.figures import axis_label

    labels = [axis_label(a.name) + (" (log axis)" if a.log else "") for a in st.model.axes]
    res = dg.plot_boundary_sampling(st.model, pts, store.figures_dir / "boundary.png", band=boundary_band(st.model),
                                    title=title, formats=("pdf",), axis_labels=labels)
    return [Path(p) for p in res["paths"]], table


def plot_campaign(spec, root=DEFAULT_ROOT, *, code_hash: str | None = None, table=None,
                  allow_damaged: bool = False) -> list[Path]:
    """Draw the spec's diagrams from the campaign table into ``<root>/<name>/figures/``.

    Without ``table``, the stored runs are verified first: DamagedRunsError names the damaged ones
    unless ``allow_damaged`` (then they are left out of the figures, with a warning).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sweep.campaign.figures import save_figure

    spec = as_spec(spec)
    root = results_root(spec, root)
    store = ResultsStore(root, spec.name)
    if table is None:
        plan = plan_campaign(spec, root, code_hash=code_hash)
        check_intact(plan, allow_damaged)
        table = build_table(spec, root, plan=plan)
    store.figures_dir.mkdir(parents=True, exist_ok=True)
    out = []
    if table.empty:
        return out
    if spec.sampler["kind"] == "boundary":
        figs, table = _boundary_figure(spec, store, table)
        out.extend(figs)
    for i, g in enumerate(spec.diagrams):
        kind = g["kind"]
        path = store.figures_dir / g.get("file", f"{kind}.png" if sum(d["kind"] == kind for d in spec.diagrams) == 1 else f"{kind}_{i}.png")
        if kind in ("ca_star_vs_cement", "nf_vs_nb"):
            out.extend(_phase_diagram(spec, table, g, path))
        elif kind == "scatter":
            if g["x"] not in table.columns or g["y"] not in table.columns:
                continue
            fig, ax = plt.subplots(figsize=(5, 4))
            _scatter(table, g["x"], g["y"], ax, by=g.get("color", "regime"), logx=g.get("logx", False), logy=g.get("logy", False))
            ax.set_title(g.get("title", spec.name))
            out.extend(save_figure(fig, path))
            plt.close(fig)
        elif kind == "timeseries":
            out.extend(_timeseries_plot(spec, store, table, g, path))
        elif kind == "fields":
            out.extend(_fields_plot(spec, store, table, g, path))
    return out


def _replicated_diagram(spec, kind, fn, kw):
    """With ``[replicates]``, the diagrams of label probabilities (sweep.regimes.probability) replace the one-run-per-
    point diagrams: (function, keyword arguments)."""
    from sweep.campaign.replicates import replicate_count
    from sweep.regimes import probability as pr

    if replicate_count(spec) == 1:
        return fn, kw
    keep = {"title", "formats"} | ({"dp_cri"} if kind == "nf_vs_nb" else set())
    return (pr.plot_probability_diagram if kind == "ca_star_vs_cement" else pr.plot_nf_vs_nb_probabilities,
            {k: v for k, v in kw.items() if k in keep})
