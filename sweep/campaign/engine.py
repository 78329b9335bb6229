"""Campaigns: plan, run (resumably), tabulate, plot and report a campaign spec.

Public API (paths default to ``results/``; every function takes ``root``)::

    spec = load_spec("campaigns/examples/demo.toml")
    res = run_campaign(spec, root="results", jobs=2)           # CampaignResult
    plan = plan_campaign(spec, root="results")                   # done / failed / pending
    table = build_table(spec, root="results")                    # pandas DataFrame
    estimate_cost(spec, root="results")                          # dry-run cost (s)
    plot_campaign(spec, root="results"); write_report(spec, root="results")

Run records live in ``<root>/<name>/runs/<key>/record.json`` (see :mod:`sweep.campaign.store`);
a rerun skips every key with an intact record of the current code ("ok" or "failed";
``retry_failed=True`` reruns the failures), so an interrupted campaign loses at most its runs
in flight. It reruns damaged runs (files missing, changed or unreadable: :func:`sweep.campaign.store.verify_run`)
and reclassifies runs labelled by other classifier code.  Runs made by other solver code (stale: recorded
``code_hash`` != :func:`solver.code_hash`) are used like any other and rerun only with ``rerun_stale=True``;
archived runs (rows of the committed table without a run folder here) only with ``rerun_archived=True``.
"""
from __future__ import annotations

import json
import math
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence, TextIO

from sweep.campaign.paths import DEFAULT_ROOT, results_root
from sweep.campaign.sampler import Point
from sweep.campaign.scheduler import DefaultRunner, ExecConfig, RunTask, classification_dict, iter_records
from sweep.campaign.spec import CampaignSpec, load_spec, resolve_runner, samplers
from sweep.campaign.store import ResultsStore, current_classifier_hash, current_code_hash, run_key, verify_run, write_text_atomic

__all__ = [
    "DEFAULT_ROOT",
    "Plan",
    "CampaignResult",
    "as_spec",
    "plan_campaign",
    "run_campaign",
    "build_table",
    "write_table",
    "refresh_table",
    "estimate_cost",
    "wall_per_sim_second",
    "estimated_sim_time",
    "plot_campaign",
    "write_report",
    "reclassify",
    "sampler_status",
    "DEFAULT_WALL_S_PER_SIM_S_H2",
    "COST_MESH_EXPONENT",
    "DEFAULT_PER_RUN_OVERHEAD_S",
    "DEFAULT_SHARED_RUN_FACTOR",
    "per_run_overhead",
    "shared_run_factor",
]

# Dry-run cost model: wall seconds per simulated second of one coupled run at mesh size h (mm):
#   c(h) = c2 * (2 / h) ** COST_MESH_EXPONENT,
# c2 from <root>/bench/bench.json key "coupled_run_h2_wall_s_per_sim_s" when present (an exact
# "coupled_run_h{h:g}_wall_s_per_sim_s" key wins), else the placeholder default below. The
# exponent: elements ~ h^-2, sparse direct solves ~ n^1.25 in 2-D -> 2.5.
DEFAULT_WALL_S_PER_SIM_S_H2 = 60.0
COST_MESH_EXPONENT = 2.5
# Plus a fixed cost per run, s, whatever its simulated time: the run's child process and imports, the
# mesh and discretization, the first (symbolic) factorization, classification and writing the run
# folder.  From <root>/bench/bench.json key "per_run_overhead_s" (``dchfrac bench`` measures it) when
# present, else this default: the committed h = 2 campaigns spent 2.0-2.5 s per run outside the
# solver's time loop (wall_time_s - solver_wall_time_s of their tables) plus about 1 s of solver set-up.
DEFAULT_PER_RUN_OVERHEAD_S = 3.0
# With more than one job each run shares the machine (one core, one BLAS/MKL thread each): the rate above,
# measured on a lone run, is multiplied by the factor ``dchfrac bench`` measures with one run per core
# (bench.json key "shared_run_factor"), else by this default (h = 2 reference case, 2-core machine: 20.0 s side
# by side against 13.1 s alone, results/bench/README.md, ninth round).
DEFAULT_SHARED_RUN_FACTOR = 1.5


def as_spec(spec) -> CampaignSpec:
    """A CampaignSpec from a spec object or a path to a TOML file."""
    return spec if isinstance(spec, CampaignSpec) else load_spec(spec)


# ---------------------------------------------------------------------------
# planning
# ---------------------------------------------------------------------------
class DamagedRunsError(RuntimeError):
    """Stored runs whose files are missing, changed or do not parse (see :func:`sweep.campaign.store.verify_run`)."""


@dataclass
class Plan:
    """The grid of a campaign and what the store already holds for it.

    Each point is exactly one of: damaged (its files fail :func:`verify_run`), done ("ok") or failed (a
    record of a run folder here), archived (no run folder here, but a row of the committed table:
    :mod:`sweep.campaign.archived`) or pending (neither).  Stale (made by other solver code: recorded
    ``code_hash`` != ``code_hash``; a record without one is stale) is a note on done, failed and archived
    runs, not a state: it decides nothing unless ``rerun_stale`` (then the stale runs with a record are
    neither done nor failed: :func:`run_campaign` reruns them).
    """

    spec: CampaignSpec
    store: ResultsStore
    points: list[Point]
    keys: list[str]
    records: dict[str, dict]
    code_hash: str
    classifier_hash: str
    rerun_stale: bool = False
    verify: bool = True
    archived_rows: dict[str, dict] = field(default_factory=dict)
    unmatched_rows: list[dict] = field(default_factory=list)
    _problems: dict[str, list[str]] = field(default_factory=dict, repr=False)

    def problems(self, key: str) -> list[str]:
        """What is wrong with the stored run ``key`` ([] = intact, or not verified)."""
        if not self.verify or key not in self.records:
            return []
        if key not in self._problems:
            self._problems[key] = verify_run(self.store.run_dir(key), self.records[key])
        return self._problems[key]

    def add(self, record: Mapping[str, Any]) -> None:
        """Take in the record of a run just finished (intact by construction)."""
        self.records[record["key"]] = dict(record)
        self._problems[record["key"]] = []

    def is_stale(self, key: str) -> bool:
        """Whether the run of ``key`` (its record, else its archived row) was made by other solver code."""
        rec = self.records.get(key) or self.archived_rows.get(key) or {}
        return rec.get("code_hash") != self.code_hash

    def _with(self, pred) -> list[tuple[Point, str]]:
        return [(p, k) for p, k in zip(self.points, self.keys) if pred(k, self.records.get(k))]

    def _usable(self, k, r) -> bool:
        return r is not None and not self.problems(k) and not (self.rerun_stale and self.is_stale(k))

    @property
    def done(self):
        return self._with(lambda k, r: self._usable(k, r) and r.get("status") == "ok")

    @property
    def failed(self):
        return self._with(lambda k, r: self._usable(k, r) and r.get("status") != "ok")

    @property
    def pending(self):
        return self._with(lambda k, r: r is None and k not in self.archived_rows)

    @property
    def archived(self):
        """Points without a run folder here whose row is in the committed table."""
        return self._with(lambda k, r: r is None and k in self.archived_rows)

    def archived_status(self, status: str = "ok"):
        """The archived points whose committed row has ``status`` ("ok") or another one (any other value)."""
        ok = status == "ok"
        return [(p, k) for p, k in self.archived if (self.archived_rows[k].get("status") == "ok") == ok]

    @property
    def damaged(self):
        return self._with(lambda k, r: r is not None and bool(self.problems(k)))

    @property
    def stale(self):
        """Intact runs and archived rows made by other solver code (rerun by run_campaign only with rerun_stale)."""
        return self._with(lambda k, r: (r is not None and not self.problems(k) or k in self.archived_rows)
                          and self.is_stale(k))

    @property
    def misclassified(self):
        """Done runs labelled by sweep.regimes.classify of other classifier code (reclassified by run_campaign)."""
        return [(p, k) for p, k in self.done
                if self.records[k].get("classifier_hash") not in (None, self.classifier_hash)]

    def damage_text(self) -> str:
        """One line per damaged run: key, swept values, problems."""
        return "\n".join(f"  damaged {k} ({_swept_text(p)}): {'; '.join(self.problems(k))}" for p, k in self.damaged)


def _swept_text(p: Point) -> str:
    return ", ".join(f"{a}={v}" for a, v in p.swept.items())


def _keys(points: Sequence[Point]) -> list[str]:
    return [run_key(p.params, p.options) for p in points]


def plan_campaign(spec, root=DEFAULT_ROOT, *, code_hash: str | None = None, points: Sequence[Point] | None = None,
                  rerun_stale: bool = False, verify: bool = True) -> Plan:
    """Expand the spec's initial points and look their keys up in the store and the committed table.

    root : results root (a relative one is resolved against the spec's project root:
        :func:`sweep.campaign.paths.results_root`).
    code_hash : the current solver code (default :func:`sweep.campaign.store.current_code_hash`); records of
        other code are stale. rerun_stale : count stale runs with a record as neither done nor failed (to be
        rerun). verify : check each stored run's files against its record (:func:`sweep.campaign.store.verify_run`).
    """
    from sweep.campaign.archived import match_committed, read_committed_table, row_values

    spec = as_spec(spec)
    root = results_root(spec, root)
    code_hash = current_code_hash() if code_hash is None else code_hash
    pts = list(points) if points is not None else samplers()[spec.sampler["kind"]]().initial(spec)
    store = ResultsStore(root, spec.name)
    keys = _keys(pts)
    recs = {k: r for k in keys if (r := store.read_record(k)) is not None}
    if points is None and spec.sampler["kind"] != "grid":  # the runs a sampler added in earlier rounds
        for k, r in store.records().items():
            if k not in recs and k not in keys:
                pts.append(Point(r["params"], r["options"], {}, ("refined",), len(pts)))
                keys.append(k)
                recs[k] = r
    plan = Plan(spec, store, pts, keys, recs, code_hash, current_classifier_hash(), rerun_stale, verify)
    for k in keys:
        if k not in recs and store.run_dir(k).exists():  # a finished folder whose record was lost or broken
            recs[k] = {"key": k, "status": "damaged"}
            plan._problems[k] = ["record.json is missing or does not parse"]
    committed = read_committed_table(store.dir)
    if committed is not None:
        rows = [row_values(r) for r in committed.to_dict("records")]
        here = set(recs) | {r["key"] for r in rows if isinstance(r.get("key"), str) and store.run_dir(r["key"]).is_dir()}
        plan.archived_rows, unmatched = match_committed(pts, keys, set(recs), [r for r in rows if r.get("key") not in here])
        plan.unmatched_rows = unmatched
    return plan


def check_intact(plan: Plan, allow_damaged: bool = False) -> None:
    """Raise DamagedRunsError naming the plan's damaged runs (a warning on stderr with ``allow_damaged``)."""
    if not plan.damaged:
        return
    msg = (f"campaign {plan.spec.name}: {len(plan.damaged)} damaged run(s) (files missing, changed or unreadable "
           f"since their record was written); `dchfrac campaign run {plan.spec.source}` reruns them:\n"
           + plan.damage_text())
    if not allow_damaged:
        raise DamagedRunsError(msg)
    print(f"warning: {msg}\n  (left out)", file=sys.stderr)


# ---------------------------------------------------------------------------
# the table
# ---------------------------------------------------------------------------
_numbers_cache: dict[str, dict] = {}


def _numbers(params: Mapping[str, Any]) -> dict:
    """Dimensionless numbers of a run from sweep.regimes.numbers (empty if that module is unavailable)."""
    key = json.dumps(params, sort_keys=True, default=str)
    if key in _numbers_cache:
        return _numbers_cache[key]
    out: dict = {}
    try:
        from solver.params import Parameters
        from sweep.regimes.numbers import dimensionless_numbers

        res = dimensionless_numbers(_numbers_input(Parameters.from_dict(dict(params)).to_dict()))
        out = {k: v for k, v in dict(res).items() if _is_scalar(v)}
    except Exception:  # noqa: BLE001 - the table must build without the numbers module
        out = {}
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
    for k in ("wall_time_s", "attempts", "code_hash", "classifier_hash", "host", "finished_at"):
        put(k, rec.get(k), "rec_")
    return row


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
    return ResultsStore(root, spec.name).write_table(df, swept=spec.axis_names)


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


# ---------------------------------------------------------------------------
# running
# ---------------------------------------------------------------------------
@dataclass
class CampaignResult:
    """Outcome of :func:`run_campaign`."""

    name: str
    n_points: int
    n_executed: int
    n_ok: int
    n_failed: int
    n_skipped: int
    aborted: bool
    table_paths: list[Path]
    table: Any = None
    failures: list[tuple[str, str]] = field(default_factory=list)
    stale_rerun: list[str] = field(default_factory=list)
    stale_reused: list[str] = field(default_factory=list)
    damaged_rerun: list[str] = field(default_factory=list)
    reclassified: list[str] = field(default_factory=list)


class Progress:
    """Progress line: runs done and failed, pending, elapsed, ETA (to ``stream``)."""

    def __init__(self, name: str, total: int, already: int, stream: TextIO | None):
        self.name, self.total, self.already, self.stream = name, total, already, stream
        self.t0 = time.perf_counter()
        self.ok = self.failed = 0

    def update(self, rec: Mapping[str, Any]) -> None:
        if rec.get("status") == "ok":
            self.ok += 1
        else:
            self.failed += 1
        if self.stream is None:
            return
        n = self.ok + self.failed
        elapsed = time.perf_counter() - self.t0
        remaining = self.total - self.already - n
        eta = elapsed / n * remaining if n else float("nan")
        line = (f"[{self.name}] {self.already + n}/{self.total} done ({self.failed} failed this session), "
                f"{remaining} pending, elapsed {_hms(elapsed)}, ETA {_hms(eta)} | {rec.get('key')} "
                f"{rec.get('status')} {rec.get('wall_time_s', 0):.1f}s")
        if rec.get("status") != "ok":
            line += f": {rec.get('reason')}"
        print(line, file=self.stream, flush=True)


def _hms(s: float) -> str:
    from solver.progress import format_duration

    return format_duration(s)


def _make_runner(spec: CampaignSpec, runner) -> Callable:
    if runner is not None:
        return resolve_runner(runner) if isinstance(runner, str) else runner
    if spec.run.get("runner"):
        return resolve_runner(spec.run["runner"])
    return DefaultRunner(spec.classify)


def run_campaign(
    spec,
    root=DEFAULT_ROOT,
    *,
    jobs: int | None = None,
    backend: str = "loky",
    scheduler: str | None = None,
    timeout: float | None | str = "spec",
    retries: int | None = None,
    fail_fast: bool = False,
    retry_failed: bool = False,
    rerun_stale: bool = False,
    rerun_archived: bool = False,
    runner: Callable | str | None = None,
    isolate: str | None = None,
    code_hash: str | None = None,
    progress: TextIO | None = sys.stderr,
    table_interval: float = 2.0,
) -> CampaignResult:
    """Run every pending, damaged and stale point of ``spec`` and keep the table up to date.

    jobs : parallel runs (default spec ``[run] jobs`` or 1; -1 = all cores).
    backend, scheduler : "loky" | "dask" | "ray" and the cluster address (see sweep.campaign.scheduler).
    timeout : s per run attempt; "spec" = spec ``[run] timeout`` (None: unlimited).
    retries : extra attempts after a failure (default spec ``[run] retries`` or 0).
    fail_fast : stop at the first failed run (runs not yet started are cancelled).
    retry_failed : rerun points whose record is "failed" (otherwise they are skipped).
    rerun_stale : rerun the runs made by other solver code (by default they are kept, listed in
        ``stale_reused``, like archived rows made by other code).
    rerun_archived : rerun the archived points (committed rows without a run folder here).
    runner : callable or "module:function" (default spec ``[run] runner`` or DefaultRunner).
    isolate : "auto" | "process" | "none" (default spec ``[run] isolate`` or "auto").
    code_hash : the solver code recorded in each record (default :func:`sweep.campaign.store.current_code_hash`).
    progress : stream for the progress line (None: quiet).
    table_interval : s between table rewrites while running (always written at the end).
    """
    spec = as_spec(spec)
    root = results_root(spec, root)
    jobs, timeout, retries, isolate = _check_run_settings(spec, jobs, timeout, retries, isolate)
    runner_fn = _make_runner(spec, runner)
    code_hash = current_code_hash() if code_hash is None else code_hash
    sampler = samplers()[spec.sampler["kind"]]()
    store = ResultsStore(root, spec.name)
    store.acquire_lock()
    try:
        store.clean_tmp()
        cfg = ExecConfig(root=str(Path(root).resolve()), campaign=spec.name, runner=runner_fn, timeout=timeout,
                         retries=retries, isolate=isolate, blas_threads=1 if jobs > 1 or backend != "loky" else None,
                         code_hash=code_hash)
        points = sampler.initial(spec)
        result = CampaignResult(spec.name, 0, 0, 0, 0, 0, False, [])
        plan = None
        while points:
            plan = plan_campaign(spec, root, code_hash=code_hash, points=points, rerun_stale=rerun_stale)
            todo = _todo(plan, retry_failed, rerun_archived)
            _book_round(result, plan, len(points), rerun_stale)
            if progress is not None:
                print(f"[{spec.name}] {len(points)} runs: {_counts_text(plan)}; executing {len(todo)} on {backend} "
                      f"with {jobs} job(s)", file=progress, flush=True)
            if todo:
                _save_spec(spec, store)
            try:
                _execute(plan, todo, cfg, result, jobs=jobs, backend=backend, scheduler=scheduler,
                         fail_fast=fail_fast, progress=progress, table_interval=table_interval)
            finally:
                # whatever happened (Ctrl-C included), the table reflects every finished run
                plan = plan_campaign(spec, root, code_hash=code_hash, points=points, rerun_stale=rerun_stale)
                if todo or not store.table_csv.is_file():  # a committed table is rewritten only by new runs
                    result.table_paths = write_table(spec, root, plan=plan)
            if result.aborted:
                break
            result.reclassified += _reclassify_keys(plan, [k for _, k in plan.misclassified], spec.classify)
            points = _refined_points(sampler, spec, root, plan, store, points, write=bool(todo))
        result.n_skipped = result.n_points - result.n_executed
        if result.reclassified:
            result.table_paths = write_table(spec, root, plan=plan)
        result.table = build_table(spec, root, plan=plan)
        return result
    finally:
        store.clean_tmp()
        store.release_lock()


def _book_round(result: CampaignResult, plan: Plan, n_points: int, rerun_stale: bool) -> None:
    """Count a round's damaged runs (rerun) and stale runs (rerun with ``rerun_stale``, else reused)."""
    stale = [k for _, k in plan.stale]
    result.damaged_rerun += [k for _, k in plan.damaged]
    result.stale_reused += [] if rerun_stale else stale
    result.stale_rerun += stale if rerun_stale else []
    result.n_points = n_points


def _refined_points(sampler, spec: CampaignSpec, root, plan: Plan, store: ResultsStore, points: list,
                    write: bool = True) -> list:
    """The points of the next round: ``points`` plus the sampler's new ones, or [] when it adds none;
    ``sampler.json`` is rewritten when ``write`` (runs were made this round) or missing."""
    table = build_table(spec, root, plan=plan)
    new = [p for p in sampler.refine(spec, table) if run_key(p.params, p.options) not in set(plan.keys)]
    if write or not (store.dir / "sampler.json").is_file():
        _write_sampler_state(sampler, spec, table, store)
    return points + new if new else []


def _check_run_settings(spec: CampaignSpec, jobs, timeout, retries, isolate):
    """(jobs, timeout s, retries, isolate) from the arguments and the spec's [run] table; ValueError if bad."""
    jobs = int(spec.run.get("jobs", 1) if jobs is None else jobs)
    if jobs == -1:
        jobs = os.cpu_count() or 1
    if jobs < 1:
        raise ValueError(f"jobs={jobs} must be >= 1 or -1 (all cores)")
    timeout = spec.run.get("timeout") if timeout == "spec" else timeout
    if timeout is not None and not timeout > 0:
        raise ValueError(f"timeout={timeout!r} must be > 0 s or None")
    retries = int(spec.run.get("retries", 0) if retries is None else retries)
    if retries < 0:
        raise ValueError(f"retries={retries} must be >= 0")
    isolate = isolate or spec.run.get("isolate", "auto")
    if isolate not in ("auto", "process", "none"):
        raise ValueError(f"isolate={isolate!r} must be one of auto, process, none")
    if isolate == "none" and timeout is not None:
        raise ValueError("a per-run timeout needs the run in a child process: isolate='auto' or 'process'")
    return jobs, timeout, retries, isolate


def _todo(plan: Plan, retry_failed: bool, rerun_archived: bool = False) -> list[tuple[Point, str]]:
    """Points to execute, in grid order: pending, damaged, stale (with ``plan.rerun_stale``), failed (if
    retried; archived failed rows too), archived (with ``rerun_archived``)."""
    stale = plan.stale if plan.rerun_stale else []
    failed = plan.failed + plan.archived_status("failed") if retry_failed else []
    todo = plan.pending + plan.damaged + stale + failed + (plan.archived if rerun_archived else [])
    unique = {k: (p, k) for p, k in todo}  # a point both stale and failed is run once
    return sorted(unique.values(), key=lambda pk: pk[0].index)


def _counts_text(plan: Plan) -> str:
    """"a done, b failed, c pending" plus the stale (made by other code) and damaged counts."""
    text = f"{len(plan.done)} done, {len(plan.failed)} failed, {len(plan.pending)} pending"
    if plan.stale:
        text += (f", {len(plan.stale)} made by other code (stale: to rerun)" if plan.rerun_stale
                 else f", {len(plan.stale)} made by other code (stale: kept)")
    if plan.damaged:
        text += f", {len(plan.damaged)} damaged"
    return text


def _execute(plan: Plan, todo, cfg: ExecConfig, result: CampaignResult, *, jobs, backend, scheduler, fail_fast,
             progress, table_interval) -> None:
    """Execute ``todo`` through sweep.campaign.scheduler, counting into ``result`` and rewriting the table now and then."""
    prog = Progress(plan.spec.name, len(plan.points), len(plan.points) - len(todo), progress)
    tasks = [RunTask(k, p.params, p.options, p.index) for p, k in todo]
    last_write = time.perf_counter()
    gen = iter_records(tasks, cfg, jobs=jobs, backend=backend, scheduler=scheduler)
    try:
        for rec in gen:
            result.n_executed += 1
            prog.update(rec)
            plan.add(rec)
            if rec.get("status") == "ok":
                result.n_ok += 1
            else:
                result.n_failed += 1
                result.failures.append((rec["key"], str(rec.get("reason"))))
                if fail_fast:
                    result.aborted = True
                    break
            if time.perf_counter() - last_write > table_interval:
                plan.store.write_table(build_table(plan.spec, plan=plan), swept=plan.spec.axis_names)
                last_write = time.perf_counter()
    finally:
        gen.close()


def _write_sampler_state(sampler, spec: CampaignSpec, table, store: ResultsStore) -> None:
    """``sampler.json``: where an adaptive sampler stands (round, runs of the budget, why it stopped)."""
    if hasattr(sampler, "state"):
        from sweep.campaign.store import write_json_atomic

        write_json_atomic(store.dir / "sampler.json", sampler.state(spec, table))


def sampler_status(spec, root=DEFAULT_ROOT, *, code_hash: str | None = None, table=None) -> dict | None:
    """The adaptive sampler's state dict (see ``sweep.campaign.boundary.BoundarySampler.state``), None for the grid."""
    spec = as_spec(spec)
    root = results_root(spec, root)
    sampler = samplers()[spec.sampler["kind"]]()
    if not hasattr(sampler, "state"):
        return None
    table = build_table(spec, root, code_hash=code_hash) if table is None else table
    return sampler.state(spec, table)


def _save_spec(spec: CampaignSpec, store: ResultsStore) -> None:
    store.dir.mkdir(parents=True, exist_ok=True)
    src = Path(spec.source)
    if src.is_file():
        write_text_atomic(store.dir / "spec.toml", src.read_text())


# ---------------------------------------------------------------------------
# dry run: cost estimate
# ---------------------------------------------------------------------------
def _load_bench(root) -> dict:
    p = Path(root) / "bench" / "bench.json"
    try:
        return json.loads(p.read_text())
    except (FileNotFoundError, json.JSONDecodeError):
        return {}


def wall_per_sim_second(h: float, bench: Mapping[str, Any] | None = None) -> tuple[float, str]:
    """Estimated wall seconds per simulated second of one coupled run at mesh size ``h`` (mm),
    and where the figure comes from ("bench h=..", "bench h=2 scaled", "default")."""
    bench = bench or {}
    exact = bench.get(f"coupled_run_h{h:g}_wall_s_per_sim_s")
    if isinstance(exact, (int, float)) and exact > 0:
        return float(exact), f"bench h={h:g}"
    c2 = bench.get("coupled_run_h2_wall_s_per_sim_s")
    src = "bench h=2 scaled"
    if not (isinstance(c2, (int, float)) and c2 > 0):
        c2, src = DEFAULT_WALL_S_PER_SIM_S_H2, "default"
    return float(c2) * (2.0 / float(h)) ** COST_MESH_EXPONENT, src


def per_run_overhead(bench: Mapping[str, Any] | None = None) -> tuple[float, str]:
    """Fixed wall seconds of one campaign run besides its time loop, and where the figure comes from
    ("bench" or "default"); see DEFAULT_PER_RUN_OVERHEAD_S."""
    v = (bench or {}).get("per_run_overhead_s")
    if isinstance(v, (int, float)) and v >= 0:
        return float(v), "bench"
    return DEFAULT_PER_RUN_OVERHEAD_S, "default"


def shared_run_factor(jobs: int, bench: Mapping[str, Any] | None = None) -> tuple[float, str]:
    """How much longer a run takes beside others than alone with every core (1 for one job), and where the
    figure comes from ("one job", "bench" or "default"); see DEFAULT_SHARED_RUN_FACTOR."""
    if jobs <= 1:
        return 1.0, "one job"
    v = (bench or {}).get("shared_run_factor")
    if isinstance(v, (int, float)) and v > 0:
        return float(v), "bench"
    return DEFAULT_SHARED_RUN_FACTOR, "default"


def estimated_sim_time(params: Mapping[str, Any], options: Mapping[str, Any]) -> float:
    """Simulated time of a run, s: t_end, or less when the front should reach stop_front_radius first.

    The front estimate fills the porosity: φ π (r² − r_i²) = 2 π r_i w_i t (per unit gap height),
    so t = φ (r_stop² − r_i²) / (2 r_i w_i).
    """
    t_end = float(options.get("t_end", 2.0))
    r_stop = options.get("stop_front_radius")
    w_i, r_i, phi = params.get("w_i"), params.get("r_inner", 5.0), params.get("phi_mean", 0.4)
    if r_stop is None or not w_i or w_i <= 0 or r_stop <= r_i:
        return t_end
    return min(t_end, phi * (r_stop**2 - r_i**2) / (2.0 * r_i * w_i))


def estimate_cost(spec, root=DEFAULT_ROOT, *, jobs: int = 1, code_hash: str | None = None,
                  retry_failed: bool = False, rerun_stale: bool = False, rerun_archived: bool = False) -> dict:
    """Grid size and estimated wall time (s) of the runs to do (pending, damaged, stale unless
    ``rerun_stale``, failed with ``retry_failed``, archived with ``rerun_archived``) of a campaign on ``jobs`` workers.

    Per run: :func:`per_run_overhead` plus :func:`wall_per_sim_second` (bench figures or the documented
    default) times :func:`shared_run_factor` (a run beside others is slower than alone) times
    :func:`estimated_sim_time`; the sum divided by ``jobs`` (perfect packing: a lower bound of the wall time
    when runs differ much in cost). Failed runs count only with ``retry_failed``.
    """
    spec = as_spec(spec)
    root = results_root(spec, root)
    plan = plan_campaign(spec, root, code_hash=code_hash, rerun_stale=rerun_stale)
    bench = _load_bench(root)
    overhead, overhead_src = per_run_overhead(bench)
    shared, shared_src = shared_run_factor(jobs, bench)
    per_h: dict[float, dict] = {}
    total = 0.0
    todo = _todo(plan, retry_failed, rerun_archived)
    n_todo = len(todo)
    for p, k in todo:
        h = float(p.options.get("h", 1.0))
        c, src = wall_per_sim_second(h, bench)
        c *= shared
        t = estimated_sim_time(p.params, p.options)
        d = per_h.setdefault(h, {"runs": 0, "sim_s": 0.0, "wall_s": 0.0, "wall_s_per_sim_s": c, "source": src,
                                 "overhead_s": 0.0})
        d["runs"] += 1
        d["sim_s"] += t
        d["overhead_s"] += overhead
        d["wall_s"] += c * t + overhead
        total += c * t + overhead
    return {
        "name": spec.name,
        "grid_size": len(plan.points),
        "done": len(plan.done),
        "failed": len(plan.failed),
        "pending": len(plan.pending),
        "stale": len(plan.stale) if rerun_stale else 0,
        "stale_kept": 0 if rerun_stale else len(plan.stale),
        "archived": len(plan.archived),
        "runs_to_do": n_todo,
        "damaged": len(plan.damaged),
        "by_mesh_size": per_h,
        "cpu_s": total,
        "wall_s": total / max(1, jobs),
        "jobs": jobs,
        "per_run_overhead_s": overhead,
        "per_run_overhead_source": overhead_src,
        "shared_run_factor": shared,
        "shared_run_factor_source": shared_src,
    }


# ---------------------------------------------------------------------------
# reclassification
# ---------------------------------------------------------------------------
def reclassify(spec, root=DEFAULT_ROOT, *, code_hash: str | None = None, allow_damaged: bool = False) -> int:
    """Rerun ``sweep.regimes.classify.classify_run`` on every intact finished ("ok") run, whatever code made
    it, and rewrite its record (no simulation is rerun). Returns the number of runs updated.

    Raises DamagedRunsError naming the damaged runs unless ``allow_damaged`` (then they are left out).
    A run the classifier cannot read loses its label (``metrics.classify_error`` says why).
    """
    spec = as_spec(spec)
    root = results_root(spec, root)
    plan = plan_campaign(spec, root, code_hash=code_hash)
    check_intact(plan, allow_damaged)
    n = len(_reclassify_keys(plan, [k for _, k in plan.done], spec.classify))
    write_table(spec, root, plan=plan)
    return n


def _reclassify_keys(plan: Plan, keys: Sequence[str], classify_options: Mapping[str, Any]) -> list[str]:
    """Classify the stored runs ``keys`` with the current classifier and rewrite their records (a run that
    cannot be classified loses its label); returns ``keys``."""
    from sweep.regimes.classify import classify_run
    from sweep.campaign.store import write_json_atomic

    done = []
    for k in keys:
        rd = plan.store.run_dir(k)
        rec = dict(plan.records[k])
        rec["metrics"] = dict(rec.get("metrics") or {})
        try:
            cls = classification_dict(classify_run(str(rd), **classify_options))
            rec["classification"] = json.loads(json.dumps(cls, default=_json_default))
            rec["classifier_hash"] = plan.classifier_hash
            rec["metrics"].pop("classify_error", None)
        except Exception as e:  # noqa: BLE001 - the run stays; its label is gone and the error recorded
            rec["classification"] = {}
            rec.pop("classifier_hash", None)
            rec["metrics"]["classify_error"] = f"{type(e).__name__}: {e}"
        write_json_atomic(rd / "record.json", rec)
        plan.records[k] = rec
        done.append(k)
    return done


def _json_default(o):
    if hasattr(o, "item"):
        return o.item()
    if hasattr(o, "tolist"):
        return o.tolist()
    return str(o)


# ---------------------------------------------------------------------------
# diagrams
# ---------------------------------------------------------------------------
_REGIME_STYLE = {
    "porous_invasion": ("o", "tab:blue"),
    "uniform_invasion": ("o", "tab:blue"),
    "viscous_fingering": ("*", "tab:blue"),
    "fracturing": ("^", "tab:orange"),
    "invasive_fracturing": ("^", "tab:orange"),
    "non_invasive_fracturing": ("s", "tab:orange"),
    "fracturing_fingering": ("X", "tab:orange"),
}


def _scatter(df, x, y, ax, *, by="regime", logx=False, logy=False):
    import numpy as np

    groups = df[by].fillna("failed" if by == "regime" else "?") if by in df.columns else None
    if groups is None:
        ax.plot(df[x], df[y], "o")
    else:
        for g, sub in df.groupby(groups):
            m, c = _REGIME_STYLE.get(str(g), ("d", None))
            ax.scatter(sub[x], sub[y], marker=m, color=c, label=str(g), s=45, edgecolor="k", linewidth=0.4)
        ax.legend(fontsize=8)
    if logx:
        ax.set_xscale("log")
    if logy:
        ax.set_yscale("log")
    from sweep.campaign.figures import axis_label

    ax.set_xlabel(axis_label(x))
    ax.set_ylabel(axis_label(y))
    ax.grid(True, which="both", alpha=0.3)
    return np.asarray(df[x]).size


def _timeseries_plot(spec, store, table, g, path) -> list[Path]:
    """One curve per ok run of time-series column ``y`` against ``x``, labelled by its swept values (units)."""
    import matplotlib.pyplot as plt
    import pandas as pd

    from sweep.campaign.figures import axis_label, save_figure, swept_label

    fig, ax = plt.subplots(figsize=(6, 4))
    names = [g["by"]] if g.get("by") else list(spec.axis_names)
    missing = []
    for _, row in table[table["status"] == "ok"].iterrows():
        f = store.run_dir(row["key"]) / "timeseries.csv"
        if not f.exists():
            missing.append(row["key"])
            continue
        ts = pd.read_csv(f)
        if g["x"] in ts.columns and g["y"] in ts.columns:
            ax.plot(ts[g["x"]], ts[g["y"]], label=swept_label(row, names) or row["key"])
    ax.set_xlabel(axis_label(g["x"]))
    ax.set_ylabel(axis_label(g["y"]))
    ax.grid(True, alpha=0.3)
    if ax.lines:
        ax.legend(fontsize=7)
    ax.set_title(g.get("title", spec.name))
    if _keep_committed(path, drawn=len(ax.lines), missing=missing, why="no timeseries.csv"):
        plt.close(fig)
        return []
    paths = save_figure(fig, path)
    plt.close(fig)
    _warn_left_out(path, missing, "no timeseries.csv")
    return paths


def _keep_committed(path: Path, *, drawn: int, missing: Sequence[str], why: str) -> bool:
    """True (with a warning) when a figure would show nothing, or would replace an existing file while
    leaving runs out (their run folders are archived): the existing figure is kept."""
    if drawn and not (missing and path.is_file()):
        return False
    kept = "kept as it is" if path.is_file() else "not drawn"
    print(f"warning: {path.name} {kept}: {len(missing)} of {drawn + len(missing)} run(s) have {why} here "
          f"(pruned or archived run folders)", file=sys.stderr)
    return True


def _warn_left_out(path: Path, keys: Sequence[str], why: str) -> None:
    """Say on stderr which finished runs a figure does not show."""
    if keys:
        print(f"warning: {path.name} leaves out {len(keys)} run(s) ({why}): {' '.join(keys)}", file=sys.stderr)


def _snapshot(run_dir: Path, time_s=None):
    import numpy as np

    snaps = sorted((run_dir / "snapshots").glob("snap_*.npz"))
    mesh = run_dir / "snapshots" / "mesh.npz"
    if not snaps or not mesh.exists():
        return None
    if time_s is not None:
        ts = [float(np.load(s)["t"]) for s in snaps]
        snap = snaps[int(np.argmin([abs(t - time_s) for t in ts]))]
    else:
        snap = snaps[-1]
    m, s = np.load(mesh), np.load(snap)
    return m["points"], m["triangles"], s


def _field_rows(spec, ok, rows_col):
    """[(row label, rows of the table)] of a fields grid: one per spec block, per value of a column, or one."""
    from sweep.campaign.figures import value_label

    if rows_col == "blocks":
        rows = []
        for b in spec.blocks:
            sub = ok[ok["blocks"].str.split(";").apply(lambda ls, lab=b.label: lab in ls)]
            if b.axes and b.axes[0].name in sub.columns:
                sub = sub.sort_values(b.axes[0].name, kind="stable")
            rows.append((b.label if len(spec.blocks) > 1 else "", sub))
        return rows
    if rows_col in ok.columns:
        return [(value_label(rows_col, v), ok[ok[rows_col] == v]) for v in dict.fromkeys(ok[rows_col])]
    return [("", ok)]


def _fields_plot(spec, store, table, g, path) -> list[Path]:
    """Grid of field maps (last snapshot, or the one nearest ``time`` s) with the S = 0.5 front in white.

    rows: "blocks" (default: one row per spec block, runs ordered by the block's first axis) or a
    table column; cols: a table column giving the column order (default: run order in the row).
    Every panel shares one colour scale (diverging and centred at zero for a field with both signs),
    shown by one colorbar; row labels on the left, panel titles give the other swept values.
    """
    import matplotlib.pyplot as plt

    from solver.output import SNAPSHOT_FIELDS
    from sweep.campaign.figures import axis_label, colour_scale, save_figure, swept_label

    ok = table[table["status"] == "ok"].sort_values("index")
    rows_col, cols_col = g.get("rows", "blocks"), g.get("cols")
    rows = _field_rows(spec, ok, rows_col)
    cvals = sorted(dict.fromkeys(ok[cols_col])) if cols_col and cols_col in ok.columns else None
    ncols = max(1, len(cvals) if cvals else max((len(sub) for _, sub in rows), default=1))
    panels, missing = [], []
    for i, (_, sub) in enumerate(rows):
        for j, (_, row) in enumerate(sub.iterrows()):
            snap = _snapshot(store.run_dir(row["key"]), g.get("time"))
            if snap is not None and g["field"] in snap[2]:
                panels.append((i, cvals.index(row[cols_col]) if cvals else j, row, snap))
            else:
                missing.append(row["key"])
    if _keep_committed(path, drawn=len(panels), missing=missing, why=f"no snapshot with {g['field']}"):
        return []
    cmap, vmin, vmax = colour_scale(g["field"], [s[g["field"]] for *_, (_, _, s) in panels],
                                    fixed=(0.0, 1.0) if g["field"] in ("phi", "d", "S") else None)
    fig, axes = plt.subplots(len(rows), ncols, figsize=(3 * ncols + 0.8, 3 * len(rows)), squeeze=False)
    for ax in axes.ravel():
        ax.set_axis_off()
    others = [a for a in spec.axis_names if a != rows_col]
    im = None
    for i, j, row, (pts, tri, s) in panels:
        ax = axes[i, j]
        vals = s[g["field"]]
        shading = "flat" if len(vals) == len(tri) else "gouraud"
        im = ax.tripcolor(pts[:, 0], pts[:, 1], tri, vals, shading=shading, cmap=cmap, vmin=vmin, vmax=vmax)
        if "S" in s and len(s["S"]) == len(pts):
            ax.tricontour(pts[:, 0], pts[:, 1], tri, s["S"], levels=[0.5], colors="w", linewidths=0.8)
        ax.set_aspect("equal")
        ax.set_title("\n".join(x for x in (swept_label(row, others), f"t = {float(s['t']):.2f} s") if x), fontsize=7)
    for i, (rlabel, _) in enumerate(rows):
        if rlabel:
            axes[i, 0].annotate(rlabel, xy=(-0.08, 0.5), xycoords="axes fraction", rotation=90, ha="right",
                                va="center", fontsize=8)
    if im is not None:
        unit = SNAPSHOT_FIELDS.get(g["field"], ("",))[0]
        fig.colorbar(im, ax=axes.ravel().tolist(), shrink=0.8, label=axis_label(g["field"]) if unit else g["field"])
    fig.suptitle(g.get("title", f"{spec.name}: {g['field']}"))
    paths = save_figure(fig, path)
    plt.close(fig)
    _warn_left_out(path, missing, f"no snapshot with {g['field']}")
    return paths


def _phase_diagram(spec, table, g, path) -> list[Path]:
    """The paper's diagrams through sweep.regimes.diagrams (ok runs only); PNG (+ the diagram's formats)."""
    from sweep.regimes import diagrams as dg

    ok = table[table["status"] == "ok"]
    kind = g["kind"]
    kw: dict[str, Any] = {"title": g.get("title", f"{spec.name}")}
    if "formats" in g:
        kw["formats"] = tuple(g["formats"])
    if kind == "ca_star_vs_cement":
        need = ("cement", "Ca_star", "fracturing")
        if "fit" in g:
            kw["fit"] = bool(g["fit"])
        fn = dg.plot_ca_star_vs_cement
    else:
        need = ("N_b", "N_f", "regime")
        for k in ("experimental_range", "shade"):
            if k in g:
                kw[k] = g[k]
        if "dp_cri" in ok.columns and len(ok):
            kw["dp_cri"] = float(ok["dp_cri"].iloc[0])
        fn = dg.plot_nf_vs_nb
    if ok.empty or any(c not in ok.columns for c in need):
        return []
    res = fn(ok.reset_index(drop=True), path, **kw)
    paths = res.get("paths") if isinstance(res, Mapping) else None
    return [Path(p) for p in paths] if paths else [path]


def _boundary_figure(spec, store: ResultsStore, table):
    """The boundary sampler's figure (``figures/boundary.png``: classifier, 50 % line, band, runs by
    order) and the table with an ``order`` column (the order the sampler chose each run)."""
    import pandas as pd

    from sweep.regimes import diagrams as dg
    from sweep.campaign.boundary import BoundarySampler
    from sweep.regimes.regime_model import boundary_band
    from sweep.campaign.spec import round_sig

    st = BoundarySampler().replay(spec, table)
    names = list(spec.axis_names)
    pts = pd.DataFrame(st.to_dict(st.model.axes if st.model else ())["points"]) if st.model else None
    if pts is None or len(names) != 2:
        return [], table
    order = {tuple(round_sig(float(v), 10) for v in r[names]): r["order"] for _, r in pts.iterrows()}
    table = table.copy()
    table["order"] = [order.get(tuple(round_sig(float(v), 10) for v in row), math.nan) for row in table[names].to_numpy()]
    unc = "?" if not math.isfinite(st.uncertainty) else f"{st.uncertainty:.2f}"
    title = (f"{spec.name}: {st.runs_used}/{st.budget} runs in {len(st.rounds)} rounds, boundary band "
             f"half-width {unc} x tolerance\n" + (st.reason if st.stopped else "running"))
    res = dg.plot_boundary_sampling(st.model, pts, store.figures_dir / "boundary.png", band=boundary_band(st.model),
                                    title=title)
    return [Path(p) for p in res["paths"]], table


def plot_campaign(spec, root=DEFAULT_ROOT, *, code_hash: str | None = None, table=None,
                  allow_damaged: bool = False) -> list[Path]:
    """Draw the spec's diagrams from the campaign table into ``<root>/<name>/figures/``.

    Without ``table``, the stored runs are verified first: DamagedRunsError names the damaged ones
    unless ``allow_damaged`` (then they are left out of the figures, with a warning).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sweep.campaign.figures import save_figure

    spec = as_spec(spec)
    root = results_root(spec, root)
    store = ResultsStore(root, spec.name)
    if table is None:
        plan = plan_campaign(spec, root, code_hash=code_hash)
        check_intact(plan, allow_damaged)
        table = build_table(spec, root, plan=plan)
    store.figures_dir.mkdir(parents=True, exist_ok=True)
    out = []
    if table.empty:
        return out
    if spec.sampler["kind"] == "boundary":
        figs, table = _boundary_figure(spec, store, table)
        out.extend(figs)
    for i, g in enumerate(spec.diagrams):
        kind = g["kind"]
        path = store.figures_dir / g.get("file", f"{kind}.png" if sum(d["kind"] == kind for d in spec.diagrams) == 1 else f"{kind}_{i}.png")
        if kind in ("ca_star_vs_cement", "nf_vs_nb"):
            out.extend(_phase_diagram(spec, table, g, path))
        elif kind == "scatter":
            if g["x"] not in table.columns or g["y"] not in table.columns:
                continue
            fig, ax = plt.subplots(figsize=(5, 4))
            _scatter(table, g["x"], g["y"], ax, by=g.get("color", "regime"), logx=g.get("logx", False), logy=g.get("logy", False))
            ax.set_title(g.get("title", spec.name))
            out.extend(save_figure(fig, path))
            plt.close(fig)
        elif kind == "timeseries":
            out.extend(_timeseries_plot(spec, store, table, g, path))
        elif kind == "fields":
            out.extend(_fields_plot(spec, store, table, g, path))
    return out


# ---------------------------------------------------------------------------
# report
# ---------------------------------------------------------------------------
def write_report(spec, root=DEFAULT_ROOT, *, code_hash: str | None = None, plot: bool = True,
                 allow_damaged: bool = False) -> Path:
    """Markdown summary of a campaign (``<root>/<name>/report.md``): counts, the code that made the runs,
    regimes, failures with their reasons, the run table's main columns, and the figures (drawn first
    when ``plot``). DamagedRunsError names damaged runs unless ``allow_damaged`` (then listed)."""
    spec = as_spec(spec)
    root = results_root(spec, root)
    store = ResultsStore(root, spec.name)
    plan = plan_campaign(spec, root, code_hash=code_hash)
    check_intact(plan, allow_damaged)
    table = build_table(spec, root, plan=plan)
    check_not_emptier(store, table)
    figs = plot_campaign(spec, root, table=table) if plot else sorted(store.figures_dir.glob("*.png"))
    if not table.empty:
        store.write_table(table, swept=spec.axis_names)
    L = [f"# Campaign `{spec.name}`", ""]
    if spec.description:
        L += [spec.description.strip(), ""]
    if spec.paper:
        L += [f"Paper: {spec.paper}", ""]
    L += [f"Spec: `{spec.source}`.", "", *provenance_lines(plan), "",
          f"- runs in the grid: {len(plan.points)}",
          f"- done: {len(plan.done)}", f"- failed: {len(plan.failed)}", f"- pending: {len(plan.pending)}"]
    if plan.archived or plan.unmatched_rows:
        L.append(f"- archived (rows of the committed table, run folders not here): {_archived_text(plan)}")
    if plan.damaged:
        L += [f"- damaged (left out): {len(plan.damaged)}", "", "```", plan.damage_text(), "```"]
    L.append("")
    if not table.empty and "wall_time_s" in table.columns:
        L += [f"Total wall time of the runs: {table['wall_time_s'].sum():.1f} s "
              f"(median {table['wall_time_s'].median():.1f} s per run).", ""]
    stored = plan.store.records()  # every run of the folder (a sampler's plan holds only its initial design)
    if stored:
        from sweep.campaign.accounting import campaign_throughput

        acc = campaign_throughput(stored).text()
        L += [f"{acc[0].upper()}{acc[1:]} (`sweep/campaign/accounting.py`).", ""]
    if not table.empty and table["regime"].notna().any():
        L += ["## Regimes", "", "| regime | runs |", "|---|---|"]
        for reg, n in table["regime"].fillna("(none)").value_counts().items():
            L.append(f"| {reg} | {n} |")
        L.append("")
    failed = [(k, plan.records[k].get("reason")) for _, k in plan.failed]
    failed += [(plan.archived_rows[k].get("key"), plan.archived_rows[k].get("reason")) for _, k in
               plan.archived_status("failed")]
    if failed:
        L += ["## Failures", "", "| key | reason |", "|---|---|"]
        for k, reason in failed:
            reason = str(reason).replace("|", "\\|").replace("\n", " ")
            L.append(f"| `{k}` | {reason} |")
        L.append("")
    if figs:
        L += ["## Figures", ""]
        pngs = {Path(f).with_suffix("") for f in figs if Path(f).suffix == ".png"}
        for f in figs:
            rel = os.path.relpath(f, store.dir)
            if Path(f).suffix == ".png":
                L += [f"![{Path(f).stem}]({rel})", ""]
            elif Path(f).with_suffix("") in pngs:
                L[-2] += f" ([{Path(f).suffix[1:]}]({rel}))"
            else:
                L += [f"[{Path(f).name}]({rel})", ""]
    if not table.empty:
        cols = [c for c in ["key", "status", "regime", *spec.axis_names] if c in table.columns]
        num_cols = [c for c in table.columns if c.lower().replace("*", "_star") in
                    ("ca_star", "n_f", "n_b", "nf", "nb") and c not in cols]
        cols += num_cols + [c for c in ("wall_time_s",) if c in table.columns]
        L += ["## Runs", "", "| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
        for _, r in table[cols].iterrows():
            L.append("| " + " | ".join(_fmt(r[c]) for c in cols) + " |")
        L.append("")
    L += [f"Table: `{os.path.relpath(store.table_csv, store.dir)}` (also `table.parquet`); the unit and meaning of "
          f"every column: `columns.csv` (`dchfrac campaign columns SPEC`); load both with "
          f"`sweep.load_campaign` / `sweep.load_timeseries`.", ""]
    write_text_atomic(store.report_md, "\n".join(L))
    return store.report_md


class EmptierResultError(RuntimeError):
    """A report or plot would replace a committed table with one of fewer rows."""


def check_not_emptier(store: ResultsStore, table) -> None:
    """Raise EmptierResultError when ``table`` has fewer rows than the campaign's committed table."""
    from sweep.campaign.archived import read_committed_table

    old = read_committed_table(store.dir)
    if old is not None and len(table) < len(old):
        raise EmptierResultError(
            f"campaign {store.name}: the table rebuilt from the spec has {len(table)} rows, the committed "
            f"{store.table_csv} {len(old)}: nothing written (the spec no longer asks for the missing runs, "
            f"or their run folders are damaged; `dchfrac campaign status` lists them)")


def _archived_text(plan: Plan) -> str:
    """"N (a ok, b failed)" of the archived points and, for a sampler, the committed rows of the runs it added."""
    extra = plan.unmatched_rows if plan.spec.sampler["kind"] != "grid" else []
    rows = [plan.archived_rows[k] for _, k in plan.archived] + list(extra)
    ok = sum(r.get("status") == "ok" for r in rows)
    text = f"{len(rows)} ({ok} ok, {len(rows) - ok} failed)"
    if extra:
        text += f", {len(extra)} of them runs the sampler added"
    elif plan.unmatched_rows:
        text += f"; {len(plan.unmatched_rows)} committed rows match no point of the spec (left out)"
    return text


def code_counts(plan: Plan) -> dict[str, int]:
    """{solver code hash: runs of the plan made by it (records, archived rows)}; "pre-hash" for records
    without a hash."""
    out: dict[str, int] = {}
    extra = plan.unmatched_rows if plan.spec.sampler["kind"] != "grid" else []
    recs = [plan.records.get(k) or plan.archived_rows.get(k) for k in plan.keys] + list(extra)
    for r in recs:
        if r is not None:
            h = r.get("code_hash") or "pre-hash"
            out[h] = out.get(h, 0) + 1
    return out


def provenance_lines(plan: Plan) -> list[str]:
    """Markdown lines stating the code that made the stored runs, against the current code."""
    lines = [f"Current code: solver code hash `{plan.code_hash}`, classifier hash `{plan.classifier_hash}` "
             "(`python -m solver.codehash`)."]
    for h, n in code_counts(plan).items():
        who = "pre-hash code (made before runs recorded their code)" if h == "pre-hash" else f"code hash `{h}`"
        lines.append(f"- {n} run(s) made by {who}{' (current)' if h == plan.code_hash else ' (other code: stale)'}")
    lines.append("Stale runs are used like the others; `dchfrac campaign run SPEC --rerun-stale` reruns them.")
    return lines


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v).replace("|", "\\|")
