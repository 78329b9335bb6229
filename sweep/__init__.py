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

They load on first use (``_LAZY``), so that the ``dchfrac`` command line does not import pandas before it needs it.
"""
from importlib import import_module

#: public name -> the submodule that defines it
_LAZY = {"load_campaign": "campaign.load", "load_timeseries": "campaign.load", "load_run": "campaign.run_folder"}


def __getattr__(name):
    if name not in _LAZY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(import_module(f".{_LAZY[name]}", __name__), name)


__all__ = ["load_campaign", "load_timeseries", "load_run"]
