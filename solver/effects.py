"""Catalogue of named model ingredients ("effects"), each switched by one strength parameter.

Every effect is a field of :class:`solver.Parameters` whose *off* value gives back
the model without that ingredient exactly (the solver tests ``== off``, so the
off model is the same code path, not a small strength).  A *baseline* is any
model with some effects off; the discrepancy workflow (``sweep.discrepancy``)
asks which of the off effects the measured data call for.

``EFFECTS`` maps name -> :class:`Effect` (a tuple ``(parameter, off, description,
signature, ...)``, so ``param, off, desc, sig = EFFECTS[name][:4]`` works).

Units follow :mod:`solver.params`: β in kPa·s, the outer and cell compliances
in mm/kPa, the line compliance in mm²/kPa, the other strengths are
dimensionless factors.  Each effect's residual terms are written point-wise on
the unknowns (the weak form, or a lumped boundary term on the nodes), so the
Newton Jacobian follows from dual numbers and stays exact
(``tests/test_jacobian.py``, ``tests/test_cell_effects.py``).
"""
from __future__ import annotations

import math
from typing import NamedTuple

__all__ = ["Effect", "EFFECTS", "effect_names", "get_effect", "is_off", "switch_off", "off_effects", "effect_strength",
           "plate_bending_compliance", "tube_compliance"]


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
    estimate : an independent estimate of the strength in the experiment and where it comes from ("" if none).
    """

    parameter: str
    off: float
    description: str
    signature: str
    paper: float | None
    upper: float
    probe: float
    unit: str
    estimate: str = ""


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
    "elastic_cell": Effect(
        "cell_compliance", 0.0,
        "elastic Hele-Shaw cell: the plates open a gap delta = c_cell p+ (mm) above the pack, which stores delta/h of "
        "fluid and carries both fluids with transmissivity delta^3/12 in parallel with the pack "
        "(solver.physics.cell_gap; Pihler-Puzovic et al., PRL 108, 074502, 2012)",
        "an apparent compliance: p_inj rises more slowly and bends toward a plateau as the gap's transmissivity "
        "(~ p^3) opens a bypass; water runs ahead of the pack front near the inlet, where p is highest",
        0.0, 2e-3, 5e-4, "mm/kPa",
        "plate bending, :func:`plate_bending_compliance`: two clamped acrylic plates (E = 3 GPa, nu = 0.35) of "
        "radius 53 mm: 8.7e-4 mm/kPa at 10 mm thick, 1.1e-4 at 20 mm (delta 0.4 / 0.05 mm at 470 kPa)"),
    "line_compliance": Effect(
        "line_compliance", 0.0,
        "lumped compliance C_line (mm^2/kPa per unit cell height) of the injection line and cavity: the pack "
        "receives w_i - (C_line/L_i) dp/dt on r_i (solver.physics.line_storage_rate)",
        "a delayed, exponential pressure rise with time constant C_line x the pack's resistance; the front lags "
        "the pumped volume early and catches up once p_inj stops rising",
        0.0, 20.0, 3.0, "mm^2/kPa",
        "tubing swelling, :func:`tube_compliance`: 1 m of flexible tubing, inner radius 2 mm, wall 1 mm, "
        "E = 10 MPa: 5.0 mm^3/kPa, 2.6 mm^2/kPa per unit cell height (the rig's tubing is not reported: an "
        "order of magnitude; water's own compressibility adds 0.006 mm^3/kPa)"),
    "critical_saturation": Effect(
        "critical_saturation", 0.0,
        "critical saturation S_c (-) of the invading water: immobile below S_c, the paper's k_r1 of the reduced "
        "saturation (S - S_c)/(1 - S_c) above (Eq. relative_permeabilities; "
        "solver.physics.relative_permeabilities)",
        "no water precursor at a few percent saturation ahead of the front: the water stays behind a compact "
        "front and displaces the oil, so less water leaves through r_o early, p_inj rises higher and the front "
        "and cracks move out; nothing where the paper's law already keeps S near 0 or 1",
        0.0, 0.5, 0.1, "-"),
}


def plate_bending_compliance(E: float = 3.0e6, nu: float = 0.35, thickness: float = 10.0, radius: float = 53.0,
                             plates: int = 2) -> float:
    """Gap opening per pressure (mm/kPa) of ``plates`` clamped circular plates under a uniform pressure: the
    centre deflection w = p a^4 / (64 D) of each, D = E t^3 / (12 (1 - nu^2)) (Timoshenko and
    Woinowsky-Krieger, Theory of Plates and Shells, Sec. 62).  E kPa (acrylic about 3 GPa = 3e6 kPa), nu (-),
    thickness t and radius a in mm.  An upper bound of the local c_cell: the pressure falls from the inlet to r_o."""
    D = E * thickness**3 / (12.0 * (1.0 - nu * nu))
    return plates * radius**4 / (64.0 * D)


def tube_compliance(length: float = 1000.0, radius: float = 2.0, wall: float = 1.0, E: float = 1.0e4,
                    cell_height: float = 1.96) -> float:
    """Compliance of a thin-walled tube per unit cell height (mm^2/kPa): dV/dp = pi r^2 L (2 r / (E w)) (hoop
    strain r/(E w) per kPa, doubled for the area), divided by the cell height (mm).  length L, radius r,
    wall thickness w in mm, E in kPa (flexible PVC about 10 MPa = 1e4 kPa)."""
    return math.pi * radius**2 * length * 2.0 * radius / (E * wall) / cell_height


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
