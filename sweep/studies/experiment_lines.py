"""The experiment model's Ca*–C lines judged by the protocol declared in their headers (issue #47 item 7).

Two held-out lines (campaigns/studies/experiment_ca_star_eta_line.toml: η_o alone at the measured w_i;
experiment_ca_star_rate_line.toml: w_i alone at η_o = 0.29 kPa·s) are judged each and pooled:

* the label is rule 1 of ``sweep.regimes.classify`` at L_min = 4 mm (``sweep.studies.label_agreement``), the
  separatrix Ca*_c = A exp(B C) its profile-likelihood fit with Jeffreys' prior, and the verdict "B > 0 at
  2 sigma" (the 95 % interval of B above 0) on the pooled runs (on the one line when only one is given);
* the evidence that there is none is named: every label equal along Ca* at each C (:func:`labels_along_ca_star`),
  or an interval of B that contains 0, or the reason no fit can be made;
* the fracturing label over L_min = 2–6 mm is reported whole, beside the verdict, not instead of it;
* every run's label stands beside its time of judgement and front radius (the line stops at a 45 mm front or at
  t_end, so a run judged at t_end with a short front is judged earlier in its life than one that got there);
* a run the 45 mm rule stopped before t_end while the classifier's front (the S = 0.5 region connected to the
  inlet at the judged snapshot, its largest radius) is short of 45 mm was stopped by something else than the
  front's arrival (the saturation jumping along an open crack, results/experiment_ca_star_eta_line/README.md), and
  so was one whose last step moved the solver's front by more than one element (the table's
  ``front_radius_max_last_step`` against the run's h): :func:`stop_kind` names it "front_jump", and the count is
  reported beside the verdict;
* a failed run carries no label: it is listed with the time it reached and its reason, and counted, never
  dropped silently;
* the headers' label-blind fallback (declared there before any run): a line's failed points, and only those, are
  rerun in a companion campaign ``<line>_upwind_fallback`` with transport = "upwind".  :func:`judge` with ``fallback``
  gives the SECONDARY verdict, the failed runs replaced by the companion's runs at the same point
  (:func:`with_fallback`), beside the PRIMARY one, which stays the headers' answer.

Units: lengths mm, times s, C in %, η_o in kPa·s, w_i in mm/s, Ca* dimensionless.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from sweep.figio import write_figure
from sweep.studies import label_agreement as la

__all__ = ["L_MIN", "L_SCAN", "judge", "judge_line", "labels_along_ca_star", "stop_kind", "verdict", "with_fallback",
           "figure"]

L_MIN, L_SCAN = 4.0, (2.0, 3.0, 4.0, 5.0, 6.0)  # mm: the headers' label and scan
STOP_FRONT_MM, T_END_S = 45.0, 4.0  # the headers' time of judgement: front at 45 mm (stop_front_radius) or t_end
QUANTILES = [0.0, 0.25, 0.5, 0.75, 1.0]
RUN_COLUMNS = ["cement", "eta_o", "w_i", "Ca_star", "t_reached", "front_radius_max", "front_radius_max_last_step",
               "crack_length"]
POINT = ("cement", "eta_o", "w_i", "Ca_star")  # a point of a line: C (%), eta_o (kPa s), w_i (mm/s), Ca* (-)
FALLBACK_SUFFIX = "_upwind_fallback"  # a companion campaign's name: <line><FALLBACK_SUFFIX>


def _labelled(df: pd.DataFrame) -> pd.DataFrame:
    """The runs that carry a label: status ok with a crack length (mm)."""
    return df[(df["status"] == "ok") & df["crack_length"].notna()]


def labels_along_ca_star(ok: pd.DataFrame, l_min: float = L_MIN) -> dict:
    """Per cement ratio C (%, key as text), the labels at L_min (mm) along Ca*: "fracturing" or "porous" (every
    run the same), "mixed", or "one run: ..." (no line to read at that C), and whether every C with two runs or
    more is unmixed, with at least one such C (then no run's label depends on Ca*: the evidence of no separatrix
    along these lines)."""
    per_c, lines = {}, []
    for c, d in ok.groupby("cement"):
        f = la.fracturing(d, l_min)
        label = "fracturing" if f.all() else "porous" if not f.any() else "mixed"
        per_c[f"{float(c):g}"] = label if len(d) > 1 else f"one run: {label}"
        if len(d) > 1:
            lines.append(label)
    return {"per_cement": per_c, "every_cement_unmixed": bool(lines) and "mixed" not in lines}


def verdict(fit: dict, along: dict) -> str:
    """The protocol's verdict from a :func:`sweep.studies.label_agreement.separatrix` row and
    :func:`labels_along_ca_star`."""
    if fit.get("B_positive_at_95"):
        return "B > 0 at 2 sigma"
    if along["every_cement_unmixed"]:
        return "no separatrix: every label equal along Ca* at each C"
    if "B_interval" in fit:
        lo, hi = fit["B_interval"]
        where = "contains 0" if lo <= 0.0 <= hi else "lies below 0"
        return f"B > 0 not shown: the 95 % interval of B, [{lo:.3g}, {hi:.3g}] /%, {where}"
    return f"no separatrix: {fit.get('error', 'no fit')}"


def stop_kind(t_reached: float, front_mm: float, last_step_mm: float | None = None,
              h_mm: float | None = None) -> str:
    """How a labelled run's time of judgement came: "t_end" (it ran to T_END_S), "front" (stopped early with the
    classifier's front at STOP_FRONT_MM or beyond, to 1 mm: the front's arrival) or "front_jump" (stopped early
    with the classifier's front short of it, or with the solver's front moved more than one element, ``h_mm``, in
    the run's last step, ``last_step_mm``: an arrival the time step did not resolve).  Without the last step
    (runs recorded before it was), the classifier's front alone decides.  t_reached in s, lengths in mm."""
    if t_reached >= T_END_S - 1e-9:
        return "t_end"
    jumped = last_step_mm is not None and h_mm is not None and last_step_mm > h_mm
    return "front" if front_mm >= STOP_FRONT_MM - 1.0 and not jumped else "front_jump"


def _number(r, column: str) -> float | None:
    """A table cell as a float, None when the column is absent or the cell empty."""
    v = r.get(column)
    return None if v is None or pd.isna(v) else float(v)


def _run_rows(df: pd.DataFrame) -> list[dict]:
    """Every run as a JSON row: swept values, time reached (s), front radius (mm), crack length (mm) and the
    label at L_min, or for a failed run its reason and no label."""
    rows = []
    for _, r in df.sort_values(["cement", "Ca_star"]).iterrows():
        row = {c: _number(r, c) for c in RUN_COLUMNS}
        row["status"] = str(r["status"])
        if bool(r.get("fallback", False)):
            row["fallback"] = True
        if r["status"] == "ok" and not pd.isna(r["crack_length"]):
            row[f"fracturing_at_L{L_MIN:g}"] = bool(r["crack_length"] > L_MIN)
            row["stop"] = stop_kind(float(r["t_reached"]), float(r["front_radius_max"]),
                                    _number(r, "front_radius_max_last_step"), _number(r, "h"))
        else:
            row["reason"] = None if pd.isna(r.get("reason")) else str(r["reason"])
        rows.append(row)
    return rows


def judge_line(df: pd.DataFrame) -> dict:
    """One line (or the pooled lines): all its runs, ok or failed.  The fit at L_min, the scan, the labels
    along Ca*, the verdict and the runs."""
    ok = _labelled(df)
    fit = la.separatrix(ok, L_MIN) if len(ok) else {"runs": 0, "fracturing": 0, "error": "no labelled run"}
    along = labels_along_ca_star(ok)
    rows = _run_rows(df)
    stops = pd.Series([r["stop"] for r in rows if "stop" in r], dtype=object)
    return {"runs": int(len(df)), "labelled": int(len(ok)), "failed_or_unlabelled": int(len(df) - len(ok)),
            "stops": {k: int((stops == k).sum()) for k in ("t_end", "front", "front_jump")},
            f"at_L{L_MIN:g}": fit, "verdict": verdict(fit, along), "labels_along_ca_star": along,
            "L_scan": {str(l): la.separatrix(ok, l) if len(ok) else None for l in L_SCAN},
            "judged_time_s_quantiles_0_25_50_75_100": [float(v) for v in ok["t_reached"].quantile(QUANTILES)]
            if len(ok) else None,
            "crack_length_mm": la.crack_summary(ok) if len(ok) else None,
            "run_rows": rows}


def with_fallback(line: pd.DataFrame, fallback: pd.DataFrame, *, point=POINT,
                  who: str = "experiment_lines") -> tuple[pd.DataFrame, int]:
    """The line (or grid) with each failed run replaced by the fallback campaign's run at its point (the values of
    ``point``, POINT for a line, matched as :func:`sweep.campaign.compare.matching_key` matches campaigns; column
    ``fallback`` True on those rows), and how many were replaced.  A fallback run at a point where the line has
    no failed run, or two at one point, is refused, naming ``who``: the declared rule reruns the failed points and
    only those."""
    from sweep.campaign.compare import matching_key

    keys, fkeys = matching_key(line, point), matching_key(fallback, point)
    failed = {k for k, status in zip(keys, line["status"]) if status != "ok"}
    wrong = [k for k in fkeys if k not in failed or fkeys.count(k) > 1]
    if wrong:
        where = ", ".join(f"{c} = {v}" for c, v in zip(point, wrong[0]))
        raise ValueError(f"{who}: fallback run at {where}: the line has no failed run there, or the "
                         "fallback has two (allowed: one fallback run per failed point of the line)")
    replaced = [k in set(fkeys) and status != "ok" for k, status in zip(keys, line["status"])]
    out = pd.concat([line[~np.array(replaced, dtype=bool)].assign(fallback=False), fallback.assign(fallback=True)],
                    ignore_index=True)
    return out, len(fkeys)


def _judge_lines(lines: dict[str, pd.DataFrame]) -> dict:
    """Each line judged, with two lines the pooled runs too; the verdict is the pooled one (the one line's
    alone)."""
    out = {"lines": {name: judge_line(df) for name, df in lines.items()}}
    if len(lines) > 1:
        out["pooled"] = judge_line(pd.concat(list(lines.values()), ignore_index=True))
    out["verdict"] = (out["pooled"] if "pooled" in out else next(iter(out["lines"].values())))["verdict"]
    return out


def judge(lines: dict[str, pd.DataFrame], fallback: dict[str, pd.DataFrame] | None = None) -> dict:
    """The protocol on the named lines (name -> every run of the campaign, ok or failed): each line, and with
    two lines the pooled runs; the verdict is the pooled one (the one line's alone).  ``fallback`` (line name ->
    its companion's runs, :data:`FALLBACK_SUFFIX`) adds ``secondary``: the same judgement with each line's
    failed runs replaced by :func:`with_fallback`, and the runs replaced per line."""
    if not lines:
        raise ValueError("experiment_lines: no line given (allowed: the η_o line and optionally the w_i line)")
    unknown = sorted(set(fallback or {}) - set(lines))
    if unknown:
        raise ValueError(f"experiment_lines: fallback for {unknown}: no such line (allowed: {sorted(lines)})")
    out = {"L_min_mm": L_MIN, **_judge_lines(lines)}
    if fallback:
        filled = {name: with_fallback(df, fallback[name]) if name in fallback else (df, 0)
                  for name, df in lines.items()}
        out["secondary"] = {"fallback_runs": {name: n for name, (_, n) in filled.items()},
                            **_judge_lines({name: df for name, (df, _) in filled.items()})}
    return out


def figure(lines: dict[str, pd.DataFrame], out: dict, path: Path,
           fallback: dict[str, pd.DataFrame] | None = None) -> None:
    """PNG at ``path``: one panel per line and one pooled, the labels at L_min over the Ca*–C plane (failed runs
    as grey crosses, at their Ca*), the fitted separatrix (primary) where there is one.  With ``fallback`` (as
    :func:`judge`), the fallback's labels are drawn as squares over the failed runs and the secondary verdict is
    in each title.  Axes: C (%), Ca* (-, log)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fallback = fallback or {}
    panels = {name: (df, fallback.get(name)) for name, df in lines.items()}
    if "pooled" in out:
        fb = [f for f in fallback.values() if f is not None]
        panels["pooled"] = (pd.concat(list(lines.values()), ignore_index=True),
                            pd.concat(fb, ignore_index=True) if fb else None)
    fig, axes = plt.subplots(1, len(panels), figsize=(max(5.6, 4.4 * len(panels)), 4.2), sharey=True, squeeze=False)
    for ax, (name, (df, fb)) in zip(axes[0], panels.items()):
        res = out["pooled"] if name == "pooled" else out["lines"][name]
        _label_panel(ax, df, res, fb)
        title = f"{name}\n{res['verdict']}"
        if "secondary" in out:
            sec = out["secondary"]["pooled"] if name == "pooled" else out["secondary"]["lines"][name]
            title += f"\nwith the upwind fallback: {sec['verdict']}"
        ax.set_title(title, fontsize=8)
    axes[0][0].set_ylabel("modified capillary number Ca* (-)")
    axes[0][0].legend(fontsize=7, loc="best")
    fig.suptitle(f"Experiment model, Ca*-C lines: labels at L_min = {L_MIN:g} mm", fontsize=10)
    fig.tight_layout()
    write_figure(fig, path, dpi=110)
    plt.close(fig)


def _label_panel(ax, df: pd.DataFrame, res: dict, fallback: pd.DataFrame | None = None) -> None:
    """One panel of :func:`figure`: porous, fracturing and failed runs, the fallback's labels if given, and the
    separatrix if fitted."""
    ok = _labelled(df)
    y = la.fracturing(ok, L_MIN)
    bad = df.drop(ok.index)
    ax.scatter(ok["cement"][~y], ok["Ca_star"][~y], facecolors="none", edgecolors="C0", label="porous invasion")
    ax.scatter(ok["cement"][y], ok["Ca_star"][y], marker="^", color="C3", label="fracturing")
    ax.scatter(bad["cement"], bad["Ca_star"], marker="x", color="0.5", label="failed (no label)")
    if fallback is not None and len(fb := _labelled(fallback)):
        f = la.fracturing(fb, L_MIN)
        ax.scatter(fb["cement"], fb["Ca_star"], marker="s", s=80, facecolors="none",
                   edgecolors=["C3" if v else "C0" for v in f], label="upwind fallback (red: fracturing)")
    if len(df):
        la.separatrix_line(ax, res[f"at_L{L_MIN:g}"], df["cement"].to_numpy(dtype=float), color="k")
    ax.set_yscale("log")
    ax.set_xlabel("cement volume ratio C (%)")
