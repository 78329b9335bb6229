"""Named models ("presets"): the paper's model as written, and the model of the reference experiment.

A preset is a set of parameter changes from the defaults of :class:`solver.Parameters` (units mm, s, kPa);
``preset_parameters(name, **changes)`` (also ``from solver import preset_parameters``) gives its validated
parameters, ``dchfrac run --preset NAME`` runs it, ``dchfrac params`` lists the presets, and a campaign spec's
``[base]`` takes ``preset = "NAME"``.

* ``paper``: the defaults, the paper's reference experiment as written (Sec. 3.3–3.5, Table A): w_i = 50 mm/s
  ("chosen to match the experimental injection pressure curve"), S = 0 and μ = μ_o on r_o (Sec. 3.4).
* ``experiment``: the measured inputs where the experiment gives them.  The injection rate is the pump's
  q = 100 mL/min spread over the inlet's lateral surface, w_i = q / (2π r_i h) (:func:`measured_injection_velocity`,
  27.07 mm/s), and r_o is an outlet reservoir at p = 0 (``outer_saturation_bc = "outflow"``) with no
  chemical-potential flux (``mu_outer_bc = "zero_flux"``): both phases leave as they arrive, nothing but oil
  enters, water leaves only once it has reached r_o.  The inlet admits the pumped water and nothing else
  (``inner_saturation_bc = "injection"``): the paper's S = 1 and μ = μ_i > 0 on r_i draw water in by the
  Cahn–Hilliard flux beyond the pump's rate (13 % more by 2 s at h = 4 mm) and let oil out into the cavity.  Why (results/fidelity/README.md, issue #47): the paper's
  model keeps its 470 kPa only by losing about half the water through an unresolved outer wall, and its μ_o lies
  above the spinodal, so it pulls water in at r_o.
"""
from __future__ import annotations

import math

from .params import Parameters

#: the reference experiment's pump rate, mm³/s (100 mL/min; Sec. 3.5)
EXPERIMENT_FLOW_RATE = 100.0 * 1000.0 / 60.0
#: the gap of the experiment's Hele–Shaw cell and its inlet radius, mm (Table A, Sec. 3.5)
EXPERIMENT_CELL_HEIGHT = 1.96
EXPERIMENT_INNER_RADIUS = 5.0


def measured_injection_velocity(flow_rate: float = EXPERIMENT_FLOW_RATE, cell_height: float = EXPERIMENT_CELL_HEIGHT,
                                inner_radius: float = EXPERIMENT_INNER_RADIUS) -> float:
    """Darcy velocity w_i = q / (2π r_i h) (mm/s) of a flow rate q (mm³/s) entering through the lateral surface of
    the inlet, radius r_i (mm), over the cell height h (mm): 27.07 mm/s for the experiment's 100 mL/min."""
    for name, v in (("flow_rate", flow_rate), ("cell_height", cell_height), ("inner_radius", inner_radius)):
        if not v > 0:
            raise ValueError(f"{name}={v!r} is out of range: allowed > 0")
    return flow_rate / (2.0 * math.pi * inner_radius * cell_height)


def _presets() -> dict[str, tuple[str, dict]]:
    return {
        "paper": ("the paper's model as written: the defaults (Sec. 3.3-3.5, Table A)", {}),
        "experiment": ("measured rate w_i = q/(2 pi r_i h), q = 100 mL/min, all of it water through r_i; outlet "
                       "reservoir at p = 0 on r_o, zero mu flux (issue #47)",
                       {"w_i": measured_injection_velocity(), "cell_height": EXPERIMENT_CELL_HEIGHT,
                        "r_inner": EXPERIMENT_INNER_RADIUS, "outer_saturation_bc": "outflow",
                        "mu_outer_bc": "zero_flux", "inner_saturation_bc": "injection"}),
    }


PRESETS = _presets()


def preset_names() -> list[str]:
    """The preset names, in declaration order."""
    return list(PRESETS)


def preset_changes(name: str) -> dict:
    """The parameter changes (from the defaults) of preset ``name``; ValueError naming the allowed names."""
    if name not in PRESETS:
        raise ValueError(f"preset {name!r} is not defined; allowed: {preset_names()}")
    return dict(PRESETS[name][1])


def preset_description(name: str) -> str:
    """One line saying what preset ``name`` is."""
    preset_changes(name)
    return PRESETS[name][0]


def preset_parameters(name: str, **changes) -> Parameters:
    """Validated :class:`solver.Parameters` of preset ``name`` with ``changes`` on top (units mm, s, kPa)."""
    return Parameters(**{**preset_changes(name), **changes})
