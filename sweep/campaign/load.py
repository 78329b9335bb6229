"""Load a campaign's results into pandas: one row per run, and the time series of all its runs.

    from sweep import load_campaign, load_timeseries
    d = load_campaign("campaigns/examples/demo.toml")          # or the campaign folder results/demo
    d[d.fracturing]                                   # nullable boolean: failed runs are NA
    ts = load_timeseries("results/demo")              # long frame: key, swept values, status, t, p_inj, ...

Units mm, s, kPa; the unit and meaning of every column are in ``columns.csv`` beside the table
(``dchfrac campaign columns SPEC`` prints them).
"""
from __future__ import annotations

import os
from pathlib import Path

from sweep.campaign.columns import typed_frame

__all__ = ["load_campaign", "load_points", "load_timeseries", "campaign_dir"]


def campaign_dir(source, root="results") -> Path:
    """The campaign folder of ``source``: a campaign folder, a spec TOML path or a CampaignSpec (``root/<name>``)."""
    from sweep.campaign.paths import results_root
    from sweep.campaign.spec import CampaignSpec, load_spec

    if isinstance(source, CampaignSpec):
        return results_root(source, root) / source.name
    p = Path(source)
    if p.is_dir():
        return p
    if p.is_file():
        return results_root(p, root) / load_spec(p).name
    raise FileNotFoundError(f"campaign {str(source)!r} not found: give a campaign folder or a spec TOML file")


def load_campaign(source, root="results", *, points: bool = False):
    """One row per finished run of a campaign, typed (pandas DataFrame).

    source : campaign folder (holding ``table.parquet`` or ``table.csv``), spec TOML path or CampaignSpec;
        with a spec, the folder is ``root/<name>`` and the table is built from the run records when it has
        not been written yet.
    Columns take their dictionary dtypes: Float64, Int64, boolean (NA for failed runs), string, and
    Python lists for list columns (``crack_tip_angles_deg``, ``snapshot_times``, ``blocks``).
    ``run_dir`` is relative to the campaign folder, which is ``df.attrs["campaign_dir"]``.
    points : the per-point table of a campaign with replicates instead (:func:`load_points`).
    """
    import pandas as pd

    if points:
        return load_points(source, root)
    d = campaign_dir(source, root)
    if (d / "table.parquet").is_file():
        df = pd.read_parquet(d / "table.parquet")
    elif (d / "table.csv").is_file():
        df = pd.read_csv(d / "table.csv")
    elif not isinstance(source, (str, os.PathLike)) or Path(source).is_file():
        from sweep.campaign.plan import as_spec
        from sweep.campaign.table import build_table

        df = build_table(as_spec(source), root)
        if df.empty:
            raise FileNotFoundError(f"campaign {str(source)!r}: no table.parquet or table.csv and no finished run "
                                    f"in {d} (run it with `dchfrac campaign run`, or give --results / root)")
    else:
        raise FileNotFoundError(f"no table.parquet or table.csv in {d}")
    return typed_frame(d, df)


def load_points(source, root="results"):
    """The per-point table of a campaign with replicates (``points.parquet``, else ``points.csv``), built from the
    run table when neither is written or when the written one does not hold every run of the table (its
    ``n_runs`` do not sum to the table's rows: points of an earlier write, e.g. a campaign killed after a
    periodic table write). ``df.attrs["campaign_dir"]`` is the campaign folder."""
    import pandas as pd

    from sweep.campaign.replicates import point_table

    d = campaign_dir(source, root)
    df = None
    if (d / "points.parquet").is_file():
        df = pd.read_parquet(d / "points.parquet")
    elif (d / "points.csv").is_file():
        df = pd.read_csv(d / "points.csv")
    table = load_campaign(source, root)
    if df is None or "n_runs" not in df.columns or int(df["n_runs"].sum()) != len(table):
        df = point_table(table, [n for n in _swept_names(d, table) if n not in ("seed", "mesh_seed")])
    df.attrs["campaign_dir"] = str(d)
    return df


def _swept_names(d: Path, table) -> list[str]:
    """The swept columns of a campaign table, from its column dictionary (else its spec copy)."""
    import pandas as pd

    f = d / "columns.csv"
    if f.is_file():
        cols = pd.read_csv(f, keep_default_na=False)
        if "swept" in cols.columns:
            return [n for n, s in zip(cols["name"], cols["swept"]) if str(s) == "True" and n in table.columns]
    if (d / "spec.toml").is_file():
        from sweep.campaign.spec import load_spec

        try:
            return [n for n in load_spec(d / "spec.toml").axis_names if n in table.columns]
        except Exception:  # noqa: BLE001 - an old spec copy: key the frame by run only
            return []
    return []


def _damaged_series(d: Path, damaged: list, allow_damaged: bool) -> None:
    """Name the runs of campaign ``d`` whose time series is damaged: DamagedRunsError, or with
    ``allow_damaged`` a warning (they are left out)."""
    if not damaged:
        return
    msg = (f"campaign {d.name}: {len(damaged)} run(s) with a damaged time series; `dchfrac campaign run SPEC` "
           "reruns them: " + "; ".join(damaged))
    if not allow_damaged:
        from sweep.campaign.plan import DamagedRunsError

        raise DamagedRunsError(msg)
    import warnings

    warnings.warn(msg + " (left out)", stacklevel=3)


def load_timeseries(source, root="results", *, status: str | None = None, allow_damaged: bool = False):
    """The time series of every run of a campaign in one long frame (pandas DataFrame).

    source : as for :func:`load_campaign`. status : keep only runs with this status ("ok", "failed"),
    None keeps every run that wrote a time series (a failed run's series ends where it failed).
    Columns: ``key``, the swept values (named as the spec's axes), ``status``, then the columns of
    ``timeseries.csv`` (t in s, p_inj in kPa, radii in mm, ...; ``sweep.campaign.columns.timeseries_dictionary``).
    A run whose series is unreadable, or an "ok" run without one, is damaged: ``sweep.campaign.plan.DamagedRunsError``
    names them all, unless ``allow_damaged`` (then they are left out with a warning naming them).
    """
    import pandas as pd

    table = load_campaign(source, root)
    d = Path(table.attrs["campaign_dir"])
    swept = _swept_names(d, table)
    frames, damaged = [], []
    for _, row in table.iterrows():
        f = d / str(row["run_dir"]) / "timeseries.csv"
        if status is not None and row["status"] != status:
            continue
        if not f.is_file():
            if row["status"] == "ok" and f.parent.is_dir():  # an absent run folder is archived, not damaged
                damaged.append(f"{row['key']} ({f}: missing)")
            continue
        try:
            ts = pd.read_csv(f)
        except (ValueError, OSError, pd.errors.ParserError) as exc:    # EmptyDataError is a ValueError
            damaged.append(f"{row['key']} ({f}: {type(exc).__name__}: {exc})")
            continue
        keys = {"key": row["key"], **{n: row[n] for n in swept}, "status": row["status"]}
        frames.append(ts.assign(**keys)[[*keys, *ts.columns]])
    _damaged_series(d, damaged, allow_damaged)
    if not frames:
        raise FileNotFoundError(_no_timeseries_text(d, table, status))
    out = pd.concat(frames, ignore_index=True)
    for c in ("key", "status"):
        out[c] = out[c].astype("string")
    for n in swept:
        out[n] = out[n].astype(table[n].dtype)
    out.attrs["campaign_dir"] = str(d)
    out.attrs["units"] = {**{n: table.attrs["units"].get(n, "?") for n in ("key", *swept, "status")},
                          **{n: u for n, u in _timeseries_units().items() if n in out.columns}}
    return out


def _timeseries_units() -> dict:
    from solver.output import TIMESERIES_COLUMNS

    return {n: u for n, (u, _) in TIMESERIES_COLUMNS.items()}


def _no_timeseries_text(d: Path, table, status) -> str:
    """Why no run of a campaign has a time series: which folders are missing, or which status left every run out."""
    runs = d / "runs"
    if status is not None and not (table["status"] == status).any():
        return f"campaign {d}: no run with status {status!r} ({len(table)} runs in its table)"
    if not runs.is_dir():
        return (f"campaign {d}: no time series: its run folders ({runs}) are not here (a committed campaign keeps "
                f"its table, not its runs; `load_campaign` reads the table, `dchfrac campaign run SPEC "
                f"--rerun-archived` remakes the runs)")
    return (f"campaign {d}: none of its {len(table)} runs has a timeseries.csv under {runs} (pruned or "
            f"damaged run folders)")
