"""Anderson acceleration of the reused-Jacobian Newton iteration (solver.anderson), against known properties:
on a linear fixed-point problem of dimension n, depth >= n terminates like GMRES (exact after at most n + 1
accelerated steps); a cleared history gives the plain step; coupled runs with and without it agree to the
Newton tolerance."""
import numpy as np
import pytest

from solver import Parameters, RunOptions, simulate
from solver.anderson import Anderson


def _linear_problem(n=6, rho=0.95, seed=0):
    """x = M x + c with the spectral radius of M = rho (slow plain iteration)."""
    rng = np.random.default_rng(seed)
    Q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    M = Q @ np.diag(rho * np.linspace(-1, 1, n)) @ Q.T
    c = rng.standard_normal(n)
    return M, c, np.linalg.solve(np.eye(n) - M, c)


def test_depth_n_solves_a_linear_problem_of_dimension_n_in_n_plus_one_steps():
    M, c, x_star = _linear_problem()
    acc, x = Anderson(depth=6), np.zeros(6)
    for _ in range(8):
        x = acc.next_iterate(x, M @ x + c - x, np.ones(6))
    assert np.linalg.norm(x - x_star) < 1e-9 * np.linalg.norm(x_star)
    y = np.zeros(6)
    for _ in range(8):  # the plain iteration is far from it
        y = M @ y + c
    assert np.linalg.norm(y - x_star) > 0.1 * np.linalg.norm(x_star)


def test_without_history_the_step_is_the_plain_one():
    acc = Anderson(depth=3)
    x, dx = np.arange(4.0), np.ones(4)
    assert np.array_equal(acc.next_iterate(x, dx, np.ones(4)), x + dx)
    acc.next_iterate(x + dx, 0.5 * dx, np.ones(4))
    acc.reset()
    assert np.array_equal(acc.next_iterate(x, dx, np.ones(4)), x + dx)


def test_depth_below_one_is_refused():
    with pytest.raises(ValueError, match="depth"):
        Anderson(0)
    for bad in (-1, 21, 2.5):
        with pytest.raises(ValueError, match="anderson_depth"):
            RunOptions(anderson_depth=bad)


def test_the_depth_round_trips_and_zero_or_none_is_the_plain_iteration():
    assert RunOptions().anderson_depth == 3 and RunOptions().to_dict()["anderson_depth"] == 3
    assert RunOptions(anderson_depth=None).anderson_depth == 0 == RunOptions(anderson_depth=0).anderson_depth
    for depth in (0, 5):
        assert RunOptions.from_dict(RunOptions(anderson_depth=depth).to_dict()).anderson_depth == depth


def test_accelerated_run_meets_the_same_equations():
    """h = 6 mm, 25 fixed steps of 2 ms (the start-up, where the Newton iterations are hardest; a fixed step so
    that both runs solve the same sequence of problems): p_inj within a few Newton tolerances (1e-6 relative
    per update) of the plain iteration, and no more factorizations."""
    base = dict(h=6.0, t_end=0.05, dt0=2e-3, dt_max=2e-3, dt_grow=1.0, step_control="iterations", snapshot_times=[],
                write_xdmf=False)
    plain = simulate(Parameters(), RunOptions(**base, anderson_depth=0))
    accel = simulate(Parameters(), RunOptions(**base, anderson_depth=3))
    assert plain.status == accel.status == "ok" and not plain.rejected_steps and not accel.rejected_steps
    np.testing.assert_allclose(accel.timeseries["t"], plain.timeseries["t"], rtol=1e-12)
    p0, p1 = plain.timeseries["p_inj"].to_numpy(), accel.timeseries["p_inj"].to_numpy()
    assert np.max(np.abs(p1 / p0 - 1.0)) < 1e-5
    assert accel.factorizations <= plain.factorizations

