"""Catalogue of named model ingredients ("effects"), each switched by one strength parameter.

Every effect is a field of :class:`solver.Parameters` whose *off* value gives back
the model without that ingredient exactly (the solver tests ``== off``, so the
off model is the same code path, not a small strength).  A *baseline* is any
model with some effects off; the discrepancy workflow (``sweep.discrepancy``)
asks which of the off effects the measured data call for.

``EFFECTS`` maps name -> :class:`Effect` (a tuple ``(parameter, off, description,
signature, ...)``, so ``param, off, desc, sig = EFFECTS[name][:4]`` works).

Units follow :mod:`solver.params`: β in kPa·s, compliance in mm/kPa, the
other strengths are dimensionless factors.
"""
from __future__ import annotations

from typing import NamedTuple

__all__ = ["Effect", "EFFECTS", "effect_names", "get_effect", "is_off", "switch_off", "off_effects", "effect_strength"]


class Effect(NamedTuple):
    """One model ingredient.

    parameter : name of the :class:`solver.Parameters` field holding the strength.
    off : strength value that removes the ingredient exactly.
    description : what the ingredient is (with the paper's equation).
    signature : the physical fingerprint expected in the observables.
    paper : strength of the paper's model (None = a law of C, for β).
    upper : largest strength the workflow explores (same unit as the parameter).
    probe : strength used for one cheap signature run (screening).
    unit : unit of the strength.
    """

    parameter: str
    off: float
    description: str
    signature: str
    paper: float | None
    upper: float
    probe: float
    unit: str


EFFECTS: dict[str, Effect] = {
    "damage_viscosity": Effect(
        "beta", 0.0,
        "damage viscosity β (kPa·s) in the fracture equation (Eq. fracture_equation): rate-dependent fracture, "
        "β ḋ resists damage growth; the paper's law β = 65.7 √C (Sec. 3.6)",
        "slower damage growth: higher and later injection-pressure peak, delayed crack initiation, shorter cracks; "
        "the fracturing threshold in Ca* moves up with C",
        None, 400.0, 40.0, "kPa·s"),
    "volumetric_coupling": Effect(
        "volumetric_coupling", 0.0,
        "factor c_v on the second-order terms φ S ε̇_v and φ ε̇_v of the mass balances (Eqs. summary_equations_1,2)",
        "a volume source/sink where the skeleton dilates: changes the injected-volume split between storage and "
        "flow, small shift of front radius and pressure during fast loading",
        1.0, 1.0, 1.0, "-"),
    "korteweg_stress": Effect(
        "korteweg_factor", 0.0,
        "factor on κ in the capillary (Korteweg) stress terms (Eq. summary_equations_secondary)",
        "extra stress localized at the fluid–fluid interface: a pressure jump across the front and a different "
        "front shape (smoother fingers)",
        1.0, 1.0, 1.0, "-"),
    "compliant_boundary": Effect(
        "outer_compliance", 0.0,
        "spring on the outer circle, compliance (mm/kPa) replacing u = 0 (0 = rigid, the paper)",
        "softer overall response: lower injection pressure rising more slowly, larger displacements near the "
        "outer wall, little effect on the front at early times",
        0.0, 0.2, 0.02, "mm/kPa"),
    "crack_permeability": Effect(
        "crack_permeability", 0.0,
        "blend s of the porosity-dependent Kozeny–Carman permeability capped by the Poiseuille value h²/12 "
        "(Eq. permeability): k = k(φ0) + s (min(k(φ), k_max) − k(φ0)); off = k frozen at k(φ0)",
        "the fluid channels into opened cracks: pressure plateau/drop after initiation, faster front along "
        "cracks; nothing before initiation",
        1.0, 1.0, 1.0, "-"),
}


def effect_names() -> list[str]:
    """Names of the catalogued effects, in catalogue order."""
    return list(EFFECTS)


def get_effect(name: str) -> Effect:
    """The :class:`Effect` called ``name``; ValueError naming the allowed names otherwise."""
    try:
        return EFFECTS[name]
    except KeyError:
        raise ValueError(f"effect {name!r} is not in the catalogue; allowed: {effect_names()}") from None


def effect_strength(params, name: str) -> float:
    """Resolved strength of effect ``name`` in ``params`` (β follows its law of C when ``beta`` is None)."""
    e = get_effect(name)
    if e.parameter == "beta":
        return float(params.damage_viscosity)
    return float(getattr(params, e.parameter))


def is_off(params, name: str) -> bool:
    """True when effect ``name`` is exactly at its off value in ``params``."""
    return effect_strength(params, name) == get_effect(name).off


def switch_off(params, *names: str):
    """Copy of ``params`` with the named effects at their off values."""
    return params.replace(**{get_effect(n).parameter: get_effect(n).off for n in names})


def off_effects(params) -> list[str]:
    """Names of the effects that are off in ``params`` (the candidates of a baseline)."""
    return [n for n in EFFECTS if is_off(params, n)]
