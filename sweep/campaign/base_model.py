"""``[base] model = "FILE"`` of a campaign spec: a parameter file (e.g. the named model written by
``dchfrac discrepancy model``) taken as if its parameters were written in ``[base]``.

The path is relative to the spec file's folder (or absolute).  The file is a flat TOML table of
solver.Parameters fields (units mm, s, kPa).  It is read into the same layer as a ``preset`` (above it):
defaults that the other keys of the same ``[base]``, the axes and ``[derived]`` replace (e.g. k̄ swept in an
N_f–N_b grid; ``sweep.campaign.spec._base_defaults``).  A missing file, a file that is not TOML or a key that is not a
parameter is refused naming the spec key, the path and what is allowed, before any run.  The copy of the spec a
campaign keeps in its results folder points to copies of its model files there (:func:`spec_copy_text`).
"""
from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any, Mapping

from sweep.campaign.spec_model import SpecError, parameter_fields

__all__ = ["read_base_model", "spec_folder", "spec_copy_text"]

_ALLOWED = "a flat TOML table of solver.Parameters fields (as written by dchfrac discrepancy model)"


def spec_folder(source: str) -> Path:
    """The folder a spec's relative model paths start from: the spec file's, else the working folder."""
    p = Path(source)
    return p.parent if p.is_file() else Path(".")


def read_base_model(where: str, value: Any, folder: Path) -> dict:
    """The parameters of the model file ``value`` named at spec key ``where`` (``base.model``), relative to
    ``folder``; SpecError naming the key, the path and what is allowed."""
    from solver.tomlio import TOMLDecodeError, read_toml

    if not isinstance(value, str) or not value:
        raise SpecError(f"{where}: expected a path (text) to a parameter file, got {value!r}")
    p = Path(value) if Path(value).is_absolute() else folder / value
    if not p.is_file():
        raise SpecError(f"{where}: model file {value!r} not found (looked for {str(p)!r}, relative to the spec's "
                        f"folder); allowed: {_ALLOWED}")
    try:
        d = read_toml(p)
    except TOMLDecodeError as exc:
        raise SpecError(f"{where}: {exc}") from None
    pfields = parameter_fields()
    for k, v in d.items():
        if k not in pfields or isinstance(v, dict):
            raise SpecError(f"{where}: {str(p)!r} sets {k!r}, which is not a model parameter; allowed: {_ALLOWED}: "
                            f"{sorted(pfields)}")
    return d


def _has_model(tbl) -> bool:
    return isinstance(tbl, Mapping) and isinstance(tbl.get("base"), Mapping) and "model" in tbl["base"]


# a ``model = "..."`` entry (a line of a [base] table or a key of an inline table) and its string literal
_MODEL_ENTRY = re.compile(r"""(?<![\w.-])(model\s*=\s*)("[^"\n]*"|'[^'\n]*')""")


def _model_values(d: Mapping) -> list:
    """The ``[base] model`` values of the parsed spec ``d`` (top level, then blocks)."""
    blocks = d.get("blocks")
    tables = [d, *(blocks if isinstance(blocks, list) else [])]
    return [t["base"]["model"] for t in tables if _has_model(t)]


def spec_copy_text(src: Path, dest: Path) -> str:
    """The text of spec file ``src`` for its copy in folder ``dest`` (a campaign's results folder): each model
    file it names is copied to ``dest/base_models/`` and its ``model = "..."`` entry points there, so the copy
    reads the same parameters where it lies.  The text of ``src`` when it names no model file."""
    from solver.output import atomic_write_text
    from solver.tomlio import read_toml

    text = src.read_text()
    values = list(dict.fromkeys(v for v in _model_values(read_toml(src)) if isinstance(v, str)))
    new = {}
    for i, v in enumerate(values):
        p = Path(v) if Path(v).is_absolute() else src.parent / v
        if p.resolve().parent == (dest / "base_models").resolve():     # a copy's copy: the same file
            new[v] = f"base_models/{p.name}"
            continue
        new[v] = f"base_models/{i}_{p.name}"
        atomic_write_text(dest / new[v], p.read_text())

    def sub(m):
        literal = m.group(2)
        v = literal[1:-1] if literal[0] == "'" else json.loads(literal)
        return m.group(1) + json.dumps(new[v]) if v in new else m.group(0)

    return _MODEL_ENTRY.sub(sub, text)
