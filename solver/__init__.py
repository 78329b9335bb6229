"""dchfrac solver: the Darcy–Cahn–Hilliard model of multiphase fluid-driven fracture (Guevel et al., JMPS).

Public API::

    from solver import Parameters, RunOptions, preset_parameters, simulate
    res = simulate(Parameters(cement=1.2), RunOptions(h=1.0, t_end=2.0), out_dir="runs/ref")
    res = simulate(preset_parameters("experiment"), RunOptions(h=1.0, t_end=2.0))   # a named model

Units everywhere: mm, s, kPa (viscosity kPa·s, permeability mm², toughness kPa·mm).
``code_hash()`` names the solver source that made a result (recorded in every summary.json).
"""
__version__ = "0.1.0"

from .options import RunOptions
from .params import Parameters
from .presets import preset_parameters
from .simulate import SimulationResult, simulate


def code_hash() -> str:
    """Hash (16 hex digits) of the solver's source files: see :mod:`solver.codehash`."""
    from .codehash import code_hash as _code_hash

    return _code_hash()

__all__ = ["__version__", "code_hash", "Parameters", "preset_parameters", "RunOptions", "simulate", "SimulationResult"]
