"""dchfrac's studies over the solver, in four floors (each imports only those below it, and ``solver``):

* ``sweep.regimes``: what a run *is*: the regime classifier, the dimensionless numbers, the regime model and
  the phase diagrams (no campaign machinery);
* ``sweep.campaign``: the campaign engine: specs, samplers, scheduler, run store, tables, loaders, reports;
* ``sweep.studies``: studies of the paper built on campaigns: the reference run, the fidelity study, label
  agreement over realizations, threshold sensitivity, benchmarks;
* ``sweep.discrepancy``: the discrepancy workflow (measured data -> the missing effect);
* ``sweep.cli`` (the ``dchfrac`` command) and ``sweep.animate`` on top.

The public loaders::

    from sweep import load_campaign, load_timeseries, load_run
"""
from .campaign.load import load_campaign, load_timeseries
from .campaign.run_folder import load_run

__all__ = ["load_campaign", "load_timeseries", "load_run"]
