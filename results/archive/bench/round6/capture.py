"""Save real Jacobians of the reference run (and the right-hand side of their first solve) for the
single-precision measurement (``precision.py``): every ``EVERY``-th factorization of the run at mesh size H mm
to T_END s goes to ``OUT/J_h{H}_{k}.npz`` and ``OUT/b_h{H}_{k}.npy``.

    python results/archive/bench/round6/capture.py H T_END EVERY OUT      # e.g. 1.0 1.2 50 /tmp/jac
"""
import os
import sys
from pathlib import Path

import numpy as np
import scipy.sparse as sp

os.environ.setdefault("DCHFRAC_ASSEMBLY_THREADS", "2")
import solver.linsolve as linsolve  # noqa: E402
from solver import Parameters, RunOptions, simulate  # noqa: E402


def main(h: float, t_end: float, every: int, out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    factorize, count = linsolve.factorize, [0]

    def capturing(A, kind="auto", precision="double"):
        count[0] += 1
        f = factorize(A, kind, precision)
        if count[0] % every == 0:
            k, solve = count[0], f.solve

            def first_solve(b):
                sp.save_npz(out / f"J_h{h}_{k}.npz", sp.csr_matrix(A))
                np.save(out / f"b_h{h}_{k}.npy", b)
                f.solve = solve
                return solve(b)
            f.solve = first_solve
        return f

    sys.modules["solver.simulate"].linsolve.factorize = capturing
    res = simulate(Parameters(), RunOptions(h=h, t_end=t_end, snapshot_times=[], linear_precision="double"))
    print(res.status, count[0], "factorizations")


if __name__ == "__main__":
    main(float(sys.argv[1]), float(sys.argv[2]), int(sys.argv[3]), Path(sys.argv[4]))
