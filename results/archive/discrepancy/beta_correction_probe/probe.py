"""One-off probe (issue #53): how much the fine - coarse correction of the beta coverage twin's set-up changes
between the baseline's parameters (where the workflow takes it), the truth and the biased fit.

Conditions c06, c12, c24 (the training conditions of discrepancy_coverage_crn_kbar_cement.toml); coarse h = 4,
dt_max 0.02; fine h = 3, dt_max 0.01 on mesh_seeds 1 and 2 (two of the workflow's six realizations: common random
numbers, so the differences between parameter points are the parameters' own); 0.3 s; p_inj (kPa) and the mean
front (mm) at 15 times from 0.02 to 0.3 s.  Points: A baseline (beta 0, kbar 0.0015: the baseline's calibrated
kbar), T truth (beta 55, kbar 0.0013), F the biased fit (beta 36, kbar 0.00087), M (beta 36, kbar 0.0013: F's beta at
the true kbar) and K (beta 55, kbar 0.00087: F's kbar at the true beta).  Prints the correction's change
A -> T and A -> F in units of the noise sd (2 kPa, 0.2 mm), per condition and observable (rms over times), and
the χ² of the truth against fine data with the correction taken at A vs at T.
Run: python probe.py CACHE_DIR   (units mm, s, kPa)."""
import sys

import numpy as np

from solver import RunOptions
from sweep.discrepancy.forward import SolverForward

cache = sys.argv[1]
times = {"p_inj": np.linspace(0.02, 0.3, 15), "front_radius_mean": np.linspace(0.02, 0.3, 15)}
noise = {"p_inj": 2.0, "front_radius_mean": 0.2}
conds = {"c06": 0.6, "c12": 1.2, "c24": 2.4}
points = {"A": (0.0, 0.0015), "T": (55.0, 0.0013), "F": (36.0, 0.00087), "M": (36.0, 0.0013), "K": (55.0, 0.00087)}
base = {"outer_compliance": 0.0}
coarse = SolverForward(base, RunOptions(h=4.0, t_end=0.3, dt_max=0.02), cache)
fines = [SolverForward(base, RunOptions(h=3.0, t_end=0.3, dt_max=0.01, mesh_seed=s), cache) for s in (1, 2)]


def jobs():
    return [({"cement": c, "beta": b, "kbar": k}, times) for c in conds.values() for b, k in points.values()]


pc = coarse.predict_many(jobs())
pf = [f.predict_many(jobs()) for f in fines]
keys = [(cn, pn) for cn in conds for pn in points]
corr = {kp: {o: np.mean([pf[r][i][o] for r in range(2)], axis=0) - pc[i][o] for o in times}
        for i, kp in enumerate(keys)}
print("condition observable | rms change of the correction in noise sd: A->T, A->F, T->F | mean correction at A")
for cn in conds:
    for o in times:
        dT = (corr[(cn, "T")][o] - corr[(cn, "A")][o]) / noise[o]
        dF = (corr[(cn, "F")][o] - corr[(cn, "A")][o]) / noise[o]
        dTF = (corr[(cn, "F")][o] - corr[(cn, "T")][o]) / noise[o]
        print(f"{cn} {o:18s} | {np.sqrt(np.mean(dT**2)):7.2f} {np.sqrt(np.mean(dF**2)):7.2f} {np.sqrt(np.mean(dTF**2)):7.2f} | "
              f"{np.mean(corr[(cn, 'A')][o]):8.3f}")
# the truth's misfit to the realizations' mean fine prediction at T, with each correction (no noise): what a fit
# at the truth is charged for the correction being taken at A
chi_A = chi_T = 0.0
for i, (cn, pn) in enumerate(keys):
    if pn != "T":
        continue
    for o in times:
        fine_T = np.mean([pf[r][i][o] for r in range(2)], axis=0)
        chi_A += np.sum(((pc[i][o] + corr[(cn, "A")][o] - fine_T) / noise[o]) ** 2)
        chi_T += np.sum(((pc[i][o] + corr[(cn, "T")][o] - fine_T) / noise[o]) ** 2)
print(f"chi2 of the truth against the fine mean at the truth: correction at A {chi_A:.1f}, at T {chi_T:.1f}")
print("rms change of the correction T -> M (beta 55 -> 36 at the true kbar) and T -> K (kbar 0.0013 -> 0.00087 at beta 55),"
      " noise sd:")
for cn in conds:
    for o in times:
        dM = (corr[(cn, "M")][o] - corr[(cn, "T")][o]) / noise[o]
        dK = (corr[(cn, "K")][o] - corr[(cn, "T")][o]) / noise[o]
        print(f"{cn} {o:18s} | {np.sqrt(np.mean(dM**2)):7.2f} {np.sqrt(np.mean(dK**2)):7.2f}")
