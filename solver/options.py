"""Run options: discretization, time stepping, tolerances, outputs (mm, s)."""
from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field, fields, replace
from numbers import Integral, Real

import numpy as np

from .paths import PRECISIONS
from .plausible import did_you_mean, implausible, slip_message
from .tomlio import read_toml, write_flat_toml

_LINEAR_SOLVERS = ("auto", "superlu", "pypardiso")
TRANSPORTS = ("galerkin", "upwind", "supg")  # the transport discretizations of solver.forms
STEP_CONTROLS = ("state_change", "iterations")  # the step-size controllers solver.simulate._next_dt implements
# options added after runs were stored: left out of to_dict() at their default (None), so the
# option dicts (and the run keys / cache hashes made from them) of older runs do not change
_OMIT_WHEN_NONE = ("h_inner", "inner_grading_length", "h_outer", "frames", "xdmf_format", "pressure_stabilization", "first_stagger_rtol",
                   "linear_precision", "newton_krylov")
# options that do not change an uninterrupted run's result: left out of to_dict() at their default and never part
# of a run key or cache hash (``keyed``), so setting them names the same run
RESULT_NEUTRAL = {"checkpoint_interval": 600.0}
# written when not given; those after t_end are skipped (times given explicitly must lie in [0, t_end])
DEFAULT_SNAPSHOT_TIMES = (0.5, 1.0, 1.5, 2.0)


@dataclass(frozen=True)
class RunOptions:
    """How to solve: none of these change the model, only its discretization.

    Attributes
    ----------
    h : mesh size, mm (the paper's reference mesh: 1.0); below (r_outer - r_inner)/2 (:func:`check_run_inputs`).
    h_inner : mesh size on the inner circle, mm, 0 < h_inner <= h: the annulus mesh is graded from
        h_inner at r_inner to h at r_inner + ``inner_grading_length`` (see ``solver.mesh.annulus_mesh``); None
        (default) or h: the quasi-uniform mesh of size h.  Omitted from :meth:`to_dict` when None, so the run
        keys / cache hashes of runs made before this option existed are unchanged.
    inner_grading_length : distance from r_inner over which the inner grading reaches h, mm, > 0 (None, the
        default: ``solver.mesh.GRADING_LENGTH`` = 5 mm).  A longer one keeps the cracks that start at the cavity
        (the paper's reach r_i + 6 mm at 2 s) inside the fine zone.  Needs h_inner; omitted from :meth:`to_dict`
        when None, as h_inner.
    h_outer : mesh size on the outer circle, mm, 0 < h_outer <= h: the annulus mesh is graded from
        h_outer at r_outer to h at r_outer - 5 mm (resolves the boundary layer at the drained outer
        wall; combinable with h_inner); None (default) or h: no outer grading.  Omitted from
        :meth:`to_dict` when None, like h_inner.
    mesh_seed : perturbation seed of the mesh generator (None = deterministic default).
    t_end : final time, s.
    dt0 : time step of the first step, s (later steps follow ``step_control``).
    dt_min : smallest time step, s: a step that would be cut below it fails the run.
    dt_max : largest time step, s: the controller never grows dt beyond it.
    step_control : the step-size controller after an accepted step (``solver.simulate._next_dt``):
        "state_change" (default): the step that would change the state by about ``dt_change_target``,
        dt_next = dt 2c / (Δ + c) with Δ the step's largest nodal change of S or d, at most ``dt_grow`` dt.  It
        reads the accepted states only, so the step sequence does not depend on the Newton iteration counts
        (``anderson_depth`` leaves a run without rejected steps unchanged to the Newton tolerance) and is a
        continuous function of the parameters.  "iterations": grow dt by ``dt_grow`` after an easy step (at most
        ``easy_newton_its`` Newton iterations per stagger iteration), else keep it; the controller of the runs
        made before "state_change" existed (with ``anderson_depth = 0`` and ``newton_mass_tol = 0.01``, their
        step sequence).
    dt_change_target : target change c per step of the saturation S and the damage d with
        ``step_control = "state_change"`` (dimensionless, in (0, 1]).  The time-discretization error of backward
        Euler is O(c) (``tests/test_step_control.py``); why 0.1: ``results/archive/bench_rounds.md``, third round.
    dt_grow : largest growth factor of dt from one step to the next (with "iterations", the factor after an
        easy step).
    dt_cut : factor on dt after a rejected step.
    easy_newton_its : Newton iterations per stagger iteration up to which a step counts as easy
        (``step_control = "iterations"``).
    stop_front_radius : stop when the S = 0.5 front connected to the inlet reaches this radius, mm (None: never);
        inside (r_inner, r_outer] (checked with the parameters by :func:`check_run_inputs`).
    snapshot_times : distinct times in [0, t_end] at which fields are written, s (the initial state t = 0 and
        the last state are always written); the default (0.5, 1, 1.5, 2) s is accepted with any t_end, its
        times after t_end skipped.
    frames : also write N evenly spaced snapshots, at k t_end / N for k = 1..N (for animations; None: none).
        Omitted from :meth:`to_dict` when None, as h_inner.
    newton_rtol : relative Newton tolerance on every field's update (dimensionless; 1e-6: with a reused
        Jacobian the error left is below this, far below the time-discretization error; 1e-7 cost 12 % more
        iterations for changes of p_inj below 1e-5 relative).
    newton_mass_tol : Newton's second test (dimensionless): the global balances of the total and of the invading
        fluid over the step hold to this fraction of the injection rate (``Simulation.balanced``), so the
        cumulative volume balance (``mass_error`` of ``timeseries.csv``) holds to about this tolerance.
    newton_max_its : Newton iterations before a step is rejected.
    stagger_tol : stagger converged when max |Δd| between two stagger iterations is below this.
    stagger_max_its : stagger iterations before a step is rejected.
    damage_max_its : active-set Newton iterations of the damage problem.
    linear_solver : "auto" (pypardiso when installed, else SuperLU), "superlu" or "pypardiso".
    linear_precision : precision of the factorized Jacobian: "double", or "single" (factors in float32, the
        residual, the iterate and the Newton tests in double: an inexact Newton iteration whose linear solves are
        checked to a relative residual of ``solver.linsolve.SINGLE_FORCING`` = 1e-3, refined in mixed precision
        or refactorized in double when they miss it; ``solver.linsolve``).  The converged state meets the same
        tests as with double factors.  None (default): "single" with PARDISO, whose single-precision
        factorization and substitution are the faster (results/archive/bench_rounds.md, sixth round), and "double" with
        SuperLU.  Omitted from :meth:`to_dict` when None, as h_inner.
    jacobian_reuse : keep a factorized Jacobian (over Newton iterations, stagger iterations and
        time steps of equal dt) while the Newton updates contract by at least this factor per
        iteration; 0 disables reuse (exact Newton: every iteration factorizes).
    max_wall_time : give up (status "failed") after this many seconds of wall time, s, counted over every piece of
        a resumed run (None: no limit).
    write_xdmf : also write the snapshots as XDMF for ParaView.
    transport : discretization of the convective transport of S: "galerkin" (the plain P1 Galerkin
        form, the paper's Sec. 3.1) or "upwind" (phase mobilities at the saturation shifted upstream by
        half the element size, ``solver.forms.upwind_saturation``: first-order streamline upwinding) or
        "supg" (the Galerkin form plus the streamline-upwind/Petrov–Galerkin term of Brooks and Hughes
        (1982), ``solver.forms.supg_flux``: it adds diffusion only along the flow and only where the strong
        residual of the saturation equation is not zero; that residual leaves out the ∇k, ∇φ parts of ∇·w_1, so
        the term is consistent to O(h)).
    pressure_stabilization : factor s >= 0 on the pressure stabilization of the equal-order P1 / P1 pair
        (``solver.discretization.pressure_stabilization_tau``): the total mass balance gains
        τ_e ∫ ∇q·∇(p − p_n)/Δt with τ_e = s b (1 − φ0) h_e² / (4 (λ + 2μ)) (mm²/kPa), the term of
        Aguilar et al. (2008) and Rodrigo et al. (2016) that removes the spurious pressure oscillations of the
        undrained limit (low permeability k, small Δt: k Δt / η ≪ h² / (λ + 2μ), where the pores close at the
        compacted outer wall, k = 0, or at start-up for small k̄).  Consistent: O(h²) times ∂p/∂t.  s = 1 is the
        published value; None (default) or 0: the plain Galerkin form of the paper (Sec. 3.1).  Omitted from
        :meth:`to_dict` when None, as h_inner.
    xdmf_format : "hdf5" (arrays in fields.h5 beside fields.xdmf; needs h5py), "xml" (inline) or None / "auto"
        (hdf5 when h5py is installed). Omitted from :meth:`to_dict` when None, as h_inner.
    anderson_depth : Anderson acceleration of the Newton iterations made with a reused Jacobian (``solver.anderson``):
        the next iterate combines the last ``anderson_depth`` + 1 plain updates (1..20); 0 (or None): the plain
        iteration.  The Newton test and tolerance are unchanged, so with ``step_control = "state_change"`` a run
        without rejected steps is the plain one to the Newton tolerance, in fewer factorizations; a step that
        diverges in one iteration and not in the other is rejected in one run only, and the runs then differ by
        the time-discretization error.  With "iterations", fewer Newton iterations make the controller choose
        other steps.  Default 3 (cost and effect: ``results/archive/bench_rounds.md``).
    first_stagger_rtol : Newton tolerance of the first stagger iteration of each step (dimensionless, in
        [``newton_rtol``, 0.1]): that iteration only supplies the damage that starts the second, which is always
        made and solved to ``newton_rtol``, so the accepted state meets the same tests (``Simulation.step``).
        It saves Newton iterations, but the accepted state then moves within the stagger tolerance (up to 1e-3 of
        p_inj in the first steps) with the number of loose iterations, a discrete function of the parameters:
        the run's outputs are rougher in the parameters, which finite differences (the discrepancy workflow)
        amplify.  So it is off by default (None: every stagger iteration at ``newton_rtol``, the first allowed
        to end the stagger); for runs that are not differentiated, 1e-3 (``results/archive/bench_rounds.md``).  Used when
        ``stagger_max_its`` >= 2.  Omitted from :meth:`to_dict` when None, as h_inner.
    newton_krylov : Newton–Krylov iterations (1..100: the most GMRES iterations per Newton iteration): every
        Newton iteration assembles the exact Jacobian and solves for its update by GMRES to the forcing
        ``solver.linsolve.SINGLE_FORCING`` (1e-3), preconditioned by the kept factorization (``solver.krylov``);
        the Jacobian is factorized again only when GMRES does not reach the forcing in that many iterations.  The
        iteration is then inexact Newton with the exact Jacobian (Dembo, Eisenstat and Steihaug 1982), not the
        chord iteration of ``jacobian_reuse`` (nor Anderson's acceleration of it); the Newton test is the same.
        None (default): the chord iteration.  Omitted from :meth:`to_dict` when None, as h_inner.
    checkpoint_interval : wall time between two checkpoints of a run with a run folder, s (default 600): at the end
        of an accepted step, when at least this long has passed since the last one, the whole state of the time
        loop is written to ``checkpoint.npz`` (``solver.checkpoint``), from which a run killed part-way resumes;
        None or 0: no checkpoints.  It does not change the run's result, so it is no part of a run key or cache
        hash (``keyed``) and is omitted from :meth:`to_dict` at its default.
    """

    h: float = 1.0
    h_inner: float | None = None
    inner_grading_length: float | None = None
    h_outer: float | None = None
    mesh_seed: int | None = None
    t_end: float = 2.0
    dt0: float = 1e-3
    dt_min: float = 1e-7
    dt_max: float = 0.02
    dt_grow: float = 1.5
    dt_cut: float = 0.25
    easy_newton_its: int = 4
    step_control: str = "state_change"
    dt_change_target: float = 0.1
    stop_front_radius: float | None = None
    snapshot_times: tuple = DEFAULT_SNAPSHOT_TIMES
    newton_rtol: float = 1e-6
    newton_mass_tol: float = 1e-10
    newton_max_its: int = 25
    stagger_tol: float = 1e-4
    stagger_max_its: int = 30
    damage_max_its: int = 50
    linear_solver: str = "auto"
    linear_precision: str | None = None
    jacobian_reuse: float = 0.3
    max_wall_time: float | None = None
    write_xdmf: bool = True
    transport: str = "galerkin"
    frames: int | None = None
    xdmf_format: str | None = None
    pressure_stabilization: float | None = None
    anderson_depth: int = 3
    first_stagger_rtol: float | None = None
    newton_krylov: int | None = None
    checkpoint_interval: float | None = RESULT_NEUTRAL["checkpoint_interval"]

    def __post_init__(self):
        _check(self)

    # -- serialization ------------------------------------------------------
    def to_dict(self) -> dict:
        d = asdict(self)
        d["snapshot_times"] = list(self.snapshot_times)
        for name in _OMIT_WHEN_NONE:
            if d[name] is None:
                del d[name]
        for name, default in RESULT_NEUTRAL.items():
            if d[name] == default:
                del d[name]
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "RunOptions":
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - names)
        if unknown:
            raise ValueError(f"unknown run option(s) {unknown}{did_you_mean(unknown, names)}; allowed: {sorted(names)}")
        return cls(**d)

    def frame_times(self) -> list[float]:
        """Times after t = 0 at which snapshots are written, s: snapshot_times within (0, t_end] and the
        ``frames`` evenly spaced times, sorted, without repeats (t = 0 and the last state come besides)."""
        ts = {t for t in self.snapshot_times if 0 < t <= self.t_end + 1e-12}
        if self.frames:
            ts |= {self.t_end * k / self.frames for k in range(1, self.frames + 1)}
        out: list[float] = []
        for t in sorted(ts):
            if not out or t - out[-1] > 1e-9:
                out.append(t)
        return out

    def replace(self, **changes) -> "RunOptions":
        return replace(self, **changes)

    def to_toml(self, path) -> None:
        write_flat_toml(path, self.to_dict(), "dchfrac run options (units mm, s)")

    @classmethod
    def from_toml(cls, path) -> "RunOptions":
        return cls.from_dict(read_toml(path))

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), sort_keys=True)


def keyed(options: dict) -> dict:
    """The options dict ``options`` (a :meth:`RunOptions.to_dict`) without the options that do not change an
    uninterrupted run's result (``RESULT_NEUTRAL``): what a run key or cache hash names."""
    return {k: v for k, v in options.items() if k not in RESULT_NEUTRAL}


def _fail(name, value, allowed):
    raise ValueError(f"run option {name}={value!r} is out of range: allowed {allowed}")


# (name, kind, lower, upper, lower bound open, None allowed, plausible range): every numeric option's range,
# checked in one loop, and where a unit slip is likely the plausible (lo, hi) beside it (solver.plausible;
# outside it a run warns, ``--strict`` refuses).  kind float accepts any real number (numpy scalars included,
# stored as a Python float), int any integer.
_NUMBERS = (
    ("h", float, 0.0, 24.0, True, False, (0.05, 24.0)),
    ("h_inner", float, None, None, True, True, (0.01, 10.0)),   # in (0, h]: checked after the loop
    ("inner_grading_length", float, 0.0, None, True, True, (0.01, 1e3)),
    ("h_outer", float, None, None, True, True, (0.01, 10.0)),   # in (0, h]: checked after the loop
    ("frames", int, 1, None, False, True, None),
    ("mesh_seed", int, 0, 2**63 - 1, False, True, None),
    ("t_end", float, 0.0, None, True, False, (1e-3, 20.0)),
    ("dt0", float, 0.0, None, True, False, (1e-9, 1.0)),
    ("dt_min", float, 0.0, None, True, False, (1e-12, 0.1)),
    ("dt_max", float, 0.0, None, True, False, (1e-6, 5.0)),
    ("dt_grow", float, 1.0, None, False, False, None),
    ("dt_cut", float, 0.0, 1.0, True, False, None),
    ("easy_newton_its", int, 1, None, False, False, None),
    ("dt_change_target", float, 0.0, 1.0, True, False, None),
    ("stop_front_radius", float, 0.0, None, True, True, (0.1, 1e4)),
    ("newton_rtol", float, 0.0, 1e-2, True, False, None),
    ("newton_mass_tol", float, 0.0, 1e-2, True, False, None),
    ("newton_max_its", int, 1, None, False, False, None),
    ("stagger_tol", float, 0.0, 1.0, True, False, None),
    ("stagger_max_its", int, 1, None, False, False, None),
    ("damage_max_its", int, 1, None, False, False, None),
    ("jacobian_reuse", float, 0.0, 1.0, False, False, None),
    ("max_wall_time", float, 0.0, None, True, True, (1.0, 1e7)),
    ("pressure_stabilization", float, 0.0, 100.0, False, True, None),
    ("anderson_depth", int, 0, 20, False, True, None),     # None: 0 (the plain iteration), set after the loop
    ("first_stagger_rtol", float, 0.0, 0.1, True, True, None),
    ("newton_krylov", int, 1, 100, False, True, None),
    ("checkpoint_interval", float, 0.0, None, False, True, None),
)


# unit of every run option ("-": dimensionless; "" for counts, switches and labels): the one declaration the
# campaign column dictionary reads; the meanings are the RunOptions docstring's
OPTION_UNITS = {
    "h": "mm", "h_inner": "mm", "inner_grading_length": "mm", "h_outer": "mm", "mesh_seed": "", "t_end": "s", "dt0": "s", "dt_min": "s", "dt_max": "s",
    "dt_grow": "-", "dt_cut": "-", "easy_newton_its": "", "step_control": "", "dt_change_target": "-", "stop_front_radius": "mm", "snapshot_times": "s",
    "newton_rtol": "-", "newton_mass_tol": "-", "newton_max_its": "", "stagger_tol": "-", "stagger_max_its": "", "damage_max_its": "",
    "linear_solver": "", "linear_precision": "", "jacobian_reuse": "-", "max_wall_time": "s", "write_xdmf": "", "frames": "",
    "xdmf_format": "", "transport": "", "pressure_stabilization": "-", "anderson_depth": "",
    "first_stagger_rtol": "-", "newton_krylov": "", "checkpoint_interval": "s",
}


def option_docs() -> dict[str, str]:
    """Meaning of each run option, parsed from the Attributes section of the RunOptions docstring."""
    import re

    out: dict[str, str] = {}
    text = (RunOptions.__doc__ or "").split("----------", 1)[-1]
    for m in re.finditer(r"^    ([a-z_0-9, ]+) : (.+?)(?=^    [a-z_0-9, ]+ : |\Z)", text, re.M | re.S):
        for name in m.group(1).split(","):
            out[name.strip()] = " ".join(m.group(2).split())
    return out


def _number(name, v, kind, lo, hi, lo_open, optional):
    """The validated value of one numeric option (numpy scalars become Python numbers)."""
    if v is None and optional:
        return None
    if isinstance(v, np.generic):  # a numpy scalar: its Python value, so serialization is exact
        v = v.item()
    if isinstance(v, bool) or not isinstance(v, Integral if kind is int else Real):
        _fail(name, v, "an integer" if kind is int else "a number")
    try:
        if type(v) not in (int, float):  # another Real (e.g. a Fraction): a plain number
            v = int(v) if kind is int else float(v)
        finite = math.isfinite(v)
    except OverflowError:
        finite = False
    if not finite:
        _fail(name, f"{str(v)[:12]}... ({len(str(v))} digits)" if isinstance(v, int) else v, "a finite number")
    if lo is not None and (v <= lo if lo_open else v < lo):
        _fail(name, v, f"{'>' if lo_open else '>='} {lo}")
    if hi is not None and v > hi:
        _fail(name, v, f"<= {hi}")
    return v


def _snapshot_times(v, t_end):
    """snapshot_times as a tuple of distinct floats in [0, t_end]; the default times beyond t_end are skipped."""
    allowed = f"a list of distinct times in [0, t_end = {t_end}] s"
    if isinstance(v, (str, bytes)) or not isinstance(v, (list, tuple, np.ndarray)):
        _fail("snapshot_times", v, allowed)
    for t in v:
        if isinstance(t, (bool, np.bool_)) or not isinstance(t, Real) or not math.isfinite(t) or t < 0:
            _fail("snapshot_times", v, f"{allowed}; {t!r} is not")
    times = tuple(float(t) for t in v)
    if times == DEFAULT_SNAPSHOT_TIMES:  # the default, whatever t_end: times past t_end are not written
        return times
    late = [t for t in times if t > t_end * (1 + 1e-12)]
    if late:
        _fail("snapshot_times", list(times), f"{allowed}; {late[0]!r} s is after t_end")
    if len(set(times)) != len(times):
        _fail("snapshot_times", list(times), f"{allowed}; a time is repeated")
    return times


def _check(o: RunOptions) -> None:
    for name, kind, lo, hi, lo_open, optional, _ in _NUMBERS:
        object.__setattr__(o, name, _number(name, getattr(o, name), kind, lo, hi, lo_open, optional))
    for name in ("h_inner", "h_outer"):
        if getattr(o, name) is not None and not 0.0 < getattr(o, name) <= o.h:
            _fail(name, getattr(o, name), f"(0, h = {o.h}]")
    if o.inner_grading_length is not None and o.h_inner is None:
        _fail("inner_grading_length", o.inner_grading_length, "None unless h_inner is given (it grades the inner side)")
    if o.anderson_depth is None:
        object.__setattr__(o, "anderson_depth", 0)
    if o.first_stagger_rtol is not None and o.first_stagger_rtol < o.newton_rtol:
        _fail("first_stagger_rtol", o.first_stagger_rtol, f"None or in [newton_rtol={o.newton_rtol}, 0.1]")
    if not (o.dt_min <= o.dt0 <= o.dt_max):
        _fail("dt0", o.dt0, f"[dt_min={o.dt_min}, dt_max={o.dt_max}]")
    for name, allowed in (("linear_solver", _LINEAR_SOLVERS), ("linear_precision", (None, *PRECISIONS)),
                          ("transport", TRANSPORTS), ("step_control", STEP_CONTROLS),
                          ("xdmf_format", (None, "auto", "hdf5", "xml"))):
        if getattr(o, name) not in allowed:
            _fail(name, getattr(o, name), f"one of {allowed}")
    if not isinstance(o.write_xdmf, (bool, np.bool_)):
        _fail("write_xdmf", o.write_xdmf, "true or false (a boolean, not a string)")
    object.__setattr__(o, "write_xdmf", bool(o.write_xdmf))
    object.__setattr__(o, "snapshot_times", _snapshot_times(o.snapshot_times, o.t_end))


def check_run_inputs(params, options: RunOptions) -> list[str]:
    """Check that ``options`` can run the model ``params`` (a ``solver.Parameters``) on the annulus mesh.

    Raises ValueError naming the option, its value and the allowed range when the mesh size h (mm) does
    not fit the annulus (h < (r_outer - r_inner)/2, as ``solver.mesh.annulus_mesh`` requires) or when
    ``stop_front_radius`` (mm) is not inside (r_inner, r_outer].  Returns warnings (text) for inputs that
    run but are implausible (outside a declared plausible range: a likely unit slip, :func:`plausibility_warnings`)
    or cannot give a resolved answer (:func:`resolution_warnings`).
    """
    ri, ro = params.r_inner, params.r_outer
    if not options.h < (ro - ri) / 2:
        _fail("h", options.h, f"< (r_outer - r_inner)/2 = {(ro - ri) / 2:g} mm (annulus r_inner = {ri:g}, "
                              f"r_outer = {ro:g} mm)")
    r = options.stop_front_radius
    if r is not None and not ri < r <= ro:
        _fail("stop_front_radius", r, f"None or a radius in (r_inner = {ri:g}, r_outer = {ro:g}] mm")
    from .params import plausibility_warnings as parameter_warnings

    return parameter_warnings(params) + plausibility_warnings(options) + resolution_warnings(params, options)


def plausibility_warnings(options: RunOptions) -> list[str]:
    """One warning per run option set outside its declared plausible range (``_NUMBERS``), naming the likely
    unit slip (``t_end = 2000 s: did you mean ms?``)."""
    return [slip_message("run option", name, getattr(options, name), OPTION_UNITS[name], rng,
                         RunOptions.__dataclass_fields__[name].default)
            for name, *_, rng in _NUMBERS if implausible(getattr(options, name), rng)]


def resolution_warnings(params, options: RunOptions) -> list[str]:
    """Warnings for lengths (mm) the mesh of size h cannot resolve or the annulus cannot hold: the diffuse
    saturation interface l_S and damage band l_d below 2 h (each spans about 2 l: fewer than 2 elements across
    it), either above the annulus width r_outer - r_inner, and an inner radius below the mesh size on the
    inner circle (the cavity then has fewer than 2π edges)."""
    h, width = options.h, params.r_outer - params.r_inner
    h_in = options.h_inner if options.h_inner is not None else h
    what = {"l_S": "the diffuse saturation interface", "l_d": "the diffuse damage band"}
    out = []
    for name in ("l_S", "l_d"):
        v = getattr(params, name)
        if v < 2 * h:
            out.append(f"parameter {name} = {v:g} mm is below 2 h = {2 * h:g} mm: the mesh does not resolve "
                       f"{what[name]} (results depend on h)")
        if v > width:
            out.append(f"parameter {name} = {v:g} mm exceeds the annulus width r_outer - r_inner = {width:g} mm: "
                       f"{what[name]} fills the domain (a unit slip?)")
    if params.r_inner < h_in:
        out.append(f"parameter r_inner = {params.r_inner:g} mm is below the mesh size on the inner circle "
                   f"{h_in:g} mm: the cavity is not resolved (fewer than 2π edges on its circumference)")
    return out


def check_environment() -> list[str]:
    """Check the environment variables a run reads, before anything is written: ``DCHFRAC_KERNELS`` (a known
    backend, numba installed when asked for) and ``DCHFRAC_ASSEMBLY_THREADS`` (a positive integer) raise
    ValueError naming the variable, its value and what is allowed.  Returns warnings: a kernel cache
    (``DCHFRAC_CACHE``) that cannot be written, so that every run compiles its kernels again (about 20 s)."""
    from . import kernels
    from .jitcache import cache_dir
    from .output import check_writable_dir
    from .paths import assembly_threads, check_environment as check_path_variables

    check_path_variables()  # DCHFRAC_KERNELS, DCHFRAC_LINEAR_SOLVER
    assembly_threads()
    if kernels.backend() != "numba":
        return []
    try:
        check_writable_dir(cache_dir(), "kernel cache DCHFRAC_CACHE")
    except ValueError as exc:
        return [f"{exc}: every run compiles its kernels again (about 20 s each); set DCHFRAC_CACHE to a writable "
                "folder"]
    return []
