"""The h = 2 Ca*-C runs over three porosity draws (results/ca_star_boundary_h2_draws/, 138 runs) read as label
probabilities (issue #51): per-point P(fracturing) with Wilson intervals, the separatrix's simultaneous band and its
significance, and the probability diagram.  No run.  Units: C %, Ca* -, widths in decades of Ca*.

    python -m sweep.studies.draw_probabilities results/ca_star_boundary_h2_draws --out results/uncertain_diagrams/draws_h2
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pandas as pd

from sweep.campaign.replicates import point_table
from sweep.campaign.store import write_json_atomic
from sweep.regimes.probability import plot_probability_diagram, separatrix_band


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sweep.studies.draw_probabilities", description=__doc__.split("\n\n")[0])
    ap.add_argument("campaign", type=Path)
    ap.add_argument("--out", type=Path, required=True)
    a = ap.parse_args(argv)
    summary = summarize(a.campaign, a.out)
    print(json.dumps(summary, indent=1))
    return 0


def summarize(campaign: Path, out: Path) -> dict:
    """Write ``summary.json``, ``points.csv`` and the probability figure of a replicated campaign's table into
    ``out``; return the summary."""
    a = argparse.Namespace(campaign=Path(campaign), out=Path(out))
    t = pd.read_csv(a.campaign / "table.csv")
    t = t[t["status"] == "ok"]
    pts = point_table(t, ["cement", "eta_o"])
    band = separatrix_band(t["cement"], t["Ca_star"], t["fracturing"].astype(bool), at=[0.5, 3.0])
    a.out.mkdir(parents=True, exist_ok=True)
    fig = plot_probability_diagram(t, a.out / "figures" / "probabilities", formats=(),
                                   title="h = 2: 46 points x 3 porosity draws (ca_star_boundary_h2_draws)")
    p = pts["p_fracturing"].to_numpy()
    summary = {
        "runs": int(len(t)), "points": int(len(pts)),
        "points_draws_agree": int(np.sum((p == 0) | (p == 1))),
        "points_p_fracturing": {str(k): int(v) for k, v in pd.Series(np.round(p * 3).astype(int)).value_counts().sort_index().items()},
        "separatrix": {"A": band.A, "B_per_percent": band.B, "lr": band.lr, "p_value": band.p_value,
                       "significant_at_0.05": band.significant,
                       "band95_simultaneous_half_width_decades": {"C=0.5": float(band.half_width_decades[0]),
                                                                  "C=3": float(band.half_width_decades[1])}},
        "drawn": fig["band"] is not None,
    }
    write_json_atomic(a.out / "summary.json", summary)
    pts.to_csv(a.out / "points.csv", index=False)
    return summary


if __name__ == "__main__":
    raise SystemExit(main())
