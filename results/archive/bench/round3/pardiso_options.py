"""PARDISO options on one Jacobian of the reference case: factorization and substitution times and fill.

    MKL_NUM_THREADS=1 python results/archive/bench/round3/pardiso_options.py H CONFIGS    # e.g. 2 base,vbsr80,twolevel

H: mesh size, mm; CONFIGS: comma-separated names of CONFIGS below.  Each configuration gets its own PARDISO
handle with the solver's settings of round three (solver/linsolve.py before the two-level factorization became
its setting) plus its extra iparm entries (1-based), one analysis, then
three rounds of (numeric factorization, substitution); prints the best of three, the relative residual and the
factors' entries (iparm(18)).  The state is `dchfrac bench`'s (sweep.studies.bench.newton_state).  Units: s.
"""
import os
import sys
import time

os.environ.setdefault("MKL_CBWR", "AUTO,STRICT")

import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402

from solver import linsolve  # noqa: E402
from solver.model import residual_and_jacobian  # noqa: E402
from sweep.studies.bench import newton_state  # noqa: E402

CONFIGS = {"base": {}, "vbsr80": {37: -80}, "vbsr95": {37: -95}, "twolevel": {24: 1}, "twolevel10": {24: 10}}
SOLVER_IPARM = {1: 1, 2: 2, 8: 0, 10: 13, 11: 0, 13: 0}   # solver.linsolve._pardiso_solver's, round three
REPORT_IPARM = {18: -1, 19: -1}                          # report the factors' entries and MFLOPS


def jacobian(h: float):
    """(A, b): the Dirichlet-applied Jacobian (CSR, sorted) and residual of the bench state at mesh size h mm."""
    st = newton_state(h)
    R, J = residual_and_jacobian(st["disc"], st["p"], st["U"], st["data"])
    st["disc"].dirichlet.apply_matrix(J)
    A = sp.csr_matrix(J, dtype=float)
    A.sort_indices()
    return A, np.asfortranarray(R.reshape(-1, 1).astype(float))


def handle(extra: dict):
    """A fresh PARDISO handle with the solver's settings plus ``extra`` (1-based iparm entries)."""
    import pypardiso

    s = pypardiso.PyPardisoSolver()
    for i, v in {**SOLVER_IPARM, **REPORT_IPARM, **extra}.items():
        s.set_iparm(i, v)
    return s


def main(h: float, names: list) -> None:
    linsolve._locate_mkl_rt()
    A, b = jacobian(h)
    # the solver's own PARDISO call, with the 1-based index arrays of this matrix's pattern
    one_based = ((A.indptr + 1).astype(np.int32), (A.indices + 1).astype(np.int32))
    print(f"unknowns {A.shape[0]}, entries {A.nnz}", flush=True)
    handles = {k: handle(CONFIGS[k]) for k in names}
    for s in handles.values():
        linsolve._call(s, A.data, one_based, 11, b)
    times = {k: {"factorize": [], "substitute": []} for k in names}
    residual = {}
    for _ in range(3):
        for k, s in handles.items():
            t = time.perf_counter()
            linsolve._call(s, A.data, one_based, 22, b)
            times[k]["factorize"].append(time.perf_counter() - t)
            s.set_iparm(8, 0)
            t = time.perf_counter()
            x = linsolve._call(s, A.data, one_based, 33, b)
            times[k]["substitute"].append(time.perf_counter() - t)
            residual[k] = np.linalg.norm(A @ x.ravel() - b.ravel()) / np.linalg.norm(b)
    for k, s in handles.items():
        print(f"{k}: factorization {min(times[k]['factorize']):.3f} s, substitution {min(times[k]['substitute']):.4f} s, "
              f"relative residual {residual[k]:.2e}, entries in the factors {s.iparm[17]}")


if __name__ == "__main__":
    main(float(sys.argv[1]), sys.argv[2].split(","))
