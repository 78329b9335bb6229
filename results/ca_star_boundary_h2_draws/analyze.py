"""The judging protocol of campaigns/ca_star_boundary_h2_draws.toml (written in its header before the runs).

1. Label agreement over the porosity draws at L_min = 4 mm: the share of points whose draws all carry the same
   label, and the spread of the crack length (max - min over the draws) per point.
2. The separatrix Ca*_c = A exp(B C) (sweep.diagrams.separatrix_profile_interval) on each seed alone and on the
   draws pooled; the verdict is "B > 0 at 2 sigma" on the pooled fit.
3. The pooled fit at L_min = 2, 3, 4, 5, 6 mm, reported whole (not the verdict).

Rule 1 of sweep.classify labels a run fracturing iff crack_length > L_min, so the labels at other L_min are read
from the stored crack lengths.  Units: lengths mm, C in %, Ca* dimensionless.

    python results/ca_star_boundary_h2_draws/analyze.py CAMPAIGN_DIR [--out summary.json] [--figure draws.png]
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from sweep.diagrams import separatrix_profile_interval
from sweep.load import load_campaign
from sweep.store import write_json_atomic

L_PROTOCOL = 4.0  # mm, the campaign's [classify] min_crack_length
L_SCAN = (2.0, 3.0, 4.0, 5.0, 6.0)  # mm


def completed_runs(campaign_dir: Path) -> pd.DataFrame:
    """The campaign's runs with status ok: seed, cement (%), eta_o (kPa s), Ca_star (-), crack_length (mm)."""
    df = load_campaign(campaign_dir)
    return df[df["status"] == "ok"][["seed", "cement", "eta_o", "Ca_star", "crack_length"]].reset_index(drop=True)


def fracturing(df: pd.DataFrame, l_min: float) -> pd.Series:
    """Rule 1 of sweep.classify at L_min (mm): a run fractures iff its crack is longer than L_min."""
    return df["crack_length"] > l_min


def agreement(df: pd.DataFrame, l_min: float = L_PROTOCOL) -> dict:
    """Per point (cement, eta_o) with every seed done: do the draws agree on the label, and the crack spread (mm)."""
    seeds = sorted(df["seed"].unique())
    g = df.assign(frac=fracturing(df, l_min)).groupby(["cement", "eta_o"])
    full = g.filter(lambda x: len(x) == len(seeds)).groupby(["cement", "eta_o"])
    same = full["frac"].agg(lambda x: x.all() or not x.any())
    spread = full["crack_length"].agg(lambda x: float(x.max() - x.min()))
    return {"seeds": [int(s) for s in seeds], "points_with_every_seed": int(same.size),
            "points_all_draws_agree": int(same.sum()),
            "share_agree": float(same.mean()) if same.size else None,
            "crack_spread_mm": {"median": float(spread.median()), "max": float(spread.max())} if same.size else None,
            "fracturing_share_by_seed": {int(s): float(fracturing(d, l_min).mean())
                                         for s, d in df.groupby("seed")}}


def separatrix(df: pd.DataFrame, l_min: float) -> dict:
    """The profile-likelihood fit on these runs at L_min (mm), or the reason it cannot be made."""
    y = fracturing(df, l_min).to_numpy()
    row = {"runs": int(len(df)), "fracturing": int(y.sum())}
    try:
        s = separatrix_profile_interval(df["cement"], df["Ca_star"], y)
    except ValueError as e:
        return {**row, "error": str(e)}
    return {**row, "A": s.A, "B": s.B, "B_interval": [float(v) for v in s.B_interval], "A_interval": [float(v) for v in s.A_interval],
            "sharpness": s.sharpness, "B_positive_at_95": bool(s.B_interval[0] > 0)}


def judge(df: pd.DataFrame) -> dict:
    """The three parts of the protocol."""
    return {"agreement_at_L4": agreement(df),
            "per_seed_at_L4": {int(k): separatrix(d, L_PROTOCOL) for k, d in df.groupby("seed")},
            "pooled_at_L4": separatrix(df, L_PROTOCOL),
            "pooled_L_scan": {str(l): separatrix(df, l) for l in L_SCAN}}


def _separatrix_line(ax, fit: dict, C: np.ndarray, **kw) -> None:
    """Draw Ca*_c = A exp(B C) (A, B from a :func:`separatrix` row) over the cement range C (%), if fitted."""
    if "B" in fit:
        c = np.linspace(C.min(), C.max(), 50)
        ax.plot(c, fit["A"] * np.exp(fit["B"] * c), **kw)


def figure(df: pd.DataFrame, out: dict, path: Path) -> None:
    """One panel per draw (labels at L_min = 4 mm with that draw's separatrix) and one of the share of draws
    that fracture at each point with the pooled separatrix.  Axes: C (%), Ca* (-, log)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    seeds = sorted(df["seed"].unique())
    fig, axes = plt.subplots(1, len(seeds) + 1, figsize=(4.2 * (len(seeds) + 1), 4.0), sharey=True)
    C = df["cement"].to_numpy()
    for ax, s in zip(axes, seeds):
        d = df[df["seed"] == s]
        y = fracturing(d, L_PROTOCOL)
        ax.scatter(d["cement"][~y], d["Ca_star"][~y], facecolors="none", edgecolors="C0", label="porous invasion")
        ax.scatter(d["cement"][y], d["Ca_star"][y], marker="^", color="C3", label="fracturing")
        fit = out["per_seed_at_L4"][int(s)]
        _separatrix_line(ax, fit, C, color="k")
        ax.set_title(f"seed {s}: " + (f"B = {fit['B']:.2f} [{fit['B_interval'][0]:.2f}, {fit['B_interval'][1]:.2f}]"
                                      if "B" in fit else "no separatrix"), fontsize=9)
    share = df.assign(f=fracturing(df, L_PROTOCOL)).groupby(["cement", "eta_o"]).agg(
        f=("f", "mean"), Ca_star=("Ca_star", "first")).reset_index()
    sc = axes[-1].scatter(share["cement"], share["Ca_star"], c=share["f"], cmap="coolwarm", vmin=0, vmax=1)
    fig.colorbar(sc, ax=axes[-1], label="share of draws fracturing")
    pooled = out["pooled_at_L4"]
    _separatrix_line(axes[-1], pooled, C, color="k")
    axes[-1].set_title(f"pooled: B = {pooled['B']:.2f} [{pooled['B_interval'][0]:.2f}, {pooled['B_interval'][1]:.2f}]"
                       if "B" in pooled else "pooled: no separatrix", fontsize=9)
    for ax in axes:
        ax.set_yscale("log")
        ax.set_xlabel("cement volume ratio C (%)")
    axes[0].set_ylabel("modified capillary number Ca* (-)")
    axes[0].legend(fontsize=8, loc="lower right")
    fig.suptitle(f"Ca*-C labels at L_min = {L_PROTOCOL:g} mm over the porosity draws (h = 2 mm); B in 1/%, 95 % intervals",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("campaign_dir", type=Path)
    ap.add_argument("--out", type=Path)
    ap.add_argument("--figure", type=Path, help="PNG: the labels per draw and the share of draws fracturing")
    a = ap.parse_args(argv)
    df = completed_runs(a.campaign_dir)
    out = judge(df)
    if a.figure:
        figure(df, out, a.figure)
    text = json.dumps(out, indent=1)
    if a.out:
        write_json_atomic(a.out, out)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
