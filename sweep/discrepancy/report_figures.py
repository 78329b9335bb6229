"""The discrepancy report's figures (matplotlib, Agg): the measured curves against the baseline and the named model,
the residual maps, and each named strength's profile likelihood (drawn from the report alone).  Units mm, s, kPa."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from sweep.figio import write_figure

from . import stats
from .observables import CURVES as CURVE_OBSERVABLES
from .observables import UNITS

__all__ = ["fig_curves", "fig_residuals", "fig_profiles"]


def fig_curves(problem, fit_before, fit_after, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ids = problem.data.ids
    obs = [o for o in CURVE_OBSERVABLES if np.any(problem.obs == o)]
    fig, axes = plt.subplots(len(obs), len(ids), figsize=(3.2 * len(ids), 2.6 * len(obs)), squeeze=False)
    pb = problem.prediction(fit_before.params, fit_before.x, ids)
    pa = problem.prediction(fit_after.params, fit_after.x, ids)
    for j, cid in enumerate(ids):
        for i, o in enumerate(obs):
            ax = axes[i, j]
            m = (problem.cond == cid) & (problem.obs == o)
            if not np.any(m):              # this condition does not measure o
                ax.axis("off")
                continue
            t = problem.t[m]
            ax.errorbar(t, problem.y[m], problem.sig[m], fmt=".", ms=3, color="k", alpha=0.5, label="measured")
            ax.plot(t, pb[cid][o], "C0-o", ms=3, label="baseline (calibrated)")
            if fit_after is not fit_before:
                ax.plot(t, pa[cid][o], "C3--s", ms=3, label="with named effect")
            ax.set_title(f"{cid}{' (held out)' if cid in problem.spec.holdout(ids) else ''}", fontsize=8)
            ax.set_xlabel("t (s)", fontsize=7)
            ax.set_ylabel(f"{o} ({UNITS[o]})", fontsize=7)
            ax.tick_params(labelsize=6)
    axes[0, 0].legend(fontsize=6)
    fig.tight_layout()
    write_figure(fig, path, dpi=110)
    plt.close(fig)


def _fig_profile(eff: str, pr: dict, path, ind: dict | None = None) -> None:
    """The profile likelihood of ``eff``: Δχ² at each evaluated strength, the threshold, the interval and, when
    given, the independent estimate ± 2σ (strength in the effect's unit)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pts = sorted(pr["points"], key=lambda q: q["value"])
    fig, ax = plt.subplots(figsize=(4.6, 3.2))
    ax.plot([q["value"] for q in pts], [q["delta_chi2"] for q in pts], "k-o", ms=3, label="profile points")
    ax.axhline(pr["threshold"], color="C3", ls="--", lw=1, label=f"threshold {pr['threshold']:.3g}")
    ax.axvspan(pr["lower"], pr["upper"], color="C0", alpha=0.15, label="95 % interval")
    if ind:
        ax.errorbar([ind["value"]], [0.0], xerr=[[2 * ind["sigma"]], [2 * ind["sigma"]]], fmt="s", color="C2",
                    capsize=3, label="independent ± 2σ")
    ax.set_xlabel(f"{eff} strength")
    ax.set_ylabel("Δχ²")
    title = "non-monotone" if pr.get("non_monotone") else ""
    ax.set_title(title, fontsize=8, color="C3")
    ax.legend(fontsize=6)
    fig.tight_layout()
    write_figure(fig, path, dpi=110)
    plt.close(fig)


def fig_residuals(problem, fit, path, title):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ids = problem.data.ids
    r = problem.residual_batch(fit.params, [fit.x], ids)[0]
    m = problem.mask(ids)
    ph, obs, cond = problem.phase[m], problem.obs[m], problem.cond[m]
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 3.4))
    for k, o in enumerate([o for o in CURVE_OBSERVABLES if np.any(obs == o)]):
        vals = [np.mean(r[(ph == p) & (obs == o)]) if np.any((ph == p) & (obs == o)) else 0 for p in range(4)]
        a1.bar(np.arange(4) + 0.25 * k, vals, width=0.25, label=o)
    a1.set_xticks(np.arange(4) + 0.25)
    a1.set_xticklabels(stats.PHASES, fontsize=7)
    a1.axhline(0, color="k", lw=0.5)
    a1.set_ylabel("mean standardized residual")
    a1.legend(fontsize=7)
    a1.set_title(title + ": per phase", fontsize=9)
    # residual sign over parameter space (Ca*–C plane when available, else condition index)
    xs, ys, labels = [], [], []
    for cid in ids:
        row = problem.overrides(cid, fit.values())
        try:
            from solver import Parameters
            from sweep.regimes.numbers import dimensionless_numbers

            dn = dimensionless_numbers(Parameters.from_dict(row))
            x = float(dn["Ca_star"]) if "Ca_star" in dn else float(ids.index(cid))
        except Exception:
            x = float(ids.index(cid))
        xs.append(x)
        ys.append(float(row.get("cement", 1.2)))
        labels.append(cid)
    mr = np.array([np.mean(r[(cond == cid) & (obs == "p_inj")]) if np.any((cond == cid) & (obs == "p_inj")) else 0 for cid in ids])
    sc = a2.scatter(xs, ys, c=mr, cmap="coolwarm", vmin=-max(3, np.abs(mr).max()), vmax=max(3, np.abs(mr).max()), s=60, edgecolor="k")
    for cid, x, y in zip(labels, xs, ys):
        reg = problem.data.regimes.get(cid)
        mark = ""
        if reg is not None:
            pr = problem.prediction(fit.params, fit.x, ids)[cid].get("regime")
            mark = "" if pr == reg[1] else " ✗"
        a2.annotate(cid + mark, (x, y), fontsize=7)
    if all(x > 0 for x in xs) and max(xs) / max(min(xs), 1e-300) > 20:
        a2.set_xscale("log")
    a2.set_xlabel("Ca* (or condition index)")
    a2.set_ylabel("C (%)")
    a2.set_title("mean p_inj residual; ✗ = regime misclassified", fontsize=9)
    fig.colorbar(sc, ax=a2)
    fig.tight_layout()
    write_figure(fig, path, dpi=110)
    plt.close(fig)


def fig_profiles(report: dict, out: Path) -> set[str]:
    """``profile_<effect>.png`` of every profile with evaluated points (from the report alone); their names."""
    made = set()
    for eff, pr in (report.get("profiles") or {}).items():
        if pr.get("points"):
            _fig_profile(eff, pr, out / f"profile_{eff}.png", (report.get("independent_estimates") or {}).get(eff))
            made.add(f"profile_{eff}.png")
    return made
