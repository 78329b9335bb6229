"""GMRES iterations of the block-lower-triangular AMG field split (``fieldsplit_amg.py``'s blt_amg) against the
forcing η of ‖J x − b‖ ≤ η ‖b‖, on the same Jacobians: what a looser inexact-Newton forcing would save.  Counts
only (no timing claim), with the update's error in the Newton test's measure.  Prints one JSON line per file.

    MKL_NUM_THREADS=1 OMP_NUM_THREADS=1 python results/archive/bench/fieldsplit_forcing.py J_h1_t1.npz ...
"""
import json
import os
import sys


sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import fieldsplit_amg as F  # noqa: E402
from solver import krylov, linsolve  # noqa: E402

for path in sys.argv[1:]:
    J, b0, b1, U, t, dt, h = F.load(path)
    split = F.Split(J)
    dir_u = F.dirichlet_u(J, split)
    B = F.rigid_body_modes(F.mesh_points(h, U.shape[0]), dir_u)
    ref = linsolve.factorize(J, "pypardiso", "double")
    pc = F.FieldSplit(J, split, B, dir_u, "blt", {})
    rows = []
    for eta in (1e-1, 1e-2, 1e-3):
        for k, b in enumerate((b0, b1)):
            x, its = krylov.gmres(lambda v: J @ v, pc, b, eta, F.MAXITER)
            rows.append({"forcing": eta, "rhs": k, "iterations": its,
                         "update_error": None if x is None else F.update_error(x, ref.solve(b), U)})
    print(json.dumps({"file": os.path.basename(path), "h_mm": h, "t_s": t, "blt_amg": rows}), flush=True)
