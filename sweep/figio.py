"""Writing a figure file: atomically and reproducibly.

Atomically: through ``solver.output.atomic_path``, so a reader never sees a partial figure.  Reproducibly: without
a creation date (PDF ``CreationDate``, SVG ``Date``) and with a fixed SVG id salt, so that a figure redrawn from an
unchanged table is the same file byte for byte (``dchfrac campaign redraw`` then changes only what changed).
"""
from __future__ import annotations

from pathlib import Path

__all__ = ["write_figure", "FIGURE_FORMATS"]

FIGURE_FORMATS = ("png", "pdf", "svg")
_NO_DATE = {"png": {}, "pdf": {"CreationDate": None}, "svg": {"Date": None}}


def write_figure(fig, path, *, fmt: str | None = None, **savefig_kw) -> Path:
    """Write ``fig`` to ``path`` (format ``fmt``, else the path's suffix: png, pdf or svg) atomically and without a
    date; ``savefig_kw`` go to ``Figure.savefig`` (``dpi``, ``bbox_inches``).  Returns the path."""
    import matplotlib

    from solver.output import atomic_path

    path = Path(path)
    fmt = (fmt or path.suffix.lstrip(".")).lower()
    if fmt not in FIGURE_FORMATS:
        raise ValueError(f"figure format: {fmt!r} ({path}) is not allowed; use one of {', '.join(FIGURE_FORMATS)}")
    with matplotlib.rc_context({"svg.hashsalt": "dchfrac"}), atomic_path(path) as tmp:
        fig.savefig(tmp, format=fmt, metadata=_NO_DATE[fmt], **savefig_kw)
    return path
