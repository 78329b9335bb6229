"""Flat TOML files for Parameters and RunOptions (stdlib tomllib to read, a tiny writer)."""
from __future__ import annotations

import json
from pathlib import Path

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib



class TOMLDecodeError(ValueError):
    """Raised by :func:`read_toml` on malformed TOML or a file that is not UTF-8 text; the message names the
    file (and, for malformed TOML, the line and column)."""


def toml_value(v) -> str:
    """TOML literal of a bool, string, int, float or list of those (floats round-trip exactly via repr)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, int):
        return str(v)
    return repr(float(v))


def write_flat_toml(path, d: dict, header: str | None = None) -> None:
    """Write ``d`` as a flat TOML table; None values are omitted (they mean 'default')."""
    lines = [f"# {header}"] if header else []
    lines += [f"{k} = {toml_value(v)}" for k, v in d.items() if v is not None]
    Path(path).write_text("\n".join(lines) + "\n")


def read_toml(path) -> dict:
    """Parse the TOML file ``path`` (the one TOML reader of the project; tomli on Python 3.10): UTF-8 text,
    with or without a byte-order mark.  Raises :class:`TOMLDecodeError` naming the file."""
    p = Path(path)
    try:
        text = p.read_bytes().decode("utf-8-sig")      # a BOM (written by some editors) is not TOML: dropped
    except UnicodeDecodeError as exc:
        raise TOMLDecodeError(f"{p}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise TOMLDecodeError(f"{p}: invalid TOML: {exc}") from None
