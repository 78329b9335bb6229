"""P1 finite-element kit on triangles, vectorized over elements.

Everything here works on plain arrays (``points`` (N, 2) in mm, ``triangles``
(M, 3) int) so it serves any triangulation, not only the annulus.

Layout of several fields: node-major, global dof = ``n_fields * node + field``.

Quadrature.  Linear forms of P1 functions need no quadrature (closed forms
below).  Nonlinear coefficients (permeability, relative permeabilities,
degradation, spectral split...) are evaluated at the 3-point interior Strang
rule (barycentric (2/3, 1/6, 1/6) and permutations), exact for polynomials of
degree 2: it integrates the P1 x P1 mass products exactly, samples the
coefficients away from element edges (where several of them are not smooth),
and costs three evaluations per element.  ``VERTEX`` is the nodal (lumped)
rule used where a diagonal mass is wanted (projection of the saturation
gradient, reaction terms of the damage equation).

Sparse assembly: :class:`BlockAssembler` computes the CSR sparsity pattern of
a block system once per mesh and maps every element-matrix entry to its slot
in the CSR data array; afterwards assembling a new Jacobian is one
``np.bincount`` over the element entries, with no index sorting.
"""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import scipy.sparse as sp

from . import kernels
from .ad import Dual
from .paths import assembly_threads


# --------------------------------------------------------------------------
# geometry
# --------------------------------------------------------------------------
@dataclass(frozen=True)
class Geometry:
    """Element geometry: ``areas`` (M,) mm², ``grads`` (M, 3, 2) 1/mm (∇N_a)."""

    areas: np.ndarray
    grads: np.ndarray


def geometry(points: np.ndarray, triangles: np.ndarray) -> Geometry:
    """Areas and constant shape-function gradients of P1 triangles (mm)."""
    x = points[triangles]  # (M, 3, 2)
    e1 = x[:, 1] - x[:, 0]
    e2 = x[:, 2] - x[:, 0]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    if np.any(det <= 0):
        raise ValueError("triangles must be counter-clockwise with positive area")
    # gradients of barycentric coordinates: ∇N_a = rot90(opposite edge) / det
    grads = np.empty((len(triangles), 3, 2))
    for a in range(3):  # loop over the 3 local nodes, vectorized over elements
        b, c = (a + 1) % 3, (a + 2) % 3
        edge = x[:, c] - x[:, b]
        grads[:, a, 0] = -edge[:, 1] / det
        grads[:, a, 1] = edge[:, 0] / det
    return Geometry(areas=0.5 * det, grads=grads)


@dataclass(frozen=True)
class Quadrature:
    """Rule on the reference triangle: barycentric points (nq, 3), weights (nq,) summing to 1."""

    bary: np.ndarray
    weights: np.ndarray


STRANG3 = Quadrature(
    bary=np.array([[2 / 3, 1 / 6, 1 / 6], [1 / 6, 2 / 3, 1 / 6], [1 / 6, 1 / 6, 2 / 3]]),
    weights=np.full(3, 1 / 3),
)
VERTEX = Quadrature(bary=np.eye(3), weights=np.full(3, 1 / 3))


def at_quadrature(nodal: np.ndarray, triangles: np.ndarray, quad: Quadrature) -> np.ndarray:
    """Interpolate nodal values (N,) or (N, k) to quadrature points -> (M, nq) or (M, nq, k)."""
    x = nodal[triangles]
    if x.ndim == 2:
        return x @ quad.bary.T
    if x.ndim == 3:
        return np.matmul(quad.bary, x)  # batched (nq, 3) @ (3, k): numpy's einsum is ~10x slower here
    return np.einsum("qa,ma...->mq...", quad.bary, x)


def element_gradient(nodal: np.ndarray, triangles: np.ndarray, geom: Geometry) -> np.ndarray:
    """Constant gradient per element of a nodal P1 field (N,) -> (M, 2)."""
    return np.matmul(nodal[triangles][:, None, :], geom.grads)[:, 0]


def field_gradients(grads: np.ndarray, U_elem: np.ndarray, *, in_order: bool = False) -> np.ndarray:
    """Constant gradients (M, nf, 2) of the P1 fields with element nodal values ``U_elem`` (M, 3, nf), from the
    shape-function gradients ``grads`` (M, 3, 2): Σ_a U_af ∂N_a/∂x_i.  One batched product (numpy's einsum
    "mai,maf->mfi" takes ~10x longer); ``in_order``: summed over a = 0, 1, 2 in that order, as the generated
    kernels do, so that the numpy reference kernels equal them bitwise (~3x slower than the product)."""
    if not in_order:
        return np.matmul(U_elem.transpose(0, 2, 1), grads)
    out = U_elem[:, 0, :, None] * grads[:, 0, None, :]
    out += U_elem[:, 1, :, None] * grads[:, 1, None, :]
    out += U_elem[:, 2, :, None] * grads[:, 2, None, :]
    return out


def _values_in_order(bary: np.ndarray, U_elem: np.ndarray) -> np.ndarray:
    """Values (M, nq, nf) of the P1 fields at the points of ``bary`` (nq, 3), Σ_a N_a(q) U_af summed over
    a = 0, 1, 2 in that order (as the generated kernels)."""
    out = bary[None, :, 0, None] * U_elem[:, None, 0, :]
    out += bary[None, :, 1, None] * U_elem[:, None, 1, :]
    out += bary[None, :, 2, None] * U_elem[:, None, 2, :]
    return out


def nodal_average(elem_values: np.ndarray, triangles: np.ndarray, areas: np.ndarray, n_nodes: int) -> np.ndarray:
    """Area-weighted (lumped L2) projection of element values (M,) to nodes (N,)."""
    w = np.repeat(areas / 3.0, 3)
    num = np.bincount(triangles.ravel(), weights=np.repeat(elem_values, 3) * w, minlength=n_nodes)
    den = np.bincount(triangles.ravel(), weights=w, minlength=n_nodes)
    return num / den


# --------------------------------------------------------------------------
# sparse assembly
# --------------------------------------------------------------------------
def node_pattern(triangles: np.ndarray, n_nodes: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Node-to-node CSR pattern of P1 triangles: ``indptr`` (N + 1,), ``indices`` (columns sorted in each
    row) and ``slot`` (M, 3 a, 3 b), the CSR position of the pair (node a, node b) of each element."""
    t = np.asarray(triangles, dtype=np.int64)
    key = (t[:, :, None] * n_nodes + t[:, None, :]).ravel()
    ukey, slot = np.unique(key, return_inverse=True)
    indptr = np.concatenate([[0], np.cumsum(np.bincount(ukey // n_nodes, minlength=n_nodes))])
    return indptr, ukey % n_nodes, slot.reshape(len(t), 3, 3)


class BlockAssembler:
    """CSR assembly of ``n_fields`` P1 fields with a pattern computed once.

    ``matrix(Ke)`` takes element matrices (M, 3 nf, 3 nf) with local index
    ``a * nf + f`` (node a, field f) and returns a CSR matrix sharing the
    stored pattern; ``vector(Fe)`` takes (M, 3 nf).
    """

    def __init__(self, triangles: np.ndarray, n_nodes: int, n_fields: int):
        self.n_nodes = int(n_nodes)
        self.n_fields = int(n_fields)
        self.ndof = self.n_nodes * self.n_fields
        nf = self.n_fields
        triangles = np.asarray(triangles, dtype=np.int64)
        self.edofs = (nf * triangles[:, :, None] + np.arange(nf)[None, None, :]).reshape(len(triangles), 3 * nf)
        # the block pattern is the node pattern with a full nf x nf block per node pair: row nf n + f holds
        # columns nf m + g for the neighbours m of n (sorted) and every g, and starts at
        # nf² indptr_n[n] + f nf deg(n); so every slot follows from the node pattern without sorting
        n_indptr, n_indices, n_slot = node_pattern(triangles, self.n_nodes)
        deg = np.diff(n_indptr)
        f = np.arange(nf)
        row_start = nf * nf * n_indptr[:-1, None] + nf * f[None, :] * deg[:, None]  # (N, nf)
        self.nnz = int(nf * nf * n_indptr[-1])
        self.indptr = np.append(row_start.ravel(), self.nnz).astype(np.int32)
        # block position of (node slot k, f, g): row_start[n, f] + nf (k - indptr_n[n]) + g
        k_row = np.repeat(np.arange(self.n_nodes), deg)
        k_off = nf * (np.arange(len(n_indices)) - n_indptr[k_row])
        pos = row_start[k_row][:, :, None] + k_off[:, None, None] + f[None, None, :]  # (nnz_n, nf f, nf g)
        cols = nf * n_indices[:, None, None] + f[None, None, :]
        self.indices = np.empty(self.nnz, dtype=np.int32)
        self.indices[pos.ravel()] = np.broadcast_to(cols, pos.shape).ravel()
        # element slot map (M, 3 a, nf f, 3 b, nf g) in the local order a nf + f, b nf + g
        na = triangles[:, :, None]  # (M, 3 a, 1)
        base = nf * nf * n_indptr[na] + nf * (n_slot - n_indptr[na])  # (M, 3 a, 3 b)
        frow = nf * f[None, None, :] * deg[triangles][:, :, None]  # (M, 3 a, nf f)
        self._slot = (base[:, :, None, :, None] + frow[:, :, :, None, None] + f[None, None, None, None, :]).ravel()
        self._slot_fm = None  # the same map for field-major element matrices, made on first use
        self._slot_sum = None  # its inverse, for the compiled gather (solver.kernels.SlotSum)
        self._ukey = np.repeat(np.arange(self.ndof, dtype=np.int64), np.diff(self.indptr)) * self.ndof + self.indices
        # slot of each diagonal entry (every dof touches its own element)
        self.diag_slot = np.searchsorted(self._ukey, np.arange(self.ndof, dtype=np.int64) * (self.ndof + 1))

    def slots(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """CSR data positions of entries (rows, cols); they must lie in the pattern."""
        key = np.asarray(rows, np.int64) * self.ndof + np.asarray(cols, np.int64)
        pos = np.searchsorted(self._ukey, key)
        if np.any(pos >= self.nnz) or np.any(self._ukey[np.minimum(pos, self.nnz - 1)] != key):
            raise ValueError("entries outside the element sparsity pattern")
        return pos

    def _csr(self, data: np.ndarray) -> sp.csr_matrix:
        """The matrix of the pattern with entries ``data``.  Its index arrays are the pattern's own (shared, not
        copied: every matrix of a run has this one pattern, and nothing here changes a matrix's structure in
        place), flagged sorted, so that the factorization recognizes the pattern by identity and skips the
        O(nnz) comparisons."""
        A = sp.csr_matrix((data, self.indices, self.indptr), shape=(self.ndof, self.ndof), copy=False)
        A.has_sorted_indices = True
        return A

    def matrix(self, Ke: np.ndarray) -> sp.csr_matrix:
        return self._csr(np.bincount(self._slot, weights=Ke.ravel(), minlength=self.nnz))

    def matrix_field_major(self, Kf: np.ndarray) -> sp.csr_matrix:
        """As :meth:`matrix` for element matrices laid out (M, nf equation, nf field, 3 a, 3 b).

        The layout in which :func:`assemble_forms` accumulates (each term adds to a contiguous block);
        the slot map is permuted once instead of the element matrices at every assembly.  With the
        compiled kernels (:mod:`solver.kernels`) each slot gathers its entries (on
        :func:`assembly_threads` threads, the same sums for any count).
        """
        if self._slot_fm is None:
            nf = self.n_fields
            self._slot_fm = self._slot.reshape(-1, 3, nf, 3, nf).transpose(0, 2, 4, 1, 3).ravel()
        if kernels.backend() == "numba":
            if self._slot_sum is None:
                self._slot_sum = kernels.SlotSum(self._slot_fm, self.nnz)
            n = assembly_threads()
            return self._csr(self._slot_sum(Kf, n, _pool(n) if n > 1 else None))
        return self._csr(np.bincount(self._slot_fm, weights=Kf.ravel(), minlength=self.nnz))

    def vector(self, Fe: np.ndarray) -> np.ndarray:
        return np.bincount(self.edofs.ravel(), weights=Fe.ravel(), minlength=self.ndof)

    def dirichlet_rows(self, dofs: np.ndarray) -> "DirichletRows":
        return DirichletRows(self, np.asarray(dofs, dtype=np.int64))


class DirichletRows:
    """Dirichlet conditions that keep the CSR structure: rows zeroed, unit diagonal."""

    def __init__(self, asm: BlockAssembler, dofs: np.ndarray):
        self.dofs = np.unique(dofs)
        starts = asm.indptr[self.dofs]
        ends = asm.indptr[self.dofs + 1]
        counts = ends - starts
        self.row_slots = np.repeat(starts, counts) + (np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts))
        self.diag_slots = asm.diag_slot[self.dofs]

    def apply_matrix(self, A: sp.csr_matrix) -> sp.csr_matrix:
        A.data[self.row_slots] = 0.0
        A.data[self.diag_slots] = 1.0
        return A

    def apply_residual(self, R: np.ndarray, x: np.ndarray, values: np.ndarray) -> np.ndarray:
        """Residual rows become ``x - values`` on the constrained dofs."""
        R[self.dofs] = x[self.dofs] - values
        return R


# --------------------------------------------------------------------------
# linear operators (closed forms for P1)
# --------------------------------------------------------------------------
_LOCAL_MASS = (np.ones((3, 3)) + np.eye(3)) / 12.0


def mass_matrix(points, triangles, lumped: bool = False) -> sp.csr_matrix:
    """Scalar P1 mass matrix ∫ N_a N_b (mm²); ``lumped`` gives the row-sum diagonal."""
    g = geometry(points, triangles)
    n = len(points)
    if lumped:
        return sp.diags(np.bincount(triangles.ravel(), weights=np.repeat(g.areas / 3, 3), minlength=n)).tocsr()
    Ke = g.areas[:, None, None] * _LOCAL_MASS
    return BlockAssembler(triangles, n, 1).matrix(Ke)


def stiffness_matrix(points, triangles, coef=None) -> sp.csr_matrix:
    """Scalar P1 stiffness ∫ c ∇N_a·∇N_b with element-constant ``coef`` (M,) (default 1)."""
    g = geometry(points, triangles)
    c = np.ones(len(triangles)) if coef is None else np.broadcast_to(coef, (len(triangles),))
    Ke = np.einsum("m,mai,mbi->mab", c * g.areas, g.grads, g.grads)
    return BlockAssembler(triangles, len(points), 1).matrix(Ke)


def strain_matrix(geom: Geometry) -> np.ndarray:
    """B (M, 3, 6): Voigt strain (εxx, εyy, 2εxy) from local dofs (ux0, uy0, ux1, ...)."""
    M = len(geom.areas)
    B = np.zeros((M, 3, 6))
    B[:, 0, 0::2] = geom.grads[:, :, 0]
    B[:, 1, 1::2] = geom.grads[:, :, 1]
    B[:, 2, 0::2] = geom.grads[:, :, 1]
    B[:, 2, 1::2] = geom.grads[:, :, 0]
    return B


def plane_strain_D(E: float, nu: float) -> np.ndarray:
    """Plane-strain elasticity matrix in Voigt notation (kPa), E in kPa."""
    lam = E * nu / ((1 + nu) * (1 - 2 * nu))
    mu = E / (2 * (1 + nu))
    return np.array([[lam + 2 * mu, lam, 0.0], [lam, lam + 2 * mu, 0.0], [0.0, 0.0, mu]])


def elasticity_matrix(points, triangles, E: float, nu: float) -> sp.csr_matrix:
    """Vector plane-strain stiffness ∫ ε(v):C:ε(u) (kPa·mm² per mm² of dof), 2 fields node-major."""
    g = geometry(points, triangles)
    B = strain_matrix(g)
    Ke = np.einsum("m,mki,kl,mlj->mij", g.areas, B, plane_strain_D(E, nu), B)
    return BlockAssembler(triangles, len(points), 2).matrix(Ke)


# --------------------------------------------------------------------------
# boundary integrals on tagged edges
# --------------------------------------------------------------------------
def edge_geometry(points: np.ndarray, edges: np.ndarray):
    """Lengths (E,) mm and unit normals (E, 2) of edges (direction rotated clockwise).

    The orientation of these normals depends on the edge's node order; use
    :func:`outward_normals` for normals pointing out of a triangulated domain.
    """
    t = points[edges[:, 1]] - points[edges[:, 0]]
    L = np.hypot(t[:, 0], t[:, 1])
    n = np.stack([t[:, 1], -t[:, 0]], axis=1) / L[:, None]
    return L, n


def outward_normals(points: np.ndarray, edges: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lengths (E,) and outward unit normals (E, 2) of boundary edges of a triangulation."""
    L, n = edge_geometry(points, edges)
    # the triangle owning each edge: its third vertex lies inside
    key = lambda a, b: np.minimum(a, b).astype(np.int64) * len(points) + np.maximum(a, b)
    tk = np.concatenate([key(triangles[:, i], triangles[:, (i + 1) % 3]) for i in range(3)])
    third = np.concatenate([triangles[:, (i + 2) % 3] for i in range(3)])
    order = np.argsort(tk)
    pos = np.searchsorted(tk[order], key(edges[:, 0], edges[:, 1]))
    opp = points[third[order[pos]]]
    mid = 0.5 * (points[edges[:, 0]] + points[edges[:, 1]])
    flip = np.einsum("ei,ei->e", opp - mid, n) > 0
    n[flip] *= -1
    return L, n


def edge_mass(points, edges, n_nodes: int) -> sp.csr_matrix:
    """∫_Γ N_a N_b ds over the given edges (mm)."""
    L, _ = edge_geometry(points, edges)
    loc = np.array([[2.0, 1.0], [1.0, 2.0]]) / 6.0
    rows = np.repeat(edges, 2, axis=1).ravel()
    cols = np.tile(edges, (1, 2)).ravel()
    data = (L[:, None, None] * loc).ravel()
    return sp.csr_matrix((data, (rows, cols)), shape=(n_nodes, n_nodes))


def edge_load(points, edges, n_nodes: int, g) -> np.ndarray:
    """∫_Γ g N_a ds for a constant or per-edge ``g`` (units of g times mm)."""
    L, _ = edge_geometry(points, edges)
    g = np.broadcast_to(np.asarray(g, dtype=float), L.shape)
    return np.bincount(edges.ravel(), weights=np.repeat(0.5 * L * g, 2), minlength=n_nodes)


# --------------------------------------------------------------------------
# element chunks: cache-sized pieces of the element arrays, optionally on threads
# --------------------------------------------------------------------------
CHUNK_ELEMENTS = 2048  # a chunk's dual-number intermediates (~10 MB at 7 fields) stay in L2/L3


def element_chunks(n_elements: int, size: int = CHUNK_ELEMENTS) -> tuple:
    """Contiguous slices covering ``range(n_elements)``, each of at most ``size`` elements."""
    if size < 1:
        raise ValueError(f"chunk size must be >= 1, got {size}")
    return tuple(slice(a, min(a + size, n_elements)) for a in range(0, n_elements, size))


THREAD_CHUNK_ELEMENTS = 5000  # with threads, fewer larger chunks: less time under the GIL per element


@lru_cache(maxsize=64)
def thread_chunks(n_elements: int, threads: int) -> tuple:
    """Chunks for ``threads`` assembly threads: a multiple of ``threads`` chunks of about
    :data:`THREAD_CHUNK_ELEMENTS` (measured at h = 1 mm on 2 threads: 4 chunks of 5,103 elements
    0.142 s against 10 of 2,048 0.157 s per residual and Jacobian).  Results do not depend on the
    chunking: every element is computed on its own."""
    k = threads * max(1, round(n_elements / (threads * THREAD_CHUNK_ELEMENTS)))
    return element_chunks(n_elements, -(-n_elements // k))


@lru_cache(maxsize=None)
def _pool(n: int) -> ThreadPoolExecutor:
    return ThreadPoolExecutor(max_workers=n, thread_name_prefix="dchfrac-assembly")


def map_chunks(fn, chunks) -> None:
    """Call ``fn(chunk)`` for every chunk, on :func:`assembly_threads` threads; exceptions propagate.

    ``fn`` must write disjoint outputs per chunk, so the result does not depend on the thread count.
    """
    n = min(assembly_threads(), len(chunks))
    if n <= 1:
        for c in chunks:
            fn(c)
        return
    for f in [_pool(n).submit(fn, c) for c in chunks]:
        f.result()


# --------------------------------------------------------------------------
# point-wise forms -> element residuals and exact Jacobians
# --------------------------------------------------------------------------
def qp_inputs(U_elem: np.ndarray, geom: Geometry, quad: Quadrature) -> np.ndarray:
    """Point-wise inputs (M, nq, nf, 3): value and 2 gradient components of every field.

    ``U_elem`` (M, 3, nf) are the element's nodal values.
    """
    if kernels.backend() == "numba":
        return kernels.qp_inputs(U_elem, quad.bary, geom.grads)
    vals = _values_in_order(quad.bary, U_elem)
    grads = field_gradients(geom.grads, U_elem, in_order=True)
    nq = len(quad.weights)
    out = np.empty(vals.shape + (3,))
    out[..., 0] = vals
    out[..., 1:] = grads[:, None, :, :].repeat(nq, axis=1)
    return out


def _field_derivatives(c: Dual, M: int, nq: int):
    """The fields a Dual coefficient depends on and its derivatives (M, nq, n_fields_used, 3) w.r.t. them."""
    fields = sorted({s // 3 for s in c.idx})
    D = np.zeros((M, nq, len(fields) * 3))
    pos = {f: n for n, f in enumerate(fields)}
    D[..., [3 * pos[s // 3] + s % 3 for s in c.idx]] = c.dd
    return fields, D.reshape(M, nq, len(fields), 3)


def assemble_forms(F, geom: Geometry, quad: Quadrature, need_jacobian: bool = True, n_fields: int | None = None,
                   out: tuple | None = None):
    """Element residuals and Jacobians of the weak form Σ_q w |e| Σ_k F_ik(q) B_ak(q).

    ``F[i][k]`` is the point-wise coefficient (M, nq) of equation i: k = 0
    multiplies the test function value N_a, k = 1, 2 its gradient ∂N_a/∂x_k
    (the f0 / f1 split of a weak form); ``None`` marks a structural zero.
    Coefficients are :class:`Dual` numbers whose derivative slots are the
    inputs of :func:`qp_inputs` flattened as ``3 * field + l``, or plain
    arrays when ``need_jacobian`` is False.  Returns ``Fe`` (M, 3, neq) and
    ``Ke`` (M, neq, nf, 3, 3) (equation, field; test node a, trial node b), the layout of
    :meth:`BlockAssembler.matrix_field_major`.

    Because ∇N_a is constant on a P1 element, the gradient part of the test
    side is summed over quadrature points before it meets ∇N_a, and the
    trial side is contracted per field: no (M, nq, neq, 3, nf, 3) tensor
    is ever formed.

    ``out = (Fe, Ke)``: arrays (or views) of those shapes, zero on entry, to accumulate into
    instead of new ones (``Ke`` None without the Jacobian).  The caller's global arrays
    are then written in place: no per-chunk allocation, concatenation or copy (these
    moved ~70 MB per assembly at h = 1 mm).
    """
    M, nq = len(geom.areas), len(quad.weights)
    wq = quad.weights[None, :] * geom.areas[:, None]  # (M, nq)
    bary = quad.bary  # (nq, 3): N_a at the points
    G = geom.grads  # (M, 3, 2)
    neq = len(F)
    Fe, Ke = out if out is not None else (np.zeros((M, 3, neq)), None)
    if need_jacobian:
        nf = n_fields if n_fields is not None else next(c for row in F for c in row if c is not None).nvar // 3
        if Ke is None:
            Ke = np.zeros((M, neq, nf, 3, 3))  # field-major: every term adds to a contiguous block
        if Fe.shape != (M, 3, neq) or Ke.shape != (M, neq, nf, 3, 3):
            raise ValueError(f"out shapes {Fe.shape}, {Ke.shape} != {(M, 3, neq)}, {(M, neq, nf, 3, 3)}")
        bary_pairs = bary[:, :, None] * bary[:, None, :]  # (nq, 3 a, 3 b): N_a N_b at the points
        compiled = kernels.backend() == "numba"
        terms = []  # (i, k, dd, idx) for the compiled kernel, which takes every term in one pass
    for i, row in enumerate(F):
        for k, c in enumerate(row):
            if c is None:
                continue
            v = c.v if isinstance(c, Dual) else c
            if k == 0:
                Fe[:, :, i] += (wq * v) @ bary
            else:
                Fe[:, :, i] += (wq * v).sum(axis=1)[:, None] * G[:, :, k - 1]
            if not need_jacobian or not isinstance(c, Dual) or not c.idx:
                continue
            if compiled:
                terms.append((i, k, c.dd, c.idx))
                continue
            _add_jacobian_term(Ke[:, i], c, k, wq, bary, bary_pairs, G)
    if need_jacobian and compiled:
        kernels.forms_jacobian(Ke, wq, bary, G, terms)
    return Fe, Ke


def _add_jacobian_term(Ki: np.ndarray, c: Dual, k: int, wq: np.ndarray, bary: np.ndarray, bary_pairs: np.ndarray,
                       G: np.ndarray) -> None:
    """Add the Jacobian of one coefficient F_ik (a Dual over the points) to ``Ki`` (M, nf, 3 a, 3 b), the
    equation's view of Ke: the numpy path of :func:`assemble_forms` (the compiled kernel takes every term in one
    pass)."""
    M, nq = wq.shape
    fields, D = _field_derivatives(c, M, nq)  # only the fields F_ik depends on
    if not fields:
        return
    nfc = len(fields)
    cols = slice(fields[0], fields[-1] + 1) if fields[-1] - fields[0] + 1 == nfc else fields
    # ∂F_ik/∂U_jb at point q = D_j0 N_b(q) + D_j1 ∂N_b/∂x + D_j2 ∂N_b/∂y, summed over the (few)
    # points with explicit broadcasts: no batched 3 x 3 products (slow in numpy) and no BLAS calls
    # with an inner dimension of 3 (multithreaded BLAS made those 2x slower on a busy machine)
    WD = wq[:, None, :, None] * D.transpose(0, 2, 1, 3)  # (M, nfc, nq, 3 slots)
    Gb = G.transpose(0, 2, 1)[:, None]  # (M, 1, 2, 3 b)
    if k == 0:
        # Σ_q w N_a N_b D_j0 + Σ_l (Σ_q w N_a D_jl) ∂N_b/∂x_l
        A = sum(WD[:, :, q, 0, None, None] * bary_pairs[q] for q in range(nq))  # (M, nfc, 3 a, 3 b)
        H1 = sum(WD[:, :, q, 1, None] * bary[q] for q in range(nq))  # (M, nfc, 3 a)
        H2 = sum(WD[:, :, q, 2, None] * bary[q] for q in range(nq))
        A += H1[..., None] * Gb[:, :, 0, None, :] + H2[..., None] * Gb[:, :, 1, None, :]
        Ki[:, cols] += A
    else:
        # ∂N_a/∂x_k Σ_q w (D_j0 N_b + D_j1 ∂N_b/∂x + D_j2 ∂N_b/∂y)
        Tq = sum(WD[:, :, q, 0, None] * bary[q] for q in range(nq))  # (M, nfc, 3 b)
        s = WD[:, :, :, 1:].sum(axis=2)  # (M, nfc, 2)
        Tq += s[:, :, 0, None] * Gb[:, :, 0] + s[:, :, 1, None] * Gb[:, :, 1]
        Ki[:, cols] += G[:, None, :, None, k - 1] * Tq[:, :, None, :]
