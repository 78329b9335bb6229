"""The discretized model on one mesh and its time-step solver (Sec. 3.1 of the paper).

Per time step: (a) monolithic Newton on the poromechanics block (u, p, S, μ [, G]) with d frozen; (b) the damage
variational inequality d_n <= d <= 1 (primal-dual active set, :mod:`solver.damage`); (a)-(b) repeated until
max |Δd| between stagger iterations < ``stagger_tol``.  Newton stops on a small update and a closed global balance
(:meth:`Simulation.balanced`).  A step that fails raises :class:`StepFailure`; :mod:`solver.simulate` retries it
with a smaller dt.  Units mm, s, kPa.
"""
from __future__ import annotations

import numpy as np

from . import damage, fem, krylov, linsolve, metrics, paths, physics
from .anderson import Anderson
from .model import P, S, UX, UY, build_discretization, residual_and_jacobian, step_data
from .options import RunOptions
from .profiling import phase

__all__ = ["Simulation", "StepFailure"]

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


class Simulation:
    """The discretized model on one mesh, and its Newton / damage / stagger solvers."""

    def __init__(self, params, options: RunOptions, mesh, phi0: np.ndarray):
        self.params, self.options, self.mesh = params, options, mesh
        self.disc = build_discretization(mesh, params, phi0, transport=options.transport,
                                         pressure_stabilization=options.pressure_stabilization)
        self.dmg = damage.damage_operators(self.disc.points, self.disc.triangles)
        self.edges = metrics.mesh_edges(self.disc.triangles)
        self.solver_kind = paths.resolve(options.linear_solver, self.disc.asm.ndof)
        self.precision = paths.resolve_precision(options.linear_precision, self.solver_kind)
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
        With ``options.newton_krylov`` every iteration assembles the exact Jacobian and solves for its update by
        GMRES preconditioned by the kept factors (:meth:`_krylov_update`), refactorizing only when GMRES does
        not reach the forcing: inexact Newton, without the chord iteration's rollback and Anderson's acceleration.
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
        nk = o.newton_krylov is not None  # Newton–Krylov: the exact Jacobian every iteration, GMRES on kept factors
        seen = {}  # the residual the balance test assembled at the iterate it tested (reused by the next iteration)
        for it in range(1, o.newton_max_its + 1):
            need_j = self.lu is None or not reuse or nk
            if not need_j and seen.get("x") is x:
                R = seen.pop("R")
            else:
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
            dx = self._krylov_update(J, R) if nk and self.lu is not None else None
            if dx is None and need_j:
                self.lu, self.lu_dt, fresh = linsolve.factorize(J, self.solver_kind, self.precision,
                                                                 condense=disc.projection_dofs), data.dt, True
                if accel:
                    accel.reset()
            if dx is None:
                dx = self.lu.solve(-R)
            if not np.all(np.isfinite(dx)):
                raise StepFailure("non-finite Newton update")
            fresh = fresh or nk  # a Newton–Krylov update is an (inexact) Newton step with the exact Jacobian
            x_back = None if fresh else x.copy()
            x = x + dx if nk else self._advance(x, dx, accel)
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
            if upd <= (rtol or o.newton_rtol) * (1.0 if fresh or ratio < 0.5 else 0.1) and (rtol or self.balanced(X, data, seen)):
                return X.copy(), it
            if reuse and not fresh and ratio > 1.0 and x_back is not None:
                x, self.lu, prev = x_back, None, None  # diverging with a stale Jacobian: undo, refresh
                continue
            if reuse and not fresh and ratio > o.jacobian_reuse:
                self.lu = None  # contraction too slow: refresh the Jacobian next iteration
            fresh = False if reuse and not nk else fresh
            prev = upd
        self.lu = None
        raise StepFailure(f"Newton did not converge in {o.newton_max_its} iterations (last relative update {upd:.2e})",
                          node=int(np.argmax((np.abs(dx.reshape(-1, nf)) / scale).max(axis=1))))

    def _krylov_update(self, J, R: np.ndarray) -> np.ndarray | None:
        """The Newton update J dx = −R by GMRES preconditioned by the kept factors (``options.newton_krylov``
        iterations at most, to the forcing ``linsolve.SINGLE_FORCING``), or None when it does not get there."""
        with phase("solve"):
            dx, its = krylov.gmres(lambda v: J @ v, self.lu.solve, -R, linsolve.SINGLE_FORCING,
                                   self.options.newton_krylov)
        linsolve.STATS["krylov_iterations"] = linsolve.STATS.get("krylov_iterations", 0) + its
        return dx

    def balanced(self, X: np.ndarray, data, keep: dict | None = None) -> bool:
        """Whether the iterate X (nodes x fields) conserves mass over the step: the global balances of the total
        fluid (the p rows, Eq. summary_equations_2) and of the invading fluid (the S rows) have defects
        |Σ R| (mm²/s, over the rows without a Dirichlet condition: Σ_a N_a = 1, so the sum is the step's
        balance with the boundary fluxes as reactions) within ``newton_mass_tol`` of the injection rate
        w_i × inner length.  The global material-balance test of reservoir simulators (MRST's ``tolerance_mb``
        beside the update test): a small update with a reused Jacobian bounds the error in the fields, not
        in the conserved totals; this one makes the volume balance of ``timeseries.csv`` hold to the
        tolerance whatever the step sequence and the Jacobian's age.  Without injection (w_i = 0) there is no
        scale for the balance (``mass_error`` is relative to the injected volume) and the update test decides.
        ``keep``: a dict that receives the residual it assembled ("R", Dirichlet rows applied) at the flat iterate
        ("x", the array X views), for the next Newton iteration at the same iterate."""
        disc, nf = self.disc, self.disc.n_fields
        rate = self.params.w_i * disc.inner_length
        if rate <= 0.0:
            return True
        with phase("assembly"), np.errstate(all="ignore"):
            R, _ = residual_and_jacobian(disc, self.params, X, data, need_jacobian=False)
            disc.dirichlet.apply_residual(R, X.ravel(), disc.dirichlet_values)  # Dirichlet rows: x − value = 0
        if keep is not None:
            keep.update(x=X.base if X.base is not None else X, R=R)
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
