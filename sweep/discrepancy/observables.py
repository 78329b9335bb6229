"""The observable registry: the one place an observable of the discrepancy workflow is defined.

An observable has a name (the ``observable`` column of observations.csv), a unit, how it is read from a
solver run (from its time series ``timeseries.csv``, one row per time step, or from its last snapshot) and a
default noise (one standard deviation, in its unit, used by the twin experiments).  The measured-data loader, the forward model, the
twins, the residual maps and the report all take their observables from :data:`REGISTRY`; adding one means
a new :class:`Observable` here and the column it reads in the solver's time series (solver/simulate.py).

A "curve" observable is a number per observation time; a "label" observable (the regime) is one label per
condition, classified from the run's last snapshot (sweep.regimes.classify), not from the time series.  A
curve observable with ``snapshot`` set (the crack count) is read from the run's last snapshot, which the
workflow's forward runs write at t_end only: it is observed at t_end (checked before any run,
``checks.check_data_against_model``).
Units: mm, s, kPa; volumes per unit cell height in mm² (mm³/mm).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

__all__ = ["Observable", "REGISTRY", "CURVES", "LABELS", "SNAPSHOT_CURVES", "UNITS", "get_observable", "read_curves",
           "ObservableUnavailable"]


class ObservableUnavailable(ValueError):
    """A run's time series lacks the column an observable is read from."""


@dataclass(frozen=True)
class Observable:
    """name; unit ("kPa", "mm", "-", "label"); kind "curve" | "label"; columns: the time-series columns it reads;
    read(ts, r_inner) -> values per time-series row (None for a label or a snapshot observable); default_noise:
    one sd in ``unit`` (None for a label); doc: what it measures; snapshot(classification) -> its value from the
    classification of the run's last snapshot (sweep.regimes.classify; None: read from the time series)."""

    name: str
    unit: str
    kind: str
    columns: tuple
    read: Callable | None
    default_noise: float | None
    doc: str
    snapshot: Callable | None = None


def _column(name: str) -> Callable:
    return lambda ts, r_inner: ts[name].to_numpy(float)


def _crack_length(ts, r_inner: float) -> np.ndarray:
    """open_tip_radius − r_inner where a crack is open (open_tip_radius > 0), else 0 (mm)."""
    tip = ts["open_tip_radius"].to_numpy(float)
    return np.where(tip > 0, np.maximum(tip - r_inner, 0.0), 0.0)


def _crack_count(c) -> float:
    """Open crack branches of the classification ``c`` of a run's last snapshot (sweep.regimes.classify: tips of
    the open-porosity cracks whose depth in r is at least max(L_min, l_d)); the experiments' "main cracks"."""
    return float(c.n_cracks)


REGISTRY: dict[str, Observable] = {o.name: o for o in (
    Observable("p_inj", "kPa", "curve", ("p_inj",), _column("p_inj"), 2.0,
               "injection pressure: mean pore pressure on the inner circle"),
    Observable("front_radius_mean", "mm", "curve", ("front_radius_mean",), _column("front_radius_mean"), 0.2,
               "angular mean radius of the S = 0.5 invasion front connected to the inlet"),
    Observable("front_radius_branches", "mm", "curve", ("front_radius_branches",),
               _column("front_radius_branches"), 0.3,
               "mean radius of the three main (farthest) invasion branches: the paper's front measure "
               "(Sec. 3.5); noisier than the angular mean, it follows three tips"),
    Observable("crack_length", "mm", "curve", ("open_tip_radius",), _crack_length, 0.3,
               "length of the open crack beyond the inner radius (0 before initiation)"),
    Observable("water_outflow_volume", "mm²", "curve", ("water_outflow_volume",), _column("water_outflow_volume"),
               5.0, "cumulative invading water out through the outer circle r_o, a volume per unit cell height "
               "(mm² = mm³/mm: divide a collected volume by the gap); 0 until the water reaches r_o, so it also "
               "dates the breakthrough.  Default noise 5 mm²: 0.01 g of water on a balance over a 1.96 mm gap"),
    Observable("crack_count", "-", "curve", (), None, 1.0,
               "number of open crack branches at the last snapshot (t_end): the main cracks of the experiment; "
               "read from the snapshot, so observed at t_end only", snapshot=_crack_count),
    Observable("regime", "label", "label", (), None, None,
               "regime label of the last snapshot (sweep.regimes.classify.REGIMES), e.g. invasive_fracturing"),
)}

CURVES = tuple(n for n, o in REGISTRY.items() if o.kind == "curve")
LABELS = tuple(n for n, o in REGISTRY.items() if o.kind == "label")
SNAPSHOT_CURVES = tuple(n for n in CURVES if REGISTRY[n].snapshot is not None)
UNITS = {n: o.unit for n, o in REGISTRY.items()}


def get_observable(name: str) -> Observable:
    """The registered observable ``name``; ValueError naming the allowed ones otherwise."""
    if name not in REGISTRY:
        raise ValueError(f"unknown observable {name!r} (allowed: {list(REGISTRY)})")
    return REGISTRY[name]


def read_curves(ts, names, r_inner: float) -> dict:
    """{name: values per time-series row} of the curve observables ``names`` from a run's time series
    ``ts`` (DataFrame), snapshot observables left out; r_inner: the run's inner radius, mm.  A missing column raises
    :class:`ObservableUnavailable` naming the observable and the column."""
    out = {}
    for name in names:
        o = get_observable(name)
        if o.snapshot is not None:
            continue
        missing = [c for c in o.columns if c not in ts.columns]
        if missing:
            raise ObservableUnavailable(
                f"observable {name!r} is unavailable: the run's time series has no column {missing[0]!r} "
                f"(columns: {sorted(ts.columns)})")
        out[name] = o.read(ts, r_inner)
    return out
