"""Vectorized forward-mode automatic differentiation (dual numbers), sparse in the inputs.

The coupled residual of the model is written point-wise at quadrature points
as functions of the field values and gradients there (see ``solver.physics``).
Evaluating those functions on :class:`Dual` numbers gives, in the same pass,
their exact derivatives with respect to every point-wise input, from which
``solver.fem.assemble_forms`` builds the exact Newton Jacobian.  No derivative
is written by hand, so none can be forgotten when a term is added; the Taylor
test in ``tests/test_jacobian.py`` proves the result.

A Dual holds a value array ``v`` of any shape ``S`` and the derivatives with
respect to the inputs it actually depends on: ``idx`` (sorted tuple of input
slots) and ``dd`` of shape ``S + (len(idx),)``.  ``d`` gives the dense
derivative ``S + (nvar,)``.  Why sparse: the coupled model has 21 inputs per
point (7 fields x value and 2 gradient components) but most intermediate
quantities depend on a few (a strain on 4, the porosity on 3, a constant on
none); carrying only those cut the Jacobian assembly time about 2x at
h = 2 mm.  Binary operations work on the union of the two index sets (the
index bookkeeping is cached: the same few sets recur at every call).
All operations broadcast like numpy over ``S``.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np


@lru_cache(maxsize=4096)
def _union(ia: tuple, ib: tuple):
    """Union of two sorted index tuples and the positions of each in it (slices when contiguous)."""
    u = tuple(sorted(set(ia) | set(ib)))
    pos = {k: n for n, k in enumerate(u)}
    return u, _positions([pos[k] for k in ia]), _positions([pos[k] for k in ib])


def _positions(p: list):
    if not p:
        return slice(0, 0)
    if p == list(range(p[0], p[0] + len(p))):
        return slice(p[0], p[0] + len(p))
    return np.asarray(p)


def _scatter(dd, pos, shape, n: int) -> np.ndarray:
    """Derivative slots ``dd`` placed at positions ``pos`` of ``n`` slots (zeros elsewhere)."""
    out = np.zeros(shape + (n,))
    out[..., pos] = dd
    return out


def _combine(a, ca, b, cb, shape):
    """Derivative slots of ca * a + cb * b (ca, cb: value-shaped factors or None for 1) on the union of slots."""
    da = a.dd if ca is None else a.dd * ca[..., None]
    db = b.dd if cb is None else b.dd * cb[..., None]
    if a.idx == b.idx:
        return a.idx, da + db
    u, pa, pb = _union(a.idx, b.idx)
    if isinstance(pa, slice) and isinstance(pb, slice) and (pa.stop == pb.start or pb.stop == pa.start):
        # disjoint, one set entirely before the other (the common case): one concatenation, no scatter
        parts = (da, db) if pa.start == 0 else (db, da)
        return u, np.concatenate([np.broadcast_to(x, shape + x.shape[-1:]) for x in parts], axis=-1)
    out = _scatter(da, pa, shape, len(u))
    out[..., pb] += db
    return u, out


class Dual:
    """A value with its gradient with respect to ``nvar`` independent inputs (stored sparsely)."""

    __slots__ = ("v", "dd", "idx", "nv")
    __array_priority__ = 1000
    __array_ufunc__ = None  # ndarray (op) Dual defers to Dual's reflected operators

    def __init__(self, v, d, idx: tuple | None = None, nvar: int | None = None):
        """``Dual(v, d)``: dense derivative ``d`` (S + (nvar,)); or ``d`` on the slots ``idx`` of ``nvar`` inputs."""
        self.v = v
        self.dd = d
        if idx is None:
            nvar = d.shape[-1]
            idx = tuple(range(nvar))
        self.idx = idx
        self.nv = nvar

    # -- construction -----------------------------------------------------
    @staticmethod
    def variables(values) -> list["Dual"]:
        """Independent variables from ``values`` of shape ``S + (nvar,)``, or a list of ``nvar`` arrays
        (each its own shape, broadcastable against the others: e.g. per-element and per-point inputs).

        Returns ``nvar`` Duals; the k-th has unit derivative in slot k.
        """
        cols = [values[..., k] for k in range(values.shape[-1])] if isinstance(values, np.ndarray) else list(values)
        one = np.ones((1,) * (np.ndim(cols[0]) + 1))
        return [Dual(v, np.broadcast_to(one, np.shape(v) + (1,)), (k,), len(cols)) for k, v in enumerate(cols)]

    def _new(self, v, dd, idx=None):
        return Dual(v, dd, self.idx if idx is None else idx, self.nv)

    @property
    def nvar(self) -> int:
        return self.nv

    @property
    def d(self) -> np.ndarray:
        """Dense derivative, shape ``v.shape + (nvar,)``."""
        if len(self.idx) == self.nv:
            return np.broadcast_to(self.dd, np.shape(self.v) + (self.nv,))
        return _scatter(self.dd, list(self.idx), np.shape(self.v), self.nv)

    # -- arithmetic -------------------------------------------------------
    def __add__(self, o):
        if isinstance(o, Dual):
            v = self.v + o.v
            idx, dd = _combine(self, None, o, None, v.shape)
            return self._new(v, dd, idx)
        return self._new(self.v + o, self.dd)

    __radd__ = __add__

    def __sub__(self, o):
        if isinstance(o, Dual):
            v = self.v - o.v
            idx, dd = _combine(self, None, -o, None, v.shape)
            return self._new(v, dd, idx)
        return self._new(self.v - o, self.dd)

    def __rsub__(self, o):
        return self._new(o - self.v, -self.dd)

    def __neg__(self):
        return self._new(-self.v, -self.dd)

    def __mul__(self, o):
        if isinstance(o, Dual):
            v = self.v * o.v
            idx, dd = _combine(self, np.broadcast_to(o.v, v.shape), o, np.broadcast_to(self.v, v.shape), v.shape)
            return self._new(v, dd, idx)
        o = np.asarray(o)
        return self._new(self.v * o, self.dd * o[..., None] if o.ndim else self.dd * o)

    __rmul__ = __mul__

    def __truediv__(self, o):
        if isinstance(o, Dual):
            inv = 1.0 / o.v
            v = self.v * inv
            shape = np.shape(v)
            idx, dd = _combine(self, np.broadcast_to(inv, shape), o, -np.broadcast_to(v * inv, shape), shape)
            return self._new(v, dd, idx)
        o = np.asarray(o, dtype=float)
        return self * (1.0 / o)

    def __rtruediv__(self, o):
        inv = 1.0 / self.v
        v = o * inv
        return self._new(v, -self.dd * (v * inv)[..., None])

    def __pow__(self, n):
        if n == 2:
            return self * self
        if n == 3:
            return self * self * self
        v = self.v**n
        return self._new(v, self.dd * (n * self.v ** (n - 1))[..., None])

    def __getitem__(self, idx):
        if not isinstance(idx, tuple):
            idx = (idx,)
        dd = np.broadcast_to(self.dd, np.shape(self.v) + (len(self.idx),))
        return self._new(self.v[idx], dd[idx + (slice(None),)])

    def __repr__(self) -> str:  # pragma: no cover - debugging aid
        return f"Dual(v.shape={np.shape(self.v)}, slots={len(self.idx)}/{self.nv})"


def value(x):
    """Value part of a Dual or plain array."""
    return x.v if isinstance(x, Dual) else x


def sqrt(x: Dual) -> Dual:
    s = np.sqrt(x.v)
    with np.errstate(divide="ignore", invalid="ignore"):
        fac = np.where(s > 0, 0.5 / np.where(s > 0, s, 1.0), 0.0)
    return x._new(s, x.dd * fac[..., None])


def where(cond: np.ndarray, a, b) -> Dual:
    """Element-wise choice; the derivative follows the chosen branch."""
    a = as_dual_like(a, b)
    b = as_dual_like(b, a)
    v = np.where(cond, a.v, b.v)
    shape = v.shape
    c = np.asarray(cond)[..., None]
    if a.idx == b.idx:
        return a._new(v, np.where(c, a.dd, b.dd))
    u, pa, pb = _union(a.idx, b.idx)
    return a._new(v, np.where(c, _scatter(a.dd, pa, shape, len(u)), _scatter(b.dd, pb, shape, len(u))), u)


def positive_part(x: Dual) -> Dual:
    """Macaulay bracket <x> = max(x, 0) (derivative 0 at x <= 0)."""
    return where(x.v > 0, x, 0.0)


def as_dual_like(x, ref):
    """Promote a constant to a Dual with zero derivative (no slots) shaped like ``ref``."""
    if isinstance(x, Dual):
        return x
    if not isinstance(ref, Dual):
        raise TypeError("where() needs at least one Dual argument")
    v = np.broadcast_to(np.asarray(x, dtype=float), ref.v.shape)
    return Dual(v, np.zeros(ref.v.shape + (0,)), (), ref.nv)


def clip(x: Dual, lo: float, hi: float) -> Dual:
    """Clip to [lo, hi]; derivative zero outside."""
    return where(x.v < lo, lo, where(x.v > hi, hi, x))
