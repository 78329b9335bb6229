"""Static condensation of the projected gradient on one saved Jacobian of the reference run (eighth round).

    python results/archive/bench/round8/condense_offline.py H T_END K [REPEATS]

runs the reference case (Parameters() defaults) at mesh size H mm to T_END s with the fast path, keeps the K-th
factorized Jacobian and its right-hand side, and factorizes it with SuperLU as the default path does (rows
equilibrated, COLAMD, symmetric mode, pivot threshold 0.1): the full matrix against the Schur complement of the
projected-gradient unknowns (solver.linsolve._Condensation).  Prints the stored entries, the entries of the
factors, the factorization time (best of REPEATS) and the relative residual of both solves on the full system.
The committed figures (results/archive/bench_rounds.md, eighth round) are from K = 80 at H = 2, T_END = 1 (t about 0.6 s)
and K = 100 at H = 1, T_END = 1.
"""
import sys
import time

import numpy as np
import scipy.sparse as sp

from solver import Parameters, RunOptions, linsolve, simulate

h, t_end, k_keep = float(sys.argv[1]), float(sys.argv[2]), int(sys.argv[3])
repeats = int(sys.argv[4]) if len(sys.argv) > 4 else 3
kept = {}
factorize, count = linsolve.factorize, [0]


def keep(A, kind="auto", precision="double", condense=None):
    count[0] += 1
    lu = factorize(A, kind, precision, condense)
    if count[0] == k_keep:
        solve = lu.solve

        def first_solve(b):
            kept.update(A=sp.csr_matrix(A, copy=True), b=np.array(b), g=condense)
            lu.solve = solve
            return solve(b)
        lu.solve = first_solve
    return lu


sys.modules["solver.simulate"].linsolve.factorize = keep
simulate(Parameters(), RunOptions(h=h, t_end=t_end, snapshot_times=[], write_xdmf=False))
A, b, g = kept["A"], kept["b"], kept["g"]


def timed(condense):
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        f = linsolve._SuperLU(A, False, condense)
        best = min(best, time.perf_counter() - t0)
    x = f._substitute(b)
    return best, f.lu.L.nnz + f.lu.U.nnz, np.linalg.norm(A @ x - b) / np.linalg.norm(b), f


t_full, fill_full, res_full, _ = timed(None)
t_cond, fill_cond, res_cond, f = timed(g)
print(f"h = {h} mm, factorization {k_keep}: {A.shape[0]} unknowns, {A.nnz} stored entries "
      f"({np.count_nonzero(A.data)} non-zero); condensed {f.cond.K.shape[0]} unknowns, {f.cond.K.nnz} entries")
print(f"full:      {t_full:.3f} s, {fill_full} entries in the factors, residual {res_full:.1e}")
print(f"condensed: {t_cond:.3f} s, {fill_cond} entries in the factors, residual {res_cond:.1e}")
