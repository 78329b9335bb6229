"""Plausible ranges: a value outside the range an experiment of the model's kind can have, read as a likely
unit slip (units mm, s, kPa).

A parameter's or run option's plausible range sits beside its allowed range in its one declaration
(``solver.params._param``, ``solver.options._NUMBERS``).  A value that is allowed but implausible runs with a
warning naming the likely slip (``E = 331000 kPa is 331 MPa: did you mean Pa?``); ``--strict`` refuses it.
"""
from __future__ import annotations

import math

__all__ = ["SLIPS", "did_you_mean", "implausible", "slip_hint", "slip_message"]

#: unit -> [(the unit a user may have meant, factor)]: a value v given in that unit reads as v * factor too
#: much in ours (E = 331 000 "kPa" typed in Pa is 1000 times the 331 kPa meant)
SLIPS = {
    "kPa": [("Pa", 1e3), ("MPa", 1e-3), ("GPa", 1e-6)],
    "kPa·s": [("Pa·s", 1e3), ("mPa·s", 1e6)],
    "kPa·mm": [("mN/m (= Pa·mm)", 1e3)],
    "mm": [("µm", 1e3), ("cm", 0.1), ("m", 1e-3)],
    "mm²": [("µm²", 1e6), ("cm²", 1e-2), ("m²", 1e-6)],
    "mm/s": [("µm/s", 1e3), ("cm/s", 0.1), ("m/s", 1e-3)],
    "s": [("ms", 1e3), ("min", 1.0 / 60.0)],
    "%": [("a fraction (0.012 for 1.2 %)", 1e-2)],
}


def implausible(value, plausible) -> bool:
    """Is the number ``value`` outside the closed range ``plausible`` = (lo, hi) (None: no range)?"""
    return plausible is not None and value is not None and not plausible[0] <= value <= plausible[1]


def _restate(value: float, unit: str) -> str:
    """A large pressure restated in MPa ("331000 kPa is 331 MPa"), else ""."""
    if unit == "kPa" and abs(value) >= 1e3:
        return f" is {value / 1e3:g} MPa"
    return ""


def slip_hint(name: str, value, unit: str, plausible, reference=None) -> str:
    """``name = value unit``, restated, with the unit slip that brings it inside ``plausible`` = (lo, hi)
    (``E = 331000 kPa is 331 MPa: did you mean Pa?``), or "check its value and unit".  Of several such slips,
    the one that brings it nearest (in ratio) to ``reference`` (the default, > 0), else the first."""
    lo, hi = plausible
    u = f" {unit}" if unit not in ("-", "") else ""
    guess = [(meant, f) for meant, f in SLIPS.get(unit, ()) if lo <= value / f <= hi]
    if reference and reference > 0 and value > 0:
        guess.sort(key=lambda g: abs(math.log(value / g[1] / reference)))
    why = f"did you mean {guess[0][0]}?" if guess else "check its value and unit (mm, s, kPa)"
    return f"{name} = {value:g}{u}{_restate(value, unit)}: {why}"


def slip_message(kind: str, name: str, value, unit: str, plausible, reference=None) -> str:
    """The warning for an implausible ``value`` of the ``kind`` ("parameter", "run option") ``name``: its
    value in its unit, the unit slip that brings it inside the plausible range (:func:`slip_hint`), the range."""
    u = f" {unit}" if unit not in ("-", "") else ""
    return (f"{kind} {slip_hint(name, value, unit, plausible, reference)} (plausible range [{plausible[0]:g}, "
            f"{plausible[1]:g}]{u}; --strict refuses it)")


def did_you_mean(unknown, names) -> str:
    """' (did you mean 'E'?)' for the known ``names`` closest to the first of the ``unknown`` names, else ''."""
    import difflib

    close = difflib.get_close_matches(str(next(iter(unknown), "")), list(names), n=1, cutoff=0.6)
    if not close:
        close = [n for n in names if n.lower() == str(next(iter(unknown), "")).lower()]
    return f" (did you mean {close[0]!r}?)" if close else ""
