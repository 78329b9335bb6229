"""Cheaper twins without other numbers (issue #53 item 4, "Ten minutes"): the Jacobian's points run in the
batch of each residual evaluation (``[fit] prefetch_jacobian``), and the profile's linear correction from m of
the k fine realizations at every anchor with the m-mean's error carried by the realization covariance
(``[profile] correction_realizations``).

Known answers: a fit with the Jacobian prefetched is the same fit (the same points, x and cost to rounding) in
fewer forward batches; the realization variance of a k-realization estimate is (1 + 1/k) s², that of an
m-mean (1 + 1/m) s² (one more realization about an m-sample mean); a linear correction from the first m
realizations at every anchor is the line through their means.  Units kPa, mm, s; strengths in kPa·s.
"""
import tempfile
from pathlib import Path

import numpy as np
import pytest

from sweep.discrepancy.coverage import NOISE, SETUPS, TIMES, _spec
from sweep.discrepancy.data import load_measured
from sweep.discrepancy.layout import CurveLayout
from sweep.discrepancy.noise import add_discretization_error, coarse_and_fines, correction_from
from sweep.discrepancy.problem import Problem
from sweep.discrepancy.profile import _Profile
from sweep.discrepancy.realizations import RealizationCovariance
from sweep.discrepancy.toy import MeshToy
from sweep.discrepancy.twin import make_twin

SU = SETUPS[0]                     # E calibrated, rate axis, damage viscosity hidden
TRAIN = ["c0", "c1", "c2"]
TRUTH = {"beta": 40.0, "volumetric_coupling": 0.0, "E": 331.0}
AT = {"E": 331.0, "effect:damage_viscosity": 40.0}


class _Batches(MeshToy):
    """MeshToy recording the size of every forward batch (predict_many call)."""

    def __init__(self, *a, **kw):
        super().__init__(*a, **kw)
        self.batches = []

    def predict_many(self, jobs):
        self.batches.append(len(jobs))
        return super().predict_many(jobs)


def _data(fwd, seed=1):
    with tempfile.TemporaryDirectory() as tmp:
        return load_measured(make_twin(Path(tmp) / "d", fwd, SU.conditions(), TIMES, TRUTH, noise=NOISE, seed=seed,
                                       observables=tuple(NOISE), regime=False))


def _problem(data, fwd, tables: dict):
    spec = _spec(SU, {"noise": {"disc_error_fraction": 0.0}, **tables})
    return Problem(data, spec, fwd), tuple(spec.calibrate) + (spec.candidate_param("damage_viscosity"),)


# --- [fit] prefetch_jacobian ------------------------------------------------------------------------------------

def test_a_prefetched_jacobian_gives_the_same_fit_in_fewer_batches():
    """The same robust least squares from the same start with and without the prefetch: x and cost equal to
    rounding, every point of the plain fit also run by the prefetching one (its extra runs: Jacobian points of
    rejected steps only), in fewer forward batches (the residuals and the Jacobian of an accepted step in one)."""
    data = _data(MeshToy(2.0, 0, shape="wander"))
    out = {}
    for pre in (False, True):
        fwd = _Batches(4.0, 0, spread=0.0)
        prob, params = _problem(data, fwd, {"fit": {"prefetch_jacobian": pre, "max_nfev": 8}})
        fit = prob.fit(params, [np.array([params[0].to_x(300.0), 20.0])], TRAIN)
        out[pre] = (fit, fwd, {tuple(np.round(x, 9)) for x in prob.evaluated(params, TRAIN)})
    (f0, fw0, pts0), (f1, fw1, pts1) = out[False], out[True]
    assert np.allclose(f1.x, f0.x, rtol=1e-10, atol=1e-12) and f1.cost == pytest.approx(f0.cost, rel=1e-10)
    assert pts0 <= pts1 and fw1.n_runs >= fw0.n_runs
    assert len(fw1.batches) < len(fw0.batches)
    assert fw1.batches[0] == len(TRAIN) * (1 + len(params))      # the start and its Jacobian's points together


def test_prefetch_jacobian_is_a_checked_bool():
    with pytest.raises(ValueError, match="fit.prefetch_jacobian"):
        _spec(SU, {"fit": {"prefetch_jacobian": 1}})
    assert _spec(SU, {}).fit.prefetch_jacobian is False


def test_a_chi2_tolerance_stops_the_fit_where_steps_gain_less_than_it():
    """On the wandering mesh toy (a model with jitter) the plain fit takes 8 evaluations to meet scipy's
    default tolerances; with [fit] chi2_tol = 0.1 it stops once a step gains less than 0.1 in χ²: fewer forward
    runs, and a cost (χ²/2 of the robust loss) within 0.05 of the plain fit's or below it."""
    data = _data(MeshToy(2.0, 0, shape="wander"))
    out = {}
    for tol in (0.0, 0.1):
        fwd = _Batches(4.0, 0, spread=0.0)
        prob, params = _problem(data, fwd, {"fit": {"chi2_tol": tol, "max_nfev": 12}})
        fit = prob.fit(params, [np.array([params[0].to_x(300.0), 20.0])], TRAIN)
        out[tol] = (fit, fwd.n_runs)
    (plain, n0), (tol, n1) = out[0.0], out[0.1]
    assert n1 < n0
    assert tol.cost <= plain.cost + 0.05


def test_chi2_tol_is_a_checked_nonnegative_float():
    with pytest.raises(ValueError, match="fit.chi2_tol"):
        _spec(SU, {"fit": {"chi2_tol": -0.1}})
    assert _spec(SU, {}).fit.chi2_tol == 0.0


# --- [profile] correction_realizations ----------------------------------------------------------------------------

def _layout(n=8):
    t = np.linspace(0.02, 0.3, n)
    return CurveLayout(np.zeros(n, int), np.array(["p_inj"] * n), t)


def test_the_realization_variance_carries_the_error_of_the_mean_in_use():
    """Six realizations with sample sd s = 2 at every point: the covariance's variance is (1 + 1/6) s² = 4.667
    (kPa²); for the mean of 3 of them (1 + 1/3) s² = 5.333, for the mean of 2 (1 + 1/2) s² = 6; back to all six
    with 0; the same m twice changes nothing; the correlation and a jitter term are kept; m outside 0, 2..k
    refused."""
    lay = _layout()
    dev = np.array([-1.0, 1.0, -1.0, 1.0, -1.0, 1.0]) * np.sqrt(20.0 / 6.0)     # sample sd 2 (ddof 1)
    fines = 10.0 + dev[:, None] * np.ones(8)
    rc = RealizationCovariance.estimate(fines, lay)
    assert rc.k == 6 and rc.variance(8) == pytest.approx(np.full(8, (1 + 1 / 6) * 4.0))
    three = rc.for_mean_of(3)
    assert three.variance(8) == pytest.approx(np.full(8, (1 + 1 / 3) * 4.0))
    assert three.for_mean_of(3).variance(8) == pytest.approx(three.variance(8))
    assert three.for_mean_of(2).variance(8) == pytest.approx(np.full(8, 1.5 * 4.0))
    assert three.for_mean_of(0).variance(8) == pytest.approx(rc.variance(8))
    c0, c3 = rc.blocks[0][1], three.blocks[0][1]
    assert np.allclose(c3 / np.sqrt(np.outer(np.diag(c3), np.diag(c3))), c0 / np.sqrt(np.outer(np.diag(c0), np.diag(c0))))
    jit = {0: (rc.blocks[0][0], np.eye(8))}
    assert rc.with_jitter(jit).for_mean_of(3).variance(8) == pytest.approx(three.variance(8) + 1.0)
    for bad in (1, 7):
        with pytest.raises(ValueError, match="for_mean_of"):
            rc.for_mean_of(bad)


def _profile(m: int, fines: list, data):
    prob, params = _problem(data, MeshToy(4.0, 0, spread=0.0),
                            {"profile": {"likelihood": "gaussian", "correction": "linear",
                                         "correction_realizations": m, "correction_anchors": 2}})
    add_discretization_error(prob, fines, AT)
    var0 = prob.noise.real_cov.variance(prob.y.size)
    fit = prob.fit(params, [np.array([params[0].to_x(331.0), 40.0])], TRAIN)
    runs0 = sum(f.n_runs for f in fines)
    return prob, _Profile(prob, fit, 1, TRAIN, 3.841, fines), sum(f.n_runs for f in fines) - runs0, var0


def test_the_linear_correction_from_m_realizations_at_every_anchor():
    """``correction_realizations = 2`` of k = 4: every anchor runs the first 2 realizations (2 x 2 anchors x 4
    conditions fine runs against 4 x 2 x 4), the line through two anchors goes through the corrections of those
    two (the known answer: correction_from of the first two fine models at each anchor), and the covariance's realization term
    is scaled by (1 + 1/2)/(1 + 1/4) = 1.2, where it stays for what follows the profile."""
    data = _data(MeshToy(2.0, 0, shape="wander"))
    fines = [MeshToy(2.0, 1 + i, shape="wander") for i in range(4)]
    _, _, n_all, _ = _profile(0, fines, data)
    prob, pf, n_two, var0 = _profile(2, fines, data)
    assert (n_all, n_two) == (4 * 2 * 4, 2 * 2 * 4)
    assert pf.cm.realizations == 2 and prob.noise.real_cov.mean_of == 2
    assert prob.noise.real_cov.variance(var0.size) == pytest.approx(var0 * 1.5 / 1.25)
    prob.noise.correction_mean_of(0)                 # the anchors are placed under the fit's noise model
    for x, (full, _) in zip(pf.cm.xs, pf.anchors()[0]):
        vals = {q.name: q.from_x(float(v)) for q, v in zip(pf.fit.params, full)}
        coarse, two = coarse_and_fines(prob, fines[:2], vals)
        assert np.allclose(pf.cm.at(x), correction_from(coarse, two), atol=1e-9)


def test_correction_realizations_is_checked():
    assert _spec(SU, {}).profile.correction_realizations == 0
    for bad, match in (({"correction_realizations": 3}, "profile.correction_realizations=3"),
                       ({"correction": "linear", "correction_realizations": 1}, "at least 2"),
                       ({"correction": "linear", "correction_realizations": -1}, "profile.correction_realizations"),
                       ({"correction": "linear", "correction_realizations": 3, "correction_slope_realizations": 2},
                        "set one of them to 0")):
        with pytest.raises(ValueError, match=match):
            _spec(SU, {"profile": bad})
