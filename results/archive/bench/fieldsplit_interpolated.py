"""A Jacobian of the reference case at mesh size H assembled at a state interpolated from a coarser run's dump
(issue #49, the field-split / AMG study): a Jacobian with the coarse run's front and crack on the fine mesh,
for a linear-solver study only (the state is not a solution on the fine mesh, and its interfaces are as wide as
the coarse mesh made them).

The state U (7 fields) and the damage d of SRC (a ``fieldsplit_dump.py`` file with ``points`` and ``d``) are
interpolated linearly on the coarse mesh's triangles to the fine mesh's nodes (the nearest coarse node where a fine
node lies outside them, between a chord and the circle), the Dirichlet values imposed; the Jacobian J and −R are
assembled at that state with U_n = the state and SRC's dt (the time terms vanish at the start of a step), then one
chord step x1 = x − θ J⁻¹ R is made (θ halved from 1 until the residual decreases) and −R(x1) is the second
right-hand side.  Written in the format of
``fieldsplit_dump.py``.

    python results/archive/bench/fieldsplit_interpolated.py SRC.npz H OUT.npz
"""
import json
import sys

import matplotlib.tri as mtri
import numpy as np
from scipy.spatial import cKDTree

from solver import Parameters, RunOptions, linsolve
from solver.mesh import GRADING_LENGTH, annulus_mesh
from solver.model import residual_and_jacobian, step_data
from solver.porosity import initial_porosity
from solver.stagger import Simulation


def reference_mesh(p, h):
    o = RunOptions(h=h)
    return annulus_mesh(p.r_inner, p.r_outer, o.h, o.mesh_seed, h_inner=o.h_inner,
                        grading_length=o.inner_grading_length or GRADING_LENGTH, h_outer=o.h_outer), o


def interpolate(src_pts, src_tri, values, pts):
    tri = mtri.Triangulation(src_pts[:, 0], src_pts[:, 1], src_tri)
    finder = tri.get_trifinder()
    inside = finder(pts[:, 0], pts[:, 1]) >= 0
    near = cKDTree(src_pts).query(pts[~inside])[1]
    out = np.empty((len(pts), values.shape[1]))
    for k in range(values.shape[1]):
        out[inside, k] = mtri.LinearTriInterpolator(tri, values[:, k])(pts[inside, 0], pts[inside, 1]).data
        out[~inside, k] = values[near, k]
    return out


src, h, out = np.load(sys.argv[1]), float(sys.argv[2]), sys.argv[3]
p = Parameters()
coarse, _ = reference_mesh(p, float(src["h"]))
assert np.allclose(coarse.points, src["points"])
mesh, o = reference_mesh(p, h)
sim = Simulation(p, o, mesh, initial_porosity(mesh, p))
disc, nf = sim.disc, sim.disc.n_fields
V = interpolate(np.asarray(coarse.points), np.asarray(coarse.triangles),
                np.column_stack([src["U"], src["d"]]), disc.points)
U, d = V[:, :nf], np.clip(V[:, nf], 0.0, 1.0)
x = U.ravel().copy()
x[disc.dirichlet.dofs] = disc.dirichlet_values
U = x.reshape(-1, nf)
dt = float(src["dt"])
data = step_data(disc, p, U, d, dt)


def assemble(xv, jac):
    R, J = residual_and_jacobian(disc, p, xv.reshape(-1, nf), data, need_jacobian=jac)
    disc.dirichlet.apply_residual(R, xv, disc.dirichlet_values)
    if jac:
        disc.dirichlet.apply_matrix(J)
    return R, J


R0, J = assemble(x, True)
J = J.tocsr().copy()
dx = linsolve.factorize(J, "pypardiso", "double").solve(-R0)
theta = 1.0
R1, _ = assemble(x + dx, False)
while not np.linalg.norm(R1) < np.linalg.norm(R0) and theta > 1e-3:  # far from a solution: a damped step
    theta /= 2
    R1, _ = assemble(x + theta * dx, False)
np.savez(out + ".tmp.npz", indptr=J.indptr, indices=J.indices, data=J.data, shape=J.shape, rhs0=-R0, rhs1=-R1,
         U=U, d=d, t=float(src["t"]), dt=dt, h=h, points=disc.points, interpolated_from=float(src["h"]))
import os  # noqa: E402

os.replace(out + ".tmp.npz", out)
print(json.dumps({"saved": out, "from_h": float(src["h"]), "t": float(src["t"]), "n": J.shape[0], "nnz": J.nnz,
                  "theta": theta, "chord_contraction": float(np.linalg.norm(R1) / np.linalg.norm(R0)), "max_d": float(d.max())}))
