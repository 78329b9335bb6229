"""Time loop of the coupled model: staggered Newton / active-set damage, adaptive steps, outputs.

Per time step (Sec. 3.1 of the paper):
  (a) monolithic Newton on the poromechanics block (u, p, S, μ [, G]) with d frozen;
  (b) the damage variational inequality d_n <= d <= 1 (primal-dual active set);
  repeat (a)-(b) until max |Δd| between stagger iterations < ``stagger_tol``.
Newton stops on a small update and a closed global balance (``Simulation.balanced``).
After an accepted step the next dt follows the step's change of S and d
(``_next_dt``).  A step whose Newton or stagger iterations fail is retried with a
smaller dt (every rejection logged); past ``dt_min`` the run ends with status
"failed", keeping everything written so far.
"""
from __future__ import annotations

import json
import math
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from . import damage, fem, linsolve, metrics, physics, profiling
from .anderson import Anderson
from .model import (MU, P, S, UX, UY, build_discretization, element_fields, line_stored_rate, outlet_water_outflow,
                    porosity_state, residual_and_jacobian, step_data, storage_fraction)
from .options import RunOptions, check_environment, check_run_inputs
from .output import RunWriter
from .profiling import phase

# floors of the per-field update scales used by the Newton test (mm, kPa, -, kPa, 1/mm)
_FLOORS = np.array([1e-2, 1e-2, 1.0, 1.0, 1e-2, 0.1, 0.1])
# fields the step predictor extrapolates (the others start from the last state): displacement and pressure
# evolve smoothly; S, μ and G carry the moving diffuse interface, where an extrapolated start overshoots
# [0, 1] and Newton on the double well diverges more often
_PREDICTED_FIELDS = [UX, UY, P]


class StepFailure(Exception):
    """A time step could not be solved at the current dt; ``node``: the node where the Newton iterate went
    furthest (out of the saturation bounds, or the largest scaled update), or None."""

    def __init__(self, message: str, node: int | None = None):
        super().__init__(message)
        self.node = node




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


class Simulation:
    """The discretized model on one mesh, and its Newton / damage / stagger solvers."""

    def __init__(self, params, options: RunOptions, mesh, phi0: np.ndarray):
        self.params, self.options, self.mesh = params, options, mesh
        self.disc = build_discretization(mesh, params, phi0, transport=options.transport,
                                         pressure_stabilization=options.pressure_stabilization)
        self.dmg = damage.damage_operators(self.disc.points, self.disc.triangles)
        self.edges = metrics.mesh_edges(self.disc.triangles)
        self.solver_kind = linsolve.resolve(options.linear_solver, self.disc.asm.ndof)
        self.precision = linsolve.resolve_precision(options.linear_precision, self.solver_kind)
        nf = self.disc.n_fields
        U = np.zeros((self.disc.n_nodes, nf))
        self.U = U
        self.d = np.zeros(self.disc.n_nodes)
        self.t = 0.0
        self.floors = _FLOORS[:nf]
        self.lu, self.lu_dt = None, None  # factorized Jacobian kept for reuse
        self.previous = None  # (U, d, dt) of the step before the last accepted one, for the predictor
        self.fact0 = linsolve.STATS["factorizations"]  # counter at the start of this run

    # ------------------------------------------------------------ poromechanics
    def newton(self, U0: np.ndarray, d: np.ndarray, data, rtol: float | None = None) -> tuple[np.ndarray, int]:
        """Solve the poromechanics block with d frozen to the relative tolerance ``rtol`` (default
        ``options.newton_rtol`` and the balance test ``balanced``); raises StepFailure.

        Newton with Jacobian reuse: a factorized Jacobian is kept across
        iterations, stagger iterations and time steps while the updates
        contract by at least ``options.jacobian_reuse`` per iteration (the
        factorization is the floor of this solver's cost); otherwise, and
        always when ``jacobian_reuse`` is 0, a fresh exact Jacobian is
        assembled and factorized, which gives Newton's quadratic convergence.
        """
        disc, nf, o = self.disc, self.disc.n_fields, self.options
        x = U0.ravel().copy()
        x[disc.dirichlet.dofs] = disc.dirichlet_values
        reuse = o.jacobian_reuse > 0
        if self.lu is not None and not (0.5 <= self.lu_dt / data.dt <= 2.0):
            self.lu = None  # the time terms scale with 1/dt: too different to reuse
        prev = None
        fresh = False
        x_back = None  # state before an update made with a reused Jacobian (rolled back if it diverged)
        accel = Anderson(o.anderson_depth) if o.anderson_depth else None
        for it in range(1, o.newton_max_its + 1):
            need_j = self.lu is None or not reuse
            with phase("assembly"), np.errstate(all="ignore"):  # a diverging trial iterate is handled below
                R, J = residual_and_jacobian(disc, self.params, x.reshape(-1, nf), data, need_jacobian=need_j)
                disc.dirichlet.apply_residual(R, x, disc.dirichlet_values)
                if need_j:
                    disc.dirichlet.apply_matrix(J)
            if not np.all(np.isfinite(R)):
                if x_back is None:
                    raise StepFailure("non-finite residual")
                x, x_back, self.lu, prev = x_back, None, None, None  # stale Jacobian diverged: back off, refresh
                continue
            if need_j:
                self.lu, self.lu_dt, fresh = linsolve.factorize(J, self.solver_kind, self.precision,
                                                                 condense=disc.projection_dofs), data.dt, True
                if accel:
                    accel.reset()
            dx = self.lu.solve(-R)
            if not np.all(np.isfinite(dx)):
                raise StepFailure("non-finite Newton update")
            x_back = None if fresh else x.copy()
            x = self._advance(x, dx, accel)
            X = x.reshape(-1, nf)
            scale = np.maximum(np.abs(X).max(axis=0), self.floors)
            upd = float((np.abs(dx.reshape(-1, nf)).max(axis=0) / scale).max())
            ratio = upd / prev if prev else 0.0
            if upd > 1e3 or not (-1.0 < X[:, S].min() and X[:, S].max() < 2.0):
                if x_back is not None:  # the stale Jacobian's fault: undo and refresh
                    x, x_back, self.lu, prev = x_back, None, None, None
                    continue
                self.lu = None
                raise StepFailure(f"Newton diverged (relative update {upd:.2e}, S in [{X[:, S].min():.3g}, {X[:, S].max():.3g}])",
                                  node=int(np.argmax(np.abs(X[:, S] - 0.5))))
            # with a reused Jacobian convergence is linear: the error left is about upd * ratio / (1 - ratio)
            # a loose solve (rtol given: the first stagger iteration's) only starts the next, so no balance test
            if upd <= (rtol or o.newton_rtol) * (1.0 if fresh or ratio < 0.5 else 0.1) and (rtol or self.balanced(X, data)):
                return X.copy(), it
            if reuse and not fresh and ratio > 1.0 and x_back is not None:
                x, self.lu, prev = x_back, None, None  # diverging with a stale Jacobian: undo, refresh
                continue
            if reuse and not fresh and ratio > o.jacobian_reuse:
                self.lu = None  # contraction too slow: refresh the Jacobian next iteration
            fresh = False if reuse else fresh
            prev = upd
        self.lu = None
        raise StepFailure(f"Newton did not converge in {o.newton_max_its} iterations (last relative update {upd:.2e})",
                          node=int(np.argmax((np.abs(dx.reshape(-1, nf)) / scale).max(axis=1))))

    def balanced(self, X: np.ndarray, data) -> bool:
        """Whether the iterate X (nodes x fields) conserves mass over the step: the global balances of the total
        fluid (the p rows, Eq. summary_equations_2) and of the invading fluid (the S rows) have defects
        |Σ R| (mm²/s, over the rows without a Dirichlet condition: Σ_a N_a = 1, so the sum is the step's
        balance with the boundary fluxes as reactions) within ``newton_mass_tol`` of the injection rate
        w_i × inner length.  The global material-balance test of reservoir simulators (MRST's ``tolerance_mb``
        beside the update test): a small update with a reused Jacobian bounds the error in the fields, not
        in the conserved totals; this one makes the volume balance of ``timeseries.csv`` hold to the
        tolerance whatever the step sequence and the Jacobian's age.  Without injection (w_i = 0) there is no
        scale for the balance (``mass_error`` is relative to the injected volume) and the update test decides."""
        disc, nf = self.disc, self.disc.n_fields
        rate = self.params.w_i * disc.inner_length
        if rate <= 0.0:
            return True
        with phase("assembly"), np.errstate(all="ignore"):
            R, _ = residual_and_jacobian(disc, self.params, X, data, need_jacobian=False)
            disc.dirichlet.apply_residual(R, X.ravel(), disc.dirichlet_values)  # Dirichlet rows: x − value = 0
        R = R.reshape(-1, nf)
        defect = max(abs(float(R[:, P].sum())), abs(float(R[:, S].sum())))
        return defect <= self.options.newton_mass_tol * rate

    def _advance(self, x: np.ndarray, dx: np.ndarray, accel: Anderson | None) -> np.ndarray:
        """The next Newton iterate: x + dx, or with ``accel`` the Anderson-accelerated one (residuals scaled by
        each field's scale, as the Newton test)."""
        if accel is None:
            return x + dx
        nf = self.disc.n_fields
        w = np.tile(1.0 / np.maximum(np.abs(x.reshape(-1, nf)).max(axis=0), self.floors), self.disc.n_nodes)
        return accel.next_iterate(x, dx, w)

    def active_energy(self, U: np.ndarray) -> np.ndarray:
        """Nodal (lumped-projected) active strain energy ψ_A (kPa) of displacement U."""
        tri = self.disc.triangles
        g = fem.field_gradients(self.disc.geom.grads, U[tri][:, :, :2])
        exx, eyy, exy = g[:, UX, 0], g[:, UY, 1], 0.5 * (g[:, UX, 1] + g[:, UY, 0])
        _, _, psi = physics.spectral_split(exx, eyy, exy, self.params.lame_lambda, self.params.lame_mu)
        return fem.nodal_average(psi, tri, self.disc.geom.areas, self.disc.n_nodes)

    # ------------------------------------------------------------ one step
    def predict(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Start of the stagger iterations of a step of size dt (s): the states (U, d) extrapolated linearly
        from the last two accepted steps (the state itself on the first step), U in ``_PREDICTED_FIELDS``
        only, d clipped to [d_n, 1].

        A start only: Newton converges to the same tolerance and the stagger stops on the same test
        max |Δd| < ``stagger_tol`` (its first iteration measured from d_n), so the accepted state meets
        the same equations; a closer start saves Newton iterations in every stagger iteration.
        """
        if self.previous is None:
            return self.U, self.d.copy()
        U_prev, d_prev, dt_prev = self.previous
        a = dt / dt_prev
        U = self.U.copy()
        f = _PREDICTED_FIELDS
        U[:, f] += a * (self.U[:, f] - U_prev[:, f])
        return U, np.clip(self.d + a * (self.d - d_prev), self.d, 1.0)

    def state_change(self, U: np.ndarray, d: np.ndarray) -> float:
        """Largest nodal change of the saturation S or the damage d (both dimensionless, in [0, 1]) from the
        last accepted state to (U, d): the measure of the state-change step controller (``_next_dt``).
        The inlet nodes, where S = 1 is imposed (Sec. 3.4), do not count: their jump on the first step is
        the boundary condition, not the solution's change."""
        dS = np.abs(U[:, S] - self.U[:, S])
        dS[self.disc.inner_nodes] = 0.0
        return float(max(dS.max(), np.max(np.abs(d - self.d))))

    def commit(self, U: np.ndarray, d: np.ndarray, dt: float) -> None:
        """Accept the step of size dt (s) that ends at (U, d)."""
        self.previous = (self.U, self.d, dt)
        self.U, self.d, self.t = U, d, self.t + dt

    def step(self, dt: float):
        """Advance by dt; returns (U, d, info) without committing. Raises StepFailure.

        With ``first_stagger_rtol`` the first stagger iteration solves Newton to that looser tolerance
        and cannot end the stagger: its damage only starts the second iteration, which (like every
        later one) solves to ``newton_rtol``; the accepted state meets the same two tests as always
        (the last stagger iteration's Newton at ``newton_rtol``, and max |Δd| < ``stagger_tol``).
        """
        o = self.options
        d_n = self.d
        U, d_k = self.predict(dt)
        newton_total = 0
        loose = o.first_stagger_rtol if o.stagger_max_its >= 2 else None
        for s in range(1, o.stagger_max_its + 1):
            with phase("stagger"):
                data = step_data(self.disc, self.params, self.U, d_k, dt)
            U, its = self.newton(U, d_k, data, rtol=loose if s == 1 else None)
            newton_total += its
            with phase("stagger"):
                psi = self.active_energy(U)
            with phase("damage"):
                res = damage.solve(d_k, d_n, psi, self.params, dt, self.dmg, max_its=o.damage_max_its)
            if not res.converged:
                raise StepFailure(f"damage active-set did not converge (KKT residual {res.kkt_residual:.2e})")
            # the first iteration's change is measured from d_n, not from the predicted start: a good
            # prediction must not end the stagger before one damage solve has been checked by a second
            change = float(np.max(np.abs(res.d - (d_n if s == 1 else d_k))))
            d_k = res.d
            if change < o.stagger_tol and not (s == 1 and loose):
                with phase("stagger"):
                    data = step_data(self.disc, self.params, self.U, d_k, dt)
                return U, d_k, {"newton_its": newton_total, "stagger_its": s, "damage_kkt": res.kkt_residual, "data": data,
                                "step_change": self.state_change(U, d_k)}
        raise StepFailure(f"stagger did not converge in {o.stagger_max_its} iterations (last max |Δd| {change:.2e})")


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
        kind = linsolve.resolve(options.linear_solver, 10**6)
        return {"linear_solver": kind, "linear_precision": linsolve.resolve_precision(options.linear_precision, kind),
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
    V0 = _stored_volume(sim, store0)
    cum["W0"] = _stored_volume(sim, _water_fraction(sim, sim.U, store0))
    warned_layer = False
    prof = profiling.active()
    with phase("output"):
        _snapshot(sim, snaps, writer)  # the initial state, t = 0
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
            _accumulate_balances(sim, U, info["data"], dt_try, cum, ev, phi_q)
            sim.commit(U, d, dt_try)
            store = storage_fraction(sim.disc, sim.params, U, phi_q)
            row = _row(sim, dt_try, info, cum, V0, _stored_volume(sim, store),
                       _stored_volume(sim, _water_fraction(sim, U, store)))
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
                _snapshot(sim, snaps, writer)
            if writer and len(rows) % 25 == 0:
                writer.write_timeseries(pd.DataFrame(rows))
        if o.stop_front_radius is not None and np.isfinite(row["front_radius_max"]) and row["front_radius_max"] >= o.stop_front_radius:
            break
        dt = _next_dt(o, dt_try, info)
    if not snaps or snaps[-1][0] != sim.t:
        with phase("output"):
            _snapshot(sim, snaps, writer)
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


def _accumulate_balances(sim, U, data, dt: float, cum: dict, ev: np.ndarray, phi_q: np.ndarray) -> None:
    """Add the step's injected, outflow, source and water volumes (mm²) to ``cum``.

    From the unconstrained residual at the converged state U: its Dirichlet rows are the reactions.  ``ev``,
    ``phi_q``: U's volumetric strain and porosity (:func:`solver.model.porosity_state`).
    """
    disc, p = sim.disc, sim.params
    R, _ = residual_and_jacobian(disc, p, U, data, need_jacobian=False)
    nf = disc.n_fields
    Rp, Rs = R[P::nf], R[S::nf]
    cum["inj"] += dt * p.w_i * disc.inner_length
    cum["out"] += -dt * Rp[disc.outer_nodes].sum()
    if disc.inner_weights is not None:  # the injection line's storage (solver.model.line_stored_rate)
        cum["line"] += dt * float(line_stored_rate(disc, p, U, data).v.sum())
    cum["src"] += dt * _source(sim, data, ev, phi_q)
    cum["w_src"] += dt * _source(sim, data, ev, phi_q * fem.at_quadrature(U[:, S], disc.triangles, fem.STRANG3))
    cum["w_in"] += dt * Rs[disc.inner_nodes].sum()
    if disc.outlet is None:  # S = 0 imposed on r_o: the water outflow is its reaction (0 with no S condition)
        cum["w_out"] += -dt * Rs[disc.outer_nodes].sum()
    else:  # the outlet's boundary term (solver.model.outlet_water_outflow), part of the S rows
        cum["w_out"] += dt * outlet_water_outflow(disc, p, U, R).sum()


def _stored_volume(sim, phi_q: np.ndarray) -> float:
    """∫ φ dx (mm² per unit cell height) from φ at the Strang points (equal weights); φ is the storage fraction
    (pores and the elastic cell's gap, :func:`solver.model.storage_fraction`)."""
    return float(np.sum(sim.disc.geom.areas * phi_q.mean(axis=1)))


def _water_fraction(sim, U: np.ndarray, phi_q: np.ndarray) -> np.ndarray:
    """φ S at the Strang points (M, 3), the invading fluid's volume fraction as the S rows' storage term sees it."""
    return phi_q * fem.at_quadrature(U[:, S], sim.disc.triangles, fem.STRANG3)


def _source(sim, data, ev: np.ndarray, phi_q: np.ndarray) -> float:
    """c_v ∫ φ ε̇_v dx: the second-order volume source of the total mass balance (mm²/s), from the step's
    frozen data and the new state's ε_v and φ; with φ S in place of φ (:func:`_water_fraction`), that of the
    invading balance."""
    dev = (ev - data.ev_n) / data.dt
    return float(sim.params.volumetric_coupling * np.sum(sim.disc.geom.areas * phi_q.mean(axis=1) * dev))


def _row(sim, dt, info, cum, V0, V, W) -> dict:
    """The time series' row of the committed state: V its stored volume, W its stored invading volume (mm²,
    :func:`_stored_volume`)."""
    disc, p, U, d = sim.disc, sim.params, sim.U, sim.d
    ef = element_fields(disc, p, U, d, fluxes=False)
    Sn = U[:, S]
    fm, fx, fb = metrics.front_measures(disc.points, Sn, sim.edges, disc.inner_nodes)
    err = abs(cum["inj"] - (V - V0 + cum["src"] + cum["out"] + cum["line"])) / max(cum["inj"], 1e-300)
    area = disc.geom.areas
    d_el = d[disc.triangles].mean(axis=1)
    inv = float(np.sum(area * ef["phi"] * Sn[disc.triangles].mean(axis=1)))
    return {
        "t": sim.t, "dt": dt,
        "p_inj": float(np.mean(U[disc.inner_nodes, P])),
        "injected_volume": cum["inj"],
        "invading_volume": inv,
        "water_inflow_volume": cum["w_in"],
        "water_outflow_volume": cum["w_out"],
        "outflow_volume": cum["out"],
        "line_stored_volume": cum["line"],
        "stored_volume": V,
        "source_volume": cum["src"],
        "mass_error": err,
        "water_stored_volume": W,
        "water_source_volume": cum["w_src"],
        "water_mass_error": abs(cum["w_in"] - cum["w_out"] - (W - cum["W0"] + cum["w_src"])) / max(cum["inj"], 1e-300),
        "mean_damage": float(np.sum(area * d_el) / area.sum()),
        "max_damage": float(d.max()),
        "max_hoop_stress": float(ef["hoop_stress"].max()),
        "front_radius_mean": fm,
        "front_radius_max": fx,
        "front_radius_branches": fb,
        "open_tip_radius": metrics.open_tip_radius(disc.points, disc.triangles, ef["phi"], disc.inner_nodes),
        "outer_layer_area": metrics.outer_layer_area(disc.points, disc.triangles, area, Sn, sim.edges, disc.inner_nodes, disc.outer_nodes),
        "newton_its": info["newton_its"],
        "stagger_its": info["stagger_its"],
        "damage_kkt": info["damage_kkt"],
        "step_change": info["step_change"],
        "factorizations": linsolve.STATS["factorizations"] - sim.fact0,
    }


def _snapshot(sim, snaps, writer):
    disc = sim.disc
    ef = element_fields(disc, sim.params, sim.U, sim.d)
    fields = {
        "S": sim.U[:, S].copy(), "mu": sim.U[:, MU].copy(), "p": sim.U[:, P].copy(), "d": sim.d.copy(),
        "u": sim.U[:, :2].copy(),
        "phi": ef["phi"], "eps_v": ef["eps_v"], "hoop_stress": ef["hoop_stress"], "k": ef["k"], "w1_mag": ef["w1_mag"],
    }
    snaps.append((sim.t, fields))
    if writer:
        writer.write_snapshot(len(snaps) - 1, sim.t, fields)


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
