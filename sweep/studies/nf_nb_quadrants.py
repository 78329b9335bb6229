"""The N_f–N_b map judged by the paper's delimiters (Sec. 3.8; rows 17–17d of results/README.md).

A campaign over (η_o, η_w, k̄) with an ``nf_vs_nb`` diagram whose ``dp_cri = "estimate"`` is judged on its
labelled runs (status ok with a regime):

* dp_cri (kPa) is estimated from the judged runs as the campaign's table estimates it
  (``sweep.regimes.numbers.estimate_dp_cri``: the dp_vis where a logistic fit of the fracturing outcome crosses
  1/2), and N_f = dp_vis / dp_cri;
* row 17: the share of runs that fracture with N_f > 1 and the share that do not with N_f < 1;
* rows 17a and 17b: the regime counts on each side of N_b = 1, for N_f < 1 and N_f > 1, against the paper's
  regime there (uniform invasion below N_b = 1 and viscous fingering above for N_f < 1; invasive fracturing below
  and non-invasive fracturing above for N_f > 1).  A row is reproduced when the paper's regime is the most
  frequent label on both sides; each of the two paper regimes' share below and above N_b = 1 is reported beside
  it with its Wilson 95 % interval (the paper's direction, even where its delimiter is not reproduced, and
  whether the runs can tell the two sides apart);
* row 17c: where the fracturing-with-fingering runs fall; row 17d: the viscous-fingering runs with N_b > 1 and
  N_f > 1 (the paper: none);
* with a fallback campaign (its failed points rerun by a declared fallback, named ``<campaign>_upwind_fallback``):
  the SECONDARY verdict, the failed runs replaced by the fallback's (``experiment_lines.with_fallback``) and dp_cri
  re-estimated on that set, beside the PRIMARY one;
* with a reference campaign over the same grid: the label-by-label comparison of the points labelled in both
  (``sweep.campaign.compare.compare_campaigns``), never on N_f, whose scale each campaign estimates.

A failed run carries no label: counted, never dropped silently.  Units: dp_vis and dp_cri in kPa; N_f, N_b
dimensionless; η in kPa·s, k̄ in mm².
"""
from __future__ import annotations

from pathlib import Path

import pandas as pd

from sweep.regimes.numbers import estimate_dp_cri
from sweep.regimes.probability import wilson_interval

__all__ = ["POINT", "PAPER", "labelled", "judge_runs", "judge"]

POINT = ("eta_o", "eta_w", "kbar")  # a grid point: η_o, η_w (kPa·s), k̄ (mm²)
NB_SIDES = ("N_b < 1", "N_b > 1")  # the two sides of the paper's N_b = 1 delimiter
#: the paper's regime in each quadrant (Sec. 3.8), keyed (N_f side, N_b side)
PAPER = {("N_f < 1", "N_b < 1"): "uniform_invasion", ("N_f < 1", "N_b > 1"): "viscous_fingering",
         ("N_f > 1", "N_b < 1"): "invasive_fracturing", ("N_f > 1", "N_b > 1"): "non_invasive_fracturing"}
ROWS = {"17a": "N_f < 1", "17b": "N_f > 1"}


def labelled(runs: pd.DataFrame) -> pd.DataFrame:
    """The runs that carry a label: status ok with a regime and a fracturing outcome."""
    return runs[(runs["status"] == "ok") & runs["regime"].notna() & runs["fracturing"].notna()]


def _quadrant_masks(ok: pd.DataFrame) -> dict:
    nf, nb = ok["N_f"].to_numpy(float), ok["N_b"].to_numpy(float)
    side = {"N_f < 1": nf < 1.0, "N_f > 1": nf >= 1.0, "N_b < 1": nb < 1.0, "N_b > 1": nb >= 1.0}
    return {(f, b): side[f] & side[b] for f, b in PAPER}


def _counts(labels: pd.Series) -> dict:
    return {str(k): int(v) for k, v in labels.value_counts().sort_index().items()}


def _share(k: int, n: int) -> dict:
    """k of n with the Wilson 95 % interval of the share (dimensionless; [0, 1] for n = 0)."""
    lo, hi = wilson_interval(k, n)
    return {"k": int(k), "n": int(n), "wilson_95": [round(float(lo), 4), round(float(hi), 4)]}


def _row_17ab(quads: dict, f_side: str) -> dict:
    """Rows 17a/17b: the counts on each side of N_b = 1 at one side of N_f = 1, the paper's regimes, whether the
    paper's regime is the most frequent label on both sides, and each of the two paper regimes' share on each
    side (the paper's direction, where its delimiter is not reproduced)."""
    c = {b: quads[(f_side, b)] for b in NB_SIDES}
    paper = {b: PAPER[(f_side, b)] for b in NB_SIDES}

    def top(counts):  # the most frequent label; None when two labels tie for it
        best = sorted(counts.values())[-2:]
        return max(counts, key=counts.get) if best and (len(best) == 1 or best[0] < best[1]) else None

    shares = {regime: {b: _share(c[b].get(regime, 0), sum(c[b].values())) for b in c} for regime in paper.values()}
    return {**c, "paper": paper, "reproduced": all(top(c[b]) == paper[b] for b in c), "paper_regime_shares": shares}


def judge_runs(runs: pd.DataFrame) -> dict:
    """Rows 17–17d on one set of runs (a campaign's table, or the one with its fallback): dp_cri (kPa) estimated
    from its labelled runs, the rows' counts and verdicts, and the runs without a label."""
    ok = labelled(runs)
    est = estimate_dp_cri(ok["dp_vis"].to_numpy(float), ok["fracturing"].astype(bool).to_numpy())
    ok = ok.assign(N_f=ok["dp_vis"].astype(float) / est.dp_cri)
    masks = _quadrant_masks(ok)
    quads = {q: _counts(ok.loc[m, "regime"]) for q, m in masks.items()}
    fr = ok["fracturing"].astype(bool).to_numpy()
    above = ok["N_f"].to_numpy(float) >= 1.0
    ff = ok["regime"].to_numpy() == "fracturing_fingering"
    vf_high = quads[("N_f > 1", "N_b > 1")].get("viscous_fingering", 0)
    return {
        "runs": int(len(runs)), "labelled": int(len(ok)), "without_label": int(len(runs) - len(ok)),
        "dp_cri_kPa": est.dp_cri, "dp_cri_interval_kPa": list(est.interval),
        "17": {"fracture_with_N_f_above_1": {"k": int(fr[above].sum()), "n": int(above.sum())},
               "no_fracture_with_N_f_below_1": {"k": int((~fr[~above]).sum()), "n": int((~above).sum())}},
        **{row: _row_17ab(quads, f_side) for row, f_side in ROWS.items()},
        "17c": {f"{f}, {b}": int((m & ff).sum()) for (f, b), m in masks.items()},
        "17d": {"viscous_fingering_with_N_b_and_N_f_above_1": vf_high, "reproduced": vf_high == 0},
    }


def _reference(campaign_dir, reference_dir) -> dict:
    """The label-by-label comparison with a reference campaign over the same grid (points labelled in both)."""
    from sweep.campaign.compare import compare_campaigns

    c = compare_campaigns(campaign_dir, reference_dir)
    both = c.pairs[(c.pairs["status_a"] == "ok") & (c.pairs["status_b"] == "ok")]
    both = both[both["regime_a"].notna() & both["regime_b"].notna()]
    same = both["regime_a"].astype(str).to_numpy() == both["regime_b"].astype(str).to_numpy()
    moved = both[~same].groupby(["regime_b", "regime_a"]).size()
    return {"reference": c.b, "matched": int(len(c.pairs)), "labelled_in_both": int(len(both)),
            "same_label": int(same.sum()),
            "moved": [{"reference": str(b), "this": str(a), "runs": int(n)} for (b, a), n in moved.items()]}


def judge(campaign_dir, *, fallback_dir=None, reference_dir=None) -> dict:
    """Rows 17–17d of a campaign folder (PRIMARY: failed runs carry no label); with ``fallback_dir`` the
    SECONDARY verdict beside it; with ``reference_dir`` the label-by-label comparison with that campaign."""
    from sweep.campaign.load import load_campaign
    from sweep.studies.experiment_lines import with_fallback

    runs = load_campaign(campaign_dir)
    out = {"campaign": Path(campaign_dir).name, "primary": judge_runs(runs)}
    out["primary"]["failed"] = runs.loc[runs["status"] != "ok", list(POINT)].to_dict("records")
    if fallback_dir is not None:
        merged, n = with_fallback(runs, load_campaign(fallback_dir), point=POINT, who="nf_nb_quadrants")
        out["secondary"] = {**judge_runs(merged), "fallback": Path(fallback_dir).name, "replaced": n,
                            "fallback_labels": _counts(labelled(merged[merged["fallback"]])["regime"])}
    if reference_dir is not None:
        out["against_reference"] = _reference(campaign_dir, reference_dir)
    return out

