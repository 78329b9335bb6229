"""Replicates as a campaign concept: runs that repeat a point over porosity draws (and mesh seeds), and the
per-point aggregates of their results (issue #51).

Spec::

    [replicates]
    porosity_seed = 5     # runs per point over the random initial porosity: seed = base seed + 0 .. 4
    mesh_seed = 2         # optional: over the mesh perturbation too (crossed: 10 runs per point); replicate 0
                          #   keeps the base mesh_seed (None: the deterministic mesh), replicate m >= 1 runs
                          #   mesh_seed = (base or 0) + m

Each replicate is an ordinary run (its own key, record and folder), so resume, isolation and the loaders work
as for any run, and replicate 0 is the run the point has without replicates (a campaign can gain replicates
without rerunning it).  The table keeps one row per run; ``points.csv`` / ``points.parquet`` beside it hold one
row per point (:func:`point_table`), with their units and meanings in ``points_columns.csv``;
``sweep.campaign.load.load_points`` (or ``load_campaign(..., points=True)``) reads them.

Units: those of the table (mm, s, kPa); probabilities dimensionless.
"""
from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from sweep.campaign.spec_model import SpecError

__all__ = ["REPLICATE_KEYS", "check_replicates", "replicate_count", "expand_replicates", "point_table",
           "write_points", "fixed_columns", "point_columns", "CONTINUOUS_MEASURES"]

# replicate key -> (namespace, field it varies)
REPLICATE_KEYS: dict[str, tuple[str, str]] = {"porosity_seed": ("params", "seed"),
                                              "mesh_seed": ("options", "mesh_seed")}
# continuous measures aggregated per point (mean, sd, min, max over the ok replicates), if in the table
CONTINUOUS_MEASURES = ("crack_length", "n_cracks", "n_fingers", "front_radius_mean", "front_radius_max",
                       "invasion_reach", "open_area", "p_inj_max")
MAX_REPLICATES = 1000


def check_replicates(raw: Any, top, blocks: Sequence, derived: Mapping[str, str]) -> dict[str, int]:
    """The ``[replicates]`` table validated: {key: count >= 1}; SpecError naming the key, its value and what is
    allowed.  A replicated seed may not also be swept, derived or (for the porosity draw) meaningless because
    the porosity field is not random."""
    if raw is None:
        return {}
    if not isinstance(raw, Mapping):
        raise SpecError(f"replicates: expected a table {{porosity_seed = N, mesh_seed = M}}, got {raw!r}")
    out = {}
    for k, v in raw.items():
        if k not in REPLICATE_KEYS:
            raise SpecError(f"replicates.{k}: unknown key; allowed: {sorted(REPLICATE_KEYS)}")
        if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= MAX_REPLICATES:
            raise SpecError(f"replicates.{k}={v!r}: must be an integer in [1, {MAX_REPLICATES}] (runs per point)")
        target, name = REPLICATE_KEYS[k]
        for b in blocks:
            if any(a.name == name and a.target == target for a in b.axes):
                raise SpecError(f"replicates.{k}: {name!r} is also swept as an axis; replicate it or sweep it, not both")
        if name in derived:
            raise SpecError(f"replicates.{k}: {name!r} is derived; it cannot be replicated")
        out[k] = v
    if out.get("porosity_seed", 1) > 1:
        for b in (top, *blocks):
            field = b.params.get("porosity_field", "random")
            if field != "random":
                raise SpecError(f"replicates.porosity_seed={out['porosity_seed']}: porosity_field={field!r} "
                                "draws no random porosity, every replicate would be the same run (allowed: "
                                "porosity_field = \"random\")")
    return out


def replicate_count(spec) -> int:
    """Runs per point of the spec (1 without ``[replicates]``)."""
    return math.prod((getattr(spec, "replicates", None) or {}).values())


def _variants(spec, point) -> list[tuple[dict, dict]]:
    """(params, options) of each replicate of one point, porosity draw fastest."""
    reps = getattr(spec, "replicates", None) or {}
    n_p, n_m = reps.get("porosity_seed", 1), reps.get("mesh_seed", 1)
    out = []
    for m in range(n_m):
        for r in range(n_p):
            params, options = dict(point.params), dict(point.options)
            params["seed"] = int(params.get("seed") or 0) + r
            if m:
                options["mesh_seed"] = int(options.get("mesh_seed") or 0) + m
            out.append((params, options))
    return out


def expand_replicates(spec, points: Sequence) -> list:
    """Each point of ``points`` as its replicate runs (``[replicates]``), indices renumbered in order; the points
    unchanged without replicates."""
    if replicate_count(spec) == 1:
        return list(points)
    out = []
    for p in points:
        for params, options in _variants(spec, p):
            out.append(replace(p, params=params, options=options, index=len(out)))
    return out


# --------------------------------------------------------------------------- per-point aggregates
def _axis_columns(table, axis_names: Sequence[str]) -> list[str]:
    cols = []
    for n in axis_names:
        c = next((c for c in (n, f"swept_{n}", f"param_{n}", f"opt_{n}") if c in table.columns), None)
        if c is None:
            raise ValueError(f"table: no column for axis {n!r} (columns {list(table.columns)[:12]}...)")
        cols.append(c)
    return cols


def fixed_columns(table, axis_cols: Sequence[str]) -> dict[str, str]:
    """{name: column} of the model parameters and run options other than the axes and the replicated seeds whose
    value differs between runs of the table (blocks that fix them at other values): they tell points apart too.
    Columns with a missing value (a row of an older table) or non-scalar values are left out."""
    from sweep.campaign.spec_model import option_fields, parameter_fields

    seeds = {name for _, name in REPLICATE_KEYS.values()}
    out = {}
    for prefix, names in (("param_", parameter_fields()), ("opt_", option_fields())):
        for n in names:
            c = next((c for c in (n, prefix + n) if c in table.columns), None)
            if c is None or n in seeds or c in axis_cols or n in out:
                continue
            v = table[c]
            if v.isna().any() or not all(isinstance(x, (bool, int, float, str, np.generic)) for x in v):
                continue
            if v.nunique() > 1:
                out[n] = c
    return out


def point_columns(table, axis_names: Sequence[str]) -> tuple[list[str], list[str]]:
    """(names, columns) that tell a point of ``table`` from another: the axes, then every other parameter and run
    option that differs between runs (:func:`fixed_columns`); the replicated seeds are not among them.  The one
    point key of the point table and of the replicated diagrams."""
    cols = _axis_columns(table, axis_names)
    fixed = fixed_columns(table, cols)
    return [*axis_names, *fixed], [*cols, *fixed.values()]


def point_table(table, axis_names: Sequence[str], *, level: float = 0.95):
    """One row per point of a campaign table with one row per run (pandas DataFrame): the runs with equal axis
    values and equal values of every other parameter and run option but the replicated seeds (blocks may fix a
    parameter at other values: ``fixed_columns``).

    Columns: the axis values (then those other parameters that differ between points); ``n_runs`` (rows),
    ``n_ok`` (ok runs with a label: the replicates counted);
    for the boolean ``fracturing`` and each regime r seen: ``p_fracturing`` / ``p_<r>`` the fraction of the
    ok replicates with that label and its Wilson interval ``..._lo``, ``..._hi`` at ``level``; ``mixed``
    (the replicates' regimes disagree); for each continuous measure of CONTINUOUS_MEASURES present:
    ``<m>_mean``, ``<m>_sd`` (sample sd, NaN for one replicate), ``<m>_min``, ``<m>_max``; and the first value
    of the dimensionless numbers that the replicates share (Ca_star, N_b, N_f, dp_vis).
    """
    import pandas as pd

    from sweep.regimes.probability import wilson_interval

    if table is None or len(table) == 0:
        return pd.DataFrame()
    names, cols = point_columns(table, axis_names)
    ok = (table["status"] == "ok") if "status" in table.columns else pd.Series(True, index=table.index)
    regimes = sorted({str(v) for v in table.loc[ok, "regime"].dropna()}) if "regime" in table.columns else []
    rows = []
    groups = table.groupby(cols, sort=False, dropna=False) if cols else [((), table)]
    for vals, g in groups:
        vals = vals if isinstance(vals, tuple) else (vals,)
        row: dict[str, Any] = dict(zip(names, vals))
        good = g[ok.loc[g.index]]
        row["n_runs"], row["n_ok"] = len(g), int(_labelled(good).sum())
        for name, hit in _label_columns(good, regimes):
            k, n = int(np.sum(hit)), len(hit)
            lo, hi = wilson_interval(k, n, level)
            row[f"p_{name}"], row[f"p_{name}_lo"], row[f"p_{name}_hi"] = (k / n if n else math.nan), float(lo), float(hi)
        row["mixed"] = bool(good["regime"].nunique() > 1) if "regime" in good.columns else False
        _continuous(row, good)
        for c in ("Ca_star", "N_b", "N_f", "dp_vis"):
            if c in g.columns:
                row[c] = g[c].iloc[0]
        rows.append(row)
    return pd.DataFrame(rows)


def _labelled(good):
    """Which ok runs carry a label (a regime or the fracturing flag): a run whose classification failed has none."""
    import pandas as pd

    cols = [c for c in ("regime", "fracturing") if c in good.columns]
    if not cols:
        return pd.Series(True, index=good.index)
    return good[cols].notna().any(axis=1)


def _label_columns(good, regimes):
    """(name, boolean array over the ok replicates) of each label whose probability is tabulated."""
    out = []
    if "fracturing" in good.columns:
        fr = good["fracturing"].dropna()
        out.append(("fracturing", fr.astype(bool).to_numpy()))
    if "regime" in good.columns:
        reg = good["regime"].dropna().astype(str).to_numpy()
        out += [(r, reg == r) for r in regimes if r != "fracturing"]
    return out


def _continuous(row: dict, good) -> None:
    for m in CONTINUOUS_MEASURES:
        if m not in good.columns:
            continue
        v = good[m].astype("Float64").dropna().to_numpy(float)
        row[f"{m}_mean"] = float(v.mean()) if v.size else math.nan
        row[f"{m}_sd"] = float(v.std(ddof=1)) if v.size > 1 else math.nan
        row[f"{m}_min"] = float(v.min()) if v.size else math.nan
        row[f"{m}_max"] = float(v.max()) if v.size else math.nan


def points_dictionary(points, table_dictionary=None):
    """name, unit, meaning of each column of a point table; units of aggregated columns from the table's own
    dictionary (``columns.csv``, else the declarations of ``sweep.campaign.columns``)."""
    import pandas as pd

    from sweep.campaign.columns import column_info

    units = {}
    if table_dictionary is not None:
        units = dict(zip(table_dictionary["name"], table_dictionary["unit"]))

    def unit(c):
        if c in units:
            return units[c]
        info = column_info(c)
        return info[0] if info else ""

    rows = []
    for c in points.columns:
        base = next((c[: -len(s)] for s in ("_mean", "_sd", "_min", "_max") if c.endswith(s) and c[: -len(s)] in
                     CONTINUOUS_MEASURES), None)
        if base:
            rows.append((c, unit(base), f"{c[len(base) + 1:]} of {base} over the ok replicates"))
        elif c.startswith("p_"):
            rows.append((c, "-", "fraction of the ok replicates with label " + c[2:].removesuffix("_lo").removesuffix("_hi")
                         + (" (Wilson interval bound)" if c.endswith(("_lo", "_hi")) else "")))
        elif c in ("n_runs", "n_ok"):
            rows.append((c, "", "runs of the point" if c == "n_runs" else "ok runs with a label (the replicates)"))
        elif c == "mixed":
            rows.append((c, "", "the replicates' regimes disagree"))
        else:
            rows.append((c, unit(c), "point coordinate or shared dimensionless number"))
    return pd.DataFrame(rows, columns=["name", "unit", "meaning"])


def write_points(spec, table, store) -> list[Path]:
    """points.csv, points.parquet and points_columns.csv beside the table (atomically); [] without replicates."""
    import os
    import uuid

    import pandas as pd

    from sweep.campaign.store import write_text_atomic

    if replicate_count(spec) == 1 or table is None or len(table) == 0:
        return []
    pts = point_table(table, spec.axis_names)
    dic = pd.read_csv(store.columns_csv, keep_default_na=False) if store.columns_csv.is_file() else None
    csv, pq, cols = store.dir / "points.csv", store.dir / "points.parquet", store.dir / "points_columns.csv"
    write_text_atomic(cols, points_dictionary(pts, dic).to_csv(index=False))
    write_text_atomic(csv, pts.to_csv(index=False))
    tmp = pq.with_name(f".points.{uuid.uuid4().hex[:8]}.parquet")
    pts.to_parquet(tmp, index=False)
    os.replace(tmp, pq)
    return [csv, pq]
