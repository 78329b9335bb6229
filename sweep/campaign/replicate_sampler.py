"""The boundary sampler with replicates: ``kind = "boundary"`` and ``[replicates] porosity_seed = N`` (issue #51).

N is then the most runs a point may get; each round of ``sweep.campaign.replicate_allocation`` decides which
points get one more porosity draw (the uncertain ones) and where new points go (one run each), and stops when the
separatrix band is within ``band_tolerance``.  Spec::

    [axes]                        # two axes: the first linear or log, the second log (the separatrix is a line
    cement = {linear = [0.5, 3.0, 3]}   #   in (first, log second): Ca*_c = A exp(B C) with eta_o at fixed w_i)
    eta_o = {log = [0.03, 3.0, 3]}

    [replicates]
    porosity_seed = 5             # at most 5 runs per point (seed = base seed + 0 .. 4)

    [sampler]
    kind = "boundary"
    budget = 150                  # runs, replicates included
    tolerance = 0.1               # spacing of new points (axis units, decades on log axes), as without replicates
    label = "fracturing"          # a boolean column, or labels = [negative, positive] of a text column
    band_tolerance = 0.25         # stop: simultaneous 95 % band of the separatrix within +-0.25 decades
    clear = 0.1                   # fitted probability below 0.1 or above 0.9: one run settles the point
    replicate_share = 0.5         # at most half of a round's runs are replicates

Resuming replays the rounds from the table, as the boundary sampler does: round r + 1 is a function of the seed
and of the labels of rounds 0..r.  Units: the axes' (decades on log axes).
"""
from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np

from sweep.campaign.boundary_picks import BoundaryState, axis_column, coord_key, missing_label
from sweep.campaign.replicate_allocation import ReplicateSettings, decide_round
from sweep.campaign.spec_model import SpecError

__all__ = ["REPLICATE_SAMPLER_KEYS", "split_settings", "initial", "refine", "state", "replay", "majority_label"]

# [sampler] keys of the replicate allocation: key -> (test, what is allowed)
REPLICATE_SAMPLER_KEYS: dict[str, tuple] = {
    "band_tolerance": (lambda v: _num(v) and v > 0, "a number > 0 (decades of the second axis)"),
    "clear": (lambda v: _num(v) and 0 < v < 0.5, "a number in (0, 0.5)"),
    "replicate_share": (lambda v: _num(v) and 0 < v <= 1, "a number in (0, 1]"),
}


def _num(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def split_settings(settings: Mapping[str, Any]) -> tuple[dict, dict]:
    """(the boundary sampler's settings, the replicate allocation's, checked: SpecError names sampler.<key>)."""
    own = {k: v for k, v in settings.items() if k in REPLICATE_SAMPLER_KEYS}
    for k, v in own.items():
        test, what = REPLICATE_SAMPLER_KEYS[k]
        if not test(v):
            raise SpecError(f"sampler.{k}={v!r}: must be {what}")
    return {k: v for k, v in settings.items() if k not in own}, own


def _setup(sampler, spec):
    """(boundary config, ReplicateSettings, positive label test) of a replicated boundary spec; SpecError when the
    spec does not fit (two axes, second on a log axis, porosity replicates only)."""
    cfg = sampler._config(spec)
    if set(spec.replicates) != {"porosity_seed"}:
        raise SpecError(f"{spec.source}: replicates: the boundary sampler replicates the porosity draw only "
                        f"(porosity_seed), got {sorted(spec.replicates)}")
    if len(cfg.axes) != 2 or not cfg.axes[1].log:
        raise SpecError(f"{spec.source}: axes: the boundary sampler with replicates needs two axes, the second "
                        f"on a log scale (the separatrix is a line in the first and the log of the second)")
    _, own = split_settings({k: v for k, v in spec.sampler.items() if k != "kind"})
    rs = ReplicateSettings(max_replicates=spec.replicates["porosity_seed"], level=cfg.settings.confidence, **own)
    labels = cfg.settings.labels
    if len(labels) == 2:   # labels = [negative, positive]; another label is left out, as by the boundary sampler
        return cfg, rs, lambda v: {labels[0]: False, labels[1]: True}.get(str(v))
    return cfg, rs, lambda v: _boolean(v, cfg.settings.label)


_BOOLEAN = {"True": True, "1": True, "1.0": True, "fracturing": True,
            "False": False, "0": False, "0.0": False, "porous_invasion": False}


def _boolean(v, label: str) -> bool:
    """A boolean label column's value; SpecError naming ``sampler.label`` for a text label without ``labels``."""
    if str(v) not in _BOOLEAN:
        raise SpecError(f"sampler.label={label!r}: value {v!r} is not a boolean; a text column needs "
                        "labels = [negative, positive] (the others are left out)")
    return _BOOLEAN[str(v)]


def _observed(table, cfg, positive, base_seed: int) -> dict:
    """{(coords key, replicate): label (bool) or None for a failed run or a label outside ``labels``} of the
    table's runs."""
    out: dict = {}
    if table is None or len(table) == 0:
        return out
    cols = [axis_column(table, a.name).to_numpy() for a in cfg.axes]
    seeds = axis_column(table, "seed").to_numpy()
    lab = table[cfg.settings.label].to_numpy() if cfg.settings.label in table.columns else np.full(len(table), None)
    ok = table["status"].to_numpy() == "ok" if "status" in table.columns else np.ones(len(table), bool)
    for i in range(len(table)):
        v = lab[i]
        good = ok[i] and not missing_label(v)
        out[(coord_key([c[i] for c in cols]), int(seeds[i]) - base_seed)] = positive(v) if good else None
    return out


def _replay(sampler, spec, table) -> dict:
    """The rounds so far [[(coords, r)]], the pending runs of the last one, and the stop decision."""
    cfg, rs, positive = _setup(sampler, spec)
    base = int(sampler._point(spec, cfg, cfg.initial[0], 0).params["seed"])
    seen = _observed(table, cfg, positive, base)
    rounds = [[(c, 0) for c in cfg.initial]]
    while True:
        pending = [(c, r) for c, r in rounds[-1] if (coord_key(c), r) not in seen]
        if pending:
            return {"cfg": cfg, "rounds": rounds, "pending": pending, "stop": "", "decision": None, "seen": seen}
        runs = [(c, r, seen[(coord_key(c), r)]) for rr in rounds for c, r in rr]
        sig = ("replicates", tuple((coord_key(c), r, v) for c, r, v in runs))   # memoized: each round is decided once
        if sig not in sampler._memo:
            sampler._memo[sig] = decide_round(cfg.axes, runs, rs, batch=cfg.batch, budget=cfg.settings.budget,
                                              seed=cfg.settings.seed, round_no=len(rounds))
        dec = sampler._memo[sig]
        if dec["stop"]:
            return {"cfg": cfg, "rounds": rounds, "pending": [], "stop": dec["stop"], "decision": dec, "runs": runs,
                    "seen": seen}
        rounds.append(dec["batch"])


def _points(sampler, spec, cfg, runs, start: int) -> list:
    """Campaign points of (coords, r): the boundary sampler's point with the porosity seed base + r."""
    from dataclasses import replace

    out = []
    for i, (c, r) in enumerate(runs):
        p = sampler._point(spec, cfg, c, start + i)
        out.append(replace(p, params={**p.params, "seed": int(p.params["seed"]) + r}))
    return out


def initial(sampler, spec) -> list:
    """Round 0: the initial design, one run (replicate 0) per point."""
    cfg, _, _ = _setup(sampler, spec)
    return _points(sampler, spec, cfg, [(c, 0) for c in cfg.initial], 0)


def refine(sampler, spec, table) -> list:
    """The pending runs of the current round (replayed from the table); [] once the sampler stops."""
    st = _replay(sampler, spec, table)
    start = sum(len(r) for r in st["rounds"][:-1])
    return _points(sampler, spec, st["cfg"], st["pending"], start)


def state(sampler, spec, table) -> dict:
    """JSON-able standing: rounds, runs used of the budget, stop reason, band half-width (decades), the separatrix,
    and per point of the sequence its ``replicates`` (finished runs with a label: those the fit counts, as
    ``n_ok`` of points.csv), ``unlabelled`` (finished runs without one: failed, or a label outside ``labels``)
    and ``pending`` (runs of the current round not finished)."""
    st = _replay(sampler, spec, table)
    cfg, dec = st["cfg"], st["decision"]
    band = dec["band"] if dec else None
    names = [a.name for a in cfg.axes]
    return {"sampler": "boundary", "replicates": spec.replicates["porosity_seed"], "round": len(st["rounds"]),
            "runs_used": sum(len(r) for r in st["rounds"]), "budget": cfg.settings.budget, "stopped": bool(st["stop"]),
            "reason": st["stop"], "pending": len(st["pending"]),
            "band_half_width_decades": None if not dec or not math.isfinite(dec["half"]) else dec["half"],
            "separatrix": None if band is None else {"A": band.A, "B": band.B, "p_value": band.p_value,
                                                     "significant": band.significant},
            "points": [{**dict(zip(names, c)), **n} for c, n in _point_runs(st).items()]}


def _point_runs(st: dict) -> dict:
    """{coords: {"replicates", "unlabelled", "pending"}} of the replayed sequence ``st``: a run of the rounds is
    pending when the table has no row of it, else labelled or not (``_observed``)."""
    out: dict = {}
    for rr in st["rounds"]:
        for c, r in rr:
            d = out.setdefault(tuple(c), {"replicates": 0, "unlabelled": 0, "pending": 0})
            k = (coord_key(c), r)
            d["pending" if k not in st["seen"] else "unlabelled" if st["seen"][k] is None else "replicates"] += 1
    return out


def majority_label(votes: list) -> str:
    """The label most of a point's runs give; a tie goes to the label of its first run in ``votes`` (the table's
    order: replicate 0 first), so that a point's label never depends on the interpreter's string hashing."""
    return max(votes, key=votes.count)


def replay(sampler, spec, table):
    """A ``BoundaryState`` for the boundary figure: the rounds' points (a point once per replicate), each point's
    majority label (:func:`majority_label`), and the boundary sampler's classifier fitted to every labelled run
    (replicates as repeated rows)."""
    st = _replay(sampler, spec, table)
    cfg = st["cfg"]
    out = BoundaryState([[c for c, _ in rr] for rr in st["rounds"]], {}, cfg.settings.budget,
                        stopped=bool(st["stop"]), reason=st["stop"])
    if table is None or len(table) == 0 or cfg.settings.label not in table.columns:
        return out
    ok = (table["status"] == "ok").to_numpy() if "status" in table.columns else np.ones(len(table), bool)
    lab = table[cfg.settings.label].to_numpy()
    keep = ok & np.array([not missing_label(v) for v in lab])
    X = np.stack([axis_column(table, a.name).to_numpy(float) for a in cfg.axes], axis=1)[keep]
    y = [str(v) for v in lab[keep]]
    votes: dict = {}
    for x, v in zip(X, y):
        votes.setdefault(coord_key(x), []).append(v)
    out.labels = {k: majority_label(v) for k, v in votes.items()}
    if len(set(y)) >= 2:
        out.model = sampler._fit(cfg, X, y)
    if st["decision"] is not None and math.isfinite(st["decision"]["half"]):
        out.uncertainty = st["decision"]["half"] / cfg.axes[1].tolerance
    return out
