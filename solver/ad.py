"""Vectorized forward-mode automatic differentiation (dual numbers).

The coupled residual of the model is written point-wise at quadrature points
as functions of the field values and gradients there (see ``solver.physics``).
Evaluating those functions on :class:`Dual` numbers gives, in the same pass,
their exact derivatives with respect to every point-wise input, from which
``solver.fem.assemble_forms`` builds the exact Newton Jacobian.  No derivative
is written by hand, so none can be forgotten when a term is added; the Taylor
test in ``tests/test_jacobian.py`` proves the result.

A Dual holds a value array ``v`` of any shape ``S`` and a derivative array
``d`` of shape ``S + (nvar,)``.  All operations broadcast like numpy over
``S``; ``nvar`` is the number of independent inputs.
"""
from __future__ import annotations

import numpy as np


class Dual:
    """A value with its gradient with respect to ``nvar`` independent inputs."""

    __slots__ = ("v", "d")
    __array_priority__ = 1000
    __array_ufunc__ = None  # ndarray (op) Dual defers to Dual's reflected operators

    def __init__(self, v, d):
        self.v = v
        self.d = d

    # -- construction -----------------------------------------------------
    @staticmethod
    def variables(values: np.ndarray) -> list["Dual"]:
        """Independent variables from ``values`` of shape ``S + (nvar,)``.

        Returns ``nvar`` Duals; the k-th has unit derivative in slot k.
        """
        nvar = values.shape[-1]
        eye = np.eye(nvar)
        out = []
        for k in range(nvar):
            d = np.broadcast_to(eye[k], values.shape[:-1] + (nvar,))
            out.append(Dual(values[..., k], d))
        return out

    @property
    def nvar(self) -> int:
        return self.d.shape[-1]

    # -- arithmetic -------------------------------------------------------
    def __add__(self, o):
        if isinstance(o, Dual):
            return Dual(self.v + o.v, self.d + o.d)
        return Dual(self.v + o, self.d)

    __radd__ = __add__

    def __sub__(self, o):
        if isinstance(o, Dual):
            return Dual(self.v - o.v, self.d - o.d)
        return Dual(self.v - o, self.d)

    def __rsub__(self, o):
        return Dual(o - self.v, -self.d)

    def __neg__(self):
        return Dual(-self.v, -self.d)

    def __mul__(self, o):
        if isinstance(o, Dual):
            return Dual(self.v * o.v, self.d * o.v[..., None] + o.d * self.v[..., None])
        o = np.asarray(o)
        return Dual(self.v * o, self.d * o[..., None] if o.ndim else self.d * o)

    __rmul__ = __mul__

    def __truediv__(self, o):
        if isinstance(o, Dual):
            inv = 1.0 / o.v
            v = self.v * inv
            return Dual(v, (self.d - o.d * v[..., None]) * inv[..., None])
        o = np.asarray(o, dtype=float)
        return self * (1.0 / o)

    def __rtruediv__(self, o):
        inv = 1.0 / self.v
        v = o * inv
        return Dual(v, -self.d * (v * inv)[..., None])

    def __pow__(self, n):
        if n == 2:
            return self * self
        if n == 3:
            return self * self * self
        v = self.v**n
        return Dual(v, self.d * (n * self.v ** (n - 1))[..., None])

    def __getitem__(self, idx):
        if not isinstance(idx, tuple):
            idx = (idx,)
        return Dual(self.v[idx], self.d[idx + (slice(None),)])

    def __repr__(self) -> str:  # pragma: no cover - debugging aid
        return f"Dual(v.shape={np.shape(self.v)}, nvar={self.nvar})"


def value(x):
    """Value part of a Dual or plain array."""
    return x.v if isinstance(x, Dual) else x


def sqrt(x: Dual) -> Dual:
    s = np.sqrt(x.v)
    with np.errstate(divide="ignore", invalid="ignore"):
        fac = np.where(s > 0, 0.5 / np.where(s > 0, s, 1.0), 0.0)
    return Dual(s, x.d * fac[..., None])


def where(cond: np.ndarray, a, b) -> Dual:
    """Element-wise choice; the derivative follows the chosen branch."""
    a = as_dual_like(a, b)
    b = as_dual_like(b, a)
    return Dual(np.where(cond, a.v, b.v), np.where(cond[..., None], a.d, b.d))


def positive_part(x: Dual) -> Dual:
    """Macaulay bracket <x> = max(x, 0) (derivative 0 at x <= 0)."""
    return where(x.v > 0, x, 0.0)


def as_dual_like(x, ref):
    """Promote a constant to a Dual with zero derivative shaped like ``ref``."""
    if isinstance(x, Dual):
        return x
    if not isinstance(ref, Dual):
        raise TypeError("where() needs at least one Dual argument")
    v = np.broadcast_to(np.asarray(x, dtype=float), ref.v.shape)
    return Dual(v, np.zeros(ref.v.shape + (ref.nvar,)))


def clip(x: Dual, lo: float, hi: float) -> Dual:
    """Clip to [lo, hi]; derivative zero outside."""
    return where(x.v < lo, lo, where(x.v > hi, hi, x))
