"""The judging protocol of campaigns/studies/ca_star_boundary_h2_pockets.toml (written in its header before the runs).

1. The separatrix Ca*_c = A exp(B C) on the sampler's runs (deterministic mesh) at L_min = 4 mm; the verdict is
   "B > 0 at 2 sigma".
2. The same fit over L_min = 2-6 mm, reported whole (not the verdict), beside the crack lengths.
3. With the mesh stage (campaigns/studies/ca_star_boundary_h2_pockets_meshes.toml: the same points on mesh_seed 1): label
   agreement between the two meshes at L_min = 4 mm, the crack-length spread, and the pooled fit.

The deterministic mesh is realization 0 of column ``mesh_seed``.  Units: lengths mm, C in %, Ca* dimensionless.

    python results/ca_star_boundary_h2_pockets/analyze.py SAMPLER_DIR [MESHES_DIR] [--out summary.json]
        [--figure meshes.png] [--crack-map crack_length.png]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import pandas as pd

from sweep.studies import label_agreement as la
from sweep.campaign.load import load_campaign

L_PROTOCOL = 4.0  # mm, the campaign's [classify] min_crack_length
L_SCAN = (2.0, 3.0, 4.0, 5.0, 6.0)  # mm
L_PEAK = (7.0, 8.0, 9.0, 10.0)  # mm: the longest-crack scan (8 mm: the rule chosen on the h = 1 line)
COLUMNS = ["mesh_seed", "cement", "eta_o", "Ca_star", "crack_length", "open_tip_radius_max", "r_inner"]


def completed(campaign_dir: Path, mesh_seed: int | None) -> pd.DataFrame:
    """The campaign's ok runs; ``mesh_seed`` fills the column when the campaign does not sweep it."""
    df = load_campaign(campaign_dir)
    df = df[df["status"] == "ok"]
    if mesh_seed is not None:
        df = df.assign(mesh_seed=mesh_seed)
    return df[COLUMNS].reset_index(drop=True)


def peak_record(df: pd.DataFrame) -> dict:
    """Not the protocol (added after the sampler's runs, reported whole): the label of sweep.regimes.classify's
    ``crack_record = "longest"`` (the longest crack up to the judged time, mm), whose L_min = 8 mm was chosen on
    the h = 1 random-field line (results/ca_star_peak_label_h2/), with the fit at L_PEAK; and the rank
    correlations of the judged and the longest crack with C and Ca*."""
    peak = la.longest(df)
    rho = {f"{which}_vs_{c}": v for which, d in (("judged", df), ("longest", peak))
           for c, v in la.rank_correlations(d).items()}
    return {"L_scan": {str(l): la.separatrix(peak, l) for l in L_PEAK}, "spearman": rho,
            "longest_crack_mm": la.crack_summary(peak),
            "closing_mm_median": float((peak["crack_length"] - df["crack_length"]).median())}


def paired(sampler: pd.DataFrame, meshes: pd.DataFrame) -> pd.DataFrame:
    """The sampler's runs at the mesh stage's points (matched exactly: the stage copies them at full precision)
    followed by the mesh stage's runs."""
    pts = meshes[la.POINT].drop_duplicates()
    return pd.concat([sampler.merge(pts, on=la.POINT), meshes], ignore_index=True)


def judge(sampler: pd.DataFrame, both: pd.DataFrame | None) -> dict:
    """Parts 1-2 on the sampler's runs and, with the mesh stage (``both``: :func:`paired`), part 3."""
    out = {"sampler": {"at_L4": la.separatrix(sampler, L_PROTOCOL),
                       "L_scan": {str(l): la.separatrix(sampler, l) for l in L_SCAN},
                       "crack_length_mm": la.crack_summary(sampler)},
           "longest_crack_not_protocol": peak_record(sampler)}
    if both is not None:
        out["meshes"] = {**la.judge(both, "mesh_seed", L_PROTOCOL, L_SCAN),
                         "agreement_L_scan": {str(l): la.agreement(both, "mesh_seed", l) for l in L_SCAN}}
    return out


def crack_map(df: pd.DataFrame, path: Path) -> None:
    """PNG at ``path``: the crack length (mm, colour) over the Ca*-C plane, one panel per mesh (column
    ``mesh_seed``).  Axes: C (%), Ca* (-, log)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    seeds = sorted(df["mesh_seed"].unique())
    fig, axes = plt.subplots(1, len(seeds), figsize=(4.8 * len(seeds), 4.0), sharey=True, squeeze=False)
    lo, hi = df["crack_length"].min(), df["crack_length"].max()
    for ax, s in zip(axes[0], seeds):
        d = df[df["mesh_seed"] == s]
        sc = ax.scatter(d["cement"], d["Ca_star"], c=d["crack_length"], cmap="viridis", vmin=lo, vmax=hi)
        ax.set_yscale("log")
        ax.set_xlabel("cement volume ratio C (%)")
        ax.set_title(f"mesh_seed {s} ({'deterministic' if s == 0 else 'perturbed'} mesh), {len(d)} runs", fontsize=9)
    axes[0][0].set_ylabel("modified capillary number Ca* (-)")
    fig.colorbar(sc, ax=axes[0].tolist(), label="crack length at the judged time (mm)")
    fig.suptitle("Crack length, three-pocket field (h = 2 mm)", fontsize=10)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sampler_dir", type=Path)
    ap.add_argument("meshes_dir", type=Path, nargs="?")
    ap.add_argument("--out", type=Path)
    ap.add_argument("--figure", type=Path, help="PNG: the labels per mesh and the share of meshes fracturing")
    ap.add_argument("--crack-map", type=Path, help="PNG: the crack length over the Ca*-C plane per mesh")
    a = ap.parse_args(argv)
    sampler = completed(a.sampler_dir, 0)
    both = paired(sampler, completed(a.meshes_dir, None)) if a.meshes_dir else None
    out = judge(sampler, both)
    if a.figure and both is not None:
        la.figure(both, out["meshes"], "mesh_seed", L_PROTOCOL, a.figure,
                  f"Ca*-C labels at L_min = {L_PROTOCOL:g} mm on the three-pocket field, deterministic mesh (0) "
                  "and a perturbed one (1); h = 2 mm, B in 1/%, 95 % intervals")
    if a.crack_map:
        crack_map(sampler if both is None else pd.concat([sampler, both[both["mesh_seed"] != 0]]), a.crack_map)
    la.report(out, a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
