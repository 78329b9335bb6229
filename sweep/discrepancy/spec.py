"""The model SPEC of the discrepancy workflow (TOML), validated before any work.

Example (units mm, s, kPa)::

    [baseline]                       # solver.Parameters fields common to every condition
    kbar = 0.0015
    effects_off = ["damage_viscosity", "outer_compliance"]   # effect names set to their off values

    [[calibrate]]                    # baseline parameters fitted on the training conditions
    name = "kbar"; lower = 5e-4; upper = 5e-3; scale = "log"     # initial = baseline value

    [candidates]
    effects = ["damage_viscosity", "compliant_boundary"]        # default: every effect off in the baseline
    scaling = { damage_viscosity = "sqrt_cement" }              # optional: parameter = strength * sqrt(C)
    upper = { damage_viscosity = 200.0 }                          # optional: strength bounds / probes
    probe = { damage_viscosity = 40.0 }

    [holdout]                        # whole conditions, never time points
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
                                     # their sample std (kPa, mm) is added in quadrature to σ

    [workflow]                       # criteria (defaults shown); passing candidates are ranked, and tied
                                     # within tie_bic, by their BICs under common series weights
    delta_bic = -10.0; tie_bic = 10.0; min_gap_reduction = 0.1; min_explained = 0.5
    min_ratio = 0.15; tie_cos = 0.95; max_rounds = 3; max_refits = 2; starts = 1
    loss = "soft_l1"; f_scale = 3.0; max_nfev = 20; n_jobs = 1; seed = 0
    disc_error_fraction = 0.5; disc_refresh = 1   # at most this many refresh passes (0: none) ...
    disc_refresh_tol = 0.05          # ... stopping once every named strength moves by <= this (relative) in a pass
    interval = "profile"             # the named strength's interval: "profile" (likelihood) or "wald"
    profile_expand = 3               # doublings of the profile bracket beyond the Wald bound
    profile_refine = 2               # evaluations refining each bound (regula falsi in √Δχ²) ...
    profile_refine_tol = 0.15        # ... until Δχ² there is within this fraction of the threshold
    profile_rough_tol = 0.25         # flag the interval when the profile falls by more than this fraction of
                                     # its threshold walking away from the fit (a jagged coarse model)
    profile_fine = true              # with [discretization]: correct each profile point where it is (the
                                     # correction is a constant vector; false keeps the fit's along the profile)
    named_needs_noise_level = true   # name an effect only if the named model's residuals are at noise level
    realization_covariance = "correlated"   # how mesh realizations' deviations enter the residuals: "correlated"
                                     # (per series, correlated in time, estimated from the realizations;
                                     # residuals whitened) or "diagonal" (the simplification: per-point
                                     # sample std in quadrature)
    systematic_null = "estimated_covariance"   # the residual test's null with a correlated realization
                                     # covariance: "estimated_covariance" (its scale has k − 1 degrees of
                                     # freedom: statistics mapped to the known-covariance scale by simulation)
                                     # or "known_covariance" (the simplification: the estimate taken as exact)
    model_jitter = "none"            # the coarse model's jitter in its parameters as an error term
                                     # (sweep/discrepancy/jitter.py): "estimated" (runs at model_jitter_steps
                                     # values q (1 + model_jitter_rel_step j) of each free parameter, at the
                                     # initial baseline and again at a named model's fit; the polynomial
                                     # residuals' variance is added to the covariance the residuals are
                                     # whitened with) or "none" (not modelled: right for a model smooth in its
                                     # parameters; campaigns run before 2026-11-25's third sitting)
    model_jitter_steps = 7; model_jitter_rel_step = 0.05
    profile_smoothing = "none"       # "quadratic": the named strength's interval from a quadratic fitted to the
                                     # profile points with a Monte-Carlo-adjusted cutoff (MCAP, Ionides et al.
                                     # 2017; stats.quadratic_profile_interval), for a model whose profile
                                     # points are noisy (model_jitter); "none": the raw crossings
    profile_grid = 4                 # with "quadratic": this many more profile points per side, evenly out to
                                     # twice the raw bound's distance from the fit (the quadratic's span)
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from solver.effects import EFFECTS, get_effect
from solver.params import CHOICE_FIELDS

__all__ = ["CalibParam", "DiscrepancySpec", "load_spec", "spec_from_dict", "fine_options", "SCALINGS"]

SCALINGS = ("none", "sqrt_cement")
_WF_DEFAULTS = dict(delta_bic=-10.0, tie_bic=10.0, min_gap_reduction=0.1, min_explained=0.5, min_ratio=0.15,
                    tie_cos=0.95, max_rounds=3, max_refits=2, starts=1, loss="soft_l1", f_scale=3.0,
                    max_nfev=20, n_jobs=1, seed=0, diff_step=0.02, z_crit=3.0, rho_crit=0.3, nan_residual=50.0,
                    disc_error_fraction=0.5, disc_refresh=1, disc_refresh_tol=0.05, profile_fine=True, interval="profile", profile_expand=3,
                    profile_refine=2, profile_refine_tol=0.15, profile_rough_tol=0.25,
                    named_needs_noise_level=True, realization_covariance="correlated",
                    systematic_null="estimated_covariance", model_jitter="none", model_jitter_steps=7,
                    model_jitter_rel_step=0.05, profile_smoothing="none", profile_grid=4)

_WF_CHOICES = {"interval": ("profile", "wald"), "realization_covariance": ("correlated", "diagonal"),
               "systematic_null": ("estimated_covariance", "known_covariance"), "model_jitter": ("none", "estimated"),
               "profile_smoothing": ("none", "quadratic")}


@dataclass(frozen=True)
class CalibParam:
    """A fitted parameter: name (Parameters field), bounds, initial value, scale "log" | "linear", FD step
    (in decades for log, in the parameter's unit for linear; None = 2 % of the range)."""

    name: str
    lower: float
    upper: float
    initial: float
    scale: str = "log"
    step: float | None = None

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
    workflow: dict = field(default_factory=dict)
    discretization: dict | None = None

    def wf(self, key):
        return self.workflow.get(key, _WF_DEFAULTS[key])

    def baseline_overrides(self) -> dict:
        """Baseline parameter overrides with the off effects at their off values."""
        d = dict(self.baseline)
        for e in self.effects_off:
            d[get_effect(e).parameter] = get_effect(e).off
        return d

    def holdout(self, ids: list) -> list:
        """Held-out condition ids among ``ids`` (by explicit list or every n-th counting from the last)."""
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
    better correction and their spread an uncertainty of the comparison (see workflow.add_discretization_error).
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


def spec_from_dict(d: dict) -> DiscrepancySpec:
    """Validate a parsed TOML spec (see the module docstring)."""
    from solver import Parameters, RunOptions

    known = {"baseline", "calibrate", "candidates", "holdout", "options", "workflow", "discretization"}
    extra = sorted(set(d) - known)
    if extra:
        _bad("tables", extra, f"only {sorted(known)}")
    base = dict(d.get("baseline", {}))
    off = tuple(base.pop("effects_off", ()))
    for e in off:
        get_effect(e)
    try:
        Parameters.from_dict(base)
    except ValueError as exc:
        raise ValueError(f"discrepancy spec [baseline]: {exc}") from None
    cal = []
    for c in d.get("calibrate", []):
        name = c.get("name")
        if name not in Parameters.__dataclass_fields__ or name in (*CHOICE_FIELDS, "seed"):
            _bad("calibrate.name", name, "a numeric solver.Parameters field")
        if name in {get_effect(e).parameter for e in EFFECTS}:
            _bad("calibrate.name", name, "not an effect strength (effects are candidates)")
        lo, hi = float(c.get("lower", math.nan)), float(c.get("upper", math.nan))
        scale = c.get("scale", "log")
        if scale not in ("log", "linear"):
            _bad(f"calibrate[{name}].scale", scale, "'log' or 'linear'")
        if not (lo < hi) or (scale == "log" and lo <= 0):
            _bad(f"calibrate[{name}].lower/upper", (lo, hi), "lower < upper (and > 0 for log scale)")
        init = c.get("initial", base.get(name, getattr(Parameters(), name)))
        if init is None or not (lo <= float(init) <= hi):
            _bad(f"calibrate[{name}].initial", init, f"inside [{lo}, {hi}]")
        cal.append(CalibParam(name, lo, hi, float(init), scale, c.get("step")))
    cand = d.get("candidates", {})
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
        get_effect(k)
    ho = d.get("holdout", {})
    ids = ho.get("ids")
    every = ho.get("every")
    if ids is None and every is None:
        _bad("holdout", ho, "ids = [...] or every = n (whole conditions are held out)")
    if every is not None and (not isinstance(every, int) or every < 2):
        _bad("holdout.every", every, "an integer >= 2")
    opts = dict(d.get("options", {}))
    try:
        RunOptions.from_dict(opts)
    except ValueError as exc:
        raise ValueError(f"discrepancy spec [options]: {exc}") from None
    disc = d.get("discretization")
    if disc is not None:
        if "mesh_seeds" in disc:
            _check_mesh_seeds(disc)
        try:
            RunOptions.from_dict({**opts, **{k: v for k, v in disc.items() if k != "mesh_seeds"}})
        except ValueError as exc:
            raise ValueError(f"discrepancy spec [discretization]: {exc}") from None
    wf = dict(d.get("workflow", {}))
    unknown = sorted(set(wf) - set(_WF_DEFAULTS))
    if unknown:
        _bad("workflow", unknown, f"keys among {sorted(_WF_DEFAULTS)}")
    for key, allowed in _WF_CHOICES.items():      # the enumerated options, checked alike
        v = wf.get(key, _WF_DEFAULTS[key])
        if v not in allowed:
            _bad(f"workflow.{key}", v, " or ".join(f'"{c}"' for c in allowed))
    for key in ("profile_fine", "named_needs_noise_level"):
        if not isinstance(wf.get(key, True), bool):
            _bad(f"workflow.{key}", wf[key], "true or false")
    pg = wf.get("profile_grid", 4)
    if not isinstance(pg, int) or isinstance(pg, bool) or not 2 <= pg <= 20:
        _bad("workflow.profile_grid", pg, "an integer in [2, 20] (profile points per side for the quadratic)")
    ms = wf.get("model_jitter_steps", 7)
    if not isinstance(ms, int) or isinstance(ms, bool) or ms < 5 or ms % 2 == 0 or ms > 21:
        _bad("workflow.model_jitter_steps", ms, "an odd integer in [5, 21] (runs per stepped parameter)")
    mr = wf.get("model_jitter_rel_step", 0.05)
    if not isinstance(mr, (int, float)) or isinstance(mr, bool) or not 0 < mr < 0.5:
        _bad("workflow.model_jitter_rel_step", mr, "a number in (0, 0.5) (relative step of a parameter)")
    pr = wf.get("profile_refine", 2)
    if not isinstance(pr, int) or isinstance(pr, bool) or not 0 <= pr <= 10:
        _bad("workflow.profile_refine", pr, "an integer in [0, 10]")
    prt = wf.get("profile_refine_tol", 0.15)
    if not isinstance(prt, (int, float)) or isinstance(prt, bool) or not 0 < prt < 1:
        _bad("workflow.profile_refine_tol", prt, "a number in (0, 1)")
    prr = wf.get("profile_rough_tol", 0.25)
    if not isinstance(prr, (int, float)) or isinstance(prr, bool) or not 0 < prr <= 10:
        _bad("workflow.profile_rough_tol", prr, "a number in (0, 10]")
    pe = wf.get("profile_expand", 3)
    if not isinstance(pe, int) or isinstance(pe, bool) or not 0 <= pe <= 10:
        _bad("workflow.profile_expand", pe, "an integer in [0, 10]")
    dr = wf.get("disc_refresh", 1)
    if not isinstance(dr, int) or isinstance(dr, bool) or not 0 <= dr <= 20:
        _bad("workflow.disc_refresh", dr, "an integer in [0, 20] (refresh passes at most)")
    dt = wf.get("disc_refresh_tol", 0.05)
    if isinstance(dt, bool) or not isinstance(dt, (int, float)) or not 0 < dt < 1:
        _bad("workflow.disc_refresh_tol", dt, "a number in (0, 1) (relative change of a named strength)")
    return DiscrepancySpec(base, off, tuple(cal), names, scaling, upper, probe,
                           tuple(ids) if ids is not None else None, every, opts, wf,
                           dict(disc) if disc is not None else None)


def load_spec(path) -> DiscrepancySpec:
    """Read and validate a SPEC TOML file."""
    from solver.tomlio import read_toml

    path = Path(path)
    if not path.is_file():
        raise ValueError(f"discrepancy spec {path} not found")
    return spec_from_dict(read_toml(path))
