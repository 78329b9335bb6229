"""The table of a fieldsplit_amg.py JSON: per Jacobian and variant the set-up, GMRES iterations, solve time, the
per-update cost (set-up amortized over the chord iteration) and its ratio to PARDISO's, side by side.

    python results/archive/bench/fieldsplit_table.py results/archive/bench/fieldsplit_amg_h2.json ...
"""
import json
import sys


def fmt(x, spec=".3g"):
    return "-" if x is None else format(x, spec)


for path in sys.argv[1:]:
    d = json.load(open(path))
    y = d["h1_refactorization_start"]["refactorization_s"]
    ye = (d.get("h1_refactorization_end") or {}).get("refactorization_s")
    print(f"\n{path}: yardstick (h = 1 refactorization) {y:.2f} s at the start, {fmt(ye, '.2f')} s at the end; "
          f"load average {d['load_average_start'][0]:.1f}; threads MKL {d['threads']['MKL_NUM_THREADS']}")
    print("| h, mm | t, s | variant | set-up s | set-up / PARDISO's | iterations | solve s (fresh, chord) | "
          "update error | per update s | ratio to PARDISO |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for st in d["studies"]:
        for name, v in st["summary"].items():
            if "error" in v:
                print(f"| {st['h_mm']:g} | {st['t_s']:.3f} | {name} | failed: {v['error'][:60]} |")
                continue
            its = "/".join(str(i) for i in v["iterations"]) + ("" if v["converged"] else " (not converged)")
            err = "/".join(fmt(e, ".1e") for e in v["update_error"])
            print(f"| {st['h_mm']:g} | {st['t_s']:.3f} | {name} | {v['setup_s']:.3g} | {v['setup_ratio_to_pardiso']:.2f} | "
                  f"{its} | {v['solve_first_s']:.3g}, {v['solve_later_s']:.3g} | {err} | {v['per_update_s']:.3g} | "
                  f"{v['per_update_ratio_to_pardiso']:.2f} |")
        parts = st.get("gmres_iteration_parts_s")
        if parts:
            print("|   | parts of one BLT GMRES iteration, s: " + ", ".join(f"{k} {v:.3g}" for k, v in parts.items())
                  + f"; A_uu asymmetry {st['A_uu_asymmetry']:.1e} |")
