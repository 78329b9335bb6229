"""Discrepancy workflow: find where simulation and measured data disagree, name the missing effect
(from solver.effects.EFFECTS), add it, show the held-out gap shrink.  Units mm, s, kPa.

    from sweep.discrepancy import load_measured, load_spec, SolverForward, run_workflow
    CLI: dchfrac discrepancy init --measured DIR [--out SPEC]       (a commented starting SPEC from the data)
         dchfrac discrepancy run --measured DIR --model SPEC --out DIR

How a run goes through the code (stages in workflow.py, pieces in their modules): results/discrepancy/DESIGN_NOTES.md.
"""
from .cli import add_discrepancy_commands
from .data import OBSERVABLES, MeasuredData, load_measured, write_measured
from .forward import ForwardModel, SolverForward
from .spec import DiscrepancySpec, load_spec, spec_from_dict
from .toy import ToyForward
from .twin import make_twin
from .workflow import VERDICTS, run_workflow

__all__ = ["add_discrepancy_commands", "OBSERVABLES", "MeasuredData", "load_measured", "write_measured",
           "ForwardModel", "SolverForward", "DiscrepancySpec", "load_spec", "spec_from_dict", "ToyForward",
           "make_twin", "VERDICTS", "run_workflow"]
