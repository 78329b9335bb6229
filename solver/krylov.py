"""Right-preconditioned GMRES for the Newton–Krylov option (run option ``newton_krylov``).

Solves A x = b for the Newton update with the exact Jacobian A, preconditioned by a kept factorization M⁻¹ of an
earlier Jacobian (Saad 2003, Iterative Methods for Sparse Linear Systems, Alg. 9.5, right preconditioning).  With
right preconditioning the Arnoldi residual is the true residual ‖b − A x‖, so the stopping test reads the linear
residual itself: the inexact Newton condition ‖A x − b‖ ≤ η ‖b‖ of Dembo, Eisenstat and Steihaug (1982).
Unitless: the units are those of A and b.
"""
from __future__ import annotations

import numpy as np

__all__ = ["gmres"]


def gmres(matvec, precond, b: np.ndarray, rtol: float, maxiter: int) -> tuple[np.ndarray | None, int]:
    """x with ‖b − A x‖ ≤ ``rtol`` ‖b‖ from a zero start, or None when ``maxiter`` iterations do not reach
    it; returns (x, iterations).  ``matvec(v)`` = A v, ``precond(v)`` ≈ A⁻¹ v (the kept factors)."""
    nb = float(np.linalg.norm(b))
    if nb == 0.0:
        return np.zeros_like(b), 0
    V = [b / nb]
    Z = []
    H = np.zeros((maxiter + 1, maxiter))
    e1 = np.zeros(maxiter + 1)
    e1[0] = nb
    for k in range(maxiter):
        z = precond(V[k])
        if not np.all(np.isfinite(z)):
            return None, k + 1
        Z.append(z)
        w = matvec(z)
        for i in range(k + 1):  # modified Gram-Schmidt
            H[i, k] = float(V[i] @ w)
            w = w - H[i, k] * V[i]
        H[k + 1, k] = float(np.linalg.norm(w))
        y, *_ = np.linalg.lstsq(H[:k + 2, :k + 1], e1[:k + 2], rcond=None)
        res = float(np.linalg.norm(e1[:k + 2] - H[:k + 2, :k + 1] @ y))
        if res <= rtol * nb or H[k + 1, k] <= 1e-14 * nb:
            return np.column_stack(Z) @ y, k + 1
        V.append(w / H[k + 1, k])
    return None, maxiter
