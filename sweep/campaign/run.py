"""Run a campaign resumably, and relabel its finished runs.

    res = run_campaign("campaigns/examples/demo.toml", jobs=2)      # CampaignResult
    reclassify(spec)                                                # the classifier rerun on finished runs

A rerun skips every key with an intact record ("ok" or "failed"; ``retry_failed=True`` reruns the failures),
so an interrupted campaign loses at most its runs in flight.  It reruns damaged runs
(:func:`sweep.campaign.store.verify_run`).  Runs made by other solver code (stale) are kept unless
``rerun_stale=True``; archived runs (committed rows without a run folder here) unless ``rerun_archived=True``;
labels made by other classifier code unless ``relabel=True``.  Nothing made by other code is redone silently: the
table's ``code_hash`` and ``classifier_hash`` columns show what made each row.
"""
from __future__ import annotations

import json
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence, TextIO

from sweep.campaign.paths import DEFAULT_ROOT, results_root
from sweep.campaign.plan import Plan, _counts_text, _keys, _todo, as_spec, check_intact, check_same_campaign, plan_campaign
from sweep.campaign.scheduler import DefaultRunner, ExecConfig, RunTask, classification_dict, iter_records
from sweep.campaign.spec import CampaignSpec, resolve_runner, samplers
from sweep.campaign.store import ResultsStore, current_code_hash, run_key, write_text_atomic
from sweep.campaign.replicates import write_points
from sweep.campaign.table import build_table, write_table

__all__ = ["CampaignResult", "run_campaign", "reclassify", "sampler_status"]


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
    labels_kept: list[str] = field(default_factory=list)   # labelled by other classifier code, kept (no relabel)


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
    relabel: bool = False,
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
    relabel : relabel the finished runs whose labels were made by other classifier code (by default they keep
        their labels, are listed in ``labels_kept`` and the table shows each row's ``classifier_hash``).
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
    store.load_writers()          # before any run: the way out of a Ctrl-C writes the table without an import
    store.acquire_lock()
    try:
        store.clean_tmp()
        points = sampler.initial(spec)
        check_same_campaign(spec, store, _keys(points))
        cfg = ExecConfig(root=str(Path(root).resolve()), campaign=spec.name, runner=runner_fn, timeout=timeout,
                         retries=retries, isolate=isolate, blas_threads=1 if jobs > 1 or backend != "loky" else None,
                         code_hash=code_hash)
        result = CampaignResult(spec.name, 0, 0, 0, 0, 0, False, [])
        plan = None
        while points:
            todo, plan = _run_round(spec, root, store, cfg, result, points, code_hash=code_hash,
                                    retry_failed=retry_failed, rerun_stale=rerun_stale, rerun_archived=rerun_archived,
                                    jobs=jobs, backend=backend, scheduler=scheduler, fail_fast=fail_fast,
                                    progress=progress, table_interval=table_interval)
            if result.aborted:
                break
            other_labels = [k for _, k in plan.misclassified]
            if relabel:
                result.reclassified += _reclassify_keys(plan, other_labels, spec.classify)
            else:
                result.labels_kept = sorted(set(result.labels_kept) | set(other_labels))
            points = _refined_points(sampler, spec, root, plan, store, points, write=bool(todo), progress=progress)
        result.n_skipped = result.n_points - result.n_executed
        if result.reclassified:
            result.table_paths = write_table(spec, root, plan=plan)
        result.table = build_table(spec, root, plan=plan)
        return result
    finally:
        store.clean_tmp()
        store.release_lock()


def _run_round(spec, root, store, cfg, result, points, *, code_hash, retry_failed, rerun_stale, rerun_archived,
               jobs, backend, scheduler, fail_fast, progress, table_interval):
    """One round of a campaign: plan ``points``, execute what is to do, and rewrite the table from every finished
    run (Ctrl-C included).  Returns (the runs executed, the plan after them)."""
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
    return todo, plan


def _book_round(result: CampaignResult, plan: Plan, n_points: int, rerun_stale: bool) -> None:
    """Count a round's damaged runs (rerun) and stale runs (rerun with ``rerun_stale``, else reused)."""
    stale = [k for _, k in plan.stale]
    result.damaged_rerun += [k for _, k in plan.damaged]
    result.stale_reused += [] if rerun_stale else stale
    result.stale_rerun += stale if rerun_stale else []
    result.n_points = n_points


def _refined_points(sampler, spec: CampaignSpec, root, plan: Plan, store: ResultsStore, points: list,
                    write: bool = True, progress=None) -> list:
    """The points of the next round: ``points`` plus the sampler's new ones, or [] when it adds none;
    ``sampler.json`` is rewritten when ``write`` (runs were made this round) or missing, and the sampler's
    standing printed to ``progress`` (the round lines count this round's plan only: a resumed sampler replays
    its earlier rounds from the table)."""
    table = build_table(spec, root, plan=plan)
    new = [p for p in sampler.refine(spec, table) if run_key(p.params, p.options) not in set(plan.keys)]
    if write or not (store.dir / "sampler.json").is_file():
        st = _write_sampler_state(sampler, spec, table, store)
        if progress is not None and st:
            print(f"[{spec.name}] {_sampler_text(st)}", file=progress, flush=True)
    return points + new if new else []


def _sampler_text(st: dict) -> str:
    """One line of an adaptive sampler's standing (its ``state`` dict): round, runs of the budget, pending runs,
    the band's half-width when it has one, why it stopped."""
    band = st.get("band_half_width_decades")
    return (f"sampler: round {st['round']}, {st['runs_used']} of {st['budget']} runs used, {st['pending']} pending"
            + (f", band half-width {band:.3g} decades" if band is not None else "")
            + (f"; stopped: {st['reason']}" if st.get("stopped") else ""))


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
            if time.perf_counter() - last_write > table_interval:   # the table and its points, never one alone
                table = build_table(plan.spec, plan=plan)
                plan.store.write_table(table, swept=plan.spec.axis_names)
                write_points(plan.spec, table, plan.store)
                last_write = time.perf_counter()
    finally:
        gen.close()


def _write_sampler_state(sampler, spec: CampaignSpec, table, store: ResultsStore) -> dict | None:
    """``sampler.json``: where an adaptive sampler stands (round, runs of the budget, why it stopped); returns
    that state (None for a grid)."""
    if not hasattr(sampler, "state"):
        return None
    from sweep.campaign.store import write_json_atomic

    st = sampler.state(spec, table)
    write_json_atomic(store.dir / "sampler.json", st)
    return st


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
    if src.is_file():     # with its [base] model files beside it (sweep.campaign.base_model)
        from sweep.campaign.base_model import spec_copy_text

        write_text_atomic(store.dir / "spec.toml", spec_copy_text(src, store.dir))


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
