"""dchfrac solver: the Darcy–Cahn–Hilliard model of multiphase fluid-driven fracture (Guevel et al., JMPS).

Public API::

    from solver import Parameters, RunOptions, simulate
    res = simulate(Parameters(cement=1.2), RunOptions(h=1.0, t_end=2.0), out_dir="runs/ref")

Units everywhere: mm, s, kPa (viscosity kPa·s, permeability mm², toughness kPa·mm).
"""
__version__ = "0.1.0"

from .options import RunOptions
from .params import Parameters
from .simulate import SimulationResult, simulate

__all__ = ["__version__", "Parameters", "RunOptions", "simulate", "SimulationResult"]
