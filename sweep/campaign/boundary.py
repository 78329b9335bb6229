"""The ``boundary`` sampler: adaptive runs where a phase diagram's regime boundaries are least certain.

Units: the axes' own (model units: mm, s, kPa; kPa*s, mm^2, ...); tolerances in axis units, decades on
log axes; uncertainties reported in tolerance units (1 = one tolerance).

Campaign TOML::

    [axes]                                  # 1 to 3 axes, each {linear = [..]}, {log = [..]} or {range = [..]}
    cement = {linear = [0.5, 3.0, 3]}       # bounds: first and last value (%); the count matters only
    eta_o = {log = [0.029, 0.29, 3]}        #   with initial = "grid" (the crossed values)

    [sampler]
    kind = "boundary"
    budget = 60                 # max runs, initial design included (required)
    tolerance = 0.1             # boundary location, axis units (decades on log axes); or a table per axis
    seed = 0                    # same seed, same sequence of points
    batch = 2                   # runs per round (default: [run] jobs of the spec, else 1)
    initial = "lhs"             # "lhs" (n_initial points, Latin hypercube) or "grid" (the axes' values)
    n_initial = 9
    label = "regime"            # table column classified (e.g. "fracturing" for the Ca*-C diagram)
    labels = []                 # the label set (>= 2; default: the labels seen); others are ignored
    degree = 3                  # total degree of the classifier's Legendre basis
    prior_sd = 100.0            # largest prior sd of its degree-1 coefficients (default: 8 per tolerance
                                #   unit of the finest axis, sharp enough for a sharp boundary)
    prior_span = 64             # the prior sd is a hyperparameter over [prior_sd / prior_span, prior_sd]
                                #   (factor-2 grid, weighted by its evidence); 1 fixes it at prior_sd
    smoothness = 0.3            # prior sd ratio per extra degree (curvature is a priori small)
    confidence = 0.95           # of the boundary's uncertainty band
    fill_batch = false          # true: when the picks' bands leave fewer than `batch` candidates, halve the
                                #   bands until the round is full (fewer rounds; see results/archive/boundary_sampler)

Each round fits :func:`sweep.regimes.regime_model.fit_regime_model` to the labelled runs, measures the
boundary-location uncertainty (z sigma_loc on the MAP boundaries, in tolerance units) and,
unless it is <= 1 along the whole boundary or the budget is spent, picks the next batch by the
straddle score z sigma_loc - distance to the boundary (both in tolerance units) over a seeded
candidate set, each pick excluding the candidates within its own band (batch spread out); no point
within half a tolerance of a sampled one. While the band is wide (the first rounds) one pick's band can
cover every candidate, and the round runs fewer than ``batch`` points while a core waits. ``fill_batch``
then halves the exclusion radii (never below half a tolerance) and picks again, so that every round runs
``batch`` points. It is off by default: it changes the designs, and with them the coverage of the separatrix
intervals on fuzzy labels (results/archive/boundary_sampler/README.md).

The prior sd of the classifier's slopes is the inverse of the regimes' transition width. It is not
fixed: each fit weighs a grid of prior sds by their evidence (marginal likelihood of the labels), and
sigma_loc is the root-mean-square deviation of the boundary under that posterior (Laplace sd of each
member plus the spread of the members' boundaries). Labels mixed across a fuzzy transition keep the
soft members probable, so the band widens and the sampler places more runs before it stops; sharp
labels leave the sharpest member alone, as with a fixed prior sd.

Resuming needs no state file: the sequence is replayed from the campaign table. Round r + 1 is a
function of the seed and of the labels of rounds 0..r only, so a killed campaign, rerun, replays its
finished rounds and returns the unfinished round's missing points: the same seed gives the same
sequence. Runs of the store that are not in the sequence (another seed) are not used.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, fields
from typing import Any, Mapping

import numpy as np

from scipy.spatial import cKDTree

from sweep.regimes.regime_model import AxisScale, RegimeModel, boundary_band, boundary_uncertainty, fit_regime_model
from sweep.campaign import replicate_sampler
from sweep.campaign.boundary_picks import (COORD_DIGITS, MIN_SPACING, BoundaryState, axis_column, coord_key,
                                           missing_label, picks, point_coords, tol_coords)
from sweep.campaign.sampler import Point, resolve_point
from sweep.campaign.spec_model import CampaignSpec, SpecError, expand_block, round_sig

__all__ = ["BoundarySettings", "BoundarySampler", "BoundaryState"]

_N_CANDIDATES = 1024     # candidate points per round and per axis dimension (seeded)


@dataclass(frozen=True)
class BoundarySettings:
    """``[sampler]`` settings of a boundary campaign (see the module docstring); units of the axes."""

    budget: int
    tolerance: Any
    seed: int = 0
    batch: int | None = None
    initial: str = "lhs"
    n_initial: int = 9
    label: str = "regime"
    labels: tuple = ()
    degree: int = 3
    prior_sd: float | None = None
    smoothness: float = 0.3
    prior_span: float = 64.0
    confidence: float = 0.95
    fill_batch: bool = False


def _is_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_num(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _tol_ok(v) -> bool:
    if isinstance(v, Mapping):
        return bool(v) and all(_is_num(t) and t > 0 for t in v.values())
    return _is_num(v) and v > 0


# one table of checks: key -> (test, what is allowed)
_CHECKS: dict[str, tuple] = {
    "budget": (lambda v: _is_int(v) and v >= 1, "an integer >= 1 (max runs, initial design included)"),
    "tolerance": (_tol_ok, "a number > 0 (axis units, decades on log axes) or a table {axis = number > 0}"),
    "seed": (lambda v: _is_int(v) and v >= 0, "an integer >= 0"),
    "batch": (lambda v: v is None or (_is_int(v) and v >= 1), "an integer >= 1"),
    "initial": (lambda v: v in ("lhs", "grid"), "\"lhs\" or \"grid\""),
    "n_initial": (lambda v: _is_int(v) and v >= 2, "an integer >= 2"),
    "label": (lambda v: isinstance(v, str) and v != "", "a column name of the campaign table"),
    "labels": (lambda v: isinstance(v, (list, tuple)) and (len(v) == 0 or len(set(map(str, v))) >= 2),
               "a list of at least two distinct labels (or empty: the labels seen)"),
    "degree": (lambda v: _is_int(v) and 1 <= v <= 6, "an integer in [1, 6]"),
    "prior_sd": (lambda v: v is None or (_is_num(v) and v > 0), "a number > 0"),
    "smoothness": (lambda v: _is_num(v) and 0 < v <= 1, "a number in (0, 1]"),
    "prior_span": (lambda v: _is_num(v) and v >= 1, "a number >= 1 (1: prior_sd fixed)"),
    "confidence": (lambda v: _is_num(v) and 0.5 <= v < 1, "a number in [0.5, 1)"),
    "fill_batch": (lambda v: isinstance(v, bool), "true or false"),
}


def parse_settings(settings: Mapping[str, Any]) -> BoundarySettings:
    """Validate the ``[sampler]`` table (without ``kind``); SpecError names ``sampler.<key>``."""
    settings, _ = replicate_sampler.split_settings(settings)   # the replicate allocation's keys (sweep.campaign.replicate_sampler)
    allowed = [f.name for f in fields(BoundarySettings)]
    for k in settings:
        if k not in allowed:
            raise SpecError(f"sampler.{k}: unknown setting of the boundary sampler; allowed: {allowed}")
    if "budget" not in settings or "tolerance" not in settings:
        miss = "budget" if "budget" not in settings else "tolerance"
        raise SpecError(f"sampler.{miss}: required by the boundary sampler ({_CHECKS[miss][1]})")
    for k, v in settings.items():
        test, what = _CHECKS[k]
        if not test(v):
            raise SpecError(f"sampler.{k}={v!r}: must be {what}")
    s = BoundarySettings(**{**settings, "labels": tuple(str(v) for v in settings.get("labels", ()))})
    if s.initial == "lhs" and s.budget < s.n_initial:
        raise SpecError(f"sampler.budget={s.budget}: must be >= the initial design (n_initial = {s.n_initial})")
    return s


@dataclass(frozen=True)
class _Config:
    """A spec resolved for the sampler: settings, axis scales, batch size, base inputs."""

    settings: BoundarySettings
    axes: tuple[AxisScale, ...]
    targets: tuple[str, ...]
    batch: int
    initial: tuple[tuple[float, ...], ...]


class BoundarySampler:
    """Adaptive sampler of regime boundaries (``kind = "boundary"``); see the module docstring."""

    kind = "boundary"

    def __init__(self):
        self._memo: dict[tuple, dict] = {}

    @staticmethod
    def check_settings(settings: Mapping[str, Any]) -> None:
        parse_settings(settings)

    # -- configuration -----------------------------------------------------------------------
    def _config(self, spec: CampaignSpec) -> _Config:
        s = parse_settings({k: v for k, v in spec.sampler.items() if k != "kind"})
        if not spec.replicates and (extra := sorted(set(spec.sampler) & set(replicate_sampler.REPLICATE_SAMPLER_KEYS))):
            raise SpecError(f"{spec.source}: sampler.{extra[0]}: a setting of the boundary sampler with replicates; "
                            "add [replicates] porosity_seed = N (N >= 1) or remove it")
        if len(spec.blocks) != 1:
            raise SpecError(f"{spec.source}: blocks: the boundary sampler takes one set of [axes], not [[blocks]]")
        block = spec.blocks[0]
        if not 1 <= len(block.axes) <= 3:
            raise SpecError(f"{spec.source}: axes: the boundary sampler needs 1 to 3 axes, got {len(block.axes)}")
        axes = tuple(_axis_scale(spec, a, s.tolerance) for a in block.axes)
        if isinstance(s.tolerance, Mapping):
            extra = sorted(set(s.tolerance) - {a.name for a in axes})
            if extra:
                raise SpecError(f"{spec.source}: sampler.tolerance.{extra[0]}: not an axis; axes: {[a.name for a in axes]}")
        jobs = int(spec.run.get("jobs", 1))
        batch = s.batch or (os.cpu_count() or 1 if jobs == -1 else jobs)
        initial = self._initial_coords(s, axes, block)
        if len(initial) > s.budget:
            raise SpecError(f"{spec.source}: sampler.budget={s.budget}: must be >= the initial design "
                            f"({len(initial)} points)")
        return _Config(s, axes, tuple(a.target for a in block.axes), batch, initial)

    @staticmethod
    def _initial_coords(s: BoundarySettings, axes, block) -> tuple:
        if s.initial == "grid":
            combos = expand_block(block)
            return tuple(tuple(round_sig(float(c[(a.target, a.name)]), COORD_DIGITS) for a in block.axes) for c in combos)
        # Latin hypercube drawn here, not by scipy.stats.qmc.LatinHypercube: the replay regenerates this design
        # from the seed to match the committed campaigns' runs, and scipy's draws other points for the same seed
        rng = np.random.default_rng([s.seed, 0])
        n, d = s.n_initial, len(axes)
        U = np.stack([(rng.permutation(n) + rng.uniform(size=n)) / n for _ in range(d)], axis=1) * 2.0 - 1.0
        return tuple(point_coords(axes, u) for u in U)

    # -- the sampler interface ---------------------------------------------------------------
    def initial(self, spec: CampaignSpec) -> list[Point]:
        if spec.replicates:   # replicates where the label is uncertain: sweep.campaign.replicate_sampler
            return replicate_sampler.initial(self, spec)
        cfg = self._config(spec)
        return [self._point(spec, cfg, c, i) for i, c in enumerate(cfg.initial)]

    def refine(self, spec: CampaignSpec, table) -> list[Point]:
        if spec.replicates:
            return replicate_sampler.refine(self, spec, table)
        cfg = self._config(spec)
        st = self._replay(cfg, table)
        n0 = st.runs_used - len(st.rounds[-1])
        last = {coord_key(c): i for i, c in enumerate(st.rounds[-1])}
        return [self._point(spec, cfg, c, n0 + last[coord_key(c)]) for c in st.pending]

    def state(self, spec: CampaignSpec, table) -> dict:
        """The campaign's standing as a JSON-able dict (see :meth:`BoundaryState.to_dict`)."""
        if spec.replicates:
            return replicate_sampler.state(self, spec, table)
        cfg = self._config(spec)
        return self._replay(cfg, table).to_dict(cfg.axes)

    def replay(self, spec: CampaignSpec, table) -> BoundaryState:
        """The full state, with the classifier fitted to every labelled run of the sequence."""
        if spec.replicates:
            return replicate_sampler.replay(self, spec, table)
        cfg = self._config(spec)
        st = self._replay(cfg, table)
        X, y = _labelled(st)
        if len(set(y)) >= 2:
            st.model = self._fit(cfg, X, y)
        return st

    # -- replay ------------------------------------------------------------------------------
    def _point(self, spec, cfg: _Config, coords, index: int):
        block = spec.blocks[0]
        params, options = {**spec.params, **block.params}, {**spec.options, **block.options}
        swept = {}
        for a, t, v in zip(cfg.axes, cfg.targets, coords):
            (params if t == "params" else options)[a.name] = v
            swept[a.name] = v
        where = f"{spec.source}: boundary sampler point ({', '.join(f'{k}={v!r}' for k, v in swept.items())})"
        rp, ro = resolve_point(where, params, options, spec.derived)
        return Point(rp, ro, swept, (block.label,), index)

    def _replay(self, cfg: _Config, table) -> BoundaryState:
        st = BoundaryState([list(cfg.initial)], _observations(table, cfg), cfg.settings.budget)
        while True:
            st.pending = [c for c in st.rounds[-1] if coord_key(c) not in st.labels]
            if st.pending:
                return st
            dec = self._decide(cfg, st)
            st.uncertainty, st.pairs, st.model = dec["uncertainty"], dec["pairs"], dec["model"]
            if dec["stop"]:
                st.stopped, st.reason = True, dec["stop"]
                return st
            st.rounds.append(list(dec["batch"]))

    def _decide(self, cfg: _Config, st: BoundaryState) -> dict:
        """Stop (with the reason) or the next batch, from the rounds so far (memoized)."""
        sig = tuple((coord_key(c), st.labels.get(coord_key(c))) for r in st.rounds for c in r)
        if sig in self._memo:
            return self._memo[sig]
        s = cfg.settings
        X, y = _labelled(st)
        used, model, unc = st.runs_used, None, {"max": math.inf, "pairs": {}}
        if len(set(y)) >= 2:
            model = self._fit(cfg, X, y)
            unc = boundary_uncertainty(model)
        out = {"model": model, "uncertainty": unc["max"], "pairs": unc["pairs"], "stop": "", "batch": []}
        if unc["max"] <= 1.0 and st.uncertainty <= 1.0:
            out["stop"] = (f"converged: the {s.confidence:.0%} band of the boundary is within the tolerance "
                           f"everywhere, two rounds running (largest half-width {unc['max']:.2f} tolerance) after {used} runs")
        elif used >= s.budget:
            out["stop"] = (f"budget spent: {used} of {s.budget} runs; largest boundary half-width "
                           f"{unc['max']:.3g} tolerance" + ("" if model else f" (fewer than two labels seen: {sorted(set(y))})"))
        else:
            pts = [c for r in st.rounds for c in r]
            out["batch"] = _next_batch(cfg, model, pts, min(cfg.batch, s.budget - used), len(st.rounds),
                                       fill=s.fill_batch)
            if not out["batch"]:
                out["stop"] = (f"resolution reached: no candidate farther than {MIN_SPACING} tolerance from the "
                               f"{used} sampled points (largest boundary half-width {unc['max']:.3g} tolerance)")
        self._memo[sig] = out
        return out

    @staticmethod
    def _fit(cfg: _Config, X, y) -> RegimeModel:
        s = cfg.settings
        labels = s.labels or None
        prior_sd = s.prior_sd or 8.0 * max(a.tol_per_u for a in cfg.axes)
        return fit_regime_model(X, y, cfg.axes, degree=s.degree, prior_sd=prior_sd, smoothness=s.smoothness,
                                confidence=s.confidence, labels=labels, prior_span=s.prior_span)


# ---------------------------------------------------------------------------------------------
def _axis_scale(spec: CampaignSpec, a, tolerance) -> AxisScale:
    if a.scale not in ("linear", "log", "range"):
        raise SpecError(f"{spec.source}: axes.{a.name}: the boundary sampler needs a continuous axis "
                        f"{{linear = [start, stop, n]}}, {{log = [...]}} or {{range = [...]}}, got an explicit list")
    vals = [float(v) for v in a.values]
    lo, hi = min(vals), max(vals)
    if not hi > lo:
        raise SpecError(f"{spec.source}: axes.{a.name}: bounds [{lo!r}, {hi!r}] must have start != stop")
    tol = float(tolerance.get(a.name, math.nan) if isinstance(tolerance, Mapping) else tolerance)
    if not tol > 0:
        raise SpecError(f"{spec.source}: sampler.tolerance: no tolerance for axis {a.name!r}")
    return AxisScale(a.name, lo, hi, a.scale == "log", tol)


def _observations(table, cfg: _Config) -> dict[tuple, str | None]:
    """{coordinates: label (None for a failed or unlabelled run)} of every run in the table."""
    out: dict[tuple, str | None] = {}
    if table is None or len(table) == 0:
        return out
    cols = [axis_column(table, a.name).to_numpy() for a in cfg.axes]
    lab = cfg.settings.label
    labels = table[lab].to_numpy() if lab in table.columns else np.full(len(table), None)
    ok = table["status"].to_numpy() == "ok" if "status" in table.columns else np.ones(len(table), bool)
    for i in range(len(table)):
        v = labels[i]
        good = ok[i] and not missing_label(v)
        out[coord_key([c[i] for c in cols])] = str(v) if good else None
    return out


def _labelled(st: BoundaryState):
    pts = [c for r in st.rounds for c in r if st.labels.get(coord_key(c)) is not None]
    return np.array(pts, float).reshape(len(pts), -1), [st.labels[coord_key(c)] for c in pts]


def _next_batch(cfg: _Config, model: RegimeModel | None, sampled, n: int, round_no: int, *,
                fill: bool = False) -> list:
    """Up to n new points: the straddle score's best, each excluding the candidates within its band
    (or, without a model, maximin space filling); none within MIN_SPACING of a sampled point. With ``fill``,
    a pass that ends short of n is redone with every exclusion radius halved (down to MIN_SPACING), so
    that the batch is full whenever enough candidates are left."""
    axes = cfg.axes
    d = len(axes)
    rng = np.random.default_rng([cfg.settings.seed, round_no])
    U = rng.uniform(-1.0, 1.0, size=(_N_CANDIDATES * d, d))
    T = tol_coords(axes, U)
    S = tol_coords(axes, np.stack([a.to_u(np.array(sampled)[:, j]) for j, a in enumerate(axes)], axis=1))
    dmin = np.min(np.linalg.norm(T[:, None, :] - S[None, :, :], axis=2), axis=1)
    band = boundary_band(model) if model is not None else {"U": np.empty((0, d))}
    score = half = None
    if len(band["U"]):
        # straddle, measured geometrically: the band's half-width at the nearest point of an estimated
        # boundary minus the distance to it (sd(g) away from the boundary also carries the slope's
        # scale, unidentified for separable labels, and a pair's zero line may lie where neither wins)
        dist, j = cKDTree(tol_coords(axes, band["U"])).query(T)
        half = band["half"][j]
        score = half - dist
    shrink = 1.0
    while True:
        out = picks(U, T, dmin, score, half, n, shrink)
        if not fill or len(out) >= n or score is None or shrink * max(float(half.max()), 1.0) <= MIN_SPACING:
            return [point_coords(axes, U[i]) for i in out]
        shrink *= 0.5
