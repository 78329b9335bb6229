"""Column dictionary of a campaign table (name, unit, dtype, meaning) and the typing that follows it.

Units (mm, s, kPa) come from their one declaration: model parameters from ``solver.params``
(``field_unit``, ``_FIELD_DOCS``), run options from ``solver.options.OPTION_UNITS`` and the
RunOptions docstring, time-series columns and the metrics made from them from
``solver.output.TIMESERIES_COLUMNS``. The columns the campaign itself makes (bookkeeping, the
dimensionless numbers of ``sweep.regimes.numbers``, the classification of ``sweep.regimes.classify``) are
declared here, in ``TABLE_COLUMNS``.

dtypes: "Float64", "Int64", "boolean", "string" (pandas nullable types, so failed runs are NA
and ``d[d.fracturing]`` works) and "list<float>", "list<string>" (Python lists in memory,
Arrow lists in Parquet, JSON text in CSV).
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import fields
from pathlib import Path
from typing import Any, Mapping

__all__ = ["TABLE_COLUMNS", "column_info", "column_dictionary", "timeseries_dictionary", "typed_table",
           "typed_frame", "to_csv_frame", "arrow_schema", "LIST_DTYPES"]

LIST_DTYPES = ("list<float>", "list<string>")

# columns made by the campaign (sweep.campaign.table.build_table, sweep.regimes.numbers, sweep.regimes.classify):
# name -> (unit, dtype, meaning)
TABLE_COLUMNS: dict[str, tuple[str, str, str]] = {
    "index": ("", "Int64", "position of the run in the campaign grid"),
    "key": ("", "string", "run key: hash of parameters, options and solver version (folder runs/<key>)"),
    "status": ("", "string", "'ok' or 'failed'"),
    "reason": ("", "string", "why a run failed (empty when ok)"),
    "regime": ("", "string", "flow regime of the classifier (README: Flow regimes)"),
    "blocks": ("", "list<string>", "spec blocks that contain the run"),
    "run_dir": ("", "string", "run folder, relative to the campaign folder"),
    "stale": ("", "boolean", "made by other solver code than the current (used; --rerun-stale reruns it)"),
    "code_hash": ("", "string", "hash of the solver code that made the run (python -m solver.codehash)"),
    "classifier_hash": ("", "string", "hash of the classifier code that labelled the run"),
    "classify_error": ("", "string", "why the classifier failed on an ok run"),
    # sweep.regimes.numbers.dimensionless_numbers
    "k0": ("mm²", "Float64", "reference permeability: expectation of k(phi0) over the initial porosity"),
    "Ca": ("-", "Float64", "capillary number eta_o w_i / gamma"),
    "Ca_star": ("-", "Float64", "modified capillary number Ca* (l0 = r_outer, bead diameter delta)"),
    "dp_vis": ("kPa", "Float64", "viscous pressure drop eta_o w_i l0 / k0 (l0 = r_outer)"),
    "N_b": ("-", "Float64", "branching number (l0 = r_inner)"),
    "N_f": ("-", "Float64", "fracturing number dp_vis / dp_cri"),
    "M": ("-", "Float64", "viscosity ratio eta_o / eta_w"),
    "Da": ("-", "Float64", "Darcy number k0 / r_inner²"),
    "dp_cri": ("kPa", "Float64", "critical pressure drop of the N_f-N_b diagram (spec or logistic estimate)"),
    # sweep.regimes.classify.classification_to_dict
    "fracturing": ("", "boolean", "crack longer than min_crack_length (rule 1 of the classifier)"),
    "crack_tip_radius": ("mm", "Float64", "farthest distance from the centre reached by a crack (r_inner if none)"),
    "crack_length": ("mm", "Float64", "crack_tip_radius - r_inner (0 if no crack)"),
    "n_cracks": ("", "Int64", "open crack branches"),
    "crack_tip_angles_deg": ("deg", "list<float>", "angles of the crack-branch tips"),
    "open_area": ("mm²", "Float64", "area of the cracks (phi >= phi_open, connected to the cavity)"),
    "front_radius_mean": ("mm", "Float64", "angular mean of the front r(theta) at the classified snapshot"),
    "front_radius_min": ("mm", "Float64", "angular minimum of the front r(theta) at the classified snapshot"),
    "front_radius_max": ("mm", "Float64", "angular maximum of the front r(theta) at the classified snapshot"),
    "n_fingers": ("", "Int64", "fingers of the S = 0.5 front"),
    "finger_angles_deg": ("deg", "list<float>", "angles of the finger tips"),
    "finger_radius_mean": ("mm", "Float64", "mean tip radius of the fingers (NaN without fingers)"),
    "n_unexplained_fingers": ("", "Int64", "fingers not aligned with a crack tip"),
    "invasion_reach": ("mm", "Float64", "largest distance of an invaded point to the cavity or a crack"),
    "outside_fraction": ("-", "Float64", "invaded area farther than confined_distance from cavity and cracks, "
                                         "over the invaded area"),
    "invaded_area": ("mm²", "Float64", "area of the invaded region connected to the cavity"),
    "t_classified": ("s", "Float64", "time of the classified snapshot"),
    # sweep.campaign.scheduler (records)
    "t_reached": ("s", "Float64", "last simulated time"),
    "n_steps": ("", "Int64", "accepted time steps"),
    "front_radius_max_last_step": ("mm", "Float64", "how far the front's angular maximum moved in the last accepted "
                                                    "step (more than an element: a jump the step did not resolve)"),
    "solver_wall_time_s": ("s", "Float64", "wall time of the simulation"),
    "wall_time_s": ("s", "Float64", "wall time of the run (simulation, classification, bookkeeping), summed over the "
                    "pieces of a run resumed from its checkpoint"),
    "attempts": ("", "Int64", "attempts made (1 + retries used)"),
    "solver_version": ("", "string", "solver version in the run key"),
    "host": ("", "string", "machine that ran it"),
    "finished_at": ("", "string", "UTC time the run finished (ISO 8601)"),
}

# prefixes build_table gives a name that is already taken (sweep.campaign.table._row)
_PREFIXES = {"num_": "dimensionless number", "swept_": "swept value", "cls_": "classification",
             "m_": "run metric", "param_": "model parameter", "opt_": "run option", "rec_": "run record"}
# metrics made from a time-series column (sweep.campaign.scheduler._timeseries_metrics): suffix -> meaning
_TS_SUFFIXES = {"_final": "at the last step", "_max": "largest over the run"}


def _dtype_of_annotation(ann: Any) -> str:
    a = str(ann)
    if "tuple" in a or "list" in a:
        return "list<float>"
    for word, dt in (("bool", "boolean"), ("float", "Float64"), ("int", "Int64"), ("str", "string")):
        if word in a:
            return dt
    return "string"


def _declared() -> dict[str, tuple[str, str, str]]:
    """Every declared column: parameters, options, time-series metrics, then TABLE_COLUMNS."""
    from solver.options import OPTION_UNITS, RunOptions, option_docs
    from solver.output import TIMESERIES_COLUMNS
    from solver.params import Parameters, field_doc, field_unit

    out: dict[str, tuple[str, str, str]] = {}
    for f in fields(Parameters):
        try:
            unit, doc = field_unit(f.name), field_doc(f.name)
        except ValueError:  # a parameter without its declaration: tests/test_params.py asks for one
            unit, doc = "?", ""
        out[f.name] = (unit, _dtype_of_annotation(f.type), f"model parameter: {doc}")
    docs = option_docs()
    for f in fields(RunOptions):
        out[f.name] = (OPTION_UNITS.get(f.name, "?"), _dtype_of_annotation(f.type), f"run option: {docs.get(f.name, '')}")
    for name, (unit, meaning) in TIMESERIES_COLUMNS.items():
        for suffix, how in _TS_SUFFIXES.items():
            out[name + suffix] = (unit, "Float64", f"{meaning}, {how}")
    out.update(TABLE_COLUMNS)
    return out


def column_info(name: str, declared: Mapping[str, tuple[str, str, str]] | None = None) -> tuple[str, str, str] | None:
    """(unit, dtype, meaning) of a table column, None when it is not declared (a custom runner's output)."""
    declared = _declared() if declared is None else declared
    if name in declared:
        return declared[name]
    for prefix, what in _PREFIXES.items():
        if name.startswith(prefix) and name[len(prefix):] in declared:
            unit, dtype, meaning = declared[name[len(prefix):]]
            return unit, dtype, f"{what} (the column without the prefix holds another value of that name): {meaning}"
    return None


def _inferred(series) -> tuple[str, str, str]:
    """(unit, dtype, meaning) of an undeclared column, from its values."""
    import pandas as pd

    vals = [v for v in series if not _isna(v)]
    if vals and all(isinstance(v, bool) for v in vals):
        dt = "boolean"
    elif vals and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in vals):
        dt = "Int64" if pd.api.types.is_integer_dtype(series) else "Float64"
    elif not vals and pd.api.types.is_numeric_dtype(series):
        dt = "Float64"
    else:
        dt = "string"
    return "?", dt, "(undeclared: a custom runner's output)"


def column_dictionary(df, swept=()) -> "pd.DataFrame":  # noqa: F821
    """The column dictionary of a campaign table: one row per column with name, unit, dtype, swept (the
    column is one of the spec's axes ``swept``: the keys of a run with ``key``), meaning."""
    import pandas as pd

    declared = _declared()
    rows = []
    for c in df.columns:
        info = column_info(c, declared) or _inferred(df[c])
        meaning = f"swept value of the {info[2]}" if c in swept else info[2]
        rows.append({"name": c, "unit": info[0], "dtype": info[1], "swept": c in swept, "meaning": meaning})
    return pd.DataFrame(rows, columns=["name", "unit", "dtype", "swept", "meaning"])


def timeseries_dictionary() -> "pd.DataFrame":  # noqa: F821
    """Column dictionary of a run's timeseries.csv (name, unit, dtype, meaning)."""
    import pandas as pd
    from solver.output import TIMESERIES_COLUMNS

    rows = [{"name": n, "unit": u, "dtype": "Int64" if u == "" else "Float64", "meaning": m}
            for n, (u, m) in TIMESERIES_COLUMNS.items()]
    return pd.DataFrame(rows, columns=["name", "unit", "dtype", "meaning"])


def _isna(v) -> bool:
    if v is None:
        return True
    if isinstance(v, float):
        return math.isnan(v)
    try:
        import pandas as pd

        return v is pd.NA or v is pd.NaT
    except ImportError:  # pragma: no cover
        return False


def _as_list(v, item):
    """A list cell from a list, a JSON list text or a ';'-joined text (the classifier's angles)."""
    if isinstance(v, (list, tuple)) or hasattr(v, "tolist"):
        return [item(x) for x in list(v)]
    if _isna(v):
        return None
    s = str(v).strip()
    if s.startswith("["):
        return [item(x) for x in json.loads(s)]
    return [item(x) for x in s.split(";") if x.strip() != ""]


def _bool_cell(v):
    if _isna(v):
        return pd_na()
    if isinstance(v, str):
        low = v.strip().lower()
        if low in ("true", "1"):
            return True
        if low in ("false", "0"):
            return False
        raise ValueError(f"not a boolean: {v!r}")
    return bool(v)


def pd_na():
    import pandas as pd

    return pd.NA


def _typed_column(series, dtype: str):
    import pandas as pd

    if dtype == "list<float>":
        return pd.Series([_as_list(v, float) for v in series], index=series.index, dtype=object)
    if dtype == "list<string>":
        return pd.Series([_as_list(v, str) for v in series], index=series.index, dtype=object)
    if dtype == "boolean":
        return pd.Series([_bool_cell(v) for v in series], index=series.index, dtype="boolean")
    if dtype in ("Float64", "Int64"):
        num = pd.to_numeric(series.astype(object).where(series.notna(), None), errors="coerce")
        if dtype == "Int64" and (num.dropna() % 1 != 0).any():
            return num.astype("Float64")
        return num.astype(dtype)
    return series.astype(object).where(series.notna(), None).astype("string")


def typed_table(df, dictionary=None):
    """``df`` with each column cast to its dictionary dtype (nullable pandas types, real lists)."""
    dictionary = column_dictionary(df) if dictionary is None else dictionary
    out = df.copy()
    out.attrs = {}  # pandas deep-copies attrs at every column operation; the caller sets them on the result
    for name, dtype in zip(dictionary["name"], dictionary["dtype"]):
        if name in out.columns:
            out[name] = _typed_column(out[name], dtype)
    return out


def to_csv_frame(df, dictionary):
    """A copy of a typed table for CSV: list cells as JSON text (``typed_table`` reads them back)."""
    out = df.copy()
    for name, dtype in zip(dictionary["name"], dictionary["dtype"]):
        if dtype in LIST_DTYPES and name in out.columns:
            out[name] = [None if v is None else json.dumps(list(v)) for v in out[name]]
    return out


def arrow_schema(df, dictionary):
    """The pyarrow schema of a typed table: every column typed (never Arrow null), lists as Arrow lists; each
    field's metadata holds its ``unit`` and ``meaning`` (and ``swept``), the schema's ``dchfrac.columns`` the
    whole dictionary as JSON (``pyarrow.parquet.read_schema(path).field("cement").metadata``)."""
    import pyarrow as pa

    kinds = {"Float64": pa.float64(), "Int64": pa.int64(), "boolean": pa.bool_(), "string": pa.string(),
             "list<float>": pa.list_(pa.float64()), "list<string>": pa.list_(pa.string())}
    info = {r["name"]: r for r in dictionary.to_dict("records")}

    def meta(c):
        r = info.get(c, {})
        return {k: str(r.get(k, "")) for k in ("unit", "meaning", "swept") if k in r}

    fields_ = [pa.field(str(c), kinds[info.get(c, {}).get("dtype", "string")], metadata=meta(c)) for c in df.columns]
    rows = [{k: (bool(v) if k == "swept" else str(v)) for k, v in r.items()} for r in dictionary.to_dict("records")]
    return pa.schema(fields_, metadata={"dchfrac.columns": json.dumps(rows), "dchfrac.units": "mm, s, kPa"})


def typed_frame(d: Path, df):
    """A campaign table read from folder ``d``, typed by its column dictionary; ``attrs``: campaign_dir, units."""
    dictionary = _dictionary(d, df)
    df = typed_table(_relative_run_dirs(df), dictionary)
    df.attrs["campaign_dir"] = str(d)
    df.attrs["units"] = {n: u for n, u in zip(dictionary["name"], dictionary["unit"]) if n in df.columns}
    return df


def _dictionary(d: Path, df):
    """The column dictionary written beside the table, else the one made from the declarations."""
    import pandas as pd

    f = d / "columns.csv"
    if f.is_file():
        written = pd.read_csv(f, keep_default_na=False)
        if set(df.columns) <= set(written["name"]):
            return written
    return column_dictionary(df)


def _relative_run_dirs(df):
    """Absolute run folders (tables written before run_dir became relative) -> ``runs/<key>``."""
    if "run_dir" not in df.columns:
        return df
    df = df.copy()
    df["run_dir"] = [f"runs/{Path(v).name}" if isinstance(v, str) and os.path.isabs(v) else v for v in df["run_dir"]]
    return df
