"""Verification of probabilistic boundaries on a stochastic oracle (issue #51, item 4): band coverage and runs.

The oracle is a Ca*-C map whose label flips with a known probability that depends on the distance to a known
boundary.  The boundary is the exponential separatrix log10 Ca*_c(C) = log10 A + B C log10(e) (a straight line in
the (C, log Ca*) plane); a run at distance d = log10 Ca* - log10 Ca*_c(C) (decades) has the label of its side
(fracturing above) flipped with probability q(d) = exp(-|d| / w) / 2, so that P(fracturing) is 1/2 on the
boundary and tends to 0 or 1 over a few ``width`` w.  The link is a Laplace CDF, not the logistic of the fitted
model: the study also checks that the band does not lean on the link's shape.  Each label is a seeded
function of (study seed, point, replicate), as a porosity draw is of its seed.

For each study seed two designs label the map:

* **grid**: g x g points (C linear, Ca* log, over the domain) with R replicates each (g^2 R runs);
* **sampler**: ``sweep.campaign.replicate_allocation`` from a Latin-hypercube start, one run per new point and
  replicates where the fitted probability is uncertain, stopped by its rule when the band's half-width is <=
  the grid's half-width on the same seed (the same precision), or at the grid's run count.

Reported (``summary.json``): per seed and over the seeds, the runs used by the sampler against the grid's
(target <= 1/2), whether the simultaneous 95 % band covers the whole true line over the C range (target >= 90 %
of seeds for the sampler), and the band half-widths (decades).  Units: C in %, Ca* dimensionless, widths in
decades of Ca*.

    python -m sweep.studies.oracle --seeds 20 --out results/uncertain_diagrams/oracle
"""
from __future__ import annotations

import argparse
import json
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from sweep.campaign.replicate_allocation import ReplicateSettings, decide_round
from sweep.regimes.regime_model import AxisScale

__all__ = ["StochasticOracle", "StudySettings", "run_grid", "run_sampler", "run_study", "main"]


@dataclass(frozen=True)
class StochasticOracle:
    """The map: boundary Ca*_c = A exp(B C) (A -, B 1/%), flip scale ``width`` (decades of Ca*), domain C in
    [c_lo, c_hi] (%) and Ca* in [ca_lo, ca_hi]."""

    A: float = 1.0e6
    B: float = 1.2
    width: float = 0.2
    c_lo: float = 0.5
    c_hi: float = 3.0
    ca_lo: float = 1.0e5
    ca_hi: float = 1.0e9

    def line(self, C: Any) -> np.ndarray:
        """log10 Ca*_c(C)."""
        return (math.log(self.A) + self.B * np.asarray(C, float)) / math.log(10.0)

    def probability(self, C: Any, ca_star: Any) -> np.ndarray:
        """P(fracturing) at (C, Ca*): 1 - q(d) above the boundary, q(d) below, q(d) = exp(-|d|/w) / 2."""
        d = np.log10(np.asarray(ca_star, float)) - self.line(C)
        q = 0.5 * np.exp(-np.abs(d) / self.width)
        return np.where(d > 0, 1.0 - q, q)

    def label(self, coords: tuple, replicate: int, seed: int) -> bool:
        """One draw at (C, Ca*), a function of (seed, point, replicate) only."""
        C, ca = coords
        key = [int(seed), int(round(C * 1e6)), int(round(math.log10(ca) * 1e6)) % 2**31, int(replicate)]
        return bool(np.random.default_rng(key).uniform() < float(self.probability(C, ca)))

    def axes(self, tolerance: float = 0.1) -> tuple[AxisScale, AxisScale]:
        return (AxisScale("cement", self.c_lo, self.c_hi, False, tolerance),
                AxisScale("Ca_star", self.ca_lo, self.ca_hi, True, tolerance))


@dataclass(frozen=True)
class StudySettings:
    """grid g x g with ``grid_replicates`` each; the sampler's ``batch``, ``n_initial`` LHS points and its
    ``max_replicates``, ``clear``, ``replicate_share``; ``level`` of the bands; ``n_band`` C values where coverage
    is checked."""

    grid: int = 6
    grid_replicates: int = 5
    batch: int = 6
    n_initial: int = 9
    max_replicates: int = 5
    clear: float = 0.1
    replicate_share: float = 0.5
    level: float = 0.95
    n_band: int = 7


def _band(oracle: StochasticOracle, runs, level: float, n_band: int) -> dict:
    """The full band of the labelled runs and whether it covers the true line at every one of n_band C values."""
    from sweep.regimes.probability import separatrix_band

    C = [c[0] for c, _, _ in runs]
    ca = [c[1] for c, _, _ in runs]
    at = np.linspace(oracle.c_lo, oracle.c_hi, n_band)
    try:
        b = separatrix_band(C, ca, [v for _, _, v in runs], level=level, at=at)
    except ValueError as exc:
        return {"covers": False, "half_max": None, "significant": False, "why": str(exc)}
    truth = oracle.line(at) * math.log(10.0)
    return {"covers": b.covers(truth), "half_max": float(np.max(b.half_width_decades)),
            "half_ends": [float(b.half_width_decades[0]), float(b.half_width_decades[-1])],
            "significant": b.significant, "A": b.A, "B": b.B}


def run_grid(oracle: StochasticOracle, seed: int, st: StudySettings) -> dict:
    """The g x g grid with its replicates on one seed: runs, band (see :func:`_band`), the labelled runs."""
    Cs = np.linspace(oracle.c_lo, oracle.c_hi, st.grid)
    cas = np.geomspace(oracle.ca_lo, oracle.ca_hi, st.grid)
    runs = [((float(c), float(a)), r, oracle.label((float(c), float(a)), r, seed))
            for c in Cs for a in cas for r in range(st.grid_replicates)]
    return {"runs": len(runs), **_band(oracle, runs, st.level, st.n_band), "labels": runs}


def run_sampler(oracle: StochasticOracle, seed: int, st: StudySettings, band_tolerance: float, budget: int) -> dict:
    """The replicate-allocating sampler on one seed until its stopping rule: runs used, rounds, why it stopped,
    points and replicate counts, and the final band (see :func:`_band`)."""
    from sweep.campaign.boundary import BoundarySampler, BoundarySettings

    axes = oracle.axes()
    rs = ReplicateSettings(st.max_replicates, st.clear, st.replicate_share, band_tolerance, st.level)
    init = BoundarySampler._initial_coords(BoundarySettings(budget, 0.1, seed=seed, n_initial=st.n_initial), axes, None)
    runs = [(c, 0, oracle.label(c, 0, seed)) for c in init]
    rnd = 1
    while True:
        dec = decide_round(axes, runs, rs, batch=st.batch, budget=budget, seed=seed, round_no=rnd)
        if dec["stop"]:
            break
        runs += [(c, r, oracle.label(c, r, seed)) for c, r in dec["batch"]]
        rnd += 1
    reps: dict = {}
    for c, _, _ in runs:
        reps[c] = reps.get(c, 0) + 1
    hist = np.bincount(list(reps.values()))
    return {"runs": len(runs), "rounds": rnd, "reason": dec["stop"], "points": len(reps),
            "replicate_histogram": {str(i): int(v) for i, v in enumerate(hist) if i and v},
            **_band(oracle, runs, st.level, st.n_band), "labels": runs}


def run_study(seeds, oracle: StochasticOracle | None = None, st: StudySettings | None = None,
              progress=None) -> dict:
    """Both designs on each seed; the per-seed results and the totals (see the module docstring)."""
    oracle, st = oracle or StochasticOracle(), st or StudySettings()
    rows = []
    for seed in seeds:
        t0 = time.perf_counter()
        g = run_grid(oracle, seed, st)
        target = g["half_max"] if g["half_max"] is not None else math.inf
        s = run_sampler(oracle, seed, st, target, g["runs"])
        row = {"seed": int(seed), "grid": {k: v for k, v in g.items() if k != "labels"},
               "sampler": {k: v for k, v in s.items() if k != "labels"}, "runs_ratio": s["runs"] / g["runs"],
               "wall_s": round(time.perf_counter() - t0, 1)}
        rows.append(row)
        if progress:
            print(json.dumps({k: row[k] for k in ("seed", "runs_ratio", "wall_s")} | {
                "sampler_covers": s["covers"], "grid_covers": g["covers"], "sampler_half": s["half_max"],
                "grid_half": g["half_max"]}), file=progress, flush=True)
    ratio = np.array([r["runs_ratio"] for r in rows])
    return {"oracle": asdict(oracle), "settings": asdict(st), "n_seeds": len(rows),
            "sampler_coverage": float(np.mean([r["sampler"]["covers"] for r in rows])),
            "grid_coverage": float(np.mean([r["grid"]["covers"] for r in rows])),
            "runs_ratio_median": float(np.median(ratio)), "runs_ratio_max": float(ratio.max()),
            "runs_ratio_mean": float(ratio.mean()),
            "sampler_converged": int(sum(r["sampler"]["reason"].startswith("converged") for r in rows)),
            "seeds": rows}


def main(argv=None) -> int:
    import sys

    from sweep.campaign.store import write_json_atomic

    ap = argparse.ArgumentParser(prog="python -m sweep.studies.oracle", description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=20, help="number of study seeds (0 .. n-1)")
    ap.add_argument("--out", type=Path, required=True, help="output folder (summary.json, figures/)")
    a = ap.parse_args(argv)
    if a.seeds < 1:
        ap.error(f"--seeds={a.seeds}: must be >= 1")
    t0 = time.perf_counter()
    summary = run_study(range(a.seeds), progress=sys.stderr)
    summary["wall_s"] = round(time.perf_counter() - t0, 1)
    a.out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(a.out / "summary.json", summary)
    _figures(a.out / "figures", StochasticOracle(), StudySettings(), summary)
    print(json.dumps({k: v for k, v in summary.items() if k != "seeds"}, indent=1))
    return 0


def _figures(out: Path, oracle: StochasticOracle, st: StudySettings, summary: dict) -> None:
    """Seed 0's two diagrams (sampler, grid) with the true boundary dotted."""
    import pandas as pd

    from sweep.regimes.probability import plot_probability_diagram

    g = run_grid(oracle, 0, st)
    s = run_sampler(oracle, 0, st, summary["seeds"][0]["grid"]["half_max"] or math.inf, g["runs"])
    truth = lambda C: 10.0 ** oracle.line(C)  # noqa: E731
    for name, res in (("sampler_seed0", s), ("grid_seed0", g)):
        df = pd.DataFrame([{"cement": c[0], "Ca_star": c[1], "fracturing": v} for c, _, v in res["labels"]])
        plot_probability_diagram(df, out / name, truth=truth, formats=(),
                                 title=f"oracle seed 0, {name.split('_')[0]}: {res['runs']} runs at "
                                       f"{df.groupby(['cement', 'Ca_star']).ngroups} points")


if __name__ == "__main__":
    raise SystemExit(main())
