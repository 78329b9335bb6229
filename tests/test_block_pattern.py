"""The block CSR pattern of solver.fem.BlockAssembler, built from the node pattern, against the definition:
the sorted unique (row, column) pairs of every element's dofs, and the slot of each element entry in it."""
import numpy as np
import pytest
import scipy.sparse as sp
from scipy.spatial import Delaunay

from solver import fem
from solver.mesh import annulus_mesh


def _reference(tri, n_nodes, nf):
    """The pattern by its definition: np.unique over every (row, col) of the element dofs."""
    ndof = n_nodes * nf
    edofs = (nf * tri[:, :, None] + np.arange(nf)).reshape(len(tri), 3 * nf)
    key = np.repeat(edofs, 3 * nf, axis=1).ravel().astype(np.int64) * ndof + np.tile(edofs, (1, 3 * nf)).ravel()
    ukey, slot = np.unique(key, return_inverse=True)
    indptr = np.concatenate([[0], np.cumsum(np.bincount(ukey // ndof, minlength=ndof))])
    return indptr, ukey % ndof, slot


def _meshes():
    m = annulus_mesh(5.0, 53.0, h=6.0)
    yield "annulus", np.asarray(m.triangles), m.n_nodes
    rng = np.random.default_rng(4)
    pts = rng.uniform(size=(60, 2))
    t = Delaunay(pts).simplices
    perm = rng.permutation(60)  # node numbers unrelated to the geometry
    yield "random", perm[t], 60


@pytest.mark.parametrize("name, tri, n", list(_meshes()), ids=lambda v: v if isinstance(v, str) else "")
@pytest.mark.parametrize("nf", [1, 2, 5, 7])
def test_block_pattern_matches_its_definition(name, tri, n, nf):
    asm = fem.BlockAssembler(tri, n, nf)
    indptr, indices, slot = _reference(tri, n, nf)
    assert np.array_equal(asm.indptr, indptr) and np.array_equal(asm.indices, indices)
    assert np.array_equal(asm._slot, slot) and asm.nnz == len(indices)
    # the diagonal slots and an assembled matrix against scipy's COO sum of the same element matrices
    A = asm._csr(np.zeros(asm.nnz))
    A.data[asm.diag_slot] = 1.0
    assert np.array_equal(A.diagonal(), np.ones(n * nf))
    rng = np.random.default_rng(1)
    Ke = rng.standard_normal((len(tri), 3 * nf, 3 * nf))
    rows = np.repeat(asm.edofs, 3 * nf, axis=1).ravel()
    cols = np.tile(asm.edofs, (1, 3 * nf)).ravel()
    ref = sp.coo_matrix((Ke.ravel(), (rows, cols)), shape=(n * nf, n * nf)).tocsr()
    assert abs(asm.matrix(Ke) - ref).max() < 1e-12
