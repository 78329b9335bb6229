"""Print the tables of results/archive/bench_rounds.md, third round, from the JSON files beside this script
(each made by ``dchfrac bench --profile --h H --out FILE [--option K=V ...]``).

    python results/archive/bench/round3/tables.py
"""
import json
from pathlib import Path

import numpy as np

HERE = Path(__file__).parent
WINDOWS = ((0.0, 0.05), (0.05, 1.1), (1.1, 1.6), (1.6, 2.0))  # s: start-up, smooth, crack event, end


def load(name):
    j = json.loads((HERE / name).read_text())
    r = j["runs"][0]
    c = r["p_inj_curve"]
    return j, r, np.array(c["t_s"]), np.array(c["p_inj_kPa"])


def phase_seconds(r):
    tot = {}
    for part in r["profile"]["by_part"].values():
        for k, s in part["seconds"].items():
            tot[k] = tot.get(k, 0.0) + s
    return tot


def deviation(t, p, t_ref, p_ref):
    """max |p / p_ref - 1| (%) in each window of WINDOWS."""
    d = 100 * np.abs(p / np.interp(t, t_ref, p_ref) - 1)
    return [float(d[(t > a) & (t <= b)].max()) for a, b in WINDOWS]


def counts_table(names):
    print("| run | wall s | steps (rejected) | Newton its | factorizations | factorization s | solve s | start-up s | p_inj(2 s) kPa | h = 1 refact. s |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for n in names:
        j, r, _, _ = load(n)
        ph = phase_seconds(r)
        print(f"| {n} | {r['wall_s']:.1f} | {r['accepted_steps']} ({r['rejected_steps']}) | {r['newton_iterations']} | "
              f"{r['factorizations']} | {ph['numeric_factorization']:.1f} | {ph['solve']:.1f} | "
              f"{r['profile']['by_part']['startup']['wall_s']:.1f} | {r['p_inj_end_kPa']:.2f} | "
              f"{j['h1_refactorization']['refactorization_s']:.2f} |")


def accuracy_table(names, refs):
    print("| run | " + " | ".join(f"against {ref}: " + ", ".join(f"{a}-{b} s" for a, b in WINDOWS) for ref in refs) + " |")
    print("|---|" + "---|" * len(refs))
    curves = {ref: load(ref)[2:] for ref in refs}
    for n in names:
        _, _, t, p = load(n)
        cells = [", ".join(f"{x:.2f}" for x in deviation(t, p, *curves[ref])) for ref in refs]
        print(f"| {n} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    print("h = 2 mm, two pairs side by side, the campaign paused:\n")
    counts_table(["clean_h2_before.json", "clean_h2_after.json", "clean_h2_after_b.json", "clean_h2_before_b.json"])
    print("\nh = 1 mm, one pair side by side:\n")
    counts_table(["clean_h1_before.json", "clean_h1_after_without_balance_test.json"])
    print("\nh = 1 mm, one run at a time on the idle machine:\n")
    counts_table(["solo_h1_before.json", "solo_h1_after.json", "solo1_h1_before.json",
                  "solo1_h1_after_without_balance_test.json"])
    print("\naccuracy at h = 2 mm: max |p_inj / p_ref - 1| (%) by window, against two fine-step runs:\n")
    acc = ["accuracy_h2_iter.json", "accuracy_h2_iter_aa3.json", "accuracy_h2_c010.json", "accuracy_h2_c010_aa3.json",
           "accuracy_h2_c015_aa3.json", "accuracy_h2_c020_aa3.json"]
    accuracy_table(acc, ["accuracy_h2_c0025_ref.json", "accuracy_h2_iter_dt5ms.json"])
    counts_table(acc + ["accuracy_h2_c0025_ref.json", "accuracy_h2_iter_dt5ms.json"])
