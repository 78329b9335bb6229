"""The workflow's settings: typed, frozen option dataclasses grouped by concern, validated in one loop.

A SPEC (TOML) sets them in four tables, every key optional (defaults below)::

    [fit]          how a model is fitted: robust least squares, starts, budget
    [acceptance]   when a candidate effect is named, tied or refused
    [noise]        the error model: discretization correction, its refresh, the coarse model's jitter
    [profile]      the profile-likelihood interval of a named strength

Each field declares its allowed values once (``_rule``); :func:`parse_options` checks every field of every
table by one loop and names the table, key, value and what is allowed.  Units: mm, s, kPa where a value has
one (most are dimensionless: standardized residuals, BIC, fractions).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

from .stats import LAG1_ESTIMATORS, THRESHOLDS

__all__ = ["FitOptions", "AcceptanceOptions", "NoiseOptions", "ProfileOptions", "WorkflowOptions",
           "parse_options", "OPTION_TABLES", "REMOVED_WORKFLOW_KEYS"]


def _rule(default, kind: str, lo=None, hi=None, lo_open=False, hi_open=False, choices=(), odd=False, doc=""):
    """A field with its allowed values: kind "int" | "float" | "bool" | "choice", bounds [lo, hi] (open
    ends with ``lo_open``/``hi_open``), ``choices`` for "choice", ``odd`` for odd integers; ``doc`` says
    what it does (the SPEC template of ``dchfrac discrepancy init`` prints it)."""
    return field(default=default, metadata={"kind": kind, "lo": lo, "hi": hi, "lo_open": lo_open,
                                            "hi_open": hi_open, "choices": tuple(choices), "odd": odd, "doc": doc})


class _Checked:
    """Validation of every field by its rule on construction (one loop, as solver.options.RunOptions); a
    float field given as an int is stored as a float.  ``TABLE``: the SPEC table, for the messages."""

    TABLE = ""

    def __post_init__(self):
        for f in fields(self):
            v = getattr(self, f.name)
            if not _ok(f, v):
                raise ValueError(f"discrepancy spec: {self.TABLE}.{f.name}={v!r} is not allowed: {_allowed(f)}")
            if f.metadata["kind"] == "float":
                object.__setattr__(self, f.name, float(v))


@dataclass(frozen=True)
class FitOptions(_Checked):
    """Bounded robust least squares (scipy TRF) on standardized residuals."""

    TABLE = "fit"

    loss: str = _rule("soft_l1", "choice", choices=("soft_l1", "linear", "huber", "cauchy", "arctan"),
                      doc="robust loss of scipy.optimize.least_squares")
    f_scale: float = _rule(3.0, "float", 0.0, lo_open=True, doc="residual scale where the robust loss bends")
    max_nfev: int = _rule(20, "int", 1, doc="function evaluations per least-squares start")
    chi2_tol: float = _rule(0.0, "float", 0.0,
                            doc="a least-squares start stops once a step lowers the (robust) chi2 by less than "
                                "this (0: scipy's ftol 1e-8, run to max_nfev on a model with jitter); a chi2 "
                                "far below every interval's threshold (3.84 and up) moves no reported number")
    starts: int = _rule(1, "int", 1, 50, doc="starts per fit (the spec's initial values, then random ones)")
    seed: int = _rule(0, "int", 0, doc="seed of the random starts and of the residual test's null draws")
    nan_residual: float = _rule(50.0, "float", 0.0, lo_open=True,
                                doc="standardized residual of a point the model could not compute (failed run)")
    n_jobs: int = _rule(1, "int", 1, 256, doc="parallel solver runs")
    prefetch_jacobian: bool = _rule(False, "bool",
                                    doc="run the forward-difference Jacobian's points in the batch of each residual "
                                        "evaluation of a real least-squares fit (the same points and numbers: with "
                                        "n_jobs >= 2 the runs fill the parallel slots a batch of one run per "
                                        "condition leaves idle; a rejected step's Jacobian runs are wasted)")


@dataclass(frozen=True)
class AcceptanceOptions(_Checked):
    """When an effect is named or tied: evidence, screening and the residual test."""

    TABLE = "acceptance"

    delta_bic: float = _rule(-10.0, "float", hi=0.0, doc="BIC change a candidate's refit must reach (<=)")
    tie_bic: float = _rule(10.0, "float", 0.0, doc="passing candidates within this BIC (common weights) tie")
    min_gap_reduction: float = _rule(0.1, "float", 0.0, 1.0, hi_open=True,
                                     doc="relative shrink of the held-out gap a candidate needs")
    min_explained: float = _rule(0.5, "float", 0.0, 1.0, doc="fraction of the excess chi2 a candidate must explain")
    min_ratio: float = _rule(0.15, "float", 0.0, 1.0, hi_open=True,
                             doc="signature left outside the calibrated parameters' span, below: not identifiable")
    tie_cos: float = _rule(0.95, "float", 0.0, 1.0, doc="signatures this parallel are tied in the screen")
    z_crit: float = _rule(3.0, "float", 0.0, lo_open=True, doc="residual test: chi2-excess z of a systematic series")
    rho_crit: float = _rule(0.3, "float", 0.0, 1.0, doc="residual test: lag-1 autocorrelation of a systematic series")
    max_rounds: int = _rule(3, "int", 1, 20, doc="effects named one after another at most")
    max_refits: int = _rule(2, "int", 1, 50, doc="best-screened candidates refitted per round (plus their ties)")
    confounded_measurements: bool = _rule(
        True, "bool", doc="for each candidate the screen finds inside the reach of the [[alternative]] parameters: "
                          "run its mimic (one run per training condition) and name the measurements that would tell "
                          "them apart (discriminate.confounded_measurements)")


@dataclass(frozen=True)
class NoiseOptions(_Checked):
    """The error model beside the measured uncertainties (noise.py)."""

    TABLE = "noise"

    disc_error_fraction: float = _rule(0.5, "float", 0.0, 1.0,
                                       doc="this fraction of the discretization correction added to sigma")
    disc_refresh: int = _rule(1, "int", 0, 20,
                              doc="passes re-estimating the correction at the named model's fit (0: none)")
    disc_refresh_tol: float = _rule(0.05, "float", 0.0, 1.0, lo_open=True, hi_open=True,
                                    doc="refresh stops once every named strength moves by <= this (relative)")
    disc_refresh_tol_sd: float = _rule(0.0, "float", 0.0, 10.0,
                                       doc="refresh also stops once every named strength moves by <= this times "
                                           "its Wald standard error at the pass's fit (0: off)")
    realization_blocks: str = _rule(
        "series", "choice", choices=("series", "observable"),
        doc="blocks of the mesh-realization covariance: series (one per condition x observable, independent) or "
            "observable (one per observable over all its conditions, correlated between conditions at the pooled "
            "correlation rho_o of the realizations' deviation curves: the data are one realization for every "
            "condition)")
    lag1: str = _rule(
        "pooled", "choice", choices=tuple(LAG1_ESTIMATORS),
        doc="estimator of the lag-1 autocorrelation rho giving the correlation time tau = -dt/ln rho of the "
            "realization covariance and of the jitter term: pooled (the sum of the n - 1 lag products over the sum "
            "of the n squares of each curve: E = (n - 1)/n rho, tau short) or mean_ratio (the mean lag product over "
            "the mean square, each sum over its own count: E -> rho; stats.mean_ratio_lag1)")
    model_jitter: str = _rule("none", "choice", choices=("none", "estimated"),
                              doc="the coarse model's jitter in its parameters as an error term")
    model_jitter_steps: int = _rule(7, "int", 5, 21, odd=True, doc="runs per stepped parameter (odd)")
    model_jitter_rel_step: float = _rule(0.05, "float", 0.0, 0.5, lo_open=True, hi_open=True,
                                         doc="relative step of a parameter when estimating the jitter")


@dataclass(frozen=True)
class ProfileOptions(_Checked):
    """The named strength's profile-likelihood interval (profile.py)."""

    TABLE = "profile"

    expand: int = _rule(3, "int", 0, 10, doc="doublings of the bracket beyond the Wald bound")
    refine: int = _rule(2, "int", 0, 10, doc="evaluations refining each bound (regula falsi in sqrt(delta chi2))")
    refine_tol: float = _rule(0.15, "float", 0.0, 1.0, lo_open=True, hi_open=True,
                              doc="refinement stops when delta chi2 is within this fraction of the threshold")
    rough_tol: float = _rule(0.25, "float", 0.0, 10.0, lo_open=True,
                             doc="flag the interval when the profile falls by this fraction of its threshold")
    fine: bool = _rule(True, "bool", doc="with [discretization]: correct each profile point where it is "
                                         "(false: the fit's correction, far cheaper)")
    correction: str = _rule("point", "choice", choices=("point", "linear", "piecewise"),
                            doc="with fine = true: point (the correction re-estimated at each profile point from the "
                                "realizations), linear (the correction as a linear function of the strength, fitted "
                                "once from the realizations at correction_anchors strengths and the same for every "
                                "point and re-centring: common random numbers, a smooth profile) or piecewise (linear "
                                "between those anchors, and an anchor added wherever the profile goes beyond them: "
                                "never extrapolated)")
    correction_follows: str = _rule(
        "strength", "choice", choices=("strength", "all"),
        doc="with correction = linear: what the correction is a linear function of: strength (the profiled "
            "strength only; each refit made under its value at the held strength) or all (the strength and every "
            "calibrated parameter, from two more anchors per calibrated parameter at the fit +- correction_span Wald "
            "half-widths; every refit of the profile and the named model's settling evaluate it at their own "
            "trial parameters, so a fit sees how the fine-minus-coarse difference moves with what it fits)")
    correction_anchors: int = _rule(3, "int", 2, 9, doc="with correction = linear or piecewise: strengths the "
                                                        "correction is first estimated at (the fit and evenly about "
                                                        "it)")
    correction_span: float = _rule(1.0, "float", 0.0, 10.0, lo_open=True,
                                   doc="with correction = linear or piecewise: the first anchors' reach about the "
                                       "fit, in Wald half-widths of the 95 % interval (of the strength; with "
                                       "correction_follows = all also of each calibrated parameter)")
    correction_slope_realizations: int = _rule(
        0, "int", 0, 50, doc="with correction = linear: 0 runs every fine realization at every anchor; m >= 1 runs "
                             "them all at the first anchor and the first m at the others, whose correction is the "
                             "first's plus the mean change of those m realizations between the two (common random "
                             "numbers: a realization's own deviation cancels in its change)")
    correction_realizations: int = _rule(
        0, "int", 0, 50, doc="with correction = linear: 0 runs every fine realization at every anchor; m >= 2 runs the "
                             "first m at every anchor (common random numbers), and the realization covariance's term "
                             "for the error of the mean correction becomes 1/m of the realization variance instead "
                             "of 1/k (the covariance scaled by (1 + 1/m)/(1 + 1/k)): fewer fine runs, a wider "
                             "interval")
    smoothing: str = _rule("none", "choice", choices=("none", "quadratic"),
                           doc="quadratic: the interval from a quadratic through noisy profile points (MCAP)")
    grid: int = _rule(4, "int", 2, 20, doc="with quadratic smoothing: extra profile points per side")
    likelihood: str = _rule("weighted", "choice", choices=("weighted", "gaussian", "marginal"),
                            doc="delta chi2 of the profile: weighted (series weights n_eff/n from the fit's "
                                "lag-1 autocorrelation), gaussian (the whitened chi2), marginal (the realization "
                                "covariance's scale integrated over its sampling distribution from k realizations)")
    threshold: str = _rule("chi2", "choice", choices=THRESHOLDS,
                           doc="delta chi2 threshold of the interval: chi2 (the chi2(1) quantile, 3.84 at 95 %), "
                               "f_realizations (the F(1, k - 1) quantile at the same probability, k the mesh "
                               "realizations: the strength's variance counted as known to k - 1 degrees of freedom; "
                               "6.61 at k = 6, 18.5 at k = 3) or f_welch (F(1, nu), nu the Welch-Satterthwaite "
                               "degrees of freedom with only the variance's realization part known to k - 1: "
                               "between k - 1 and infinity); chi2(1) without realizations (NoiseModel.threshold_dof)")
    emulator: str = _rule("none", "choice", choices=("none", "gp"),
                          doc="gp: the profile points' refits on a Gaussian-process emulator of the coarse model "
                              "(emulator.py), its predictive covariance added to the likelihood's, refined with "
                              "real runs where the profile goes and at the interval's ends (none: real runs only)")
    emulator_design: int = _rule(8, "int", 3, 200,
                                 doc="with the emulator: space-filling design points around the fit (the fit's own "
                                     "included; at least parameters + 4 are used), one run per training condition each")
    emulator_tol: float = _rule(0.1, "float", 0.0, 10.0, lo_open=True,
                                doc="with the emulator: its predictive sd allowed at a profile point, as the norm of "
                                    "the whitened residuals; beyond it a real run is added there")
    emulator_checks: int = _rule(3, "int", 1, 20,
                                 doc="with the emulator: real runs confirming each interval end at most (the emulator "
                                     "refined and the end recomputed while they disagree beyond its sd)")

    emulate_refits: bool = _rule(False, "bool",
                                 doc="with the emulator: also the candidates' multi-start joint refits and the "
                                     "profile's re-centring refit on emulators, each emulated optimum checked with "
                                     "a real run and polished by real least squares (single-start refits stay real)")
    emulator_polish: int = _rule(2, "int", 1, 50,
                                 doc="with emulate_refits: real least-squares evaluations from an emulated optimum, "
                                     "each with its Jacobian (1: the residuals and Jacobian there only)")

    def __post_init__(self):
        super().__post_init__()
        if self.correction in ("linear", "piecewise") and not self.fine:
            raise ValueError(f"discrepancy spec: profile.correction=\"{self.correction}\" is not allowed with "
                             "profile.fine=false (the fit's correction for every point): set fine = true or "
                             "correction = \"point\"")
        if self.correction == "piecewise" and self.correction_slope_realizations:
            raise ValueError(f"discrepancy spec: profile.correction_slope_realizations="
                             f"{self.correction_slope_realizations} is not allowed with profile.correction="
                             "\"piecewise\" (an anchor added beyond the others runs every realization): set "
                             "correction = \"linear\" or correction_slope_realizations = 0")
        if self.correction_follows != "strength" and self.correction != "linear":
            raise ValueError(f"discrepancy spec: profile.correction_follows=\"{self.correction_follows}\" is not allowed "
                             f"with profile.correction=\"{self.correction}\" (only the linear correction is a function "
                             "of the parameters): set correction = \"linear\" or correction_follows = \"strength\"")
        if self.correction_realizations and self.correction != "linear":
            raise ValueError(f"discrepancy spec: profile.correction_realizations={self.correction_realizations} is not "
                             f"allowed with profile.correction=\"{self.correction}\": set correction = \"linear\" or "
                             "correction_realizations = 0")
        if self.correction_realizations == 1:
            raise ValueError("discrepancy spec: profile.correction_realizations=1 is not allowed: a mean and its error "
                             "need at least 2 realizations (0: all of them)")
        if self.correction_realizations and self.correction_slope_realizations:
            raise ValueError(f"discrepancy spec: profile.correction_realizations={self.correction_realizations} is not "
                             f"allowed with profile.correction_slope_realizations={self.correction_slope_realizations}"
                             ": set one of them to 0")
        if self.emulate_refits and self.emulator == "none":
            raise ValueError("discrepancy spec: profile.emulate_refits=true is not allowed with "
                             "profile.emulator=\"none\": set emulator = \"gp\" or emulate_refits = false")


@dataclass(frozen=True)
class WorkflowOptions:
    """All four groups, as a SPEC holds them."""

    fit: FitOptions = field(default_factory=FitOptions)
    acceptance: AcceptanceOptions = field(default_factory=AcceptanceOptions)
    noise: NoiseOptions = field(default_factory=NoiseOptions)
    profile: ProfileOptions = field(default_factory=ProfileOptions)


OPTION_TABLES = {"fit": FitOptions, "acceptance": AcceptanceOptions, "noise": NoiseOptions, "profile": ProfileOptions}

# keys of the former string-keyed [workflow] table: where each went, or why it is gone (the loader's message)
REMOVED_WORKFLOW_KEYS = {
    "diff_step": "removed (never read: each calibrated parameter's step is its [[calibrate]] step)",
    "interval": "removed: the named strength's interval is always the profile likelihood",
    "realization_covariance": "removed: mesh realizations always enter as a covariance correlated in time",
    "systematic_null": "removed: the residual test is always calibrated for the estimated covariance",
    "named_needs_noise_level": "removed: an effect is named only when the named model's residuals are at noise level",
}


def _allowed(f) -> str:
    m = f.metadata
    if m["kind"] == "bool":
        return "true or false"
    if m["kind"] == "choice":
        return " or ".join(f'"{c}"' for c in m["choices"])
    what = "an odd integer" if m["odd"] else ("an integer" if m["kind"] == "int" else "a number")
    lo, hi = (None if b is None else f"{b:g}" for b in (m["lo"], m["hi"]))
    if lo is not None and hi is not None:
        return f"{what} in {'(' if m['lo_open'] else '['}{lo}, {hi}{')' if m['hi_open'] else ']'}"
    if lo is not None:
        return f"{what} {'>' if m['lo_open'] else '>='} {lo}"
    if hi is not None:
        return f"{what} {'<' if m['hi_open'] else '<='} {hi}"
    return what


def _ok(f, v) -> bool:
    m = f.metadata
    if m["kind"] == "bool":
        return isinstance(v, bool)
    if m["kind"] == "choice":
        return v in m["choices"]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or (m["kind"] == "int" and not isinstance(v, int)):
        return False
    if not math.isfinite(v) or (m["odd"] and v % 2 == 0):
        return False
    lo, hi = m["lo"], m["hi"]
    if lo is not None and (v <= lo if m["lo_open"] else v < lo):
        return False
    return not (hi is not None and (v >= hi if m["hi_open"] else v > hi))


def _table(name: str, cls, d: dict):
    """One option table: unknown keys named; the values checked by the dataclass itself."""
    known = {f.name: f for f in fields(cls)}
    unknown = sorted(set(d) - set(known))
    if unknown:
        raise ValueError(f"discrepancy spec: [{name}] {unknown} unknown; keys allowed: {sorted(known)}")
    return cls(**d)                              # every field checked by __post_init__


def _reject_workflow_table(wf: dict) -> None:
    """The former [workflow] table: refused, each key named with its new table or why it was removed."""
    where = {f.name: f"[{t}] {f.name}" for t, cls in OPTION_TABLES.items() for f in fields(cls)}
    where.update({f"profile_{f.name}": f"[profile] {f.name}" for f in fields(ProfileOptions)})
    moves = [f"{k!r} -> {REMOVED_WORKFLOW_KEYS.get(k) or where.get(k) or 'unknown'}" for k in sorted(wf)]
    raise ValueError("discrepancy spec: the [workflow] table is replaced by [fit], [acceptance], [noise] and "
                     "[profile]; " + ("; ".join(moves) if moves else "remove it"))


def parse_options(d: dict) -> WorkflowOptions:
    """The four option tables of a parsed SPEC ``d`` (other tables ignored here), validated."""
    if "workflow" in d:
        if not isinstance(d["workflow"], dict):
            raise ValueError(f"discrepancy spec: [workflow] = {d['workflow']!r} is not allowed: its settings moved to "
                             f"the tables {sorted(OPTION_TABLES)}")
        _reject_workflow_table(dict(d["workflow"]))
    parts = {}
    for name, cls in OPTION_TABLES.items():
        t = d.get(name, {})
        if not isinstance(t, dict):
            raise ValueError(f"discrepancy spec: [{name}] must be a table, not {t!r}")
        parts[name] = _table(name, cls, t)
    return WorkflowOptions(**parts)
