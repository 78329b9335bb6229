"""Forward models for the discrepancy workflow: the coupled solver (cached on disk) and a protocol.

A forward model maps a *full* set of parameter overrides (condition + baseline +
calibrated values + effect strengths, a dict of solver.Parameters fields) and the
observation times to predicted observables::

    predict_many([(overrides, {"p_inj": times, ...}), ...]) -> [{"p_inj": array, ..., "regime": label}, ...]

Units: times s, p_inj kPa, front_radius_mean and crack_length mm.  A failed or
short run gives NaN where it has no value (the workflow turns NaN into a large
residual, never silently into agreement).
"""
from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

import numpy as np
import pandas as pd

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
    """Stable short hash of (parameters, options): the cache key of a forward run."""
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
    """Interpolate solver time-series columns at the observation times.

    ``crack_length`` (mm) = open_tip_radius − r_inner where a crack is open (open_tip_radius > 0), else 0.
    Times before the first step take the first stored value; times after the last step are NaN.
    """
    out = {}
    if ts is None or len(ts) == 0:
        return {k: (np.full(len(v), np.nan) if k != "regime" else None) for k, v in times.items()}
    t = ts["t"].to_numpy(float)
    tmax = t[-1] if t_reached is None else t_reached
    cols = {
        "p_inj": ts["p_inj"].to_numpy(float),
        "front_radius_mean": ts["front_radius_mean"].to_numpy(float),
        "crack_length": np.where(ts["open_tip_radius"].to_numpy(float) > 0,
                                 np.maximum(ts["open_tip_radius"].to_numpy(float) - r_inner, 0.0), 0.0),
    }
    for obs, tq in times.items():
        if obs == "regime":
            continue
        tq = np.asarray(tq, float)
        v = np.interp(tq, t, cols[obs])
        v[tq > tmax * (1 + 1e-9) + 1e-12] = np.nan
        out[obs] = v
    return out


def finished(run_dir) -> bool:
    """Is the cache entry ``run_dir`` a finished run ("ok" or "failed")?

    A run writes ``summary.json`` with status "running" when it starts (solver.output); one that was
    killed (machine lost, job cancelled) keeps it.  Such an entry is not a result: reading it would feed
    the workflow a truncated curve (NaN residuals), so it is run again."""
    f = Path(run_dir) / "summary.json"
    if not f.is_file():
        return False
    try:
        return json.loads(f.read_text()).get("status") in ("ok", "failed")
    except (OSError, ValueError):
        return False


def _run_one(pdict: dict, odict: dict, run_dir: str, classify: bool) -> None:
    """Run the solver into ``run_dir`` (a cache entry) unless it is already finished."""
    import shutil

    from solver import Parameters, RunOptions, simulate

    rd = Path(run_dir)
    if finished(rd):
        return
    if rd.exists():
        shutil.rmtree(rd)  # an interrupted run's partial files must not mix with the new run's
    simulate(Parameters.from_dict(pdict), RunOptions.from_dict(odict), out_dir=rd)


class SolverForward(ForwardModel):
    """The coupled solver with an on-disk cache (one run folder per hash of parameters and options).

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
        self.cache_dir = Path(cache_dir)
        self.cache_dir.mkdir(parents=True, exist_ok=True)
        self.n_jobs = int(n_jobs)
        self.n_runs = 0

    @property
    def regime_labels(self) -> tuple:
        """The regime labels this model gives (sweep.classify.REGIMES): measured labels must be among them."""
        from sweep.classify import REGIMES

        return REGIMES

    def _pdict(self, overrides: dict) -> dict:
        from solver import Parameters

        return Parameters.from_dict({**self.base, **overrides}).to_dict()

    def run_dir(self, overrides: dict) -> Path:
        pd_ = {k: v for k, v in self._pdict(overrides).items() if v is not None}
        return self.cache_dir / params_hash(pd_, self.options.to_dict())

    def predict_many(self, jobs: list) -> list:
        todo = {}
        for o, _ in jobs:
            rd = self.run_dir(o)
            if not finished(rd):
                todo[str(rd)] = {k: v for k, v in self._pdict(o).items() if v is not None}
        if todo:
            self.n_runs += len(todo)
            od = self.options.to_dict()
            if self.n_jobs != 1 and len(todo) > 1:
                from joblib import Parallel, delayed, parallel_config

                # one BLAS/PARDISO thread per solver run: n_jobs runs already share the cores
                with parallel_config(backend="loky", inner_max_num_threads=1):
                    Parallel(n_jobs=self.n_jobs)(delayed(_run_one)(p, od, rd, True) for rd, p in todo.items())
            else:
                for rd, p in todo.items():
                    _run_one(p, od, rd, True)
        return [self._read(self.run_dir(o), o, t) for o, t in jobs]

    def predict_one(self, overrides: dict, times: dict) -> dict:
        return self.predict_many([(overrides, times)])[0]

    def _read(self, rd: Path, overrides: dict, times: dict) -> dict:
        summ = json.loads((rd / "summary.json").read_text())
        f = rd / "timeseries.csv"
        ts = pd.read_csv(f) if f.is_file() and f.stat().st_size > 0 else None
        r_inner = self._pdict(overrides)["r_inner"]
        ok = summ.get("status") == "ok"
        out = observables_from_timeseries(ts, times, r_inner, summ.get("t_reached") if not ok else None)
        if "regime" in times:
            out["regime"] = _regime(rd) if ok else None
        return out


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


def _regime(rd: Path):
    """Regime label of the last snapshot of run folder ``rd`` (sweep.classify), None if unavailable."""
    try:
        from sweep.classify import classify_run

        return str(classify_run(rd).classification.regime)
    except Exception:  # classifier missing or run without snapshot: no label, reported as such
        return None
