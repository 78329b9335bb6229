"""Checks of measured data against the model SPEC and the forward models, made before any forward run.

``load_measured`` checks a data folder alone and ``spec.load_spec`` a SPEC alone; what only their
combination shows is checked here (units mm, s, kPa):

* the held-out ids are conditions of the data, and both training and held-out sets are non-empty;
* every condition's parameters (baseline, calibrated initial values, the condition's columns) run on
  every solver forward model's mesh (``solver.options.check_run_inputs``: h fits the annulus, ...);
* no observation time is after a solver forward model's ``t_end`` (times in ms instead of s), and a snapshot
  observable (the crack count, read from the last snapshot) is observed at ``t_end``;
* measured ``p_inj`` is within ``PRESSURE_SCALE_FACTOR`` times the condition's Young's modulus E
  (kPa): the model's pressures stay within a few E, so values 1000x larger are pressures in Pa;
* a measured front radius is not clearly (by ``data.LENGTH_SIGMAS`` uncertainties) inside r_inner or beyond r_outer;
* regime labels are labels the forward model gives (its ``regime_labels``, when it declares them).

Each problem is a ValueError naming the input, its value and what is allowed.
"""
from __future__ import annotations

from .data import LENGTH_SIGMAS

__all__ = ["check_data_against_model", "spec_models", "PRESSURE_SCALE_FACTOR"]

# measured p_inj above this many E (kPa) is refused as a unit error (the model's p_inj: below ~4 E)
PRESSURE_SCALE_FACTOR = 100.0


def check_data_against_model(data, spec, forwards=(), strict: bool = False) -> list[str]:
    """Raise ValueError if ``data`` (MeasuredData) cannot be compared with ``spec`` (DiscrepancySpec) run
    by ``forwards`` (forward models: the workflow's and the fine check models); see the module docstring.

    Returns the warnings of implausible inputs (a likely unit slip, a length the mesh does not resolve:
    ``solver.options.check_run_inputs``), each once naming the conditions it concerns; with ``strict`` the
    first of them is raised instead.  ``discrepancy init`` and ``discrepancy run`` both call this (init with
    :func:`spec_models`)."""
    _check_holdout(data, spec)
    params = _condition_parameters(data, spec)
    solver_options = [f.options for f in forwards if _is_run_options(getattr(f, "options", None))]
    warnings = _check_runnable(params, solver_options)
    _check_times(data, solver_options)
    _check_snapshot_times(data, solver_options)
    _check_pressure_scale(data, params)
    _check_front_radii(data, params)
    for f in forwards:
        _check_regime_labels(data, getattr(f, "regime_labels", None))
    if strict and warnings:
        raise ValueError(f"--strict refuses: {warnings[0]}"
                         + (f" (and {len(warnings) - 1} more warning(s))" if len(warnings) > 1 else ""))
    return warnings


class _SpecModel:
    """What the checks read of a solver forward model: its run options and regime labels (no run, no cache)."""

    def __init__(self, options: dict):
        from solver import RunOptions
        from sweep.regimes.classify import REGIMES

        self.options = RunOptions.from_dict(options)
        self.regime_labels = REGIMES


def spec_models(spec) -> list:
    """Stand-ins of the solver forward models ``discrepancy run`` makes of ``spec`` (its ``[options]`` and each
    fine check model's), for :func:`check_data_against_model` before any forward model exists."""
    from .spec import fine_options

    try:
        return [_SpecModel(o) for o in [spec.options, *fine_options(spec)]]
    except ValueError as exc:
        raise ValueError(f"discrepancy spec [options]: {exc}") from None


def _is_run_options(o) -> bool:
    from solver import RunOptions

    return isinstance(o, RunOptions)


def _check_holdout(data, spec) -> None:
    held = spec.holdout(data.ids)  # raises for held-out ids absent from the data
    if not held:
        raise ValueError(f"discrepancy spec: [holdout] holds out no condition of {data.ids} (allowed: at least one "
                         "held-out condition, so that the gap on unseen conditions can be measured)")
    if len(held) == len(data.ids):
        raise ValueError(f"discrepancy spec: [holdout] holds out every condition {data.ids} (allowed: at least "
                         "one condition left to calibrate on)")


def _condition_parameters(data, spec) -> dict:
    """{condition id: solver.Parameters} at the baseline with the calibrated parameters' initial values."""
    from solver import Parameters

    start = {**spec.baseline_overrides(), **{p.name: p.initial for p in spec.calibrate}}
    out = {}
    for cid in data.ids:
        try:
            out[cid] = Parameters.from_dict({**start, **data.condition_params(cid)})
        except ValueError as exc:
            raise ValueError(f"condition {cid!r} with the spec's [baseline]: {exc}") from None
    return out


def _check_runnable(params: dict, solver_options: list) -> list[str]:
    """Every condition runs with every solver model's options; returns the warnings, each once with the
    conditions it concerns."""
    from solver.options import check_run_inputs

    seen: dict[str, list] = {}
    for o in solver_options:
        for cid, p in params.items():
            try:
                ws = check_run_inputs(p, o)
            except ValueError as exc:
                raise ValueError(f"condition {cid!r} (r_inner = {p.r_inner:g}, r_outer = {p.r_outer:g} mm) cannot "
                                 f"run with the spec's options: {exc}") from None
            for w in ws:
                seen.setdefault(w, [])
                if cid not in seen[w]:
                    seen[w].append(cid)
    return [f"condition(s) {cids}: {w}" for w, cids in seen.items()]


def _check_times(data, solver_options: list) -> None:
    if not solver_options or len(data.curves) + len(data.regimes) == 0:
        return
    t_end = min(o.t_end for o in solver_options)
    late = data.curves[data.curves.time > t_end * (1 + 1e-9)]
    if len(late):
        r = late.iloc[0]
        raise ValueError(f"observations.csv: condition {r.condition!r} {r.observable} time={r.time:g} s is after the "
                         f"model's t_end = {t_end:g} s (allowed: times in [0, t_end] s; were they given in ms?)")
    for cid, (t, _) in data.regimes.items():
        if t > t_end * (1 + 1e-9):
            raise ValueError(f"observations.csv: condition {cid!r} regime time={t:g} s is after the model's "
                             f"t_end = {t_end:g} s (allowed: times in [0, t_end] s; were they given in ms?)")


def _check_snapshot_times(data, solver_options: list) -> None:
    """Snapshot observables (``observables.SNAPSHOT_CURVES``) are read from the forward runs' last snapshot,
    at t_end (s): observed at any other time they would be compared with the wrong state."""
    from .observables import SNAPSHOT_CURVES

    c = data.curves
    for o in solver_options:
        off = c[c.observable.isin(SNAPSHOT_CURVES) & ((c.time - o.t_end).abs() > 1e-9 * max(o.t_end, 1.0))]
        if len(off):
            r = off.iloc[0]
            raise ValueError(f"observations.csv: condition {r.condition!r} {r.observable} time={r.time:g} s: this "
                             f"observable is read from the run's last snapshot, at the model's t_end = {o.t_end:g} s "
                             "(allowed: time = t_end)")


def _check_pressure_scale(data, params: dict) -> None:
    c = data.curves
    for cid, p in params.items():
        v = c.loc[(c.condition == cid) & (c.observable == "p_inj"), "value"].abs()
        if len(v) and v.max() > PRESSURE_SCALE_FACTOR * p.E:
            raise ValueError(f"observations.csv: condition {cid!r} p_inj value={v.max():g} is implausible in kPa: the "
                             f"model's pressures stay within a few E = {p.E:g} kPa (allowed: |p_inj| <= "
                             f"{PRESSURE_SCALE_FACTOR:g} E = {PRESSURE_SCALE_FACTOR * p.E:g} kPa; were they given in Pa?)")


def _check_front_radii(data, params: dict) -> None:
    c = data.curves
    for cid, p in params.items():
        f = c[(c.condition == cid) & (c.observable == "front_radius_mean")]
        bad = f[(f.value + LENGTH_SIGMAS * f.uncertainty < p.r_inner) | (f.value - LENGTH_SIGMAS * f.uncertainty > p.r_outer)]
        if len(bad):
            r = bad.iloc[0]
            raise ValueError(f"observations.csv: condition {cid!r} front_radius_mean value={r.value:g} mm at "
                             f"t = {r.time:g} s is outside the annulus (allowed: [r_inner = {p.r_inner:g}, r_outer = "
                             f"{p.r_outer:g}] mm within {LENGTH_SIGMAS:g} uncertainties)")


def _check_regime_labels(data, labels) -> None:
    if not labels:
        return
    for cid, (_, label) in data.regimes.items():
        if label not in labels:
            raise ValueError(f"observations.csv: condition {cid!r} regime value={label!r} is not a label the model "
                             f"gives (allowed: {sorted(labels)})")
