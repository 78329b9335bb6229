"""The counts of one reference run (factorizations, Newton and GMRES iterations, calls of each phase) with one
thread: the iteration cost of a solver variant, independent of the machine's load (its seconds are recorded too,
under whatever load: no timing claim).  Prints one JSON line (appended to iteration_counts.jsonl).

    MKL_NUM_THREADS=1 OMP_NUM_THREADS=1 DCHFRAC_ASSEMBLY_THREADS=1 \
        python results/archive/bench/iteration_counts.py H T_END '{"jacobian_reuse": 0.5}' >> results/bench/iteration_counts.jsonl
"""
import json
import sys

from solver import Parameters, RunOptions, linsolve, simulate

h, t_end, extra = float(sys.argv[1]), float(sys.argv[2]), json.loads(sys.argv[3])
res = simulate(Parameters(), RunOptions(**{"h": h, "t_end": t_end, "snapshot_times": [], **extra}))
p = res.profile["total"]
print(json.dumps({"h_mm": h, "t_end_s": t_end, "options": extra, "status": res.status,
                  "accepted_steps": len(res.timeseries), "rejected_steps": len(res.rejected_steps),
                  "factorizations": res.factorizations, "newton_iterations": int(res.timeseries["newton_its"].sum()),
                  "krylov_iterations": linsolve.STATS.get("krylov_iterations", 0), "calls": p["calls"],
                  "seconds": p["seconds"], "wall_s": res.wall_time,
                  "p_inj_end_kPa": float(res.timeseries["p_inj"].iloc[-1]),
                  "p_inj_curve": {"t_s": res.timeseries["t"].tolist(), "p_inj_kPa": res.timeseries["p_inj"].tolist()}}))
