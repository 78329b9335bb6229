"""Print the tables of results/bench/README.md from profile JSON files made by ``dchfrac bench --profile``: per run,
wall seconds by phase (and % of the run), the counts, and the wall time scaled to the quiet machine's yardstick
(wall × 0.28 s / the h = 1 mm refactorization measured in the same bench run).

    python results/archive/bench/profile_table.py results/bench/profile_sizes.json [more.json ...]
"""
import json
import sys

QUIET_H1_REFACTORIZATION = 0.28  # s, the quiet 2-core machine of bench.json
PHASES = ("setup", "assembly", "symbolic_factorization", "numeric_factorization", "solve", "damage", "stagger",
          "metrics", "output", "python")


def table(path: str) -> None:
    d = json.load(open(path))
    y = d["h1_refactorization"]["refactorization_s"]
    print(f"{path}: h = 1 refactorization {y:.3f} s ({y / QUIET_H1_REFACTORIZATION:.1f}x the quiet 0.28 s); "
          f"load average before {d['machine'].get('load_average_1_5_15')}, "
          f"after {d['machine'].get('load_average_after')}\n")
    runs = d["runs"]
    print("| phase | " + " | ".join(f"h = {r['h_mm']:g}{' ' + str(r['options']) if r['options'] else ''} s (%)"
                                      for r in runs) + " |")
    print("|---|" + "---|" * len(runs))
    for ph in PHASES:
        cells = [f"{r['profile']['total']['seconds'][ph]:.1f} ({100 * r['profile']['total']['fraction'][ph]:.0f})"
                 for r in runs]
        print(f"| {ph.replace('_', ' ')} | " + " | ".join(cells) + " |")
    print("| **total** | " + " | ".join(f"**{r['wall_s']:.1f}**" for r in runs) + " |")
    rows = {"scaled to the quiet yardstick, s": lambda r: f"{r['wall_s'] * QUIET_H1_REFACTORIZATION / y:.1f}",
            "accepted / rejected steps": lambda r: f"{r['accepted_steps']} / {r['rejected_steps']}",
            "Newton iterations": lambda r: str(r["newton_iterations"]),
            "factorizations": lambda r: str(r["factorizations"]),
            "p_inj at t_end, kPa": lambda r: f"{r['p_inj_end_kPa']:.6f}"}
    for name, f in rows.items():
        print(f"| {name} | " + " | ".join(f(r) for r in runs) + " |")
    for c in d.get("comparisons", []):
        print(f"\ncomparison h = {c['h_mm']:g} {c['variant']}: wall ratio {c['wall_ratio']:.3f} "
              f"(base {c['wall_s_base']}, variant {c['wall_s_variant']}), p_inj {c['p_inj_end_kPa']} "
              f"(relative change {c['p_inj_end_rel_change']:.2e}), Newton its {c['newton_iterations']}, "
              f"factorizations {c['factorizations']}")
    print()


if __name__ == "__main__":
    for p in sys.argv[1:]:
        table(p)
