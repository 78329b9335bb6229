"""Figure conventions: axis labels with units, legends in swept values with units, one colour scale
per grid, diverging maps centred at zero, PNG at 200 dpi plus a vector copy (PDF).

Units come from their declarations (``sweep.campaign.columns`` for table columns, ``solver.output`` for the
time series and the snapshot fields), never from a second table.
"""
from __future__ import annotations

from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

__all__ = ["unit_of", "axis_label", "value_label", "save_figure", "colour_scale", "DPI", "VECTOR_FORMAT"]

DPI = 200
VECTOR_FORMAT = "pdf"
# sequential colour maps of the snapshot fields (a field with both signs gets the diverging map)
_CMAPS = {"phi": "cividis", "d": "magma", "S": "Blues", "p": "plasma", "k": "viridis", "w1_mag": "inferno"}
DIVERGING = "RdBu_r"


def unit_of(name: str) -> str | None:
    """Unit of a table column, time-series column or snapshot field ("" counts and labels; None unknown)."""
    from solver.output import SNAPSHOT_FIELDS, TIMESERIES_COLUMNS
    from sweep.campaign.columns import column_info

    if name in SNAPSHOT_FIELDS:
        return SNAPSHOT_FIELDS[name][0]
    if name in TIMESERIES_COLUMNS:
        return TIMESERIES_COLUMNS[name][0]
    info = column_info(name)
    return info[0] if info is not None and info[0] != "?" else None


def axis_label(name: str) -> str:
    """``name (unit)``; dimensionless "(-)"; counts and labels bare; "(unit ?)" when undeclared."""
    u = unit_of(name)
    if u is None:
        return f"{name} (unit ?)"
    return f"{name} ({u})" if u else name


def _fmt_value(v) -> str:
    if isinstance(v, (float, np.floating)):
        return f"{float(v):.4g}"
    return str(v)


def value_label(name: str, value) -> str:
    """``name = value unit`` (``cement = 0.5 %``, ``w_i = 25 mm/s``)."""
    u = unit_of(name)
    return f"{name} = {_fmt_value(value)}" + (f" {u}" if u and u != "-" else "")


def swept_label(row, names: Iterable[str]) -> str:
    """The swept values of a table row as ``a = 1 unit, b = 2 unit`` (missing values left out)."""
    import pandas as pd

    return ", ".join(value_label(n, row[n]) for n in names if n in row.index and not pd.isna(row[n]))


def save_figure(fig, path, formats: Sequence[str] = ("png", VECTOR_FORMAT)) -> list[Path]:
    """Save ``fig`` as ``path`` with each suffix of ``formats`` (PNG at ``DPI``), atomically and without a date
    (``sweep.figio``); returns the paths."""
    from sweep.figio import write_figure

    path = Path(path)
    return [write_figure(fig, path.with_suffix(f".{fmt}"), dpi=DPI, bbox_inches="tight") for fmt in formats]


def colour_scale(field: str, arrays: Iterable[np.ndarray], fixed: tuple[float, float] | None = None):
    """(cmap, vmin, vmax) shared by every panel that shows ``field``: the range over all ``arrays``;
    a field with both signs gets the diverging map with limits symmetric about zero (white = 0)."""
    vals = [np.asarray(a, float) for a in arrays]
    vals = [a[np.isfinite(a)] for a in vals if a.size]
    if fixed is not None:
        lo, hi = fixed
    elif not vals or not any(a.size for a in vals):
        lo, hi = 0.0, 1.0
    else:
        lo, hi = min(float(a.min()) for a in vals if a.size), max(float(a.max()) for a in vals if a.size)
    if lo < 0.0 < hi:
        m = max(-lo, hi)
        return DIVERGING, -m, m
    if hi <= lo:
        hi = lo + (abs(lo) if lo else 1.0) * 1e-9 + 1e-300
    return _CMAPS.get(field, "viridis"), lo, hi
