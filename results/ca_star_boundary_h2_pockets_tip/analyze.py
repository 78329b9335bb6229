"""The judging protocol of campaigns/studies/ca_star_boundary_h2_pockets_tip.toml (written in its header before the runs).

1. The separatrix Ca*_c = A exp(B C) on all the sampler's runs at L_min = 6 mm; the verdict is "B > 0 at 2 sigma".
2. The fit over L_min = 4-10 mm, reported whole, for the judged crack and for the longest crack up to the judged
   time (crack_record = "longest"), with the crack lengths as a continuous quantity.
3. The judged and the longest crack's rank correlations with C and Ca*.

Units: lengths mm, C in %, Ca* dimensionless.

    python results/ca_star_boundary_h2_pockets_tip/analyze.py CAMPAIGN_DIR [--out summary.json]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sweep.studies import label_agreement as la
from sweep.campaign.load import load_campaign

L_PROTOCOL = 6.0  # mm, the campaign's [classify] min_crack_length
L_SCAN = (4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0)  # mm


def judge(df) -> dict:
    """The three parts of the protocol on the ok runs ``df``."""
    out = {"runs": int(len(df)), "at_L6": la.separatrix(df, L_PROTOCOL)}
    for name, d in (("judged", df), ("longest", la.longest(df))):
        out[name] = {"L_scan": {str(l): la.separatrix(d, l) for l in L_SCAN},
                     "crack_length_mm": la.crack_summary(d), "spearman": la.rank_correlations(d)}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("campaign_dir", type=Path)
    ap.add_argument("--out", type=Path)
    a = ap.parse_args(argv)
    df = load_campaign(a.campaign_dir)
    la.report(judge(df[df["status"] == "ok"].reset_index(drop=True)), a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
