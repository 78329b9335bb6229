"""The campaign data model: what a spec holds and how its grid expands (units mm, s, kPa).

:class:`CampaignSpec` (its :class:`Block` and :class:`Axis`), :class:`SpecError`, the expansion of a block into
grid points, the safe arithmetic of ``[derived]`` and the canonical form of values that run keys hash.  The
samplers (``sweep.campaign.sampler``, ``sweep.campaign.boundary``) and the results store build on this module; reading and
validating a spec file is ``sweep.campaign.spec``, which builds on the samplers.
"""
from __future__ import annotations

import ast
import dataclasses
import itertools
import json
import math
from dataclasses import dataclass, field
from typing import Any, Mapping

SIG_DIGITS = 12  # significant digits kept for generated values and in run keys


class SpecError(ValueError):
    """An invalid campaign spec; the message names the offending key."""


# ---------------------------------------------------------------------------
# model field names (lazy: solver.params / solver.options are imported on use)
# ---------------------------------------------------------------------------
def parameters_class():
    """The model's parameter dataclass, ``solver.params.Parameters`` (imported on first use)."""
    from solver.params import Parameters

    return Parameters


def options_class():
    """The run options dataclass, ``solver.options.RunOptions`` (imported on first use)."""
    from solver.options import RunOptions

    return RunOptions


def parameter_fields() -> tuple[str, ...]:
    """Names of the fields of ``solver.params.Parameters``."""
    return tuple(f.name for f in dataclasses.fields(parameters_class()))


def option_fields() -> tuple[str, ...]:
    """Names of the fields of ``solver.options.RunOptions``."""
    return tuple(f.name for f in dataclasses.fields(options_class()))


# ---------------------------------------------------------------------------
# data
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class Axis:
    """One swept quantity: ``target`` is "params" or "options"; ``values`` in the field's units;
    ``scale`` how the values were written: "values" (a list), "linear", "log" or "range"."""

    name: str
    target: str
    values: tuple
    scale: str = "values"


@dataclass(frozen=True)
class Block:
    """A grid block: overrides of the campaign's base, its axes and how they combine."""

    label: str
    params: Mapping[str, Any]
    options: Mapping[str, Any]
    axes: tuple[Axis, ...]
    mode: str = "cross"
    zip_groups: tuple[tuple[str, ...], ...] = ()


@dataclass(frozen=True)
class CampaignSpec:
    """A validated campaign. ``params``/``options`` are the campaign-wide bases."""

    name: str
    description: str = ""
    paper: str = ""
    params: Mapping[str, Any] = field(default_factory=dict)
    options: Mapping[str, Any] = field(default_factory=dict)
    derived: Mapping[str, str] = field(default_factory=dict)
    blocks: tuple[Block, ...] = ()
    sampler: Mapping[str, Any] = field(default_factory=lambda: {"kind": "grid"})
    classify: Mapping[str, Any] = field(default_factory=dict)
    diagrams: tuple[Mapping[str, Any], ...] = ()
    run: Mapping[str, Any] = field(default_factory=dict)
    source: str = "<dict>"
    replicates: Mapping[str, int] = field(default_factory=dict)   # sweep.campaign.replicates: runs per point

    @property
    def axis_names(self) -> tuple[str, ...]:
        """Swept names in order of first appearance (options prefixed ``options.`` only if ambiguous)."""
        seen: dict[str, None] = {}
        for b in self.blocks:
            for a in b.axes:
                seen.setdefault(a.name, None)
        return tuple(seen)


# ---------------------------------------------------------------------------
# small helpers
# ---------------------------------------------------------------------------
def round_sig(x, digits: int = SIG_DIGITS):
    """Round a float to ``digits`` significant digits (ints, bools, strings unchanged)."""
    if isinstance(x, float) and math.isfinite(x) and x != 0.0:
        return float(f"{x:.{digits}g}")
    return x


def is_number(v) -> bool:
    """A real number of a spec file (int or float; a bool is not a number here)."""
    return isinstance(v, (int, float)) and not isinstance(v, bool)


# ---------------------------------------------------------------------------
# safe arithmetic for [derived]
# ---------------------------------------------------------------------------
_FUNCS = {"sqrt": math.sqrt, "exp": math.exp, "log": math.log, "log10": math.log10, "abs": abs, "min": min, "max": max}
_BINOPS = {ast.Add: lambda a, b: a + b, ast.Sub: lambda a, b: a - b, ast.Mult: lambda a, b: a * b,
           ast.Div: lambda a, b: a / b, ast.Pow: lambda a, b: a ** b}


#: bounds of a ``[derived]`` expression: its length (characters) and its syntax-tree size.  Its numbers are
#: floats (a 64-bit float overflows at once where Python's integers would grow without bound: 9**9**9)
MAX_EXPRESSION_CHARS = 500
MAX_EXPRESSION_NODES = 200


def _parse_bounded(expr: str):
    """The syntax tree of ``expr``; ValueError when it exceeds the bounds above."""
    if len(expr) > MAX_EXPRESSION_CHARS:
        raise ValueError(f"expression of {len(expr)} characters is too long (allowed: at most "
                         f"{MAX_EXPRESSION_CHARS})")
    tree = ast.parse(expr, mode="eval")
    n = sum(1 for _ in ast.walk(tree))
    if n > MAX_EXPRESSION_NODES:
        raise ValueError(f"expression of {n} syntax nodes is too large (allowed: at most {MAX_EXPRESSION_NODES})")
    return tree


def expression_names(expr: str) -> set[str]:
    """The names a ``[derived]`` expression reads (its functions excluded); SyntaxError or ValueError (too
    large) when it is not one."""
    tree = _parse_bounded(expr)
    return {n.id for n in ast.walk(tree) if isinstance(n, ast.Name) and n.id not in _FUNCS}


def _float(v, expr: str) -> float:
    try:
        return float(v)
    except OverflowError:
        raise ValueError(f"number {str(v)[:20]}... in expression {expr!r} is too large for a float") from None


def evaluate_expression(expr: str, env: Mapping[str, float]) -> float:
    """Evaluate an arithmetic expression over ``env`` (numbers only, as floats; no attribute access, no calls
    except sqrt, exp, log, log10, abs, min, max; bounded size).  Raises ValueError naming the unknown name, an
    overflow, a division by zero or a non-finite result."""
    def ev(node):
        if isinstance(node, ast.Expression):
            return ev(node.body)
        if isinstance(node, ast.Constant) and is_number(node.value):
            return _float(node.value, expr)
        if isinstance(node, ast.Name):
            if node.id not in env:
                raise ValueError(f"unknown name {node.id!r} in expression {expr!r}")
            if not is_number(env[node.id]):
                raise ValueError(f"name {node.id!r} = {env[node.id]!r} in expression {expr!r} is not a number")
            return _float(env[node.id], expr)
        if isinstance(node, ast.BinOp) and type(node.op) in _BINOPS:
            return _BINOPS[type(node.op)](ev(node.left), ev(node.right))
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            v = ev(node.operand)
            return -v if isinstance(node.op, ast.USub) else v
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in _FUNCS and not node.keywords:
            return _FUNCS[node.func.id](*[ev(a) for a in node.args])
        raise ValueError(f"unsupported syntax {ast.dump(node)[:60]} in expression {expr!r}")

    try:
        v = float(ev(_parse_bounded(expr)))
    except OverflowError:
        raise ValueError(f"expression {expr!r} overflows a float (allowed: a finite number)") from None
    except ZeroDivisionError:
        raise ValueError(f"expression {expr!r} divides by zero") from None
    if not math.isfinite(v):
        raise ValueError(f"expression {expr!r} gives {v} (allowed: a finite number)")
    return v


# ---------------------------------------------------------------------------
# grid expansion
# ---------------------------------------------------------------------------
def block_groups(block: Block) -> list[tuple[Axis, ...]]:
    """The axes of a block grouped for expansion: each group is zipped, groups are crossed."""
    by = {a.name: a for a in block.axes}
    if block.mode == "zip":
        return [tuple(block.axes)] if block.axes else []
    groups, used = [], set()
    for a in block.axes:
        if a.name in used:
            continue
        g = next((g for g in block.zip_groups if a.name in g), (a.name,))
        groups.append(tuple(by[n] for n in g))
        used.update(g)
    return groups


def grid_size(block: Block) -> int:
    """Number of grid points of a block (before points shared with other blocks are merged)."""
    return math.prod(len(g[0].values) for g in block_groups(block))


def expand_block(block: Block) -> list[dict[tuple[str, str], Any]]:
    """All combinations of a block's axes, as dicts {(target, name): value}, first axis slowest."""
    groups = block_groups(block)
    per_group = [[{(a.target, a.name): a.values[i] for a in g} for i in range(len(g[0].values))] for g in groups]
    out = []
    for combo in itertools.product(*per_group):
        pt: dict = {}
        for c in combo:
            pt.update(c)
        out.append(pt)
    return out


# ---------------------------------------------------------------------------
# canonical values (run keys)
# ---------------------------------------------------------------------------
def plain_value(v):
    """``v`` as plain JSON types: tuples become lists and numpy scalars Python numbers, recursively through lists and dicts."""
    if isinstance(v, tuple):
        return [plain_value(x) for x in v]
    if isinstance(v, list):
        return [plain_value(x) for x in v]
    if isinstance(v, dict):
        return {k: plain_value(x) for k, x in v.items()}
    if hasattr(v, "item") and callable(v.item) and not isinstance(v, (str, bytes)):
        try:
            return v.item()
        except (TypeError, ValueError):
            pass
    return v


def canonical_value(v):
    """Canonical form for hashing: floats at 12 significant digits, ints as floats, sorted dicts."""
    v = plain_value(v)
    if isinstance(v, bool) or v is None or isinstance(v, str):
        return v
    if isinstance(v, int):
        return float(v)
    if isinstance(v, float):
        if v != v:
            return "nan"
        if v in (float("inf"), float("-inf")):
            return "inf" if v > 0 else "-inf"
        return round_sig(v) + 0.0  # -0.0 -> 0.0
    if isinstance(v, list):
        return [canonical_value(x) for x in v]
    if isinstance(v, dict):
        return {str(k): canonical_value(x) for k, x in sorted(v.items())}
    return str(v)


def canonical_json(obj) -> str:
    """Compact, sorted JSON of :func:`canonical_value` (0.1 and 0.1000000000001 give the same text)."""
    return json.dumps(canonical_value(obj), sort_keys=True, separators=(",", ":"))
