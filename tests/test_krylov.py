"""The Newton–Krylov option (run option ``newton_krylov``; solver.krylov), against known answers: GMRES terminates
in as many iterations as the preconditioned matrix has distinct eigenvalues, its true residual meets the
forcing, it reports failure when the iterations do not reach it; a coupled run with it solves the same equations
as the chord iteration, to the Newton tolerance, in no more Newton iterations."""
import numpy as np
import pytest

from solver import Parameters, RunOptions, simulate
from solver.krylov import gmres


def _matrix_with_eigenvalues(eigs, seed=0):
    """A dense non-symmetric matrix V diag(eigs) V⁻¹ of size len(eigs), with a well-conditioned V."""
    rng = np.random.default_rng(seed)
    n = len(eigs)
    V = np.eye(n) + 0.3 * rng.standard_normal((n, n)) / np.sqrt(n)
    return V @ np.diag(eigs) @ np.linalg.inv(V)


def test_gmres_terminates_in_as_many_iterations_as_distinct_eigenvalues():
    A = _matrix_with_eigenvalues(np.repeat([1.0, 2.0, 5.0], 10))  # minimal polynomial of degree 3
    b = np.random.default_rng(1).standard_normal(30)
    x, its = gmres(lambda v: A @ v, lambda v: v, b, 1e-10, 30)
    assert its == 3
    assert np.linalg.norm(A @ x - b) <= 1e-10 * np.linalg.norm(b)


def test_gmres_with_the_exact_preconditioner_takes_one_iteration():
    A = _matrix_with_eigenvalues(np.linspace(1.0, 100.0, 20))
    b = np.arange(1.0, 21.0)
    Ainv = np.linalg.inv(A)
    x, its = gmres(lambda v: A @ v, lambda v: Ainv @ v, b, 1e-12, 5)
    assert its == 1
    np.testing.assert_allclose(x, np.linalg.solve(A, b), rtol=1e-10)


def test_gmres_meets_the_forcing_with_a_stale_preconditioner_and_fails_without_enough_iterations():
    """A preconditioner made from a perturbed matrix (a kept factorization of an earlier Jacobian): the true
    residual of the answer is within the forcing; one iteration is not enough, and None says so."""
    rng = np.random.default_rng(2)
    A = _matrix_with_eigenvalues(np.linspace(1.0, 50.0, 40))
    P_inv = np.linalg.inv(A + 0.2 * np.diag(np.diag(A)) + 0.05 * rng.standard_normal((40, 40)))
    b = rng.standard_normal(40)
    x, its = gmres(lambda v: A @ v, lambda v: P_inv @ v, b, 1e-3, 40)
    assert 1 < its < 40
    assert np.linalg.norm(A @ x - b) <= 1e-3 * np.linalg.norm(b) * (1 + 1e-9)
    assert gmres(lambda v: A @ v, lambda v: P_inv @ v, b, 1e-3, 1) == (None, 1)


def test_newton_krylov_is_refused_out_of_range_and_left_out_of_the_run_key_when_off():
    for bad in (0, 101, 2.5):
        with pytest.raises(ValueError, match="newton_krylov"):
            RunOptions(newton_krylov=bad)
    assert "newton_krylov" not in RunOptions().to_dict()
    assert RunOptions.from_dict(RunOptions(newton_krylov=10).to_dict()).newton_krylov == 10


def test_newton_krylov_run_meets_the_same_equations_as_the_chord_iteration():
    """h = 6 mm, 25 fixed steps of 2 ms (the start-up, where the Newton iterations are hardest): p_inj within a
    few Newton tolerances (1e-6 relative per update) of the chord iteration, in no more Newton iterations (the
    exact Jacobian converges at least as fast as a kept one)."""
    base = dict(h=6.0, t_end=0.05, dt0=2e-3, dt_max=2e-3, dt_grow=1.0, step_control="iterations", snapshot_times=[],
                write_xdmf=False)
    chord = simulate(Parameters(), RunOptions(**base))
    nk = simulate(Parameters(), RunOptions(**base, newton_krylov=10))
    assert chord.status == nk.status == "ok" and not chord.rejected_steps and not nk.rejected_steps
    np.testing.assert_allclose(nk.timeseries["t"], chord.timeseries["t"], rtol=1e-12)
    p0, p1 = chord.timeseries["p_inj"].to_numpy(), nk.timeseries["p_inj"].to_numpy()
    assert np.max(np.abs(p1 / p0 - 1.0)) < 1e-5
    assert nk.timeseries["newton_its"].sum() <= chord.timeseries["newton_its"].sum()


def test_the_residual_of_the_balance_test_is_reused_and_changes_nothing(monkeypatch):
    """The residual the mass-balance test assembles at an iterate is the one the next Newton iteration needs at
    that iterate: reusing it saves assemblies and leaves the run bitwise unchanged (against the same run with the
    balance test not handing it over)."""
    from solver.stagger import Simulation

    base = dict(h=6.0, t_end=0.03, dt0=2e-3, dt_max=2e-3, dt_grow=1.0, snapshot_times=[], write_xdmf=False)
    reused = simulate(Parameters(), RunOptions(**base))
    original = Simulation.balanced
    monkeypatch.setattr(Simulation, "balanced", lambda self, X, data, keep=None: original(self, X, data))
    assembled = simulate(Parameters(), RunOptions(**base))
    assert reused.status == assembled.status == "ok"
    assert reused.timeseries["p_inj"].tolist() == assembled.timeseries["p_inj"].tolist()
    assert reused.timeseries["newton_its"].tolist() == assembled.timeseries["newton_its"].tolist()
    calls = [r.profile["total"]["calls"]["assembly"] for r in (reused, assembled)]
    assert calls[0] < calls[1]
