"""Forward models for the discrepancy workflow: the coupled solver (cached on disk) and a protocol.

A forward model maps a *full* set of parameter overrides (condition + baseline +
calibrated values + effect strengths, a dict of solver.Parameters fields) and the
observation times to predicted observables::

    predict_many([(overrides, {"p_inj": times, ...}), ...]) -> [{"p_inj": array, ..., "regime": label}, ...]

Units: times s, each observable in its unit (sweep.discrepancy.observables).  A failed or
short run gives NaN where it has no value (the workflow turns NaN into a large
residual, never silently into agreement).
"""
from __future__ import annotations

import hashlib
import json
import logging
from pathlib import Path

import numpy as np
import pandas as pd

from .observables import REGISTRY, SNAPSHOT_CURVES, get_observable, read_curves

log = logging.getLogger("dchfrac.discrepancy")

__all__ = ["ForwardModel", "SolverForward", "fine_forwards", "finished", "params_hash", "observables_from_timeseries"]


class ForwardModel:
    """Protocol: subclasses implement :meth:`predict_one`; :meth:`predict_many` may run in parallel."""

    n_runs = 0  # forward evaluations actually computed (not served from a cache)

    def predict_one(self, overrides: dict, times: dict) -> dict:  # pragma: no cover - interface
        raise NotImplementedError

    def predict_many(self, jobs: list) -> list:
        """[(overrides, times)] -> [predictions]; default: sequential."""
        return [self.predict_one(o, t) for o, t in jobs]


def params_hash(params_dict: dict, options_dict: dict) -> str:
    """Stable short hash of (parameters, options): the name of a forward run's cache folder. The code
    that made the entry is checked by :func:`finished` (summary.json ``code_hash``), so an entry of other
    code is run again in the same folder.  The options that do not change a run's result
    (``solver.options.keyed``: checkpoint_interval) are no part of it."""
    from solver.options import keyed

    options_dict = keyed(options_dict)

    def norm(v):
        if isinstance(v, float):
            return float(f"{v:.12g}")
        if isinstance(v, (list, tuple)):
            return [norm(x) for x in v]
        return v
    blob = json.dumps({"p": {k: norm(v) for k, v in sorted(params_dict.items())},
                       "o": {k: norm(v) for k, v in sorted(options_dict.items())}}, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:20]


def observables_from_timeseries(ts: pd.DataFrame, times: dict, r_inner: float, t_reached: float | None = None) -> dict:
    """Interpolate the curve observables (:mod:`.observables`) at the observation times ``times``
    ({observable: times s}; "regime" is skipped: it is classified from the last snapshot).

    r_inner : the run's inner radius, mm.  Times before the first step take the first stored value; times
    after the last step (or after ``t_reached`` s, a failed run's last time) are NaN.  An observable whose
    column the time series lacks raises :class:`.observables.ObservableUnavailable` naming it.
    """
    if ts is None or len(ts) == 0:
        return {k: (np.full(len(v), np.nan) if k != "regime" else None) for k, v in times.items()}
    t = ts["t"].to_numpy(float)
    tmax = t[-1] if t_reached is None else t_reached
    cols = read_curves(ts, [o for o in times if get_observable(o).kind == "curve"], r_inner)
    out = {}
    for obs, v_rows in cols.items():
        tq = np.asarray(times[obs], float)
        v = np.interp(tq, t, v_rows)
        v[tq > tmax * (1 + 1e-9) + 1e-12] = np.nan
        out[obs] = v
    return out


def finished(run_dir, code_hash: str | None = None) -> bool:
    """Is the cache entry ``run_dir`` a finished run ("ok" or "failed") of the current solver code?

    A run writes ``summary.json`` with status "running" when it starts (solver.output); one that was
    killed (machine lost, job cancelled) keeps it.  Such an entry is not a result: reading it would feed
    the workflow a truncated curve (NaN residuals), so it is run again.  So is an entry whose
    ``code_hash`` (the solver source that made it) is not ``code_hash`` (default: the current one), and
    an "ok" entry whose time series is missing or does not parse (damaged)."""
    from sweep.campaign.store import current_code_hash

    rd = Path(run_dir)
    summ = _summary(rd)
    if summ is None or summ.get("code_hash") != (code_hash or current_code_hash()):
        return False
    if summ.get("status") == "failed":
        return True
    return summ.get("status") == "ok" and _timeseries(rd) is not None


def _summary(rd: Path) -> dict | None:
    """A cache entry's summary.json (status "ok", "failed" or "running", code_hash, ...), None when missing or
    unreadable."""
    try:
        summ = json.loads((rd / "summary.json").read_text())
    except (OSError, ValueError):
        return None
    return summ if isinstance(summ, dict) else None


def _timeseries(rd: Path):
    """The run's time series (DataFrame), None if missing, empty or unreadable."""
    try:
        ts = pd.read_csv(rd / "timeseries.csv")
    except (OSError, ValueError, pd.errors.EmptyDataError, pd.errors.ParserError):
        return None
    return ts if len(ts) and "t" in ts.columns else None


def _run_one(pdict: dict, odict: dict, run_dir: str, code_hash: str) -> None:
    """Run the solver into ``run_dir`` (a cache entry) unless it is already finished by code ``code_hash``; an
    entry interrupted with a checkpoint of the current solver code resumes from it (``solver.checkpoint``).

    A run that raises is recorded as a failure (summary.json: status "failed", the reason, no t_reached),
    which the workflow reads as no prediction (NaN), never as a result."""
    import shutil

    from solver import Parameters, RunOptions, simulate
    from sweep.campaign.store import write_json_atomic

    from solver import checkpoint

    rd = Path(run_dir)
    if finished(rd, code_hash):
        return
    if rd.exists() and not checkpoint.resumable(rd):
        shutil.rmtree(rd)  # an interrupted or other code's run's files must not mix with the new run's
    try:
        simulate(Parameters.from_dict(pdict), RunOptions.from_dict(odict), out_dir=rd)
    except Exception as e:  # noqa: BLE001 - recorded as this entry's failure
        rd.mkdir(parents=True, exist_ok=True)
        write_json_atomic(rd / "summary.json", {"status": "failed", "reason": f"{type(e).__name__}: {e}",
                                               "complete": False, "t_reached": None, "code_hash": code_hash})


class SolverForward(ForwardModel):
    """The coupled solver with an on-disk cache (one run folder per hash of parameters and options; an
    entry made by other solver code, interrupted or damaged is run again: :func:`finished`).

    base : dict of solver.Parameters fields common to every run (below the overrides).
    options : solver.RunOptions (mesh size h mm, t_end s, dt_max s, ...); snapshots are written
        only at t_end (needed for the regime classification).
    cache_dir : folder of the cache (inside the workflow's out dir).
    n_jobs : parallel solver runs for uncached jobs (joblib loky).
    """

    def __init__(self, base: dict, options, cache_dir, n_jobs: int = 1):
        from solver import Parameters

        self.base = dict(base)
        Parameters.from_dict(self.base)  # validate now
        self.options = options.replace(snapshot_times=(options.t_end,), write_xdmf=False)
        self.cache_dir = Path(cache_dir)      # made at the first run: a refused input leaves no folder
        self.n_jobs = int(n_jobs)
        self.n_runs = 0

    @property
    def regime_labels(self) -> tuple:
        """The regime labels this model gives (sweep.regimes.classify.REGIMES): measured labels must be among them."""
        from sweep.regimes.classify import REGIMES

        return REGIMES

    def _pdict(self, overrides: dict) -> dict:
        from solver import Parameters

        return Parameters.from_dict({**self.base, **overrides}).to_dict()

    def run_dir(self, overrides: dict) -> Path:
        pd_ = {k: v for k, v in self._pdict(overrides).items() if v is not None}
        return self.cache_dir / params_hash(pd_, self.options.to_dict())

    def invalid(self, overrides: dict) -> str | None:
        """Why ``overrides`` are not a valid parameter set (solver.Parameters' message), or None.  A fit may
        step into such a set (K_s below the drained bulk modulus of a softer E, say): it is answered as a
        run that reached no time, never run and never cached."""
        try:
            self._pdict(overrides)
        except ValueError as exc:
            return str(exc)
        return None

    def predict_many(self, jobs: list) -> list:
        from sweep.campaign.store import current_code_hash

        code = current_code_hash()
        bad = [self.invalid(o) for o, _ in jobs]
        for why in dict.fromkeys(b for b in bad if b):
            log.warning("forward model: %s; the point counts as a run that reached no time", why)
        out = [observables_from_timeseries(None, t, 0.0) if b else None for (_, t), b in zip(jobs, bad)]
        good = [j for j, b in zip(jobs, bad) if not b]
        for k, pred in zip([i for i, b in enumerate(bad) if not b], self._predict_valid(good, code)):
            out[k] = pred
        return out

    def _predict_valid(self, jobs: list, code: str) -> list:
        """Predictions of valid parameter sets: cached entries of the current code read, the others run."""
        todo = {}
        for o, _ in jobs:
            rd = self.run_dir(o)
            if not finished(rd, code):
                todo[str(rd)] = {k: v for k, v in self._pdict(o).items() if v is not None}
        if todo:
            self.n_runs += len(todo)
            self._run_batch(todo, code)
        return [self._read(self.run_dir(o), o, t) for o, t in jobs]

    def _run_batch(self, todo: dict, code: str) -> None:
        """Run the uncached entries ``todo`` ({run dir: parameter dict}), on ``n_jobs`` processes, with a
        progress line before and after the batch (a fine run can take an hour: an overnight run says what it is
        doing, and a resumed entry says so)."""
        import time

        from solver import checkpoint

        self.cache_dir.mkdir(parents=True, exist_ok=True)
        od = self.options.to_dict()
        held = sum(1 for rd in todo if (Path(rd) / checkpoint.NAME).is_file())
        log.info("forward: %d run(s) at h = %g mm to t = %g s%s, %d job(s); cache %s", len(todo), self.options.h,
                 self.options.t_end, f" ({held} with a checkpoint to resume from)" if held else "", self.n_jobs,
                 self.cache_dir)
        t0 = time.perf_counter()
        if self.n_jobs != 1 and len(todo) > 1:
            from joblib import Parallel, delayed, parallel_config

            # one BLAS/PARDISO thread per solver run: n_jobs runs already share the cores
            with parallel_config(backend="loky", inner_max_num_threads=1):
                Parallel(n_jobs=self.n_jobs)(delayed(_run_one)(p, od, rd, code) for rd, p in todo.items())
        else:
            for rd, p in todo.items():
                _run_one(p, od, rd, code)
        failed = sum(1 for rd in todo if (_summary(Path(rd)) or {}).get("status") != "ok")
        log.info("forward: %d run(s) at h = %g mm done in %.0f s%s", len(todo), self.options.h,
                 time.perf_counter() - t0, f", {failed} failed" if failed else "")

    def predict_one(self, overrides: dict, times: dict) -> dict:
        return self.predict_many([(overrides, times)])[0]

    def _read(self, rd: Path, overrides: dict, times: dict) -> dict:
        """Predictions of the finished entry ``rd``: a failed run's values up to the time it reached
        (NaN after; all NaN when it reached none)."""
        summ = json.loads((rd / "summary.json").read_text())
        ok = summ.get("status") == "ok"
        ts = _timeseries(rd) if ok or summ.get("t_reached") is not None else None
        r_inner = self._pdict(overrides)["r_inner"]
        out = observables_from_timeseries(ts, times, r_inner, summ.get("t_reached") if not ok else None)
        return {**out, **snapshot_observables(rd, times, ok)}


def fine_forwards(spec, cache_dir, n_jobs: int = 1) -> list:
    """The workflow's fine check models: one SolverForward per entry of :func:`.spec.fine_options` (one per
    mesh realization with ``[discretization] mesh_seeds``, else one; [] without ``[discretization]``).

    The data are one realization of mesh and porosity field; the workflow corrects with the realizations'
    mean and adds their spread to σ (workflow.add_discretization_error).  One cache folder serves all:
    the cache key hashes the options, mesh_seed included."""
    from solver import RunOptions

    from .spec import fine_options

    return [SolverForward(spec.baseline_overrides(), RunOptions.from_dict(o), cache_dir, n_jobs=n_jobs)
            for o in fine_options(spec)]


def snapshot_observables(rd: Path, times: dict, ok: bool) -> dict:
    """The observables of ``times`` read from the last snapshot of the finished entry ``rd``, classified once
    (sweep.regimes.classify): the regime label (None when unavailable) and each snapshot curve
    (:data:`.observables.SNAPSHOT_CURVES`) at its times (s), the last snapshot's value, which is the value at t_end
    where the checks put every such observation (NaN when unavailable).  A failed run gives none; a snapshot the
    classifier cannot read is logged."""
    curves = [n for n in SNAPSHOT_CURVES if n in times]
    if not curves and "regime" not in times:
        return {}
    c = _last_classification(rd, curves + (["regime"] if "regime" in times else [])) if ok else None
    out = {n: np.full(len(times[n]), np.nan if c is None else REGISTRY[n].snapshot(c)) for n in curves}
    if "regime" in times:
        out["regime"] = None if c is None else str(c.regime)
    return out


def _last_classification(rd: Path, wanted: list):
    """The classification of the last snapshot of run folder ``rd``, None if unavailable (logged with the
    observables ``wanted`` of it)."""
    try:
        from sweep.regimes.classify import classify_run

        return classify_run(rd).classification
    except Exception as exc:  # noqa: BLE001 - classifier missing or run without snapshot: no prediction
        log.warning("%s of %s not read: its last snapshot is not classified (%s)", ", ".join(wanted), rd, exc)
        return None


def cache_status(cache_dir) -> list[dict]:
    """One row per entry of a forward-run cache folder (a discrepancy run's progress, read while it runs or
    after it stopped): key, mesh size h (mm) and mesh seed from its options, status ("ok", "failed", "running":
    in flight or interrupted), the time reached (s: t_reached of a finished run, the checkpoint's time of a
    running one, None before its first checkpoint), wall time (s, finished runs) and whether the current solver
    code made it (an entry of other code is run again when the workflow needs it).  Sorted by key."""
    import tomllib

    from solver import checkpoint
    from sweep.campaign.store import current_code_hash

    code = current_code_hash()
    rows = []
    for rd in sorted(p for p in Path(cache_dir).iterdir() if p.is_dir()):
        summ = _summary(rd)
        try:
            opts = tomllib.loads((rd / "options.toml").read_text())
        except (OSError, ValueError):
            summ = None
        if summ is None:
            rows.append({"key": rd.name, "h": None, "mesh_seed": None, "status": "unreadable", "t": None,
                         "wall_s": None, "current_code": False})
            continue
        t = summ.get("t_reached")
        if summ.get("status") == "running":
            ck, _ = checkpoint.load(rd)
            t = None if ck is None else float(ck["t"])
        rows.append({"key": rd.name, "h": opts.get("h"), "mesh_seed": opts.get("mesh_seed"),
                     "status": summ.get("status"), "t": t, "wall_s": summ.get("wall_time_s"),
                     "current_code": summ.get("code_hash") == code})
    return rows
