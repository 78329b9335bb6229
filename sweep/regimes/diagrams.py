"""Phase diagrams of the paper: Ca* vs cement ratio (Sec. 3.6) and N_f vs N_b (Sec. 3.8).

Matplotlib is used through the object API with the Agg canvas (no pyplot, no global
backend change). Each plot is written as PNG plus the vector formats requested
(default SVG). Inputs are pandas DataFrames with one row per run, so that the campaign
framework and the discrepancy workflow can reuse these functions.

Required columns
----------------
``plot_ca_star_vs_cement``: ``cement`` (C, %), ``Ca_star`` (-), ``fracturing`` (bool).
    Optional: ``source`` (e.g. "simulation" / "experiment"; one colour per source).
``plot_nf_vs_nb``: ``N_b`` (-), ``N_f`` (-), ``regime`` (one of sweep.regimes.classify.REGIMES).
    Optional: ``run_dir`` (run folder, for thumbnails).
Rows with missing / non-positive numbers or an unknown regime are dropped (:func:`placed_rows`, the one rule of
every phase diagram here and in ``sweep.regimes.probability``); the returned dict counts them (``n_dropped``) and
names them by their index labels in ``df`` (``dropped``).
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from sweep.figio import FIGURE_FORMATS, write_figure

from .classify import REGIMES
from .separatrix import (SEPARATRIX_P_MAX, fit_exponential_separatrix, separatrix_band, separatrix_test,
                         unlocated_reason)

__all__ = [
    "REGIME_STYLE",
    "regime_map",
    "plot_ca_star_vs_cement",
    "plot_nf_vs_nb",
    "plot_boundary_sampling",
    "regime_style",
    "placed_rows",
    "separatrix_test",
    "SEPARATRIX_P_MAX",
]

BLUE = "#1f77b4"
ORANGE = "#ff7f0e"
# marker, colour, label, shading colour (paper's symbols, Sec. 3.8)
REGIME_STYLE: dict[str, dict[str, Any]] = {
    "uniform_invasion": dict(marker="o", color=BLUE, label="uniform invasion", shade="#c6dbef"),
    "viscous_fingering": dict(marker="*", color=BLUE, label="viscous fingering", shade="#9ecae1"),
    "invasive_fracturing": dict(marker="^", color=ORANGE, label="invasive fracturing", shade="#fdd0a2"),
    "non_invasive_fracturing": dict(marker="s", color=ORANGE, label="non-invasive fracturing",
                                    shade="#fdae6b"),
    "fracturing_fingering": dict(marker="x", color=ORANGE, label="fracturing/fingering",
                                 shade="#e7cb94"),
}
# the two labels of the Ca*-C diagram (the ``fracturing`` column: True/False) in the same palette
_TWO_LABELS = {
    "fracturing": dict(marker="^", color=ORANGE, label="fracturing", shade="#fdd0a2"),
    "porous_invasion": dict(marker="o", color=BLUE, label="porous invasion (no fracture)", shade="#c6dbef"),
}
_FAILED = dict(marker="X", color="0.45", label="failed (no label)", shade="#dddddd")


def regime_style(label: Any) -> dict[str, Any]:
    """marker, color, label (words, never True/False) and shade of a regime name or a ``fracturing`` value:
    the one palette of every figure (blue: invasion without fracture, orange: fracturing; grey: no label)."""
    if label is None or (isinstance(label, float) and label != label):
        return _FAILED
    if isinstance(label, (bool, np.bool_)) or str(label) in ("True", "False"):
        return _TWO_LABELS["fracturing" if str(label) == "True" else "porous_invasion"]
    name = str(label)
    if name in REGIME_STYLE:
        return REGIME_STYLE[name]
    if name in _TWO_LABELS:
        return _TWO_LABELS[name]
    return dict(marker="d", color="0.3", label=name.replace("_", " "), shade="#eeeeee")


# fitted separatrices are drawn only when they explain the labels better than a constant fracturing rate at
# this level (likelihood-ratio test, 2 degrees of freedom: the C and ln Ca* slopes)
# --------------------------------------------------------------------------- helpers
def placed_rows(df: Any, x: str, y: str, label: str, *, log_x: bool = False, log_y: bool = True) -> np.ndarray:
    """Boolean mask of the rows of ``df`` a phase diagram places: both coordinates finite numbers, > 0 on a log
    axis (Ca*, N_b, N_f are drawn on log axes), and a label the diagram draws: for ``label == "regime"`` a regime
    the classifier names (``REGIMES``), else a truth value (True / False or 1 / 0).  Units: the columns' own."""
    import pandas as pd

    ok = np.ones(len(df), bool)
    for col, log in ((x, log_x), (y, log_y)):
        v = pd.to_numeric(df[col], errors="coerce").to_numpy(dtype=float)
        ok &= np.isfinite(v) & ((v > 0) if log else True)
    lab = df[label].to_numpy()
    if label == "regime":
        ok &= np.isin(lab.astype(str), REGIMES) & pd.notna(lab)
    else:
        ok &= np.array([isinstance(v, (bool, np.bool_)) or (isinstance(v, (int, float, np.integer, np.floating))
                                                            and v in (0, 1)) for v in lab], bool)
    return ok


def _dropped(df: Any, ok: np.ndarray) -> list:
    """Index labels of the rows of ``df`` not placed (``~ok``)."""
    return list(df.index[~ok])


def _require(df: Any, cols: Sequence[str], fn: str) -> None:
    import pandas as pd

    if not isinstance(df, pd.DataFrame):
        raise ValueError(f"df={type(df).__name__}: {fn} needs a pandas DataFrame")
    missing = [c for c in cols if c not in df.columns]
    if missing:
        raise ValueError(f"df: missing column(s) {missing} required by {fn} "
                         f"(has {list(df.columns)})")


def _new_figure(size: tuple[float, float]):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=size, dpi=150)
    FigureCanvasAgg(fig)
    return fig


def marker_outline(marker: str) -> dict:
    """A black outline for a filled marker; an unfilled one (x, +) has no edge to draw."""
    from matplotlib.markers import MarkerStyle

    return {"edgecolor": "k"} if MarkerStyle(marker).is_filled() else {}


def _save(fig, out_path: str | Path, formats: Iterable[str]) -> list[Path]:
    out = Path(out_path)
    stem = out.with_suffix("") if out.suffix.lower() in (".png", ".svg", ".pdf") else out
    stem.parent.mkdir(parents=True, exist_ok=True)
    fmts = ["png"] + [f for f in formats if f != "png"]
    bad = [f for f in fmts if f not in FIGURE_FORMATS]
    if bad:
        raise ValueError(f"formats: {bad[0]!r} not allowed; use one of {', '.join(FIGURE_FORMATS)}")
    return [write_figure(fig, stem.parent / f"{stem.name}.{f}", bbox_inches="tight") for f in fmts]


def _fmt_pm(v: float, s: float) -> str:
    if not math.isfinite(s) or s == 0:
        return f"{v:.3g}"
    return f"{v:.3g} ± {s:.2g}"


# --------------------------------------------------------------------------- Ca* vs C
#: the caption of a diagram with one run per point: what it does not show (sweep.regimes.probability draws the
#: label probabilities of a campaign with [replicates])
ONE_RUN_NOTE = ("one run per point: each label's own uncertainty (another porosity draw) is not measured; declare "
                "[replicates] for label probabilities")


def plot_ca_star_vs_cement(df: Any, out_path: str | Path, *, fit: bool = True,
                           formats: Sequence[str] = ("svg",), title: str | None = None,
                           ridge: float = 1e-3) -> dict[str, Any]:
    """Ca* vs cement ratio C (%) with the two regimes and the exponential separatrix.

    df columns: ``cement``, ``Ca_star``, ``fracturing`` (+ optional ``source``).
    Porous invasion: open circles; fracturing: filled triangles; one colour per source.
    With ``fit`` and both outcomes present, the separatrix Ca*_c = A exp(B C) is fitted
    (``fit_exponential_separatrix``) and drawn with A, B and their 1-sigma in the legend, unless the labels do
    not locate it (``unlocated_reason``: its significance is :func:`separatrix_test`, the rule of the replicated
    diagram too).
    Writes ``out_path`` as PNG plus ``formats``; returns {"paths", "fit", "band", "no_fit_reason", "n_dropped",
    "dropped"}.
    """
    _require(df, ("cement", "Ca_star", "fracturing"), "plot_ca_star_vs_cement")
    C = df["cement"].to_numpy(dtype=float)
    cs = df["Ca_star"].to_numpy(dtype=float)
    fr = df["fracturing"].to_numpy()
    ok = placed_rows(df, "cement", "Ca_star", "fracturing")
    n_drop = int((~ok).sum())
    C, cs, fr = C[ok], cs[ok], fr[ok].astype(bool)
    src = df["source"].astype(str).to_numpy()[ok] if "source" in df.columns else np.full(len(C), "simulation")

    fig = _new_figure((5.5, 4.2))
    ax = fig.add_subplot(1, 1, 1)
    colours = [ORANGE, BLUE, "#2ca02c", "#d62728", "#9467bd"]
    one = len(set(src)) == 1
    for k, s in enumerate(sorted(set(src))):
        no, yes = regime_style(False), regime_style(True)
        col_no, col_yes = (no["color"], yes["color"]) if one else (colours[k % len(colours)],) * 2
        m = src == s
        ax.scatter(C[m & ~fr], cs[m & ~fr], marker=no["marker"], facecolors="none", edgecolors=col_no,
                   label=no["label"] if one else f"{s}: {no['label']}")
        ax.scatter(C[m & fr], cs[m & fr], marker=yes["marker"], color=col_yes,
                   label=yes["label"] if one else f"{s}: {yes['label']}")
    sep, no_fit = None, None
    if fit and fr.any() and (~fr).any() and len(C) >= 3:
        try:
            sep = fit_exponential_separatrix(C, cs, fr, ridge=ridge)
        except ValueError as exc:
            no_fit = str(exc)   # said on the figure: a missing line must not look like an omission
    elif fit:
        no_fit = "both regimes are needed to fit a separatrix"
    if sep is not None:
        no_fit = unlocated_reason(sep, C, cs, fr)
        sep = None if no_fit else sep
    if no_fit:
        ax.text(0.5, -0.27, "no exponential separatrix: " + no_fit, transform=ax.transAxes, fontsize=6.5,
                va="top", ha="center", wrap=True)
    band = None
    if sep is not None:
        cc = np.linspace(C.min(), C.max(), 200) if np.ptp(C) > 0 else np.array([C[0] - 0.5, C[0] + 0.5])
        note = " (separable)" if sep.separable else ""
        ax.plot(cc, sep(cc), "k-", lw=1.5,
                label=f"Ca*$_c$ = A exp(B C){note}\nA = {_fmt_pm(sep.A, sep.sigma_A)}, "
                      f"B = {_fmt_pm(sep.B, sep.sigma_B)}")
        band = _draw_separatrix_band(ax, C, cs, fr)
    ax.text(0.5, -0.38 if no_fit else -0.30, ONE_RUN_NOTE, transform=ax.transAxes, fontsize=6, va="top",
            ha="center", color="0.35", wrap=True)
    ax.set_yscale("log")
    ax.set_xlabel("cement volume ratio C (%)")
    ax.set_ylabel("modified capillary number Ca*")
    if title:
        ax.set_title(title)
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2,
              frameon=False)
    paths = _save(fig, out_path, formats)
    return {"paths": paths, "fit": sep, "band": band, "no_fit_reason": no_fit, "n_dropped": n_drop,
            "dropped": _dropped(df, ok)}


def _draw_separatrix_band(ax, C, cs, fr, level: float = 0.95):
    """The separatrix's simultaneous ``level`` profile-likelihood band of ln Ca*_c over the sampled C
    (sweep.regimes.probability.separatrix_band: each run one Bernoulli observation), grey, clipped to half a
    decade beyond the sampled Ca*; returns the band, or None when it cannot be computed (then not drawn)."""
    try:
        band = separatrix_band(C, cs, fr, level=level)
    except ValueError:
        return None
    lim = np.log(cs.min()) - 0.5 * math.log(10.0), np.log(cs.max()) + 0.5 * math.log(10.0)
    edge_lo, edge_hi = band.edges              # an unbounded side reaches the clip
    lo, hi = (np.exp(np.clip(v, *lim)) for v in (edge_lo, edge_hi))
    clipped = bool(np.any(edge_lo < lim[0]) or np.any(edge_hi > lim[1]))
    ax.fill_between(band.C, lo, hi, color="0.5", alpha=0.3, lw=0, zorder=0,
                    label=f"{level:.0%} band of Ca*$_c$ (whole line, profile likelihood)"
                          + (", clipped" if clipped else ""))
    return band


# --------------------------------------------------------------------------- N_f vs N_b
def regime_map(log_nb: Any, log_nf: Any, regimes: Sequence[str], grid_x: Any, grid_y: Any,
               k: int = 1) -> np.ndarray:
    """Regime of each grid point by k-nearest-neighbour vote in the (log10 N_b, log10 N_f) plane.

    log_nb, log_nf (n,) run coordinates (log10); regimes (n,) labels; grid_x, grid_y
    arrays of query coordinates (log10; same shape). Both axes are scaled by the spread
    of the runs so that one decade counts the same on each axis when their spans
    differ. Ties go to the nearest neighbour. Returns an array of labels, grid shape.
    """
    from scipy.spatial import cKDTree

    x = np.asarray(log_nb, float)
    y = np.asarray(log_nf, float)
    lab = np.asarray(regimes, dtype=object)
    if not (x.size == y.size == lab.size) or x.size == 0:
        raise ValueError(f"log_nb, log_nf, regimes lengths=({x.size}, {y.size}, {lab.size}): "
                         "must be equal and >= 1")
    if not isinstance(k, (int, np.integer)) or k < 1:
        raise ValueError(f"k={k!r}: must be an integer >= 1")
    gx = np.asarray(grid_x, float)
    gy = np.asarray(grid_y, float)
    sx = max(float(np.ptp(x)), 1e-9)
    sy = max(float(np.ptp(y)), 1e-9)
    s = max(sx, sy)
    tree = cKDTree(np.c_[x / s, y / s])
    kk = min(k, x.size)
    _, idx = tree.query(np.c_[gx.ravel() / s, gy.ravel() / s], k=kk)
    if kk == 1:
        out = lab[idx]
    else:
        names, codes = np.unique(lab, return_inverse=True)
        votes = np.zeros((idx.shape[0], len(names)))
        w = 1.0 + 1e-6 * (kk - np.arange(kk))  # nearest wins ties
        np.add.at(votes, (np.arange(idx.shape[0])[:, None], codes[idx]), w[None, :])
        out = names[np.argmax(votes, axis=1)]
    return out.reshape(gx.shape)


_PALETTE = ("#c6dbef", "#fdd0a2", "#c7e9c0", "#dadaeb", "#fcbba1", "#d9d9d9")


def _label_shade(label: str, i: int) -> str:
    if label in REGIME_STYLE:
        return REGIME_STYLE[label]["shade"]
    if label in ("True", "False", "fracturing", "porous_invasion"):
        return regime_style(label)["shade"]
    return _PALETTE[i % len(_PALETTE)]


def _shade_classifier(ax, model, GX, GY, alpha: float = 0.75):
    """Colour the plane by the classifier: each label's shade weighted by its probability (a smooth map,
    white where no label is likely), and the borders of the most probable label as thin black lines."""
    from matplotlib.colors import to_rgb

    P = model.proba(np.c_[GX.ravel(), GY.ravel()])
    cols = np.array([to_rgb(_label_shade(lab, i)) for i, lab in enumerate(model.labels)])
    img = (P @ cols).reshape(GX.shape + (3,))
    ax.pcolormesh(GX, GY, img, shading="auto", alpha=alpha, zorder=0, rasterized=True)
    top = np.argmax(P, axis=1).reshape(GX.shape)
    for k in range(len(model.labels)):
        m = (top == k).astype(float)
        if 0 < m.mean() < 1:
            ax.contour(GX, GY, m, levels=[0.5], colors="k", linewidths=0.8, zorder=1)
    return P


def plot_boundary_sampling(model, points: Any, out_path: str | Path, *, band: Mapping[str, Any] | None = None,
                           title: str | None = None, formats: Sequence[str] = ("svg",), grid: int = 200,
                           axis_labels: Sequence[str] | None = None) -> dict[str, Any]:
    """The boundary sampler's view of a 2-axis campaign: classifier shading, probability contours, the
    50 % line (the boundary) with its uncertainty band, and the runs numbered and coloured by order.

    model : a ``sweep.regimes.regime_model.RegimeModel`` over two axes (axis units; log axes drawn in log).
    points : DataFrame with the two axis columns, ``order`` (0, 1, ...) and ``label`` (None: failed).
    band : ``sweep.regimes.regime_model.boundary_band(model)``; the band is the set of points closer to an
        estimated boundary point than its half-width (tolerance units), drawn hatched.
    Two labels: contours of P(second label) at 10, 30, 70, 90 % (thin) and 50 % (thick); more labels:
    the borders of the most probable label (thick). axis_labels : the two axis labels with units (default:
    the axis names). Writes PNG plus ``formats``; returns {"paths"}.
    """
    from scipy.spatial import cKDTree

    if len(model.axes) != 2:
        raise ValueError(f"model: {len(model.axes)} axes; the boundary figure draws two")
    ax0, ax1 = model.axes
    fig = _new_figure((6.0, 5.0))
    ax = fig.add_subplot(1, 1, 1)
    u = np.linspace(-1.0, 1.0, grid)
    UX, UY = np.meshgrid(u, u)
    GX, GY = ax0.from_u(UX), ax1.from_u(UY)
    P = _shade_classifier(ax, model, GX, GY)
    if len(model.labels) == 2:
        cs = ax.contour(GX, GY, P[:, 1].reshape(GX.shape), levels=[0.1, 0.3, 0.7, 0.9], colors="0.3",
                        linewidths=0.5, linestyles="dotted", zorder=1)
        ax.clabel(cs, fmt=lambda v: f"{v:.0%}", fontsize=5)
        ax.contour(GX, GY, P[:, 1].reshape(GX.shape), levels=[0.5], colors="k", linewidths=1.8, zorder=2)
    if band is not None and len(band["U"]):
        tol = np.array([ax0.tol_per_u, ax1.tol_per_u])
        dist, j = cKDTree(band["U"] * tol).query(np.c_[UX.ravel(), UY.ravel()] * tol)
        inside = (dist <= np.asarray(band["half"])[j]).reshape(GX.shape).astype(float)
        ax.contourf(GX, GY, inside, levels=[0.5, 1.5], colors="none", hatches=["////"], zorder=1)
        ax.contour(GX, GY, inside, levels=[0.5], colors="0.35", linewidths=0.6, zorder=1)
    order = points["order"].to_numpy()
    x, y = points[ax0.name].to_numpy(float), points[ax1.name].to_numpy(float)
    labels = points["label"].to_numpy()
    markers = {lab: "o^sDvP"[i % 6] for i, lab in enumerate(model.labels)}
    for lab in list(model.labels) + [None]:
        m = np.array([(v is None or v != v) if lab is None else v == lab for v in labels])
        if m.any():
            mk = markers.get(lab, "x")
            sc = ax.scatter(x[m], y[m], c=order[m], cmap="viridis", vmin=0, vmax=max(order.max(), 1),
                            marker=mk, s=28, linewidth=0.4, zorder=3, label=regime_style(lab)["label"],
                            **marker_outline(mk))
    for xv, yv, o in zip(x, y, order):
        ax.annotate(str(int(o)), (xv, yv), xytext=(3, 3), textcoords="offset points", fontsize=5, zorder=4)
    fig.colorbar(sc, ax=ax, label="order of the run", fraction=0.046, pad=0.04)
    for a, setter in ((ax0, ax.set_xscale), (ax1, ax.set_yscale)):
        if a.log:
            setter("log")
    ax.set_xlim(ax0.lo, ax0.hi)
    ax.set_ylim(ax1.lo, ax1.hi)
    names = tuple(axis_labels) if axis_labels else (ax0.name, ax1.name)
    ax.set_xlabel(names[0])
    ax.set_ylabel(names[1])
    if title:
        ax.set_title(title, fontsize=8)
    from matplotlib.patches import Patch

    handles, _ = ax.get_legend_handles_labels()
    handles.append(Patch(facecolor="none", edgecolor="0.35", hatch="////",
                         label=f"{model.confidence:.0%} band of the boundary"))
    ax.legend(handles=handles, fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=3, frameon=False)
    return {"paths": _save(fig, out_path, formats)}


def _thumbnail(fig, ax, run_dir: str | Path, xy: tuple[float, float], pos: tuple[float, float],
               size: float, at: Any) -> None:
    """Circular inset of a run: porosity and the S = 0.5 contour in white.

    The fields are drawn from the classifier's raster (one image, light in SVG)."""
    from .classify import _load_mesh, build_raster, select_snapshot

    run_dir = Path(run_dir)
    points, tris = _load_mesh(run_dir)
    _, snap = select_snapshot(run_dir, at)
    with np.load(snap) as z:
        S = np.asarray(z["S"], float)
        phi = np.asarray(z["phi"], float)
    ras = build_raster(points, tris)
    phi_img = ras.elemental(phi) if phi.size == len(tris) and phi.size != len(points) else ras.nodal(phi)
    S_img = ras.nodal(S, fill=np.nan)
    ext = (ras.x[0] - ras.pixel / 2, ras.x[-1] + ras.pixel / 2,
           ras.y[0] - ras.pixel / 2, ras.y[-1] + ras.pixel / 2)
    ins = ax.inset_axes([pos[0] - size / 2, pos[1] - size / 2, size, size])
    ins.imshow(np.ma.masked_invalid(phi_img), origin="lower", extent=ext, cmap="viridis",
               vmin=0.2, vmax=1.0, interpolation="nearest")
    if np.nanmax(S_img) >= 0.5 > np.nanmin(S_img):
        ins.contour(ras.x, ras.y, np.ma.masked_invalid(S_img), levels=[0.5], colors="white",
                    linewidths=0.8)
    ins.set_aspect("equal")
    ins.axis("off")
    ax.annotate("", xy=xy, xycoords="data", xytext=pos, textcoords="axes fraction",
                arrowprops=dict(arrowstyle="-", color="0.3", lw=0.6))


def plot_nf_vs_nb(df: Any, out_path: str | Path, *, shade: bool | str = True, k: int = 1,
                  experimental_range: Mapping[str, float] | Sequence[float] | None = None,
                  thumbnails: Sequence[Mapping[str, Any]] | None = None,
                  dp_cri: float | None = None, formats: Sequence[str] = ("svg",),
                  title: str | None = None, grid: int = 300) -> dict[str, Any]:
    """Log-log phase diagram N_f vs N_b with the five regimes (Sec. 3.8, Fig. phase_diagram).

    df columns: ``N_b``, ``N_f``, ``regime`` (+ ``run_dir`` for thumbnails).
    Symbols: blue circle uniform invasion, blue star viscous fingering, orange triangle
    invasive fracturing, orange square non-invasive fracturing, orange cross
    fracturing/fingering. ``shade``: True or "classifier" colours the plane by the regime
    probabilities of ``sweep.regimes.regime_model`` (multinomial logistic regression on a cubic basis in
    the log plane: each regime's shade weighted by its probability, the most probable regime's
    borders drawn as thin lines); "nearest" by ``regime_map`` (k nearest runs, a staircase);
    False: no shading. ``order`` column (optional): each run numbered by it. Dashed lines N_f = 1 and N_b = 1. ``experimental_range``:
    (nb_min, nb_max, nf_min, nf_max) or a mapping with those keys, drawn as a red
    rectangle. ``thumbnails``: list of {"row": index label of df (or "run_dir": path
    and "xy": (N_b, N_f)), "pos": (x, y) axes fraction of the inset centre,
    "size": axes fraction (0.18), "at": snapshot selector (default "last")}.
    ``dp_cri`` (kPa) is written in the title when given. Writes PNG plus ``formats``;
    returns {"paths", "n_dropped", "dropped", "counts"}.
    """
    _require(df, ("N_b", "N_f", "regime"), "plot_nf_vs_nb")
    nb = df["N_b"].to_numpy(dtype=float)
    nf = df["N_f"].to_numpy(dtype=float)
    rg = df["regime"].astype(str).to_numpy()
    ok = placed_rows(df, "N_b", "N_f", "regime", log_x=True)
    n_drop = int((~ok).sum())
    nb, nf, rg = nb[ok], nf[ok], rg[ok]
    if not isinstance(grid, (int, np.integer)) or grid < 10:
        raise ValueError(f"grid={grid!r}: must be an integer >= 10")

    fig = _new_figure((6.0, 5.0))
    ax = fig.add_subplot(1, 1, 1)
    ax.set_xscale("log")
    ax.set_yscale("log")
    if nb.size:
        lx, ly = np.log10(nb), np.log10(nf)
        x0, x1 = min(lx.min(), 0.0) - 0.5, max(lx.max(), 0.0) + 0.5
        y0, y1 = min(ly.min(), 0.0) - 0.5, max(ly.max(), 0.0) + 0.5
    else:
        lx = ly = np.empty(0)
        x0, x1, y0, y1 = -2.0, 2.0, -2.0, 2.0
    _shade_regimes(ax, shade, lx, ly, rg, (x0, x1, y0, y1), grid, k)
    counts = {}
    for r in REGIMES:
        m = rg == r
        counts[r] = int(m.sum())
        st = REGIME_STYLE[r]
        if m.any():
            ax.scatter(nb[m], nf[m], marker=st["marker"], color=st["color"],
                       s=60 if st["marker"] == "*" else 30, label=st["label"], zorder=3)
    if "order" in df.columns:
        for xv, yv, o in zip(nb, nf, df["order"].to_numpy()[ok]):
            if o == o:
                ax.annotate(str(int(o)), (xv, yv), xytext=(3, 3), textcoords="offset points", fontsize=5, zorder=5)
    ax.axhline(1.0, color="0.2", ls="--", lw=1.0, zorder=2)
    ax.axvline(1.0, color="0.2", ls="--", lw=1.0, zorder=2)
    if experimental_range is not None:
        x0, x1, y0, y1 = _experimental_box(ax, experimental_range, (x0, x1, y0, y1))
    ax.set_xlim(10**x0, 10**x1)
    ax.set_ylim(10**y0, 10**y1)
    ax.set_xlabel("branching number $N_b$")
    ax.set_ylabel("fracturing number $N_f$")
    t = title or ""
    if dp_cri is not None:
        t = (t + "\n" if t else "") + f"$\\delta p_{{cri}}$ = {dp_cri:.3g} kPa"
    if t:
        ax.set_title(t, fontsize=9)
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=3,
              frameon=False)
    ax.text(0.5, -0.30, ONE_RUN_NOTE, transform=ax.transAxes, fontsize=6, va="top", ha="center", color="0.35",
            wrap=True)
    _place_thumbnails(fig, ax, df, thumbnails or ())
    paths = _save(fig, out_path, formats)
    return {"paths": paths, "n_dropped": n_drop, "dropped": _dropped(df, ok), "counts": counts}


def _shade_regimes(ax, shade, lx, ly, rg, bounds, grid: int, k: int) -> None:
    """Shade the (log N_b, log N_f) plane within ``bounds`` by regime: the classifier's probabilities
    (``shade`` True or "classifier") or the k-nearest-run staircase ("nearest")."""
    x0, x1, y0, y1 = bounds
    nb, nf = 10**lx, 10**ly
    if shade not in (True, False, "classifier", "nearest"):
        raise ValueError(f"shade={shade!r}: must be true/\"classifier\" (smooth, from the regime classifier), "
                         "\"nearest\" (nearest-neighbour staircase) or false")
    if shade == "nearest" and nb.size:
        from matplotlib.colors import ListedColormap

        gx, gy = np.meshgrid(np.linspace(x0, x1, grid), np.linspace(y0, y1, grid))
        lab = regime_map(lx, ly, rg, gx, gy, k=k)
        code = np.vectorize(REGIMES.index)(lab)
        cmap = ListedColormap([REGIME_STYLE[r]["shade"] for r in REGIMES])
        ax.pcolormesh(10**gx, 10**gy, code, cmap=cmap, vmin=-0.5, vmax=len(REGIMES) - 0.5,
                      shading="auto", alpha=0.6, zorder=0, rasterized=True)
    elif shade and len(set(rg)) >= 2:
        from .regime_model import AxisScale, fit_regime_model

        axes = (AxisScale("N_b", 10**x0, 10**x1, True, 0.1), AxisScale("N_f", 10**y0, 10**y1, True, 0.1))
        model = fit_regime_model(np.c_[nb, nf], rg, axes, degree=3, prior_sd=10.0)
        gx, gy = np.meshgrid(np.linspace(x0, x1, grid), np.linspace(y0, y1, grid))
        _shade_classifier(ax, model, 10**gx, 10**gy)

def _experimental_box(ax, experimental_range, bounds) -> tuple:
    """Draw the experiments' (N_b, N_f) rectangle; returns the log10 axis bounds widened to hold it."""
    x0, x1, y0, y1 = bounds
    from matplotlib.patches import Rectangle

    if isinstance(experimental_range, Mapping):
        try:
            e = [float(experimental_range[k_]) for k_ in ("nb_min", "nb_max", "nf_min", "nf_max")]
        except KeyError as exc:
            raise ValueError(f"experimental_range: missing key {exc}; needs nb_min, nb_max, "
                             "nf_min, nf_max") from None
    else:
        e = [float(v) for v in experimental_range]
    if len(e) != 4 or min(e) <= 0 or e[1] <= e[0] or e[3] <= e[2]:
        raise ValueError(f"experimental_range={experimental_range!r}: needs 0 < nb_min < "
                         "nb_max and 0 < nf_min < nf_max")
    ax.add_patch(Rectangle((e[0], e[2]), e[1] - e[0], e[3] - e[2], fill=False, ec="red",
                           lw=1.5, zorder=4, label="experiments"))
    x0, x1 = min(x0, math.log10(e[0]) - 0.2), max(x1, math.log10(e[1]) + 0.2)
    y0, y1 = min(y0, math.log10(e[2]) - 0.2), max(y1, math.log10(e[3]) + 0.2)
    return x0, x1, y0, y1


def _place_thumbnails(fig, ax, df, thumbnails) -> None:
    """Inset snapshots of chosen runs (see :func:`plot_nf_vs_nb`'s ``thumbnails``)."""
    for th in thumbnails:
        if not isinstance(th, Mapping) or "pos" not in th:
            raise ValueError(f"thumbnails: entry {th!r} must be a mapping with 'pos'")
        if "row" in th:
            row = df.loc[th["row"]]
            run_dir, xy = row["run_dir"], (float(row["N_b"]), float(row["N_f"]))
        else:
            run_dir, xy = th["run_dir"], tuple(th["xy"])
        _thumbnail(fig, ax, run_dir, xy, tuple(th["pos"]), float(th.get("size", 0.18)), th.get("at", "last"))


