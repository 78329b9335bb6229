"""The report's sections on what to measure next: the measurements that would tell apart the models the data
cannot (a tie, a strength reaching off) and, per candidate confounded with ``[[alternative]]`` parameters, what
would tell it from its mimic (:mod:`.discriminate`).  Units: each observable's own (kPa, mm, mm², -); times in s;
separations in noise sd."""
from __future__ import annotations

__all__ = ["discriminating_lines", "confounded_lines", "measurement_table", "fmt"]


def fmt(v) -> str:
    """A value for a report line: floats to 4 significant digits, lists and dicts element by element."""
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, list):
        return "[" + ", ".join(fmt(x) for x in v) + "]"
    if isinstance(v, dict):
        return ", ".join(f"{k}: {fmt(x)}" for k, x in v.items())
    return str(v)


def discriminating_lines(report: dict) -> list[str]:
    """The measurements that would tell apart the models the data cannot (sweep.discrepancy.discriminate)."""
    rows = report.get("discriminating_measurements") or []
    if not rows:
        return []
    return (["", "## The measurements that would tell them apart", "",
             "Each tied model predicted at every condition for every registered observable; the separation is the "
             "smallest difference over pairs of models in noise sd (the data's own where they hold the observable, "
             "else the registry's default), at the time it is largest; `measured`: the data already hold it there.",
             ""] + measurement_table(rows) + [""])


def confounded_lines(report: dict) -> list[str]:
    """Per candidate confounded with [[alternative]] parameters: its mimic and the measurements that would tell
    them apart (sweep.discrepancy.discriminate.confounded_measurements)."""
    conf = report.get("confounded_measurements") or {}
    if not conf:
        return []
    L = ["", "## What would tell each confounded candidate from the alternatives", "",
         "Each candidate at its probe strength against its mimic: the baseline with the calibrated and "
         "[[alternative]] parameters moved, to first order, to reproduce its signature on the training data "
         "(linear misfit: the part of the signature the move leaves; training RMS: the two models' standardized "
         "difference where the data are, from real runs).  The separation is in noise sd (the data's own where "
         "they hold the observable, else the registry's default), at the time it is largest.", ""]
    for c, e in conf.items():
        L += [f"**{c}** at {fmt(e['probe'])} against the mimic {fmt(e['mimic'])}"
              + (f" (at an end of the range of {e['clipped']})" if e.get("clipped") else "")
              + f": linear misfit {fmt(e['linear_misfit'])}, training RMS {fmt(e['training_rms'])} sd.", ""]
        L += measurement_table(e["measurements"]) + [""]
    return L


def measurement_table(rows: list) -> list[str]:
    """A table of discriminating measurements (discriminate.discriminating_measurements rows)."""
    if not rows:
        return ["(no registered observable could be predicted for both models)"]
    models = list(rows[0]["predictions"])
    L = ["| observable | condition | t (s) | " + " | ".join(models) + " | separation (sd) | sd | measured |",
         "|---|---|---|" + "---|" * len(models) + "---|---|---|"]
    for r in rows:
        vals = " | ".join(str(v) if isinstance(v, str) or v is None else f"{v:.4g}" for v in r["predictions"].values())
        sd = "label" if r["noise_source"] == "label" else f"{r['noise_sd']:.3g} {r['unit']} ({r['noise_source']})"
        sep = "labels differ" if r["separation"] is None else f"{r['separation']:.3g}"   # inf in JSON is None
        L.append(f"| {r['observable']} | {r['condition']} | {r['time']:.3g} | {vals} | {sep} | {sd} "
                 f"| {'yes' if r['measured'] else 'no'} |")
    if rows[0]["separation"] is not None and rows[0]["separation"] < 2.0:
        L += ["", "No registered observable at these conditions separates them by 2 sd: a discriminating condition "
                  "(another injection rate, oil viscosity or a later time) is needed."]
    return L
