"""dchfrac campaigns: specs, scheduler, results store, classifier, diagrams, loaders.

    from sweep import load_campaign, load_timeseries
"""
from .load import load_campaign, load_timeseries

__all__ = ["load_campaign", "load_timeseries"]
