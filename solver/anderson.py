"""Anderson acceleration of the Newton iteration with a reused (stale) Jacobian.

With a reused factorization J0 the Newton iteration is the fixed-point iteration
x <- g(x) = x + dx(x), dx(x) = -J0^{-1} R(x), which converges linearly.  Anderson acceleration (type II,
Walker and Ni 2011, SIAM J. Numer. Anal. 49: 1715) takes the next iterate as the combination of the last
``depth`` + 1 values of g whose fixed-point residuals dx combine to the smallest (scaled) norm:

    gamma = argmin || f_k - dF gamma ||,   x_{k+1} = g(x_k) - dG gamma,

with dF, dG the differences of successive residuals f = dx and values g.  It costs vector operations only
(no residual, factorization or substitution).  The Newton test is unchanged: it measures dx(x_k), the
update of the plain iteration at the current iterate, so the converged state meets the same tolerance.
The history is cleared whenever the Jacobian is refreshed (the map g changes with J0).

Residuals are compared in scaled variables (each field divided by the scale of the Newton test), since
the fields' units differ by orders of magnitude (mm, kPa, -).
"""
from __future__ import annotations

import numpy as np

__all__ = ["Anderson"]


class Anderson:
    """History of a fixed-point iteration and its accelerated next iterate; ``depth`` >= 1."""

    def __init__(self, depth: int):
        if depth < 1:
            raise ValueError(f"depth={depth!r}: must be an integer >= 1")
        self.depth = depth
        self.reset()

    def reset(self) -> None:
        """Forget the history (the map changed: a new Jacobian)."""
        self.f_prev, self.g_prev = None, None
        self.dF: list[np.ndarray] = []
        self.dG: list[np.ndarray] = []

    def next_iterate(self, x: np.ndarray, dx: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """The accelerated iterate after x with plain update dx; ``weights`` scale each entry of the
        residual (1 / the field's scale), x and dx flat arrays of equal length."""
        f, g = dx * weights, x + dx
        if self.f_prev is not None:
            self.dF.append(f - self.f_prev)
            self.dG.append(g - self.g_prev)
            if len(self.dF) > self.depth:
                self.dF.pop(0)
                self.dG.pop(0)
        self.f_prev, self.g_prev = f, g
        if not self.dF:
            return g
        F = np.column_stack(self.dF)
        gamma, *_ = np.linalg.lstsq(F, f, rcond=1e-10)
        return g - np.column_stack(self.dG) @ gamma
