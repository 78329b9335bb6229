"""Samplers: which runs a campaign asks for.

A sampler turns a :class:`~sweep.spec.CampaignSpec` into :class:`Point` objects (fully
resolved model parameters and run options, in the model's units: mm, s, kPa). The
interface is two methods, so that a smarter sampler can be dropped in:

* ``initial(spec) -> list[Point]``: the first batch of runs;
* ``refine(spec, table) -> list[Point]``: more runs given the campaign table so far
  (one row per finished run, see ``sweep.campaign.build_table``); an empty list ends
  the campaign.

:class:`GridSampler` (``kind = "grid"``) returns the whole grid at once and never refines.
:class:`sweep.boundary.BoundarySampler` (``kind = "boundary"``) starts from a small
space-filling design and adds batches where a probabilistic classifier of the regime is
least certain about the boundary, until it is located within a tolerance or a budget is spent.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any, Mapping

from sweep.spec import CampaignSpec, SpecError, evaluate_expression, expand_block, round_sig

__all__ = ["Point", "GridSampler", "SAMPLERS", "grid_points", "validate_points", "canonical_json"]


@dataclass(frozen=True)
class Point:
    """One requested run.

    params : every ``Parameters`` field (resolved, JSON-able), model units.
    options : every ``RunOptions`` field (resolved, JSON-able); h mm, times s.
    swept : the values that define this point in the grid {name: value}.
    blocks : labels of the blocks that asked for it (a point shared by several blocks runs once).
    index : position in the grid (order of the table rows).
    """

    params: Mapping[str, Any]
    options: Mapping[str, Any]
    swept: Mapping[str, Any]
    blocks: tuple[str, ...]
    index: int


def _jsonable(v):
    if isinstance(v, tuple):
        return [_jsonable(x) for x in v]
    if isinstance(v, list):
        return [_jsonable(x) for x in v]
    if isinstance(v, dict):
        return {k: _jsonable(x) for k, x in v.items()}
    if hasattr(v, "item") and callable(v.item) and not isinstance(v, (str, bytes)):
        try:
            return v.item()
        except (TypeError, ValueError):
            pass
    return v


def canonical_value(v):
    """Canonical form for hashing: floats at 12 significant digits, ints as floats, sorted dicts."""
    v = _jsonable(v)
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


def _resolve(where: str, params: dict, options: dict, derived: Mapping[str, str]):
    from solver.options import check_run_inputs
    from sweep.spec import _options_class, _parameters_class

    P, O = _parameters_class(), _options_class()
    try:
        base = P.from_dict(params)
    except (ValueError, TypeError) as e:
        raise SpecError(f"{where}: {e}") from None
    if derived:
        env = _jsonable(base.to_dict())
        extra = {}
        for k, expr in derived.items():
            try:
                extra[k] = round_sig(evaluate_expression(expr, env))
            except (ValueError, ZeroDivisionError, OverflowError, TypeError) as e:
                raise SpecError(f"{where}: derived.{k} = {expr!r}: {e}") from None
        try:
            base = P.from_dict({**params, **extra})
        except (ValueError, TypeError) as e:
            raise SpecError(f"{where}: derived values {extra}: {e}") from None
    try:
        opts = O.from_dict(options)
        check_run_inputs(base, opts)  # the mesh fits the annulus, the stop radius lies inside it
    except (ValueError, TypeError) as e:
        raise SpecError(f"{where}: {e}") from None
    return _jsonable(base.to_dict()), _jsonable(opts.to_dict())


def grid_points(spec: CampaignSpec) -> list[Point]:
    """Every grid point of every block, resolved and validated, duplicates merged (first wins the index).

    Raises SpecError naming the block/axis values and the offending key.
    """
    pts: list[Point] = []
    seen: dict[str, int] = {}
    for bi, block in enumerate(spec.blocks):
        for combo in expand_block(block):
            params = {**spec.params, **block.params}
            options = {**spec.options, **block.options}
            swept = {}
            for (target, name), v in combo.items():
                (params if target == "params" else options)[name] = v
                swept[name] = v
            desc = ", ".join(f"{k}={v!r}" for k, v in swept.items()) or "base point"
            where = f"{spec.source}: " + (f"blocks[{bi}] ({block.label}) " if len(spec.blocks) > 1 or block.label else "") + f"grid point ({desc})"
            rp, ro = _resolve(where, params, options, spec.derived)
            cj = canonical_json({"params": rp, "options": ro})
            if cj in seen:
                i = seen[cj]
                old = pts[i]
                if block.label not in old.blocks:
                    pts[i] = Point(old.params, old.options, {**old.swept, **swept}, old.blocks + (block.label,), old.index)
                continue
            seen[cj] = len(pts)
            pts.append(Point(rp, ro, swept, (block.label,), len(pts)))
    if not pts:
        raise SpecError(f"{spec.source}: the grid is empty")
    return pts


def validate_points(spec: CampaignSpec) -> None:
    """Expand and validate the initial points of the spec's sampler (raises SpecError)."""
    SAMPLERS[spec.sampler.get("kind", "grid")]().initial(spec)


class GridSampler:
    """The full grid, crossed/zipped as the spec says; nothing to refine."""

    kind = "grid"

    @staticmethod
    def check_settings(settings: Mapping[str, Any]) -> None:
        if settings:
            raise SpecError(f"sampler: the grid sampler takes no settings, got {sorted(settings)}")

    def initial(self, spec: CampaignSpec) -> list[Point]:
        return grid_points(spec)

    def refine(self, spec: CampaignSpec, table) -> list[Point]:
        return []


SAMPLERS: dict[str, type] = {"grid": GridSampler}


def _register_boundary() -> None:
    from sweep.boundary import BoundarySampler  # imports this module: registered after its definitions

    SAMPLERS[BoundarySampler.kind] = BoundarySampler


_register_boundary()
