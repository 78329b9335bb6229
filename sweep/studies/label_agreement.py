"""Fracturing labels of one set of Ca*–C points over several realizations (porosity draws, perturbed meshes).

A boundary campaign labels each point once, on one draw of the random initial porosity and one mesh.  A second
campaign that reruns the same points on other realizations asks how much of the boundary is the realization:

* :func:`agreement` — per point with every realization done, whether all carry the same label, and the spread of
  the crack length (max − min over the realizations);
* :func:`separatrix` — the fit Ca*_c = A exp(B C) (:func:`sweep.regimes.separatrix.separatrix_profile_interval`) on a set of
  runs, or the reason none can be fitted;
* :func:`judge` — both, per realization and pooled, with the pooled fit over a scan of L_min;
* :func:`figure` — one panel per realization and one of the share of realizations that fracture;
* :func:`longest`, :func:`crack_summary`, :func:`rank_correlations` — the crack as a continuous quantity: the
  longest crack up to the judged time (the record of ``crack_record = "longest"``), the lengths' quantiles and
  distinct values, and their rank correlations with C and Ca*.

Rule 1 of ``sweep.regimes.classify`` labels a run fracturing iff its crack is longer than L_min
(:func:`fracturing`), so the labels at another L_min are read from the stored crack lengths.
Units: lengths mm, C in %, η_o in kPa·s, Ca* dimensionless.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Sequence

import numpy as np
import pandas as pd

from sweep.regimes.separatrix import interval_text, separatrix_profile_interval
from sweep.campaign.store import write_json_atomic
from sweep.figio import write_figure

__all__ = ["fracturing", "agreement", "separatrix", "separatrix_line", "judge", "figure", "report", "longest",
           "crack_summary", "rank_correlations"]

POINT = ["cement", "eta_o"]  # a Ca*–C point: cement ratio (%) and oil viscosity (kPa·s)


def fracturing(df: pd.DataFrame, l_min: float) -> pd.Series:
    """Rule 1 of sweep.regimes.classify at L_min (mm): a run fractures iff its ``crack_length`` (mm) exceeds L_min."""
    return df["crack_length"] > l_min


def longest(df: pd.DataFrame) -> pd.DataFrame:
    """``df`` with ``crack_length`` (mm) replaced by the longest crack up to the judged time: the larger of the
    judged crack and ``open_tip_radius_max`` − ``r_inner`` (mm), as ``sweep.regimes.classify`` reads it with
    ``crack_record = "longest"`` for a run judged at its last step."""
    return df.assign(crack_length=np.maximum(df["crack_length"], df["open_tip_radius_max"] - df["r_inner"]))


def crack_summary(df: pd.DataFrame) -> dict:
    """The crack lengths (mm) of the runs: quantiles 0, 25, 50, 75, 100 % and the distinct values to 0.01 mm."""
    L = df["crack_length"]
    return {"quantiles_0_25_50_75_100": [float(v) for v in L.quantile([0, 0.25, 0.5, 0.75, 1.0])],
            "distinct_values": sorted({round(float(v), 2) for v in L})}


def rank_correlations(df: pd.DataFrame, columns: Sequence[str] = ("cement", "Ca_star")) -> dict:
    """Spearman's rank correlation of ``crack_length`` with each of ``columns``."""
    from scipy.stats import spearmanr

    return {c: float(spearmanr(df["crack_length"], df[c])[0]) for c in columns}


def agreement(df: pd.DataFrame, by: str, l_min: float) -> dict:
    """Label agreement at L_min (mm) over the realizations in column ``by``, on the points that have them all:
    the count and share of points whose realizations agree, the crack-length spread (mm; median and max over
    the points), and the share of runs fracturing per realization."""
    reals = sorted(df[by].unique())
    g = df.assign(frac=fracturing(df, l_min)).groupby(POINT)
    full = g.filter(lambda x: x[by].nunique() == len(reals)).groupby(POINT)
    same = full["frac"].agg(lambda x: x.all() or not x.any())
    spread = full["crack_length"].agg(lambda x: float(x.max() - x.min()))
    return {"realizations": [int(s) for s in reals], "points_with_every_realization": int(same.size),
            "points_all_agree": int(same.sum()),
            "share_agree": float(same.mean()) if same.size else None,
            "crack_spread_mm": {"median": float(spread.median()), "max": float(spread.max())} if same.size else None,
            "fracturing_share": {int(s): float(fracturing(d, l_min).mean()) for s, d in df.groupby(by)}}


def separatrix(df: pd.DataFrame, l_min: float) -> dict:
    """The profile-likelihood fit Ca*_c = A exp(B C) (B in 1/%) on these runs at L_min (mm), with the verdict
    "B > 0 at 95 %", or the reason it cannot be made."""
    y = fracturing(df, l_min).to_numpy()
    row = {"runs": int(len(df)), "fracturing": int(y.sum())}
    try:
        s = separatrix_profile_interval(df["cement"], df["Ca_star"], y)
    except ValueError as e:
        return {**row, "error": str(e)}
    return {**row, "A": s.A, "B": s.B, "B_interval": [float(v) for v in s.B_interval],
            "A_interval": [float(v) for v in s.A_interval], "sharpness": s.sharpness,
            "B_positive_at_95": bool(s.B_interval[0] > 0)}


def judge(df: pd.DataFrame, by: str, l_min: float, l_scan: Sequence[float]) -> dict:
    """Agreement and per-realization fits at the protocol's L_min (mm), the pooled fit at L_min (the verdict)
    and the pooled fit at each length of ``l_scan`` (mm; reported whole, not the verdict)."""
    tag = f"L{l_min:g}"
    return {f"agreement_at_{tag}": agreement(df, by, l_min),
            f"per_{by}_at_{tag}": {int(k): separatrix(d, l_min) for k, d in df.groupby(by)},
            f"pooled_at_{tag}": separatrix(df, l_min),
            "pooled_L_scan": {str(float(l)): separatrix(df, l) for l in l_scan}}


def separatrix_line(ax, fit: dict, C: np.ndarray, **kw) -> None:
    """Draw Ca*_c = A exp(B C) (A, B from a :func:`separatrix` row) over the cement range C (%), if fitted."""
    if "B" in fit:
        c = np.linspace(C.min(), C.max(), 50)
        ax.plot(c, fit["A"] * np.exp(fit["B"] * c), **kw)


def _fit_title(head: str, fit: dict) -> str:
    if "B" not in fit:
        return f"{head}: no separatrix"
    return f"{head}: B = {fit['B']:.2f} {interval_text(*fit['B_interval'])}"


def figure(df: pd.DataFrame, out: dict, by: str, l_min: float, path: Path, title: str) -> None:
    """PNG at ``path``: one panel per realization (labels at L_min (mm) with its separatrix) and one of the
    share of realizations fracturing at each point with the pooled separatrix; ``out`` is :func:`judge`'s.
    Axes: C (%), Ca* (-, log)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tag = f"L{l_min:g}"
    reals = sorted(df[by].unique())
    fig, axes = plt.subplots(1, len(reals) + 1, figsize=(4.2 * (len(reals) + 1), 4.0), sharey=True)
    C = df["cement"].to_numpy()
    for ax, s in zip(axes, reals):
        d = df[df[by] == s]
        y = fracturing(d, l_min)
        ax.scatter(d["cement"][~y], d["Ca_star"][~y], facecolors="none", edgecolors="C0", label="porous invasion")
        ax.scatter(d["cement"][y], d["Ca_star"][y], marker="^", color="C3", label="fracturing")
        fit = out[f"per_{by}_at_{tag}"][int(s)]
        separatrix_line(ax, fit, C, color="k")
        ax.set_title(_fit_title(f"{by} {s}", fit), fontsize=9)
    share = df.assign(f=fracturing(df, l_min)).groupby(POINT).agg(
        f=("f", "mean"), Ca_star=("Ca_star", "first")).reset_index()
    sc = axes[-1].scatter(share["cement"], share["Ca_star"], c=share["f"], cmap="coolwarm", vmin=0, vmax=1)
    fig.colorbar(sc, ax=axes[-1], label=f"share of {by} values fracturing")
    separatrix_line(axes[-1], out[f"pooled_at_{tag}"], C, color="k")
    axes[-1].set_title(_fit_title("pooled", out[f"pooled_at_{tag}"]), fontsize=9)
    for ax in axes:
        ax.set_yscale("log")
        ax.set_xlabel("cement volume ratio C (%)")
    axes[0].set_ylabel("modified capillary number Ca* (-)")
    axes[0].legend(fontsize=8, loc="lower right")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    write_figure(fig, path, dpi=110)
    plt.close(fig)


def report(out: dict, path: Path | None) -> None:
    """Print ``out`` as JSON and, with ``path``, write it there atomically."""
    if path:
        write_json_atomic(path, out)
    print(json.dumps(out, indent=1))
