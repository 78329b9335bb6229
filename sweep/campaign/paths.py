"""Where a campaign's results are: the results root resolved against the spec's project, not the working directory.

The project root of a spec is the folder holding the ``campaigns/`` folder the spec lives in
(``<project>/campaigns/studies/foo.toml`` -> ``<project>``).  A relative results root (the default
``results``) is taken from there, so ``load_campaign("…/campaigns/studies/foo.toml")`` reads
``…/results/foo`` from any directory.  A spec outside a ``campaigns/`` folder, or given as a dict, keeps
the working directory as its base.  An absolute root is used as it is; the CLI makes a ``--results`` the
user typed absolute against the working directory before it gets here.
"""
from __future__ import annotations

from pathlib import Path

__all__ = ["DEFAULT_ROOT", "project_root", "results_root"]

DEFAULT_ROOT = "results"


def project_root(spec_path) -> Path | None:
    """The folder holding the ``campaigns/`` folder that contains ``spec_path``, None if it is in none."""
    try:
        p = Path(spec_path).resolve()
    except (OSError, RuntimeError, TypeError):
        return None
    for parent in p.parents:
        if parent.name == "campaigns":
            return parent.parent
    return None


def results_root(spec, root=DEFAULT_ROOT) -> Path:
    """The results root of ``spec`` (a CampaignSpec or a spec path): ``root`` if absolute, else ``root`` under
    the spec's project root (:func:`project_root`), else under the working directory."""
    root = Path(DEFAULT_ROOT if root is None else root)
    if root.is_absolute():
        return root
    source = getattr(spec, "source", spec)
    base = project_root(source) if source is not None else None
    return (base / root) if base is not None else root
