"""One small interface for every sparse direct solve, so the factorization can be swapped.

``factorize(A, kind)`` returns an object with ``solve(b)``.  Backends:

* ``"superlu"`` (the fallback, scipy only): scipy's SuperLU called
  directly (``spsolve`` silently switches to UMFPACK when installed).  The
  rows are first equilibrated (each divided by its largest entry: the block
  rows of momentum, mass and chemical potential differ by orders of
  magnitude), then factorized with the COLAMD column ordering, symmetric
  mode and a diagonal pivot threshold of 0.1.  COLAMD rather than minimum
  degree on AᵀA+A: with the threshold pivoting of the coupled Jacobian the
  minimum-degree fill grows as the run goes on and COLAMD's does not
  (results/archive/bench_rounds.md, sixth round).
  Threshold pivoting is kept (0.1, not 0), and every solve is checked: if
  the relative residual of a solve exceeds 1e-8 the matrix is refactorized
  with full partial pivoting (COLAMD, threshold 1) and the solve repeated.
* ``"pypardiso"`` (a core dependency where MKL's wheels install: x86_64 Linux and Windows): MKL PARDISO,
  picked by ``"auto"`` when importable (``DCHFRAC_LINEAR_SOLVER=superlu`` forces the fallback).
  Measured on the coupled Jacobian (7 fields):
  h = 2 mm (18,494 unknowns) 0.13 s against SuperLU's 0.41 s, h = 1 mm
  (72,709) 0.78 s against 4.5 s.  The symbolic analysis (ordering and
  symbolic factorization, PARDISO phase 11) depends only on the sparsity
  pattern, which the block assembler keeps fixed for a whole run, so it is
  done once per pattern and every later factorization is numerical only
  (phase 22): 0.068 s and 0.44 s at h = 2 and 1 mm.  Solves call phase 33
  directly (pypardiso's own ``solve`` hashes the whole matrix each call).
  The first solve with new factors is checked as for SuperLU; a poor one (PARDISO perturbs tiny
  pivots) is improved by iterative refinement with the same factors.

Static condensation (``factorize(..., condense=g)``, SuperLU only): unknowns g whose block A_gg is
diagonal, as the lumped gradient projection G = Π∇S is (solver/forms.py), are eliminated before the
factorization, and SuperLU factorizes the Schur complement K = A_rr − A_rg A_gg⁻¹ A_gr of the other unknowns r:

  x_r = K⁻¹ (b_r − A_rg A_gg⁻¹ b_g),   x_g = A_gg⁻¹ (b_g − A_gr x_r).

This is exact algebra, not an approximation.  K is formed from the values, so it widens the stencil to second
neighbours only where A_rg is non-zero: the Korteweg force is bilinear in G, and its derivative vanishes where
∇S does, away from the interfaces.  K has 2/7 fewer unknowns than A and less fill.  PARDISO keeps the full matrix:
its symbolic analysis is reused for the run's fixed pattern, and K's pattern moves with the interfaces.

The residual check (one matrix-vector product and two norms, a fifth to a third of a
substitution at h = 1 mm) is made on the first solve with each set of factors: a backward-stable
factorization gives small residuals for every right-hand side, and an unstable one shows on the
first.  Factors whose first solve needed a fallback or a refinement are checked on every solve.

Precision of the factors (``factorize(..., precision=)``, run option ``linear_precision``): "double", or
"single": the factors are made and applied in single precision (float32; PARDISO's iparm(28) = 1, SuperLU's
sgstrf) while the matrix, the right-hand side, the residual check and the solution stay in double.  Newton
then takes inexact steps: a linear solve whose relative residual is at most ``SINGLE_FORCING`` (1e-3) leaves
Newton's convergence linear with a rate of about that residual (Dembo, Eisenstat and Steihaug 1982, inexact
Newton methods), far below the contraction the Jacobian reuse already accepts (0.3), and the converged state
meets the same residual-based tests.  The first solve with single factors is checked: above the forcing
tolerance it is refined in mixed precision (residual in double, correction with the single factors; up to three
steps), and if that does not reach it the matrix is factorized again in double.

Each call counts a factorization in ``STATS`` so runs can report how many
factorizations they needed (the floor of this solver's cost).
"""
from __future__ import annotations

import os

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .profiling import phase
from .paths import resolve, resolve_precision

STATS = {"factorizations": 0}

#: the largest relative residual ||A x - b|| / ||b|| accepted from a solve with single-precision factors: the
#: forcing term of the inexact Newton iteration, 300x below the contraction the Jacobian reuse accepts (0.3).
SINGLE_FORCING = 1e-3


def _locate_mkl_rt() -> None:
    """Point pypardiso at MKL's runtime library before it looks for it.

    Without ``PYPARDISO_MKL_RT`` pypardiso globs the whole of ``sys.prefix/lib*/**`` for ``mkl_rt``,
    on import and again for every solver object: about 4 s per process here (measured: 2.3 s import +
    1.7 s per solver object), which is a third of a short h = 4 mm run.  The pip wheel of MKL puts the
    library directly in ``<prefix>/lib``; look there only, and leave pypardiso's own search as the
    fallback when it is elsewhere."""
    import glob
    import site
    import sys

    if os.environ.get("PYPARDISO_MKL_RT"):
        return
    for base in (sys.prefix, site.USER_BASE):
        hits = sorted(glob.glob(f"{base}/lib/libmkl_rt.so*") + glob.glob(f"{base}/lib/libmkl_rt*.dylib")
                      + glob.glob(f"{base}/Library/bin/mkl_rt*.dll"), key=len)
        if hits:
            os.environ["PYPARDISO_MKL_RT"] = hits[0]
            return


class _Factors:
    """What both backends share: the single-precision layer of ``solve`` (see the module docstring)."""

    single: bool
    trusted: bool
    A: sp.csr_matrix

    def solve(self, b):
        with phase("solve"):
            b = np.asarray(b, float)
            if not self.single or self.trusted:
                return self._solve(b)
            x = self._solve(b)
            nb = max(np.linalg.norm(b), 1e-300)
            for k in range(4):  # the check, and up to three mixed-precision refinement steps
                r = b - self.A @ x
                if np.linalg.norm(r) <= SINGLE_FORCING * nb:
                    self.trusted = k == 0  # a solve that needed refinement keeps its factors checked
                    return x
                if k < 3:
                    STATS["refinements"] = STATS.get("refinements", 0) + 1
                    x = x + self._solve(r)
            STATS["factorizations"] += 1
            STATS["precision_fallbacks"] = STATS.get("precision_fallbacks", 0) + 1
            with phase("numeric_factorization"):
                self.single, self.trusted = False, False
                self._factorize()
            return self._solve(b)


class _Condensation:
    """The elimination of unknowns ``g`` whose block A_gg of ``A`` is diagonal (see the module docstring)."""

    def __init__(self, A: sp.csr_matrix, g: np.ndarray):
        keep = np.ones(A.shape[0], bool)
        keep[g] = False
        self.r, self.g = np.flatnonzero(keep), np.asarray(g)
        A_rows = A[self.g]
        A_gg = A_rows[:, self.g].tocoo()
        off = A_gg.row != A_gg.col
        diag = A_gg.diagonal()
        if np.any(A_gg.data[off] != 0) or np.any(diag == 0):
            raise ValueError("condense: the block of the eliminated unknowns must be diagonal with a non-zero "
                             "diagonal")
        self.dinv = 1.0 / diag
        A_r = A[self.r]
        self.A_rg, self.A_gr = A_r[:, self.g].tocsr(), A_rows[:, self.r].tocsr()
        self.A_rg.eliminate_zeros()  # the pattern's couplings to G are zero away from the interfaces
        self.A_gr.eliminate_zeros()
        self.K = (A_r[:, self.r] - self.A_rg @ sp.diags(self.dinv) @ self.A_gr).tocsr()

    def reduce(self, b: np.ndarray) -> np.ndarray:
        """The right-hand side of the condensed system, b_r − A_rg A_gg⁻¹ b_g."""
        return b[self.r] - self.A_rg @ (self.dinv * b[self.g])

    def expand(self, b: np.ndarray, x_r: np.ndarray) -> np.ndarray:
        """The full solution from the condensed one: x_g = A_gg⁻¹ (b_g − A_gr x_r)."""
        x = np.empty(b.shape[0])
        x[self.r] = x_r
        x[self.g] = self.dinv * (b[self.g] - self.A_gr @ x_r)
        return x


class _SuperLU(_Factors):
    def __init__(self, A, single: bool = False, condense: np.ndarray | None = None):
        self.A = sp.csr_matrix(A)
        self.cond = None if condense is None else _Condensation(self.A, condense)
        M = self.A if self.cond is None else self.cond.K
        rmax = np.asarray(abs(M).max(axis=1).todense()).ravel()
        if np.any(rmax == 0):
            raise np.linalg.LinAlgError("singular matrix: a zero row")
        self.dr = 1.0 / rmax
        As = sp.diags(self.dr) @ M
        self.As = As.tocsc()
        self.single = single
        self._factorize()

    def _factorize(self):
        self.lu = self._splu("COLAMD", 0.1, dict(SymmetricMode=True))
        self.safe = False
        self.trusted = False  # the first solve passed its check without a fallback: later solves are not checked

    def _splu(self, order: str, thresh: float, options: dict | None = None):
        return spla.splu(self.As.astype(np.float32) if self.single else self.As, permc_spec=order,
                         diag_pivot_thresh=thresh, options=options or {})

    def _substitute(self, b):
        rhs = self.dr * (b if self.cond is None else self.cond.reduce(b))
        x = self.lu.solve(rhs.astype(np.float32) if self.single else rhs).astype(float)
        return x if self.cond is None else self.cond.expand(b, x)

    def _solve(self, b):
        x = self._substitute(b)
        if self.trusted or self.single:  # single factors: checked against the forcing tolerance by solve()
            return x
        nb = np.linalg.norm(b)
        rel = np.linalg.norm(self.A @ x - b) / max(nb, 1e-300)
        if not self.safe and rel > 1e-8:
            STATS["factorizations"] += 1
            STATS["pivoting_fallbacks"] = STATS.get("pivoting_fallbacks", 0) + 1
            with phase("numeric_factorization"):
                self.lu = self._splu("COLAMD", 1.0)
            self.safe = True
            x = self._substitute(b)
        else:
            self.trusted = not self.safe
        return x


_PARDISO = {}  # per precision: the process-wide solver, its pattern, 1-based index arrays, and the owner


def _pardiso_solver(precision: str = "double") -> dict:
    """The process-wide PARDISO handle of ``precision`` with its state (one per process and precision:
    constructing one searches the file system for MKL, and a handle holds one factorization at a time)."""
    if precision not in _PARDISO:
        # Conditional numerical reproducibility: without it MKL's threaded kernels may sum in another
        # order from run to run (p_inj differed by 1e-14 between identical runs); set before MKL loads.
        os.environ.setdefault("MKL_CBWR", "AUTO,STRICT")
        _locate_mkl_rt()
        import pypardiso

        s = pypardiso.PyPardisoSolver()
        # pypardiso starts from iparm = 0, which makes PARDISO overwrite every setting with its defaults on
        # the first call; iparm(1) = 1 keeps ours.  Defaults except: sequential METIS ordering (2, so that
        # identical runs give identical results), no scaling and weighted matching (11, 13: with them PARDISO
        # perturbed pivots of the coupled Jacobian, relative residual 4e-3 at h = 2 mm; without them none is
        # perturbed and the residual is 3e-12, every diagonal entry here being nonzero: mass, storage,
        # stiffness), pivot perturbation 1e-13 (10), no internal iterative refinement (8, reset before each
        # solve: PARDISO writes the number of steps it made there), refined in solve() only when needed, the
        # two-level factorization (24: 1), with which the substitution uses every core (same fill, and the
        # same result bitwise run to run; results/archive/bench_rounds.md, fourth round), and the precision of the
        # factors (28: 1 single, 0 double).
        for i, v in {1: 1, 2: 2, 8: 0, 10: 13, 11: 0, 13: 0, 24: 1, 28: int(precision == "single")}.items():
            s.set_iparm(i, v)
        _PARDISO[precision] = dict(solver=s, pattern=None, pattern_arrays=None, owner=None, one_based=None)
    return _PARDISO[precision]


class _Pardiso(_Factors):
    """PARDISO factors of one matrix; the process-wide handle of their precision holds one factorization at a
    time."""

    def __init__(self, A, single: bool = False):
        self.A = sp.csr_matrix(A, dtype=float)
        self.A.sort_indices()
        self.single = single
        self._factorize()

    def _factorize(self):
        self.trusted = False  # set by the first solve when its residual needs no refinement
        self.data = self.A.data.astype(np.float32) if self.single else self.A.data
        state, A = _pardiso_solver("single" if self.single else "double"), self.A
        state["solver"]._check_A(A)
        pat = state["pattern"]
        # the same pattern: the very index arrays of the last analysis (the assembler shares its pattern's arrays
        # with every matrix it makes, fem.BlockAssembler._csr), or equal ones
        same = pat is not None and ((state["pattern_arrays"][0] is A.indptr and state["pattern_arrays"][1] is A.indices)
                                    or (pat[0].shape == A.indptr.shape and pat[1].shape == A.indices.shape
                                        and np.array_equal(pat[0], A.indptr) and np.array_equal(pat[1], A.indices)))
        rhs = np.zeros((A.shape[0], 1), self.data.dtype)
        if not same:  # the symbolic analysis (phase 11) is done once per pattern and reused after
            state["pattern"] = (A.indptr.copy(), A.indices.copy())
            state["pattern_arrays"] = (A.indptr, A.indices)
            state["one_based"] = ((A.indptr + 1).astype(np.int32), (A.indices + 1).astype(np.int32))
            with phase("symbolic_factorization"):
                _call(state["solver"], self.data, state["one_based"], 11, rhs)
        _call(state["solver"], self.data, state["one_based"], 22, rhs)
        state["owner"] = self

    def _solve(self, b):
        state = _pardiso_solver("single" if self.single else "double")
        if state["owner"] is not self:  # another matrix was factorized since: factorize this one again
            STATS["factorizations"] += 1
            with phase("numeric_factorization"):
                self._factorize()
        x = self._substitute(state, b)
        if self.trusted or self.single:  # single factors: checked against the forcing tolerance by solve()
            return x
        nb = max(np.linalg.norm(b), 1e-300)
        for k in range(3):  # iterative refinement, rarely needed (perturbed pivots)
            r = b - self.A @ x
            if np.linalg.norm(r) <= 1e-10 * nb:
                self.trusted = k == 0
                break
            STATS["refinements"] = STATS.get("refinements", 0) + 1
            x = x + self._substitute(state, r)
        return x

    def _substitute(self, state: dict, b: np.ndarray) -> np.ndarray:
        """Forward and back substitution with the current factors (PARDISO phase 33), in double."""
        # No internal iterative refinement (PARDISO overwrites iparm(8) with the number of steps it made, so
        # it is reset before every call): solve() checks the residual and refines only when needed.
        state["solver"].set_iparm(8, 0)
        rhs = np.asfortranarray(b, dtype=self.data.dtype)
        return _call(state["solver"], self.data, state["one_based"], 33, rhs).reshape(b.shape).astype(float, copy=False)


def _call(s, data: np.ndarray, one_based: tuple, phase_id: int, b: np.ndarray) -> np.ndarray:
    """One PARDISO call (``phase_id`` 11 analysis, 22 numeric factorization, 33 substitution) on the matrix
    with values ``data`` (float64, or float32 for a handle with iparm(28) = 1; ``b`` of the same type) and
    the 1-based int32 index arrays ``one_based`` = (ia, ja), made once per pattern: pypardiso's own
    ``_call_pardiso`` converts them on every call (20 ms per call at h = 1 mm, half a substitution)."""
    import ctypes

    ia, ja = one_based
    x = np.zeros_like(b)
    err = ctypes.c_int32(0)
    i32 = ctypes.POINTER(ctypes.c_int32)
    real = ctypes.POINTER(ctypes.c_float if data.dtype == np.float32 else ctypes.c_double)
    s._mkl_pardiso(s.pt.ctypes.data_as(ctypes.POINTER(s._pt_type[0])), ctypes.byref(ctypes.c_int32(1)),
                   ctypes.byref(ctypes.c_int32(1)), ctypes.byref(ctypes.c_int32(s.mtype)),
                   ctypes.byref(ctypes.c_int32(phase_id)), ctypes.byref(ctypes.c_int32(len(ia) - 1)),
                   data.ctypes.data_as(real), ia.ctypes.data_as(i32), ja.ctypes.data_as(i32),
                   s.perm.ctypes.data_as(i32), ctypes.byref(ctypes.c_int32(1 if b.ndim == 1 else b.shape[1])),
                   s.iparm.ctypes.data_as(i32), ctypes.byref(ctypes.c_int32(s.msglvl)),
                   b.ctypes.data_as(real), x.ctypes.data_as(real), ctypes.byref(err))
    if err.value != 0:
        from pypardiso.pardiso_wrapper import PyPardisoError

        raise PyPardisoError(err.value)
    return np.ascontiguousarray(x)


def factorize(A: sp.spmatrix, kind: str = "auto", precision: str | None = "double",
              condense: np.ndarray | None = None):
    """Factorize ``A`` with the chosen backend and precision ("double", "single", or None for
    :func:`resolve_precision`'s choice); returns an object with ``solve(b)`` (in double either way).
    ``condense``: indices of unknowns whose block of ``A`` is diagonal, eliminated before a SuperLU
    factorization (static condensation, see the module docstring; PARDISO ignores it)."""
    kind = resolve(kind, A.shape[0])
    single = resolve_precision(precision, kind) == "single"
    STATS["factorizations"] += 1
    # charged to the active profile (solver.profiling) as numeric factorization, except PARDISO's symbolic
    # analysis of a new pattern; SuperLU orders and factorizes in one call, all charged as numeric
    with phase("numeric_factorization"):
        return _Pardiso(A, single) if kind == "pypardiso" else _SuperLU(A, single, condense)
