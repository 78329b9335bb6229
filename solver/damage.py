"""Cohesive phase-field damage with damage viscosity and irreversibility.

Discrete problem (Eq. fracture_equation, backward Euler, test function r):

  R_a(d) = m_a [β (d_a − d_n,a)/Δt + 3G_c/(8 l_d) + g'(d_a) ψ̄_A,a] + (3 G_c l_d / 4) (K d)_a

with the variational-inequality constraints d_n <= d <= 1 (irreversibility
ḋ >= 0 and the upper bound): R_a >= 0 where d_a = d_n,a, R_a <= 0 where
d_a = 1, R_a = 0 in between.  K is the P1 stiffness, m_a the lumped mass and
ψ̄_A the lumped projection of the element active energy; the zeroth-order
terms use vertex quadrature so that the constraint acts node by node.

The bounds are enforced exactly by a primal-dual active-set (semismooth
Newton) method on the complementarity function Φ(d) = d − mid(lb, d − c R, ub),
c = 1/diag(J) (Hintermüller, Ito & Kunisch 2002; Hu et al. 2020): each
iteration fixes the predicted active nodes at their bound and takes a Newton
step on the others; it stops when the active set no longer changes and the
KKT residual ‖Φ‖∞ is below tolerance.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from . import fem, physics


@dataclass(frozen=True)
class DamageOperators:
    """Mesh operators of the damage problem: stiffness K (N, N) and lumped mass (N,) mm²."""

    K: sp.csr_matrix
    lumped_mass: np.ndarray


def damage_operators(points: np.ndarray, triangles: np.ndarray) -> DamageOperators:
    K = fem.stiffness_matrix(points, triangles)
    m = np.asarray(fem.mass_matrix(points, triangles, lumped=True).diagonal())
    return DamageOperators(K=K, lumped_mass=m)


@dataclass(frozen=True)
class DamageResult:
    d: np.ndarray
    iterations: int
    kkt_residual: float
    converged: bool


def residual(d, d_n, psi_a, params, dt: float, ops: DamageOperators) -> np.ndarray:
    """Damage residual R(d) (kPa·mm² per node) for nodal ψ̄_A (kPa)."""
    Gc, ld, beta = params.fracture_toughness, params.l_d, params.damage_viscosity
    local = beta * (d - d_n) / dt + 3 * Gc / (8 * ld) + physics.degradation_prime(d, params.m) * psi_a
    return ops.lumped_mass * local + (0.75 * Gc * ld) * (ops.K @ d)


def jacobian(d, psi_a, params, dt: float, ops: DamageOperators) -> sp.csr_matrix:
    Gc, ld, beta = params.fracture_toughness, params.l_d, params.damage_viscosity
    diag = ops.lumped_mass * (beta / dt + physics.degradation_second(d, params.m) * psi_a)
    return (0.75 * Gc * ld) * ops.K + sp.diags(diag)


def kkt_residual(d, R, lb, ub, c) -> float:
    """‖d − mid(lb, d − c R, ub)‖∞: zero exactly at a KKT point."""
    return float(np.max(np.abs(d - np.clip(d - c * R, lb, ub)))) if len(d) else 0.0


def _symmetric_solve(A: sp.spmatrix, b: np.ndarray) -> np.ndarray:
    """Solve A x = b for the symmetric damage block A (a principal submatrix of K-scaled stiffness plus a diagonal).

    First Jacobi-preconditioned conjugate gradients (:func:`_jacobi_cg`): where β/Δt + g''(d) ψ_A > 0 the block
    is symmetric positive definite, and with the damage viscosity its lumped-mass diagonal β/Δt dominates the
    gradient term 0.75 G_c l_d K, so CG converges in a few iterations.  If it does not reach a relative residual
    of 1e-12 (a block that is not positive definite, or poorly conditioned without viscosity), SuperLU in
    symmetric mode (minimum degree on Aᵀ+A, diagonal pivots); a solve whose relative residual then exceeds 1e-10
    is repeated with partial pivoting (COLAMD, threshold 1).
    """
    x = _jacobi_cg(A, b)
    if x is not None:
        return x
    A = A.tocsc()  # SuperLU's format, made only when it is needed
    x = spla.splu(A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options=dict(SymmetricMode=True)).solve(b)
    nb = max(np.linalg.norm(b), 1e-300)
    if not np.all(np.isfinite(x)) or np.linalg.norm(A @ x - b) > 1e-10 * nb:
        x = spla.splu(A, permc_spec="COLAMD", diag_pivot_thresh=1.0).solve(b)
    return x


def _jacobi_cg(A: sp.spmatrix, b: np.ndarray, rtol: float = 1e-12, max_its: int = 100) -> np.ndarray | None:
    """Conjugate gradients with the diagonal as preconditioner, to ‖b − A x‖ <= rtol ‖b‖; None when the diagonal
    is not positive, a direction of non-positive curvature appears (A not positive definite) or ``max_its``
    iterations do not reach the tolerance."""
    diag = A.diagonal()
    if not np.all(diag > 0):
        return None
    A = A.tocsr()
    inv = 1.0 / diag
    target = rtol * max(np.linalg.norm(b), 1e-300)
    x = inv * b
    r = b - A @ x
    z = inv * r
    p = z.copy()
    rz = r @ z
    for _ in range(max_its):
        if np.linalg.norm(r) <= target:
            return x
        Ap = A @ p
        curvature = p @ Ap
        if not curvature > 0:
            return None
        alpha = rz / curvature
        x += alpha * p
        r -= alpha * Ap
        z = inv * r
        rz, rz_old = r @ z, rz
        p = z + (rz / rz_old) * p
    return x if np.linalg.norm(r) <= target else None


def solve(d_start, d_n, psi_a, params, dt: float, ops: DamageOperators, tol: float = 1e-10, max_its: int = 50) -> DamageResult:
    """Solve the damage variational inequality d_n <= d <= 1 (all nodal, dimensionless).

    ``d_start`` is the initial guess (clipped into the bounds), ``psi_a`` the nodal
    active energy (kPa), ``dt`` the time step (s).
    """
    lb = np.asarray(d_n, float)
    ub = np.ones_like(lb)
    d = np.clip(np.asarray(d_start, float), lb, ub)
    prev_active = None
    for it in range(1, max_its + 1):
        R = residual(d, d_n, psi_a, params, dt, ops)
        J = jacobian(d, psi_a, params, dt, ops).tocsr()
        c = 1.0 / np.abs(J.diagonal())
        trial = d - c * R
        lo = trial <= lb
        up = trial >= ub
        inactive = ~(lo | up)
        err = kkt_residual(d, R, lb, ub, c)
        active = (lo, up)
        if err < tol and prev_active is not None and np.array_equal(prev_active[0], lo) and np.array_equal(prev_active[1], up):
            return DamageResult(d, it - 1, err, True)
        if err < tol and prev_active is None and not inactive.any():
            return DamageResult(d, it - 1, err, True)
        prev_active = active
        delta = np.zeros_like(d)
        delta[lo] = lb[lo] - d[lo]
        delta[up] = ub[up] - d[up]
        if inactive.any():
            I = np.flatnonzero(inactive)
            rhs = -R[I] - (J @ delta)[I]  # delta is zero on the inactive nodes
            delta[I] = _symmetric_solve(J[I][:, I], rhs)
        d = d + delta
        if err < tol and np.max(np.abs(delta)) < tol:
            R = residual(d, d_n, psi_a, params, dt, ops)
            err = kkt_residual(d, R, lb, ub, c)
            return DamageResult(d, it, err, err < 10 * tol)
    R = residual(d, d_n, psi_a, params, dt, ops)
    J = jacobian(d, psi_a, params, dt, ops)
    err = kkt_residual(d, R, lb, ub, 1.0 / np.abs(J.diagonal()))
    return DamageResult(d, max_its, err, err < tol)
