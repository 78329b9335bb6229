"""Time loop of the coupled model: set-up, adaptive steps, outputs.

Each time step is solved by :class:`solver.stagger.Simulation` (staggered Newton / active-set damage, Sec. 3.1 of
the paper); what an accepted step records (time-series row, snapshots) is :mod:`solver.records`.
After an accepted step the next dt follows the step's change of S and d
(``_next_dt``).  A step whose Newton or stagger iterations fail is retried with a
smaller dt (every rejection logged); past ``dt_min`` the run ends with status
"failed", keeping everything written so far.  A run with a run folder writes checkpoints
(:mod:`solver.checkpoint`), from which a run killed part-way resumes.
"""
from __future__ import annotations

import time
import traceback
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from . import checkpoint, linsolve, paths, profiling
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
    resumed_from_t: list = field(default_factory=list)  # times (s) the run resumed from checkpoints


def _validate_mesh(mesh):
    for tag in ("inner", "outer"):
        if tag not in mesh.boundary_edges:
            raise ValueError(f"mesh has no boundary tag {tag!r}: the model needs 'inner' (injection) and 'outer' edges")


def simulate(params, options: RunOptions | None = None, out_dir=None, mesh=None, phi0=None, progress: bool = False,
             check_memory: bool = True, resume: bool = True) -> SimulationResult:
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
    resume : continue from the checkpoint in ``out_dir`` (``solver.checkpoint``, written every
        ``options.checkpoint_interval`` s of wall time) when it was written by this code for these parameters,
        options and mesh; any other checkpoint is ignored with one line in ``log.txt`` and the run starts at
        t = 0, as it does with ``resume=False``.  The resumed run keeps the snapshots and time series written
        before the checkpoint; its first step factorizes a fresh Jacobian (none is kept in the checkpoint), which
        is the only difference from the uninterrupted run: none with ``jacobian_reuse = 0``, the Newton tolerance
        otherwise.  ``summary.json`` then records ``resumed_from_t`` (s) and the wall time of every piece.

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
        status, reason, loop, nfact = _run(params, options, out_dir, mesh, phi0, progress, t_wall, warnings, path,
                                           resume)
    wall = loop.elapsed + time.perf_counter() - t_wall
    return SimulationResult(status, reason, pd.DataFrame(loop.rows), loop.snaps, wall,
                            str(out_dir) if out_dir is not None else None, loop.rejected, nfact,
                            profile=prof.to_dict(), path=path, resumed_from_t=loop.resumed_from_t)


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


def _run(params, options, out_dir, mesh, phi0, progress, t_wall, warnings=(), path=None, resume=True):
    """Set up, run the time loop (from the run folder's checkpoint when ``resume`` and it matches) and write the run
    folder; returns (status, reason, the loop's state, factorizations of the run); fills ``path`` with the run's
    :func:`run_path`."""
    sim, loop = None, None
    status, reason = "ok", None
    fact0 = linsolve.STATS["factorizations"]
    with phase("output"):
        writer, ck = _start_writer(out_dir, params, options, warnings, resume)
    try:
        with phase("setup"):
            sim = _setup(params, options, mesh, phi0)
        with phase("output"):
            loop = _start_loop(sim, params, options, writer, ck, t_wall)
        status, reason = _time_loop(sim, options, loop, writer, progress, t_wall)
    except Exception as exc:  # never a traceback as the only trace
        status, reason = "failed", f"{type(exc).__name__}: {exc}"
        if writer:
            writer.log(traceback.format_exc())
    loop = loop or _Loop([], options.dt0, {}, 0.0)
    nfact = linsolve.STATS["factorizations"] - fact0 + loop.factorizations
    if path is not None:
        path.update(run_path(sim, options))
    if writer:
        with phase("output"):
            writer.finish(pd.DataFrame(loop.rows), status, reason, loop.elapsed + time.perf_counter() - t_wall,
                          loop.rows[-1]["t"] if loop.rows else 0.0, loop.rejected, nfact, xdmf=options.write_xdmf,
                          path=run_path(sim, options), resumed_from_t=loop.resumed_from_t)
            checkpoint.remove(writer.dir)  # a run that ended is not resumed
    if progress:
        progress.close()
    return status, reason, loop, nfact


@dataclass
class _Loop:
    """The time loop's state besides the Simulation's (U, d, t, predictor): what a checkpoint holds with it."""

    pending: list  # snapshot times still to write, s
    dt: float  # the next step to try, s
    cum: dict  # cumulative balances, mm² ("W0": the invading fluid stored at t = 0)
    V0: float  # fluid stored at t = 0, mm²
    rows: list = field(default_factory=list)  # time-series rows
    snaps: list = field(default_factory=list)  # (t, fields) of the snapshots
    rejected: list = field(default_factory=list)  # rejected steps
    warned: bool = False  # the outer-layer warning was logged
    elapsed: float = 0.0  # wall time of the earlier pieces of a resumed run, s
    factorizations: int = 0  # factorizations of the earlier pieces of a resumed run
    resumed_from_t: list = field(default_factory=list)  # times the run resumed from, s
    identity: dict | None = None  # the run's identity (solver.checkpoint.identity)
    saved_at: float = 0.0  # perf_counter time of the last checkpoint or of this piece's start, s

    def checkpoint_state(self, sim, wall: float) -> dict:
        """The JSON part of a checkpoint (solver.checkpoint) after ``wall`` s of this piece of the run."""
        return {"dt": self.dt, "pending": self.pending, "cum": self.cum, "V0": self.V0, "rows": self.rows,
                "rejected": self.rejected, "warned": self.warned, "n_snapshots": len(self.snaps),
                "factorizations": linsolve.STATS["factorizations"] - sim.fact0, "elapsed": self.elapsed + wall,
                "resumed_from_t": self.resumed_from_t, "identity": self.identity}


def _start_writer(out_dir, params, options, warnings, resume):
    """(RunWriter, checkpoint to resume from or None) of a run with ``out_dir``, started (inputs written, a fresh
    run's old files removed); (None, None) without.  A checkpoint of other code, parameters or options, or one that
    cannot be read, is ignored with one log line."""
    if out_dir is None:
        return None, None
    writer = RunWriter(out_dir)
    ck, why = checkpoint.load(out_dir) if resume else (None, None)
    if ck is not None:
        why = checkpoint.mismatch(ck.get("identity") or {}, checkpoint.inputs_identity(params, options))
        ck = None if why else ck
    if ck is None:
        checkpoint.remove(out_dir)
    writer.start(params, options, resume=ck is not None)
    for w in warnings if ck is None else ():  # a resumed run's log holds them
        writer.log(f"WARNING: {w}")
    if why:
        writer.log(f"checkpoint ignored, the run starts at t = 0: {why}")
    return writer, ck


def _start_loop(sim, params, options, writer, ck, t_wall) -> _Loop:
    """The loop's state at the start of this piece of the run: resumed from the checkpoint ``ck`` when it is of
    this mesh and its snapshots are on disk, else at t = 0 (the initial snapshot taken)."""
    ident = checkpoint.identity(params, options, sim) if writer else None
    if writer:
        writer.write_mesh(sim.disc.points, sim.disc.triangles)
    loop = None
    if ck is not None:
        why = checkpoint.mismatch(ck["identity"], ident)
        try:
            loop = None if why else _resumed_loop(ck, sim, writer)
        except (OSError, ValueError, KeyError) as exc:
            why = f"its snapshots cannot be read ({type(exc).__name__}: {exc})"
        if loop is None:
            writer.remove_snapshots()
            writer.log(f"checkpoint ignored, the run starts at t = 0: {why}")
    loop = loop or _initial_loop(sim, options, writer)
    loop.identity, loop.saved_at = ident, t_wall
    return loop


def _initial_loop(sim, o: RunOptions, writer) -> _Loop:
    """The loop's state at t = 0: the stored volumes of the initial state and its snapshot."""
    cum = {"inj": 0.0, "src": 0.0, "out": 0.0, "w_in": 0.0, "w_out": 0.0, "w_src": 0.0, "line": 0.0}
    store0 = storage_fraction(sim.disc, sim.params, sim.U, porosity_state(sim.disc, sim.params, sim.U)[2])
    cum["W0"] = stored_volume(sim, water_fraction(sim, sim.U, store0))
    loop = _Loop(o.frame_times(), o.dt0, cum, stored_volume(sim, store0))
    take_snapshot(sim, loop.snaps, writer)  # the initial state, t = 0
    return loop


def _resumed_loop(ck: dict, sim, writer) -> _Loop:
    """The loop's state and ``sim``'s (U, d, t, predictor, factorization count) from the checkpoint ``ck``; the
    snapshots written before it are read back, those written after it removed.  Raises OSError, ValueError or
    KeyError (``sim`` untouched) when a snapshot is missing or unreadable."""
    n = int(ck["n_snapshots"])
    snaps = []
    for i in range(n):
        with np.load(writer.snap_dir / f"snap_{i:05d}.npz", allow_pickle=False) as z:
            snaps.append((float(z["t"]), {k: z[k] for k in z.files if k != "t"}))
    t = float(ck["t"])
    loop = _Loop(ck["pending"], ck["dt"], ck["cum"], ck["V0"], ck["rows"], snaps, ck["rejected"], ck["warned"],
                 ck["elapsed"], int(ck["factorizations"]), ck["resumed_from_t"] + [t])
    writer.remove_snapshots(n)
    writer.write_timeseries(pd.DataFrame(loop.rows))
    writer.log(f"resumed from the checkpoint at t = {t:.6g} s ({len(loop.rows)} steps)")
    sim.U, sim.d, sim.t, sim.previous = ck["U"], ck["d"], t, ck["previous"]
    sim.fact0 -= loop.factorizations
    return loop


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


def _time_loop(sim: Simulation, o: RunOptions, loop: _Loop, writer, progress, t_wall):
    """Advance ``sim`` from its time to ``o.t_end`` (s), recording into ``loop``; returns (status, reason)."""
    prof = profiling.active()
    while sim.t < o.t_end - 1e-12:
        if o.max_wall_time is not None and loop.elapsed + time.perf_counter() - t_wall > o.max_wall_time:
            return "failed", f"max_wall_time {o.max_wall_time} s exceeded at t = {sim.t:.4g} s"
        prof.set_part(sim.t)
        target = min(o.t_end, loop.pending[0]) if loop.pending else o.t_end
        dt_try = min(loop.dt, o.dt_max, target - sim.t)
        try:
            U, d, info = sim.step(dt_try)
        except (StepFailure, np.linalg.LinAlgError, RuntimeError, FloatingPointError, ValueError) as exc:
            failure = _reject(sim, o, loop, writer, dt_try, exc)
            if failure:
                return "failed", failure
            continue
        row = _accept(sim, U, d, dt_try, info, loop, writer)
        if progress:
            progress.update(sim.t, f"dt = {dt_try:.2e} s, newton {info['newton_its']}, stagger {info['stagger_its']}, "
                                   f"p_inj = {row['p_inj']:.1f} kPa, front = {row['front_radius_mean']:.1f} mm")
        with phase("output"):
            if loop.pending and abs(sim.t - loop.pending[0]) < 1e-9:
                loop.pending.pop(0)
                take_snapshot(sim, loop.snaps, writer)
            if writer and len(loop.rows) % 25 == 0:
                writer.write_timeseries(pd.DataFrame(loop.rows))
        if o.stop_front_radius is not None and np.isfinite(row["front_radius_max"]) and row["front_radius_max"] >= o.stop_front_radius:
            break
        loop.dt = _next_dt(o, dt_try, info)
        _checkpoint_if_due(sim, o, loop, writer, t_wall)
    if not loop.snaps or loop.snaps[-1][0] != sim.t:
        with phase("output"):
            take_snapshot(sim, loop.snaps, writer)
    return "ok", None


def _reject(sim, o: RunOptions, loop: _Loop, writer, dt_try: float, exc: Exception) -> str | None:
    """Record the rejected step of size dt_try (s) and cut the next dt; returns the run's failure reason when
    the cut falls below ``dt_min``, else None."""
    profiling.active().count("rejected_steps")
    loop.rejected.append({"t": sim.t, "dt": dt_try, "reason": str(exc)})
    if writer:
        writer.log(f"rejected step at t={sim.t:.6g} dt={dt_try:.3g}: {exc}")
    loop.dt = dt_try * o.dt_cut
    if loop.dt >= o.dt_min:
        return None
    limit = physical_limit(sim, getattr(exc, "node", None))
    return (f"time step below dt_min={o.dt_min} at t = {sim.t:.6g} s (last: {exc})"
            + (f"; physical limit: {limit}" if limit else ""))


def _accept(sim, U, d, dt_try: float, info: dict, loop: _Loop, writer) -> dict:
    """Commit the step of size dt_try (s) ending at (U, d): balances, time-series row (returned), counts and the
    outer-layer warning."""
    with phase("metrics"):
        _, ev, phi_q = porosity_state(sim.disc, sim.params, U)  # the new state's porosity, read twice below
        accumulate_balances(sim, U, info["data"], dt_try, loop.cum, ev, phi_q)
        sim.commit(U, d, dt_try)
        store = storage_fraction(sim.disc, sim.params, U, phi_q)
        row = step_row(sim, dt_try, info, loop.cum, loop.V0, stored_volume(sim, store),
                       stored_volume(sim, water_fraction(sim, U, store)))
    loop.rows.append(row)
    _count_step(profiling.active(), info)
    if row["outer_layer_area"] > 0 and not loop.warned:
        loop.warned = True
        if writer:
            writer.log(f"WARNING: invaded layer not connected to the inlet at the outer circle (area {row['outer_layer_area']:.3g} mm^2) at t={sim.t:.4g} s; see mu_outer_bc")
    return row


def _checkpoint_if_due(sim, o: RunOptions, loop: _Loop, writer, t_wall: float) -> None:
    """Write the checkpoint (solver.checkpoint) when the run has a folder and ``o.checkpoint_interval`` s of wall
    time have passed since the last one."""
    if writer is None or not o.checkpoint_interval or time.perf_counter() - loop.saved_at < o.checkpoint_interval:
        return
    with phase("output"):
        checkpoint.save(writer.dir, sim, loop.checkpoint_state(sim, time.perf_counter() - t_wall))
    loop.saved_at = time.perf_counter()


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
