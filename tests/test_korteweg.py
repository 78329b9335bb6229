"""The Korteweg force of the Darcy law, κ∇·(∇S⊗∇S), from the projected gradient G = Π∇S.

P1 saturation has zero second derivatives inside elements, so the model carries G as
nodal unknowns (solver.model docstring).  For a smooth S the discrete force must
converge to the analytic one, and the residual's G rows must vanish exactly at G = Π∇S.
"""
import numpy as np

from solver import Parameters
from solver.mesh import annulus_mesh
from solver.model import GX, GY, S, build_discretization, korteweg_force, project_gradient, residual_and_jacobian, step_data
from solver.porosity import constant_porosity

R0, W = 25.0, 4.0  # a radial interface of width ~ l_S


def _exact_force(x, kappa):
    """κ∇·(∇S⊗∇S) for S = ½(1 + tanh((r − R0)/W)): radial, κ (S'' + S'/r + S'' ... ) S'."""
    r = np.hypot(x[:, 0], x[:, 1])
    t = np.tanh((r - R0) / W)
    s1 = 0.5 * (1 - t**2) / W  # S'
    s2 = -(1 - t**2) * t / W**2  # S''
    # ∇·(∇S⊗∇S) = (ΔS)∇S + (∇∇S)∇S = (S'' + S'/r) S' e_r + S'' S' e_r
    fr = kappa * ((s2 + s1 / r) * s1 + s2 * s1)
    return fr[:, None] * x / r[:, None]


def _error(h):
    p = Parameters()
    mesh = annulus_mesh(h=h)
    disc = build_discretization(mesh, p, constant_porosity(mesh, 0.4))
    r = np.hypot(*disc.points.T)
    U = np.zeros((disc.n_nodes, disc.n_fields))
    U[:, S] = 0.5 * (1 + np.tanh((r - R0) / W))
    U[:, GX:GY + 1] = project_gradient(disc, U[:, S])
    f = korteweg_force(disc, U, p.kappa)
    xc = disc.points[disc.triangles].mean(axis=1)
    fe = _exact_force(xc, p.kappa)
    band = np.abs(np.hypot(*xc.T) - R0) < 3 * W  # the interface region, away from the boundaries
    err = np.sqrt(np.sum(disc.geom.areas[band] * np.sum((f - fe)[band] ** 2, axis=1)))
    ref = np.sqrt(np.sum(disc.geom.areas[band] * np.sum(fe[band] ** 2, axis=1)))
    return err / ref, disc, U, p


def test_korteweg_force_converges_to_the_analytic_force():
    """Relative L2 error in the interface band falls at least linearly with h (P1 gradient of a recovered gradient)."""
    e2, *_ = _error(2.0)
    e1, *_ = _error(1.0)
    assert e1 < 0.15, (e2, e1)  # measured 0.57, 0.24, 0.098 at h = 4, 2, 1 mm (W = 4 mm): ~h/W
    assert np.log(e2 / e1) / np.log(2.0) > 0.9, (e2, e1)


def test_projection_rows_vanish_at_the_projected_gradient():
    """The residual's G rows are exactly the lumped projection: zero residual at G = Π∇S."""
    _, disc, U, p = _error(4.0)
    data = step_data(disc, p, U, np.zeros(disc.n_nodes), 1e-3)
    R, _ = residual_and_jacobian(disc, p, U, data, need_jacobian=False)
    nf = disc.n_fields
    RG = np.concatenate([R[GX::nf], R[GY::nf]])
    scale = np.abs(U[:, GX:GY + 1]).max() * disc.lumped_mass.max()
    assert np.abs(RG).max() < 1e-12 * scale
