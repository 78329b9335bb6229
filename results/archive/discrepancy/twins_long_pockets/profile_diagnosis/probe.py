"""The compliance twin's profile near its fit: real runs against the workflow's emulator.

Runs the twin `compliant_boundary_long_pockets` of campaigns/discrepancy/discrepancy_twins_long_pockets.toml up to its
profile stage (every earlier run comes from CACHE), then
  * on real runs: the profile's reference (the fit's own point under the correction re-estimated there) and
    Delta chi2 at compliance 0.009917 mm/kPa (E refitted, the correction re-estimated at the point);
  * on the workflow's emulator, as the workflow's profile runs: the reference and Delta chi2 at 0.009917 and
    0.010057 mm/kPa;
  * on the workflow's emulator: at the fit and at compliance 0.009917, 0.010057, 0.009811 (E at the fit), the
    whitened squared size of (real coarse run - emulator mean) on the profile's rows, and the data's chi2
    against each.
Units: compliance mm/kPa, E kPa, chi2 dimensionless.

    python probe.py CAMPAIGN CACHE OUT.json [--real-points 0.009917]
"""
from __future__ import annotations

import argparse
import json
import logging

import numpy as np

import sweep.discrepancy.workflow as W
from sweep.discrepancy import twins as T
from sweep.discrepancy.profile import _Profile
from sweep.campaign.store import write_json_atomic

TWIN = "compliant_boundary_long_pockets"


class _AtProfile(Exception):
    """Raised in place of the profile stage, carrying its arguments."""


def state_at_profile(campaign: str, cache: str, scratch: str, twin: str = TWIN) -> dict:
    """The workflow's problem, fit, parameter index, training ids, fine models and emulator at the profile of
    the campaign's twin ``twin``."""
    cap = {}

    def stop(problem, fit, j, ids, max_passes=2, fine_forward=None, emulator=None):
        cap.update(problem=problem, fit=fit, j=j, ids=ids, fine=fine_forward, em=emulator)
        raise _AtProfile

    W.profile_recentred = stop
    setup = T._prepare_campaign(campaign, scratch, cache, 2)
    try:
        T._run_one_twin(setup, next(t for t in setup.camp["twin"] if t["name"] == twin))
    except _AtProfile:
        return cap
    raise RuntimeError("the twin ended before its profile stage")


def profile_points(st: dict, values, emulator: bool) -> dict:
    """Reference and Delta chi2 points of the profile on real runs, or on the workflow's emulator (as the
    workflow's profile runs)."""
    pf = _Profile(st["problem"], st["fit"], st["j"], st["ids"], 3.841, st["fine"], st["em"] if emulator else None)
    out = {"chi2_fit": float(pf.chi2_fit), "chi2_reference": float(pf.chi2_hat), "threshold": float(pf.thr),
           "points": []}
    for v in values:
        pf.dchi2(pf.p.to_x(v))
        out["points"].append({k: (float(x) if isinstance(x, (float, np.floating)) else x)
                              for k, x in pf.points[-1].items()})
    return out


def emulator_gap(st: dict, values) -> list:
    """At the fit and at (E_hat, c) for c in values: |real coarse - emulator mean|^2 whitened, and chi2s."""
    prob, fit, j, em = st["problem"], st["fit"], st["j"], st["em"]
    mask, x_hat, rows = prob.mask(st["ids"]), np.asarray(fit.x, float), []
    for c in (None, *values):
        x = x_hat.copy()
        if c is not None:
            x[j] = fit.params[j].to_x(c)
        m, (mean, _) = em.model_vectors([x])[0], em.predict(x)
        size = [prob.standardize(a, mask, 0.0) for a in (m - mean, prob.y[mask] - m, prob.y[mask] - mean)]
        rows.append({"compliance": float(fit.params[j].from_x(x[j])), "real_minus_emulator": float(size[0] @ size[0]),
                     "chi2_real_run": float(size[1] @ size[1]), "chi2_emulator_mean": float(size[2] @ size[2]),
                     "emulator_sd_norm": float(em.sd_norm(x))})
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("campaign")
    ap.add_argument("cache")
    ap.add_argument("out")
    ap.add_argument("--scratch", default="probe_scratch")
    ap.add_argument("--real-points", type=float, nargs="*", default=[0.009917])
    ap.add_argument("--emulated-points", type=float, nargs="*", default=[0.009917, 0.010057])
    a = ap.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    st = state_at_profile(a.campaign, a.cache, a.scratch)
    out = {"fit": {k: float(v) for k, v in st["fit"].values().items()},
           "emulator": emulator_gap(st, (0.009917, 0.010057, 0.009811)),
           "real": profile_points(st, a.real_points, emulator=False),
           "emulated": profile_points(st, a.emulated_points, emulator=True)}
    write_json_atomic(a.out, out)
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
