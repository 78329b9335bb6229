"""The N_f–N_b map over porosity draws judged by the protocol declared in its header (issue #51 item 5;
campaigns/studies/nf_vs_nb_probabilities_h2.toml, "Judging protocol"):

1. per point, each regime's probability with its Wilson interval and the continuous measures' mean and spread:
   the campaign's ``points.csv`` (``sweep.campaign.replicates``), read here, not recomputed;
2. the share of points whose draws give one regime (and one fracturing label), over the whole grid and on each
   side of N_f = 1 and of N_b = 1 (N_f from the dp_cri the campaign estimates, as its table);
3. for each of the paper's delimiters N_f = 1 and N_b = 1 (Sec. 3.8): the share of points within one decade of
   it whose draws disagree, against the share farther away; reported whole, with no verdict beyond it.

A point is judged when all its declared replicates finished ok (``complete``); the others are counted, never
dropped silently.  Every share carries its Wilson 95 % interval (``sweep.regimes.probability.wilson_interval``).

Units: N_f, N_b dimensionless; shares in [0, 1].
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from sweep.regimes.probability import wilson_interval

__all__ = ["DECADES", "DELIMITERS", "replicates_declared", "complete_points", "share", "judge", "judge_dir"]

DECADES = 1.0  # "within one decade" of a delimiter: |log10 N| <= 1
DELIMITERS = ("N_f", "N_b")  # the paper's delimiters, each at N = 1 (Sec. 3.8)


def replicates_declared(spec_path: Path) -> int:
    """The runs per point a campaign's spec declares: the product of its ``[replicates]`` counts (1 without)."""
    import tomllib

    spec = tomllib.loads(Path(spec_path).read_text())
    return math.prod(int(v) for v in spec.get("replicates", {}).values())


def complete_points(points: pd.DataFrame, replicates: int) -> pd.DataFrame:
    """The points whose ``replicates`` runs all finished ok (``n_ok``), with ``fracturing_mixed``: their draws
    disagree on the fracturing label (0 < p_fracturing < 1)."""
    if replicates < 2:
        raise ValueError(f"nf_nb_draws: replicates={replicates}: the protocol compares draws (allowed: >= 2)")
    done = points[points["n_ok"] == replicates].copy()
    p = done["p_fracturing"].to_numpy(float)
    done["fracturing_mixed"] = (p > 0.0) & (p < 1.0)
    done["mixed"] = done["mixed"].astype(bool)
    return done


def share(mask) -> dict:
    """k of n with the share k/n and its Wilson 95 % interval (None for n = 0)."""
    mask = np.asarray(mask, bool)
    k, n = int(mask.sum()), int(mask.size)
    lo, hi = wilson_interval(k, n)
    return {"k": k, "n": n, "share": k / n if n else None, "wilson_95": [float(lo), float(hi)]}


def _agreement(done: pd.DataFrame) -> dict:
    """Measure 2: the share of points with one regime, and with one fracturing label, over the grid and on each
    side of each delimiter."""
    sides = {"all": np.ones(len(done), bool)}
    for d in DELIMITERS:
        v = done[d].to_numpy(float)
        sides[f"{d} < 1"], sides[f"{d} >= 1"] = v < 1.0, v >= 1.0
    return {which: {side: share(~done[col].to_numpy(bool)[m]) for side, m in sides.items()}
            for which, col in (("one_regime", "mixed"), ("one_fracturing_label", "fracturing_mixed"))}


def _near_delimiters(done: pd.DataFrame) -> dict:
    """Measure 3: per delimiter, the share of points whose draws disagree on the regime within DECADES of it
    and farther away."""
    out = {}
    mixed = done["mixed"].to_numpy(bool)
    for d in DELIMITERS:
        v = done[d].to_numpy(float)
        known = np.isfinite(v) & (v > 0)
        near = known & (np.abs(np.log10(np.where(known, v, 1.0))) <= DECADES)
        out[d] = {"within_one_decade": share(mixed[near]), "farther": share(mixed[known & ~near]),
                  "without_value": int((~known).sum())}
    return out


def judge(points: pd.DataFrame, replicates: int) -> dict:
    """The protocol's measures 2 and 3 on a campaign's points (``points.csv``) with ``replicates`` declared runs
    per point, and the count of points not judged (fewer ok runs)."""
    missing = sorted({"n_ok", "mixed", "p_fracturing", *DELIMITERS} - set(points.columns))
    if missing:
        raise ValueError(f"nf_nb_draws: points.csv lacks {missing} (allowed: a replicate campaign's points with "
                         "an nf_vs_nb diagram's dp_cri)")
    done = complete_points(points, replicates)
    return {"replicates": replicates, "points": int(len(points)), "complete": int(len(done)),
            "not_complete": int(len(points) - len(done)), "decades": DECADES,
            "agreement": _agreement(done), "near_delimiters": _near_delimiters(done)}


def judge_dir(campaign_dir: Path) -> dict:
    """:func:`judge` on a campaign folder's ``points.csv`` with the replicates its ``spec.toml`` declares."""
    d = Path(campaign_dir)
    for f in ("points.csv", "spec.toml"):
        if not (d / f).is_file():
            raise ValueError(f"nf_nb_draws: {d}: no {f} (allowed: a replicate campaign's folder with its report)")
    return judge(pd.read_csv(d / "points.csv"), replicates_declared(d / "spec.toml"))
