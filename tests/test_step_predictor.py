"""Step predictor of the time loop: linear extrapolation of (u, p) and of d (clipped to [d_n, 1]) from the last two steps."""
import numpy as np

from solver import Parameters, RunOptions
from solver.mesh import annulus_mesh
from solver.model import MU, P, S, UX
from solver.porosity import initial_porosity
from solver.simulate import Simulation


def _sim():
    p = Parameters()
    mesh = annulus_mesh(p.r_inner, p.r_outer, 8.0)
    return Simulation(p, RunOptions(h=8.0), mesh, initial_porosity(mesh, p))


def test_first_step_starts_from_the_state():
    sim = _sim()
    U, d = sim.predict(1e-3)
    assert np.array_equal(U, sim.U) and np.array_equal(d, sim.d)


def test_extrapolation_is_exact_for_states_linear_in_time():
    sim = _sim()
    rng = np.random.default_rng(1)
    U0, U1 = rng.standard_normal(sim.U.shape), rng.standard_normal(sim.U.shape)  # U(t) = U0 + t U1
    d0, d1 = np.full(len(sim.d), 0.2), rng.uniform(0, 12, len(sim.d))  # d1 > 10: past 1 by t = 0.08
    sim.U, sim.d = U0.copy(), d0.copy()
    sim.commit(U0 + 0.01 * U1, d0 + 0.01 * d1, 0.01)
    sim.commit(U0 + 0.03 * U1, d0 + 0.03 * d1, 0.02)
    U, d = sim.predict(0.05)  # to t = 0.08
    np.testing.assert_allclose(U[:, [UX, P]], (U0 + 0.08 * U1)[:, [UX, P]], rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(U[:, [S, MU]], sim.U[:, [S, MU]])  # the interface fields start from the state
    d_n = np.minimum(d0 + 0.03 * d1, 1.0)
    np.testing.assert_allclose(d, np.clip(d0 + 0.08 * d1, d_n, 1.0), rtol=1e-12)
    assert d.max() == 1.0  # some nodes would extrapolate past 1


def test_predicted_damage_never_below_the_last_state():
    sim = _sim()
    sim.d = np.full(len(sim.d), 0.5)
    sim.commit(sim.U, np.full(len(sim.d), 0.4), 0.01)  # damage decreasing: irreversibility keeps d_n
    _, d = sim.predict(0.01)
    np.testing.assert_array_equal(d, 0.4)
