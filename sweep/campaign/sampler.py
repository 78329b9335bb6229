"""Samplers: which runs a campaign asks for.

A sampler turns a :class:`~sweep.campaign.spec.CampaignSpec` into :class:`Point` objects (fully
resolved model parameters and run options, in the model's units: mm, s, kPa). The
interface is two methods, so that a smarter sampler can be dropped in:

* ``initial(spec) -> list[Point]``: the first batch of runs;
* ``refine(spec, table) -> list[Point]``: more runs given the campaign table so far
  (one row per finished run, see ``sweep.campaign.table.build_table``); an empty list ends
  the campaign.

:class:`GridSampler` (``kind = "grid"``) returns the whole grid at once and never refines.
:class:`sweep.campaign.boundary.BoundarySampler` (``kind = "boundary"``) starts from a small
space-filling design and adds batches where a probabilistic classifier of the regime is
least certain about the boundary, until it is located within a tolerance or a budget is spent.
The kinds a spec may name are ``sweep.campaign.spec.samplers()``; a new sampler is added there.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

from sweep.campaign.spec_model import (CampaignSpec, SpecError, canonical_json, evaluate_expression, expand_block, options_class,
                              parameters_class, plain_value, round_sig)

__all__ = ["Point", "GridSampler", "grid_points", "resolve_point"]


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


def resolve_point(where: str, params: dict, options: dict, derived: Mapping[str, str]):
    """(parameters, options) of one point as JSON-able dicts of every field (mm, s, kPa): the ``[derived]``
    expressions evaluated, both built and checked against the annulus; SpecError prefixed by ``where``."""
    from solver.options import check_run_inputs

    P, O = parameters_class(), options_class()
    try:
        base = P.from_dict(params)
    except (ValueError, TypeError) as e:
        raise SpecError(f"{where}: {e}") from None
    if derived:
        env = plain_value(base.to_dict())
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
    return plain_value(base.to_dict()), plain_value(opts.to_dict())


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
            rp, ro = resolve_point(where, params, options, spec.derived)
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


class GridSampler:
    """The full grid, crossed/zipped as the spec says; nothing to refine."""

    kind = "grid"

    @staticmethod
    def check_settings(settings: Mapping[str, Any]) -> None:
        if settings:
            raise SpecError(f"sampler: the grid sampler takes no settings, got {sorted(settings)}")

    def initial(self, spec: CampaignSpec) -> list[Point]:
        from sweep.campaign.replicates import expand_replicates

        return expand_replicates(spec, grid_points(spec))

    def refine(self, spec: CampaignSpec, table) -> list[Point]:
        return []
