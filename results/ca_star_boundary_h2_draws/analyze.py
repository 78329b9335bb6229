"""The judging protocol of campaigns/studies/ca_star_boundary_h2_draws.toml (written in its header before the runs).

1. Label agreement over the porosity draws (column ``seed``) at L_min = 4 mm: the share of points whose draws all
   carry the same label, and the spread of the crack length (max - min over the draws) per point.
2. The separatrix Ca*_c = A exp(B C) (sweep.regimes.separatrix.separatrix_profile_interval) on each seed alone and on the
   draws pooled; the verdict is "B > 0 at 2 sigma" on the pooled fit.
3. The pooled fit at L_min = 2, 3, 4, 5, 6 mm, reported whole (not the verdict).

The protocol's steps are sweep.studies.label_agreement's.  Units: lengths mm, C in %, Ca* dimensionless.

    python results/ca_star_boundary_h2_draws/analyze.py CAMPAIGN_DIR [--out summary.json] [--figure draws.png]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sweep.studies import label_agreement as la
from sweep.campaign.load import load_campaign

L_PROTOCOL = 4.0  # mm, the campaign's [classify] min_crack_length
L_SCAN = (2.0, 3.0, 4.0, 5.0, 6.0)  # mm
COLUMNS = ["seed", "cement", "eta_o", "Ca_star", "crack_length"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("campaign_dir", type=Path)
    ap.add_argument("--out", type=Path)
    ap.add_argument("--figure", type=Path, help="PNG: the labels per draw and the share of draws fracturing")
    a = ap.parse_args(argv)
    df = load_campaign(a.campaign_dir)
    df = df[df["status"] == "ok"][COLUMNS].reset_index(drop=True)
    out = la.judge(df, "seed", L_PROTOCOL, L_SCAN)
    if a.figure:
        la.figure(df, out, "seed", L_PROTOCOL, a.figure, f"Ca*-C labels at L_min = {L_PROTOCOL:g} mm over the "
                  "porosity draws (h = 2 mm); B in 1/%, 95 % intervals")
    la.report(out, a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
