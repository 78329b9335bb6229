"""The pressure stabilization of the equal-order (u, p) pair (``RunOptions.pressure_stabilization``) and the
physical-limit diagnosis of failed runs (``solver.simulate.physical_limit``).

1. Undrained limit, Terzaghi's column (the set-up of test_poroelasticity.py): on the first step with
   c Δt / h² = 1e-4 the exact pressure is monotone, 0 <= p <= p0 (p0 the undrained pressure).  The plain
   P1 / P1 form oscillates from node to node with peaks far above p0 (Murad and Loula 1994); with the
   perturbation τ ∫ ∇q·∇(p − p_n)/Δt of Rodrigo et al. (2016) the 1D scheme is monotone.  The column's one
   row of right triangles is not exactly 1D: the tolerance 0.5 % of p0 covers its cross-diagonal coupling.
2. The term is the written form: the residual change is τ_e ∫ ∇q·∇(p − p_n)/Δt on the total mass rows and
   the same times the water fractional flow λ1/(λ1 + λ2) on the invading-fluid rows (1 in water, 0 in oil).
3. Start-up at the low-permeability edge of the paper's grid (k̄ = 1e-4 mm², η_w = 1e-3 kPa·s): the first
   step keeps p >= 0 (injection into a layer drained at p = 0) and the volume balance.
4. A failed step at a node touching an element whose pores are closed (porosity <= 0) or whose skeleton is
   gone (porosity >= 1) is reported as that physical limit, and only then.
"""
import dataclasses

import numpy as np
import pytest
from test_poroelasticity import L, NX, _params, column, theory

from solver import Parameters, RunOptions, linsolve, simulate
from solver.mesh import annulus_mesh
from solver.model import MU, P, S, build_discretization, residual_and_jacobian, step_data
from solver.porosity import random_porosity
from solver.simulate import Simulation, physical_limit


def _first_step(stab, ratio=1e-4):
    """Terzaghi's column after one backward-Euler step of c Δt / h² = ``ratio``: (x, p/p0) sorted by x."""
    par = _params(0.0)
    disc = column(par, stab)
    p0, c = theory(par, 0.0)
    h = L / NX
    nf, N = disc.n_fields, disc.n_nodes
    U = np.zeros((N, nf))
    U[:, S] = 1.0
    data = step_data(disc, par, U, np.zeros(N), ratio * h * h / c)
    X = U.ravel().copy()
    X[disc.dirichlet.dofs] = disc.dirichlet_values
    for _ in range(10):  # a linear problem: Newton converges in one step, the second checks it
        R, J = residual_and_jacobian(disc, par, X.reshape(N, nf), data)
        disc.dirichlet.apply_residual(R, X, disc.dirichlet_values)
        disc.dirichlet.apply_matrix(J)
        dx = linsolve.factorize(J, "superlu").solve(-R)
        X += dx
        if np.abs(dx).max() < 1e-12 * p0:
            break
    x = disc.points[:, 0]
    o = np.argsort(x)
    return x[o], X.reshape(N, nf)[o, P] / p0


def test_undrained_first_step_oscillates_without_and_is_monotone_with_stabilization():
    _, plain = _first_step(None)
    assert plain.max() > 1.5, plain.max()  # the plain form's spurious peak (measured 2.1 p0)
    _, stab = _first_step(1.0)
    assert stab.min() >= 0.0 and stab.max() <= 1.005, (stab.min(), stab.max())


def _state(disc, rng, S_value):
    N = disc.n_nodes
    U = np.zeros((N, disc.n_fields))
    U[:, P] = 200.0 * rng.random(N)
    U[:, :2] = 0.01 * rng.standard_normal((N, 2))
    U[:, S] = S_value
    U[:, MU] = 0.01 * rng.standard_normal(N)
    return U


@pytest.mark.parametrize("S_value,water_share", [(1.0, 1.0), (0.0, 0.0)])
def test_stabilization_residual_is_the_weighted_pressure_laplacian(S_value, water_share):
    par = Parameters(korteweg_factor=0.0)
    mesh = annulus_mesh(h=4.0)
    phi0 = random_porosity(mesh, seed=2)
    plain = build_discretization(mesh, par, phi0)
    stab = build_discretization(mesh, par, phi0, pressure_stabilization=1.0)
    rng = np.random.default_rng(4)
    U, U_n, dt = _state(plain, rng, S_value), _state(plain, rng, S_value), 2e-3
    d = np.zeros(plain.n_nodes)
    R0, _ = residual_and_jacobian(plain, par, U, step_data(plain, par, U_n, d, dt), need_jacobian=False)
    R1, _ = residual_and_jacobian(stab, par, U, step_data(stab, par, U_n, d, dt), need_jacobian=False)
    # independent assembly: Σ_e τ_e A_e ∇N_a·∇(p − p_n) / Δt
    tri, G, A = plain.triangles, plain.geom.grads, plain.geom.areas
    gp = np.einsum("mai,ma->mi", G, (U[:, P] - U_n[:, P])[tri])
    tau = 1.0 * par.biot * (1 - phi0) * np.max([np.sum((plain.points[tri[:, a]] - plain.points[tri[:, (a + 1) % 3]]) ** 2,
                                                        axis=1) for a in range(3)], axis=0) / (4 * (par.lame_lambda + 2 * par.lame_mu))
    local = (tau * A)[:, None] * np.einsum("mai,mi->ma", G, gp) / dt
    expect = np.bincount(tri.ravel(), weights=local.ravel(), minlength=plain.n_nodes)
    nf = plain.n_fields
    scale = np.abs(expect).max()
    assert np.allclose(R1[P::nf] - R0[P::nf], expect, rtol=0, atol=1e-10 * scale)
    assert np.allclose(R1[S::nf] - R0[S::nf], water_share * expect, rtol=0, atol=1e-10 * scale)
    for f in range(nf):
        if f not in (P, S):
            assert np.array_equal(R1[f::nf], R0[f::nf])


def test_low_permeability_start_up_keeps_pressure_nonnegative_and_volume_balanced():
    par = Parameters(eta_o=0.01, eta_w=1e-3, kbar=1e-4, cement=1.2)
    res = simulate(par, RunOptions(h=4.0, t_end=1e-3, dt0=1e-3, snapshot_times=(), write_xdmf=False,
                                   pressure_stabilization=1.0))
    assert res.status == "ok", res.reason
    p = res.snapshots[-1][1]["p"]
    assert p.min() >= -1e-9 * p.max(), (p.min(), p.max())
    assert res.timeseries.mass_error.iloc[-1] < 1e-9


def test_option_is_validated_and_left_out_of_old_option_dicts(tmp_path):
    with pytest.raises(ValueError, match=r"pressure_stabilization=-1\.0.*>= 0"):
        RunOptions(pressure_stabilization=-1.0)
    assert "pressure_stabilization" not in RunOptions().to_dict()
    o = RunOptions(pressure_stabilization=np.float64(1.0))
    o.to_toml(tmp_path / "o.toml")
    assert RunOptions.from_toml(tmp_path / "o.toml") == o and o.pressure_stabilization == 1.0


def _sim():
    par = Parameters()
    mesh = annulus_mesh(h=4.0)
    return Simulation(par, RunOptions(h=4.0), mesh, random_porosity(mesh, seed=1))


def test_physical_limit_names_closed_pores_and_dissolved_skeleton_only_there():
    sim = _sim()
    r = np.hypot(*sim.disc.points.T)
    node = int(np.argmin(np.abs(r - 30.0)))
    assert physical_limit(sim, node) is None  # the initial state is inside the porosity law's range
    assert physical_limit(sim, None) is None
    K_s = sim.params.K_s
    # φ = φ0 + (1 − φ0) p/K_s with ε_v = 0: p = −K_s closes every pore, p = +2 K_s/(1 − φ0_min) opens them all
    sim.U[:, P] = -K_s
    assert "pores closed at r = 30" in physical_limit(sim, node)
    # one closed element around the node is enough: its flux and its share of the node's capacity are gone
    sim.U[:, P] = 0.0
    first = np.flatnonzero(np.any(sim.disc.triangles == node, axis=1))[0]
    sim.U[sim.disc.triangles[first], P] = -2.0 * K_s
    assert "pores closed at r = 30" in physical_limit(sim, node)
    far = int(np.argmin(np.abs(r - 15.0)))
    assert physical_limit(sim, far) is None  # the closed element is not around this node
    sim.U[:, P] = 2.0 * K_s / (1.0 - sim.disc.phi0.max())
    assert "skeleton dissolved" in physical_limit(sim, node)


def test_failed_run_at_closed_pores_reports_the_limit_in_its_reason(monkeypatch):
    """A run whose step fails at a node with closed pores ends "failed" with the limit in its reason."""
    import importlib

    sm = importlib.import_module("solver.simulate")  # the module (``solver.simulate`` the package exports is the function)

    def fail_at_wall(self, dt):
        self.U[:, P] = -2.0 * self.params.K_s  # pores closed everywhere
        r = np.hypot(*self.disc.points.T)
        raise sm.StepFailure("Newton diverged (test)", node=int(np.argmax(r)))

    monkeypatch.setattr(sm.Simulation, "step", fail_at_wall)
    res = simulate(Parameters(), RunOptions(h=8.0, t_end=0.01, dt0=1e-3, dt_min=1e-4, snapshot_times=(),
                                            write_xdmf=False))
    assert res.status == "failed"
    assert "physical limit: pores closed at r = 53.00 mm" in res.reason
