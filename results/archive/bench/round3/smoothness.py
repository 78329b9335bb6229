"""p_inj at t_end as a function of E (kPa) near Table A's value, for the two step controllers: roughness of the
curve (rms of the residual of a quadratic fit, relative) and of its finite-difference derivative.

    python results/archive/bench/round3/smoothness.py results/archive/bench/round3/smoothness_E_h6.json
"""
import json, sys, time
import numpy as np
from solver import Parameters, RunOptions, simulate

E0 = Parameters().E
Es = E0 * (1 + np.linspace(-0.02, 0.02, 17))
out = {}
for name, kw in {"iterations": dict(step_control="iterations", anderson_depth=0, newton_mass_tol=0.01),
                 "state_change": {}}.items():
    p = []
    for E in Es:
        r = simulate(Parameters(E=float(E)), RunOptions(h=6.0, t_end=0.3, snapshot_times=[], write_xdmf=False, **kw))
        p.append(float(r.timeseries.p_inj.iloc[-1]))
    p = np.array(p)
    x = (Es - E0) / E0
    fit = np.polyval(np.polyfit(x, p, 2), x)
    dp = np.diff(p) / np.diff(Es)
    out[name] = {"E": Es.tolist(), "p_inj": p.tolist(),
                 "quadratic_residual_rms_rel": float(np.sqrt(np.mean((p - fit) ** 2)) / np.mean(p)),
                 "fd_slope_kPa_per_kPa": dp.tolist(),
                 "fd_slope_cv": float(np.std(dp) / abs(np.mean(dp)))}
    print(name, out[name]["quadratic_residual_rms_rel"], out[name]["fd_slope_cv"], flush=True)
json.dump(out, open(sys.argv[1], "w"), indent=1)
