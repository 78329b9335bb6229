"""PARDISO factorization and substitution of one saved Jacobian (``capture.py``) in double and in single
precision (iparm(28)), with the solver's settings (solver.linsolve._pardiso_solver): best of 3 factorizations
and 5 substitutions, the relative residual of the single solve, and the largest difference of the two solutions
per field, relative to the field's largest value (s, dimensionless).

    python results/archive/bench/round6/precision.py J.npz b.npy
"""
import sys
import time

import numpy as np
import scipy.sparse as sp

from solver import linsolve


def measure(J, b, precision: str) -> tuple[float, float, np.ndarray]:
    state = linsolve._pardiso_solver(precision)
    s = state["solver"]
    real = np.float32 if precision == "single" else np.float64
    data, rhs = J.data.astype(real), b.astype(real)
    one_based = ((J.indptr + 1).astype(np.int32), (J.indices + 1).astype(np.int32))
    linsolve._call(s, data, one_based, 11, rhs)
    fact, subst = [], []
    for _ in range(3):
        t = time.perf_counter()
        linsolve._call(s, data, one_based, 22, rhs)
        fact.append(time.perf_counter() - t)
    for _ in range(5):
        s.set_iparm(8, 0)
        t = time.perf_counter()
        x = linsolve._call(s, data, one_based, 33, rhs)
        subst.append(time.perf_counter() - t)
    state["pattern"] = None  # this handle's analysis is this script's, not a run's
    return min(fact), min(subst), x.astype(float)


def main(j_path: str, b_path: str, n_fields: int = 5) -> None:
    J = sp.load_npz(j_path).tocsr()
    J.sort_indices()
    b = np.load(b_path)
    out = {p: measure(J, b, p) for p in linsolve.PRECISIONS}
    for p, (f, s, x) in out.items():
        rel = np.linalg.norm(J @ x - b) / np.linalg.norm(b)
        print(f"{p}: factorization {f:.4f} s, substitution {1e3 * s:.2f} ms, relative residual {rel:.2e}")
    xd, xs = out["double"][2], out["single"][2]
    diff = [float(np.abs(xs[f::n_fields] - xd[f::n_fields]).max() / np.abs(xd[f::n_fields]).max()) for f in range(n_fields)]
    print("largest difference per field (ux, uy, p, S, mu), relative:", ", ".join(f"{d:.1e}" for d in diff))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
