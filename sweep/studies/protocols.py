"""The judging protocols of the boundary lines, each declared in its campaign's header before the runs.

A protocol reads a finished campaign's table (``sweep.campaign.load.load_campaign``, ok runs only) and returns
a JSON-able summary built from :mod:`sweep.studies.label_agreement`; ``dchfrac judge`` writes it as
``summary.json`` beside the committed table, with the protocol's figures:

* ``draws`` (campaigns/studies/ca_star_boundary_h2_draws.toml): label agreement over the porosity draws (column
  ``seed``) at L_min = 4 mm, the separatrix Ca*_c = A exp(B C) per draw and pooled (verdict: B > 0 at 2 sigma,
  pooled), the pooled fit over L_min = 2-6 mm;
* ``pockets`` (campaigns/studies/ca_star_boundary_h2_pockets.toml, with the mesh stage ``..._meshes.toml`` as the
  second folder): the separatrix on the sampler's runs at L_min = 4 mm (the verdict) and over 2-6 mm, the crack
  lengths; the longest-crack record (not the protocol, reported whole); with the mesh stage, agreement between
  the deterministic mesh (``mesh_seed`` 0) and the perturbed one and the pooled fit;
* ``pockets_tip`` (campaigns/studies/ca_star_boundary_h2_pockets_tip.toml): the separatrix at L_min = 6 mm (the
  verdict), the fit over 4-10 mm for the judged and the longest crack, their lengths and rank correlations;
* ``experiment_lines`` (campaigns/studies/experiment_ca_star_eta_line.toml, with the w_i line
  ``experiment_ca_star_rate_line.toml`` as the second folder): per line and pooled, the separatrix at
  L_min = 4 mm (the verdict: "B > 0 at 2 sigma", or the evidence that there is none) and over 2-6 mm, every run
  with its time reached and front radius beside its label, and the failed runs, which carry no label; with
  ``--fallback <line>_upwind_fallback`` folders, the secondary verdict with the failed runs rerun by the
  headers' fallback (:mod:`sweep.studies.experiment_lines`);
* ``nf_nb_draws`` (campaigns/studies/nf_vs_nb_probabilities_h2.toml): the share of points whose porosity draws
  give one regime, over the grid and on each side of N_f = 1 and N_b = 1, and near each delimiter against
  farther away (:mod:`sweep.studies.nf_nb_draws`);
* ``nf_nb_quadrants`` (campaigns/studies/nf_vs_nb_h2_wall_floor.toml, experiment_nf_vs_nb.toml): rows 17–17d of
  results/README.md, the regimes on each side of the paper's delimiters N_f = 1 and N_b = 1 against the paper's,
  with dp_cri estimated from the judged runs; with ``--fallback <campaign>_upwind_fallback`` the secondary
  verdict, and with a second folder the label-by-label comparison with that reference campaign
  (:mod:`sweep.studies.nf_nb_quadrants`).

Units: lengths mm, C in %, eta_o in kPa s, Ca* dimensionless.
"""
from __future__ import annotations

from pathlib import Path

import pandas as pd

from sweep.campaign.load import load_campaign
from sweep.figio import write_figure
from sweep.studies import label_agreement as la
from sweep.studies.commands import PROTOCOL_NAMES

__all__ = ["PROTOCOLS", "judge_draws", "judge_pockets", "judge_pockets_tip", "crack_map"]

DRAWS_L, DRAWS_SCAN = 4.0, (2.0, 3.0, 4.0, 5.0, 6.0)  # mm: the draws campaign's [classify] min_crack_length, scan
POCKETS_L, POCKETS_SCAN = 4.0, (2.0, 3.0, 4.0, 5.0, 6.0)  # mm
POCKETS_PEAK = (7.0, 8.0, 9.0, 10.0)  # mm: the longest-crack scan (8 mm: the rule chosen on the h = 1 line)
TIP_L, TIP_SCAN = 6.0, (4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0)  # mm
DRAWS_COLUMNS = ["seed", "cement", "eta_o", "Ca_star", "crack_length"]
POCKETS_COLUMNS = ["mesh_seed", "cement", "eta_o", "Ca_star", "crack_length", "open_tip_radius_max", "r_inner"]


def ok_runs(campaign_dir, columns=None, **fill) -> pd.DataFrame:
    """The campaign's ok runs (``columns`` only, when given); ``fill`` sets columns the campaign does not sweep."""
    df = load_campaign(campaign_dir)
    df = df[df["status"] == "ok"].assign(**fill)
    return (df[columns] if columns else df).reset_index(drop=True)


def judge_draws(runs: pd.DataFrame) -> dict:
    """The draws protocol on the ok runs (columns ``DRAWS_COLUMNS``)."""
    return la.judge(runs, "seed", DRAWS_L, DRAWS_SCAN)


def _peak_record(df: pd.DataFrame) -> dict:
    """The label of ``crack_record = "longest"`` (the longest crack up to the judged time, mm) with the fit at
    ``POCKETS_PEAK``, the rank correlations of the judged and the longest crack with C and Ca*, and the median
    closing (longest - judged, mm)."""
    peak = la.longest(df)
    rho = {f"{which}_vs_{c}": v for which, d in (("judged", df), ("longest", peak))
           for c, v in la.rank_correlations(d).items()}
    return {"L_scan": {str(l): la.separatrix(peak, l) for l in POCKETS_PEAK}, "spearman": rho,
            "longest_crack_mm": la.crack_summary(peak),
            "closing_mm_median": float((peak["crack_length"] - df["crack_length"]).median())}


def paired(sampler: pd.DataFrame, meshes: pd.DataFrame) -> pd.DataFrame:
    """The sampler's runs at the mesh stage's points (matched exactly: the stage copies them at full precision)
    followed by the mesh stage's runs."""
    pts = meshes[la.POINT].drop_duplicates()
    return pd.concat([sampler.merge(pts, on=la.POINT), meshes], ignore_index=True)


def judge_pockets(sampler: pd.DataFrame, both: pd.DataFrame | None = None) -> dict:
    """The pockets protocol on the sampler's ok runs and, with the mesh stage (``both``: :func:`paired`), its
    mesh comparison."""
    out = {"sampler": {"at_L4": la.separatrix(sampler, POCKETS_L),
                       "L_scan": {str(l): la.separatrix(sampler, l) for l in POCKETS_SCAN},
                       "crack_length_mm": la.crack_summary(sampler)},
           "longest_crack_not_protocol": _peak_record(sampler)}
    if both is not None:
        out["meshes"] = {**la.judge(both, "mesh_seed", POCKETS_L, POCKETS_SCAN),
                         "agreement_L_scan": {str(l): la.agreement(both, "mesh_seed", l) for l in POCKETS_SCAN}}
    return out


def judge_pockets_tip(runs: pd.DataFrame) -> dict:
    """The tip-refined pockets protocol on the ok runs."""
    out = {"runs": int(len(runs)), "at_L6": la.separatrix(runs, TIP_L)}
    for name, d in (("judged", runs), ("longest", la.longest(runs))):
        out[name] = {"L_scan": {str(l): la.separatrix(d, l) for l in TIP_SCAN},
                     "crack_length_mm": la.crack_summary(d), "spearman": la.rank_correlations(d)}
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
    write_figure(fig, path, dpi=110)
    plt.close(fig)


def _run_draws(a) -> dict:
    runs = ok_runs(a.campaign_dir, DRAWS_COLUMNS)
    out = judge_draws(runs)
    if a.figure:
        la.figure(runs, out, "seed", DRAWS_L, a.figure, f"Ca*-C labels at L_min = {DRAWS_L:g} mm over the "
                  "porosity draws (h = 2 mm); B in 1/%, 95 % intervals")
    return out


def _run_pockets(a) -> dict:
    sampler = ok_runs(a.campaign_dir, POCKETS_COLUMNS, mesh_seed=0)
    both = paired(sampler, ok_runs(a.second_dir, POCKETS_COLUMNS)) if a.second_dir else None
    out = judge_pockets(sampler, both)
    if a.figure and both is not None:
        la.figure(both, out["meshes"], "mesh_seed", POCKETS_L, a.figure,
                  f"Ca*-C labels at L_min = {POCKETS_L:g} mm on the three-pocket field, deterministic mesh (0) "
                  "and a perturbed one (1); h = 2 mm, B in 1/%, 95 % intervals")
    if a.crack_map:
        crack_map(sampler if both is None else pd.concat([sampler, both[both["mesh_seed"] != 0]]), a.crack_map)
    return out


def _run_pockets_tip(a) -> dict:
    return judge_pockets_tip(ok_runs(a.campaign_dir))


def _fallback_line(d) -> str:
    """The line a fallback folder belongs to: its name without ``experiment_lines.FALLBACK_SUFFIX``."""
    from sweep.studies.experiment_lines import FALLBACK_SUFFIX

    return Path(d).name.removesuffix(FALLBACK_SUFFIX)


def _check_fallback(a) -> str | None:
    """Why ``--fallback`` cannot be judged (another protocol, a folder not named <line>_upwind_fallback for a
    line judged here), or None."""
    from sweep.studies.experiment_lines import FALLBACK_SUFFIX

    if a.protocol not in FALLBACK_JUDGED:
        return f"--fallback {a.fallback[0]}: only {' and '.join(FALLBACK_JUDGED)} take a fallback campaign"
    names = {Path(d).name for d in filter(None, (getattr(a, f) for f in FALLBACK_JUDGED[a.protocol]))}
    if len(a.fallback) > len(names):
        return (f"--fallback given {len(a.fallback)} times: {a.protocol} judges {len(names)} campaign(s) here "
                f"(allowed: one fallback each)")
    for d in a.fallback:
        if not Path(d).name.endswith(FALLBACK_SUFFIX) or _fallback_line(d) not in names:
            return (f"--fallback {d}: its folder must be named <line>{FALLBACK_SUFFIX} for a line judged here "
                    f"(allowed lines: {sorted(names)})")
    return None


def _run_experiment_lines(a) -> dict:
    from sweep.studies import experiment_lines as el

    lines = {Path(d).name: load_campaign(d) for d in filter(None, (a.campaign_dir, a.second_dir))}
    fallback = {_fallback_line(d): load_campaign(d) for d in a.fallback or ()}
    out = el.judge(lines, fallback or None)
    if a.figure:
        el.figure(lines, out, a.figure, fallback)
    return out


def _run_nf_nb_draws(a) -> dict:
    from sweep.studies import nf_nb_draws

    return nf_nb_draws.judge_dir(a.campaign_dir)


def _run_nf_nb_quadrants(a) -> dict:
    from sweep.studies import nf_nb_quadrants

    fallback = a.fallback[0] if a.fallback else None
    return nf_nb_quadrants.judge(a.campaign_dir, fallback_dir=fallback, reference_dir=a.second_dir)


#: what each protocol of ``dchfrac judge`` (sweep.studies.commands.PROTOCOL_NAMES) runs
PROTOCOLS = dict(zip(PROTOCOL_NAMES, (_run_draws, _run_pockets, _run_pockets_tip, _run_experiment_lines,
                                      _run_nf_nb_draws, _run_nf_nb_quadrants)))
#: the protocols that take a second campaign folder, and what it is
SECOND_DIR = {"pockets": "its mesh stage", "experiment_lines": "the w_i line",
              "nf_nb_quadrants": "a reference campaign over the same grid"}
#: the protocols that take a fallback campaign (``--fallback``), and the arguments naming the campaigns it may
#: stand in for (nf_nb_quadrants' second folder is a reference, not judged)
FALLBACK_JUDGED = {"experiment_lines": ("campaign_dir", "second_dir"), "nf_nb_quadrants": ("campaign_dir",)}


def cmd_judge(a) -> int:
    import sys

    if a.second_dir and a.protocol not in SECOND_DIR:
        allowed = "; ".join(f"{k} ({v})" for k, v in SECOND_DIR.items())
        print(f"dchfrac judge: SECOND_DIR={a.second_dir}: only these protocols take a second campaign: {allowed}",
              file=sys.stderr)
        return 2
    why = _check_fallback(a) if a.fallback else None
    if why:
        print(f"dchfrac judge: {why}", file=sys.stderr)
        return 2
    for d in filter(None, (a.campaign_dir, a.second_dir, *(a.fallback or ()))):
        if not (Path(d) / "table.csv").is_file():
            print(f"dchfrac judge: {d}: no table.csv (allowed: a campaign folder with its table)", file=sys.stderr)
            return 2
    try:
        out = PROTOCOLS[a.protocol](a)
    except ValueError as e:  # an input the protocol cannot judge: named, nothing written
        print(f"dchfrac judge: {e}", file=sys.stderr)
        return 2
    la.report(out, a.out)
    return 0
