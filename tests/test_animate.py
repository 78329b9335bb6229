"""`dchfrac animate`: one frame per snapshot, fixed colour scales, a time stamp, MP4 or GIF, bad input exit 2.

The run folder below holds three snapshots of known fields: S = 1 inside the radius 10 + 20 t mm,
the pressure p = 100 t (1 - r / 53) kPa (its range grows with t, so a per-frame autoscale would move).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from fake_runs import annulus_grid
import pytest

from sweep.animate import animate_run, build_animation
from sweep.cli import main

TIMES = (0.0, 0.5, 1.0)


@pytest.fixture()
def run(tmp_path):
    pts, tri = annulus_grid()
    d = tmp_path / "run" / "snapshots"
    d.mkdir(parents=True)
    np.savez(d / "mesh.npz", points=pts, triangles=tri)
    rad = np.hypot(pts[:, 0], pts[:, 1])
    for k, t in enumerate(TIMES):
        S = (rad < 10.0 + 20.0 * t).astype(float)
        np.savez(d / f"snap_{k:05d}.npz", t=t, S=S, p=100.0 * t * (1 - rad / 53.0), d=0.1 * t * S,
                 phi=np.full(len(tri), 0.4))
    return tmp_path / "run"


def test_fixed_scales_and_time_stamp(run):
    fig, update, n = build_animation(run, ("S", "p", "d"))
    assert n == len(TIMES)
    clims = []
    for k, t in enumerate(TIMES):
        update(k)
        assert fig._suptitle.get_text() == f"t = {t:.3f} s"
        clims.append([ax.collections[0].get_clim() for ax in fig.axes if ax.get_label() != "<colorbar>"])
    assert all(c == clims[0] for c in clims)  # one scale per field over all frames
    s_lim, p_lim, d_lim = clims[0]
    assert s_lim == (0.0, 1.0) and d_lim == (0.0, 1.0)
    # p from 0 to 100 (1 - 5/53) kPa at t = 1 s on the inner circle
    assert p_lim == pytest.approx((0.0, 100.0 * (1 - 5.0 / 53.0)), rel=1e-12)


def test_writes_one_frame_per_snapshot(run):
    from PIL import Image

    path = animate_run(run, ("S", "p"))
    assert path.parent == run and path.suffix in (".mp4", ".gif")
    assert not [p for p in run.iterdir() if p.name.startswith(".")]
    if path.suffix == ".gif":
        im = Image.open(path)
        assert im.n_frames == len(TIMES)
        frames = []
        for k in range(im.n_frames):
            im.seek(k)
            frames.append(np.asarray(im.convert("RGB"), dtype=int))
        assert all(np.abs(frames[k + 1] - frames[k]).sum() > 0 for k in range(len(frames) - 1))


@pytest.mark.parametrize("argv, message", [
    (["--fields", "S,velocity"], "unknown field(s) ['velocity']"),
    (["--out", "movie.avi"], "allowed suffixes"),
    (["--fps", "0"], "--fps 0"),
])
def test_bad_input_exits_2_with_one_line(run, capsys, argv, message):
    assert main(["animate", str(run), *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err


def test_not_a_run_folder_exits_2(tmp_path, capsys):
    assert main(["animate", str(tmp_path / "nowhere")]) == 2
    assert "not a run folder" in capsys.readouterr().err
