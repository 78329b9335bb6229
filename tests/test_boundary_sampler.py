"""The boundary sampler on known answers: synthetic oracles replace the solver (no solver run).

* An exponential separatrix Ca*_c = A exp(B C) (porous invasion / fracturing) over (C, eta_o), Ca*
  from sweep.regimes.numbers as in a campaign table; sharp, and with a fuzzy transition (labels drawn from a
  logistic of width W_FUZZY decades about the separatrix).
* A 3-regime map over two log axes whose regions are the argmax of three quadratics (curved
  boundaries and a triple point).

Claims checked over 20 seeds each: the boundary is located within the tolerance (Hausdorff distance per
pair of labels between the true and the fitted boundaries, in tolerance units, <= 1), with at most half
the runs of the grid that reaches the same tolerance (spacing 2 x tolerance on every axis: a boundary
between two neighbours of different labels is then within one tolerance of their midpoint); and, on the
separatrix, sharp and fuzzy, the 95 % profile intervals of A and B
(sweep.regimes.separatrix.separatrix_profile_interval) cover the truth in >= 90 % of seeds.

Seed counts of the coverage claim, from the binomial law of the number of seeds covered: with the
sharp separatrix the intervals bound the separating separatrices and are conservative, 20 seeds and
>= 18 covered. With fuzzy labels the intervals are likelihood intervals whose coverage is the stated
95 %; 40 seeds and >= 36 covered (90 %): a method at 95 % fails this with probability 0.05, one at
80 % passes it with probability 0.08 (with 20 seeds and >= 18: 0.08 and 0.21).
"""
from __future__ import annotations

import math
import re

import numpy as np
import pandas as pd
import pytest
from scipy.spatial import cKDTree

from sweep.campaign.boundary import BoundarySampler
from sweep.campaign.table import _numbers
from sweep.regimes.separatrix import separatrix_profile_interval
from sweep.regimes.regime_model import unit_grid
from sweep.campaign.spec import SpecError, spec_from_dict

SEEDS = range(20)
A_TRUE, B_TRUE = 1.0e6, 1.2          # Ca*_c = A exp(B C), C in %
W_FUZZY = 0.05                       # decades of Ca*: width of the fuzzy transition
CA_AXES = {"cement": {"linear": [0.5, 3.0, 3]}, "eta_o": {"log": [1e-3, 1.0, 3]}}
MAP_AXES = {"eta_o": {"log": [1e-4, 1.0, 3]}, "kbar": {"log": [1e-4, 1e-1, 3]}}


def _spec(axes, **sampler):
    d = {"name": "boundary_test", "base": {"eta_w": 1e-6, "kbar": 0.0015}, "options": {"h": 4.0},
         "axes": axes, "sampler": {"kind": "boundary", **sampler}}
    if "kbar" in axes:
        d["base"] = {"eta_w": 1e-6}
    return spec_from_dict(d)


# ------------------------------------------------------------------------------------ oracles
def _log_ca_star(params) -> float:
    return math.log10(_numbers(params)["Ca_star"])


def _log_ca_c(C):
    return np.log10(A_TRUE * np.exp(B_TRUE * np.asarray(C, float)))


def separatrix_sharp(params, seed=0):
    return "fracturing" if _log_ca_star(params) > _log_ca_c(params["cement"]) else "porous_invasion"


def separatrix_fuzzy(params, seed=0):
    """Fracturing with probability expit((log10 Ca* - log10 Ca*_c) / W_FUZZY); one draw per point and seed."""
    z = (_log_ca_star(params) - _log_ca_c(params["cement"])) / W_FUZZY
    key = [seed, int(round(params["cement"] * 1e6)), int(round(math.log10(params["eta_o"]) * 1e6)) % 2**31]
    u = np.random.default_rng(key).uniform()
    return "fracturing" if u < 1.0 / (1.0 + math.exp(-z)) else "porous_invasion"


MAP_LABELS = ("uniform_invasion", "viscous_fingering", "invasive_fracturing")


def _map_scores(x, y):
    """x = log10 eta_o in [-4, 0], y = log10 kbar in [-4, -1]: three quadratics, the regime is their argmax."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    return np.stack([np.zeros_like(x), 4.0 * (y + 2.2 - 0.4 * (x + 2.0) - 0.15 * (x + 2.0) ** 2),
                     4.0 * (x + 2.5 - 0.5 * (y + 2.5) ** 2 + 0.3 * y)], axis=-1)


def three_regimes(params, seed=0):
    return MAP_LABELS[int(np.argmax(_map_scores(math.log10(params["eta_o"]), math.log10(params["kbar"]))))]


# ------------------------------------------------------------------------------------ driver
def drive(spec, oracle, seed=0):
    """initial / refine with the oracle in place of the solver (the table holds what a campaign's does)."""
    s = BoundarySampler()
    pts, rows = s.initial(spec), []
    while pts:
        for p in pts:
            rows.append({"status": "ok", **p.swept, "regime": oracle(p.params, seed)})
        pts = s.refine(spec, pd.DataFrame(rows))
    table = pd.DataFrame(rows)
    return s.replay(spec, table), table


def _boundary_pixels(labels: np.ndarray, T: np.ndarray) -> dict:
    """{(label a, label b): tolerance coordinates of grid points with a neighbour labelled otherwise}."""
    out: dict = {}
    for ax in (0, 1):
        a = np.swapaxes(labels, 0, ax)
        t = np.swapaxes(T, 0, ax)
        m = a[1:] != a[:-1]
        for la, lb, p in zip(a[1:][m], a[:-1][m], 0.5 * (t[1:][m] + t[:-1][m])):
            out.setdefault(tuple(sorted((la, lb))), []).append(p)
    return {k: np.array(v) for k, v in out.items()}


def boundary_error(model, truth_fn, n=300) -> float:
    """Largest Hausdorff distance (tolerance units) between the true and fitted boundaries, pair by pair
    (a pair on one side only counts as infinite)."""
    U = unit_grid(2, n)
    X = np.stack([a.from_u(U[:, j]) for j, a in enumerate(model.axes)], axis=1)
    T = (U * np.array([a.tol_per_u for a in model.axes])).reshape(n, n, 2)
    est = np.array(model.labels, dtype=object)[np.argmax(model.proba(X), axis=1)].reshape(n, n)
    true = np.asarray(truth_fn(X), dtype=object).reshape(n, n)
    bt, be = _boundary_pixels(true, T), _boundary_pixels(est, T)
    if set(bt) != set(be):
        return math.inf
    worst = 0.0
    for k in bt:
        d1 = cKDTree(be[k]).query(bt[k])[0].max()
        d2 = cKDTree(bt[k]).query(be[k])[0].max()
        worst = max(worst, d1, d2)
    return float(worst)


def grid_runs_for_tolerance(spec) -> int:
    """Runs of the regular grid with spacing 2 x tolerance on every axis (the grid reaching the tolerance)."""
    n = 1
    for a in BoundarySampler()._config(spec).axes:
        n *= math.ceil((a.t_hi - a.t_lo) / (2.0 * a.tolerance)) + 1
    return n


def _sep_truth(X):
    log_ca = np.log10(X[:, 1] * _CA_PER_ETA_O[0])           # Ca* is proportional to eta_o in this campaign
    return np.where(log_ca > _log_ca_c(X[:, 0]), "fracturing", "porous_invasion")


def _map_truth(X):
    return np.array(MAP_LABELS, dtype=object)[np.argmax(_map_scores(np.log10(X[:, 0]), np.log10(X[:, 1])), axis=1)]


_BASE_PARAMS: dict = {}
_CA_PER_ETA_O = [math.nan]


@pytest.fixture(scope="module", autouse=True)
def _base_params():
    s = BoundarySampler()
    spec = _spec(CA_AXES, budget=60, tolerance=0.1)
    _BASE_PARAMS.update(s.initial(spec)[0].params)
    _CA_PER_ETA_O[0] = _numbers(_BASE_PARAMS)["Ca_star"] / _BASE_PARAMS["eta_o"]


# ------------------------------------------------------------------------------------ claims
@pytest.mark.parametrize("case", ["separatrix", "three_regimes"])
def test_locates_the_boundary_within_tolerance_with_half_the_grid_runs(case):
    axes, oracle, truth, tol = ((CA_AXES, separatrix_sharp, _sep_truth, {"cement": 0.1, "eta_o": 0.1})
                                if case == "separatrix" else (MAP_AXES, three_regimes, _map_truth, 0.1))
    runs, errors, reasons = [], [], []
    for seed in SEEDS:
        spec = _spec(axes, budget=150, tolerance=tol, seed=seed, batch=4)
        st, _ = drive(spec, oracle, seed)
        runs.append(st.runs_used)
        errors.append(boundary_error(st.model, truth))
        reasons.append(st.reason.split(":")[0])
    grid = grid_runs_for_tolerance(spec)
    print(f"{case}: runs {min(runs)}-{max(runs)} (median {np.median(runs):.0f}) against {grid} for the grid; "
          f"errors (tolerance units) max {max(errors):.2f}, median {np.median(errors):.2f}; stops {set(reasons)}")
    assert all(r == "converged" for r in reasons)
    assert max(errors) <= 1.0
    assert max(runs) <= grid / 2


def separatrix_coverage(oracle, seeds=SEEDS, tolerance=0.1):
    """Runs, and how many seeds' 95 % profile intervals of A and B hold the truth, sampling ``oracle``."""
    cover_a = cover_b = 0
    runs, widths = [], []
    for seed in seeds:
        spec = _spec(CA_AXES, budget=300, tolerance=tolerance, seed=seed, batch=4, degree=2)
        st, table = drive(spec, oracle, seed)
        runs.append(st.runs_used)
        ca = table["eta_o"].to_numpy() * _CA_PER_ETA_O[0]
        sep = separatrix_profile_interval(table["cement"], ca, table["regime"] == "fracturing", level=0.95)
        cover_a += sep.A_interval[0] <= A_TRUE <= sep.A_interval[1]
        cover_b += sep.B_interval[0] <= B_TRUE <= sep.B_interval[1]
        widths.append(sep.B_interval[1] - sep.B_interval[0])
    return runs, cover_a, cover_b, widths


@pytest.mark.parametrize("oracle, n_seeds", [(separatrix_sharp, 20), (separatrix_fuzzy, 40)])
def test_separatrix_A_B_intervals_cover_the_truth(oracle, n_seeds):
    runs, cover_a, cover_b, widths = separatrix_coverage(oracle, seeds=range(n_seeds))
    print(f"{oracle.__name__}: runs {min(runs)}-{max(runs)} (median {np.median(runs):.0f}); 95 % intervals cover "
          f"A in {cover_a}/{n_seeds}, B in {cover_b}/{n_seeds}; B interval width median {np.median(widths):.3f} /%"
          f" (truth {B_TRUE})")
    assert cover_a >= 0.9 * n_seeds and cover_b >= 0.9 * n_seeds
    assert np.median(widths) < 0.5 * B_TRUE       # an interval, not the whole axis


def test_separatrix_fit_stays_finite_on_separable_labels():
    """Labels split exactly by the true separatrix: the Jeffreys-penalized sharpness is finite, the labels are
    flagged separable, and the intervals are finite and hold the truth."""
    C, L = np.meshgrid(np.linspace(0.5, 3.0, 8), np.linspace(12.0, 18.0, 8))
    ca = np.exp(L.ravel()) * np.exp(0.013 * np.arange(64) % 0.05)              # off the grid's symmetry
    sep = separatrix_profile_interval(C.ravel(), ca, ca > A_TRUE * np.exp(B_TRUE * C.ravel()))
    assert sep.separable and math.isfinite(sep.sharpness) and sep.sharpness > 0
    assert sep.A_interval[0] <= A_TRUE <= sep.A_interval[1] and sep.B_interval[0] <= B_TRUE <= sep.B_interval[1]


@pytest.mark.parametrize("beta", [4.0, 16.0])
def test_classifier_prior_scale_follows_the_transition_width(beta):
    """Type-II maximum likelihood of the prior scale sigma: with 2000 labels drawn from P = expit(beta u) the
    slope's direction w_b - w_a (prior sd sigma sqrt 2) is beta, so the evidence peaks at sigma = beta / sqrt 2,
    and the factor-2 grid holds a point in [beta / 2, beta]; a step picks the largest sigma (the sharpest)."""
    from sweep.regimes.regime_model import AxisScale, fit_regime_model

    axes = (AxisScale("x", 0.0, 1.0, False, 0.01),)
    rng = np.random.default_rng(0)
    u = rng.uniform(-1.0, 1.0, 2000)
    fuzzy = np.where(rng.uniform(size=u.size) < 1.0 / (1.0 + np.exp(-beta * u)), "b", "a")
    model = fit_regime_model(((u + 1) / 2)[:, None], fuzzy, axes, degree=1, prior_sd=128.0, prior_span=64)
    assert beta / 2 <= model.prior_sd <= beta
    assert math.isclose(sum(m[0] for m in model.mixture), 1.0)
    step = fit_regime_model(((u + 1) / 2)[:, None], np.where(u > 0.1, "b", "a"), axes, degree=1, prior_sd=128.0,
                            prior_span=64)
    assert step.prior_sd == 128.0


# ------------------------------------------------------------------------------------ as a campaign
_INTERRUPT_AFTER = [None]


def separatrix_runner(params, options, run_dir):
    """Campaign runner with the sharp separatrix as the regime (Ctrl-C after _INTERRUPT_AFTER runs)."""
    if _INTERRUPT_AFTER[0] is not None:
        if _INTERRUPT_AFTER[0] == 0:
            raise KeyboardInterrupt
        _INTERRUPT_AFTER[0] -= 1
    return {"status": "ok", "regime": separatrix_sharp(params)}


def _campaign_spec(source="<dict>"):
    return spec_from_dict({"name": "bnd", "base": {"eta_w": 1e-6, "kbar": 0.0015}, "options": {"h": 4.0},
                           "axes": CA_AXES, "run": {"isolate": "none"},
                           "sampler": {"kind": "boundary", "budget": 40, "tolerance": 0.2, "seed": 3, "batch": 3}},
                          source=source)


def _coords(root):
    from sweep.campaign.store import ResultsStore

    return sorted((r["params"]["cement"], r["params"]["eta_o"]) for r in ResultsStore(root, "bnd").records().values())


def test_campaign_stores_resumes_after_ctrl_c_and_repeats_its_sequence(tmp_path):
    import json

    from sweep.campaign.run import run_campaign

    spec = _campaign_spec()
    full = run_campaign(spec, tmp_path / "full", runner=separatrix_runner, code_hash="t", progress=None)
    state = json.loads((tmp_path / "full" / "bnd" / "sampler.json").read_text())
    assert state["stopped"] and state["runs_used"] == full.n_executed == len(_coords(tmp_path / "full")) <= 40
    st, _ = drive(spec, separatrix_sharp)
    assert sorted(c for r in st.rounds for c in r) == _coords(tmp_path / "full")     # the sequence, stored
    from sweep.campaign.plot import _boundary_figure
    from sweep.campaign.table import build_table
    from sweep.campaign.store import ResultsStore

    figs, table = _boundary_figure(spec, ResultsStore(tmp_path / "full", "bnd"), build_table(spec, tmp_path / "full",
                                                                                              code_hash="t"))
    assert [f.name for f in figs] == ["boundary.png", "boundary.pdf"] and all(f.stat().st_size > 0 for f in figs)
    assert sorted(table["order"]) == list(range(full.n_executed))                  # every run numbered by order
    _INTERRUPT_AFTER[0] = 14
    try:
        with pytest.raises(KeyboardInterrupt):
            run_campaign(spec, tmp_path / "cut", runner=separatrix_runner, code_hash="t", progress=None)
    finally:
        _INTERRUPT_AFTER[0] = None
    assert len(_coords(tmp_path / "cut")) == 14
    import io

    log = io.StringIO()
    rest = run_campaign(spec, tmp_path / "cut", runner=separatrix_runner, code_hash="t", progress=log)
    assert rest.n_executed == full.n_executed - 14
    assert _coords(tmp_path / "cut") == _coords(tmp_path / "full")
    # the resumed campaign's log states the sampler's whole standing, not only this round's plan
    standing = [ln for ln in log.getvalue().splitlines() if "sampler: round" in ln]
    budget = state["budget"]
    assert standing and f"{full.n_executed} of {budget} runs used, 0 pending" in standing[-1]
    assert "stopped: " + state["reason"] in standing[-1]


def test_cli_status_shows_round_budget_and_uncertainty(tmp_path, capsys):
    from sweep.campaign.run import run_campaign
    from sweep.campaign.cli import main as cli_main

    path = tmp_path / "bnd.toml"
    path.write_text('name = "bnd"\n[base]\neta_w = 1e-6\nkbar = 0.0015\n[options]\nh = 4.0\n[axes]\n'
                    'cement = {linear = [0.5, 3.0, 3]}\neta_o = {log = [1e-3, 1.0, 3]}\n'
                    '[sampler]\nkind = "boundary"\nbudget = 40\ntolerance = 0.2\nseed = 3\nbatch = 3\n'
                    '[run]\nisolate = "none"\nrunner = "test_boundary_sampler:separatrix_runner"\n')
    run_campaign(_campaign_spec(str(path)), tmp_path, runner=separatrix_runner, progress=None)
    assert cli_main(["status", str(path), "--results", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "boundary sampler: round " in out and "/40 runs of the budget" in out and "x tolerance" in out
    assert "stopped: converged" in out
    # the accounting counts every run of the campaign folder, not only the initial design's
    used = re.search(r"round \d+, (\d+)/40 runs", out).group(1)
    assert f"throughput: {used} runs in" in out


@pytest.mark.parametrize("sampler, axes, key", [
    ({"budget": 5, "tolerance": 0.1}, CA_AXES, "sampler.budget"),
    ({"budget": 40, "tolerance": 0.0}, CA_AXES, "sampler.tolerance"),
    ({"budget": 40, "tolerance": {"cement": 0.1}}, CA_AXES, "sampler.tolerance"),
    ({"budget": 40, "tolerance": {"cement": 0.1, "eta_o": 0.1, "w_i": 1.0}}, CA_AXES, "sampler.tolerance.w_i"),
    ({"budget": 40, "tolerance": 0.1, "labels": ["fracturing"]}, CA_AXES, "sampler.labels"),
    ({"budget": 40, "tolerance": 0.1, "batch": 0}, CA_AXES, "sampler.batch"),
    ({"budget": 40, "tolerance": 0.1, "initial": "sobol"}, CA_AXES, "sampler.initial"),
    ({"budget": 40, "tolerance": 0.1, "budjet": 3}, CA_AXES, "sampler.budjet"),
    ({"budget": 40, "tolerance": 0.1, "prior_span": 0.5}, CA_AXES, "sampler.prior_span"),
    ({"budget": 40, "tolerance": 0.1, "fill_batch": "yes"}, CA_AXES, "sampler.fill_batch"),
    ({"tolerance": 0.1}, CA_AXES, "sampler.budget"),
    ({"budget": 40, "tolerance": 0.1}, {"cement": [0.5, 1.0, 2.0], "eta_o": {"log": [1e-3, 1.0, 3]}}, "axes.cement"),
    ({"budget": 8, "tolerance": 0.1, "initial": "grid"}, CA_AXES, "sampler.budget"),
])
def test_bad_settings_are_rejected_before_any_run_naming_the_key(sampler, axes, key):
    with pytest.raises(SpecError, match=key.replace(".", r"\.")):
        _spec(axes, **sampler)


def _round_sizes(fill: bool, seeds, batch: int = 2) -> list[list[int]]:
    """Points per round after the initial design (the last round left out: the budget may cut it)."""
    sizes = []
    for seed in seeds:
        spec = _spec(CA_AXES, budget=150, tolerance={"cement": 0.1, "eta_o": 0.1}, seed=seed, batch=batch,
                     fill_batch=fill)
        st, _ = drive(spec, separatrix_sharp, seed)
        sizes.append([len(r) for r in st.rounds[1:-1]])
    return sizes


def test_fill_batch_runs_full_rounds_where_one_band_covers_every_candidate():
    # without it the first rounds, whose band is wide, run one point and leave a core waiting; with it every
    # round runs the batch (the candidates never run out on this 2D domain at tolerance 0.1)
    short_off = sum(k < 2 for sizes in _round_sizes(False, range(4)) for k in sizes)
    on = _round_sizes(True, range(4))
    assert short_off >= 1
    assert all(k == 2 for sizes in on for k in sizes)


def test_nf_vs_nb_classifier_shading_recovers_a_known_map(tmp_path):
    """The smooth shading is the regime classifier fitted in the log plane: on runs from a known 3-regime map
    (a 6 x 6 grid) its most probable regime agrees with the map away from the boundaries."""
    from sweep.regimes.diagrams import plot_nf_vs_nb
    from sweep.regimes.regime_model import AxisScale, fit_regime_model

    lx, ly = np.meshgrid(np.linspace(-2, 4, 6), np.linspace(-3, 2, 6))
    lab = _map_truth(np.c_[10 ** (lx.ravel() / 1.5 - 2.0), 10 ** (ly.ravel() * 0.6 - 2.5)])
    df = pd.DataFrame({"N_b": 10 ** lx.ravel(), "N_f": 10 ** ly.ravel(), "regime": lab})
    out = plot_nf_vs_nb(df, tmp_path / "nfnb", formats=())
    assert out["paths"][0].stat().st_size > 0
    axes = (AxisScale("N_b", 10**-2.5, 10**4.5, True, 0.1), AxisScale("N_f", 10**-3.5, 10**2.5, True, 0.1))
    model = fit_regime_model(df[["N_b", "N_f"]].to_numpy(), lab, axes, degree=3, prior_sd=10.0)
    qx, qy = np.meshgrid(np.linspace(-2, 4, 40), np.linspace(-3, 2, 40))
    Q = np.c_[10 ** qx.ravel(), 10 ** qy.ravel()]
    truth = _map_truth(np.c_[10 ** (qx.ravel() / 1.5 - 2.0), 10 ** (qy.ravel() * 0.6 - 2.5)])
    got = np.array(model.labels, dtype=object)[np.argmax(model.proba(Q), axis=1)]
    assert np.mean(got == truth) > 0.9
    with pytest.raises(ValueError, match="shade"):
        plot_nf_vs_nb(df, tmp_path / "bad", shade="staircase", formats=())
