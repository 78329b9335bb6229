"""Dump real Newton Jacobians and right-hand sides of the reference run (issue #49, the field-split / AMG study).

Runs the reference case (``Parameters()``, ``RunOptions(h, t_end)``) and, at the first factorization at or after
each target time (s), saves the Jacobian J (Dirichlet rows applied, the run's block pattern), the first two
right-hand sides solved with its factors (−R of the Newton iterate the Jacobian was assembled at, then the next
chord iteration's), the last accepted state U (nodes x 7 fields, for the Newton test's field scales), the damage d,
the mesh's nodes (mm), dt and t,
to ``OUT/J_h{H}_t{T}.npz``.  Solver state is untouched: the hook only copies.

    MKL_NUM_THREADS=1 OMP_NUM_THREADS=1 DCHFRAC_ASSEMBLY_THREADS=1 \
        python results/archive/bench/fieldsplit_dump.py H T_END OUT T1 [T2 ...]
"""
import json
import os
import sys

import numpy as np

from solver import Parameters, RunOptions, linsolve, simulate, stagger

h, t_end, out = float(sys.argv[1]), float(sys.argv[2]), sys.argv[3]
targets = sorted(float(t) for t in sys.argv[4:])
os.makedirs(out, exist_ok=True)
current = {}
_step, _factorize = stagger.Simulation.step, linsolve.factorize


def step(self, dt):
    current.update(sim=self, dt=dt)
    return _step(self, dt)


class Recorder:
    """The factors, passing solves through, keeping the first two right-hand sides."""

    def __init__(self, lu, save):
        self.lu, self.save, self.rhs = lu, save, []

    def solve(self, b):
        if len(self.rhs) < 2:
            self.rhs.append(np.array(b, float))
            if len(self.rhs) == 2:
                self.save(self.rhs)
        return self.lu.solve(b)


def factorize(A, *args, **kw):
    lu = _factorize(A, *args, **kw)
    sim = current.get("sim")
    if not targets or sim is None or sim.t < targets[0] - 1e-12:
        return lu
    target = targets.pop(0)
    J, U, d, t, dt = A.tocsr().copy(), sim.U.copy(), sim.d.copy(), sim.t, current["dt"]

    def save(rhs):
        path = os.path.join(out, f"J_h{h:g}_t{target:g}.npz")
        np.savez(path + ".tmp.npz", indptr=J.indptr, indices=J.indices, data=J.data, shape=J.shape,
                 rhs0=rhs[0], rhs1=rhs[1], U=U, d=d, t=t, dt=dt, h=h, points=sim.disc.points)
        os.replace(path + ".tmp.npz", path)
        print(json.dumps({"saved": path, "t": t, "dt": dt, "n": J.shape[0], "nnz": J.nnz}), flush=True)

    return Recorder(lu, save)


stagger.Simulation.step = step
linsolve.factorize = factorize
res = simulate(Parameters(), RunOptions(h=h, t_end=t_end, snapshot_times=[]))
print(json.dumps({"status": res.status, "steps": len(res.timeseries), "wall_s": res.wall_time,
                  "p_inj_end_kPa": float(res.timeseries["p_inj"].iloc[-1])}), flush=True)
