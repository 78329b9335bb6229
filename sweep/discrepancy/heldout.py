"""Held-out observables: a data set of one condition (or a few) checked on observables it was not fitted to.

A laboratory experiment is often one condition (results/fidelity/experiment/: the paper's reference
experiment, C = 1.2 %, η_o = 0.29 kPa·s), so no whole condition can be held out.  With ``[holdout]
observables = [...]`` every condition that measures a listed observable is split in two: the condition itself
keeps its other observables (the training rows) and a twin condition ``<id>~held`` with the same parameters
holds the listed ones (the held-out rows).  Every stage then works as with held-out conditions: the fit sees
only the training rows, the held-out gap is measured on the listed observables, and the forward runs of the
two are the same runs (same parameters and times: the problem's cache).  Units those of the observables.
"""
from __future__ import annotations

import pandas as pd

from .data import MeasuredData

__all__ = ["HELD_SUFFIX", "split_observables", "heldout_data"]

HELD_SUFFIX = "~held"


def split_observables(data: MeasuredData, observables) -> MeasuredData:
    """``data`` with the curves of ``observables`` (names; "regime" for the regime label) moved to twin
    conditions ``<id>~held`` (module docstring).  A condition left without a training observable is an error;
    a listed observable measured nowhere is an error.  Idempotent: data already split are returned as given."""
    obs = list(observables)
    if any(str(i).endswith(HELD_SUFFIX) for i in data.ids):
        return data
    measured = set(data.curves.observable) | ({"regime"} if data.regimes else set())
    missing = [o for o in obs if o not in measured]
    if missing:
        raise ValueError(f"[holdout] observables {missing} are not measured in the data (measured: {sorted(measured)})")
    cur = data.curves
    held_c = cur[cur.observable.isin(obs)]
    keep_c = cur[~cur.observable.isin(obs)]
    held_r = {k: v for k, v in data.regimes.items() if "regime" in obs}
    keep_r = {k: v for k, v in data.regimes.items() if "regime" not in obs}
    bare = [c for c in data.ids if c not in set(keep_c.condition) and c not in keep_r]
    if bare:
        raise ValueError(f"[holdout] observables {obs}: conditions {bare} would keep no observable to fit "
                         "(allowed: at least one training observable in every condition)")
    twins = [c for c in data.ids if c in set(held_c.condition) or c in held_r]
    conds = pd.concat([data.conditions, data.conditions.loc[twins].rename(index=lambda c: c + HELD_SUFFIX)])
    held_c = held_c.assign(condition=held_c.condition + HELD_SUFFIX)
    curves = (pd.concat([keep_c, held_c]).sort_values(["condition", "observable", "time"], kind="stable")
              .reset_index(drop=True))
    regimes = {**keep_r, **{k + HELD_SUFFIX: v for k, v in held_r.items()}}
    return MeasuredData(conds, curves, regimes)


def heldout_data(data: MeasuredData, spec) -> MeasuredData:
    """``data`` as the workflow uses it under ``spec``: split by ``[holdout] observables`` when given."""
    return split_observables(data, spec.holdout_observables) if spec.holdout_observables else data
