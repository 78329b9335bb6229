"""The lag-1 estimator of the error model's correlation time ([noise] lag1, sweep/discrepancy/stats.py).

Known answers: on stationary AR(1) curves (the sampled Ornstein–Uhlenbeck process, ρ = exp(−Δt/τ)) of n points
each, "mean_ratio" (mean lag product over mean square) gives τ within its Monte-Carlo error, the error computed
from the draw count (Isserlis: the variance of a quadratic form of Gaussian curves, in closed form), while
"pooled" (n − 1 lag products over n squares) gives the ((n − 1)/n)·ρ it is biased to; both by hand on a short
curve with a missing point; the option reaches the realization covariance and the jitter term from the SPEC.
Units: times s, τ s; ρ dimensionless.
"""
import numpy as np
import pytest

from solver import Parameters
from sweep.discrepancy import ToyForward, stats
from sweep.discrepancy.layout import CurveLayout
from sweep.discrepancy.noise import add_discretization_error, model_jitter_at
from sweep.discrepancy.options import NoiseOptions, parse_options
from sweep.discrepancy.realizations import RealizationCovariance
from test_discrepancy_workflow import _problem, _spec_with

TAU, DT, N = 0.3, 0.1, 12                  # s, s, points per curve: the shared-realization toy's


def _ar1(rng, k: int, n: int, rho: float) -> np.ndarray:
    """(k, n) stationary AR(1) curves of unit variance and lag-1 correlation ``rho``."""
    x = np.empty((k, n))
    x[:, 0] = rng.standard_normal(k)
    for i in range(1, n):
        x[:, i] = rho * x[:, i - 1] + np.sqrt(1.0 - rho**2) * rng.standard_normal(k)
    return x


def _ratio_sd(k: int, n: int, rho: float) -> float:
    """Monte-Carlo sd of the mean-ratio estimate from k curves of n points (delta method): ρ̂ − ρ ≈ U/σ² with
    U = P̄ − ρ S̄ (P̄ the mean lag product, S̄ the mean square) = Σ_curves xᵀ A x, A the n × n form of one curve;
    Var U = k · 2 tr(AΣAΣ) (Isserlis), Σ_ij = ρ^|i−j|."""
    i = np.arange(n)
    S = rho ** np.abs(i[:, None] - i[None, :])
    A = (np.eye(n, k=1) + np.eye(n, k=-1)) / (2.0 * k * (n - 1)) - rho * np.eye(n) / (k * n)
    return float(np.sqrt(k * 2.0 * np.trace(A @ S @ A @ S)))


def _tau(rho: float) -> float:
    return -DT / np.log(rho)


def test_mean_ratio_recovers_tau_and_pooled_is_short_by_n_minus_1_over_n():
    """k = 4000 OU curves of 12 points, τ = 0.3 s, Δt = 0.1 s: the mean ratio's τ̂ within 4 of its MC sds of
    τ; the pooled ρ̂ within 4 sds of (11/12)·ρ (its τ̂ → 0.238 s), more than 4 sds short of τ."""
    rho = np.exp(-DT / TAU)
    k = 4000
    curves = [_ar1(np.random.default_rng(11), k, N, rho)]
    sd_rho = _ratio_sd(k, N, rho)
    sd_tau = TAU**2 / (DT * rho) * sd_rho                          # dτ/dρ = τ²/(Δt ρ)
    r_new, r_old = stats.mean_ratio_lag1(curves), stats.pooled_lag1(curves)
    assert abs(_tau(r_new) - TAU) <= 4.0 * sd_tau, (_tau(r_new), sd_tau)
    f = (N - 1) / N
    assert abs(r_old - f * rho) <= 4.0 * f * sd_rho, r_old
    tau_old = _tau(f * rho)
    assert tau_old == pytest.approx(0.2379, abs=1e-4)
    assert TAU - _tau(r_old) > 4.0 * sd_tau
    assert r_old == pytest.approx(f * r_new, rel=1e-12)              # equal-length curves: exactly the factor


def test_the_mc_sd_is_the_spread_over_replicates():
    """The closed-form sd of :func:`_ratio_sd` against the spread of 400 replicate estimates (k = 50 curves
    each): their ratio within 4 of its own sampling sds, 1/√(2 · 399)."""
    rho = np.exp(-DT / TAU)
    rng = np.random.default_rng(12)
    est = [stats.mean_ratio_lag1([_ar1(rng, 50, N, rho)]) for _ in range(400)]
    ratio = np.std(est, ddof=1) / _ratio_sd(50, N, rho)
    assert abs(ratio - 1.0) <= 4.0 / np.sqrt(2.0 * 399), ratio


def test_both_estimators_by_hand_with_a_missing_point():
    """[1, 2, 3]: pooled (2 + 6)/14; mean ratio (8/2)/(14/3).  [1, 2, NaN, 3, 4]: the pairs with both points
    present (2, 12) and the points present (1, 4, 9, 16); pooled as if the missing point were 0."""
    a = [np.array([[1.0, 2.0, 3.0]])]
    assert stats.pooled_lag1(a) == pytest.approx(8.0 / 14.0)
    assert stats.mean_ratio_lag1(a) == pytest.approx((8.0 / 2.0) / (14.0 / 3.0))
    b = np.array([[1.0, 2.0, np.nan, 3.0, 4.0]])
    assert stats.mean_ratio_lag1([b]) == pytest.approx((14.0 / 2.0) / (30.0 / 4.0))
    assert stats.pooled_lag1([b]) == stats.pooled_lag1([np.nan_to_num(b)]) == pytest.approx(14.0 / 30.0)
    assert stats.mean_ratio_lag1([np.array([[1.0, np.nan, 1.0]])]) == 0.0           # no pair: no correlation
    assert stats.mean_ratio_lag1([np.ones((2, 5))]) == 0.99                           # clipped


def test_the_realization_covariance_takes_the_estimator():
    """Six OU realizations on four conditions × 12 times: ρ of "mean_ratio" is n/(n − 1) times "pooled"'s
    (equal-length series), τ longer, and the covariance's blocks differ; the default is "pooled"."""
    t = np.tile(np.arange(1, N + 1) * DT, 4)
    lay = CurveLayout(series=np.repeat(np.arange(4), N), obs=np.array(["p_inj"] * t.size), t=t)
    fines = _ar1(np.random.default_rng(3), 24, N, np.exp(-DT / TAU)).reshape(6, 4 * N)
    old, new = (RealizationCovariance.estimate(fines, lay, lag1=e) for e in ("pooled", "mean_ratio"))
    assert RealizationCovariance.estimate(fines, lay).rho == old.rho and old.lag1 == "pooled"
    assert new.lag1 == "mean_ratio" and new.rho["p_inj"] == pytest.approx(old.rho["p_inj"] * N / (N - 1), rel=1e-12)
    assert new.tau["p_inj"] > old.tau["p_inj"] > 0.0
    assert not np.allclose(new.blocks[0][1], old.blocks[0][1])


class _Wander(ToyForward):
    """The toy plus a seeded OU curve (sd 1 kPa, τ 0.1 s) in p_inj per (realization ``seed``, w_i): a fine mesh
    realization whose deviation is correlated in time."""

    def __init__(self, seed: int):
        super().__init__({}, h=8.0)
        self.seed = seed

    def predict_one(self, overrides, times):
        out = super().predict_one(overrides, times)
        t = np.asarray(times["p_inj"], float)
        rng = np.random.default_rng([self.seed, int(round(Parameters.from_dict({**self.base, **overrides}).w_i))])
        dt = np.diff(t, prepend=t[0])
        z = np.empty(t.size)
        z[0] = rng.standard_normal()
        for i in range(1, t.size):
            r = np.exp(-dt[i] / 0.1)
            z[i] = r * z[i - 1] + np.sqrt(1.0 - r**2) * rng.standard_normal()
        out["p_inj"] = out["p_inj"] + z
        return out


def _series_counts(layout, obs: str) -> tuple[int, int]:
    """(points, adjacent pairs) of observable ``obs``'s series."""
    n = [rows.size for rows in layout.series_rows().values() if layout.obs[rows[0]] == obs]
    return sum(n), sum(m - 1 for m in n)


def test_the_spec_option_reaches_the_covariance_and_the_jitter(tmp_path):
    """``[noise] lag1`` from the SPEC: add_discretization_error builds the realization covariance with it
    (ρ of p_inj scaled by points/pairs of its series exactly, τ longer: 0.100 s, the fine toy's, against
    0.091 s) and model_jitter_at the jitter term (its ρ scaled the same)."""
    fines = [_Wander(s) for s in range(4)]
    at = {"kbar": 1e-3, "E": 331.0}
    got = {}
    for i, e in enumerate(("pooled", "mean_ratio")):
        prob = _problem(tmp_path / e, _spec_with({"noise": {"lag1": e}}))
        add_discretization_error(prob, fines, at)
        jit = model_jitter_at(prob, at, [p for p in prob.spec.calibrate if p.name == "E"], n_steps=5)
        got[e] = (prob.real_cov, jit)
    n_pts, n_pairs = _series_counts(got["pooled"][0].layout, "p_inj")
    (old, j_old), (new, j_new) = got["pooled"], got["mean_ratio"]
    assert old.lag1 == "pooled" and new.lag1 == "mean_ratio"
    assert new.rho["p_inj"] == pytest.approx(old.rho["p_inj"] * n_pts / n_pairs, rel=1e-12)
    assert 0.0 < old.rho["p_inj"] < new.rho["p_inj"] < 0.99 and new.tau["p_inj"] > old.tau["p_inj"]
    for o in ("front_radius_mean", "crack_length"):        # the jitter's ρ unclipped there (p_inj's: 0.99)
        n_pts, n_pairs = _series_counts(old.layout, o)
        assert 0.0 < j_old.rho[o] < j_new.rho[o] < 0.99
        assert j_new.rho[o] == pytest.approx(j_old.rho[o] * n_pts / n_pairs, rel=1e-12)


def test_an_unknown_lag1_estimator_is_refused_naming_key_value_and_choices():
    assert NoiseOptions().lag1 == "pooled"
    assert parse_options({"noise": {"lag1": "mean_ratio"}}).noise.lag1 == "mean_ratio"
    with pytest.raises(ValueError, match=r"noise\.lag1='unbiased'.*\"pooled\" or \"mean_ratio\""):
        parse_options({"noise": {"lag1": "unbiased"}})
    with pytest.raises(ValueError, match="estimator='burg'"):
        stats.lag1_estimate([np.ones((1, 3))], "burg")
