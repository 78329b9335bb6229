"""Campaign specifications: parse and validate the TOML files of ``campaigns/``.

A campaign spec names a study, its base model parameters (units mm, s, kPa as in
``solver.params.Parameters``), the axes swept (each over a model parameter or a run
option), the run options (``solver.options.RunOptions``: h in mm, times in s), the
classification options passed to ``sweep.regimes.classify.classify_run``, the diagrams to draw
and scheduler defaults. Everything is checked before any run starts: an unknown key, an
out-of-range value or an empty grid raises :class:`SpecError` (a ``ValueError``) naming
the key.  The validated spec's types and its grid expansion are ``sweep.campaign.spec_model`` (its
public names are importable from here); this module reads and checks, the samplers of
:func:`samplers` expand and check every point.

Format (all tables optional except ``name``)::

    name = "ca_star_vs_cement"          # [A-Za-z0-9_.-]+, the results folder name
    description = "..."
    paper = "Sec. 3.6"

    [base]                              # Parameters fields (kPa, kPa*s, mm, mm^2, ...)
    preset = "experiment"               # optional: a named model (solver.presets), the keys below on top
    model = "named_model.toml"          # optional: a parameter file (dchfrac discrepancy model), relative to
                                        # this file's folder, over the preset (sweep.campaign.base_model); the
                                        # keys below, the axes and [derived] replace the values of both
    eta_w = 1e-6

    [derived]                           # parameters computed from the others, per run
    psi_c = "0.0015*cement**2"          # + - * / ** sqrt exp log log10 abs min max

    [options]                           # RunOptions fields (h mm, t_end s, ...)
    h = 4.0

    [axes]                              # swept parameters or run options
    cement = {linear = [0.5, 3.0, 6]}   # start, stop, count (stop included)
    eta_o = {log = [1e-4, 1.0, 5]}      # start, stop, count, geometric spacing
    seed = [1, 2, 3]                    # explicit list ({values = [...]} alike)
    w_i = {range = [25, 100, 25]}       # start, stop (included), step
    options.h = [4.0, 2.0]              # explicit namespace when needed
    mode = "cross"                      # or "zip" (all axes zipped), default cross
    zip = [["eta_o", "w_i"]]            # groups zipped together, crossed with the rest

    [[blocks]]                          # optional: the grid is the union of blocks,
    label = "psi_c"                     # each with its own base/options/axes/mode/zip
    axes = {psi_c = [2.16e-4, 2.16e-3, 2.16e-2]}

    [sampler]
    kind = "grid"                       # see samplers(); "boundary": adaptive runs where
                                        # the regime boundary is least certain (sweep.campaign.boundary: budget,
                                        # tolerance, seed, batch, ...; axes linear/log/range bounds)

    [replicates]                        # runs per point (sweep.campaign.replicates): porosity draws
    porosity_seed = 5                   # seed = base seed + 0..4; optional mesh_seed = M crossed with them

    [classify]                          # keyword arguments of classify_run

    [[diagrams]]
    kind = "ca_star_vs_cement"          # or nf_vs_nb, timeseries, scatter, fields

    [run]                               # scheduler defaults, overridden by the CLI
    timeout = 3600.0                    # s per run (None: no limit)
    retries = 0
    runner = "module:function"          # default: solver.simulate + classify_run
    max_runs = 10000                    # largest grid allowed (default DEFAULT_MAX_RUNS)
"""
from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path
from typing import Any, Mapping

# the data model lives in sweep.campaign.spec_model (below the samplers, which build on it); its public names are this
# module's too, so that a spec's reader needs one import
from sweep.campaign.replicates import check_replicates
from sweep.campaign.spec_model import (Axis, Block, CampaignSpec, SpecError, evaluate_expression, expression_names, is_number,
                              grid_size, option_fields, parameter_fields, round_sig)

__all__ = [
    "SpecError",
    "Axis",
    "Block",
    "CampaignSpec",
    "load_spec",
    "spec_from_dict",
    "samplers",
    "resolve_runner",
    "parameter_fields",
    "option_fields",
    "evaluate_expression",
    "round_sig",
]


def samplers() -> dict[str, type]:
    """The sampler kinds a spec's ``[sampler] kind`` may name, {kind: class}.  Imported on first use: the boundary
    sampler's statistics (scipy.stats) take about a second to import, which a reader of results does not need."""
    from sweep.campaign.boundary import BoundarySampler
    from sweep.campaign.sampler import GridSampler

    return {GridSampler.kind: GridSampler, BoundarySampler.kind: BoundarySampler}


def resolve_runner(ref: str):
    """The callable named by a runner reference ``"package.module:function"`` (``[run] runner``); ValueError
    naming the reference when it cannot be imported or is not callable."""
    import importlib

    mod, _, name = ref.partition(":")
    try:
        obj = getattr(importlib.import_module(mod), name)
    except (ImportError, AttributeError) as e:
        raise ValueError(f"runner={ref!r} cannot be imported: {e}") from None
    if not callable(obj):
        raise ValueError(f"runner={ref!r} is not callable")
    import inspect

    try:       # a runner is called as runner(params, options, run_dir) (sweep.campaign.scheduler)
        inspect.signature(obj).bind({}, {}, "run_dir")
    except (TypeError, ValueError):
        raise ValueError(f"runner={ref!r} is not a runner: a Python function runner(params, options, run_dir) "
                         "(sweep.campaign.scheduler)") from None
    if not inspect.isfunction(obj):
        raise ValueError(f"runner={ref!r} is a {type(obj).__name__}, not a runner: a Python function "
                         "runner(params, options, run_dir) (sweep.campaign.scheduler)")
    return obj


# ---------------------------------------------------------------------------
# small helpers
# ---------------------------------------------------------------------------
def _fail(where: str, msg: str):
    """Raise SpecError naming the key; control characters of a key are escaped, so the message is one line."""
    where = where.encode("unicode_escape").decode("ascii")
    raise SpecError(f"{where}: {msg}")


_TOP_KEYS = {
    "name", "description", "paper", "base", "derived", "options", "axes", "mode", "zip",
    "blocks", "sampler", "classify", "diagrams", "run", "replicates",
}
_BLOCK_KEYS = {"label", "base", "options", "axes", "mode", "zip"}
_RUN_KEYS = {"timeout", "retries", "runner", "jobs", "isolate", "max_runs"}
# grids above this many runs are refused (quickly, before expansion) unless [run] max_runs or --max-runs allows them
DEFAULT_MAX_RUNS = 10_000
# and no grid above this many, whatever max_runs says: its plan (each point validated) would take hours
MAX_RUNS_CEILING = 100_000
_MODES = ("cross", "zip")


def _axis_values(where: str, spec, limit: int) -> tuple:
    """One axis spec (list or {values|linear|log|range}) as a tuple of values (at most ``limit``); their
    distinctness is checked with the axis's zip group (:func:`_check_distinct`)."""
    vals = _expand_axis(where, spec, limit)
    if len(vals) > limit:
        _too_many(where, len(vals), limit)
    return vals


def _check_distinct(where: str, group: list) -> None:
    """The points of a group of axes swept together (one crossed axis, or the axes of a zip group) are
    distinct: a repeated point would silently be one run.  A zipped axis may repeat a value when the
    zipped tuples differ."""
    keys = [tuple(_value_key(a.values[i]) for a in group) for i in range(len(group[0].values))]
    if len(set(keys)) != len(keys):
        i = next(i for i, k in enumerate(keys) if keys.count(k) > 1)
        if len(group) == 1:
            _fail(f"{where}axes.{group[0].name}", f"value {group[0].values[i]!r} given twice (allowed: distinct "
                                                    "values; a repeated value is one run)")
        point = {a.name: a.values[i] for a in group}
        _fail(f"{where}zip", f"zipped point {point} given twice (allowed: distinct points; a repeated point is one run)")


def _value_key(v):
    """Hashable identity of an axis value: numbers by value (1 == 1.0), others by their JSON text."""
    import json

    if isinstance(v, int) and not isinstance(v, bool) and abs(v) > 2**1023:
        return v                  # beyond any float: its own identity (refused later as a parameter value)
    return float(v) if is_number(v) else json.dumps(v, sort_keys=True, default=str)


def _too_many(where: str, n: int, limit: int):
    if n > MAX_RUNS_CEILING:
        _fail(where, f"{n} runs exceed the limit max_runs = {limit} and the ceiling {MAX_RUNS_CEILING} of any grid "
                     "(each point is planned on its own: split it into campaigns, or sample it: [sampler])")
    _fail(where, f"{n} runs exceed the limit max_runs = {limit} (allowed: at most max_runs; raise it with "
                 f"[run] max_runs = {n} in the spec or --max-runs {n})")


def _expand_axis(where: str, spec, limit: int) -> tuple:
    if isinstance(spec, list):
        return tuple(round_sig(v) for v in spec)
    if not isinstance(spec, dict):
        _fail(where, f"expected a list of values or a table with one of values/linear/log/range, got {spec!r}")
    if len(spec) != 1:
        _fail(where, f"expected exactly one of values/linear/log/range, got keys {sorted(spec)}")
    (kind, arg), = spec.items()
    if kind == "values":
        if not isinstance(arg, list):
            _fail(f"{where}.values", f"expected a list, got {arg!r}")
        return tuple(round_sig(v) for v in arg)
    if kind not in ("linear", "log", "range"):
        _fail(where, f"unknown range kind {kind!r}; allowed: values, linear, log, range")
    if not (isinstance(arg, list) and len(arg) == 3 and all(is_number(v) for v in arg)):
        _fail(f"{where}.{kind}", f"expected 3 numbers [start, stop, {'step' if kind == 'range' else 'count'}], got {arg!r}")
    a, b, n = arg
    ints = isinstance(a, int) and isinstance(b, int)
    if kind in ("linear", "log"):
        if not isinstance(n, int) or n < 0:
            _fail(f"{where}.{kind}", f"count={n!r} must be an integer >= 0")
        if kind == "log" and (a <= 0 or b <= 0):
            _fail(f"{where}.log", f"start={a!r} and stop={b!r} must be > 0 for a log range")
        if n > limit:
            _too_many(f"{where}.{kind}", n, limit)
        if n == 1:
            vals = [float(a)]
        elif kind == "linear":
            vals = [a + (b - a) * i / (n - 1) for i in range(n)]
        else:
            la, lb = math.log10(a), math.log10(b)
            vals = [10.0 ** (la + (lb - la) * i / (n - 1)) for i in range(n)]
            ints = False
    else:
        if n == 0 or (b - a) * n < 0:
            _fail(f"{where}.range", f"step={n!r} must be non-zero and point from start={a!r} to stop={b!r}")
        count = int(math.floor((b - a) / n * (1 + 1e-12) + 1e-9)) + 1
        if count > limit:
            _too_many(f"{where}.range", count, limit)
        vals = [a + i * n for i in range(count)]
        ints = ints and isinstance(n, int)
    vals = [round_sig(float(v)) for v in vals]
    if ints and all(float(v).is_integer() for v in vals):
        vals = [int(v) for v in vals]
    return tuple(vals)


def _axis_scale(spec) -> str:
    """How an axis spec (already checked by :func:`_axis_values`) spaces its values."""
    return next(iter(spec)) if isinstance(spec, dict) else "values"


def _resolve_name(where: str, name: str, pfields, ofields) -> tuple[str, str]:
    """Return (target, field) for an axis/base name."""
    if name in pfields and name in ofields:
        _fail(where, f"{name!r} is both a parameter and a run option: write params.{name} or options.{name}")
    if name in pfields:
        return "params", name
    if name in ofields:
        return "options", name
    _fail(where, f"unknown key {name!r}: not a field of Parameters {sorted(pfields)} nor of RunOptions {sorted(ofields)}")


def _parse_axes(where: str, axes_tbl, pfields, ofields, limit: int) -> list[Axis]:
    if not isinstance(axes_tbl, dict):
        _fail(where, f"expected a table, got {axes_tbl!r}")
    out: list[Axis] = []
    for name, spec in axes_tbl.items():
        if name in ("params", "options") and isinstance(spec, dict) and not (
            len(spec) == 1 and next(iter(spec)) in ("values", "linear", "log", "range")
        ):
            allowed = pfields if name == "params" else ofields
            for sub, sspec in spec.items():
                if sub not in allowed:
                    _fail(f"{where}.{name}.{sub}", f"unknown key {sub!r}: allowed {sorted(allowed)}")
                out.append(Axis(sub, name, _axis_values(f"{where}.{name}.{sub}", sspec, limit), _axis_scale(sspec)))
            continue
        target, fname = _resolve_name(f"{where}.{name}", name, pfields, ofields)
        out.append(Axis(fname, target, _axis_values(f"{where}.{name}", spec, limit), _axis_scale(spec)))
    names = [a.name for a in out]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        _fail(where, f"axis {dup[0]!r} given twice")
    return out


def _base_defaults(w: str, base: dict, folder: Path) -> tuple[dict, dict]:
    """(defaults, rest) of a ``[base]`` table: the parameters of its ``preset`` (solver.presets) and then of its
    ``model`` file (sweep.campaign.base_model), which the base's own keys, the axes and ``[derived]`` replace, and
    the base without those two keys."""
    defaults = {}
    if "preset" in base:
        from solver.presets import preset_changes

        try:
            defaults.update(preset_changes(base["preset"]))
        except ValueError as exc:
            _fail(f"{w}base.preset", str(exc))
    if "model" in base:
        from sweep.campaign.base_model import read_base_model

        defaults.update(read_base_model(f"{w}base.model", base["model"], folder))
    return defaults, {k: v for k, v in base.items() if k not in ("preset", "model")}


def _parse_block(where: str, tbl: dict, pfields, ofields, label: str, limit: int, folder: Path = Path("."),
                 free: frozenset = frozenset()) -> Block:
    """One grid block.  ``folder``: where a ``[base] model`` path starts; ``free``: the ``[derived]`` parameters,
    which replace a preset's or model file's value as the block's own axes do."""
    unknown = sorted(set(tbl) - _BLOCK_KEYS - ({"name", "description", "paper", "derived", "blocks", "sampler",
                                                "classify", "diagrams", "run"} if where == "<top>" else set()))
    if unknown:
        _fail(f"{where}.{unknown[0]}", f"unknown key {unknown[0]!r}; allowed: {sorted(_BLOCK_KEYS)}")
    w = "" if where == "<top>" else f"{where}."
    base = tbl.get("base", {})
    if not isinstance(base, dict):
        _fail(f"{w}base", f"expected a table, got {base!r}")
    params, options = {}, {}
    defaults, base = _base_defaults(w, base, folder)
    for k, v in base.items():
        if k not in pfields:
            _fail(f"{w}base.{k}", f"unknown parameter {k!r}; allowed: {sorted(pfields)}")
        params[k] = v
    opts = tbl.get("options", {})
    if not isinstance(opts, dict):
        _fail(f"{w}options", f"expected a table, got {opts!r}")
    for k, v in opts.items():
        if k not in ofields:
            _fail(f"{w}options.{k}", f"unknown run option {k!r}; allowed: {sorted(ofields)}")
        options[k] = v
    if not isinstance(tbl.get("axes", {}), dict):
        _fail(f"{w}axes", f"expected a table, got {tbl.get('axes')!r}")
    axes_tbl = dict(tbl.get("axes", {}))
    mode = tbl.get("mode", axes_tbl.pop("mode", "cross"))
    zips = tbl.get("zip", axes_tbl.pop("zip", []))
    axes = _parse_axes(f"{w}axes", axes_tbl, pfields, ofields, limit)
    if mode not in _MODES:
        _fail(f"{w}mode", f"mode={mode!r} not allowed: one of {_MODES}")
    if not isinstance(zips, list) or not all(isinstance(g, list) and all(isinstance(n, str) for n in g) for g in zips):
        _fail(f"{w}zip", f"expected a list of lists of axis names, got {zips!r}")
    names = {a.name: a for a in axes}
    grouped: set[str] = set()
    for g in zips:
        for n in g:
            bare = n.split(".", 1)[1] if n.startswith(("params.", "options.")) else n
            if bare not in names:
                _fail(f"{w}zip", f"{n!r} is not an axis of this block; axes: {sorted(names)}")
            if bare in grouped:
                _fail(f"{w}zip", f"axis {n!r} is in two zip groups")
            grouped.add(bare)
    zip_groups = tuple(tuple(n.split(".", 1)[1] if n.startswith(("params.", "options.")) else n for n in g) for g in zips)
    groups = [tuple(a.name for a in axes)] if mode == "zip" else list(zip_groups)
    for g in groups:
        lens = {n: len(names[n].values) for n in g}
        if len(set(lens.values())) > 1:
            _fail(f"{w}zip", f"zipped axes must have equal lengths, got {lens}")
    for a in axes:
        if len(a.values) == 0:
            _fail(f"{w}axes.{a.name}", "the grid is empty: this axis has no values")
    in_groups = {n for g in groups for n in g}
    for g in groups + [(a.name,) for a in axes if a.name not in in_groups]:
        _check_distinct(w, [names[n] for n in g])
    for a in axes:
        if a.target == "params" and a.name in params:
            _fail(f"{w}axes.{a.name}", f"{a.name!r} is both swept and set in base")
        if a.target == "options" and a.name in options:
            _fail(f"{w}axes.{a.name}", f"{a.name!r} is both swept and set in options")
    grid_set = free | {a.name for a in axes if a.target == "params"}
    params = {**{k: v for k, v in defaults.items() if k not in grid_set}, **params}
    return Block(label=str(tbl.get("label", label)), params=params, options=options, axes=tuple(axes),
                 mode=mode, zip_groups=zip_groups)


# ---------------------------------------------------------------------------
# parsing
# ---------------------------------------------------------------------------
_NAME_RE = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.-]*$")  # a plain folder name: not ".", "..", ".hidden"


def spec_from_dict(d: Mapping[str, Any], source: str = "<dict>", max_runs: int | None = None) -> CampaignSpec:
    """Build and validate a :class:`CampaignSpec` from a parsed TOML dict.

    Checks: known keys everywhere, axis syntax, zip lengths, non-empty axes, and that every
    grid point builds a valid ``Parameters``/``RunOptions`` (the sampler's initial points are expanded
    and validated). Raises :class:`SpecError` naming the key.

    max_runs : the largest grid allowed (default: ``[run] max_runs``, else DEFAULT_MAX_RUNS); a larger one
    is refused from the axes' lengths, before any grid point is built.  A ``[base] model`` path is relative to
    the folder of ``source`` when it is a file, else to the working folder.
    """
    try:
        return _spec_from_dict(d, source, max_runs)
    except SpecError as e:
        if str(e).startswith(source):
            raise
        raise SpecError(f"{source}: {e}") from None


def _spec_from_dict(d, source, max_runs) -> CampaignSpec:
    if not isinstance(d, Mapping):
        _fail("<top>", f"expected a table, got {d!r}")
    unknown = sorted(set(d) - _TOP_KEYS)
    if unknown:
        _fail(unknown[0], f"unknown key {unknown[0]!r}; allowed: {sorted(_TOP_KEYS)}")
    name = d.get("name")
    if not isinstance(name, str) or not _NAME_RE.match(name):
        _fail("name", f"name={name!r} must be a plain folder name: letters, digits, '_', '.', '-', "
                      "starting with a letter, digit or '_'")
    pfields, ofields = parameter_fields(), option_fields()
    run = _table(d, "run", {})
    _check_run(run)
    limit = run.get("max_runs", DEFAULT_MAX_RUNS) if max_runs is None else _check_max_runs("--max-runs", max_runs)
    from sweep.campaign.base_model import spec_folder

    folder = spec_folder(source)
    free = frozenset(d["derived"]) if isinstance(d.get("derived"), Mapping) else frozenset()
    top = _parse_block("<top>", {k: d[k] for k in ("base", "options", "axes", "mode", "zip") if k in d},
                       pfields, ofields, label="", limit=limit, folder=folder, free=free)
    blocks = _parse_blocks(d.get("blocks"), top, pfields, ofields, limit, folder, free)
    derived = _table(d, "derived", {})
    _check_derived(derived, top, blocks, pfields)
    sampler = _sampler(d)
    classify = _table(d, "classify", {})
    _check_classify(classify)
    diagrams = d.get("diagrams", [])
    if not isinstance(diagrams, list) or not all(isinstance(g, dict) for g in diagrams):
        _fail("diagrams", f"expected an array of tables, got {diagrams!r}")
    for i, g in enumerate(diagrams):
        _check_diagram(f"diagrams[{i}]", g, pfields, ofields)
    replicates = check_replicates(d.get("replicates"), top, blocks, derived)
    size = sum(grid_size(b) for b in blocks) * math.prod(replicates.values())
    if size > limit:
        _too_many("axes" if d.get("blocks") is None else "blocks", size, limit)
    spec = CampaignSpec(
        name=name, description=str(d.get("description", "")), paper=str(d.get("paper", "")),
        params=dict(top.params), options=dict(top.options), derived=dict(derived), blocks=blocks,
        sampler=sampler, classify=dict(classify), diagrams=tuple(diagrams), run=dict(run), source=source,
        replicates=replicates,
    )
    samplers()[sampler["kind"]]().initial(spec)  # expands and validates every initial point (raises SpecError)
    return spec


def _table(d: Mapping, key: str, default: dict) -> dict:
    """The sub-table ``key`` of the spec (``default`` when absent); anything else than a table is refused."""
    t = d.get(key, default)
    if not isinstance(t, dict):
        _fail(key, f"expected a table, got {t!r}")
    return t


def _parse_blocks(blocks_raw, top, pfields, ofields, limit: int, folder: Path = Path("."),
                  free: frozenset = frozenset()) -> tuple:
    """The ``[[blocks]]`` of the spec, or the top-level block alone; labels distinct, no top-level axes beside them."""
    if blocks_raw is None:
        return (top,)
    if not isinstance(blocks_raw, list) or not blocks_raw:
        _fail("blocks", f"expected a non-empty array of tables, got {blocks_raw!r}")
    if top.axes:
        _fail("axes", "top-level axes and [[blocks]] cannot be combined: put the axes in the blocks")
    blocks = tuple(_parse_block(f"blocks[{i}]", b if isinstance(b, dict) else _fail(f"blocks[{i}]", "expected a table"),
                                pfields, ofields, label=str(i), limit=limit, folder=folder, free=free)
                   for i, b in enumerate(blocks_raw))
    labels = [b.label for b in blocks]
    if len(set(labels)) != len(labels):
        _fail("blocks", f"block labels must be distinct, got {labels}")
    return blocks


def _check_derived(derived: dict, top, blocks: tuple, pfields) -> None:
    """Each derived parameter: a known parameter, an expression of parameters that are not derived themselves,
    neither set nor swept anywhere else."""
    for k, expr in derived.items():
        if k not in pfields:
            _fail(f"derived.{k}", f"unknown parameter {k!r}; allowed: {sorted(pfields)}")
        if not isinstance(expr, str):
            _fail(f"derived.{k}", f"expected an expression string, got {expr!r}")
        try:
            names = expression_names(expr)
        except SyntaxError as e:
            _fail(f"derived.{k}", f"invalid expression {expr!r}: {e.msg}")
        except (ValueError, RecursionError, MemoryError) as e:
            _fail(f"derived.{k}", f"invalid expression: {str(e) or type(e).__name__}")
        bad = sorted(names - set(pfields))
        if bad:
            _fail(f"derived.{k}", f"unknown name {bad[0]!r} in {expr!r}; names must be parameters")
        if names & set(derived):
            _fail(f"derived.{k}", f"{expr!r} uses another derived parameter {sorted(names & set(derived))}")
        if k in top.params or any(k == a.name for b in blocks for a in b.axes) or any(k in b.params for b in blocks):
            _fail(f"derived.{k}", f"{k!r} is derived and also set or swept")


def _sampler(d: Mapping) -> dict:
    """The ``[sampler]`` table with its kind (default "grid"), the kind's settings checked by the sampler."""
    kinds = samplers()
    sampler = {"kind": "grid", **_table(d, "sampler", {"kind": "grid"})}
    if sampler["kind"] not in kinds:
        _fail("sampler.kind", f"kind={sampler['kind']!r} not allowed: one of {sorted(kinds)}")
    kinds[sampler["kind"]].check_settings({k: v for k, v in sampler.items() if k != "kind"})
    return sampler


def _check_classify(classify: dict) -> None:
    """Unknown classify options are errors (checked against classify_run's signature once it exists)."""
    try:
        import inspect

        from sweep.regimes.classify import classify_run
    except ImportError:
        return
    sig = inspect.signature(classify_run)
    allowed = [n for n, p in sig.parameters.items() if p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD)][1:]
    thresholds = {k: v for k, v in classify.items() if k not in allowed}
    if any(p.kind == p.VAR_KEYWORD for p in sig.parameters.values()):
        try:
            from sweep.regimes.classify import ClassifierOptions
        except ImportError:
            return
        names = [f.name for f in dataclasses.fields(ClassifierOptions)]
        allowed = allowed + names
        for k in thresholds:
            if k not in names:
                _fail(f"classify.{k}", f"unknown classification option {k!r}; allowed: {allowed}")
        try:
            ClassifierOptions(**thresholds)
        except (TypeError, ValueError) as e:
            _fail("classify", str(e))
        return
    for k in classify:
        if k not in allowed:
            _fail(f"classify.{k}", f"unknown classification option {k!r}; allowed: {allowed}")


DIAGRAM_KINDS = ("ca_star_vs_cement", "nf_vs_nb", "timeseries", "scatter", "fields")
_DIAGRAM_KEYS = {"kind", "title", "file", "x", "y", "by", "color", "logx", "logy", "field", "time", "rows", "cols",
                 "dp_cri", "experimental_range", "shade", "fit", "formats"}


def _check_diagram(where, g, pfields, ofields) -> None:
    kind = g.get("kind")
    if kind not in DIAGRAM_KINDS:
        _fail(f"{where}.kind", f"kind={kind!r} not allowed: one of {DIAGRAM_KINDS}")
    unknown = sorted(set(g) - _DIAGRAM_KEYS)
    if unknown:
        _fail(f"{where}.{unknown[0]}", f"unknown key {unknown[0]!r}; allowed: {sorted(_DIAGRAM_KEYS)}")
    if kind in ("timeseries", "scatter") and ("x" not in g or "y" not in g):
        _fail(where, f"a {kind} diagram needs x and y")
    dp = g.get("dp_cri")
    if dp is not None and dp != "estimate" and not (is_number(dp) and dp > 0):
        _fail(f"{where}.dp_cri", f"dp_cri={dp!r} must be a pressure > 0 (kPa) or \"estimate\"")
    if kind == "fields" and "field" not in g:
        _fail(f"{where}.field", "a fields diagram needs the field to draw (e.g. 'phi', 'd', 'S')")


def _check_run(run: dict) -> None:
    unknown = sorted(set(run) - _RUN_KEYS)
    if unknown:
        _fail(f"run.{unknown[0]}", f"unknown key {unknown[0]!r}; allowed: {sorted(_RUN_KEYS)}")
    t = run.get("timeout")
    if t is not None and (not is_number(t) or t <= 0):
        _fail("run.timeout", f"timeout={t!r} must be a number of seconds > 0")
    r = run.get("retries", 0)
    if not isinstance(r, int) or isinstance(r, bool) or r < 0:
        _fail("run.retries", f"retries={r!r} must be an integer >= 0")
    j = run.get("jobs", 1)
    if not isinstance(j, int) or isinstance(j, bool) or j == 0 or j < -1:
        _fail("run.jobs", f"jobs={j!r} must be an integer >= 1 or -1 (all cores)")
    iso = run.get("isolate", "auto")
    if iso not in ("auto", "process", "none"):
        _fail("run.isolate", f"isolate={iso!r} must be one of auto, process, none")
    rn = run.get("runner")
    if rn is not None and (not isinstance(rn, str) or ":" not in rn):
        _fail("run.runner", f"runner={rn!r} must be 'module:function'")
    if rn is not None:  # imported now, so that a dry run refuses a runner a real run could not import
        try:
            resolve_runner(rn)
        except ValueError as e:
            _fail("run.runner", f"{e} (allowed: 'module:function' of an importable module)")
    if "max_runs" in run:
        _check_max_runs("run.max_runs", run["max_runs"])


def _check_max_runs(where: str, n) -> int:
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        _fail(where, f"max_runs={n!r} must be an integer >= 1 (the largest grid allowed)")
    if n > MAX_RUNS_CEILING:
        _fail(where, f"max_runs={n} must be at most {MAX_RUNS_CEILING} (each point is planned and validated on its "
                     f"own, about 2 ms: a larger grid would take hours before its first run; split it into "
                     "campaigns, or sample it: [sampler])")
    return n


def load_spec(path, max_runs: int | None = None) -> CampaignSpec:
    """Read and validate a campaign TOML file (see the module docstring for the format);
    ``max_runs`` overrides the spec's ``[run] max_runs`` (see :func:`spec_from_dict`)."""
    from solver.tomlio import TOMLDecodeError, read_toml

    p = Path(path)
    if not p.is_file():
        raise SpecError(f"campaign spec {str(p)!r} not found")
    try:
        d = read_toml(p)
    except TOMLDecodeError as e:              # its message names the file
        raise SpecError(str(e)) from None
    return spec_from_dict(d, source=str(p), max_runs=max_runs)


