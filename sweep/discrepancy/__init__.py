"""Discrepancy workflow: find where simulation and measured data disagree, name the missing effect
(from solver.effects.EFFECTS), add it, show the held-out gap shrink.  Units mm, s, kPa.

    from sweep.discrepancy import load_measured, load_spec, SolverForward, run_workflow
    CLI: dchfrac discrepancy init --measured DIR [--out SPEC]       (a commented starting SPEC from the data)
         dchfrac discrepancy run --measured DIR --model SPEC --out DIR

How a run goes through the code (stages in workflow.py, pieces in their modules): results/discrepancy/DESIGN_NOTES.md.
The names load on first use (``_LAZY``): the ``dchfrac`` parser adds the discrepancy commands without importing the
workflow.
"""
from importlib import import_module

#: public name -> the submodule that defines it
_LAZY = {"add_discrepancy_commands": "cli", "OBSERVABLES": "data", "MeasuredData": "data", "load_measured": "data",
         "write_measured": "data", "ForwardModel": "forward", "SolverForward": "forward", "DiscrepancySpec": "spec",
         "load_spec": "spec", "spec_from_dict": "spec", "ToyForward": "toy", "make_twin": "twin",
         "VERDICTS": "workflow", "run_workflow": "workflow"}


def __getattr__(name):
    if name not in _LAZY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(import_module(f".{_LAZY[name]}", __name__), name)


__all__ = ["add_discrepancy_commands", "OBSERVABLES", "MeasuredData", "load_measured", "write_measured",
           "ForwardModel", "SolverForward", "DiscrepancySpec", "load_spec", "spec_from_dict", "ToyForward",
           "make_twin", "VERDICTS", "run_workflow"]
