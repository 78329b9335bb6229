"""Pruning a campaign (sweep.campaign.archive): the labels, the table and the resume are those of the unpruned runs.

The runner writes run folders in the solver's format: an annulus r = 10..60 mm, three snapshots at 0.5, 1 and
1.5 s, a front of S at R(t) = 30 t mm, and an open crack (phi = 1) along the +x axis from r_i to r_i + L with
L = 2 + 8 eta_o mm growing with time; the other elements at phi = 0.4. The campaign classifies at the first
snapshot whose front reaches 30 mm (t = 1 s), so the kept snapshot is the middle one.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sweep.campaign.archive import LABEL_FIELDS, prune_campaign, prune_run
from sweep.campaign.table import build_table
from sweep.campaign.plan import plan_campaign
from sweep.campaign.run import reclassify, run_campaign
from sweep.campaign.cli import main as cli_main
from sweep.campaign.spec import spec_from_dict
from sweep.campaign.store import ResultsStore, verify_run

VERSION = "test-archive"
R_I, R_O = 10.0, 60.0


def _annulus(nr: int = 51, nt: int = 256):
    r = np.linspace(R_I, R_O, nr)
    th = np.linspace(0.0, 2 * np.pi, nt + 1)[:-1]
    R, T = np.meshgrid(r, th, indexing="ij")
    pts = np.column_stack([(R * np.cos(T)).ravel(), (R * np.sin(T)).ravel()])
    i, j = np.meshgrid(np.arange(nr - 1), np.arange(nt), indexing="ij")
    a, b = (i * nt + j).ravel(), (i * nt + (j + 1) % nt).ravel()
    c, d = a + nt, b + nt
    return pts, np.vstack([np.column_stack([a, b, d]), np.column_stack([a, d, c])])


def crack_runner(params, options, run_dir):
    """A solver-format run folder (see the module docstring); every snapshot field of the solver's output."""
    pts, tri = _annulus()
    snaps = Path(run_dir, "snapshots")
    snaps.mkdir()
    np.savez(snaps / "mesh.npz", points=pts, triangles=tri)
    rad = np.hypot(pts[:, 0], pts[:, 1])
    cen = pts[tri].mean(axis=1)
    rc, thc = np.hypot(cen[:, 0], cen[:, 1]), np.abs(np.arctan2(cen[:, 1], cen[:, 0]))
    for k, t in enumerate((0.5, 1.0, 1.5)):
        S = np.clip((30.0 * t - rad) / 2.0 + 0.5, 0.0, 1.0)
        L = (2.0 + 8.0 * params["eta_o"]) * t
        phi = np.where((rc < R_I + L) & (thc < 0.03), 1.0, 0.4)
        z = np.zeros(len(pts))
        np.savez(snaps / f"snap_{k:05d}.npz", t=t, S=S, mu=z, p=z + t, d=z, u=np.zeros((len(pts), 2)),
                 phi=phi, eps_v=np.zeros(len(tri)), hoop_stress=np.zeros(len(tri)), k=np.zeros(len(tri)),
                 w1_mag=np.zeros(len(tri)))
    for f in ("fields.xdmf", "fields.h5"):  # stand-ins for the ParaView copy of the snapshots
        Path(run_dir, f).write_text("copy of every snapshot\n")
    pd.DataFrame({"t": [0.0, 1.5], "p_inj": [0.0, 10.0 * params["eta_o"]]}).to_csv(
        Path(run_dir, "timeseries.csv"), index=False)
    return {"status": "ok"}


def _spec():
    return spec_from_dict({"name": "arch", "base": {"r_inner": R_I, "r_outer": R_O},
                           "axes": {"eta_o": [0.25, 1.0]},
                           "classify": {"at": {"front_radius": 30.0}, "min_crack_length": 4.0}})


def _labelled_campaign(root: Path):
    spec = _spec()
    run_campaign(spec, root, runner=crack_runner, jobs=1, code_hash=VERSION, progress=None)
    assert reclassify(spec, root, code_hash=VERSION) == 2
    return spec


def _labels(spec, root):
    cols = ["key", "regime", "fracturing", "crack_length", "n_cracks", "front_radius_mean", "t_classified"]
    return build_table(spec, root, code_hash=VERSION)[cols].sort_values("key").reset_index(drop=True)


def test_pruned_runs_keep_labels_table_and_resume(tmp_path):
    spec = _labelled_campaign(tmp_path)
    before = _labels(spec, tmp_path)
    # crack L(1 s) = 2 + 8 eta_o: 4 mm (not beyond L_min = 4) and 10 mm (fracturing)
    assert list(before["t_classified"]) == [1.0, 1.0]
    assert sorted(before["fracturing"]) == [False, True]

    rep = prune_campaign(spec, tmp_path)
    assert sorted(rep.pruned) == sorted(before["key"]) and rep.skipped == {} and rep.bytes_freed > 0
    store = ResultsStore(tmp_path, "arch")
    for key, rec in store.records().items():
        d = store.run_dir(key)
        assert sorted(p.name for p in (d / "snapshots").iterdir()) == ["mesh.npz", "snap_00001.npz"]
        with np.load(d / "snapshots" / "snap_00001.npz") as z:
            assert tuple(z.files) == LABEL_FIELDS and float(z["t"]) == 1.0
        assert rec["pruned"]["removed"] == ["snapshots/snap_00000.npz", "snapshots/snap_00002.npz",
                                            "fields.xdmf", "fields.h5"]
        assert not (d / "fields.h5").exists() and (d / "timeseries.csv").is_file()
        assert verify_run(d, rec) == []

    # the resumed campaign has nothing to do, and relabelling the pruned runs gives the same table
    plan = plan_campaign(spec, tmp_path, code_hash=VERSION)
    assert len(plan.done) == 2 and not plan.pending and not plan.damaged
    assert reclassify(spec, tmp_path, code_hash=VERSION) == 2
    pd.testing.assert_frame_equal(_labels(spec, tmp_path), before)

    # a second prune leaves every run as it is, saying why
    again = prune_campaign(spec, tmp_path)
    assert again.pruned == [] and set(again.skipped.values()) == {"already pruned"}


def test_a_changed_pruned_file_is_a_damaged_run(tmp_path):
    spec = _labelled_campaign(tmp_path)
    prune_campaign(spec, tmp_path)
    store = ResultsStore(tmp_path, "arch")
    key = sorted(store.records())[0]
    snap = store.run_dir(key) / "snapshots" / "snap_00001.npz"
    with np.load(snap) as z:
        kept = {f: z[f] for f in z.files}
    kept["phi"] = kept["phi"] * 0.5
    np.savez_compressed(snap, **kept)
    plan = plan_campaign(spec, tmp_path, code_hash=VERSION)
    assert [k for _, k in plan.damaged] == [key]


def test_prune_refuses_unlabelled_failed_and_damaged_runs_before_touching_them(tmp_path):
    spec = _spec()
    run_campaign(spec, tmp_path, runner=crack_runner, jobs=1, code_hash=VERSION, progress=None)
    store = ResultsStore(tmp_path, "arch")
    key, rec = sorted(store.records().items())[0]
    d = store.run_dir(key)
    files = sorted(p.name for p in (d / "snapshots").iterdir())
    with pytest.raises(ValueError, match="t_classified"):
        prune_run(d, rec)
    with pytest.raises(ValueError, match="only finished"):
        prune_run(d, {**rec, "status": "failed"})
    (d / "timeseries.csv").write_text("t,p_inj\n0,1\n")
    with pytest.raises(ValueError, match="damaged run: timeseries.csv"):
        prune_run(d, {**rec, "classification": {"t_classified": 1.0}})
    assert sorted(p.name for p in (d / "snapshots").iterdir()) == files
    assert json.loads((d / "record.json").read_text()) == rec


def test_cli_prune_and_its_bad_arguments(tmp_path, capsys):
    spec_file = tmp_path / "arch.toml"
    spec_file.write_text('name = "arch"\n[axes]\neta_o = [0.25, 1.0]\n')
    assert cli_main(["prune", str(spec_file), "--results", str(tmp_path / "none")]) == 2
    assert "no runs of campaign 'arch'" in capsys.readouterr().err
