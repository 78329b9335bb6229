"""Verification of the poroelastic block of the model (solver/model.py): Terzaghi consolidation.

Setting (one fluid, no damage): S = 1 and μ = 0 fixed everywhere (then
k_r1 = 1, k_r2 = 0, the invading-fluid row is replaced and only Darcy +
elasticity act), permeability frozen at k0 = k(φ0) (``crack_permeability=0``)
so the problem is linear, φ0 = 0.4 uniform, no Korteweg terms.
Column 0 <= x <= L, uniaxial strain (u_y = 0 everywhere): at x = 0 a
compressive traction σ_xx = −P0 is applied from t = 0+ and the column is
drained (p = 0); at x = L: u_x = 0 and no flow.

The model's equations in 1D (E' = λ + 2μ, b = 1 − K/K_s, λ_f = k0/η_w):

    momentum   E' ε − b p = −P0                       (total stress uniform)
    mass       φ̇ + c_v φ ε̇ = λ_f p_xx,  φ = φ0 + (1 − φ0)(ε + p/K_s).

NOTE this is not Biot's symmetric system: the storage uses (1 − φ0) where
Biot's would use b.  Eliminating ε = (b p − P0)/E':

  c_v = 0:  (1 − φ0)(b/E' + 1/K_s) ṗ = λ_f p_xx
  c_v = 1:  to first order in the strain (φ ≈ φ0 in the c_v term, error
            O(ε) ~ P0/E' ~ 0.3 % here): (b/E' + (1 − φ0)/K_s) ṗ = λ_f p_xx

so ṗ = c p_xx with c = λ_f / s, s = the storage above.  Undrained response
(no time for flow: the storage variable is still 0):

  c_v = 0:  ε + p/K_s = 0            ->  p0 = P0 / (b + E'/K_s)
  c_v = 1:  ε + (1 − φ0) p/K_s = 0   ->  p0 = P0 / (b + (1 − φ0) E'/K_s)

and backward Euler started from the unloaded state with the load on is exactly
BE on this diffusion equation from the uniform initial value p0.  Series
solution (T = c t / L², x from the drained end, M_n = (2n+1)π/2):

    p = p0 Σ 2/M_n sin(M_n x / L) exp(−M_n² T),
    settlement u_x(0) = ∫ (P0 − b p)/E' dx = (P0 L − b p0 L Σ 2/M_n² e^{−M_n² T}) / E'.

Tolerance 2 % of p0: the error is dominated by backward Euler (first order
in dt, largest at early times when the boundary layer is thin), with 80 P1
elements (h = 0.25 mm) and steps growing from ΔT = 5e-5 by 15 % to 0.01
(132 steps).  Measured pressure errors: 0.9 %, 0.8 %, 0.4 %, 0.3 % of p0 at
T = 0.02, 0.1, 0.3, 1 (both c_v); settlement errors 0.2-0.5 %.  With h = 0.2 mm
and ~4x more steps the pressure errors fall to 0.4 %, 0.1 %, 0.1 %, 0.06 % at
T = 0.05, 0.2, 0.5, 1: the discrete solution converges to the series.
"""
import dataclasses

import numpy as np
import pytest

from solver import Parameters, fem, linsolve
from solver.mesh import Mesh, rectangle_mesh
from solver.model import MU, P, S, UX, UY, build_discretization, residual_and_jacobian, step_data

L, P0, PHI0, NX = 20.0, 1.0, 0.4, 80
TIMES = (0.02, 0.1, 0.3, 1.0)


def _params(cv):
    return Parameters(korteweg_factor=0.0, volumetric_coupling=cv, crack_permeability=0.0)


def theory(par, cv):
    """(p0 kPa, c mm²/s) of the model's 1D consolidation (see module docstring)."""
    Ep, b, Ks = par.lame_lambda + 2 * par.lame_mu, par.biot, par.K_s
    lam_f = PHI0**3 / (1 - PHI0) ** 2 * par.kbar / par.eta_w
    if cv == 0:
        s, p0 = (1 - PHI0) * (b / Ep + 1 / Ks), P0 / (b + Ep / Ks)
    else:
        s, p0 = b / Ep + (1 - PHI0) / Ks, P0 / (b + (1 - PHI0) * Ep / Ks)
    return p0, lam_f / s


def biot_theory(par):
    """Biot's classical (symmetric) consolidation with incompressible fluid, for contrast."""
    Ep, b, Ks = par.lame_lambda + 2 * par.lame_mu, par.biot, par.K_s
    lam_f = PHI0**3 / (1 - PHI0) ** 2 * par.kbar / par.eta_w
    s = b * b / Ep + (b - PHI0) / Ks
    return b / (Ep * s) * P0, lam_f / s


def series(x, T, p0, nterm=400):
    Mn = (2 * np.arange(nterm)[:, None] + 1) * np.pi / 2
    return p0 * np.sum(2 / Mn * np.sin(Mn * x / L) * np.exp(-Mn**2 * T), axis=0)


def settlement(par, T, p0):
    Mn = (2 * np.arange(400) + 1) * np.pi / 2
    Ep = par.lame_lambda + 2 * par.lame_mu
    return (P0 * L - par.biot * p0 * L * np.sum(2 / Mn**2 * np.exp(-Mn**2 * T))) / Ep


def column(par, stab=None):
    """Discretization of the column with our own boundary conditions and load (``stab``: the factor of
    the pressure stabilization, ``RunOptions.pressure_stabilization``)."""
    m = rectangle_mesh(L, L / NX, NX, 1, diagonal="right")
    edges = dict(m.boundary_edges)
    edges["inner"], edges["outer"] = edges["left"], edges["right"]
    mesh = Mesh(m.points, m.triangles, edges)
    disc = build_discretization(mesh, par, np.full(len(mesh.triangles), PHI0), pressure_stabilization=stab)
    nf, N = disc.n_fields, disc.n_nodes
    x = disc.points[:, 0]
    top, bottom, alln = np.flatnonzero(x < 1e-9), np.flatnonzero(x > L - 1e-9), np.arange(N)
    dofs = np.concatenate([nf * alln + UY, nf * alln + S, nf * alln + MU, nf * top + P, nf * bottom + UX])
    vals = np.concatenate([np.zeros(N), np.ones(N), np.zeros(N), np.zeros(len(top)), np.zeros(len(bottom))])
    o = np.argsort(dofs)
    # traction t = −σn = P0 e_x on x = 0 (outward normal −e_x): residual term −∫ t·v ds
    inject = np.zeros(disc.asm.ndof)
    inject[UX::nf] = -P0 * fem.edge_load(disc.points, mesh.boundary_edges["left"], N, 1.0)
    return dataclasses.replace(
        disc, dirichlet=disc.asm.dirichlet_rows(dofs[o]), dirichlet_values=vals[o], inject=inject,
        boundary_op=disc.boundary_op * 0.0, boundary_vals=np.zeros_like(disc.boundary_vals))


def consolidate(cv, stab=None):
    par = _params(cv)
    disc = column(par, stab)
    nf, N = disc.n_fields, disc.n_nodes
    p0, c = theory(par, cv)
    tc = L * L / c
    U = np.zeros((N, nf))
    U[:, S] = 1.0
    d = np.zeros(N)
    t, dT, out, todo = 0.0, 5e-5, {}, list(TIMES)
    while todo:
        dt = min(dT * tc, todo[0] * tc - t)
        data = step_data(disc, par, U, d, dt)
        X = U.ravel().copy()
        X[disc.dirichlet.dofs] = disc.dirichlet_values
        for _ in range(10):
            R, J = residual_and_jacobian(disc, par, X.reshape(N, nf), data)
            disc.dirichlet.apply_residual(R, X, disc.dirichlet_values)
            disc.dirichlet.apply_matrix(J)
            dx = linsolve.factorize(J, "superlu").solve(-R)
            X += dx
            if np.abs(dx[P::nf]).max() < 1e-10 * p0 and np.abs(dx[UX::nf]).max() < 1e-12 * L:
                break
        else:
            raise AssertionError("Newton did not converge")
        U = X.reshape(N, nf).copy()
        t += dt
        if abs(t - todo[0] * tc) < 1e-12 * tc:
            out[todo.pop(0)] = U.copy()
        dT = min(1.15 * dT, 0.01)
    return par, disc, out


@pytest.fixture(scope="module", params=[(0.0, None), (1.0, None), (0.0, 1.0)], ids=["cv0", "cv1", "cv0-stabilized"])
def run(request):
    """The consolidation with c_v = 0 and 1, and with the pressure stabilization: a consistent O(h²) ṗ
    perturbation, so it meets the same series to the same tolerance."""
    cv, stab = request.param
    return (cv, *consolidate(cv, stab))


def test_pressure_matches_series_solution(run):
    cv, par, disc, out = run
    p0, _ = theory(par, cv)
    x = disc.points[:, 0]
    for T, U in out.items():
        err = np.abs(U[:, P] - series(x, T, p0)).max() / p0
        assert err < 0.02, (cv, T, err)


def test_settlement_matches_series_solution(run):
    cv, par, disc, out = run
    p0, _ = theory(par, cv)
    x = disc.points[:, 0]
    for T, U in out.items():
        u_top = U[x < 1e-9, UX].mean()
        assert u_top == pytest.approx(settlement(par, T, p0), rel=0.02), (cv, T)
    # uniaxial strain really held: displacement uniform across the column
    for U in out.values():
        assert np.abs(U[:, UY]).max() == 0.0


def test_wrong_storage_coefficients_are_detected(run):
    """The tolerance discriminates between storage laws: the series of the other c_v variant and,
    for c_v = 0, Biot's classical symmetric storage b ε̇ + ((b − φ0)/K_s) ṗ (the model uses
    (1 − φ0)(ε̇ + ṗ/K_s)) miss the computed pressure by more than 5 % of p0 at every checked time
    (measured: 8-24 % and 11-19 %), so a silent switch of storage law would fail the tests above."""
    cv, par, disc, out = run
    p0, c = theory(par, cv)
    po, co = theory(par, 1.0 - cv)
    pb, cb = biot_theory(par)
    x = disc.points[:, 0]
    for T, U in out.items():
        err_other = np.abs(U[:, P] - series(x, T * co / c, po)).max() / p0  # same physical time
        assert err_other > 0.05, (cv, T, err_other)
        if cv == 0.0:
            err_biot = np.abs(U[:, P] - series(x, T * cb / c, pb)).max() / p0
            assert err_biot > 0.05, (T, err_biot)
