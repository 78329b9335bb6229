"""A strongly compacted (or dilated) state of the coupled residual, shared by the floor and ceiling tests: whether
the residual's exact Jacobian stays exact where a bound of a law is active (Taylor remainder of second order)."""
from __future__ import annotations

import numpy as np

from solver import Parameters
from solver.mesh import annulus_mesh
from solver.model import MU, P, S, build_discretization, element_fields, residual_and_jacobian, step_data
from solver.porosity import random_porosity


def taylor_slopes_under_compaction(par: Parameters, field: str, dilation: bool = False):
    """(slopes of the Taylor remainder |R(U + eV) − R(U) − e J V| for e = 1e-2, 1e-3, 1e-4, the element values
    of ``field`` ("phi" or "k") that the paper's law (no floors) gives at the same state).

    The state: h = 4 mm, random displacements, pressures down to −K_s (compaction: the linear porosity falls
    below the floors in many elements; with ``dilation``, up to +2 K_s: it rises above 1), random S and μ;
    units mm, s, kPa."""
    mesh = annulus_mesh(h=4.0)
    disc = build_discretization(mesh, par, random_porosity(mesh, seed=3))
    rng = np.random.default_rng(2)
    N = disc.n_nodes
    U = np.zeros((N, disc.n_fields))
    U[:, :2] = 0.02 * rng.standard_normal((N, 2))
    U[:, P] = (2.0 if dilation else -1.0) * par.K_s * rng.random(N)
    U[:, S] = rng.random(N)
    U[:, MU] = 0.01 * rng.standard_normal(N)
    data = step_data(disc, par, 0.9 * U, np.zeros(N), 1e-3)
    R, J = residual_and_jacobian(disc, par, U, data)
    V = rng.standard_normal(U.shape) * np.array([0.01, 0.01, 1, 0.05, 0.01, 0.05, 0.05])[: disc.n_fields]
    eps = np.array([1e-2, 1e-3, 1e-4])
    rem = [np.linalg.norm(residual_and_jacobian(disc, par, U + e * V, data, need_jacobian=False)[0] - R - e * (J @ V.ravel()))
           for e in eps]
    slopes = np.diff(np.log(rem)) / np.diff(np.log(eps))
    return slopes, element_fields(disc, Parameters(), U, np.zeros(N))[field]
