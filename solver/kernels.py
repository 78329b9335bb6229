"""Compiled assembly kernels (optional: numba), with the numpy path as the reference.

The element Jacobian of a weak-form term Σ_q w |e| F_ik(q) B_ak(q) is a contraction of the
point-wise derivatives ∂F_ik/∂(input slot) with the P1 shape functions (see
:func:`solver.fem.assemble_forms`).  In numpy that contraction needs broadcast temporaries per
(term, field) and a dense copy of the sparse dual derivatives; compiled, it is one pass over the
elements that adds every term to the element's block while it sits in L1.  The CSR scatter
becomes a gather over the inverted slot map (:class:`SlotSum`), which can run on threads, instead
of a ``bincount`` over 9 M weights.  Both paths give the same matrices to round-off (summation
order differs); ``tests/test_kernels.py`` checks that, and the Taylor tests run on both.

With numba, :func:`solver.model.element_residuals` does not call this contraction: the point-wise physics,
its derivatives and the contraction are generated as one kernel from the traced forms
(:mod:`solver.codegen`); :func:`forms_jacobian` still serves :func:`solver.fem.assemble_forms` for other forms
(tests), :class:`SlotSum` the CSR gather of every Jacobian.

Selection: ``DCHFRAC_KERNELS`` = ``auto`` (default: numba when importable), ``numba`` (error if
it is not installed) or ``numpy`` (the fallback path).  numba is a core dependency; the code runs
without it (numpy kernels).  Kernels release the GIL (``nogil``), so the element chunks of
:func:`solver.fem.map_chunks` run them on several threads; they are serial inside, so they never
compete with a campaign's one-solver-per-core parallelism or nest thread pools.
"""
from __future__ import annotations

import os
from functools import lru_cache

import numpy as np

__all__ = ["backend", "numba_available", "forms_jacobian", "SlotSum", "qp_inputs"]

_CHOICES = ("auto", "numba", "numpy")


@lru_cache(maxsize=None)
def numba_available() -> bool:
    """Whether numba is installed (found without importing it: the import takes a second or more)."""
    from importlib.util import find_spec

    return find_spec("numba") is not None


def backend() -> str:
    """The active kernel backend, ``"numba"`` or ``"numpy"``, from ``DCHFRAC_KERNELS``."""
    v = os.environ.get("DCHFRAC_KERNELS", "auto").strip().lower()
    if v not in _CHOICES:
        raise ValueError(f"DCHFRAC_KERNELS={v!r} is not allowed: one of {_CHOICES}")
    if v == "numpy":
        return "numpy"
    if v == "numba" and not numba_available():
        raise ValueError("DCHFRAC_KERNELS='numba' but numba is not installed (pip install numba)")
    return "numba" if numba_available() else "numpy"


# ---------------------------------------------------------------- kernels (pure Python bodies)
def _forms_jacobian_py(Ke, wq, bary, G, dds, t_eq, t_k, t_off, s_field, s_l):  # pragma: no cover - compiled
    """Ke[e, i, f, a, b] += Σ_q wq[e,q] Σ_{slots s of (i, f)} dd[e,q,s] T_a^k(q) B_b^l(q).

    Term t is the coefficient F_ik (i = t_eq[t], k = t_k[t]); dds[t] (M, nq, ns_t) are its
    derivatives with respect to its slots, whose field and l are s_field and s_l at t_off[t] + s.
    Test side T_a^0 = N_a(q), T_a^k = ∂N_a/∂x_{k-1} (constant on the element); trial side
    B_b^0 = N_b(q), B_b^l = ∂N_b/∂x_{l-1}.  Whichever side is constant is pulled out of the point
    sum.  All terms of one element are added before the next element, so its block of Ke
    (neq nf 9 doubles) stays in L1.
    """
    M, nq = wq.shape
    wd = np.empty(nq)
    for e in range(M):
        for term in range(len(dds)):
            _add_term(Ke, e, t_eq[term], t_k[term], dds[term], t_off[term], s_field, s_l, wq, bary, G, wd)


def _add_term_py(Ke, e, i, k, dd, off, s_field, s_l, wq, bary, G, wd):  # pragma: no cover - compiled
    """One term's contribution to element e (see :func:`_forms_jacobian_py`)."""
    nq = wq.shape[1]
    for s in range(dd.shape[2]):
        f = s_field[off + s]
        l = s_l[off + s]
        for q in range(nq):
            wd[q] = wq[e, q] * dd[e, q, s]
        if k == 0 and l == 0:
            # Σ_q w D N_a N_b: the only case needing the point-wise product
            for a in range(3):
                for b in range(3):
                    acc = 0.0
                    for q in range(nq):
                        acc += wd[q] * bary[q, a] * bary[q, b]
                    Ke[e, i, f, a, b] += acc
        elif k == 0:
            # (Σ_q w D N_a) ∂N_b/∂x_l
            for a in range(3):
                h = 0.0
                for q in range(nq):
                    h += wd[q] * bary[q, a]
                for b in range(3):
                    Ke[e, i, f, a, b] += h * G[e, b, l - 1]
        else:
            # ∂N_a/∂x_k (Σ_q w D B_b)
            for b in range(3):
                t = 0.0
                if l == 0:
                    for q in range(nq):
                        t += wd[q] * bary[q, b]
                else:
                    for q in range(nq):
                        t += wd[q]
                    t *= G[e, b, l - 1]
                for a in range(3):
                    Ke[e, i, f, a, b] += G[e, a, k - 1] * t


def _qp_inputs_py(U_elem, bary, grads, out):  # pragma: no cover - compiled
    """out[e, q, f] = (Σ_a N_a(q) U[e,a,f], Σ_a ∂N_a/∂x U[e,a,f], Σ_a ∂N_a/∂y U[e,a,f])."""
    M, _, nf = U_elem.shape
    nq = bary.shape[0]
    for e in range(M):
        for f in range(nf):
            gx = 0.0
            gy = 0.0
            for a in range(3):
                gx += grads[e, a, 0] * U_elem[e, a, f]
                gy += grads[e, a, 1] * U_elem[e, a, f]
            for q in range(nq):
                v = 0.0
                for a in range(3):
                    v += bary[q, a] * U_elem[e, a, f]
                out[e, q, f, 0] = v
                out[e, q, f, 1] = gx
                out[e, q, f, 2] = gy


def _gather_sum_py(perm, ptr, values, out, s0, s1):  # pragma: no cover - compiled
    """out[s] = Σ_{j = ptr[s]}^{ptr[s+1]-1} values[perm[j]] for s in [s0, s1): each sum in a fixed order."""
    for s in range(s0, s1):
        acc = 0.0
        for j in range(ptr[s], ptr[s + 1]):
            acc += values[perm[j]]
        out[s] = acc


@lru_cache(maxsize=None)
def _compiled():
    import numba

    jit = numba.njit(cache=True, nogil=True, fastmath=False)
    # the element loop calls the term kernel by its global name: bind the compiled one before compiling
    globals()["_add_term"] = jit(_add_term_py)
    return jit(_forms_jacobian_py), jit(_gather_sum_py), jit(_qp_inputs_py)


def compiled_dispatchers() -> tuple:
    """The numba dispatchers of this module's kernels that every run calls: the CSR gather of the Jacobian
    (for :mod:`solver.jitcache`'s compile feedback)."""
    return (_compiled()[1],)


# ---------------------------------------------------------------- public entry points
def forms_jacobian(Ke: np.ndarray, wq: np.ndarray, bary: np.ndarray, G: np.ndarray, terms: list) -> None:
    """Add the element Jacobians of all ``terms`` to ``Ke`` (M, neq, nf, 3, 3), in place (compiled).

    wq (M, nq): quadrature weight × element area (mm²); bary (nq, 3): N_a at the points;
    G (M, 3, 2): ∂N_a/∂x (1/mm).  ``terms``: (i, k, dd, idx) per coefficient F_ik with derivatives
    dd (M, nq, len(idx)) (or broadcastable) with respect to the input slots ``idx`` (slot = 3 field + l,
    l = 0 value, 1, 2 gradient); k = 0 for the test-function value, 1 or 2 for its gradient.
    """
    kern = _compiled()[0]
    M, nq = wq.shape
    terms = [t for t in terms if len(t[3])]
    if not terms:
        return
    # read-only broadcast views, no copies.  numba types a tuple of arrays by their layouts: contiguous
    # ('C') and broadcast ('A') views make different tuple types, so the terms go in (at most) two
    # homogeneous groups, one kernel call each
    views = [np.broadcast_to(t[2], (M, nq, len(t[3]))) for t in terms]
    for contiguous in (True, False):
        group = [(t, v) for t, v in zip(terms, views) if v.flags.c_contiguous == contiguous]
        if not group:
            continue
        idx = np.concatenate([np.asarray(t[3], np.int64) for t, _ in group])
        t_eq = np.array([t[0] for t, _ in group], np.int64)
        t_k = np.array([t[1] for t, _ in group], np.int64)
        t_off = np.cumsum([0] + [len(t[3]) for t, _ in group[:-1]]).astype(np.int64)
        kern(Ke, wq, bary, G, tuple(v for _, v in group), t_eq, t_k, t_off, idx // 3, idx % 3)


class SlotSum:
    """Sum of entries into CSR slots, ``out[s] = Σ_{j: slot[j] = s} values[j]``, in a fixed order.

    The inverse of the slot map is computed once (a stable sort: contributions to a slot are summed
    in element order), so every sum is a contiguous gather, and disjoint ranges of slots can be
    summed on ``threads`` threads with identical results for any thread count.
    """

    def __init__(self, slot: np.ndarray, n_slots: int):
        itype = np.int32 if slot.size < 2**31 else np.int64
        self.perm = np.argsort(slot, kind="stable").astype(itype)
        self.ptr = np.concatenate([[0], np.cumsum(np.bincount(slot, minlength=n_slots))]).astype(np.int64)
        self.n_slots = int(n_slots)
        self.bounds: dict[int, list[int]] = {}  # slot ranges per thread count (_bounds)

    def _bounds(self, threads: int) -> list[int]:
        """Slot ranges of the ``threads`` threads, split by contributions (not slots) so the threads get equal
        work; made once per thread count (the search on the int64 offsets, with integer targets: float
        targets would make numpy convert the whole offset array)."""
        if threads not in self.bounds:
            targets = (np.arange(1, threads, dtype=np.int64) * int(self.ptr[-1])) // threads
            self.bounds[threads] = [0, *np.searchsorted(self.ptr, targets).tolist(), self.n_slots]
        return self.bounds[threads]

    def __call__(self, values: np.ndarray, threads: int = 1, pool=None) -> np.ndarray:
        gather = _compiled()[1]
        out = np.empty(self.n_slots)
        values = values.reshape(-1)
        if threads <= 1 or pool is None:
            gather(self.perm, self.ptr, values, out, 0, self.n_slots)
            return out
        bounds = self._bounds(threads)
        futures = [pool.submit(gather, self.perm, self.ptr, values, out, a, b) for a, b in zip(bounds[:-1], bounds[1:])]
        for f in futures:
            f.result()
        return out


def qp_inputs(U_elem: np.ndarray, bary: np.ndarray, grads: np.ndarray) -> np.ndarray:
    """Point-wise value and gradient (M, nq, nf, 3) of P1 fields from nodal values U_elem (M, 3, nf) (compiled).

    bary (nq, 3): N_a at the points; grads (M, 3, 2): ∂N_a/∂x (1/mm).  Same as :func:`solver.fem.qp_inputs`.
    """
    M, _, nf = U_elem.shape
    out = np.empty((M, bary.shape[0], nf, 3))
    _compiled()[2](np.ascontiguousarray(U_elem), bary, grads, out)
    return out
