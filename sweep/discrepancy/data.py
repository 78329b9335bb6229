"""Measured data for the discrepancy workflow: a documented folder format, a validating loader, a writer.

Format (a folder, units mm, s, kPa)::

    conditions.csv    one row per experiment: ``id`` (text, unique) and any number of
                      solver.Parameters fields (e.g. ``cement``, ``w_i``, ``eta_o``) that
                      differ between experiments; empty cells take the model's value.
    observations.csv  columns ``condition, observable, time, value, uncertainty``:
                      condition  an ``id`` of conditions.csv
                      observable one of OBSERVABLES (the registry, observables.py:
                                 p_inj kPa; front_radius_mean, front_radius_branches,
                                 crack_length mm; crack_count -, at t_end; regime a label)
                      time       s (finite, >= 0)
                      value      in the observable's unit; for ``regime`` a label
                                 (e.g. "invasive_fracturing", one of sweep.regimes.classify.REGIMES), its time the moment of classification
                      uncertainty one standard deviation, same unit as value (> 0; ignored
                                 and may be 0 for regime)

Every problem (missing file or column, unknown observable or condition, NaN,
negative or zero uncertainty, a length negative by more than 5 uncertainties, a non-integer value of an integer
parameter such as ``seed``, a condition without observations, duplicated ids, a pressure that looks like Pa
instead of kPa)
is a ValueError naming the file, the row (line number in the file, header = line 1)
and the column.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
import pandas as pd


from .observables import CURVES, LABELS, UNITS

__all__ = ["OBSERVABLES", "CURVE_OBSERVABLES", "UNITS", "MeasuredData", "load_measured", "write_measured"]

CURVE_OBSERVABLES = CURVES                 # from the observable registry (observables.py)
OBSERVABLES = CURVES + LABELS
LENGTH_OBSERVABLES = tuple(n for n in CURVES if UNITS[n] == "mm")
# A measured length below -5 uncertainties cannot be a noisy 0, nor a front radius 5 uncertainties inside r_inner or
# beyond r_outer a front (checks.py): they are refused.  The test is applied to every value,
# so its false alarm per value must be tiny: P(N(0, 1) < -5) = 2.9e-7 (10^4 noisy zeros refused by mistake with
# probability 0.3 %), where 3 uncertainties would refuse 1.3e-3 of them (a twin with 50 times x 4 conditions of
# zero crack length: up to one in four).
LENGTH_SIGMAS = 5.0
OBS_COLUMNS = ("condition", "observable", "time", "value", "uncertainty")


@dataclass(frozen=True)
class MeasuredData:
    """Validated measured data.

    conditions : DataFrame indexed by condition id (str); columns are Parameters fields.
    curves : DataFrame with columns condition, observable, time (s), value, uncertainty
        (numeric observables only, sorted by condition, observable, time).
    regimes : dict condition id -> (time s, label) for conditions with a regime observation.
    """

    conditions: pd.DataFrame
    curves: pd.DataFrame
    regimes: dict

    @property
    def ids(self) -> list[str]:
        """Condition ids in file order."""
        return list(self.conditions.index)

    def condition_params(self, cid: str) -> dict:
        """Parameter overrides of condition ``cid`` (NaN cells dropped; integer parameters such as ``seed``
        as int, whatever dtype their column took; other numbers as float)."""
        return dict(self._condition_params[cid])

    @cached_property
    def _condition_params(self) -> dict:
        """{condition id: its parameter overrides}, read once (every forward prediction asks for them)."""
        from solver.params import integer_fields

        ints = integer_fields()
        out = {}
        for cid, row in zip(self.conditions.index, self.conditions.itertuples(index=False, name=None)):
            vals = {k: _py(v) for k, v in zip(self.conditions.columns, row)}
            out[cid] = {k: int(v) if k in ints else v for k, v in vals.items()
                        if not (isinstance(v, float) and math.isnan(v))}
        return out

    def subset(self, ids) -> "MeasuredData":
        """The data restricted to the conditions ``ids``."""
        ids = list(ids)
        return MeasuredData(self.conditions.loc[ids], self.curves[self.curves.condition.isin(ids)].reset_index(drop=True),
                            {k: v for k, v in self.regimes.items() if k in ids})

    def times(self, cid: str, observable: str) -> np.ndarray:
        """Observation times (s) of ``observable`` in condition ``cid``."""
        c = self.curves
        return c.loc[(c.condition == cid) & (c.observable == observable), "time"].to_numpy(float)

    def observation_times(self) -> dict:
        """{condition: {observable: times}} for every numeric series, plus regime times."""
        out: dict = {}
        for (cid, obs), g in self.curves.groupby(["condition", "observable"], sort=False):
            out.setdefault(cid, {})[obs] = g.time.to_numpy(float)
        for cid, (t, _) in self.regimes.items():
            out.setdefault(cid, {})["regime"] = np.array([t])
        return out


def _py(v):
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (np.floating,)):
        return float(v)
    return v


def _err(path, line, column, msg):
    where = f"{path}" + (f", row {line}" if line is not None else "") + (f", column {column!r}" if column else "")
    raise ValueError(f"{where}: {msg}")


def _read_csv(path: Path) -> pd.DataFrame:
    if not path.is_file():
        _err(path, None, None, "file not found (a measured-data folder needs conditions.csv and observations.csv)")
    try:
        return pd.read_csv(path, dtype=str, keep_default_na=False, skipinitialspace=True)
    except Exception as exc:  # pandas parser errors
        _err(path, None, None, f"cannot be read as CSV ({exc})")


def _num(path, line, col, cell, *, allow_empty=False):
    """The number in ``cell`` (the text of column ``col`` on line ``line`` of the CSV file ``path``)."""
    s = str(cell).strip()
    if s == "":
        if allow_empty:
            return float("nan")
        _err(path, line, col, "empty value (a number is required)")
    try:
        v = float(s)
    except ValueError:
        _err(path, line, col, f"{s!r} is not a number")
    if math.isnan(v) or math.isinf(v):
        _err(path, line, col, f"{s!r} is not a finite number")
    return v


def _integer(path, line, col, cell) -> int:
    """An integer cell (e.g. ``seed``): 3 or 3.0, not 3.5."""
    v = _num(path, line, col, cell)
    if not v.is_integer():
        _err(path, line, col, f"{cell!r} is not an integer (allowed: an integer, e.g. 3)")
    return int(v)


def load_measured(folder) -> MeasuredData:
    """Read and validate a measured-data folder (see the module docstring for the format)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise ValueError(f"measured-data folder {folder} does not exist")
    cpath, opath = folder / "conditions.csv", folder / "observations.csv"
    conditions = _read_conditions(cpath)
    ids = list(conditions.index)
    odf = _read_csv(opath)
    curves, regimes = _read_observations(opath, odf, ids)
    check_units(opath, odf)
    _check_coverage(cpath, opath, ids, curves, regimes)
    curves = curves.sort_values(["condition", "observable", "time"], kind="stable").reset_index(drop=True)
    return MeasuredData(conditions, curves, regimes)


def _read_conditions(cpath: Path) -> pd.DataFrame:
    """conditions.csv as a DataFrame indexed by id: typed parameter values, each row valid ``Parameters``."""
    from solver import Parameters

    cdf = _read_csv(cpath)
    if "id" not in cdf.columns:
        _err(cpath, 1, "id", "missing column (conditions.csv needs an 'id' column)")
    allowed = set(Parameters.__dataclass_fields__)
    for col in cdf.columns:
        if col != "id" and col not in allowed:
            _err(cpath, 1, col, f"unknown column: not a solver.Parameters field (allowed: id and {sorted(allowed)})")
    if len(cdf) == 0:
        _err(cpath, None, None, "no conditions")
    ids, rows = [], []
    for i in range(len(cdf)):
        cid = str(cdf.at[i, "id"]).strip()
        if cid == "":
            _err(cpath, i + 2, "id", "empty id")
        if cid in ids:
            _err(cpath, i + 2, "id", f"duplicated id {cid!r}")
        ids.append(cid)
        rec = _condition_row(cpath, cdf, i)
        try:  # parameters must be valid before any work starts
            Parameters(**{k: v for k, v in rec.items() if not (isinstance(v, float) and math.isnan(v))})
        except (ValueError, TypeError) as exc:
            _err(cpath, i + 2, None, f"invalid parameters: {exc}")
        rows.append(rec)
    return pd.DataFrame(rows, index=pd.Index(ids, name="id"))


def _condition_row(cpath: Path, cdf: pd.DataFrame, i: int) -> dict:
    """Row ``i`` of conditions.csv as parameter values: text, integer or float by the field's declaration."""
    from solver.params import integer_fields, text_fields

    rec = {}
    for col in cdf.columns:
        if col == "id":
            continue
        s = str(cdf.at[i, col]).strip()
        if s == "":
            rec[col] = float("nan")
        elif col in text_fields():
            rec[col] = s
        elif col in integer_fields():
            rec[col] = _integer(cpath, i + 2, col, cdf.at[i, col])
        else:
            rec[col] = _num(cpath, i + 2, col, cdf.at[i, col])
    return rec


def _read_observations(opath: Path, odf: pd.DataFrame, ids: list) -> tuple[pd.DataFrame, dict]:
    """observations.csv as curve rows (condition, observable, time s, value, uncertainty) and regime labels."""
    for col in OBS_COLUMNS:
        if col not in odf.columns:
            _err(opath, 1, col, f"missing column (required: {list(OBS_COLUMNS)})")
    recs, regimes = [], {}
    for i, row in enumerate(odf.to_dict("records")):  # plain dicts: a cell of a DataFrame costs microseconds
        line = i + 2
        cid = str(row["condition"]).strip()
        if cid not in ids:
            _err(opath, line, "condition", f"unknown condition {cid!r} (not an id of conditions.csv)")
        obs = str(row["observable"]).strip()
        if obs not in OBSERVABLES:
            _err(opath, line, "observable", f"unknown observable {obs!r} (allowed: {list(OBSERVABLES)})")
        t = _num(opath, line, "time", row["time"])
        if t < 0:
            _err(opath, line, "time", f"negative time {t} s")
        if obs == "regime":
            label = str(row["value"]).strip()
            if label == "" or label.lower() == "nan":
                _err(opath, line, "value", "empty regime label")
            if cid in regimes:
                _err(opath, line, "observable", f"second regime observation for condition {cid!r}")
            regimes[cid] = (t, label)
            continue
        recs.append((cid, obs, t, *_value_and_uncertainty(opath, row, line, obs)))
    return pd.DataFrame(recs, columns=list(OBS_COLUMNS)), regimes


def _value_and_uncertainty(opath: Path, row: dict, line: int, obs: str) -> tuple[float, float]:
    """Value and uncertainty (> 0) of a curve observation (``row``: line ``line`` of observations.csv); a length
    may not be negative beyond its noise."""
    v = _num(opath, line, "value", row["value"])
    u = _num(opath, line, "uncertainty", row["uncertainty"])
    if u < 0:
        _err(opath, line, "uncertainty", f"negative uncertainty {u}")
    if u == 0:
        _err(opath, line, "uncertainty", "zero uncertainty (a standard deviation > 0 is required)")
    if obs in LENGTH_OBSERVABLES and v < -LENGTH_SIGMAS * u:
        _err(opath, line, "value", f"negative {obs} {v} mm (allowed: a length >= 0 mm, within "
                                   f"{LENGTH_SIGMAS:g} uncertainties)")
    return v, u


def _check_coverage(cpath: Path, opath: Path, ids: list, curves: pd.DataFrame, regimes: dict) -> None:
    """Every condition observed; no (condition, observable, time) twice."""
    for cid in ids:
        if not (curves.condition == cid).any() and cid not in regimes:
            _err(cpath, ids.index(cid) + 2, "id", f"condition {cid!r} has no observations in {opath.name}")
    dup = curves.duplicated(["condition", "observable", "time"])
    if dup.any():
        i = int(np.flatnonzero(dup.to_numpy())[0])
        _err(opath, None, "time", f"duplicated (condition, observable, time) {tuple(curves.iloc[i][:3])}")


# ------------------------------------------------------------------------------ unit plausibility checks
# A measured injection pressure above this (kPa) is read as a value given in Pa: the experiments' peak injection
# pressure is of order 500 kPa (the paper's reference, Sec. 3.5), and 10 MPa is beyond any annulus of the model's.
PA_SUSPECT_KPA = 1.0e4


def check_units(path: Path, odf: pd.DataFrame) -> None:
    """Reject pressures that look like Pa instead of kPa: the first p_inj row whose value or uncertainty exceeds
    PA_SUSPECT_KPA is named with its file, row and column.  ``odf``: observations.csv as read (strings; rows
    already validated)."""
    rows = odf["observable"].astype(str).str.strip() == "p_inj"
    for col in ("value", "uncertainty"):
        v = pd.to_numeric(odf[col].where(rows), errors="coerce").abs()
        bad = np.flatnonzero((v > PA_SUSPECT_KPA).to_numpy())
        if bad.size:
            i = int(bad[0])
            _err(path, i + 2, col, f"p_inj {col} {odf.at[i, col].strip()} is above {PA_SUSPECT_KPA:g} kPa: a "
                 "pressure in Pa? The workflow reads kPa (divide Pa by 1000)")


def write_measured(folder, conditions: dict, curves: pd.DataFrame, regimes: dict | None = None) -> Path:
    """Write a measured-data folder.

    conditions : {id: {parameter: value}}; curves : DataFrame with OBS_COLUMNS (numeric observables);
    regimes : {id: (time s, label)}.  Returns the folder path.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    cols = sorted({k for d in conditions.values() for k in d})
    crows = [{"id": cid, **{c: d.get(c, "") for c in cols}} for cid, d in conditions.items()]
    pd.DataFrame(crows, columns=["id"] + cols).to_csv(folder / "conditions.csv", index=False)
    out = curves[list(OBS_COLUMNS)].copy()
    if regimes:
        reg = pd.DataFrame([(cid, "regime", t, lab, 0.0) for cid, (t, lab) in regimes.items()], columns=list(OBS_COLUMNS))
        out = pd.concat([out.astype({"value": object}), reg], ignore_index=True)
    out.to_csv(folder / "observations.csv", index=False, float_format="%.10g")
    return folder
