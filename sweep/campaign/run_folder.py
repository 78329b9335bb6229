"""Read one run folder (``dchfrac run --out DIR``, or ``results/<campaign>/runs/<key>``) into Python.

    from sweep import load_run
    run = load_run("results/ca_star_boundary_h1_floor/runs/04ac225cb0c791ab")
    run.params["cement"], run.units["cement"]        # every parameter and option, with its unit (mm, s, kPa)
    run.timeseries                                   # pandas DataFrame, one row per accepted step; .attrs["units"]
    run.snapshots[-1]["phi"], run.snapshots[-1]["t"] # the snapshots kept (NPZ arrays, t in s)
    run.mesh["points"], run.mesh["triangles"]        # mm
    run.missing                                      # what the folder does not hold (a pruned run keeps one snapshot)

The fields are also in ``fields.xdmf`` (XDMF 3, a temporal collection with its arrays in ``fields.h5``) for ParaView.
In Python read it with ``meshio.xdmf.TimeSeriesReader`` (``read_points_cells()``, then ``read_data(i)`` for
each step); plain ``meshio.read`` reads single-grid files only and stops on a time series.
"""
from __future__ import annotations

import json
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["RunData", "load_run"]


@dataclass(frozen=True)
class RunData:
    """The contents of one run folder; see :func:`load_run`.

    folder : the run folder. params, options : ``params.toml``, ``options.toml`` (model units mm, s, kPa).
    units : {parameter, option, time-series or snapshot field name: unit}. summary : ``summary.json``
    (status, wall time, code_hash); record : ``record.json`` of a campaign run (None for a single run).
    timeseries : pandas DataFrame of ``timeseries.csv`` (``attrs["units"]``), None when absent.
    snapshots : the NPZ snapshots kept, in time order, each {field: array, "t": s, "file": name}.
    mesh : {"points": (n, 2) mm, "triangles": (m, 3)} of ``snapshots/mesh.npz``, None when absent.
    missing : the files of a complete run folder that this one does not hold.
    """

    folder: Path
    params: dict
    options: dict
    units: dict
    summary: dict
    record: dict | None
    timeseries: Any
    snapshots: list = field(default_factory=list)
    mesh: dict | None = None
    missing: tuple = ()

    @property
    def times(self) -> list[float]:
        """Times of the snapshots kept, s."""
        return [float(s["t"]) for s in self.snapshots]


def _toml(path: Path) -> dict:
    with open(path, "rb") as f:
        return tomllib.load(f)


def _units(folder: Path) -> dict:
    from solver.options import OPTION_UNITS
    from solver.output import SNAPSHOT_FIELDS, TIMESERIES_COLUMNS
    from solver.params import Parameters, field_unit
    from dataclasses import fields

    out = {}
    for f in fields(Parameters):
        try:
            out[f.name] = field_unit(f.name)
        except ValueError:
            out[f.name] = "?"
    out.update(OPTION_UNITS)
    out.update({n: u for n, (u, _) in TIMESERIES_COLUMNS.items()})
    out.update({n: v[0] for n, v in SNAPSHOT_FIELDS.items()})
    cols = folder / "timeseries_columns.csv"
    if cols.is_file():
        import pandas as pd

        d = pd.read_csv(cols, keep_default_na=False)
        out.update(dict(zip(d["name"], d["unit"])))
    return out


def _snapshots(folder: Path) -> list[dict]:
    import numpy as np

    out = []
    for p in sorted((folder / "snapshots").glob("snap_*.npz")):
        with np.load(p) as z:
            out.append({**{k: z[k] for k in z.files}, "t": float(z["t"]), "file": p.name})
    return sorted(out, key=lambda s: s["t"])


def load_run(folder) -> RunData:
    """The parameters, options, time series (with units), snapshots and mesh of one run folder.

    Raises FileNotFoundError naming the folder when it is not a run folder (no ``params.toml``); what a
    pruned or partial folder lacks is listed in ``missing`` rather than raised.
    """
    import numpy as np
    import pandas as pd

    folder = Path(folder)
    if not (folder / "params.toml").is_file():
        raise FileNotFoundError(f"{folder}: not a run folder (no params.toml); a committed campaign keeps its "
                                f"table, not its run folders: read it with sweep.load_campaign")
    units = _units(folder)
    ts = None
    if (folder / "timeseries.csv").is_file():
        ts = pd.read_csv(folder / "timeseries.csv")
        ts.attrs["units"] = {c: units.get(c, "?") for c in ts.columns}
    mesh = None
    if (folder / "snapshots" / "mesh.npz").is_file():
        with np.load(folder / "snapshots" / "mesh.npz") as z:
            mesh = {k: z[k] for k in z.files}
    snaps = _snapshots(folder)
    want = ["options.toml", "summary.json", "timeseries.csv", "snapshots/mesh.npz"]
    missing = [w for w in want if not (folder / w).is_file()] + ([] if snaps else ["snapshots/snap_*.npz"])
    if (folder / "record.json").is_file() and (pruned := json.loads((folder / "record.json").read_text()).get("pruned")):
        missing += [f"{r} (pruned)" for r in pruned.get("removed", [])]
    read = lambda name: json.loads((folder / name).read_text()) if (folder / name).is_file() else None  # noqa: E731
    return RunData(folder, _toml(folder / "params.toml"),
                   _toml(folder / "options.toml") if (folder / "options.toml").is_file() else {},
                   units, read("summary.json") or {}, read("record.json"), ts, snaps, mesh, tuple(missing))
