"""Probabilistic regime boundaries: label probabilities from replicate runs, the fracturing separatrix with its
confidence band, a smooth classifier's 0.5 contour, and the diagram that shows them (numpy + scipy only).

Replicates are runs at the same point of the plane that differ only in the porosity draw (or the mesh seed).
Their labels are Bernoulli draws of the point's label probability p. This module estimates p per point
(Wilson score interval), and over the plane by two models:

* **the exponential separatrix** Ca*_c(C) = A exp(B C) (Sec. 3.6, Eq. modified_capillary_number's map) as the
  0.5 contour of P(fracturing) = expit(s (ln Ca* - ln A - B C)), fitted with Jeffreys' prior exactly as
  :func:`sweep.regimes.diagrams.separatrix_profile_interval` (whose optimizer this module reuses).  Its **band**
  at C0 is the profile-likelihood interval of ln Ca*_c(C0): the values v for which the best fit constrained
  to pass through (C0, v) stays within chi2_q(level)/2 of the best fit.  With q = 2 (``simultaneous``, the
  default) the band is the projection of the joint confidence region of the line (ln A, B), so it covers the
  whole true line at once with probability ``level`` (asymptotically), not just each C0 alone.
  **Significance**: the penalized likelihood-ratio test of the separatrix model against a constant
  probability (2 degrees of freedom: B and s); a separatrix whose test does not reject at ``alpha`` is never
  drawn (the labels do not show that the plane orders them).  :func:`separatrix_test` is that rule, for this
  diagram and the one-run Ca*-C diagram alike.
* **a smooth classifier**: :func:`sweep.regimes.regime_model.fit_regime_model` (a logistic fit on a cubic
  Legendre basis with a smoothness prior whose scale is weighed by its evidence), the non-parametric check of
  the straight line; its 0.5 contour and its Laplace band (``boundary_band``).

Units: C in % (cement volume ratio), Ca* dimensionless (> 0); logarithms natural unless said (decades).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .separatrix import (SEPARATRIX_P_MAX, SeparatrixBand, separatrix_band, separatrix_significance,
                         separatrix_summary, separatrix_test)

__all__ = ["wilson_interval", "replicate_points", "SeparatrixBand", "separatrix_band", "separatrix_significance",
           "separatrix_test", "fit_probability_map", "plot_probability_diagram", "plot_nf_vs_nb_probabilities", "separatrix_summary"]


def wilson_interval(k: Any, n: Any, level: float = 0.95) -> tuple[np.ndarray, np.ndarray]:
    """Wilson score interval of a binomial probability from k successes in n trials (arrays broadcast).

    (p + z^2/2n -+ z sqrt(p(1-p)/n + z^2/4n^2)) / (1 + z^2/n), z the two-sided normal quantile of ``level``;
    n = 0 gives [0, 1]. Dimensionless."""
    from scipy.stats import norm

    k, n = np.asarray(k, float), np.asarray(n, float)
    if np.any(k < 0) or np.any(k > n) or not 0 < level < 1:
        raise ValueError(f"k={k!r}, n={n!r}, level={level!r}: need 0 <= k <= n and level in (0, 1)")
    z = float(norm.ppf(0.5 + 0.5 * level))
    with np.errstate(invalid="ignore", divide="ignore"):
        p = k / n
        mid = (p + z * z / (2 * n)) / (1 + z * z / n)
        half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    lo = np.where(n > 0, np.clip(mid - half, 0.0, 1.0), 0.0)
    hi = np.where(n > 0, np.clip(mid + half, 0.0, 1.0), 1.0)
    return lo, hi


def _sig12(v) -> Any:
    """A point coordinate as a grouping key: floats to 12 significant digits, other values as they are."""
    try:
        return float(f"{float(v):.12g}")
    except (TypeError, ValueError):
        return v


def replicate_points(x: Any, y: Any, label: Any, level: float = 0.95, *, point: Any = None) -> dict[str, np.ndarray]:
    """Group runs by their point: per point ``x``, ``y``, ``n`` runs, ``k`` runs labelled True, ``p`` = k/n, the
    Wilson interval ``lo``, ``hi`` at ``level``, and ``mixed`` (the replicates disagree: 0 < k < n). Units those of
    x and y.  A point is ``point`` (one id per run: e.g. the tuple of the campaign's axis values), else (x, y)
    (equal values, 12 significant digits): distinct points can share (x, y) (Ca* ~ eta_o w_i), and their runs
    are then not replicates of one point."""
    x, y = np.asarray(x, float).ravel(), np.asarray(y, float).ravel()
    lab = np.asarray(label).astype(bool).ravel()
    ids = list(zip(x, y)) if point is None else list(point)
    if not x.size == y.size == lab.size == len(ids):
        raise ValueError(f"x, y, label, point lengths=({x.size}, {y.size}, {lab.size}, {len(ids)}): must be equal")
    keys = [tuple(_sig12(v) for v in (i if isinstance(i, tuple) else (i,))) for i in ids]
    first: dict[tuple, int] = {}
    inv = np.array([first.setdefault(kk, len(first)) for kk in keys], int)
    m = len(first)
    starts = np.unique(inv, return_index=True)[1]           # each point's first run (ids in order of appearance)
    n = np.bincount(inv, minlength=m).astype(int)
    k = np.bincount(inv, weights=lab.astype(float), minlength=m).astype(int)
    lo, hi = wilson_interval(k, n, level)
    order = np.lexsort((y[starts], x[starts]))               # points sorted by (x, y)
    return {"x": x[starts][order], "y": y[starts][order], "n": n[order], "k": k[order],
            "p": (k / np.maximum(n, 1))[order], "lo": lo[order], "hi": hi[order], "mixed": ((k > 0) & (k < n))[order]}


# --------------------------------------------------------------------------- the smooth classifier
def fit_probability_map(C: Any, ca_star: Any, fracturing: Any, *, tolerance: tuple[float, float] = (0.1, 0.1),
                        bounds: tuple | None = None, degree: int = 3, confidence: float = 0.95):
    """The smooth classifier of P(fracturing) over (C %, Ca* on a log axis): ``fit_regime_model`` with labels
    "porous_invasion" / "fracturing", the boundary sampler's prior (prior sd 8 per tolerance unit of the finest
    axis, its scale weighed by evidence over a factor 64). ``tolerance`` (% , decades) sets the band's units;
    ``bounds`` ((C_lo, C_hi), (Ca_lo, Ca_hi)) default the data's range. Returns the RegimeModel."""
    from .regime_model import AxisScale, fit_regime_model

    Cc, cs = np.asarray(C, float).ravel(), np.asarray(ca_star, float).ravel()
    y = np.where(np.asarray(fracturing).astype(bool).ravel(), "fracturing", "porous_invasion")
    (c0, c1), (a0, a1) = bounds or ((Cc.min(), Cc.max()), (cs.min(), cs.max()))
    axes = (AxisScale("cement", float(c0), float(c1), False, tolerance[0]),
            AxisScale("Ca_star", float(a0), float(a1), True, tolerance[1]))
    prior_sd = 8.0 * max(a.tol_per_u for a in axes)
    return fit_regime_model(np.c_[Cc, cs], y, axes, degree=degree, prior_sd=prior_sd, prior_span=64.0,
                            confidence=confidence, labels=("porous_invasion", "fracturing"))


# --------------------------------------------------------------------------- the diagram
def plot_probability_diagram(df: Any, out_path: str | Path, *, x: str = "cement", y: str = "Ca_star",
                             label: str = "fracturing", level: float = 0.95, alpha: float = SEPARATRIX_P_MAX,
                             smooth: bool = True, title: str | None = None, truth: Any = None,
                             by: Sequence[str] | None = None, formats: Sequence[str] = ("svg",)) -> dict[str, Any]:
    """Ca*-C diagram of label probabilities from replicate runs.

    df: one row per run with columns ``x`` (C, %), ``y`` (Ca*, > 0) and ``label`` (bool); rows with a missing
    value are dropped (``n_dropped``, ``dropped``: their index labels; the rule of every diagram,
    :func:`sweep.regimes.diagrams.placed_rows`). Each point is coloured by its fraction of fracturing replicates (blue 0
    to orange 1), its size grows with the replicate count, and a black ring marks the points whose replicates
    disagree. The background is the smooth classifier's P(fracturing) with its 0.5 contour (dashed) and the edge of
    that contour's 95 % band (dotted), when ``smooth``. The separatrix and its ``level`` band are drawn only when the fit is significant at ``alpha``
    (:func:`separatrix_test`, the rule of the one-run diagram too); otherwise the figure says why. ``truth``: optional callable C -> Ca*_c
    drawn dotted (a known boundary). ``by``: the columns that name a point (a campaign's axes; default ``x`` and
    ``y``): runs at one (C, Ca*) of distinct points are not one point's replicates. Writes PNG plus ``formats``;
    returns {"paths", "points", "band", "no_fit_reason", "n_dropped", "dropped"}.
    """
    from matplotlib.colors import LinearSegmentedColormap

    from .diagrams import BLUE, ORANGE, _dropped, _new_figure, _require, _save, placed_rows

    _require(df, (x, y, label, *(by or ())), "plot_probability_diagram")
    lab = df[label]
    ok = placed_rows(df, x, y, label)
    C, cs, fr = df[x][ok].to_numpy(float), df[y][ok].to_numpy(float), lab[ok].astype(bool).to_numpy()
    ids = list(df.loc[ok, list(by)].itertuples(index=False, name=None)) if by else None
    pts = replicate_points(C, cs, fr, level, point=ids)
    fig = _new_figure((5.8, 4.6))
    ax = fig.add_subplot(1, 1, 1)
    cmap = LinearSegmentedColormap.from_list("p_frac", [BLUE, "#f7f7f7", ORANGE])
    if smooth and fr.any() and (~fr).any():
        _shade_smooth(ax, fit_probability_map(C, cs, fr), cmap)
        ax.plot([], [], ls="--", color="0.2", lw=1.0, label="smooth classifier: P(fracturing) = 0.5")
        ax.plot([], [], ls=":", color="0.2", lw=0.7, label="its 95 % band (edge)")
    band, why = _band_or_reason(C, cs, fr, level, alpha)
    ylim = (cs.min() / 10**0.5, cs.max() * 10**0.5)   # the band may leave the sampled range: it is clipped
    if band is not None:
        edge_lo, edge_hi = band.edges          # an unbounded side reaches the plot's edge
        lo, hi = (np.exp(np.clip(v, *np.log(ylim))) for v in (edge_lo, edge_hi))
        clipped = bool(np.any(edge_lo < np.log(ylim[0])) or np.any(edge_hi > np.log(ylim[1])))
        ax.fill_between(band.C, lo, hi, color="0.5", alpha=0.35, lw=0, zorder=1,
                        label=f"{level:.0%} band of Ca*$_c$" + (" (whole line)" if band.simultaneous else "")
                        + (" (beyond the plot where clipped)" if clipped else ""))
        ax.plot(band.C, np.exp(band.center), "k-", lw=1.4, zorder=2,
                label=f"Ca*$_c$ = A exp(B C): A = {band.A:.3g}, B = {band.B:.3g} /% (p = {band.p_value:.2g})")
    else:
        ax.text(0.5, -0.30, "no separatrix drawn: " + why, transform=ax.transAxes, fontsize=6.5, va="top",
                ha="center", wrap=True)
    if truth is not None:
        cc = np.linspace(C.min(), C.max(), 100)
        ax.plot(cc, truth(cc), "k:", lw=1.2, zorder=2, label="true boundary")
    sc = ax.scatter(pts["x"], pts["y"], c=pts["p"], cmap=cmap, vmin=0, vmax=1, s=14 + 10 * pts["n"],
                    edgecolor="0.3", linewidth=0.4, zorder=3)
    m = pts["mixed"]
    ax.scatter(pts["x"][m], pts["y"][m], s=14 + 10 * pts["n"][m] + 40, facecolors="none", edgecolors="k",
               linewidth=1.0, zorder=4, label=f"replicates disagree ({int(m.sum())} of {m.size} points)")
    fig.colorbar(sc, ax=ax, label="fraction of replicates fracturing", fraction=0.046, pad=0.04)
    ax.set_yscale("log")
    ax.set_ylim(*ylim)
    ax.set_xlabel("cement volume ratio C (%)")
    ax.set_ylabel("modified capillary number Ca*")
    ax.set_title(title or f"{C.size} runs at {m.size} points (replicates {int(pts['n'].min())}-{int(pts['n'].max())})",
                 fontsize=8)
    ax.legend(fontsize=6.5, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=1, frameon=False)
    return {"paths": _save(fig, out_path, formats), "points": pts, "band": band, "no_fit_reason": why,
            "n_dropped": int((~ok).sum()), "dropped": _dropped(df, ok)}


def _band_or_reason(C, cs, fr, level, alpha):
    """(band, None) when the separatrix is significant at ``alpha`` (:func:`separatrix_test`), else (None, why)."""
    if len(C) < 3 or fr.all() or (~fr).all():
        return None, "both regimes are needed to fit a separatrix"
    try:
        test = separatrix_test(C, cs, fr, alpha)
        if not test.significant:
            return None, f"the fit is {test.reason}"
        return separatrix_band(C, cs, fr, level=level, alpha=alpha), None
    except ValueError as exc:
        return None, str(exc)


def _shade_smooth(ax, model, cmap, n: int = 120) -> None:
    """The smooth classifier's P(fracturing) as a faint background, its 0.5 contour dashed and that contour's
    Laplace band (``boundary_band``: within z sigma_loc of an estimated boundary point) dotted at its edge."""
    from scipy.spatial import cKDTree

    from .regime_model import boundary_band

    ax0, ax1 = model.axes
    u = np.linspace(-1.0, 1.0, n)
    GX, GY = np.meshgrid(ax0.from_u(u), ax1.from_u(u))
    P = model.proba(np.c_[GX.ravel(), GY.ravel()])[:, list(model.labels).index("fracturing")].reshape(GX.shape)
    ax.pcolormesh(GX, GY, P, cmap=cmap, vmin=0, vmax=1, alpha=0.35, shading="auto", zorder=0, rasterized=True)
    if not P.min() < 0.5 < P.max():
        return
    ax.contour(GX, GY, P, levels=[0.5], colors="0.2", linewidths=1.0, linestyles="dashed", zorder=1)
    band = boundary_band(model)
    if len(band["U"]):
        tol = np.array([ax0.tol_per_u, ax1.tol_per_u])
        UX, UY = np.meshgrid(u, u)
        dist, j = cKDTree(band["U"] * tol).query(np.c_[UX.ravel(), UY.ravel()] * tol)
        inside = (dist <= band["half"][j]).reshape(GX.shape).astype(float)
        if 0 < inside.mean() < 1:
            ax.contour(GX, GY, inside, levels=[0.5], colors="0.2", linewidths=0.7, linestyles="dotted", zorder=1)


def plot_nf_vs_nb_probabilities(df: Any, out_path: str | Path, *, dp_cri: float | None = None, title: str | None = None,
                                by: Sequence[str] | None = None, formats: Sequence[str] = ("svg",)) -> dict[str, Any]:
    """N_f-N_b diagram (Sec. 3.8) of regime probabilities from replicate runs.

    df: one row per run with ``N_b``, ``N_f`` (-, > 0) and ``regime``; runs at equal (N_b, N_f) and equal ``by``
    columns (the campaign's axes: distinct points share (N_b, N_f) on decade grids of eta_o, eta_w and kbar) are
    one point's replicates. Each point takes the symbol and colour of its most probable regime (``REGIME_STYLE``), its opacity
    that regime's share of the replicates, a black ring when the replicates' regimes disagree and the label
    "k/n" (replicates in the most probable regime). Dashed lines N_f = 1 and N_b = 1. ``dp_cri`` (kPa) goes in the
    title. Writes PNG plus ``formats``; returns {"paths", "points" (DataFrame: N_b, N_f, n, top, p_top, mixed),
    "n_dropped", "dropped"}.
    """
    import pandas as pd

    from .classify import REGIMES
    from .diagrams import REGIME_STYLE, _dropped, _new_figure, _require, _save, placed_rows

    by = list(by or ())
    _require(df, ("N_b", "N_f", "regime", *by), "plot_nf_vs_nb_probabilities")
    nb, nf = df["N_b"].astype(float), df["N_f"].astype(float)
    ok = placed_rows(df, "N_b", "N_f", "regime", log_x=True)
    d = pd.DataFrame({"N_b": nb[ok].round(12), "N_f": nf[ok].round(12), "regime": df["regime"][ok].astype(str)})
    for i, c in enumerate(by):
        d[f"_by{i}"] = df.loc[ok, c].map(_sig12)
    rows = []
    for (b, f, *_), g in d.groupby(["N_b", "N_f", *(f"_by{i}" for i in range(len(by)))], sort=False, dropna=False):
        counts = g["regime"].value_counts()
        rows.append({"N_b": b, "N_f": f, "n": int(len(g)), "top": counts.index[0], "k_top": int(counts.iloc[0]),
                     "p_top": float(counts.iloc[0] / len(g)), "mixed": bool(len(counts) > 1)})
    pts = pd.DataFrame(rows, columns=["N_b", "N_f", "n", "top", "k_top", "p_top", "mixed"])
    fig = _new_figure((6.0, 5.0))
    ax = fig.add_subplot(1, 1, 1)
    ax.set_xscale("log")
    ax.set_yscale("log")
    for r in REGIMES:
        m = pts["top"] == r
        st = REGIME_STYLE[r]
        for _, p in pts[m].iterrows():
            ax.scatter([p["N_b"]], [p["N_f"]], marker=st["marker"], color=st["color"], alpha=max(p["p_top"], 0.15),
                       s=70 if st["marker"] == "*" else 40, zorder=3)
        if m.any():
            ax.scatter([], [], marker=st["marker"], color=st["color"], label=st["label"])
    mx = pts[pts["mixed"]]
    ax.scatter(mx["N_b"], mx["N_f"], s=140, facecolors="none", edgecolors="k", linewidth=0.9, zorder=4,
               label=f"replicates disagree ({len(mx)} of {len(pts)} points)")
    for _, p in pts.iterrows():
        ax.annotate(f"{p['k_top']}/{p['n']}", (p["N_b"], p["N_f"]), xytext=(4, -7), textcoords="offset points",
                    fontsize=5, zorder=5)
    ax.axhline(1.0, color="0.2", ls="--", lw=1.0, zorder=2)
    ax.axvline(1.0, color="0.2", ls="--", lw=1.0, zorder=2)
    ax.set_xlabel("branching number $N_b$")
    ax.set_ylabel("fracturing number $N_f$")
    t = (title or "") + ("" if dp_cri is None else f"\n$\\delta p_{{cri}}$ = {dp_cri:.3g} kPa")
    ax.set_title(t.strip() + "\nsymbol: most probable regime; opacity: its share of the replicates", fontsize=8)
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=3, frameon=False)
    return {"paths": _save(fig, out_path, formats), "points": pts, "n_dropped": int((~ok).sum()),
            "dropped": _dropped(df, ok)}
