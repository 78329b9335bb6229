"""Mesh-seed realizations of the wall-graded runs (Galerkin f_graded, SUPG fc_supg_graded) at h = 2 mm to 2 s.

    python results/archive/fidelity/scheme_convergence/seeds_run.py RUNS_ROOT/fid_seeds_h2
"""
import sys
from pathlib import Path
from solver import Parameters, RunOptions, simulate
from sweep.studies.fidelity import VARIANTS, SNAPSHOT_TIMES
out = Path(sys.argv[1])
for seed in (1, 2, 3):
    for name in ("f_graded", "fc_supg_graded"):
        changes, opts = VARIANTS[name]
        d = out / f"{name}_seed{seed}"
        if (d / "timeseries.csv").exists():
            continue
        simulate(Parameters(**changes), RunOptions(h=2.0, t_end=2.0, snapshot_times=list(SNAPSHOT_TIMES),
                 write_xdmf=False, mesh_seed=seed, **opts), out_dir=d)
        print(name, seed, "done", flush=True)
