"""Generated point-wise kernels (solver.codegen) against the Dual-number reference path.

The generated kernel evaluates the same traced forms in another order (scalar code, element-constant
parts hoisted, element-constant derivatives integrated with the quadrature moments), so agreement is
to round-off: ~1e-13 of the row scale.  The states below are built to visit every branch of the laws:
closed pores (φ <= 0), the Kozeny–Carman cap (φ >= φ*), S outside [0, 1], equal principal strains
(r² below the split's tolerance), tension and compression.
"""
import dataclasses

import numpy as np
import pytest

from solver import Parameters, codegen, fem, kernels, physics
from solver.ad import Dual
from solver.mesh import annulus_mesh
from solver.model import build_discretization, compiled_forms, residual_and_jacobian, step_data
from solver.porosity import random_porosity

pytestmark = pytest.mark.skipif(not kernels.numba_available(), reason="numba not installed")

PARAMETER_SETS = [
    {},  # n_fields 7, Korteweg on, s = 1
    {"korteweg_factor": 0.0},  # n_fields 5
    {"crack_permeability": 0.5, "outer_compliance": 0.1, "volumetric_coupling": 0.0},
    {"crack_permeability": 0.0, "korteweg_factor": 0.0, "volumetric_coupling": 2.0},
]


def _branchy_problem(changes, h=4.0):
    """A state whose sectors are in strong uniform tension (φ above the cap, r² = 0), strong uniform
    compression (φ <= 0), random mixed strains, with S in [-0.3, 1.3] and random damage."""
    p = Parameters(**changes)
    mesh = annulus_mesh(h=h)
    disc = build_discretization(mesh, p, random_porosity(mesh, seed=3))
    rng = np.random.default_rng(7)
    N, nf = disc.n_nodes, disc.n_fields
    x = disc.points
    sector = (np.floor((np.arctan2(x[:, 1], x[:, 0]) + np.pi) / (2 * np.pi) * 6).astype(int)) % 6
    U = np.zeros((N, nf))
    U[:, 0:2] = 0.03 * rng.standard_normal((N, 2))  # mixed principal strains of both signs
    U[sector == 0, 0:2] = 0.6 * x[sector == 0]  # uniform dilation: ε = 0.6 I, φ > φ*, r² = 0
    U[sector == 1, 0:2] = -0.5 * x[sector == 1]  # uniform compression: φ < 0 (closed pores)
    U[sector == 2, 0:2] = 0.002 * x[sector == 2] + 1e-4 * rng.standard_normal((np.sum(sector == 2), 2))
    U[:, 2] = 100 + 20 * rng.standard_normal(N)
    U[:, 3] = rng.uniform(-0.3, 1.3, N)
    U[:, 4] = 0.01 * rng.standard_normal(N)
    U[:, 5:] = 0.1 * rng.standard_normal((N, nf - 5))
    data = step_data(disc, p, 0.9 * U, np.clip(rng.uniform(-0.2, 0.9, N), 0, 1), 1e-3)
    return p, disc, U, data


def _branches_visited(p, disc, U):
    """Which branches of the laws the state reaches at the Strang points."""
    inp = fem.qp_inputs(U[disc.triangles], disc.geom, fem.STRANG3)  # (M, nq, nf, 3)
    exx, eyy = inp[:, :, 0, 1], inp[:, :, 1, 2]
    exy = 0.5 * (inp[:, :, 0, 2] + inp[:, :, 1, 1])
    phi = physics.porosity(disc.phi0[:, None], exx + eyy, inp[:, :, 2, 0], p.K_s)
    r2 = (0.5 * (exx - eyy)) ** 2 + exy**2
    m = 0.5 * (exx + eyy)
    rr = np.sqrt(r2)
    S = inp[:, :, 3, 0]
    star = physics.cap_porosity(p.kbar, p.k_max)
    return {"closed pores": np.any(phi <= 0), "open below cap": np.any((phi > 0) & (phi < star)),
            "above cap": np.any(phi >= star), "S < 0": np.any(S < 0), "S > 1": np.any(S > 1),
            "S inside": np.any((S > 0) & (S < 1)), "r2 = 0": np.any(r2 <= 1e-28), "r2 > 0": np.any(r2 > 1e-28),
            "tension": np.any(m - rr > 0), "compression": np.any(m + rr < 0), "mixed": np.any((m + rr > 0) & (m - rr < 0))}


def _assemble(monkeypatch, backend, p, disc, U, data, threads="1", need_jacobian=True):
    monkeypatch.setenv("DCHFRAC_KERNELS", backend)
    monkeypatch.setenv("DCHFRAC_ASSEMBLY_THREADS", threads)
    return residual_and_jacobian(disc, p, U, data, need_jacobian)


@pytest.mark.parametrize("changes", PARAMETER_SETS)
def test_generated_residual_and_jacobian_match_dual_reference(monkeypatch, changes):
    p, disc, U, data = _branchy_problem(changes)
    visited = _branches_visited(p, disc, U)
    assert all(visited.values()), visited
    R0, J0 = _assemble(monkeypatch, "numpy", p, disc, U, data)
    R1, J1 = _assemble(monkeypatch, "numba", p, disc, U, data)
    R2, _ = _assemble(monkeypatch, "numba", p, disc, U, data, need_jacobian=False)
    assert np.array_equal(J0.indptr, J1.indptr) and np.array_equal(J0.indices, J1.indices)
    # Jacobian: every entry to 1e-13 of the largest entry of its row
    scale = np.abs(J0).max(axis=1).toarray().ravel()
    rows = np.repeat(np.arange(J0.shape[0]), np.diff(J0.indptr))
    assert np.max(np.abs(J1.data - J0.data) / scale[rows]) < 1e-13
    # residual: each equation to 1e-13 of its largest row (the rows of one equation share their scale)
    nf = disc.n_fields
    for f in range(nf):
        ref = R0[f::nf]
        np.testing.assert_allclose(R1[f::nf], ref, rtol=0, atol=1e-13 * np.abs(ref).max(), err_msg=f"field {f}")
    assert np.array_equal(R2, R1)  # residual-only kernel: the same value code


def test_generated_assembly_is_independent_of_threads_and_chunks(monkeypatch):
    p, disc, U, data = _branchy_problem({})
    R0, J0 = _assemble(monkeypatch, "numba", p, dataclasses.replace(disc, chunks=()), U, data)
    small = dataclasses.replace(disc, chunks=fem.element_chunks(len(disc.triangles), 61))
    for threads in ("1", "2", "3"):
        R, J = _assemble(monkeypatch, "numba", p, small, U, data, threads)
        assert np.array_equal(R, R0) and np.array_equal(J.data, J0.data)


def test_one_kernel_per_structure_parameters_are_constants():
    """Parameter values and dt are constants of the kernel, not literals: a new parameter set of the same
    structure reuses the compiled kernel with new constants; a structural change gives another kernel."""
    p1, disc, U, data = _branchy_problem({})
    p2 = Parameters(E=2.5 * p1.E, eta_o=0.3, kbar=0.002, gamma=1.3 * p1.gamma, volumetric_coupling=0.5)
    k1, c1 = compiled_forms(p1, disc.n_fields, data)
    k2, c2 = compiled_forms(p2, disc.n_fields, dataclasses.replace(data, dt=3.7e-3))
    assert k1 is k2 and c1.shape == c2.shape and not np.array_equal(c1, c2)
    assert 3.7e-3 in c2 and data.dt in c1
    for v in (p1.lame_lambda, p1.lame_mu, p1.K_s, physics.cap_porosity(p1.kbar, p1.k_max)):
        assert repr(v) not in k1.source
    assert compiled_forms(p1, disc.n_fields, data)[0] is k1  # traced once per key
    k3, _ = compiled_forms(Parameters(crack_permeability=0.5), disc.n_fields, data)
    assert k3 is not k1 and k3.path != k1.path
    k4, _ = compiled_forms(Parameters(korteweg_factor=0.0), 5, data)
    assert k4 is not k1


def test_kinks_follow_the_dual_conventions(monkeypatch):
    """At exact kinks: max(x, 0)' = 0 at x = 0, clip' = 1 at the bounds, √' = 0 at 0, np.where follows the branch."""
    pts = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    tri = np.array([[0, 1, 2], [1, 3, 2]])
    geom = fem.geometry(pts, tri)

    def forms(X):
        a, b, c = X[0], X[3], X[6]
        pos = np.maximum(a, 0.0) * b
        clipped = np.clip(b, 0.0, 1.0) * c
        root = np.sqrt(a * a) + np.sqrt(np.where(c > 0.5, c, 0.25 + 0.0 * c))
        choice = np.where((a <= 0.0) & ~(b > 1.0), b * c, a * c)
        return [[pos + root, clipped, None], [choice, None, root * b]]

    def dual_forms(X):
        from solver import ad
        a, b, c = X[0], X[3], X[6]
        pos = ad.positive_part(a) * b
        clipped = ad.clip(b, 0.0, 1.0) * c
        root = ad.sqrt(a * a) + ad.sqrt(ad.where(c.v > 0.5, c, 0.25 + 0.0 * c))
        choice = ad.where((a.v <= 0.0) & ~(b.v > 1.0), b * c, a * c)
        return [[pos + root, clipped, None], [choice, None, root * b]]

    kern, C = codegen.forms_kernel(("test kinks",), lambda tr: [(forms(tr.inputs(0, 3)), fem.VERTEX)])
    # vertex points: the point values are the nodal values exactly, so element 0 sits on the kinks
    # (a = 0, b = 0 or 1 = the clip bounds, c = 0.5); element 1 varies inside
    for vals in ([0.0, 1.0, 0.5], [0.0, 0.0, 0.5], [-0.3, -0.2, 0.7], [0.4, 1.5, 0.2]):
        U = np.tile(np.array(vals), (4, 1))
        U[3] += [0.1, -0.05, 0.2]  # element 1 varies inside
        Fe = np.zeros((2, 3, 3))
        Ke = np.zeros((2, 3, 3, 3, 3))
        kern(C, U, tri, geom.grads, geom.areas, {}, Fe, Ke)
        inp = fem.qp_inputs(U[tri], geom, fem.VERTEX).reshape(2, 3, -1)
        X = Dual.variables([inp[:, :, k] for k in range(inp.shape[-1])])
        F0, K0 = fem.assemble_forms(dual_forms(X), geom, fem.VERTEX, True, 3)
        np.testing.assert_allclose(Fe[:, :, :2], F0, rtol=1e-14, atol=1e-15)
        np.testing.assert_allclose(Ke[:, :2], K0, rtol=1e-14, atol=1e-15)


def test_python_branch_on_a_traced_value_is_refused():
    tr = codegen.Tracer()
    x = tr.inputs(0, 1)[0]
    with pytest.raises(TypeError, match="Python branch"):
        bool(x > 0)
    with pytest.raises(TypeError, match="point-wise scalar"):
        x + np.ones(3)
