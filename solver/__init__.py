"""dchfrac solver: the Darcy–Cahn–Hilliard model of multiphase fluid-driven fracture (Guevel et al., JMPS).

Public API::

    from solver import Parameters, RunOptions, preset_parameters, simulate
    res = simulate(Parameters(cement=1.2), RunOptions(h=1.0, t_end=2.0), out_dir="runs/ref")
    res = simulate(preset_parameters("experiment"), RunOptions(h=1.0, t_end=2.0))   # a named model

Units everywhere: mm, s, kPa (viscosity kPa·s, permeability mm², toughness kPa·mm).
``code_hash()`` names the solver source that made a result (recorded in every summary.json).

The public names load on first use (``_LAZY``): importing a light module such as ``solver.budget`` or
``solver.params`` does not load the assembly, the sparse solvers or numba, so that the command line checks its
input and the memory budget before the heavy libraries load.  ``solver.simulate`` is the function (the module is
``importlib.import_module("solver.simulate")``), also after the submodule has been imported.
"""
import sys
import types
from importlib import import_module

__version__ = "0.1.0"

#: public name -> the submodule that defines it
_LAZY = {"Parameters": "params", "preset_parameters": "presets", "RunOptions": "options", "simulate": "simulate",
         "SimulationResult": "simulate"}


def code_hash() -> str:
    """Hash (16 hex digits) of the solver's source files: see :mod:`solver.codehash`."""
    from .codehash import code_hash as _code_hash

    return _code_hash()


def __getattr__(name):
    if name not in _LAZY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(f".{_LAZY[name]}", __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted({*globals(), *_LAZY})


class _Package(types.ModuleType):
    """The package, whose attribute ``simulate`` stays the function when the import system binds the submodule
    of the same name to it."""

    def __setattr__(self, name, value):
        if name == "simulate" and isinstance(value, types.ModuleType):
            return
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package

__all__ = ["__version__", "code_hash", "Parameters", "preset_parameters", "RunOptions", "simulate", "SimulationResult"]
