"""A companion campaign: the failed points of a campaign, and only those, rerun with changed options.

The experiment lines declare a label-blind fallback in their headers
(campaigns/studies/experiment_ca_star_rate_line.toml): once a line ends, its failed points are rerun with
``transport = "upwind"`` in ``<line>_upwind_fallback`` (mode "zip"), every other value as the line.
:func:`write_companion` writes that spec from the line's spec and its committed table, so "every other value as
the line" holds by construction: the companion is the line's own TOML tables with its name, its description and
the changed options replaced, and its axes replaced by the failed points, zipped.  ``dchfrac campaign companion``
is its command.  Units: those of the line's spec (mm, s, kPa).
"""
from __future__ import annotations

import json
import os
import re
import textwrap
from pathlib import Path
from typing import Any, Mapping

from solver.tomlio import read_toml, toml_value
from sweep.campaign.paths import results_root
from sweep.campaign.sampler import Point
from sweep.campaign.plan import Plan, plan_campaign
from sweep.campaign.spec import load_spec
from sweep.campaign.spec_model import CampaignSpec, plain_value

__all__ = ["add_companion_command", "cmd_companion", "companion_text", "failed_points",
           "write_companion"]

_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+$")
_SWEPT_KEYS = ("axes", "mode", "zip")   # the line's grid: replaced by the failed points


def _key(k: str) -> str:
    return k if _BARE_KEY.match(k) else json.dumps(k)


def _literal(v) -> str:
    """A TOML literal: scalars and lists as :func:`solver.tomlio.toml_value`, mappings as inline tables."""
    if isinstance(v, Mapping):
        return "{" + ", ".join(f"{_key(k)} = {_literal(x)}" for k, x in v.items()) + "}"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_literal(x) for x in v) + "]"
    return toml_value(v)


def _is_table_array(v) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(x, Mapping) for x in v)


def _table_lines(head: str, table: Mapping[str, Any]) -> list[str]:
    return ["", head] + [f"{_key(k)} = {_literal(v)}" for k, v in table.items()]


def _toml_text(d: Mapping[str, Any]) -> str:
    """``d`` as TOML: its scalars first, then each table (``[name]``) and array of tables (``[[name]]``)."""
    lines = [f"{_key(k)} = {_literal(v)}" for k, v in d.items() if not (isinstance(v, Mapping) or _is_table_array(v))]
    for k, v in d.items():
        if isinstance(v, Mapping):
            lines += _table_lines(f"[{_key(k)}]", v)
        elif _is_table_array(v):
            for table in v:
                lines += _table_lines(f"[[{_key(k)}]]", table)
    return "\n".join(lines) + "\n"


def failed_points(plan: Plan) -> list[tuple[Point, str]]:
    """The points of a campaign's ``plan`` whose runs failed (a record here or a row of its committed table),
    each with the failure's reason.

    Refuses (ValueError) a campaign with pending points (it has not ended: a point that fails later would miss
    the companion) or committed rows its spec no longer makes (the table of another grid)."""
    name = plan.spec.name
    if plan.pending:
        raise ValueError(f"campaign {name!r}: {len(plan.pending)} of its {len(plan.points)} points are pending "
                         f"(first {plan.pending[0][1]}); a companion is written once the campaign has ended")
    if plan.unmatched_rows:
        raise ValueError(f"campaign {name!r}: its table holds {len(plan.unmatched_rows)} row(s) its spec does not "
                         f"make (first {plan.unmatched_rows[0].get('key')}); is it the table of another grid?")
    failed = {k: plan.records[k] for _, k in plan.failed}
    failed.update({k: plan.archived_rows[k] for _, k in plan.archived_status("failed")})
    return [(p, str(failed[k].get("reason") or "")) for p, k in zip(plan.points, plan.keys) if k in failed]


def _check_line(spec: CampaignSpec) -> None:
    """A companion zips the failed points of one grid block; other campaigns are refused, saying why."""
    if len(spec.blocks) != 1 or spec.sampler["kind"] != "grid" or spec.replicates:
        raise ValueError(f"campaign {spec.name!r}: a companion is written for a one-block grid campaign without "
                         f"replicates (this one: {len(spec.blocks)} block(s), sampler {spec.sampler['kind']!r}, "
                         f"replicates {dict(spec.replicates) or 'none'})")


def _header(spec_path: Path, spec: CampaignSpec, failed, n_runs: int, options: Mapping[str, Any]) -> list[str]:
    change = ", ".join(f"{k} = {_literal(v)}" for k, v in options.items())
    lines = [f"# Companion of {spec_path.name} ({spec.name}), written by `dchfrac campaign companion`",
             f"# (sweep.campaign.companion): the {len(failed)} failed points of its {n_runs} runs, and only those,",
             f"# rerun with {change}; every other value is the campaign's (its other tables, copied).",
             "# Why, and how these runs are judged: that spec's header.  Units mm, s, kPa.",
             "# The failed runs (swept values; reason):"]
    for p, reason in failed:
        swept = ", ".join(f"{k} = {plain_value(v)}" for k, v in p.swept.items())
        wrapped = textwrap.wrap(f"{swept}; {reason}", 112)          # the whole reason, over as many lines as it takes
        lines += [f"#   {wrapped[0]}"] + [f"#     {w}" for w in wrapped[1:]]
    return lines


def companion_text(spec_path, results=None, *, options: Mapping[str, Any], suffix: str) -> str:
    """The TOML text of the companion of the campaign at ``spec_path``: its failed points (its run records
    under ``results``, default the spec project's results/, else its committed table) zipped, ``options`` set
    over the campaign's [options], named ``<name><suffix>``.  ValueError when the campaign has not ended, has no
    failed run, or ``options`` is empty."""
    spec_path = Path(spec_path)
    spec = load_spec(spec_path)
    _check_line(spec)
    if not options:
        raise ValueError("options: at least one option must change (the companion would rerun the same runs)")
    plan = plan_campaign(spec, results_root(spec, results), verify=False)
    failed = failed_points(plan)
    if not failed:
        raise ValueError(f"campaign {spec.name!r}: no failed run in its table, nothing to rerun")
    raw = read_toml(spec_path)
    d = {k: v for k, v in raw.items() if k not in _SWEPT_KEYS}
    d["name"] = spec.name + suffix
    d["description"] = f"{spec.name}'s failed points rerun with {dict(options)}: {raw.get('description', '')}"
    d["options"] = {**raw.get("options", {}), **options}
    d["mode"] = "zip"
    d["axes"] = {n: [plain_value(p.swept[n]) for p, _ in failed] for n in failed[0][0].swept}
    return "\n".join(_header(spec_path, spec, failed, len(plan.points), options)) + "\n" + _toml_text(d)


def write_companion(spec_path, results=None, *, options: Mapping[str, Any], suffix: str, out=None) -> Path:
    """Write :func:`companion_text` to ``out`` (default ``<spec folder>/<name><suffix>.toml``) and return its
    path.  The text is loaded as a campaign spec before it replaces anything (a bad option is refused, naming
    it); an existing ``out`` is refused (its runs may depend on it)."""
    text = companion_text(spec_path, results, options=options, suffix=suffix)
    spec_path = Path(spec_path)
    out = Path(out) if out is not None else spec_path.with_name(spec_path.stem + suffix + ".toml")
    if out.exists():
        raise FileExistsError(f"--out {out}: exists; a companion is written once (remove it to write it again)")
    tmp = out.with_name(f".{out.name}.tmp{os.getpid()}")
    try:
        tmp.write_text(text, encoding="utf-8")
        load_spec(tmp)
        os.replace(tmp, out)
    finally:
        tmp.unlink(missing_ok=True)
    return out


# ---------------------------------------------------------------------------
# ``dchfrac campaign companion`` (added to the campaign commands by sweep.campaign.cli)
# ---------------------------------------------------------------------------
def add_companion_command(sub) -> None:
    """Add ``companion`` to the ``dchfrac campaign`` subparsers ``sub``."""
    q = sub.add_parser("companion", help="write a campaign spec that reruns a campaign's failed points, and only "
                                         "those, with changed options (sweep.campaign.companion)")
    q.add_argument("spec", help="the campaign whose failed runs are rerun (spec TOML); it must have ended")
    q.add_argument("--set", dest="sets", action="append", required=True, metavar="KEY=VALUE",
                   help="an option changed in the companion; VALUE a TOML literal (h=1.0, transport='upwind') or a "
                        "bare string (transport=upwind); repeatable")
    q.add_argument("--suffix", required=True, help="the companion's name is the campaign's name + SUFFIX "
                                                   "(the experiment lines' fallback: _upwind_fallback)")
    q.add_argument("--results", default=None, metavar="DIR",
                   help="results root holding the campaign's committed table (default: results/ of the spec's project)")
    q.add_argument("--out", default=None, metavar="FILE", help="spec to write (default: <spec folder>/<name><SUFFIX>.toml)")
    q.set_defaults(func=cmd_companion)


def _set_value(item: str) -> tuple[str, object]:
    """``KEY=VALUE`` of ``--set``: VALUE read as a TOML literal, else as a string; ValueError without a KEY=."""
    from solver.tomlio import tomllib

    key, eq, text = item.partition("=")
    if not eq or not key.strip():
        raise ValueError(f"--set {item!r}: expected KEY=VALUE (e.g. transport=upwind)")
    try:
        value = tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        value = text
    return key.strip(), value


def cmd_companion(args) -> int:
    """Write the companion spec; a bad argument or a campaign that cannot have one: one line on stderr, exit 2."""
    import sys

    try:
        options = dict(_set_value(s) for s in args.sets)
        out = write_companion(args.spec, args.results, options=options, suffix=args.suffix, out=args.out)
    except (ValueError, FileExistsError) as e:   # SpecError is a ValueError
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(f"wrote {out}")
    return 0
