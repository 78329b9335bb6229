"""Compiled assembly kernels (solver.kernels): the same residual and Jacobian as the numpy path.

The numpy path is the reference; the compiled path sums in another order, so agreement is to
round-off of the assembled entries (a few ulps of the largest entry), not bitwise.
"""
import numpy as np
import pytest

from solver import Parameters, fem, kernels
from solver.mesh import annulus_mesh
from solver.model import build_discretization, residual_and_jacobian, step_data
from solver.porosity import random_porosity

needs_numba = pytest.mark.skipif(not kernels.numba_available(), reason="numba not installed")


def _problem(changes=None, h=4.0, seed=3):
    p = Parameters(**(changes or {}))
    mesh = annulus_mesh(h=h)
    disc = build_discretization(mesh, p, random_porosity(mesh, seed=seed))
    rng = np.random.default_rng(5)
    N, nf = disc.n_nodes, disc.n_fields
    r = np.hypot(*disc.points.T)
    U = np.zeros((N, nf))
    U[:, 0:2] = 0.02 * rng.standard_normal((N, 2))
    U[:, 2] = 100 * (53 - r) / 48 + rng.standard_normal(N)
    U[:, 3] = np.clip(1.2 - (r - 5) / 20, 0, 1) + 0.05 * rng.standard_normal(N)
    U[:, 4] = 0.01 * rng.standard_normal(N)
    U[:, 5:] = 0.1 * rng.standard_normal((N, nf - 5))
    data = step_data(disc, p, 0.9 * U, np.clip(0.5 * rng.random(N), 0, 1), 1e-3)
    return p, disc, U, data


def _assemble(monkeypatch, backend, p, disc, U, data, threads="1"):
    monkeypatch.setenv("DCHFRAC_KERNELS", backend)
    monkeypatch.setenv("DCHFRAC_ASSEMBLY_THREADS", threads)
    return residual_and_jacobian(disc, p, U, data)


@needs_numba
@pytest.mark.parametrize("changes", [{}, {"korteweg_factor": 0.0},
                                     {"crack_permeability": 0.5, "outer_compliance": 0.1, "volumetric_coupling": 0.0}])
def test_compiled_assembly_matches_numpy(monkeypatch, changes):
    p, disc, U, data = _problem(changes)
    R0, J0 = _assemble(monkeypatch, "numpy", p, disc, U, data)
    R1, J1 = _assemble(monkeypatch, "numba", p, disc, U, data)
    assert np.array_equal(J0.indptr, J1.indptr) and np.array_equal(J0.indices, J1.indices)
    # entries are sums of <= 7 element contributions of <= 3 points: agreement to ~10 ulps of the row scale
    scale = np.maximum(np.abs(J0).max(axis=1).toarray().ravel(), 1e-300)
    rows = np.repeat(np.arange(J0.shape[0]), np.diff(J0.indptr))
    assert np.max(np.abs(J1.data - J0.data) / scale[rows]) < 1e-14
    np.testing.assert_allclose(R1, R0, rtol=0, atol=1e-14 * np.abs(R0).max())


@needs_numba
def test_compiled_assembly_is_independent_of_threads_and_chunks(monkeypatch):
    import dataclasses

    p, disc, U, data = _problem()
    R0, J0 = _assemble(monkeypatch, "numba", p, dataclasses.replace(disc, chunks=()), U, data)
    small = dataclasses.replace(disc, chunks=fem.element_chunks(len(disc.triangles), 97))
    for threads in ("1", "2", "3"):
        R, J = _assemble(monkeypatch, "numba", p, small, U, data, threads)
        assert np.array_equal(R, R0) and np.array_equal(J.data, J0.data)


@needs_numba
def test_slot_sum_equals_bincount_for_any_thread_count():
    rng = np.random.default_rng(0)
    slot = rng.integers(0, 1000, 50_000)
    slot[:1000] = np.arange(1000)  # every slot has an entry, as in a CSR pattern
    values = rng.standard_normal(slot.size)
    ref = np.bincount(slot, weights=values, minlength=1000)
    s = kernels.SlotSum(slot, 1000)
    pool = fem._pool(3)
    for threads in (1, 2, 3):
        out = s(values, threads, pool)
        assert np.array_equal(out, ref)  # same entries summed in the same (element) order


@needs_numba
def test_compiled_qp_inputs_match_numpy():
    p, disc, U, data = _problem()
    U_elem = U[disc.triangles]
    for quad in (fem.STRANG3, fem.VERTEX):
        vals = np.einsum("qa,maf->mqf", quad.bary, U_elem)
        grads = np.einsum("mai,maf->mfi", disc.geom.grads, U_elem)
        out = kernels.qp_inputs(U_elem, quad.bary, disc.geom.grads)
        np.testing.assert_allclose(out[..., 0], vals, rtol=1e-15, atol=1e-15 * np.abs(vals).max())
        np.testing.assert_allclose(out[..., 1:], np.broadcast_to(grads[:, None], out[..., 1:].shape),
                                   rtol=1e-15, atol=1e-15 * np.abs(grads).max())


def test_kernel_backend_setting_is_validated(monkeypatch):
    monkeypatch.setenv("DCHFRAC_KERNELS", "fortran")
    with pytest.raises(ValueError, match="DCHFRAC_KERNELS.*'fortran'"):
        kernels.backend()
    monkeypatch.setenv("DCHFRAC_KERNELS", "numpy")
    assert kernels.backend() == "numpy"
    monkeypatch.setenv("DCHFRAC_KERNELS", "auto")
    assert kernels.backend() == ("numba" if kernels.numba_available() else "numpy")
    if not kernels.numba_available():
        monkeypatch.setenv("DCHFRAC_KERNELS", "numba")
        with pytest.raises(ValueError, match="numba is not installed"):
            kernels.backend()


@pytest.mark.parametrize("n, threads", [(20410, 2), (5101, 2), (80903, 2), (1275, 3), (7, 4)])
def test_thread_chunks_cover_the_elements_in_a_multiple_of_the_threads(n, threads):
    ch = fem.thread_chunks(n, threads)
    assert ch[0].start == 0 and ch[-1].stop == n
    assert all(a.stop == b.start for a, b in zip(ch[:-1], ch[1:]))
    assert len(ch) % threads == 0 or n < threads * 2
    assert max(c.stop - c.start for c in ch) <= max(-(-n // threads), 2 * fem.THREAD_CHUNK_ELEMENTS)


@needs_numba
def test_compiled_contraction_matches_numpy_for_mixed_derivative_layouts(monkeypatch):
    """Contiguous and broadcast derivative arrays (per-point and per-element coefficients) in one form:
    numba types them differently, and the compiled path must still give the numpy element matrices."""
    from solver.ad import Dual

    rng = np.random.default_rng(4)
    _, disc, _, _ = _problem()
    geom, quad, M, nq, nf = disc.geom, fem.STRANG3, len(disc.triangles), 3, 3
    per_point = Dual(rng.standard_normal((M, nq)), rng.standard_normal((M, nq, 3)), (0, 4, 8), 3 * nf)
    per_elem = Dual(rng.standard_normal((M, 1)), rng.standard_normal((M, 1, 2)), (1, 5), 3 * nf)
    const_d = Dual(rng.standard_normal((M, nq)), np.broadcast_to(np.ones((1, 1, 1)), (M, nq, 1)), (6,), 3 * nf)
    F = [[per_point, per_elem, const_d], [None, per_point, per_elem], [per_elem, None, None]]
    out = {}
    for backend in ("numpy", "numba"):
        monkeypatch.setenv("DCHFRAC_KERNELS", backend)
        out[backend] = fem.assemble_forms(F, geom, quad, True, nf)
    for a, b in zip(out["numpy"], out["numba"]):
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-14 * np.abs(a).max())
