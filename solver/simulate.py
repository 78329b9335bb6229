"""Time loop of the coupled model: set-up, adaptive steps, outputs.

Each time step is solved by :class:`solver.stagger.Simulation` (staggered Newton / active-set damage, Sec. 3.1 of
the paper); what an accepted step records (time-series row, snapshots) is :mod:`solver.records`.
After an accepted step the next dt follows the step's change of S and d
(``_next_dt``).  A step whose Newton or stagger iterations fail is retried with a
smaller dt (every rejection logged); past ``dt_min`` the run ends with status
"failed", keeping everything written so far.
"""
from __future__ import annotations

import time
import traceback
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from . import linsolve, paths, profiling
from .model import element_fields, porosity_state, storage_fraction
from .options import RunOptions, check_environment, check_run_inputs
from .output import RunWriter
from .profiling import phase
from .records import accumulate_balances, step_row, stored_volume, take_snapshot, water_fraction
from .stagger import Simulation, StepFailure

__all__ = ["simulate", "SimulationResult", "Simulation", "StepFailure", "run_path", "physical_limit", "warmup"]


@dataclass
class SimulationResult:
    """Outcome of :func:`simulate`: status "ok" or "failed" (then ``reason``), time series, snapshots."""

    status: str
    reason: str | None
    timeseries: pd.DataFrame
    snapshots: list
    wall_time: float
    out_dir: str | None = None
    rejected_steps: list = field(default_factory=list)
    factorizations: int = 0
    profile: dict | None = None  # wall seconds by phase and part of the run (solver.profiling.Profile.to_dict)
    path: dict | None = None  # the linear solver, its precision and the kernels that ran (run_path)


def _validate_mesh(mesh):
    for tag in ("inner", "outer"):
        if tag not in mesh.boundary_edges:
            raise ValueError(f"mesh has no boundary tag {tag!r}: the model needs 'inner' (injection) and 'outer' edges")


def simulate(params, options: RunOptions | None = None, out_dir=None, mesh=None, phi0=None, progress: bool = False,
             check_memory: bool = True) -> SimulationResult:
    """Run the coupled model from t = 0 to ``options.t_end`` (s).

    Parameters
    ----------
    params : solver.Parameters (mm, s, kPa), validated at construction.
    options : solver.RunOptions (mesh size h in mm, times in s, tolerances).
    out_dir : run folder (parameters TOML, time series CSV, snapshots NPZ + XDMF,
        summary.json), written atomically; None keeps everything in memory.
    mesh : optional mesh with ``points`` (mm), ``triangles`` and ``boundary_edges``
        tags "inner" and "outer" (default: the paper's annulus at size ``options.h``).
    phi0 : optional initial porosity per element (default: ``params.porosity_field``).
    progress : report progress (``solver.progress.StepProgress``: a bar with % of t_end and ETA on a
        terminal, periodic INFO lines of the logger ``dchfrac.solver`` otherwise); or a StepProgress.

    Inputs that cannot run on the annulus (``solver.options.check_run_inputs``: h too large for it,
    stop_front_radius outside it) raise ValueError before the run folder is written, and so does a mesh whose
    estimated memory exceeds what is available (``solver.budget.check_fits``) unless ``check_memory`` is False.
    """
    from .params import Parameters

    options = options or RunOptions()
    if not isinstance(params, Parameters):
        raise ValueError(f"params must be a solver.Parameters, got {type(params).__name__}")
    if not isinstance(options, RunOptions):
        raise ValueError(f"options must be a solver.RunOptions, got {type(options).__name__}")
    # before the run folder is written
    warnings = (check_run_inputs(params, options) if mesh is None else []) + check_environment()
    if mesh is None and check_memory:
        from .budget import check_fits

        check_fits(params, options)
    t_wall = time.perf_counter()
    if progress is True:
        from .progress import StepProgress

        progress = StepProgress(options.t_end)
    prof = profiling.Profile()
    path = {}
    with profiling.activate(prof), one_openblas_thread():
        status, reason, rows, snaps, rejected, nfact = _run(params, options, out_dir, mesh, phi0, progress, t_wall,
                                                            warnings, path)
    ts = pd.DataFrame(rows)
    wall = time.perf_counter() - t_wall
    return SimulationResult(status, reason, ts, snaps, wall, str(out_dir) if out_dir is not None else None, rejected, nfact,
                            profile=prof.to_dict(), path=path)


def run_path(sim: "Simulation | None", options: RunOptions) -> dict:
    """The computational path of a run (recorded in ``summary.json``): the sparse solver that factorizes its
    Jacobian, the factors' precision and the element kernels (:mod:`solver.paths`); without ``sim`` (the set-up
    failed) the path a run-sized problem would take."""
    from . import kernels

    if sim is not None:
        return {"linear_solver": sim.solver_kind, "linear_precision": sim.precision, "kernels": kernels.backend()}
    try:
        kind = paths.resolve(options.linear_solver, 10**6)
        return {"linear_solver": kind, "linear_precision": paths.resolve_precision(options.linear_precision, kind),
                "kernels": kernels.backend()}
    except ValueError as exc:
        return {"error": str(exc)}


def one_openblas_thread():
    """A context that holds numpy's and scipy's OpenBLAS thread pools to one thread (threadpoolctl; a no-op
    when it is not installed).  The run's own BLAS calls are small (norms of the Newton vectors, Anderson's
    least squares over a few columns), and idle OpenBLAS workers spinning beside PARDISO's OpenMP threads and
    the assembly threads take their cores (results/archive/bench_rounds.md, ninth round).  MKL (PARDISO) keeps its
    threads."""
    try:
        from threadpoolctl import ThreadpoolController
    except ImportError:
        from contextlib import nullcontext

        return nullcontext()
    return ThreadpoolController().select(internal_api="openblas").limit(limits=1)


def _run(params, options, out_dir, mesh, phi0, progress, t_wall, warnings=(), path=None):
    """Set up, run the time loop and write the run folder; returns (status, reason, rows, snapshots,
    rejected steps, factorizations); fills ``path`` with the run's :func:`run_path`."""
    rows, snaps, rejected = [], [], []
    sim = None
    status, reason = "ok", None
    fact0 = linsolve.STATS["factorizations"]
    with phase("output"):
        writer = RunWriter(out_dir) if out_dir is not None else None
        if writer:
            writer.start(params, options)
            for w in warnings:
                writer.log(f"WARNING: {w}")
    try:
        with phase("setup"):
            sim = _setup(params, options, mesh, phi0)
        if writer:
            with phase("output"):
                writer.write_mesh(sim.disc.points, sim.disc.triangles)
        status, reason = _time_loop(sim, options, rows, snaps, rejected, writer, progress, t_wall)
    except Exception as exc:  # never a traceback as the only trace
        status, reason = "failed", f"{type(exc).__name__}: {exc}"
        if writer:
            writer.log(traceback.format_exc())
    nfact = linsolve.STATS["factorizations"] - fact0
    if path is not None:
        path.update(run_path(sim, options))
    if writer:
        with phase("output"):
            writer.finish(pd.DataFrame(rows), status, reason, time.perf_counter() - t_wall, rows[-1]["t"] if rows else 0.0,
                          rejected, nfact, xdmf=options.write_xdmf, path=run_path(sim, options))
    if progress:
        progress.close()
    return status, reason, rows, snaps, rejected, nfact


def _setup(params, options, mesh, phi0) -> Simulation:
    """The mesh (default: the paper's annulus at ``options.h``, graded by ``h_inner`` over
    ``inner_grading_length`` and by ``h_outer``), initial porosity and discretized model."""
    if mesh is None:
        from .mesh import GRADING_LENGTH, annulus_mesh

        mesh = annulus_mesh(params.r_inner, params.r_outer, options.h, options.mesh_seed, h_inner=options.h_inner,
                            grading_length=options.inner_grading_length or GRADING_LENGTH, h_outer=options.h_outer)
    _validate_mesh(mesh)
    if phi0 is None:
        from .porosity import initial_porosity

        phi0 = initial_porosity(mesh, params)
    return Simulation(params, options, mesh, phi0)


def _time_loop(sim: Simulation, o: RunOptions, rows, snaps, rejected, writer, progress, t_wall):
    pending = o.frame_times()
    dt = o.dt0
    cum = {"inj": 0.0, "src": 0.0, "out": 0.0, "w_in": 0.0, "w_out": 0.0, "w_src": 0.0, "line": 0.0}
    store0 = storage_fraction(sim.disc, sim.params, sim.U, porosity_state(sim.disc, sim.params, sim.U)[2])
    V0 = stored_volume(sim, store0)
    cum["W0"] = stored_volume(sim, water_fraction(sim, sim.U, store0))
    warned_layer = False
    prof = profiling.active()
    with phase("output"):
        take_snapshot(sim, snaps, writer)  # the initial state, t = 0
    while sim.t < o.t_end - 1e-12:
        if o.max_wall_time is not None and time.perf_counter() - t_wall > o.max_wall_time:
            return "failed", f"max_wall_time {o.max_wall_time} s exceeded at t = {sim.t:.4g} s"
        prof.set_part(sim.t)
        target = min(o.t_end, pending[0]) if pending else o.t_end
        dt_try = min(dt, o.dt_max, target - sim.t)
        try:
            U, d, info = sim.step(dt_try)
        except (StepFailure, np.linalg.LinAlgError, RuntimeError, FloatingPointError, ValueError) as exc:
            prof.count("rejected_steps")
            rejected.append({"t": sim.t, "dt": dt_try, "reason": str(exc)})
            if writer:
                writer.log(f"rejected step at t={sim.t:.6g} dt={dt_try:.3g}: {exc}")
            dt = dt_try * o.dt_cut
            if dt < o.dt_min:
                limit = physical_limit(sim, getattr(exc, "node", None))
                return "failed", (f"time step below dt_min={o.dt_min} at t = {sim.t:.6g} s (last: {exc})"
                                  + (f"; physical limit: {limit}" if limit else ""))
            continue
        with phase("metrics"):
            _, ev, phi_q = porosity_state(sim.disc, sim.params, U)  # the new state's porosity, read twice below
            accumulate_balances(sim, U, info["data"], dt_try, cum, ev, phi_q)
            sim.commit(U, d, dt_try)
            store = storage_fraction(sim.disc, sim.params, U, phi_q)
            row = step_row(sim, dt_try, info, cum, V0, stored_volume(sim, store),
                       stored_volume(sim, water_fraction(sim, U, store)))
        rows.append(row)
        _count_step(prof, info)
        if row["outer_layer_area"] > 0 and not warned_layer:
            warned_layer = True
            if writer:
                writer.log(f"WARNING: invaded layer not connected to the inlet at the outer circle (area {row['outer_layer_area']:.3g} mm^2) at t={sim.t:.4g} s; see mu_outer_bc")
        if progress:
            progress.update(sim.t, f"dt = {dt_try:.2e} s, newton {info['newton_its']}, stagger {info['stagger_its']}, "
                                   f"p_inj = {row['p_inj']:.1f} kPa, front = {row['front_radius_mean']:.1f} mm")
        with phase("output"):
            if pending and abs(sim.t - pending[0]) < 1e-9:
                pending.pop(0)
                take_snapshot(sim, snaps, writer)
            if writer and len(rows) % 25 == 0:
                writer.write_timeseries(pd.DataFrame(rows))
        if o.stop_front_radius is not None and np.isfinite(row["front_radius_max"]) and row["front_radius_max"] >= o.stop_front_radius:
            break
        dt = _next_dt(o, dt_try, info)
    if not snaps or snaps[-1][0] != sim.t:
        with phase("output"):
            take_snapshot(sim, snaps, writer)
    return "ok", None


def physical_limit(sim: Simulation, node: int | None) -> str | None:
    """The physical limit of the model reached at ``node`` in the last accepted state, or None.

    The linear porosity law φ = φ0 + (1 − φ0)(ε_v + p/K_s) (Eq. summary_equations_3) has no bound: under
    compaction it reaches φ <= 0, where the pores are closed (k = 0, no flux across the element) and the
    element's share of the invading-fluid capacity ∫ φ N_a dx is gone or negative, so S at a node next to it
    is no longer determined by the balance.  Under dilation it reaches φ >= 1, a skeleton with no solid.  A
    step that fails at a node touching such an element fails because the model left its range, not because
    of the numerics.
    """
    if node is None:
        return None
    disc = sim.disc
    phi = element_fields(disc, sim.params, sim.U, sim.d, fluxes=False)["phi"]
    around = np.any(disc.triangles == node, axis=1)
    if not around.any():
        return None
    ph = phi[around]
    mean_phi = float(np.average(ph, weights=disc.geom.areas[around]))
    r = float(np.hypot(*disc.points[node]))
    n = f"{{}} of the {ph.size} elements around the failing node, mean porosity {mean_phi:.3g}"
    if ph.min() <= 0.0:
        return (f"pores closed at r = {r:.2f} mm (porosity <= 0 in {n.format(int((ph <= 0).sum()))}: the linear "
                "porosity law leaves [0, 1] under compaction, k = 0 and S loses its capacity there)")
    if ph.max() >= 1.0:
        return (f"skeleton dissolved at r = {r:.2f} mm (porosity >= 1 in {n.format(int((ph >= 1).sum()))}: the "
                "linear porosity law leaves [0, 1] under dilation)")
    return None


def _next_dt(o: RunOptions, dt: float, info: dict) -> float:
    """The next step after an accepted step of size dt (s), by the controller ``o.step_control``.

    "state_change": the time-step selector of reservoir simulators that targets a change of the primary
    variables per step (MRST's ``StateChangeTimeStepSelector``; Lie 2019, An Introduction to Reservoir
    Simulation Using MATLAB/GNU Octave, Sec. 10.4). With Δ the step's largest nodal change of S or d
    (``Simulation.state_change``) and c = ``dt_change_target``, dt_next = dt (1 + ω) c / (Δ + ω c) with ω = 1,
    at most ``dt_grow`` dt: the step that would change the state by about c, damped so that one step's Δ
    does not set the next alone.  It reads the accepted state, never the iteration counts.

    "iterations": dt grows by ``dt_grow`` after an easy step, one with few Newton iterations per stagger
    iteration (a reused Jacobian converges linearly, so three times more are allowed) and few stagger
    iterations.
    """
    if o.step_control == "state_change":
        c = o.dt_change_target
        return dt * min(o.dt_grow, 2.0 * c / (info["step_change"] + c))
    easy = o.easy_newton_its * (3 if o.jacobian_reuse > 0 else 1)
    if info["newton_its"] <= easy * info["stagger_its"] and info["stagger_its"] <= 3:
        return dt * o.dt_grow
    return dt


def _count_step(prof, info: dict) -> None:
    """Count an accepted step and its iterations in the profile's part of the run."""
    prof.count("accepted_steps")
    prof.count("newton_iterations", info["newton_its"])
    prof.count("stagger_iterations", info["stagger_its"])


def warmup() -> dict:
    """Compile (or load) the kernels of the default model structure ahead of the first run: a one-step run on a
    coarse mesh (h = 8 mm), nothing written.  Returns {"compiled": whether they had to be compiled, "wall_s": wall
    time in s, "path": the run's path (solver.simulate.run_path)}."""
    from .params import Parameters
    from .jitcache import _ANNOUNCED

    t0, n0 = time.perf_counter(), _ANNOUNCED[0]
    res = simulate(Parameters(), RunOptions(h=8.0, t_end=1e-3, dt0=1e-3, snapshot_times=[], write_xdmf=False))
    if res.status != "ok":
        raise RuntimeError(f"warm-up run failed: {res.reason}")
    return {"compiled": _ANNOUNCED[0] > n0, "wall_s": time.perf_counter() - t0, "path": res.path}
