"""Twin experiments: synthetic measured data from a forward model with a hidden effect, plus noise.

:func:`make_twin` evaluates ``forward`` (e.g. the solver on a *finer* mesh and smaller time step than
the workflow uses) for each condition with ``hidden`` parameter overrides, adds Gaussian noise of the
given standard deviations (units of each observable) and writes a measured-data folder.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from .data import OBS_COLUMNS, write_measured
from .observables import REGISTRY

__all__ = ["make_twin", "DEFAULT_NOISE"]

DEFAULT_NOISE = {n: o.default_noise for n, o in REGISTRY.items() if o.kind == "curve"}


def make_twin(folder, forward, conditions: dict, times, hidden: dict, noise: dict | None = None,
              seed: int = 0, observables=("p_inj", "front_radius_mean", "crack_length"), regime: bool = True):
    """Write a twin dataset; returns the folder.

    conditions : {id: {parameter: value}}; times : observation times, s (same for every curve);
    hidden : parameter overrides of the data-generating model (never told to the workflow);
    noise : {observable: sd} in the observable's unit (also written as the uncertainty column; default
        the registry's default noise, observables.py).
    Raises ValueError, before writing anything, when a data-generating run gives no value at some of the
    times (it stopped early): a twin's data cover every observation time or the twin is not made.
    """
    noise = dict(DEFAULT_NOISE, **(noise or {}))
    rng = np.random.default_rng(seed)
    times = np.asarray(times, float)
    tt = {o: times for o in observables}
    if regime:
        tt["regime"] = times[-1:]
    jobs = [({**hidden, **cp}, tt) for cp in conditions.values()]
    preds = forward.predict_many(jobs)
    _check_complete(conditions, preds, observables, times)
    rows, regimes = [], {}
    for cid, pr in zip(conditions, preds):
        for o in observables:
            v = np.asarray(pr[o], float) + rng.normal(0.0, noise[o], times.size)
            rows += [(cid, o, t, val, noise[o]) for t, val in zip(times, v)]
        if regime and pr.get("regime") is not None:
            regimes[cid] = (float(times[-1]), pr["regime"])
    return write_measured(folder, conditions, pd.DataFrame(rows, columns=list(OBS_COLUMNS)), regimes)


def _check_complete(conditions: dict, preds, observables, times: np.ndarray) -> None:
    """ValueError naming the condition, the observable and the first time (s) without a value, if any."""
    for cid, pr in zip(conditions, preds):
        for o in observables:
            bad = ~np.isfinite(np.asarray(pr[o], float))
            if bad.any():
                raise ValueError(f"twin data: condition {cid!r}: the data-generating run gives no {o} from "
                                 f"t = {times[bad][0]:.4g} s of the {times[-1]:.4g} s asked (it stopped early; its "
                                 f"summary.json in the data cache says why)")
