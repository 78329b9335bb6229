"""What both boundary samplers share (``sweep.campaign.boundary`` alone and ``sweep.campaign.replicate_sampler``
with replicates): the sampler's state, the axis columns of a campaign table, and the spaced straddle picks among
seeded candidates.

Units: the axes' own; candidate distances in tolerance units (1 = one tolerance, decades on log axes).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from sweep.campaign.spec_model import SpecError, round_sig
from sweep.regimes.regime_model import AxisScale, RegimeModel

__all__ = ["BoundaryState", "COORD_DIGITS", "MIN_SPACING", "axis_column", "coord_key", "missing_label", "picks",
           "point_coords", "tol_coords"]

COORD_DIGITS = 6        # significant digits of the chosen axis values (clean run keys)
MIN_SPACING = 0.5       # tolerance units between a new point and any sampled point


@dataclass
class BoundaryState:
    """Where a boundary campaign stands (``sweep.campaign.boundary.BoundarySampler.state``)."""

    rounds: list[list[tuple[float, ...]]]
    labels: dict[tuple, str | None]
    budget: int
    stopped: bool = False
    reason: str = ""
    uncertainty: float = math.inf
    pairs: dict[str, float] = field(default_factory=dict)
    model: RegimeModel | None = None
    pending: list[tuple[float, ...]] = field(default_factory=list)

    @property
    def runs_used(self) -> int:
        return sum(len(r) for r in self.rounds)

    def to_dict(self, axes: Sequence[AxisScale]) -> dict:
        """JSON-able summary: round, runs used of the budget, uncertainty (tolerance units), why it
        stopped, and every point in the order chosen with its round and label."""
        names = [a.name for a in axes]
        order = [{"order": i, "round": r, **dict(zip(names, c)), "label": self.labels.get(coord_key(c))}
                 for i, (r, c) in enumerate((r, c) for r, rr in enumerate(self.rounds) for c in rr)]
        return {"sampler": "boundary", "round": len(self.rounds), "runs_used": self.runs_used,
                "budget": self.budget, "uncertainty": None if not math.isfinite(self.uncertainty) else self.uncertainty,
                "uncertainty_by_pair": self.pairs, "stopped": self.stopped, "reason": self.reason,
                "pending": len(self.pending), "points": order}


def coord_key(coords) -> tuple:
    """The coordinates of a point rounded to 10 significant digits: the key that matches a run to its point."""
    return tuple(round_sig(float(v), 10) for v in coords)


def point_coords(axes, u) -> tuple[float, ...]:
    """Axis values (axis units, COORD_DIGITS significant digits) of unit coordinates ``u`` in [-1, 1]."""
    return tuple(round_sig(float(a.from_u(np.clip(ui, -1.0, 1.0))), COORD_DIGITS) for a, ui in zip(axes, u))


def missing_label(v) -> bool:
    """Whether a table cell holds no label: None, pandas' NA or a float NaN (a failed or unlabelled run)."""
    import pandas as pd

    return v is None or v is pd.NA or (isinstance(v, float) and math.isnan(v))


def axis_column(table, name: str):
    """The column of axis ``name`` in a campaign table (bare, ``swept_``, ``param_`` or ``opt_``); SpecError if none."""
    for c in (name, f"swept_{name}", f"param_{name}", f"opt_{name}"):
        if c in table.columns:
            return table[c]
    raise SpecError(f"the campaign table has no column for axis {name!r}")


def tol_coords(axes, U) -> np.ndarray:
    """Unit coordinates ``U`` (rows of points) in tolerance units, where distances are compared."""
    return U * np.array([a.tol_per_u for a in axes])


def picks(U, T, dmin, score, half, n: int, shrink: float) -> list[int]:
    """Indices of up to n candidates, best first (straddle ``score``, or maximin distance ``dmin`` without a
    model); each pick excludes the candidates within its radius: ``shrink`` x its band half-width (at least
    one tolerance, and at least MIN_SPACING after shrinking), or MIN_SPACING without a model."""
    dmin = dmin.copy()
    alive = dmin >= MIN_SPACING
    out: list[int] = []
    for _ in range(n):
        if not alive.any():
            break
        if score is None:
            i = int(np.argmax(np.where(alive, dmin, -np.inf)))
            radius = MIN_SPACING
        else:
            i = int(np.argmax(np.where(alive, score, -np.inf)))
            radius = max(shrink * max(float(half[i]), 1.0), MIN_SPACING)
        out.append(i)
        di = np.linalg.norm(T - T[i], axis=1)
        dmin = np.minimum(dmin, di)
        alive &= di >= radius
    return out
