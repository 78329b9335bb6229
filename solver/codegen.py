"""Compiled point-wise physics generated from the one definition of the weak form (optional: numba).

The coupled residual is written once, point-wise, in :func:`solver.model.pointwise_forms` (and
:func:`solver.model.projection_forms`) on top of :mod:`solver.physics`.  The reference path evaluates
those functions on :class:`solver.ad.Dual` arrays; that is exact but Python-bound (about half the
assembly time at h = 1 mm, and it holds the GIL, so assembly threads barely help).  This module
evaluates the *same* functions once on symbols instead, and turns the recorded expression graph
into a numba kernel that loops over the elements and their quadrature points with scalar code.
Nothing of the constitutive laws is written twice: a change in ``physics`` or ``model`` changes the
trace, hence the generated source, hence the kernel.

Pipeline
  1. *Trace*: :class:`Sym` is a scalar symbol that goes through the numpy branch of the physics
     (arithmetic, ``np.where``, ``np.sqrt``, ``np.maximum``, ``np.clip``, comparisons, ``&``, ``~``);
     every operation adds a node to a hash-consed DAG (:class:`Tracer`).  Python floats met on the
     way (parameters, ``dt``, literals of the laws) become entries of a constants array, never
     literals of the kernel: one compiled kernel serves every parameter set of the same structure.
     Structural Python branches (``if kap > 0``, ``n_fields == 7``) give different graphs, hence
     different kernels.  A Python branch on a symbol raises (it would bake one side in).
  2. *Differentiate*: forward mode on the DAG with respect to the point-wise input slots
     (slot = 3 field + l, l = 0 value, 1, 2 gradient component, as :func:`solver.fem.qp_inputs`),
     sparse (each node keeps only the slots it depends on), with the conventions of
     :mod:`solver.ad`: ``where`` follows the chosen branch, max(x, 0) has derivative 0 at x <= 0,
     clip has derivative 1 on [lo, hi] inclusive, sqrt has derivative 0 at 0.
  3. *Generate*: straight-line scalar source for two kernels (residual only; residual and exact
     Jacobian) that load an element's nodal values, compute the element-constant part of the graph
     once (gradients of P1 fields, per-element data, and everything made of them only: strains,
     spectral split, Korteweg stress...), then the point part per quadrature point, and contract
     the coefficients and their derivatives with the P1 shape functions into the element residual
     Fe and field-major Jacobian Ke (the layouts of :func:`solver.fem.assemble_forms`) while the
     element sits in registers.  The source is written atomically to
     ``$DCHFRAC_CACHE/kernels/forms_<hash>.py`` (default ``~/.cache/dchfrac``, the hash is that of
     the source) and imported, so numba's ``cache=True`` keeps the machine code across processes.

The kernels are ``nogil``: the element chunks of :func:`solver.fem.map_chunks` run them in parallel,
and every element is computed on its own, so results do not depend on the thread count.
``tests/test_codegen.py`` checks them against the Dual path on states that hit every branch.
"""
from __future__ import annotations

import hashlib
import importlib.util
import os
import sys
import tempfile
import threading
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import jitcache, kernels
from .jitcache import cache_dir
from .output import atomic_write_text

__all__ = ["Sym", "Tracer", "FormsKernel", "forms_kernel", "cache_dir"]

_CMP = {"lt": "<", "le": "<=", "gt": ">", "ge": ">="}
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


# ---------------------------------------------------------------- forward-mode derivatives on the graph
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


# ---------------------------------------------------------------- source generation
_SYM6 = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))


class _Source:
    """Generated source of one kernel: statements per segment (prologue, element, each point loop)."""

    def __init__(self, tr: Tracer, n_groups: int):
        self.tr = tr
        self.pro: list[str] = []
        self.elem: list[str] = []
        self.pts: list[list[str]] = [[] for _ in range(n_groups)]
        self.names: dict[int, str] = {}
        self.fields: set[int] = set()

    def name(self, n: Sym) -> str:
        if n.op == "lit":
            return repr(n.arg)
        return self.names[n.id]

    def emit_nodes(self, ids) -> None:
        """Statements for the nodes ``ids`` (in creation = topological order), each in its segment."""
        for nid in sorted(ids):
            n = self.tr.nodes[nid]
            op, a = n.op, [self.name(x) if x.op == "lit" or x.id in self.names else None for x in n.args]
            if op == "lit":
                continue
            if op == "c":
                self.names[nid] = f"c{n.arg}"
                self.pro.append(f"c{n.arg} = C[{n.arg}]")
                continue
            if op == "in":
                s, g = n.arg
                f, l = divmod(s, 3)
                self.fields.add(f)
                if l == 0:
                    nm = f"x{s}_{g}"
                    self.pts[g].append(f"{nm} = n0 * u0_{f} + n1 * u1_{f} + n2 * u2_{f}")
                else:
                    nm = f"x{s}"
                    self.elem.append(f"{nm} = g0{l - 1} * u0_{f} + g1{l - 1} * u1_{f} + g2{l - 1} * u2_{f}")
                self.names[nid] = nm
                continue
            nm = f"v{nid}"
            if op == "data":
                rhs = f"D_{n.arg}[e, q]" if n.level == 2 else f"D_{n.arg}[e]"
            elif op in ("add", "sub", "mul", "div"):
                rhs = f"{a[0]} {dict(add='+', sub='-', mul='*', div='/')[op]} {a[1]}"
            elif op == "neg":
                rhs = f"-{a[0]}"
            elif op == "pow":
                rhs = f"{a[0]} ** {n.arg}"
            elif op == "sqrt":
                rhs = f"np.sqrt({a[0]})"
            elif op == "sqrtfac":
                rhs = f"_sqrtfac({a[0]})"
            elif op == "where":
                rhs = f"_where({a[0]}, {a[1]}, {a[2]})"
            elif op in _CMP:
                rhs = f"{a[0]} {_CMP[op]} {a[1]}"
            elif op in ("and", "or"):
                rhs = f"{a[0]} {op} {a[1]}"
            elif op == "not":
                rhs = f"not {a[0]}"
            else:  # pragma: no cover
                raise NotImplementedError(op)
            self.names[nid] = nm
            self.segment(n).append(f"{nm} = {rhs}")

    def segment(self, n: Sym) -> list:
        return self.pro if n.level == 0 else self.elem if n.level == 1 else self.pts[n.grp]


def _reachable(roots) -> set:
    seen = set()
    stack = [r for r in roots if r is not None]
    while stack:
        n = stack.pop()
        if n.id not in seen:
            seen.add(n.id)
            stack.extend(n.args)
    return seen


def generate(tr: Tracer, groups: list, jacobian: bool, name: str) -> str:
    """Source of a kernel ``name(U, tri, G, area, C, bary_0, w_0, ..., D_<data>..., Fe[, Ke])``.

    ``groups``: ``[(F, eq_offset), ...]`` per quadrature rule, F[i][k] a Sym or None (structural zero).
    Contraction (Σ_q w_q |e| over the points of each rule): residual Fe[e, a, I] = F_I0 N_a + F_Ik ∂N_a/∂x_k;
    Jacobian block Ke[e, I, f, a, b] = Σ over the slots (f, l) of ∂F_Ik/∂x_{f,l} T_a^k B_b^l with T^0 = B^0 = N,
    T^k = B^k = ∂N/∂x_k: point-varying derivatives accumulate per point in scalars, element-constant ones meet
    the quadrature moments of the rule once.  Each non-zero row of Fe and block of Ke is *written* once (not
    added to): read-modify-write of ~250 entries made the LLVM optimization 4x slower (21 s against 5 s); the
    other entries are left alone (structural zeros of zeroed output arrays).
    """
    src, contrib = _contributions(tr, groups, jacobian)
    acc = _accumulators(src, contrib, len(groups))
    final = _final_writes(acc["res"], acc["blocks"])
    data_args = [f"D_{nm}" for nm, _ in tr.data_names]
    args = ["U", "tri", "G", "area", "C"] + [f"{x}_{g}" for g in range(len(groups)) for x in ("bary", "w")]
    args += data_args + ["Fe"] + (["Ke"] if jacobian else [])
    body = list(src.pro) + _moment_statements(len(groups)) + ["for e in range(tri.shape[0]):"]
    body += [_IND + line for line in _element_statements(src, acc, final, len(groups))]
    return "\n".join(["@_jit", f"def {name}({', '.join(args)}):"] + [_IND + line for line in body]) + "\n"


_IND = "    "


def _contributions(tr: Tracer, groups: list, jacobian: bool) -> tuple["_Source", list]:
    """The coefficients to contract, ``(group, node, I, k, f, l)`` with f = None for the residual and (f, l) the
    slot of a derivative for the Jacobian, and the source with the statements of every node they reach."""
    outs = [c for F, _ in groups for row in F for c in row if c is not None]
    D = derivatives(tr, outs) if jacobian else {}
    src = _Source(tr, len(groups))
    contrib = []
    for g, (F, off) in enumerate(groups):
        for i, row in enumerate(F):
            for k, c in enumerate(row):
                if c is None:
                    continue
                contrib.append((g, c, off + i, k, None, None))
                for s, d in sorted(D.get(c.id, {}).items()):
                    contrib.append((g, d, off + i, k, s // 3, s % 3))
    src.emit_nodes(_reachable([c[1] for c in contrib]))
    return src, contrib


def _accumulators(src: "_Source", contrib: list, n_groups: int) -> dict:
    """The scalar accumulators and their updates, per contribution: ``init`` (names, in first-use order),
    ``elem`` (element-constant updates), ``pts`` (per rule, point updates), ``res`` (I -> k's of the residual)
    and ``blocks`` ((I, f) -> (k, l)'s of the Jacobian)."""
    acc = {"init": [], "elem": [], "pts": [[] for _ in range(n_groups)], "blocks": {}, "res": {}}
    for g, d, I, k, f, l in contrib:
        x = src.name(d)
        point = d.level == 2
        wq, wn, wnn = ("wq", "wn{}", "wnn{}{}") if point else (f"mw{g}", f"mn{g}_{{}}", f"mnn{g}_{{}}{{}}")
        out = acc["pts"][g] if point else acc["elem"]
        if f is None:  # residual
            if k == 0:
                names = [f"r{I}_0_{a}" for a in range(3)]
                out += [f"{nm} += {x} * {wn.format(a)}" for a, nm in enumerate(names)]
            else:
                names = [f"r{I}_{k}"]
                out.append(f"{names[0]} += {x} * {wq}")
            acc["res"].setdefault(I, set()).add(k)
        else:
            if k == 0 and l == 0:
                names = [f"A{I}_{f}_{a}{b}" for a, b in _SYM6]
                out += [f"{nm} += {x} * {wnn.format(a, b)}" for (a, b), nm in zip(_SYM6, names)]
            elif k == 0 or l == 0:
                names = [f"{'H' if k == 0 else 'T'}{I}_{f}_{k + l}_{a}" for a in range(3)]
                out += [f"{nm} += {x} * {wn.format(a)}" for a, nm in enumerate(names)]
            else:
                names = [f"S{I}_{f}_{k}{l}"]
                out.append(f"{names[0]} += {x} * {wq}")
            acc["blocks"].setdefault((I, f), set()).add((k, l))
        for nm in names:
            if nm not in acc["init"]:
                acc["init"].append(nm)
    return acc


def _final_writes(res: dict, blocks: dict) -> list:
    """The statements writing each non-zero row of Fe and block of Ke once from the accumulators."""
    final = []
    for I, ks in sorted(res.items()):
        for a in range(3):
            t = [f"r{I}_0_{a}"] if 0 in ks else []
            t += [f"r{I}_{k} * g{a}{k - 1}" for k in sorted(ks - {0})]
            final.append(f"Fe[e, {a}, {I}] = {' + '.join(t)}")
    for (I, f), kl in sorted(blocks.items()):
        for a in range(3):
            for b in range(3):
                t = [f"A{I}_{f}_{min(a, b)}{max(a, b)}"] if (0, 0) in kl else []
                for k, l in sorted(kl - {(0, 0)}):
                    if k == 0:
                        t.append(f"H{I}_{f}_{l}_{a} * g{b}{l - 1}")
                    elif l == 0:
                        t.append(f"g{a}{k - 1} * T{I}_{f}_{k}_{b}")
                    else:
                        t.append(f"S{I}_{f}_{k}{l} * (g{a}{k - 1} * g{b}{l - 1})")
                final.append(f"Ke[e, {I}, {f}, {a}, {b}] = {' + '.join(t)}")
    return final


def _moment_statements(n_groups: int) -> list:
    """Quadrature moments of each rule g: Σ_q w_q, Σ_q w_q N_a, Σ_q w_q N_a N_b (for the element-constant
    coefficients), computed once per kernel call."""
    body = []
    for g in range(n_groups):
        body += [f"qm{g} = np.zeros(10)", f"for q in range(w_{g}.shape[0]):", f"{_IND}qm{g}[0] += w_{g}[q]"]
        body += [f"{_IND}qm{g}[{1 + a}] += w_{g}[q] * bary_{g}[q, {a}]" for a in range(3)]
        body += [f"{_IND}qm{g}[{4 + j}] += w_{g}[q] * bary_{g}[q, {a}] * bary_{g}[q, {b}]" for j, (a, b) in enumerate(_SYM6)]
    return body


def _element_statements(src: "_Source", acc: dict, final: list, n_groups: int) -> list:
    """The body of the loop over elements: gather, element-constant nodes and updates, each rule's point loop,
    and the final writes."""
    E = [f"t{a} = tri[e, {a}]" for a in range(3)]
    E += [f"u{a}_{f} = U[t{a}, {f}]" for f in sorted(src.fields) for a in range(3)]
    E += [f"g{a}{i} = G[e, {a}, {i}]" for a in range(3) for i in range(2)]
    E.append("ar = area[e]")
    for g in range(n_groups):
        E += [f"mw{g} = ar * qm{g}[0]"] + [f"mn{g}_{a} = ar * qm{g}[{1 + a}]" for a in range(3)]
        E += [f"mnn{g}_{a}{b} = ar * qm{g}[{4 + j}]" for j, (a, b) in enumerate(_SYM6)]
    E += src.elem
    E += [f"{nm} = 0.0" for nm in acc["init"]]
    E += acc["elem"]
    for g in range(n_groups):
        if not src.pts[g] and not acc["pts"][g]:
            continue
        Q = [f"n{a} = bary_{g}[q, {a}]" for a in range(3)]
        Q += [f"wq = w_{g}[q] * ar"] + [f"wn{a} = wq * n{a}" for a in range(3)]
        Q += [f"wnn{a}{b} = wn{a} * n{b}" for a, b in _SYM6]
        Q += src.pts[g] + acc["pts"][g]
        E += [f"for q in range(w_{g}.shape[0]):"] + [_IND + line for line in Q]
    return E + final


# ---------------------------------------------------------------- kernels: build, cache, call
_HEADER = '''"""Generated by solver.codegen from solver.model's point-wise forms: do not edit (regenerated on change)."""
import numba
import numpy as np

_jit = numba.njit(cache=True, nogil=True, fastmath=False, error_model="numpy")


# choices as calls, not inline `a if c else b`: numba rebuilds SSA form for each of those (a two-branch
# variable), which cost ~15 % of the compile time; LLVM inlines the calls into selects
@_jit
def _where(c, a, b):
    return a if c else b


@_jit
def _sqrtfac(s):
    # d√x/dx = 0.5/√x, taken as 0 at x = 0 (solver.ad.sqrt)
    return 0.5 / s if s > 0.0 else 0.0


'''


def _load_module(src: str):
    """Write ``src`` to the cache directory (atomically; kept if unchanged, so numba's cache stays valid) and import it."""
    h = hashlib.sha256(src.encode()).hexdigest()[:20]
    name = f"dchfrac_forms_{h}"
    if name in sys.modules:
        return sys.modules[name]
    failure = None
    for d in (cache_dir(), Path(tempfile.gettempdir()) / f"dchfrac-{os.getuid() if hasattr(os, 'getuid') else 0}" / "kernels"):
        path = d / f"forms_{h}.py"
        try:  # a read-only cache directory falls back to a private temporary one, with one warning
            d.mkdir(parents=True, exist_ok=True)
            if not path.exists() or path.read_text() != src:
                atomic_write_text(path, src)
            if failure is not None:
                from .jitcache import warn_unwritable

                warn_unwritable(cache_dir(), d, failure)
            break
        except OSError as exc:
            failure = failure or exc
            continue
    else:
        raise OSError(f"no writable directory for the generated kernels (tried {cache_dir()} and the temporary directory)")
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    sys.modules[name] = mod
    return mod


@dataclass(frozen=True)
class FormsKernel:
    """The compiled residual(+Jacobian) kernels of one traced structure."""

    residual: object
    jacobian: object
    quads: tuple  # ((bary (nq, 3), weights (nq,)), ...) per group
    data_names: tuple  # names of the step-data arrays, in argument order
    source: str
    path: str

    def __call__(self, C, U, tri, grads, areas, data: dict, Fe, Ke=None) -> None:
        """Write the element residuals (and Jacobians when ``Ke`` is given) of the elements ``tri`` into Fe, Ke.

        Only the structurally non-zero entries are written: Fe and Ke must be zero on entry.

        ``C``: the constants of the trace; ``data[name]``: the step-data arrays restricted to the elements.
        """
        q = [x for b, w in self.quads for x in (b, w)]
        d = [np.ascontiguousarray(data[nm]) for nm in self.data_names]
        if Ke is None:
            self.residual(U, tri, grads, areas, C, *q, *d, Fe)
        else:
            self.jacobian(U, tri, grads, areas, C, *q, *d, Fe, Ke)
        jitcache.finished(self.path)


_LOCK = threading.RLock()
_BY_SIGNATURE: dict = {}
_BY_KEY: OrderedDict = OrderedDict()


def forms_kernel(key, build) -> tuple[FormsKernel, np.ndarray]:
    """The kernel and constants for ``key`` (hashable: everything the trace depends on).

    ``build(tracer)`` traces the forms: returns ``[(F, Quadrature), ...]`` with F[i][k] symbols (or None).
    Traced once per key; kernels are shared by every key with the same structure (signature), so a new
    parameter set or time step only costs a trace, and a new structure a compile (or a load from numba's cache).
    """
    with _LOCK:
        hit = _BY_KEY.get(key)
        if hit is not None:
            _BY_KEY.move_to_end(key)
            return hit
        tr = Tracer()
        traced = build(tr)
        groups = []
        for F, _ in traced:
            groups.append([[None if c is None else tr.lift(c) for c in row] for row in F])
        sig = tr.signature([(F, None) for F in groups])
        kern = _BY_SIGNATURE.get(sig)
        if kern is None:
            offs = np.cumsum([0] + [len(F) for F in groups[:-1]]).tolist()
            gs = list(zip(groups, offs))
            src = _HEADER + generate(tr, gs, False, "residual") + "\n\n" + generate(tr, gs, True, "jacobian")
            mod = _load_module(src)
            quads = tuple((np.ascontiguousarray(q.bary, float), np.ascontiguousarray(q.weights, float)) for _, q in traced)
            kern = FormsKernel(mod.residual, mod.jacobian, quads, tuple(nm for nm, _ in tr.data_names), src, mod.__file__)
            jitcache.announce(kern.path, (mod.residual, mod.jacobian), also=kernels.compiled_dispatchers())
            _BY_SIGNATURE[sig] = kern
        out = (kern, np.array(tr.constants, dtype=float))
        _BY_KEY[key] = out
        if len(_BY_KEY) > 64:
            _BY_KEY.popitem(last=False)
        return out
