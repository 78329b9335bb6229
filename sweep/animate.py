"""Animation of a run folder's snapshots: one panel per field, fixed colour scales, a time stamp.

    dchfrac animate RUN [--fields S,phi,d,p] [--out FILE] [--fps 6]

Writes an MP4 when matplotlib has an ffmpeg writer, else a GIF (Pillow). For a smooth movie run the
solver with ``RunOptions(frames=N)``: t = 0 plus N evenly spaced snapshots. x, y in mm; field units
from ``solver.output.SNAPSHOT_FIELDS``.
"""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from solver.output import atomic_path

__all__ = ["ANIMATABLE", "animation_writer", "build_animation", "animate_run", "parse_fields", "check_animatable"]

# scalar snapshot fields (the displacement u is a vector)
ANIMATABLE = ("S", "phi", "d", "p", "mu", "eps_v", "hoop_stress", "k", "w1_mag")
_FIXED = {"S": (0.0, 1.0), "phi": (0.0, 1.0), "d": (0.0, 1.0)}


def parse_fields(text: str) -> tuple[str, ...]:
    """``"S,phi,d"`` -> ("S", "phi", "d"); an unknown name raises ValueError naming it and the allowed ones."""
    names = tuple(n.strip() for n in str(text).split(",") if n.strip())
    bad = [n for n in names if n not in ANIMATABLE]
    if not names or bad:
        raise ValueError(f"--fields {text!r}: unknown field(s) {bad or '(none given)'}; allowed: {', '.join(ANIMATABLE)}")
    return names


def check_animatable(run_dir, fields: Sequence[str]) -> int:
    """The number of snapshots of ``run_dir`` that hold every field of ``fields``; ValueError naming what is
    missing (no snapshots, fewer than 2, or fields the snapshots lack: a pruned campaign run keeps one
    snapshot with t, S and phi)."""
    from sweep.campaign.run_folder import load_run

    run = load_run(run_dir)
    pruned = " (pruned: `dchfrac campaign prune` keeps the classified snapshot's t, S, phi)" \
        if any("(pruned)" in m for m in run.missing) else ""
    if run.mesh is None or not run.snapshots:
        raise ValueError(f"run {str(run_dir)!r}: nothing to animate: missing {', '.join(run.missing)}")
    lacking = sorted({f for s in run.snapshots for f in fields if f not in s})
    if lacking:
        held = sorted(k for k in run.snapshots[0] if k in ANIMATABLE)
        raise ValueError(f"run {str(run_dir)!r}: its snapshots hold {', '.join(held) or 'no field'}, not "
                         f"{', '.join(lacking)}{pruned}; pick --fields among those")
    if len(run.snapshots) < 2:
        raise ValueError(f"run {str(run_dir)!r}: one snapshot (t = {run.times[0]:g} s){pruned}: nothing to animate; "
                         f"rerun it with --set frames=N")
    return len(run.snapshots)


def animation_writer(out: Path | None):
    """(writer name, suffix): ffmpeg and .mp4 when available, else pillow and .gif; an ``out`` suffix must match."""
    from matplotlib import animation

    ffmpeg = animation.writers.is_available("ffmpeg")
    if out is not None and Path(out).suffix.lower() == ".mp4" and not ffmpeg:
        raise ValueError(f"--out {str(out)!r}: an MP4 needs ffmpeg, which matplotlib cannot find; use a .gif name")
    if out is not None and Path(out).suffix.lower() not in (".mp4", ".gif"):
        raise ValueError(f"--out {str(out)!r}: allowed suffixes .mp4 (with ffmpeg) or .gif")
    if out is not None:
        return ("ffmpeg", ".mp4") if Path(out).suffix.lower() == ".mp4" else ("pillow", ".gif")
    return ("ffmpeg", ".mp4") if ffmpeg else ("pillow", ".gif")


def build_animation(run_dir, fields: Sequence[str] = ("S", "phi", "d", "p")):
    """(figure, update(k), number of frames) of a run folder: one panel per field with its colorbar, each
    field on one colour scale over all frames, the S = 0.5 front in white, the time in the title."""
    from matplotlib.figure import Figure
    from matplotlib.tri import Triangulation

    from solver.output import SNAPSHOT_FIELDS, load_run
    from sweep.campaign.figures import axis_label, colour_scale

    pts, tri, snaps = load_run(run_dir)
    if not snaps:
        raise ValueError(f"run {str(run_dir)!r}: no snapshots to animate")
    missing = [f for f in fields if f not in snaps[0][1]]
    if missing:
        raise ValueError(f"run {str(run_dir)!r}: snapshots have no field(s) {missing}")
    T = Triangulation(pts[:, 0], pts[:, 1], tri)
    fig = Figure(figsize=(3.4 * len(fields), 3.4), layout="constrained")
    axes = fig.subplots(1, len(fields), squeeze=False)[0]
    meshes = []
    for ax, name in zip(axes, fields):
        cmap, lo, hi = colour_scale(name, [f[name] for _, f in snaps], fixed=_FIXED.get(name))
        vals = snaps[0][1][name]
        if len(vals) == len(tri):
            m = ax.tripcolor(T, facecolors=vals, cmap=cmap, vmin=lo, vmax=hi, shading="flat")
        else:
            m = ax.tripcolor(T, vals, cmap=cmap, vmin=lo, vmax=hi, shading="gouraud")
        fig.colorbar(m, ax=ax, shrink=0.8, label=axis_label(name) if SNAPSHOT_FIELDS[name][0] else name)
        ax.set_aspect("equal")
        ax.set_xlabel("x (mm)", fontsize=7)
        ax.set_ylabel("y (mm)", fontsize=7)
        ax.tick_params(labelsize=6)
        ax.set_title(SNAPSHOT_FIELDS[name][1], fontsize=8)
        meshes.append(m)
    stamp = fig.suptitle("")
    fronts: list = []

    def update(k: int):
        t, f = snaps[k]
        for m, name in zip(meshes, fields):
            m.set_array(np.asarray(f[name], float))
        for c in fronts:
            c.remove()
        fronts.clear()
        if "S" in f and np.nanmin(f["S"]) < 0.5 < np.nanmax(f["S"]):
            for ax in axes:
                fronts.append(ax.tricontour(T, f["S"], levels=[0.5], colors="w", linewidths=0.8))
        stamp.set_text(f"t = {t:.3f} s")
        return [*meshes, stamp]

    update(0)
    return fig, update, len(snaps)


def animate_run(run_dir, fields: Sequence[str] = ("S", "phi", "d", "p"), out=None, fps: int = 6) -> Path:
    """Write the animation of a run folder (MP4 with ffmpeg, else GIF) atomically; returns its path
    (default ``RUN/animation.mp4`` or ``.gif``)."""
    from matplotlib import animation

    writer_name, suffix = animation_writer(out)
    run_dir = Path(run_dir)
    path = Path(out) if out is not None else run_dir / f"animation{suffix}"
    fig, update, n = build_animation(run_dir, fields)
    anim = animation.FuncAnimation(fig, update, frames=n, blit=False)
    with atomic_path(path) as tmp:
        anim.save(tmp, writer=animation.writers[writer_name](fps=fps), dpi=120)
    return path
