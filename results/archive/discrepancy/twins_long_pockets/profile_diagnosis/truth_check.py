"""Is the truth inside the interval on real runs?  The profile's Δχ² at the hidden strength, on real runs.

The twins' profiles run on the workflow's emulator, and its interval ends are checked with real runs there
(report.md).  This script asks the question the twin's pass rests on directly: it replays a twin of
campaigns/discrepancy/discrepancy_twins_long_pockets.toml from CACHE up to its profile stage (``probe.state_at_profile``)
and evaluates the profile at the hidden (true) strength on real runs, as the workflow's profile evaluates a
point (the others refitted, the discretization correction re-estimated at the point from the fine mesh
realizations, the others refitted again; Δχ² from the fit's own point under the correction re-estimated
there).  The truth lies inside the real-run 95 % interval when that Δχ² is below the threshold.
Units: each strength in its parameter's unit (β kPa·s, compliance mm/kPa); Δχ² dimensionless.

    python truth_check.py CAMPAIGN CACHE OUT.json --twin TWIN --value TRUTH
"""
from __future__ import annotations

import argparse
import json
import logging

from probe import profile_points, state_at_profile
from sweep.campaign.store import write_json_atomic


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("campaign")
    ap.add_argument("cache")
    ap.add_argument("out")
    ap.add_argument("--twin", required=True)
    ap.add_argument("--value", type=float, required=True, help="the hidden strength, in the parameter's unit")
    ap.add_argument("--scratch", default="probe_scratch")
    a = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s", datefmt="%H:%M:%S")
    st = state_at_profile(a.campaign, a.cache, a.scratch, twin=a.twin)
    fit = {k: float(v) for k, v in st["fit"].values().items()}
    real = profile_points(st, [a.value], emulator=False)
    d = real["points"][-1]["delta_chi2"]
    out = {"twin": a.twin, "truth": a.value, "fit": fit, "real": real,
           "truth_inside": bool(d < real["threshold"])}
    write_json_atomic(a.out, out)
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
