"""The campaign table: one row per stored or archived run, in grid order, with its dimensionless numbers.

    table = build_table("campaigns/examples/demo.toml")     # pandas DataFrame
    write_table(spec)                                       # table.csv, table.parquet, columns.csv
    refresh_table(spec)                                     # table.parquet and columns.csv from the committed table

Column units and meanings: :mod:`sweep.campaign.columns`.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Mapping

from sweep.campaign.paths import DEFAULT_ROOT, results_root
from sweep.campaign.plan import Plan, as_spec, plan_campaign
from sweep.campaign.sampler import Point
from sweep.campaign.spec import CampaignSpec
from sweep.campaign.store import ResultsStore

__all__ = ["build_table", "write_table", "refresh_table"]


_numbers_cache: dict[str, dict] = {}


def _numbers(params: Mapping[str, Any]) -> dict:
    """Dimensionless numbers of a run from sweep.regimes.numbers; empty for parameters that are not the solver's
    (a custom runner's: ``solver.params.Parameters`` refuses them with ValueError).  A failure of the numbers
    themselves on the solver's parameters is a bug and is raised, never turned into an empty row."""
    key = json.dumps(params, sort_keys=True, default=str)
    if key in _numbers_cache:
        return _numbers_cache[key]
    from solver.params import Parameters
    from sweep.regimes.numbers import dimensionless_numbers

    try:
        p = Parameters.from_dict(dict(params))
    except ValueError:
        out: dict = {}
    else:
        res = dimensionless_numbers(_numbers_input(p.to_dict()))
        out = {k: v for k, v in dict(res).items() if _is_scalar(v)}
    _numbers_cache[key] = out
    return out


def _numbers_input(p: Mapping[str, Any]) -> dict:
    """Parameters dict -> sweep.regimes.numbers input: Parameters.phi_range is the half-width of the random
    initial porosity, sweep.regimes.numbers wants (lo, hi) (or None for a non-random field)."""
    d = dict(p)
    if d.get("porosity_field", "random") == "random" and isinstance(d.get("phi_range"), (int, float)):
        d["phi_range"] = (d["phi_mean"] - d["phi_range"], d["phi_mean"] + d["phi_range"])
    else:
        d["phi_range"] = None
    return d


def _is_scalar(v) -> bool:
    return v is None or isinstance(v, (bool, int, float, str))


def _cell(v):
    if _is_scalar(v):
        return v
    return json.dumps(v, sort_keys=True, default=str)


def _row(point: Point, key: str, rec: Mapping[str, Any], with_numbers: bool, plan: Plan) -> dict:
    """Table row of one stored run; a damaged run has status "damaged", its problems as the reason and
    no classification (its regime cannot be trusted)."""
    row: dict[str, Any] = {"index": point.index, "key": key, "status": rec.get("status"), "reason": rec.get("reason")}
    cls = rec.get("classification") or {}
    if problems := plan.problems(key):
        row["status"], row["reason"], cls = "damaged", "; ".join(problems), {}
    row["regime"] = cls.get("regime")
    row["blocks"] = ";".join(point.blocks)
    row["stale"] = plan.is_stale(key)

    def put(name, value, prefix):
        name = str(name)
        if name in row:
            name = f"{prefix}{name}"
        if name not in row:
            row[name] = _cell(value)

    nums = rec.get("numbers") or (_numbers(rec.get("params", point.params)) if with_numbers else {})
    for k, v in nums.items():
        put(k, v, "num_")
    for k, v in point.swept.items():
        put(k, v, "swept_")
    for k, v in cls.items():
        if k != "regime":
            put(k, v, "cls_")
    for k, v in (rec.get("metrics") or {}).items():
        put(k, v, "m_")
    for k, v in (rec.get("params") or point.params).items():
        put(k, v, "param_")
    for k, v in (rec.get("options") or point.options).items():
        put(k, v, "opt_")
    put("wall_time_s", record_wall_time(rec), "rec_")
    for k in ("attempts", "code_hash", "classifier_hash", "host", "finished_at"):
        put(k, rec.get(k), "rec_")
    return row


def record_wall_time(rec: Mapping[str, Any]) -> float | None:
    """A run's wall time (s) over all its pieces.  A record with ``resumed_wall_s`` already sums them
    (``sweep.campaign.scheduler``); an older record of a run resumed from its checkpoint holds its last piece only,
    and gets its earlier pieces added (``sweep.campaign.accounting.earlier_pieces_s``: the solver's own wall time
    carries them)."""
    from sweep.campaign.accounting import earlier_pieces_s

    wall = rec.get("wall_time_s")
    if wall is None or wall != wall or "resumed_wall_s" in rec:
        return wall
    return wall + earlier_pieces_s(rec)


def build_table(spec, root=DEFAULT_ROOT, *, code_hash: str | None = None, plan: Plan | None = None,
                numbers: bool = True):
    """One row per stored or archived run of the campaign's grid, in grid order (pandas DataFrame).

    Columns: index, key, status ("ok", "failed" or "damaged"), reason, regime, blocks, stale (made
    by other solver code), dimensionless numbers, the swept values, classification fields,
    metrics, every parameter and run option (model units), wall_time_s, attempts, code_hash,
    classifier_hash (the code that made the run and its label), host, finished_at. A point without a
    run folder here takes its row of the committed table (archived: :mod:`sweep.campaign.archived`), as
    it was written; pending runs have no row.
    """
    import pandas as pd

    plan = plan or plan_campaign(spec, root, code_hash=code_hash)
    extra = _extra_points(plan)
    records = {**extra[2], **plan.records}
    rows = []
    for p, k in zip(plan.points + extra[0], plan.keys + extra[1]):
        if k in records:
            rows.append(_row(p, k, records[k], numbers, plan))
        elif k in plan.archived_rows:
            rows.append(_archived_row(p.index, plan.archived_rows[k], plan))
    if plan.spec.sampler["kind"] != "grid":  # runs a sampler added, known from the committed table only
        n = len(plan.points) + len(extra[0])
        rows += [_archived_row(n + i, r, plan) for i, r in enumerate(plan.unmatched_rows)]
    df = pd.DataFrame(rows)
    if not df.empty:
        df.insert(df.columns.get_loc("blocks") + 1 if "blocks" in df.columns else 3, "run_dir",
                  [str(plan.store.run_dir(k).resolve()) for k in df["key"]])
    return _add_fracturing_number(df, plan.spec)


def _archived_row(index: int, row: Mapping[str, Any], plan: Plan) -> dict:
    """The table row of an archived run: its committed row, with its position and staleness of today."""
    out = {k: v for k, v in row.items() if k not in ("run_dir", "N_f", "dp_cri")}
    out["index"] = index
    out["stale"] = row.get("code_hash") != plan.code_hash
    if "wall_time_s" in row:  # a row written from an older record of a resumed run (record_wall_time)
        out["wall_time_s"] = record_wall_time({"wall_time_s": row["wall_time_s"],
                                               "metrics": {"solver_wall_time_s": row.get("solver_wall_time_s")}})
    return out


def _dp_cri_setting(spec: CampaignSpec):
    for g in spec.diagrams:
        if g.get("kind") == "nf_vs_nb" and "dp_cri" in g:
            return g["dp_cri"]
    return None


def _add_fracturing_number(df, spec: CampaignSpec):
    """N_f = dp_vis / dp_cri (kPa/kPa) when an nf_vs_nb diagram gives ``dp_cri``: a number (kPa) or
    "estimate" (sweep.regimes.numbers.estimate_dp_cri on the campaign's ok runs: the dp_vis where a
    logistic fit of the fracturing outcome crosses 1/2). Adds the column ``dp_cri``."""
    setting = _dp_cri_setting(spec)
    if setting is None or df.empty or "dp_vis" not in df.columns:
        return df
    if setting == "estimate":
        if "fracturing" not in df.columns:
            return df
        ok = df[(df["status"] == "ok") & df["fracturing"].notna()]
        try:
            from sweep.regimes.numbers import estimate_dp_cri

            dp_cri = estimate_dp_cri(ok["dp_vis"].to_numpy(float), ok["fracturing"].astype(bool).to_numpy()).dp_cri
        except Exception:  # noqa: BLE001 - needs both outcomes; N_f stays NaN until then
            return df
    else:
        dp_cri = float(setting)
    df = df.copy()
    df["dp_cri"] = dp_cri
    df["N_f"] = df["dp_vis"].astype(float) / dp_cri
    return df


def _extra_points(plan: Plan):
    """Points added by a refining sampler in earlier sessions (records not in the initial grid): their
    points, keys and records."""
    if plan.spec.sampler["kind"] == "grid":
        return [], [], {}
    known = set(plan.keys)
    pts, keys, recs = [], [], {}
    for k, r in plan.store.records().items():
        if k not in known:
            pts.append(Point(r["params"], r["options"], {}, ("refined",), len(plan.points) + len(pts)))
            keys.append(k)
            recs[k] = r
            plan.records.setdefault(k, r)
    return pts, keys, recs


def write_table(spec, root=DEFAULT_ROOT, *, code_hash: str | None = None, plan: Plan | None = None) -> list[Path]:
    """Rebuild the campaign table from the run records and write it: table.csv, table.parquet and its column
    dictionary columns.csv (``ResultsStore.write_table``)."""
    spec = as_spec(spec)
    root = results_root(spec, root)
    df = build_table(spec, root, code_hash=code_hash, plan=plan)
    from sweep.campaign.replicates import write_points

    store = ResultsStore(root, spec.name)
    return store.write_table(df, swept=spec.axis_names) + write_points(spec, df, store)


def refresh_table(spec, root=DEFAULT_ROOT) -> list[Path]:
    """Rewrite a campaign's ``table.parquet`` (units and meanings in its schema metadata) and ``columns.csv``
    without running anything: from its committed table (``table.csv`` left as it is: the evidence), else, when
    there is none, from its run records (``table.csv`` too).  Raises FileNotFoundError naming the folder when
    there is neither."""
    from sweep.campaign.archived import read_committed_table

    spec = as_spec(spec)
    root = results_root(spec, root)
    store = ResultsStore(root, spec.name)
    committed = read_committed_table(store.dir)
    if committed is not None:
        return store.write_table(committed, swept=spec.axis_names, csv=False)[1:]
    if store.records():
        return store.write_table(build_table(spec, root), swept=spec.axis_names)
    raise FileNotFoundError(f"campaign {spec.name}: no table.parquet or table.csv and no run records in {store.dir}")
