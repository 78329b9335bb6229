"""Replicates where they are needed: one round of a boundary campaign whose labels are random (issue #51).

A point of the plane carries a label probability p (the porosity draw decides the label, see
``sweep.regimes.probability``).  Each round fits the separatrix of the two axes (a straight line in the
transformed plane: the first axis as given or in decades, the second in decades, e.g. C and Ca*, or C and
eta_o at fixed w_i) with its simultaneous band (:func:`sweep.regimes.probability.separatrix_band`), then:

* **stopping rule**: stop when the fit is significant and the band's half-width is <= ``band_tolerance``
  (decades of the second axis) at both ends of the first axis (for a straight line the band is widest at an
  end, so this bounds it everywhere), or when the budget is spent;
* **replicates**: a sampled point is *clear* when the fitted probability there is below ``clear`` or above
  1 - ``clear``: its one run settles it.  The other points are *uncertain*; up to ``replicate_share`` of the
  batch goes to one more replicate of each of the most uncertain ones (|p - 1/2| smallest, then fewest
  replicates), none beyond ``max_replicates``;
* **new points**: the rest of the batch by the straddle score of ``sweep.campaign.boundary`` (band half-width
  at the candidate's first coordinate minus its distance to the line, both in decades), each pick excluding
  the candidates within its band; none within half a tolerance of a sampled point.  Before both labels are
  seen (or while the fit fails) the batch is space filling (maximin) with one run each.

Runs are (coords, replicate r); replicate r of a point runs its base porosity seed + r. Units: the axes'
(model units, decades on log axes); probabilities dimensionless.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from sweep.campaign.boundary_picks import picks, point_coords, tol_coords
from sweep.regimes.regime_model import AxisScale

__all__ = ["ReplicateSettings", "decide_round", "point_counts"]

_N_CANDIDATES = 2048     # candidate new points per round (seeded)


@dataclass(frozen=True)
class ReplicateSettings:
    """``max_replicates`` runs per point at most; ``clear``: fitted probability below it (or above 1 - it) settles
    a point; ``replicate_share`` of a batch at most for replicates; ``band_tolerance``: the stopping half-width
    (decades of the second axis); ``level`` of the band."""

    max_replicates: int = 5
    clear: float = 0.1
    replicate_share: float = 0.5
    band_tolerance: float = 0.25
    level: float = 0.95


def point_counts(runs: Sequence[tuple]) -> dict[tuple, dict]:
    """{coords: {"n": labelled runs, "k": True labels, "next": next replicate index}} of runs (coords, r, label);
    label None: a failed run (it takes its replicate index, it gives no label)."""
    out: dict[tuple, dict] = {}
    for coords, r, lab in runs:
        d = out.setdefault(tuple(coords), {"n": 0, "k": 0, "next": 0})
        d["next"] = max(d["next"], int(r) + 1)
        if lab is not None:
            d["n"] += 1
            d["k"] += int(bool(lab))
    return out


def _plane(axes: Sequence[AxisScale], coords) -> tuple[np.ndarray, np.ndarray]:
    """(first axis as fitted: value, or log10 on a log axis; second axis value > 0) of coords (n, 2)."""
    c = np.asarray(coords, float).reshape(-1, 2)
    return axes[0].to_t(c[:, 0]), c[:, 1]


def fit_round(axes: Sequence[AxisScale], runs: Sequence[tuple], s: ReplicateSettings):
    """The separatrix band at both ends of the first axis from the labelled runs, or None (one outcome seen, or
    the labels do not order along the second axis)."""
    from sweep.regimes.probability import separatrix_band

    lab = [(c, bool(v)) for c, _, v in runs if v is not None]
    if len(lab) < 3 or len({v for _, v in lab}) < 2:
        return None
    x, y = _plane(axes, [c for c, _ in lab])
    try:
        return separatrix_band(x, y, [v for _, v in lab], level=s.level, at=[axes[0].t_lo, axes[0].t_hi])
    except ValueError:
        return None


def decide_round(axes: Sequence[AxisScale], runs: Sequence[tuple], s: ReplicateSettings, *, batch: int,
                 budget: int, seed: int, round_no: int) -> dict[str, Any]:
    """Stop (``stop`` the reason) or the next ``batch`` of runs [(coords, r)], from ``runs`` [(coords, r, label)].
    Also returns ``band`` (the fit, or None) and ``half`` (largest half-width, decades)."""
    band = fit_round(axes, runs, s)
    half = float(np.max(band.half_width_decades)) if band is not None else math.inf
    out = {"band": band, "half": half, "stop": "", "batch": []}
    used = len(runs)
    if band is not None and band.significant and half <= s.band_tolerance:
        out["stop"] = (f"converged: the {s.level:.0%} band of the separatrix is {half:.3g} decades wide at most "
                       f"(<= {s.band_tolerance:g}) after {used} runs")
        return out
    if used >= budget:
        out["stop"] = f"budget spent: {used} of {budget} runs; band half-width {half:.3g} decades"
        return out
    n = min(batch, budget - used)
    counts = point_counts(runs)
    reps = _replicates(axes, counts, band, s, max(1, math.ceil(s.replicate_share * n))) if band is not None else []
    out["batch"] = reps + [(c, 0) for c in _new_points(axes, counts, band, n - len(reps), seed, round_no)]
    if len(out["batch"]) < n and band is not None:          # no room for new points: replicates fill the batch
        more = [r for r in _replicates(axes, counts, band, s, n) if r not in out["batch"]]
        out["batch"] += more[: n - len(out["batch"])]
    if not out["batch"]:
        out["stop"] = f"resolution reached: no new point and no uncertain point below {s.max_replicates} replicates"
    return out


def _probability(axes, band, coords) -> np.ndarray:
    x, y = _plane(axes, coords)
    z = band.sharpness * (np.log(y) - math.log(band.A) - band.B * x)
    return 0.5 * (1.0 + np.tanh(0.5 * z))


def _replicates(axes, counts, band, s: ReplicateSettings, n: int) -> list[tuple]:
    """Up to n (coords, next replicate) of the uncertain points, most uncertain first."""
    pts = [c for c, d in counts.items() if d["next"] < s.max_replicates]
    if not pts:
        return []
    p = _probability(axes, band, pts)
    keep = [(abs(pi - 0.5), counts[c]["n"], c) for c, pi in zip(pts, p) if s.clear <= pi <= 1.0 - s.clear]
    keep.sort(key=lambda t: (t[0], t[1], t[2]))
    return [(c, counts[c]["next"]) for _, _, c in keep[:n]]


def _new_points(axes, counts, band, n: int, seed: int, round_no: int) -> list[tuple]:
    """Up to n new coords: straddle score against the band (maximin without a band), spaced as the boundary
    sampler's picks."""
    if n <= 0:
        return []
    rng = np.random.default_rng([seed, round_no, 51])
    U = rng.uniform(-1.0, 1.0, size=(_N_CANDIDATES, 2))
    T = tol_coords(axes, U)
    sampled = np.array(list(counts), float)
    S = tol_coords(axes, np.stack([a.to_u(sampled[:, j]) for j, a in enumerate(axes)], axis=1))
    dmin = np.min(np.linalg.norm(T[:, None, :] - S[None, :, :], axis=2), axis=1)
    score = half = None
    if band is not None:
        coords = np.stack([a.from_u(U[:, j]) for j, a in enumerate(axes)], axis=1)
        x, y = _plane(axes, coords)
        hw = np.interp(x, [axes[0].t_lo, axes[0].t_hi], band.reach_half_width_decades)   # finite where unbounded
        dist = np.abs(np.log10(y) - (math.log10(band.A) + band.B * x / math.log(10.0)))
        tol = axes[1].tolerance
        score, half = (hw - dist) / tol, hw / tol
    chosen = picks(U, T, dmin, score, half, n, 1.0)
    return [point_coords(axes, U[i]) for i in chosen]
