"""How the ten-minute twin's correction moves with k̄, from the runs ten_minute_estimate.py left in the cache copy
(no new runs): per observable, RMS over the rows in noise sd (p_inj 2 kPa, front 0.2 mm), the change of the
coarse model, of the fine realizations and of the correction between the anchors, each realization's deviation
from the mean change, and the plane's (A1, A2, A3) miss at A0 and its reach to the truth.

    python results/discrepancy/correction_follows/ten_minute_anchors.py CACHE_COPY > ten_minute_anchors.txt
"""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from ten_minute_estimate import CAMPAIGN, DATA, cached_anchors  # noqa: E402

from solver import RunOptions  # noqa: E402
from sweep.discrepancy.data import load_measured  # noqa: E402
from sweep.discrepancy.forward import SolverForward, fine_forwards  # noqa: E402
from sweep.discrepancy.heldout import heldout_data  # noqa: E402
from sweep.discrepancy.noise import coarse_and_fines, correction_from  # noqa: E402
from sweep.discrepancy.problem import Problem  # noqa: E402
from sweep.discrepancy.profile import StrengthCorrection  # noqa: E402
from sweep.discrepancy.spec import spec_from_dict  # noqa: E402
from sweep.discrepancy.twins import load_twin_campaign  # noqa: E402

NOISE = {"p_inj": 2.0, "front_radius_mean": 0.2}


def main(cache: Path) -> None:
    spec = spec_from_dict(load_twin_campaign(CAMPAIGN)["spec"])
    pb = Problem(heldout_data(load_measured(DATA), spec), spec,
                 SolverForward(spec.baseline_overrides(), RunOptions.from_dict(spec.options), cache / "workflow"))
    fine = fine_forwards(spec, cache / "workflow", 1)
    params = tuple(spec.calibrate) + (spec.candidate_param("compliant_boundary"),)
    a0, a1, a2 = cached_anchors(cache)

    def v(k, c):
        return {"kbar": k, "effect:compliant_boundary": c}

    def rms(x):
        return {o: round(float(np.sqrt(np.nanmean((x[pb.obs == o] / s) ** 2))), 3) for o, s in NOISE.items()}

    a3 = (a1[0] * 10 ** -0.15, a1[1])
    (c0, f0), (c1, f1), (c2, f2) = (coarse_and_fines(pb, fine, v(*a)) for a in (a0, a1, a2))
    c3, f3 = coarse_and_fines(pb, fine[:3], v(*a3))
    ch = f3 - f1[:3]
    print("A3 - A1 (k̄ -0.15 decades): coarse change", rms(c3 - c1), "fine mean change (3 realizations)", rms(ch.mean(0)))
    for k in range(3):
        print(f"  realization {k + 1}: deviation from the mean change", rms(ch[k] - ch.mean(0)))
    corrs = [correction_from(c1, f1), correction_from(c2, f2), correction_from(c3, f3, ref=f1)]
    print("correction change A3 - A1", rms(corrs[2] - corrs[0]))
    print("correction change A2 - A1", rms(corrs[1] - corrs[0]))
    print("correction change A0 - A1", rms(correction_from(c0, f0) - corrs[0]))
    X = np.array([[p.to_x(q[p.name]) for p in params] for q in (v(*a1), v(*a2), v(*a3))])
    plane = StrengthCorrection(X, corrs, params=params, strength=1)
    print("plane's miss at A0", rms(plane(v(*a0)) - correction_from(c0, f0)))
    print("plane's change A1 -> truth (0.0018, 0.02)", rms(plane(v(0.0018, 0.02)) - corrs[0]))
    print("plane's change A1 -> (0.003, 0.01893)", rms(plane(v(0.003, 0.018931315494712105)) - corrs[0]))
    print("new runs", pb.forward.n_runs, [f.n_runs for f in fine])


if __name__ == "__main__":
    main(Path(sys.argv[1]))
