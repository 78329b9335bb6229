"""The model SPEC of the discrepancy workflow (TOML), validated before any work.

Example (units mm, s, kPa)::

    [baseline]                       # solver.Parameters fields common to every condition
    kbar = 0.0015
    effects_off = ["damage_viscosity", "compliant_boundary"]   # effect names set to their off values

    [[calibrate]]                    # baseline parameters fitted on the training conditions
    name = "kbar"; lower = 5e-4; upper = 5e-3; scale = "log"     # initial = baseline value

    [[alternative]]                  # optional: baseline parameters held fixed but uncertain in [lower, upper]
    name = "K_s"; lower = 160.0; upper = 16000.0; scale = "log"  # (value: the baseline's).  The screen projects
                                     # a candidate's signature off their sensitivity directions too, and the
                                     # best passing candidate meets each as a rival refit (the baseline with
                                     # it freed): a rival within tie_bic makes the verdict a tie, never a name

    [candidates]
    effects = ["damage_viscosity", "compliant_boundary"]        # default: every effect off in the baseline
    scaling = { damage_viscosity = "sqrt_cement" }              # optional: parameter = strength * sqrt(C)
    upper = { damage_viscosity = 200.0 }                          # optional: strength bounds / probes
    probe = { damage_viscosity = 40.0 }
    independent = { compliant_boundary = "0.0095 ± 0.0005" }      # optional: a strength estimated outside the
                                     # data (e.g. plate bending of an elastic cell), value ± σ in the effect's
                                     # unit (also [value, sigma]); the report sets the fitted interval beside it
                                     # and flags a disagreement beyond 2σ

    [holdout]                        # whole conditions, never time points; or, with one condition (a single
                                     # experiment), observables = ["crack_length"]: those observables of every
                                     # condition are held out, the others fitted (sweep/discrepancy/heldout.py)
    ids = ["c3"]                     # or  every = 3  (every third condition, starting with the last)

    [options]                        # solver.RunOptions fields for the workflow's runs
    h = 8.0
    t_end = 0.1

    [discretization]                 # optional: RunOptions overrides of a finer check run; the difference
    h = 6.0                          # fine − coarse of the initial baseline, per point, is subtracted from
    dt_max = 0.01                    # the data and disc_error_fraction of it added in quadrature to σ;
                                     # once an effect is named, the correction is re-estimated at the
                                     # named model's fit and the model refitted (disc_refresh times)
    mesh_seeds = [1, 2, 3]           # optional (not a RunOptions field): one fine run per mesh realization
                                     # (mesh_seed = s: perturbed mesh and its element-wise porosity field),
                                     # distinct integers >= 0, at least 2.  The data are one realization the
                                     # model cannot know: the mean over realizations is the correction and
                                     # their deviations a covariance correlated in time (per series, or
                                     # per observable over its conditions: [noise] realization_blocks)

    [fit]                            # optional tables of settings, defaults shown (sweep/discrepancy/options.py)
    loss = "soft_l1"; f_scale = 3.0; max_nfev = 20; chi2_tol = 0.0; starts = 1; seed = 0; n_jobs = 1
    [acceptance]                     # passing candidates are ranked, and tied within tie_bic, by their BICs
    delta_bic = -10.0; tie_bic = 10.0; min_gap_reduction = 0.1; min_explained = 0.5    # under common weights
    min_ratio = 0.15; tie_cos = 0.95; z_crit = 3.0; rho_crit = 0.3; max_rounds = 3; max_refits = 2
    [noise]                          # with [discretization]: disc_error_fraction of the correction added to σ;
    disc_error_fraction = 0.5        # once an effect is named the correction is re-estimated at its fit and
    disc_refresh = 1                 # the model refitted, at most disc_refresh passes, until every named
    disc_refresh_tol = 0.05          # strength moves by <= disc_refresh_tol (relative) in a pass, or (when > 0)
    disc_refresh_tol_sd = 0.0        # by <= disc_refresh_tol_sd times its Wald standard error
    realization_blocks = "series"    # "observable": one realization covariance block per observable over its
                                     # conditions, correlated between them (the data: one realization for all)
    lag1 = "pooled"                  # the realization covariance's and jitter's lag-1 estimator for τ: "pooled"
                                     # (E = (n − 1)/n ρ, τ short) or "mean_ratio" (mean product / mean square)
    model_jitter = "none"            # "estimated": the coarse model's jitter in its parameters is an error term
    model_jitter_steps = 7; model_jitter_rel_step = 0.05    # (sweep/discrepancy/jitter.py)
    [profile]                        # the named strength's profile-likelihood interval
    expand = 3; refine = 2; refine_tol = 0.15; rough_tol = 0.25
    fine = true                      # with [discretization]: correct each profile point where it is
    correction = "point"             # with fine: "point" (re-estimated at each point), "piecewise" (linear between
                                     # the anchors below, one added where the profile goes beyond them) or "linear" (linear in the
    correction_anchors = 3           # strength from the realizations at correction_anchors strengths over the
    correction_span = 1.0            # fit ± correction_span Wald half-widths; the same for every point and
                                     # re-centring: common random numbers, a smooth profile)
    correction_slope_realizations = 0    # with "linear", m > 0: the anchors after the first run m realizations,
                                     # the first's mean carried by their change (0: all at every anchor)
    smoothing = "none"               # "quadratic": interval from a quadratic through noisy points (MCAP)
    grid = 4                         # with "quadratic": extra profile points per side
    likelihood = "weighted"          # delta chi2: "weighted" (lag-1 series weights), "gaussian" (whitened chi2),
                                     # "marginal" (realization-covariance scale integrated over its k-run estimate)
    threshold = "chi2"               # delta chi2 threshold: "chi2" (3.84 at 95 %), "f_realizations" (the F(1, k - 1)
                                     # quantile, k the mesh realizations: 6.61 at k = 6, 18.5 at k = 3) or "f_welch"
                                     # (F(1, nu), only the variance's realization part known to k - 1)
    emulator = "none"                # "gp": the profile points' refits on a Gaussian-process emulator of the
                                     # coarse model over the fitted parameters (emulator.py), its predictive
                                     # covariance added to the likelihood's; a design of emulator_design runs
    emulator_design = 8              # per training condition around the fit, refined with a real run where a
    emulator_tol = 0.1               # refit's emulator sd (whitened norm) exceeds emulator_tol, each interval
    emulator_checks = 3              # end confirmed by real runs (at most emulator_checks)
    emulate_refits = false           # with "gp": also the candidates' multi-start refits and the profile's
    emulator_polish = 2              # re-centring refit on emulators, each optimum checked with a real run and
                                     # polished by emulator_polish real least-squares evaluations

The former ``[workflow]`` table is refused with each of its keys named and where it went
(:data:`.options.REMOVED_WORKFLOW_KEYS`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from solver.effects import EFFECTS, get_effect
from solver.params import CHOICE_FIELDS

from .options import (OPTION_TABLES, AcceptanceOptions, FitOptions, NoiseOptions, ProfileOptions,
                      parse_options)

__all__ = ["CalibParam", "DiscrepancySpec", "load_spec", "spec_from_dict", "fine_options", "SCALINGS"]

SCALINGS = ("none", "sqrt_cement")


@dataclass(frozen=True)
class CalibParam:
    """A fitted parameter: name (Parameters field), bounds, initial value, scale "log" | "linear", FD step
    (in decades for log, in the parameter's unit for linear; None = 2 % of the range), and ``nested``: the
    value at which a model with it reduces to the model without it (None: its lower bound, an effect's
    "off"; an alternative's baseline value)."""

    name: str
    lower: float
    upper: float
    initial: float
    scale: str = "log"
    step: float | None = None
    nested: float | None = None

    def inward_step(self, x: float) -> float:
        """The finite-difference step at ``x`` (fit coordinates): ``x_step``, negated where it would leave the
        upper bound."""
        return -self.x_step if x + self.x_step > self.x_bounds[1] else self.x_step

    @property
    def x_nested(self) -> float:
        """``nested`` in fit coordinates (the lower bound when None)."""
        return self.x_bounds[0] if self.nested is None else self.to_x(self.nested)

    def to_x(self, v: float) -> float:
        return math.log10(v) if self.scale == "log" else float(v)

    def from_x(self, x: float) -> float:
        return 10.0 ** x if self.scale == "log" else float(x)

    @property
    def x_bounds(self) -> tuple[float, float]:
        return self.to_x(self.lower), self.to_x(self.upper)

    @property
    def x_step(self) -> float:
        lo, hi = self.x_bounds
        return self.step if self.step is not None else 0.02 * (hi - lo)


@dataclass(frozen=True)
class DiscrepancySpec:
    """A validated SPEC (see the module docstring): the baseline, what is calibrated, the candidate effects,
    the held-out conditions, the solver options of the runs and the workflow's settings by concern."""

    baseline: dict
    effects_off: tuple
    calibrate: tuple
    candidates: tuple
    scaling: dict
    upper: dict
    probe: dict
    holdout_ids: tuple | None
    holdout_every: int | None
    options: dict
    discretization: dict | None = None
    alternatives: tuple = ()
    independent: dict = field(default_factory=dict)    # effect -> (value, sigma), the effect's unit
    holdout_observables: tuple = ()                     # observables held out instead of whole conditions
    fit: FitOptions = field(default_factory=FitOptions)
    acceptance: AcceptanceOptions = field(default_factory=AcceptanceOptions)
    noise: NoiseOptions = field(default_factory=NoiseOptions)
    profile: ProfileOptions = field(default_factory=ProfileOptions)

    def baseline_overrides(self) -> dict:
        """Baseline parameter overrides with the off effects at their off values."""
        d = dict(self.baseline)
        for e in self.effects_off:
            d[get_effect(e).parameter] = get_effect(e).off
        return d

    def holdout(self, ids: list) -> list:
        """Held-out condition ids among ``ids`` (by explicit list or every n-th counting from the last)."""
        if self.holdout_observables:
            from .heldout import HELD_SUFFIX
            return [i for i in ids if str(i).endswith(HELD_SUFFIX)]
        if self.holdout_ids is not None:
            missing = [i for i in self.holdout_ids if i not in ids]
            if missing:
                raise ValueError(f"holdout ids {missing} are not conditions of the measured data (ids: {ids})")
            return [i for i in ids if i in self.holdout_ids]
        n = self.holdout_every
        return [cid for j, cid in enumerate(reversed(ids)) if j % n == 0][::-1]

    def candidate_param(self, name: str) -> CalibParam:
        """The strength of candidate ``name`` as a linear fitted parameter in [off, upper]."""
        e = get_effect(name)
        up = float(self.upper.get(name, e.upper))
        return CalibParam(name="effect:" + name, lower=e.off, upper=up, initial=float(self.probe.get(name, e.probe)), scale="linear")

    def probe_strength(self, name: str) -> float:
        return float(self.probe.get(name, get_effect(name).probe))


def fine_options(spec: DiscrepancySpec) -> list[dict]:
    """RunOptions dicts of the fine check runs, one per mesh realization ([] without ``[discretization]``).

    ``[options]`` overridden by ``[discretization]`` without ``mesh_seeds`` (not a RunOptions field): one
    entry, or with ``mesh_seeds`` one entry per seed s with ``mesh_seed = s``.  The measured data are one
    realization of mesh and porosity field, which the model cannot know; the realizations' mean is the
    better correction and their spread an uncertainty of the comparison (see noise.add_discretization_error).
    """
    if not spec.discretization:    # absent (or empty, as before: no fine runs)
        return []
    disc = {k: v for k, v in spec.discretization.items() if k != "mesh_seeds"}
    base = {**spec.options, **disc}
    seeds = spec.discretization.get("mesh_seeds")
    return [base] if seeds is None else [{**base, "mesh_seed": s} for s in seeds]


def _bad(key, value, allowed):
    raise ValueError(f"discrepancy spec: {key}={value!r} is not allowed: {allowed}")


def _check_mesh_seeds(disc: dict) -> None:
    """``[discretization] mesh_seeds``: a list of at least 2 distinct integers >= 0, without ``mesh_seed``."""
    seeds = disc["mesh_seeds"]
    allowed = "a list of at least 2 distinct integers >= 0 (one fine run per mesh realization)"
    if not isinstance(seeds, (list, tuple)) or len(seeds) < 2:
        _bad("discretization.mesh_seeds", seeds, allowed)
    for s in seeds:
        if not isinstance(s, int) or isinstance(s, bool) or s < 0:
            _bad("discretization.mesh_seeds", seeds, f"{allowed}; {s!r} is not")
    if len(set(seeds)) != len(seeds):
        _bad("discretization.mesh_seeds", seeds, f"{allowed}; a repeated seed repeats a realization")
    if "mesh_seed" in disc:
        _bad("discretization.mesh_seed", disc["mesh_seed"], "absent when mesh_seeds sets it per realization")


def _param_table(table: str, c: dict, base: dict) -> CalibParam:
    """One entry of ``[[calibrate]]`` or ``[[alternative]]``: a numeric solver.Parameters field that is not an
    effect strength, its bounds and scale, and its value (``initial``, default the baseline's) inside them.
    An alternative's value is always the baseline's: it is held fixed, its range says how uncertain it is."""
    from solver import Parameters

    name = c.get("name")
    if name not in Parameters.__dataclass_fields__ or name in (*CHOICE_FIELDS, "seed"):
        _bad(f"{table}.name", name, "a numeric solver.Parameters field")
    if name in {get_effect(e).parameter for e in EFFECTS}:
        _bad(f"{table}.name", name, "not an effect strength (effects are candidates)")
    lo, hi = float(c.get("lower", math.nan)), float(c.get("upper", math.nan))
    scale = c.get("scale", "log")
    if scale not in ("log", "linear"):
        _bad(f"{table}[{name}].scale", scale, "'log' or 'linear'")
    if not (lo < hi) or (scale == "log" and lo <= 0):
        _bad(f"{table}[{name}].lower/upper", (lo, hi), "lower < upper (and > 0 for log scale)")
    if table == "alternative" and "initial" in c:
        _bad(f"{table}[{name}].initial", c["initial"], "absent: an alternative keeps its baseline value")
    init = c.get("initial", base.get(name, getattr(Parameters(), name)))
    if init is None or not (lo <= float(init) <= hi):
        _bad(f"{table}[{name}].initial", init, f"inside [{lo}, {hi}]")
    step = c.get("step")
    if step is not None and not (isinstance(step, (int, float)) and not isinstance(step, bool) and step > 0):
        _bad(f"{table}[{name}].step", step, "a number > 0 (decades for log scale, the unit for linear)")
    return CalibParam(name, lo, hi, float(init), scale, step, float(init) if table == "alternative" else None)


def _check_alternatives(cal: tuple, alt: tuple) -> None:
    """Alternatives are distinct and not calibrated (a calibrated parameter's direction is projected anyway)."""
    names = [p.name for p in alt]
    for n in names:
        if names.count(n) > 1:
            _bad("alternative.name", n, "each parameter once")
        if n in {p.name for p in cal}:
            _bad("alternative.name", n, "a parameter that is not calibrated ([[calibrate]] already fits it)")


# the kind of each table and of the keys read before their own checks: (table, key or None, kind, allowed)
_SHAPES = (("baseline", None, dict, "a table"), ("candidates", None, dict, "a table"),
           ("holdout", None, dict, "a table"), ("options", None, dict, "a table of solver.RunOptions"),
           ("discretization", None, dict, "a table of solver.RunOptions and mesh_seeds"),
           ("calibrate", None, list, "an array of tables [[calibrate]]"),
           ("alternative", None, list, "an array of tables [[alternative]]"),
           ("baseline", "effects_off", list, "a list of effect names"),
           ("candidates", "effects", list, "a list of effect names"),
           ("candidates", "scaling", dict, "a table {effect = scaling}"),
           ("candidates", "upper", dict, "a table {effect = number}"),
           ("candidates", "probe", dict, "a table {effect = number}"),
           ("candidates", "independent", dict, 'a table {effect = "value ± sigma"}'))


def _check_shapes(d: dict) -> None:
    """Each table of ``d`` and the keys read before their own checks are of their kind (ValueError naming
    them); the entries of [[calibrate]] and [[alternative]] are tables with numeric bounds, effect lists hold
    names, and the upper / probe strengths are numbers."""
    for table, key, kind, allowed in _SHAPES:
        t = d.get(table)
        present = table in d if key is None else isinstance(t, dict) and key in t
        v = t if key is None else (t.get(key) if isinstance(t, dict) else None)
        if present and not isinstance(v, kind):
            _bad(table if key is None else f"{table}.{key}", v, allowed)
    for table in ("calibrate", "alternative"):
        for c in d.get(table, []):
            if not isinstance(c, dict):
                _bad(table, c, f"a table [[{table}]] with name, lower, upper")
            for k in ("lower", "upper", "initial"):
                if k in c and (isinstance(c[k], bool) or not isinstance(c[k], (int, float))):
                    _bad(f"{table}.{k}", c[k], "a number")
    for table, key in (("baseline", "effects_off"), ("candidates", "effects")):
        for e in d.get(table, {}).get(key, []):
            if not isinstance(e, str):
                _bad(f"{table}.{key}", e, "an effect name (text)")
    for key in ("upper", "probe"):
        for k, v in d.get("candidates", {}).get(key, {}).items():
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                _bad(f"candidates.{key}.{k}", v, "a number")


def _check_strengths(name: str, upper: dict, probe: dict) -> None:
    """Candidate ``name``'s upper strength (finite, above off) and probe strength (in (off, upper]: the
    signature is the model's change from off to the probe, the strength fitted in [off, upper]), each the
    SPEC's or the catalogue's."""
    e = get_effect(name)
    up, pr = upper.get(name, e.upper), probe.get(name, e.probe)
    if not (math.isfinite(up) and up > e.off):
        _bad(f"candidates.upper.{name}", up, f"a finite number above the effect's off value {e.off!r}")
    if not (math.isfinite(pr) and e.off < pr <= up):
        _bad(f"candidates.probe.{name}", pr, f"a number in ({e.off!r}, {up!r}]: above off (the signature is the "
             "change from off to the probe) and at most the upper strength")


def _independent(effect: str, v) -> tuple[float, float]:
    """An independent estimate of ``effect``'s strength, "value ± sigma" (also "+-") or [value, sigma], as
    (value, sigma) in the effect's unit; sigma > 0 and both finite."""
    get_effect(effect)
    try:
        if isinstance(v, str):
            parts = v.replace("+-", "±").split("±")
            val, sig = (float(x) for x in parts) if len(parts) == 2 else (math.nan, math.nan)
        else:
            val, sig = (float(x) for x in v)
    except (TypeError, ValueError):
        val, sig = math.nan, math.nan
    if not (math.isfinite(val) and math.isfinite(sig) and sig > 0):
        _bad(f"candidates.independent.{effect}", v, '"value ± sigma" or [value, sigma], finite, sigma > 0')
    return val, sig


def spec_from_dict(d: dict) -> DiscrepancySpec:
    """Validate a parsed TOML spec (see the module docstring)."""
    known = {"baseline", "calibrate", "alternative", "candidates", "holdout", "options", "discretization",
             *OPTION_TABLES}
    extra = sorted(set(d) - known - {"workflow"})      # [workflow]: refused by parse_options, naming its keys
    if extra:
        _bad("tables", extra, f"only {sorted(known)}")
    _check_shapes(d)
    base, off = _check_baseline(d.get("baseline", {}))
    cal = tuple(_param_table("calibrate", c, base) for c in d.get("calibrate", []))
    alt = tuple(_param_table("alternative", c, base) for c in d.get("alternative", []))
    _check_alternatives(cal, alt)
    names, scaling, upper, probe, independent = _check_candidates(d.get("candidates", {}), off)
    ids, every, hobs = _check_holdout(d.get("holdout", {}))
    opts, disc = _check_run_tables(dict(d.get("options", {})), d.get("discretization"))
    wo = parse_options(d)
    return DiscrepancySpec(base, off, cal, names, scaling, upper, probe,
                           tuple(ids) if ids is not None else None, every, opts,
                           dict(disc) if disc is not None else None, alt, independent,
                           tuple(hobs) if hobs is not None else (), wo.fit, wo.acceptance, wo.noise, wo.profile)


def _check_baseline(baseline: dict) -> tuple[dict, tuple]:
    """[baseline]: its parameters (solver.Parameters, units as there) without ``effects_off``, and the effects
    it switches off (each a catalogue effect)."""
    from solver import Parameters

    base = dict(baseline)
    off = tuple(base.pop("effects_off", ()))
    for e in off:
        get_effect(e)
    try:
        Parameters.from_dict(base)
    except ValueError as exc:
        raise ValueError(f"discrepancy spec [baseline]: {exc}") from None
    return base, off


def _check_candidates(cand: dict, off: tuple) -> tuple:
    """[candidates]: the effects (off in the baseline; default all of ``off``), their scalings, upper bounds
    and probe strengths (each effect's own unit), and independent estimates."""
    names = tuple(cand.get("effects", off))
    for e in names:
        get_effect(e)
        if e not in off:
            _bad("candidates.effects", e, f"effects that are off in the baseline ({list(off)})")
    scaling = dict(cand.get("scaling", {}))
    for k, v in scaling.items():
        get_effect(k)
        if v not in SCALINGS:
            _bad(f"candidates.scaling.{k}", v, list(SCALINGS))
    upper = {k: float(v) for k, v in cand.get("upper", {}).items()}
    probe = {k: float(v) for k, v in cand.get("probe", {}).items()}
    for k in list(upper) + list(probe):
        _check_strengths(k, upper, probe)
    independent = {k: _independent(k, v) for k, v in cand.get("independent", {}).items()}
    return names, scaling, upper, probe, independent


def _check_holdout(ho) -> tuple:
    """[holdout]: (ids, every, observables): whole conditions by id or every n-th, or held-out observables."""
    if not isinstance(ho, dict):
        _bad("holdout", ho, "a table: ids = [...] or every = n")
    ids = ho.get("ids")
    every = ho.get("every")
    if ids is not None and (not isinstance(ids, list) or not all(isinstance(i, str) for i in ids)):
        _bad("holdout.ids", ids, "a list of condition ids (text), e.g. [\"w65\"]")
    hobs = ho.get("observables")
    if hobs is not None:
        if ids is not None or every is not None:
            _bad("holdout", ho, "either ids / every (whole conditions) or observables, not both")
        from .observables import CURVES
        if (not isinstance(hobs, list) or not hobs
                or any(o not in (*CURVES, "regime") for o in hobs)):
            _bad("holdout.observables", hobs, f"a non-empty list of {[*CURVES, 'regime']}")
    elif ids is None and every is None:
        _bad("holdout", ho, "ids = [...], every = n (whole conditions are held out) or observables = [...]")
    if every is not None and (not isinstance(every, int) or every < 2):
        _bad("holdout.every", every, "an integer >= 2")
    return ids, every, hobs


def _check_run_tables(opts: dict, disc) -> tuple[dict, dict | None]:
    """[options] and [discretization]: each a valid solver.RunOptions (mm, s) on its own and over the other."""
    from solver import RunOptions

    try:
        RunOptions.from_dict(opts)
    except ValueError as exc:
        raise ValueError(f"discrepancy spec [options]: {exc}") from None
    if disc is not None:
        if "mesh_seeds" in disc:
            _check_mesh_seeds(disc)
        try:
            RunOptions.from_dict({**opts, **{k: v for k, v in disc.items() if k != "mesh_seeds"}})
        except ValueError as exc:
            raise ValueError(f"discrepancy spec [discretization]: {exc}") from None
    return opts, disc


def load_spec(path) -> DiscrepancySpec:
    """Read and validate a SPEC TOML file."""
    from solver.tomlio import read_toml

    path = Path(path)
    if not path.is_file():
        raise ValueError(f"discrepancy spec {path} not found")
    return spec_from_dict(read_toml(path))
