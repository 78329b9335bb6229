"""Coverage of the named strength's 95 % profile-likelihood interval, on twins of the toy with mesh
realizations (:class:`~.toy.MeshToy`): how often the interval holds the hidden strength, and why it misses.

Each draw is a twin: data from one fine mesh realization (h = 2 mm, a realization the workflow never sees)
with a hidden effect of random strength and a randomly displaced calibrated parameter, plus Gaussian
measurement noise; the workflow runs on the coarse model (h = 4 mm) with k other fine realizations as its
discretization check.  The interval comes from the workflow's own stages (workflow.prepare, calibrate,
search, finalize: the same problem, noise and profile code the solver twins use), with the set-up's
effect as the only candidate.  Beside the interval each draw records the profile's Δχ² at the truth (the
likelihood-ratio statistic; the exact profile set holds the truth when it is below the threshold) so a miss
can be told apart from the profile's numerics.  Units: mm, s, kPa.

    python -m sweep.discrepancy.coverage --draws 100 --out results/discrepancy/coverage/default.json
"""
from __future__ import annotations

import argparse
import math
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from solver.effects import get_effect

from .data import load_measured
from .profile import _Profile
from .spec import spec_from_dict
from .toy import MeshToy
from .twin import make_twin
from .workflow import calibrate, finalize, prepare, search

__all__ = ["SetUp", "SETUPS", "Variant", "VARIANTS", "one_draw", "wilson", "summarize", "run_study", "combine"]

TIMES = np.linspace(0.02, 0.3, 15)
LONG_TIMES = np.linspace(0.05, 1.5, 30)
NOISE = {"p_inj": 2.0, "front_radius_mean": 0.2}
OFF = ("damage_viscosity", "volumetric_coupling")
CAL_BOUNDS = {"E": (150.0, 700.0), "kbar": (5e-4, 5e-3), "K_s": (500.0, 6000.0)}
NOMINAL = {"E": 331.0, "kbar": 0.0015, "K_s": 1600.0}


@dataclass(frozen=True)
class SetUp:
    """One twin set-up: the calibrated parameter, the condition axis and its four values (the last held
    out), the hidden effect and the range its strength is drawn from (uniform, the effect's unit)."""

    name: str
    calibrate: str
    axis: str
    values: tuple
    effect: str
    strength: tuple
    whole_injection: bool = False     # to 1.5 s with the crack length observed (MeshToy cracks=True)

    @property
    def times(self) -> np.ndarray:
        """Observation times, s: 15 in [0.02, 0.3] s, or 30 in [0.05, 1.5] s over the whole injection."""
        return LONG_TIMES if self.whole_injection else TIMES

    @property
    def noise(self) -> dict:
        """Measurement noise per observable (kPa, mm)."""
        return {**NOISE, "crack_length": 0.2} if self.whole_injection else NOISE

    def conditions(self) -> dict:
        """{id: {axis: value}} of the four conditions (ids c0..c3; c3 held out)."""
        return {f"c{i}": {self.axis: float(v)} for i, v in enumerate(self.values)}


RATE, CEMENT, ETA = (30.0, 50.0, 70.0, 40.0), (0.6, 1.2, 2.4, 1.8), (0.15, 0.29, 0.6, 0.4)
ETA_LONG = (0.10, 0.29, 0.45, 0.19)     # the second outside twin's oil viscosities, the middle one held out
BETA, COUPLING = (20.0, 80.0), (0.3, 1.5)
SETUPS = (
    SetUp("E_rate_beta", "E", "w_i", RATE, "damage_viscosity", BETA),
    SetUp("kbar_cement_beta", "kbar", "cement", CEMENT, "damage_viscosity", BETA),
    SetUp("Ks_eta_beta", "K_s", "eta_o", ETA, "damage_viscosity", BETA),
    SetUp("kbar_rate_coupling", "kbar", "w_i", RATE, "volumetric_coupling", COUPLING),
    SetUp("E_cement_coupling", "E", "cement", CEMENT, "volumetric_coupling", COUPLING),
    SetUp("Ks_rate_coupling", "K_s", "w_i", RATE, "volumetric_coupling", COUPLING),
    SetUp("E_eta_beta_long", "E", "eta_o", ETA_LONG, "damage_viscosity", BETA, whole_injection=True),
)


@dataclass(frozen=True)
class Variant:
    """How a study's twins and workflow differ from the default: ``k`` fine realizations, their
    deviation's ``spread`` and the discretization ``bias`` (MeshToy), and option tables of the SPEC."""

    name: str
    k: int = 3
    spread: float = 1.0
    bias: float = 1.0
    tables: dict = field(default_factory=dict)
    shape: str = "smooth"

    def toy(self, h: float, realization: int, cracks: bool = False) -> MeshToy:
        """The variant's MeshToy on mesh size ``h`` (mm), mesh realization ``realization`` (``cracks``: the
        whole injection)."""
        return MeshToy(h, realization, self.spread, self.bias, self.shape, cracks=cracks)


_REMEDY = {"noise": {"disc_error_fraction": 0.0}, "profile": {"likelihood": "gaussian"}}
VARIANTS = {v.name: v for v in (
    Variant("default"),
    Variant("no_fraction", tables={"noise": {"disc_error_fraction": 0.0}}),
    Variant("fit_correction", tables={"profile": {"fine": False}}),
    Variant("remedy", tables=_REMEDY),
    Variant("remedy_marginal", tables={**_REMEDY, "profile": {"likelihood": "marginal"}}),
    Variant("remedy_fit_correction", tables={**_REMEDY, "profile": {"likelihood": "gaussian", "fine": False}}),
    Variant("remedy_k30", k=30, tables=_REMEDY),
    Variant("remedy_no_spread", spread=0.0, tables=_REMEDY),
    Variant("remedy_no_spread_refresh8", spread=0.0,
            tables={**_REMEDY, "noise": {"disc_error_fraction": 0.0, "disc_refresh": 8}}),
    Variant("remedy_spread3", spread=3.0, tables=_REMEDY),
    Variant("wander_default", shape="wander"),
    Variant("wander_remedy", shape="wander", tables=_REMEDY),
    Variant("wander_remedy_marginal", shape="wander", tables={**_REMEDY, "profile": {"likelihood": "marginal"}}),
    Variant("wander_remedy_marginal_emulator", shape="wander",
            tables={**_REMEDY, "profile": {"likelihood": "marginal", "emulator": "gp"}}),
    Variant("wander_remedy_marginal_emulator_refits", shape="wander",
            tables={**_REMEDY, "profile": {"likelihood": "marginal", "emulator": "gp", "emulate_refits": True}}),
    Variant("wander_remedy_marginal_fit_correction", shape="wander",
            tables={**_REMEDY, "profile": {"likelihood": "marginal", "fine": False}}),
    Variant("wander_remedy_marginal_fit_correction_emulator_refits", shape="wander",
            tables={**_REMEDY, "profile": {"likelihood": "marginal", "fine": False, "emulator": "gp",
                                           "emulate_refits": True}}),
    Variant("wander_remedy_k30", shape="wander", k=30, tables=_REMEDY),
    Variant("wander_crn_marginal", shape="wander", k=6,
            tables={**_REMEDY, "profile": {"likelihood": "marginal", "correction": "linear"}}),
    Variant("wander_point_marginal_k6", shape="wander", k=6, tables={**_REMEDY, "profile": {"likelihood": "marginal"}}),
    Variant("wander_remedy_marginal_f", shape="wander",
            tables={**_REMEDY, "profile": {"likelihood": "marginal", "threshold": "f_welch"}}),
    Variant("wander_crn_marginal_emulator_refits", shape="wander", k=6,
            tables={**_REMEDY, "profile": {"likelihood": "marginal", "correction": "linear", "emulator": "gp",
                                           "emulate_refits": True}}),
    Variant("wander_crn_marginal_emulator_refits_no_refresh_2anchors", shape="wander", k=6,
            tables={"noise": {"disc_error_fraction": 0.0, "disc_refresh": 0},
                    "profile": {"likelihood": "marginal", "correction": "linear", "correction_anchors": 2,
                                "emulator": "gp", "emulate_refits": True}}),
    Variant("wander_point_marginal_k6_emulator_refits", shape="wander", k=6,
            tables={**_REMEDY, "profile": {"likelihood": "marginal", "emulator": "gp", "emulate_refits": True}}),
    Variant("wander_fit_correction_marginal_k6", shape="wander", k=6,
            tables={**_REMEDY, "profile": {"likelihood": "marginal", "fine": False}}),
    Variant("wander_marginal_refresh8", shape="wander",
            tables={"noise": {"disc_error_fraction": 0.0, "disc_refresh": 8}, "profile": {"likelihood": "marginal"}}),
    Variant("wander_fit_correction", shape="wander", tables={"profile": {"fine": False}}),
    Variant("strong_bias", bias=4.0),
    Variant("strong_bias_fit_correction", bias=4.0, tables={"profile": {"fine": False}}),
    Variant("strong_bias_remedy", bias=4.0, tables=_REMEDY),
    Variant("emulator", tables={"profile": {"emulator": "gp"}}),
    Variant("emulator_fit_correction", tables={"profile": {"fine": False, "emulator": "gp"}}),
    Variant("emulator_refits", tables={"profile": {"emulator": "gp", "emulate_refits": True}}),
    Variant("emulator_refits_fit_correction",
            tables={"profile": {"fine": False, "emulator": "gp", "emulate_refits": True}}),
    Variant("emulator_refits_polish1_fit_correction",
            tables={"profile": {"fine": False, "emulator": "gp", "emulate_refits": True, "emulator_polish": 1}}),
)}


def _spec(su: SetUp, tables: dict):
    lo, hi = CAL_BOUNDS[su.calibrate]
    return spec_from_dict({"baseline": {"effects_off": list(OFF)},
                           "calibrate": [{"name": su.calibrate, "lower": lo, "upper": hi}],
                           "candidates": {"effects": [su.effect], "upper": {"volumetric_coupling": 3.0}},
                           "holdout": {"ids": ["c3"]},
                           "options": {"h": 4.0, "t_end": float(su.times[-1])}, **tables})


def _truth(su: SetUp, draw: int, seed: int) -> tuple[float, float]:
    """(hidden strength, true calibrated value) of draw ``draw``."""
    rng = np.random.default_rng([seed, draw, 7])
    s = float(rng.uniform(*su.strength))
    return s, NOMINAL[su.calibrate] * float(np.exp(rng.uniform(-0.2, 0.2)))


def one_draw(su: SetUp, draw: int, variant: Variant = VARIANTS["default"], seed: int = 0) -> dict:
    """One twin of set-up ``su``: the workflow's verdict, the named strength, its interval and the profile's
    Δχ² at the truth with the threshold (strength in the effect's unit)."""
    truth, cal = _truth(su, draw, seed)
    e = get_effect(su.effect)
    hidden = {get_effect(o).parameter: get_effect(o).off for o in OFF}
    hidden.update({e.parameter: truth, su.calibrate: cal})
    base = 1000 * (seed * 10007 + draw + 1)            # mesh realizations of this draw: data, then the checks
    cr = su.whole_injection
    fines = [variant.toy(2.0, base + 1 + i, cr) for i in range(variant.k)]
    with tempfile.TemporaryDirectory() as tmp:
        data = load_measured(make_twin(Path(tmp) / "d", variant.toy(2.0, base, cr),
                                       su.conditions(), su.times, hidden, noise=su.noise, seed=base,
                                       observables=tuple(su.noise), regime=False))
    run = prepare(data, _spec(su, variant.tables), variant.toy(4.0, 0, cr), fines)
    calibrate(run)
    search(run)
    row = {"setup": su.name, "draw": draw, "truth": truth, "cal_truth": cal, "named": bool(run.accepted)}
    if not run.accepted:
        return {**row, "verdict": run.verdict, "runs_by_stage": run.ledger.stages}
    finalize(run)
    row["runs_by_stage"] = run.ledger.stages
    if run.emulated is not None:
        recs = run.emulated.records
        row["emulated_refits"] = {"refits": len(recs), "confirmed": sum(r["confirmed"] for r in recs),
                                  "checks": sum(len(r["checks"]) for r in recs),
                                  "max_polish_move_over_error": max((r["polish_move_over_error"] for r in recs),
                                                                    default=0.0)}
    a = run.accepted[0]
    fit = run.current
    names = [p.name for p in fit.params]
    j = names.index("effect:" + su.effect)
    row.update({"verdict": run.verdict, "strength": a["strength"], "lower": a["strength_interval"][0],
                "upper": a["strength_interval"][1], "cal_fit": fit.values()[su.calibrate],
                "corr": _correlation(fit.J, j)})
    row["covered"] = bool(row["lower"] <= truth <= row["upper"])
    em = run.profiles[su.effect].get("emulator")
    if em:
        row["profile_emulator"] = {k: em[k] for k in ("design_points", "forward_runs", "refinements", "confirmed")}
    pf = _Profile(run.problem, fit, j, run.train, 3.841, run.fine if run.spec.profile.fine else None,
                  correction=run.correction_models.get(su.effect))
    row.update({"dchi2_truth": pf.dchi2(fit.params[j].to_x(truth)), "threshold": pf.thr,
                "dchi2_truth_others_fixed": _dchi2_others_fixed(pf, truth)})
    if run.spec.profile.threshold != "chi2":
        row["threshold_dof"] = pf.dof
    return row


def _dchi2_others_fixed(pf: _Profile, value: float) -> float:
    """Δχ² of the strength at ``value`` with the calibrated parameters held at the fit instead of profiled
    (the correction re-estimated there when the profile does so): the interval that ignores their
    correlation with the strength holds the truth when this is below the threshold."""
    from .noise import correction_at

    problem, others = pf.problem, np.delete(pf.x_hat, pf.j)
    problem.fixed = {pf.p.name: value}
    old = None
    vals = {**{q.name: q.from_x(x) for q, x in zip(pf.free, others)}, pf.p.name: value}
    try:
        if pf.cm is not None:
            old = problem.noise.shift_correction(pf.cm(vals))
        elif pf.fines:
            old = problem.noise.shift_correction(correction_at(problem, pf.fines, vals))
        r = problem.residual_batch(pf.free, [others], pf.ids)[0]
    finally:
        if old is not None:
            problem.noise.shift_correction(old)
        problem.fixed = {}
    return float(pf.deviance(r) - pf.chi2_hat)


def _correlation(J: np.ndarray, j: int) -> float:
    """Largest |correlation| of parameter ``j`` with another from the Gauss–Newton covariance (JᵀJ)⁻¹."""
    cov = np.linalg.pinv(J.T @ J)
    d = np.sqrt(np.maximum(np.diag(cov), 1e-300))
    c = cov / np.outer(d, d)
    return float(max(abs(c[j, i]) for i in range(len(d)) if i != j)) if len(d) > 1 else 0.0


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion k/n (95 % for z = 1.96)."""
    if n == 0:
        return (0.0, 1.0)
    p = k / n
    c = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    m = (p + z * z / (2 * n)) / (1 + z * z / n)
    return (m - c, m + c)


def summarize(rows: list) -> dict:
    """Coverage of the intervals and of the likelihood-ratio set (Δχ² at truth < threshold) with Wilson
    intervals, the naming rate, and the misses split by side."""
    named = [r for r in rows if r.get("named") and "covered" in r]
    n = len(named)
    k = sum(r["covered"] for r in named)
    k_lr = sum(r["dchi2_truth"] < r["threshold"] for r in named)
    return {"draws": len(rows), "named": n, "covered": k, "coverage": k / n if n else None,
            "wilson95": wilson(k, n), "lr_covered": k_lr, "lr_coverage": k_lr / n if n else None,
            "lr_wilson95": wilson(k_lr, n),
            "miss_low": sum(r["upper"] < r["truth"] for r in named),
            "miss_high": sum(r["lower"] > r["truth"] for r in named),
            "median_dchi2_truth_over_thr": float(np.median([r["dchi2_truth"] / r["threshold"] * 3.841
                                                            for r in named])) if n else None}


def run_study(setups, draws: int, variant: Variant, seed: int = 0, log=None, first: int = 0) -> dict:
    """Every set-up's twins ``first`` .. ``first + draws − 1`` under ``variant``: {"rows": [...],
    "by_setup": {name: summary}, "pooled": summary}."""
    rows = []
    for su in setups:
        for d in range(first, first + draws):
            rows.append(one_draw(su, d, variant, seed))
            if log:
                log(rows[-1])
    by = {su.name: summarize([r for r in rows if r["setup"] == su.name]) for su in setups}
    return {"variant": variant.name, "tables": variant.tables, "k": variant.k, "spread": variant.spread,
            "bias": variant.bias, "shape": variant.shape, "seed": seed, "rows": rows, "by_setup": by, "pooled": summarize(rows)}


def combine(studies: list) -> dict:
    """One study from several of one variant (other draws of the same set-ups), summaries recomputed."""
    if len({s["variant"] for s in studies}) != 1:
        raise ValueError(f"combine: studies of different variants {sorted({s['variant'] for s in studies})}")
    rows = [r for s in studies for r in s["rows"]]
    keys = [(r["setup"], r["draw"]) for r in rows]
    if len(set(keys)) != len(keys):
        raise ValueError("combine: a draw occurs twice")
    names = list(dict.fromkeys(r["setup"] for r in rows))
    by = {n: summarize([r for r in rows if r["setup"] == n]) for n in names}
    return {**{k: v for k, v in studies[0].items() if k not in ("rows", "by_setup", "pooled")},
            "rows": rows, "by_setup": by, "pooled": summarize(rows)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sweep.discrepancy.coverage", description=__doc__.split("\n\n")[0])
    ap.add_argument("--draws", type=int, default=50)
    ap.add_argument("--variant", default="default", choices=sorted(VARIANTS))
    ap.add_argument("--setups", default=",".join(s.name for s in SETUPS))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--first", type=int, default=0, help="index of the first draw")
    ap.add_argument("--out", required=True)
    ap.add_argument("--combine", nargs="+", metavar="JSON", help="merge these studies of one variant instead")
    a = ap.parse_args(argv)
    import json

    from sweep.campaign.store import write_json_atomic

    from .report import jsonable

    Path(a.out).parent.mkdir(parents=True, exist_ok=True)

    if a.combine:
        write_json_atomic(Path(a.out), combine([json.loads(Path(f).read_text()) for f in a.combine]))
        return 0
    known = {s.name: s for s in SETUPS}
    names = a.setups.split(",")
    bad = [n for n in names if n not in known]
    if bad or a.draws < 1 or a.first < 0:
        print(f"coverage: --setups {bad} unknown (allowed {sorted(known)}) or --draws={a.draws} < 1 or --first={a.first} < 0", file=sys.stderr)
        return 2
    res = run_study([known[n] for n in names], a.draws, VARIANTS[a.variant], a.seed, first=a.first,
                    log=lambda r: print(json.dumps(jsonable(r)), flush=True))
    write_json_atomic(Path(a.out), res)
    print({k: v["coverage"] for k, v in res["by_setup"].items()}, res["pooled"])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
