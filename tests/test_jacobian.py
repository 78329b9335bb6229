"""Newton's Jacobian: Taylor test (second-order remainder) and quadratic convergence."""
import numpy as np
import pytest

from solver import Parameters, RunOptions, kernels
from solver.mesh import annulus_mesh
from solver.model import build_discretization, residual_and_jacobian, step_data
from solver.porosity import random_porosity


def _state(disc, rng):
    N, nf = disc.n_nodes, disc.n_fields
    r = np.hypot(*disc.points.T)
    U = np.zeros((N, nf))
    U[:, 0:2] = 0.02 * rng.standard_normal((N, 2))
    U[:, 2] = 100 * (53 - r) / 48 + rng.standard_normal(N)
    U[:, 3] = np.clip(1.2 - (r - 5) / 20, 0, 1) + 0.05 * rng.standard_normal(N)  # overshoots [0, 1] too
    U[:, 4] = 0.01 * rng.standard_normal(N)
    if nf == 7:
        U[:, 5:] = 0.1 * rng.standard_normal((N, 2))
    return U


@pytest.mark.parametrize("backend", ["numpy", pytest.param("numba", marks=pytest.mark.skipif(
    not kernels.numba_available(), reason="numba not installed"))])
@pytest.mark.parametrize("changes,stab", [({}, None), ({"korteweg_factor": 0.0}, None),
                                          ({"crack_permeability": 0.5, "outer_compliance": 0.1, "volumetric_coupling": 0.0}, None),
                                          ({}, 1.0), ({"transport": "supg"}, None),
                                          ({"cell_compliance": 1e-3, "line_compliance": 3.0}, None),
                                          ({"critical_saturation": 0.2, "transport": "supg"}, None)])
def test_taylor_remainder_is_second_order(changes, stab, backend, monkeypatch):
    """|R(U + εV) − R(U) − ε J V| must fall as ε²: halving the slope test over three decades.

    Run with the numpy element kernels and the compiled ones (solver.kernels), with and without the
    pressure stabilization (``RunOptions.pressure_stabilization``), and with the SUPG transport."""
    monkeypatch.setenv("DCHFRAC_KERNELS", backend)
    changes = dict(changes)  # the parametrized dict is shared by both backends
    transport = changes.pop("transport", "galerkin")
    p = Parameters(**changes)
    mesh = annulus_mesh(h=4.0)
    disc = build_discretization(mesh, p, random_porosity(mesh, seed=3), transport=transport,
                                pressure_stabilization=stab)
    rng = np.random.default_rng(1)
    U = _state(disc, rng)
    d = np.clip(0.5 * rng.random(disc.n_nodes), 0, 1)
    data = step_data(disc, p, 0.9 * U, d, 1e-3)
    R, J = residual_and_jacobian(disc, p, U, data)
    V = rng.standard_normal(U.shape) * np.array([0.01, 0.01, 1, 0.05, 0.01, 0.05, 0.05])[: disc.n_fields]
    eps = np.array([1e-2, 1e-3, 1e-4])
    rem = []
    for e in eps:
        R2, _ = residual_and_jacobian(disc, p, U + e * V, data, need_jacobian=False)
        rem.append(np.linalg.norm(R2 - R - e * (J @ V.ravel())))
    slopes = np.diff(np.log(rem)) / np.diff(np.log(eps))
    assert np.all(slopes > 1.9), (rem, slopes)


def test_newton_converges_quadratically():
    """On the first time step the relative Newton updates must square from one iteration to the next."""
    from solver import simulate as sim_mod
    from solver.simulate import Simulation

    p = Parameters()
    mesh = annulus_mesh(h=4.0)
    sim = Simulation(p, RunOptions(h=4.0), mesh, random_porosity(mesh, seed=0))
    disc = sim.disc
    nf = disc.n_fields
    data = step_data(disc, p, sim.U, sim.d, 1e-3)
    x = sim.U.ravel().copy()
    x[disc.dirichlet.dofs] = disc.dirichlet_values
    norms = []
    from solver import linsolve

    for _ in range(6):
        R, J = residual_and_jacobian(disc, p, x.reshape(-1, nf), data)
        disc.dirichlet.apply_residual(R, x, disc.dirichlet_values)
        disc.dirichlet.apply_matrix(J)
        dx = linsolve.factorize(J, "superlu").solve(-R)
        x += dx
        norms.append(np.linalg.norm(dx) / np.linalg.norm(x))
        if norms[-1] < 1e-13:
            break
    norms = np.array(norms)
    # quadratic: e_{k+1} <= C e_k^2 once in the basin; check the observed order on the last informative steps
    k = np.flatnonzero(norms > 1e-12)
    assert len(k) >= 3, norms
    e = norms[k[-3:]]
    order = np.log(e[2] / e[1]) / np.log(e[1] / e[0])
    assert order > 1.7, norms


def test_chunked_and_threaded_assembly_give_identical_matrices(monkeypatch):
    """Element chunks (and threads over them) only reorder work: R and J must be bitwise the same."""
    import dataclasses

    from solver import fem

    p = Parameters()
    mesh = annulus_mesh(h=4.0)
    disc = build_discretization(mesh, p, random_porosity(mesh, seed=3))
    assert disc.chunks == fem.element_chunks(len(disc.triangles))
    rng = np.random.default_rng(2)
    U = _state(disc, rng)
    data = step_data(disc, p, 0.9 * U, np.clip(0.5 * rng.random(disc.n_nodes), 0, 1), 1e-3)
    whole = dataclasses.replace(disc, chunks=())
    R0, J0 = residual_and_jacobian(whole, p, U, data)
    Rr0, _ = residual_and_jacobian(whole, p, U, data, need_jacobian=False)
    np.testing.assert_allclose(Rr0, R0, rtol=1e-12, atol=1e-12 * np.abs(R0).max())
    small = dataclasses.replace(disc, chunks=fem.element_chunks(len(disc.triangles), 97))
    for threads in ("1", "3"):
        monkeypatch.setenv("DCHFRAC_ASSEMBLY_THREADS", threads)
        R, J = residual_and_jacobian(small, p, U, data)
        assert np.array_equal(R, R0) and np.array_equal(J.indptr, J0.indptr) and np.array_equal(J.data, J0.data)
        Rr, _ = residual_and_jacobian(small, p, U, data, need_jacobian=False)
        assert np.array_equal(Rr, Rr0)


def test_element_chunks_and_thread_setting_are_validated(monkeypatch):
    from solver import fem, paths

    ch = fem.element_chunks(10, 4)
    assert [(c.start, c.stop) for c in ch] == [(0, 4), (4, 8), (8, 10)]
    with pytest.raises(ValueError, match="chunk size"):
        fem.element_chunks(10, 0)
    monkeypatch.setenv("DCHFRAC_ASSEMBLY_THREADS", "two")
    with pytest.raises(ValueError, match="DCHFRAC_ASSEMBLY_THREADS.*'two'"):
        paths.assembly_threads()
    monkeypatch.setenv("DCHFRAC_ASSEMBLY_THREADS", "0")
    with pytest.raises(ValueError, match="positive integer"):
        paths.assembly_threads()
