"""Execute campaign runs in isolation, in parallel, through joblib's backends.

One code path for every backend: ``joblib.Parallel(return_as="generator_unordered")``
over :func:`execute_task`, inside ``joblib.parallel_config`` for

* ``loky`` (default, this machine, ``jobs`` worker processes, one BLAS thread each),
* ``dask`` (``scheduler`` = address of a ``dask.distributed`` scheduler; a LocalCluster of
  ``jobs`` single-threaded workers when no address is given; extra ``dask``),
* ``ray`` (``scheduler`` = Ray address or None for a local Ray; extra ``ray``).

With dask or ray on several machines, the results root must be on a shared file system.

A *runner* executes one run: ``runner(params: dict, options: dict, run_dir: str) -> dict``
with keys ``status`` ("ok" | "failed", default "ok"), ``reason`` (str | None),
``metrics`` (dict of scalars), ``classification`` (dict, or the regime as a str),
``numbers`` (dict, optional), ``classifier_hash`` (str: the classifier code that labelled the run,
when sweep.regimes.classify did); other scalar keys are taken as metrics. It must be
picklable (a module-level function, or a ``functools.partial`` of one).
:class:`DefaultRunner` calls ``solver.simulate`` then ``sweep.regimes.classify.classify_run``.

Each run is isolated: an exception becomes a record with status "failed" and the reason;
with a timeout (or ``isolate="process"``) the runner runs in a child Python process that
is killed when the timeout expires, so a hung or crashing run costs that run only.
Every record is written to the store by the worker as soon as the run ends; it states the solver
code (``code_hash``) and lists each file of the run folder with its size and SHA-256 (``files``).
"""
from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, Sequence

from sweep.campaign.store import ResultsStore, current_classifier_hash, file_manifest, to_json, write_json_atomic

__all__ = [
    "RunTask",
    "ExecConfig",
    "DefaultRunner",
    "execute_task",
    "iter_records",
    "normalize_result",
    "classification_dict",
    "BACKENDS",
]

BACKENDS = ("loky", "dask", "ray")
_RESERVED = {"status", "reason", "metrics", "classification", "regime", "numbers", "classifier_hash"}


@dataclass(frozen=True)
class RunTask:
    """One run to execute: its key in the store and its resolved inputs (model units)."""

    key: str
    params: Mapping[str, Any]
    options: Mapping[str, Any]
    index: int = 0


@dataclass(frozen=True)
class ExecConfig:
    """How each run is executed.

    root, campaign : where the store is (``root/campaign/runs``); absolute path for clusters.
    runner : the run callable (see module docstring).
    timeout : s of wall time per attempt (None: unlimited); implies a child process.
    retries : extra attempts after a failure.
    isolate : "auto" (child process iff timeout), "process" (always) or "none" (never).
    blas_threads : BLAS/OpenMP threads of a child process (None: inherit).
    code_hash : hash of the solver source that runs (solver.codehash), recorded in each record.
    """

    root: str
    campaign: str
    runner: Callable
    timeout: float | None = None
    retries: int = 0
    isolate: str = "auto"
    blas_threads: int | None = 1
    code_hash: str = "unknown"
    extra: Mapping[str, Any] = field(default_factory=dict)


# ---------------------------------------------------------------------------
# runners
# ---------------------------------------------------------------------------
class DefaultRunner:
    """``solver.simulate`` then ``sweep.regimes.classify.classify_run`` on the run folder.

    Metrics (from the solver's time series): t_reached (s), p_inj_max (kPa), p_inj_final (kPa),
    front_radius_mean_final / front_radius_max_final (mm), mean_damage_final (-),
    max_hoop_stress_max (kPa), mass_error_max (-), n_steps, front_radius_max_last_step (mm: how far the front's
    angular maximum moved in the last accepted step).
    """

    def __init__(self, classify_options: Mapping[str, Any] | None = None, classifier_hash: str | None = None):
        self.classify_options = dict(classify_options or {})
        # taken where the campaign is planned, so that the records and the plan name one classifier
        self.classifier_hash = classifier_hash or current_classifier_hash()

    def __call__(self, params: dict, options: dict, run_dir: str) -> dict:
        from solver import Parameters, RunOptions, simulate

        res = simulate(Parameters.from_dict(params), RunOptions.from_dict(options), out_dir=run_dir)
        out: dict[str, Any] = {"status": res.status, "reason": res.reason, "metrics": _timeseries_metrics(res.timeseries)}
        out["metrics"]["solver_wall_time_s"] = float(getattr(res, "wall_time", float("nan")))
        if res.status == "ok":
            try:
                from sweep.regimes.classify import classify_run

                out["classification"] = classification_dict(classify_run(run_dir, **self.classify_options))
                out["classifier_hash"] = self.classifier_hash
            except Exception as e:  # noqa: BLE001 - the simulation stays valid; reclassify later
                out["classify_error"] = f"{type(e).__name__}: {e}"
        return out

    def __repr__(self):
        return f"DefaultRunner({self.classify_options!r})"


def classification_dict(res) -> dict:
    """Flat dict of a ``classify_run`` result: ``classification_to_dict`` of its classification
    plus ``t_classified`` (s, the snapshot classified); a mapping or a bare regime pass through."""
    if isinstance(res, Mapping):
        return dict(res)
    if isinstance(res, str):
        return {"regime": res}
    c = getattr(res, "classification", None)
    if c is not None:
        from sweep.regimes.classify import classification_to_dict

        out = classification_to_dict(c)
        t = getattr(res, "t", None)
        if t is not None:
            out["t_classified"] = float(t)
        return out
    return {"regime": getattr(res, "regime", None)} if hasattr(res, "regime") else {"classification": repr(res)}


def _timeseries_metrics(ts) -> dict:
    m: dict[str, Any] = {}
    if ts is None or len(ts) == 0:
        return m
    last = ts.iloc[-1]
    cols = set(ts.columns)

    def put(name, value):
        try:
            m[name] = float(value)
        except (TypeError, ValueError):
            pass

    if "t" in cols:
        put("t_reached", last["t"])
    if "p_inj" in cols:
        put("p_inj_max", ts["p_inj"].max())
        put("p_inj_final", last["p_inj"])
    for c in ("front_radius_mean", "front_radius_max", "mean_damage", "open_tip_radius"):
        if c in cols:
            put(f"{c}_final", last[c])
    if "front_radius_max" in cols and len(ts) > 1:  # how the run's last step moved the front (a jump or not)
        put("front_radius_max_last_step", ts["front_radius_max"].iloc[-1] - ts["front_radius_max"].iloc[-2])
    if "open_tip_radius" in cols:  # the longest open crack of the run (crack_closure: cracks can close)
        put("open_tip_radius_max", ts["open_tip_radius"].max())
    if "max_hoop_stress" in cols:
        put("max_hoop_stress_max", ts["max_hoop_stress"].max())
    if "mass_error" in cols:
        put("mass_error_max", ts["mass_error"].abs().max())
    m["n_steps"] = int(len(ts))
    return m


def normalize_result(res) -> dict:
    """Runner output -> {status, reason, metrics, classification, numbers}."""
    if res is None:
        res = {}
    if not isinstance(res, Mapping):
        return {"status": "failed", "reason": f"runner returned {type(res).__name__}, expected a dict",
                "metrics": {}, "classification": {}}
    status = res.get("status", "ok")
    reason = res.get("reason")
    if status not in ("ok", "failed"):
        reason = f"runner returned status={status!r} (expected 'ok' or 'failed'); reason: {reason}"
        status = "failed"
    if status == "failed" and not reason:
        reason = "runner reported failure without a reason"
    cls = res.get("classification") or {}
    if isinstance(cls, str):
        cls = {"regime": cls}
    elif not isinstance(cls, Mapping):
        cls = {"classification": repr(cls)}
    cls = dict(cls)
    if "regime" in res:
        cls["regime"] = res["regime"]
    metrics = dict(res.get("metrics") or {})
    for k, v in res.items():
        if k not in _RESERVED:
            metrics[k] = v
    out = {"status": status, "reason": None if status == "ok" and reason is None else (str(reason) if reason is not None else None),
           "metrics": metrics, "classification": cls}
    if res.get("numbers") is not None:
        out["numbers"] = dict(res["numbers"])
    if res.get("classifier_hash"):
        out["classifier_hash"] = str(res["classifier_hash"])
    return json.loads(to_json(out))  # plain JSON types only


# ---------------------------------------------------------------------------
# one run
# ---------------------------------------------------------------------------
def _failed(reason: str, tb: str | None = None) -> dict:
    out = {"status": "failed", "reason": reason, "metrics": {}, "classification": {}}
    if tb:
        out["traceback"] = tb
    return out


def _run_inprocess(runner, params, options, run_dir: Path) -> dict:
    try:
        res = runner(dict(params), dict(options), str(run_dir))
    except Exception as e:  # noqa: BLE001 - isolation is the point
        tb = traceback.format_exc()
        (run_dir / "error.txt").write_text(tb)
        return _failed(f"{type(e).__name__}: {e}", tb)
    return normalize_result(res)


def child_env(cfg: ExecConfig) -> dict:
    """The environment of a run's child process: this interpreter's import path, and ``cfg.blas_threads``
    threads for every BLAS/OpenMP library when set (one run per core)."""
    env = dict(os.environ)
    paths = [p for p in sys.path if p]
    if env.get("PYTHONPATH"):
        paths.append(env["PYTHONPATH"])
    env["PYTHONPATH"] = os.pathsep.join(dict.fromkeys(paths))
    if cfg.blas_threads is not None:
        for v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS",
                  "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS"):
            env[v] = str(cfg.blas_threads)
    return env


def _kill_group(proc: subprocess.Popen) -> None:
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        with contextlib.suppress(ProcessLookupError):
            proc.kill()
    proc.wait()


def _run_child(cfg: ExecConfig, params, options, run_dir: Path) -> dict:
    try:
        import cloudpickle
    except ImportError:  # plain pickle: module-level runners only
        import pickle as cloudpickle

    payload = run_dir / ".payload.pkl"
    result = run_dir / ".result.json"
    payload.write_bytes(cloudpickle.dumps((cfg.runner, dict(params), dict(options), str(run_dir))))
    log = run_dir / "runner.log"
    with open(log, "wb") as logf:
        proc = subprocess.Popen(
            [sys.executable, "-m", "sweep.campaign.scheduler", str(payload), str(result), str(os.getpid())],
            stdout=logf, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
            env=child_env(cfg), start_new_session=True,
        )
        try:
            rc = proc.wait(timeout=cfg.timeout)
        except subprocess.TimeoutExpired:
            _kill_group(proc)
            payload.unlink(missing_ok=True)
            return _failed(f"timeout: the run exceeded {cfg.timeout:g} s of wall time and was killed")
        except BaseException:
            _kill_group(proc)  # Ctrl-C / worker shutdown: do not leave an orphan solver behind
            raise
    payload.unlink(missing_ok=True)
    try:
        out = json.loads(result.read_text())
        result.unlink()
        return out
    except (FileNotFoundError, json.JSONDecodeError):
        tail = log.read_text(errors="replace")[-2000:].strip().splitlines()[-5:]
        sig = f" (signal {-rc})" if rc < 0 else ""
        return _failed(f"the run's child process exited with code {rc}{sig} without a result: " + " | ".join(tail))


def checkpoint_elapsed(run_dir) -> float:
    """Wall time (s) of the earlier pieces of the run whose checkpoint ``run_dir`` holds (``solver.checkpoint``),
    which a resumed run adds to its own; 0 when it holds none or it cannot be read.  The time between the last
    checkpoint and the kill is lost work, not counted."""
    from solver import checkpoint

    ck, _ = checkpoint.load(run_dir)
    return float(ck.get("elapsed", 0.0)) if ck is not None else 0.0


def execute_task(task: RunTask, cfg: ExecConfig) -> dict:
    """Execute one run (with retries), write its record atomically in the store, return the record.

    Never raises for a run's own failure: exceptions, failed status, timeouts and crashed child
    processes all give a record with status "failed" and the reason.
    """
    store = ResultsStore(cfg.root, cfg.campaign)
    isolate = cfg.isolate
    if isolate == "auto":
        isolate = "process" if cfg.timeout is not None else "none"
    started = time.time()
    out, tmp, tries = _attempts(task, cfg, store, isolate)
    record = _record(task, cfg, out, tries, started, isolate)
    from solver import checkpoint

    checkpoint.remove(tmp)  # left by a run the timeout killed: a recorded run is final, a rerun starts at t = 0
    record["files"] = file_manifest(tmp)
    if "traceback" in out:
        record["traceback"] = out["traceback"]
    write_json_atomic(tmp / "record.json", record)
    store.finalize(tmp, task.key)
    return record


def _attempts(task: RunTask, cfg: ExecConfig, store, isolate: str) -> tuple[dict, Path, dict]:
    """Run ``task`` until it is ok or its retries are spent: the last attempt's output, its folder, and the
    attempts (``attempt``, ``wall`` s of the last attempt with its resumed pieces, ``earlier`` s resumed from a
    checkpoint, ``reasons`` of the failed attempts, whose folders are removed)."""
    reasons = []
    for attempt in range(1, cfg.retries + 2):
        # an execution killed part-way left a checkpoint: the first attempt resumes it (solver.checkpoint)
        tmp = (attempt == 1 and store.resumable_tmp_dir(task.key)) or store.new_tmp_dir(task.key)
        earlier = checkpoint_elapsed(tmp)  # a resumed run's wall time is its pieces' sum (s)
        t0 = time.perf_counter()
        if isolate == "process":
            try:
                out = _run_child(cfg, task.params, task.options, tmp)
            except Exception as e:  # noqa: BLE001 - e.g. an unpicklable runner: this run fails, not the campaign
                out = _failed(f"could not execute the run in a child process: {type(e).__name__}: {e}",
                              traceback.format_exc())
        else:
            out = _run_inprocess(cfg.runner, task.params, task.options, tmp)
        wall = time.perf_counter() - t0 + earlier
        if out["status"] == "ok" or attempt == cfg.retries + 1:
            break
        reasons.append(out.get("reason"))
        import shutil

        shutil.rmtree(tmp, ignore_errors=True)
    return out, tmp, {"attempt": attempt, "wall": wall, "earlier": earlier, "reasons": reasons}


def _record(task: RunTask, cfg: ExecConfig, out: dict, tries: dict, started: float, isolate: str) -> dict:
    """A run's record (record.json) from its last attempt's output; times in s, clock times local ISO 8601."""
    record = {
        "key": task.key,
        "campaign": cfg.campaign,
        "status": out["status"],
        "reason": out.get("reason"),
        "params": dict(task.params),
        "options": dict(task.options),
        "code_hash": cfg.code_hash,
        "metrics": out.get("metrics", {}),
        "classification": out.get("classification", {}),
        "wall_time_s": tries["wall"],
        "resumed_wall_s": tries["earlier"],
        "total_wall_time_s": time.time() - started + tries["earlier"],
        "attempts": tries["attempt"],
        "previous_failures": tries["reasons"],
        "started_at": time.strftime("%Y-%m-%dT%H:%M:%S", time.localtime(started)),
        "finished_at": time.strftime("%Y-%m-%dT%H:%M:%S"),
        "host": socket.gethostname(),
        "isolate": isolate,
    }
    if out.get("classifier_hash"):
        record["classifier_hash"] = out["classifier_hash"]
    if "numbers" in out:
        record["numbers"] = out["numbers"]
    return record


# ---------------------------------------------------------------------------
# backends
# ---------------------------------------------------------------------------
def check_backend(backend: str, scheduler: str | None, timeout: float = 10.0) -> None:
    """Check, before anything is run or written, that ``backend`` can run: its package imports and a dask
    scheduler address answers within ``timeout`` s.  ValueError naming the backend (and address) otherwise."""
    if backend not in BACKENDS:
        raise ValueError(f"backend={backend!r} not allowed: one of {BACKENDS}")
    if backend == "loky":
        if scheduler:
            raise ValueError(f"--scheduler {scheduler!r} is only meaningful with backend dask or ray")
        return
    package = {"dask": "dask.distributed", "ray": "ray"}[backend]
    try:
        __import__(package)
    except ImportError as e:
        raise ValueError(f"--backend {backend} needs {package} (pip install 'dchfrac[{backend}]'): {e}") from None
    if backend == "dask" and scheduler:
        from dask.distributed import Client

        try:
            Client(scheduler, timeout=timeout).close()
        except Exception as e:  # noqa: BLE001 - OSError, TimeoutError, CommClosedError...: one line naming it
            raise ValueError(f"--scheduler {scheduler!r}: no dask scheduler answers within {timeout:g} s "
                             f"({type(e).__name__}: {e})") from None


@contextlib.contextmanager
def _backend(backend: str, jobs: int, scheduler: str | None):
    """Yield n_jobs for joblib inside the backend's parallel_config."""
    from joblib import parallel_config

    if backend == "loky":
        if scheduler:
            raise ValueError(f"scheduler={scheduler!r} is only meaningful with backend dask or ray")
        with parallel_config(backend="loky", n_jobs=jobs, inner_max_num_threads=1):
            yield jobs
    elif backend == "dask":
        try:
            from dask.distributed import Client, LocalCluster
        except ImportError as e:
            raise ValueError(f"backend='dask' needs dask[distributed] (pip install 'dchfrac[dask]'): {e}") from None
        cluster = None
        if scheduler:
            client = Client(scheduler)
        else:
            n = jobs if jobs and jobs > 0 else (os.cpu_count() or 1)
            cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None)
            client = Client(cluster)
        try:
            with parallel_config(backend="dask", n_jobs=-1):
                yield -1
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    elif backend == "ray":
        try:
            import ray
            from ray.util.joblib import register_ray
        except ImportError as e:
            raise ValueError(f"backend='ray' needs ray (pip install 'dchfrac[ray]'): {e}") from None
        register_ray()
        started = False
        if not ray.is_initialized():
            ray.init(address=scheduler or None, num_cpus=None if scheduler else (jobs if jobs > 0 else None))
            started = True
        try:
            with parallel_config(backend="ray", n_jobs=jobs):
                yield jobs
        finally:
            if started:
                ray.shutdown()
    else:
        raise ValueError(f"backend={backend!r} not allowed: one of {BACKENDS}")


def iter_records(tasks: Sequence[RunTask], cfg: ExecConfig, *, jobs: int = 1, backend: str = "loky",
                 scheduler: str | None = None) -> Iterator[dict]:
    """Execute ``tasks`` and yield each record as its run finishes (completion order).

    Closing the generator early (e.g. fail-fast) cancels the runs not yet started.
    """
    if not tasks:
        return
    from joblib import Parallel, delayed

    with _backend(backend, jobs, scheduler) as n_jobs:
        # Ray's joblib backend returns lists only (it refuses generators): its records reach the campaign when
        # the round's runs are all done (each run's folder is still written as it finishes, so a killed campaign
        # resumes alike); fail_fast then stops after the round
        order = "list" if backend == "ray" else "generator_unordered"
        par = Parallel(n_jobs=n_jobs, return_as=order, batch_size=1)
        gen = par(delayed(execute_task)(t, cfg) for t in tasks)
        try:
            yield from gen
        finally:
            with contextlib.suppress(Exception):
                gen.close()


# ---------------------------------------------------------------------------
# child process entry point: python -m sweep.campaign.scheduler PAYLOAD RESULT PARENT_PID
# ---------------------------------------------------------------------------
def _watch_parent(parent_pid: int) -> None:
    def loop():
        while True:
            if os.getppid() != parent_pid:
                os._exit(70)  # the campaign worker died: stop the orphaned run
            time.sleep(0.5)

    threading.Thread(target=loop, daemon=True).start()


def _child_main(argv: Sequence[str]) -> int:
    payload, result = Path(argv[0]), Path(argv[1])
    if len(argv) > 2:
        _watch_parent(int(argv[2]))
    import pickle

    try:
        runner, params, options, run_dir = pickle.loads(payload.read_bytes())
        out = _run_inprocess(runner, params, options, Path(run_dir))
    except Exception as e:  # noqa: BLE001 - unpicklable runner etc.
        out = _failed(f"{type(e).__name__}: {e}", traceback.format_exc())
    write_json_atomic(result, out)
    return 0


if __name__ == "__main__":
    sys.exit(_child_main(sys.argv[1:]))
