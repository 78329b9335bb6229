"""Compiled point-wise physics generated from the one definition of the weak form (optional: numba).

The coupled residual is written once, point-wise, in :func:`solver.forms.pointwise_forms` (and
:func:`solver.forms.projection_forms`) on top of :mod:`solver.physics`.  The reference path evaluates
those functions on :class:`solver.ad.Dual` arrays; that is exact but Python-bound (about half the
assembly time at h = 1 mm, and it holds the GIL, so assembly threads barely help).  This module
evaluates the *same* functions once on symbols instead, and turns the recorded expression graph
into a numba kernel that loops over the elements and their quadrature points with scalar code.
Nothing of the constitutive laws is written twice: a change in ``physics`` or ``model`` changes the
trace, hence the generated source, hence the kernel.

Pipeline
  1. *Trace* and 2. *Differentiate*: :mod:`solver.tracer` records the forms on symbols as one hash-consed
     expression graph (floats met on the way become entries of a constants array) and differentiates it in
     forward mode with the conventions of :mod:`solver.ad`.
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
from .tracer import CMP, Sym, Tracer, derivatives

__all__ = ["Sym", "Tracer", "FormsKernel", "forms_kernel", "cache_dir"]

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
            elif op in CMP:
                rhs = f"{a[0]} {CMP[op]} {a[1]}"
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
_HEADER = '''"""Generated by solver.codegen from solver.forms' point-wise forms: do not edit (regenerated on change)."""
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
