"""Print a before / after table of results/archive/bench_rounds.md from the JSON files ``{before,after}_h{2,1}.json`` of a
folder (each made by ``dchfrac bench --profile --h H --out FILE``; default: this script's folder, the fourth
round), and p_inj(t) of each "after" run against its "before" run and against the committed reference curve.

    python results/archive/bench/round4/tables.py [FOLDER]      # e.g. results/archive/bench/round5
"""
import sys
from pathlib import Path

import numpy as np
import pandas as pd

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE.parent / "round3"))
import tables  # noqa: E402
from tables import WINDOWS, counts_table, deviation, load  # noqa: E402

tables.HERE = Path(sys.argv[1]) if len(sys.argv) > 1 else HERE  # the round-3 readers, on these files


def against(name, ref_t, ref_p, label):
    _, _, t, p = load(name)
    print(f"| {name} against {label} | " + ", ".join(f"{x:.3f}" for x in deviation(t, p, ref_t, ref_p)) + " |")


if __name__ == "__main__":
    print("Reference case to 2 s, one run at a time on the idle machine (the twin campaign paused):\n")
    counts_table(["before_h2.json", "after_h2.json", "before_h1.json", "after_h1.json"])
    print("\nmax |p_inj / p_ref - 1| (%) in the windows " + ", ".join(f"{a}-{b} s" for a, b in WINDOWS) + ":\n")
    print("| run | deviation |\n|---|---|")
    for h in (2, 1):
        _, _, t, p = load(f"before_h{h}.json")
        against(f"after_h{h}.json", t, p, "before")
    ref = pd.read_csv(HERE.parent.parent / "reference" / "timeseries.csv")
    against("after_h1.json", ref["t"].to_numpy(), ref["p_inj"].to_numpy(), "the committed reference")
    against("before_h1.json", ref["t"].to_numpy(), ref["p_inj"].to_numpy(), "the committed reference")
