"""The Jacobian tracer: the point-wise forms recorded on symbols as one expression graph, and its exact derivatives.

The first two steps of the compiled assembly (:mod:`solver.codegen` generates the kernel source from what they give).

1. *Trace*: :class:`Sym` is a scalar symbol that goes through the numpy branch of the physics
   (arithmetic, ``np.where``, ``np.sqrt``, ``np.maximum``, ``np.clip``, comparisons, ``&``, ``~``);
   every operation adds a node to a hash-consed DAG (:class:`Tracer`).  Python floats met on the
   way (parameters, ``dt``, literals of the laws) become entries of a constants array, never
   literals of the kernel: one compiled kernel serves every parameter set of the same structure.
   Structural Python branches (``if kap > 0``, ``n_fields == 7``) give different graphs, hence
   different kernels.  A Python branch on a symbol raises (it would bake one side in).
2. *Differentiate* (:func:`derivatives`): forward mode on the DAG with respect to the point-wise input slots
   (slot = 3 field + l, l = 0 value, 1, 2 gradient component, as :func:`solver.fem.qp_inputs`),
   sparse (each node keeps only the slots it depends on), with the conventions of
   :mod:`solver.ad`: ``where`` follows the chosen branch, max(x, 0) has derivative 0 at x <= 0,
   clip has derivative 1 on [lo, hi] inclusive, sqrt has derivative 0 at 0.

Values are those of the model (units mm, s, kPa); the graph holds no unit of its own.
"""
from __future__ import annotations

import hashlib

import numpy as np

__all__ = ["Sym", "Tracer", "derivatives", "CMP"]

#: comparison nodes and the Python operator that the generated source writes for each
CMP = {"lt": "<", "le": "<=", "gt": ">", "ge": ">="}
_BOOL = frozenset(("lt", "le", "gt", "ge", "and", "or", "not"))


# ---------------------------------------------------------------- symbols and the graph
class Sym:
    """A scalar node of the traced graph (a value at one point of one element).

    ``level``: 0 constant, 1 constant on the element, 2 varies with the quadrature point
    (``grp`` is then the quadrature group whose points it lives on).
    """

    __slots__ = ("tr", "id", "op", "args", "arg", "level", "grp")
    __array_priority__ = 1000

    def __init__(self, tr, nid, op, args, arg, level, grp):
        self.tr, self.id, self.op, self.args, self.arg, self.level, self.grp = tr, nid, op, args, arg, level, grp

    @property
    def is_bool(self) -> bool:
        return self.op in _BOOL

    # arithmetic (python floats on either side become constants of the trace)
    def __add__(self, o):
        return self.tr.add(self, o)

    def __radd__(self, o):
        return self.tr.add(o, self)

    def __sub__(self, o):
        return self.tr.sub(self, o)

    def __rsub__(self, o):
        return self.tr.sub(o, self)

    def __mul__(self, o):
        return self.tr.mul(self, o)

    def __rmul__(self, o):
        return self.tr.mul(o, self)

    def __truediv__(self, o):
        return self.tr.div(self, o)

    def __rtruediv__(self, o):
        return self.tr.div(o, self)

    def __neg__(self):
        return self.tr.neg(self)

    def __pos__(self):
        return self

    def __pow__(self, n):
        return self.tr.pow(self, n)

    # comparisons and boolean masks (the numpy branch of the physics: v < phi_star, below & ~closed)
    def __lt__(self, o):
        return self.tr.cmp("lt", self, o)

    def __le__(self, o):
        return self.tr.cmp("le", self, o)

    def __gt__(self, o):
        return self.tr.cmp("gt", self, o)

    def __ge__(self, o):
        return self.tr.cmp("ge", self, o)

    def __and__(self, o):
        return self.tr.logic("and", self, o)

    __rand__ = __and__

    def __or__(self, o):
        return self.tr.logic("or", self, o)

    __ror__ = __or__

    def __invert__(self):
        return self.tr.logic("not", self)

    def __getitem__(self, idx):
        # broadcasting views of per-element arrays (phi0[:, None]) are the same scalar at a point
        idx = idx if isinstance(idx, tuple) else (idx,)
        if all(i is None or (isinstance(i, slice) and i == slice(None)) for i in idx):
            return self
        raise TypeError(f"traced value indexed with {idx!r}: only broadcasting views ([:, None]) are point-wise")

    def __bool__(self):
        raise TypeError("a Python branch on a traced (point-wise) value: use np.where, or branch on parameters only")

    def __array_ufunc__(self, ufunc, method, *inputs, **kwargs):
        f = _UFUNCS.get(ufunc.__name__)
        if method != "__call__" or kwargs or f is None:
            return NotImplemented
        return f(self.tr, *inputs)

    def __array_function__(self, func, types, args, kwargs):
        if func is np.where and not kwargs and len(args) == 3:
            return self.tr.where(*args)
        if func is np.clip and not kwargs and len(args) == 3:
            return self.tr.clip(*args)
        return NotImplemented

    def __repr__(self) -> str:  # pragma: no cover - debugging aid
        return f"Sym#{self.id}({self.op}, level {self.level})"


_UFUNCS = {
    "add": lambda t, a, b: t.add(a, b),
    "subtract": lambda t, a, b: t.sub(a, b),
    "multiply": lambda t, a, b: t.mul(a, b),
    "divide": lambda t, a, b: t.div(a, b),
    "true_divide": lambda t, a, b: t.div(a, b),
    "negative": lambda t, a: t.neg(a),
    "positive": lambda t, a: t.lift(a),
    "square": lambda t, a: t.mul(a, a),
    "power": lambda t, a, n: t.pow(a, n),
    "sqrt": lambda t, a: t.sqrt(a),
    # max(x, y) as where(x > y, x, y): the Dual convention (ad.positive_part) at a tie, derivative of y
    "maximum": lambda t, a, b: t.where(t.cmp("gt", a, b), a, b),
    "minimum": lambda t, a, b: t.where(t.cmp("lt", a, b), a, b),
    "less": lambda t, a, b: t.cmp("lt", a, b),
    "less_equal": lambda t, a, b: t.cmp("le", a, b),
    "greater": lambda t, a, b: t.cmp("gt", a, b),
    "greater_equal": lambda t, a, b: t.cmp("ge", a, b),
    "logical_and": lambda t, a, b: t.logic("and", a, b),
    "bitwise_and": lambda t, a, b: t.logic("and", a, b),
    "logical_or": lambda t, a, b: t.logic("or", a, b),
    "bitwise_or": lambda t, a, b: t.logic("or", a, b),
    "logical_not": lambda t, a: t.logic("not", a),
    "invert": lambda t, a: t.logic("not", a),
}


class Tracer:
    """A hash-consed expression graph being recorded, with its constants.

    Node kinds: ``in`` (input slot; value slots per quadrature group, gradient slots per element),
    ``data`` (a per-element or per-point array of the step data), ``c`` (a float met while tracing:
    entry of the constants array, never merged with another so the structure does not depend on
    values), ``lit`` (a literal of the derivative rules: 0, 1, n), and the operations.
    """

    def __init__(self):
        self.nodes: list[Sym] = []
        self.keys: list[tuple] = []  # structural record of every node (the signature of the trace)
        self.constants: list[float] = []
        self._table: dict = {}
        self.data_names: list[tuple] = []  # (name, per_point) in order of first use

    # -- leaves ------------------------------------------------------------
    def _node(self, op, args=(), arg=None, level=None, grp=None):
        key = (op, tuple(a.id for a in args), arg)
        n = self._table.get(key)
        if n is not None:
            return n
        if level is None:
            level = max((a.level for a in args), default=0)
            grps = {a.grp for a in args if a.level == 2}
            if len(grps) > 1:
                raise ValueError("a traced expression mixes points of two quadrature rules")
            grp = grps.pop() if grps else None
        n = Sym(self, len(self.nodes), op, args, arg, level, grp)
        self.nodes.append(n)
        self.keys.append(key)
        self._table[key] = n
        return n

    def inputs(self, group: int, n_fields: int) -> list[Sym]:
        """Input symbols ``X[3 f + l]`` at the points of quadrature ``group`` (gradients: per element)."""
        return [self._node("in", (), (s, group), 2, group) if s % 3 == 0 else self._node("in", (), (s, None), 1)
                for s in range(3 * n_fields)]

    def data(self, name: str, per_point: bool) -> Sym:
        """A step-data array (M,) (per element) or (M, nq) (per point of quadrature group 0)."""
        if (name, per_point) not in self.data_names:
            self.data_names.append((name, per_point))
        return self._node("data", (), name, 2 if per_point else 1, 0 if per_point else None)

    def const(self, x) -> Sym:
        j = len(self.constants)
        self.constants.append(float(x))
        return self._node("c", (), j, 0)

    def lit(self, x: float) -> Sym:
        return self._node("lit", (), float(x), 0)

    def lift(self, x) -> Sym:
        if isinstance(x, Sym):
            return x
        if isinstance(x, (bool, np.bool_)):
            raise TypeError("boolean constant in a traced expression")
        if isinstance(x, (int, float, np.number)) or (isinstance(x, np.ndarray) and x.ndim == 0):
            return self.const(x)
        raise TypeError(f"cannot trace {type(x).__name__} {np.shape(x)} as a point-wise scalar (only floats and symbols)")

    # -- operations (simplified on literals only: constants may change value, literals never do) --------
    @staticmethod
    def _is(n: Sym, v: float) -> bool:
        return n.op == "lit" and n.arg == v

    def add(self, a, b):
        a, b = self.lift(a), self.lift(b)
        if self._is(a, 0.0):
            return b
        if self._is(b, 0.0):
            return a
        return self._node("add", (a, b))

    def sub(self, a, b):
        a, b = self.lift(a), self.lift(b)
        if self._is(b, 0.0):
            return a
        if self._is(a, 0.0):
            return self.neg(b)
        return self._node("sub", (a, b))

    def mul(self, a, b):
        a, b = self.lift(a), self.lift(b)
        if self._is(a, 1.0):
            return b
        if self._is(b, 1.0):
            return a
        if self._is(a, -1.0):
            return self.neg(b)
        if self._is(b, -1.0):
            return self.neg(a)
        return self._node("mul", (a, b))

    def div(self, a, b):
        a, b = self.lift(a), self.lift(b)
        if self._is(b, 1.0):
            return a
        return self._node("div", (a, b))

    def neg(self, a):
        a = self.lift(a)
        if a.op == "neg":
            return a.args[0]
        if a.op == "lit":
            return self.lit(-a.arg)
        return self._node("neg", (a,))

    def pow(self, a, n):
        if isinstance(n, Sym) or float(n) != int(n):
            raise TypeError("only integer powers of traced values are supported")
        n = int(n)
        a = self.lift(a)
        # x**2 and x**3 as products, as ad.Dual does (exact same rounding as numpy's x**2)
        if n == 1:
            return a
        if n == 2:
            return self.mul(a, a)
        if n == 3:
            return self.mul(self.mul(a, a), a)
        return self._node("pow", (a,), n)

    def sqrt(self, a):
        return self._node("sqrt", (self.lift(a),))

    def cmp(self, op, a, b):
        return self._node(op, (self.lift(a), self.lift(b)))

    def logic(self, op, a, b=None):
        args = (a,) if b is None else (a, b)
        if not all(isinstance(x, Sym) and x.is_bool for x in args):
            raise TypeError(f"'{op}' of traced values needs traced boolean masks")
        return self._node(op, args)

    def where(self, c, a, b):
        if not (isinstance(c, Sym) and c.is_bool):
            raise TypeError("np.where on traced values needs a traced condition")
        a, b = self.lift(a), self.lift(b)
        if a is b:
            return a
        return self._node("where", (c, a, b))

    def clip(self, x, lo, hi):
        """np.clip as ad.clip: where(x < lo, lo, where(x > hi, hi, x)) (derivative 1 on [lo, hi])."""
        x, lo, hi = self.lift(x), self.lift(lo), self.lift(hi)
        return self.where(self.cmp("lt", x, lo), lo, self.where(self.cmp("gt", x, hi), hi, x))

    def signature(self, outputs) -> str:
        """Hash of the graph's structure and of which nodes are the outputs (not of the constants' values)."""
        h = hashlib.sha256(repr(self.keys).encode())
        h.update(repr([[[None if c is None else c.id for c in row] for row in F] for F, _ in outputs]).encode())
        return h.hexdigest()


def derivatives(tr: Tracer, roots: list[Sym]) -> dict:
    """``{node id: {slot: derivative node}}`` for every node the ``roots`` depend on (zero = absent)."""
    need = set()
    stack = list(roots)
    while stack:
        n = stack.pop()
        if n.id not in need:
            need.add(n.id)
            stack.extend(n.args)
    D: dict = {}
    one = tr.lit(1.0)
    zero = tr.lit(0.0)
    for n in list(tr.nodes):  # creation order is topological; derivative nodes are appended behind
        if n.id not in need:
            continue
        op, a = n.op, n.args
        if op == "in":
            D[n.id] = {n.arg[0]: one}
            continue
        if op in ("c", "lit", "data") or n.is_bool:
            D[n.id] = {}
            continue
        da = D[a[0].id] if op != "where" else D[a[1].id]
        if op in ("add", "sub"):
            db = D[a[1].id]
            out = dict(da)
            for s, d in db.items():
                out[s] = (tr.add if op == "add" else tr.sub)(out[s], d) if s in out else (d if op == "add" else tr.neg(d))
        elif op == "neg":
            out = {s: tr.neg(d) for s, d in da.items()}
        elif op == "mul":
            db = D[a[1].id]
            out = {s: tr.mul(d, a[1]) for s, d in da.items()}
            for s, d in db.items():
                t = tr.mul(a[0], d)
                out[s] = tr.add(out[s], t) if s in out else t
        elif op == "div":
            # y = a/b: dy = da (1/b) - db (y/b), the factors of ad.Dual.__truediv__
            db = D[a[1].id]
            rinv = tr.div(one, a[1]) if da or db else None
            out = {s: tr.mul(d, rinv) for s, d in da.items()}
            if db:
                fac = tr.mul(n, rinv)
                for s, d in db.items():
                    t = tr.mul(d, fac)
                    out[s] = tr.sub(out[s], t) if s in out else tr.neg(t)
        elif op == "pow":
            fac = tr.mul(tr.lit(n.arg), tr.pow(a[0], n.arg - 1)) if da else None
            out = {s: tr.mul(d, fac) for s, d in da.items()}
        elif op == "sqrt":
            fac = tr._node("sqrtfac", (n,)) if da else None  # 0.5/√x, 0 at x = 0 (ad.sqrt)
            out = {s: tr.mul(d, fac) for s, d in da.items()}
        elif op == "where":
            dA, dB = D[a[1].id], D[a[2].id]
            out = {s: tr.where(a[0], dA.get(s, zero), dB.get(s, zero)) for s in sorted(set(dA) | set(dB))}
        else:  # pragma: no cover - every op of Tracer is listed above
            raise NotImplementedError(op)
        D[n.id] = out
    return D
