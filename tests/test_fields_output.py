"""Field output: t = 0 and N evenly spaced frames, XDMF 3 with HDF5 heavy data beside the .xdmf (never in
the working directory) or inline XML, one temporal collection and no separate static mesh grid, read
back exactly by meshio's TimeSeriesReader."""
from __future__ import annotations

import xml.etree.ElementTree as ET

import meshio
import numpy as np
import pytest

from solver import Parameters, RunOptions, simulate
from solver.output import load_run, write_xdmf

T_END = 0.02


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    base = tmp_path_factory.mktemp("fields")
    elsewhere = base / "cwd"
    elsewhere.mkdir()
    import os

    old = os.getcwd()
    os.chdir(elsewhere)  # the heavy data must land beside the .xdmf, not here
    try:
        res = simulate(Parameters(), RunOptions(h=4.0, t_end=T_END, snapshot_times=(), frames=4, xdmf_format="hdf5"),
                       out_dir=base / "run")
    finally:
        os.chdir(old)
    assert res.status == "ok"
    assert list(elsewhere.iterdir()) == []
    return base / "run"


def _read(path):
    with meshio.xdmf.TimeSeriesReader(str(path)) as r:
        pts, cells = r.read_points_cells()
        steps = [r.read_data(k) for k in range(r.num_steps)]
    return pts, cells, steps


def test_t0_and_evenly_spaced_frames(run):
    _, _, snaps = load_run(run)
    assert [t for t, _ in snaps] == pytest.approx([0.0, 0.005, 0.01, 0.015, 0.02], abs=1e-12)


def test_hdf5_xdmf_reads_back_the_snapshots_exactly(run):
    assert (run / "fields.h5").is_file()
    pts, cells, steps = _read(run / "fields.xdmf")
    mpts, tri, snaps = load_run(run)
    np.testing.assert_array_equal(pts[:, :2], mpts)
    assert cells[0].type == "triangle"
    np.testing.assert_array_equal(cells[0].data, tri)
    assert len(steps) == len(snaps)
    for (t, pdata, cdata), (ts, f) in zip(steps, snaps):
        assert t == ts
        for k in ("S", "mu", "p", "d"):
            np.testing.assert_array_equal(pdata[k], f[k])
        np.testing.assert_array_equal(pdata["u"][:, :2], f["u"])
        for k in ("phi", "eps_v", "hoop_stress", "k", "w1_mag"):
            np.testing.assert_array_equal(cdata[k][0], f[k])


def test_one_temporal_collection_and_no_static_mesh_grid(run):
    domain = ET.parse(run / "fields.xdmf").getroot().find("Domain")
    grids = list(domain)
    assert len(grids) == 1 and grids[0].get("CollectionType") == "Temporal"
    assert all(g.get("GridType") == "Uniform" for g in grids[0])


def test_inline_xml_reads_back_the_same_and_drops_a_stale_h5(run, tmp_path):
    import shutil

    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    write_xdmf(copy, "xml")
    assert not (copy / "fields.h5").exists()
    a, b = _read(run / "fields.xdmf"), _read(copy / "fields.xdmf")
    np.testing.assert_array_equal(a[0], b[0])
    for (ta, pa, ca), (tb, pb, cb) in zip(a[2], b[2]):
        assert ta == tb
        for k in pa:
            np.testing.assert_array_equal(pa[k], pb[k])
        for k in ca:
            np.testing.assert_array_equal(ca[k][0], cb[k][0])
    # the mesh is written once: the later grids include the first one's topology and geometry
    domain = ET.parse(copy / "fields.xdmf").getroot().find("Domain")
    assert sum(len(g.findall("Geometry")) for g in domain[0]) == 1


def test_new_options_validated_and_left_out_of_run_keys():
    assert "frames" not in RunOptions().to_dict() and "xdmf_format" not in RunOptions().to_dict()
    assert RunOptions(frames=3).to_dict()["frames"] == 3
    with pytest.raises(ValueError, match="frames"):
        RunOptions(frames=0)
    with pytest.raises(ValueError, match="xdmf_format"):
        RunOptions(xdmf_format="vtk")
    assert RunOptions(t_end=1.0, snapshot_times=(0.5, 1.0), frames=4).frame_times() == [0.25, 0.5, 0.75, 1.0]


def test_timeseries_has_its_column_dictionary_beside_it(run):
    import pandas as pd

    from solver.output import TIMESERIES_COLUMNS

    ts = pd.read_csv(run / "timeseries.csv")
    cols = pd.read_csv(run / "timeseries_columns.csv", keep_default_na=False)
    assert list(cols["name"]) == list(ts.columns)  # every column the solver writes is declared
    assert [TIMESERIES_COLUMNS[n][0] for n in cols["name"]] == list(cols["unit"])
    assert cols.set_index("name").loc["p_inj", "unit"] == "kPa"


@pytest.mark.parametrize("fmt", ["hdf5", "xml"])
def test_vtk_xdmf_reader_reads_every_frame(run, tmp_path, fmt):
    """VTK's XDMF reader (the pip wheel's vtkXdmfReader; ParaView's readers are built on the same library)."""
    xdmf2 = pytest.importorskip("vtkmodules.vtkIOXdmf2")
    import shutil

    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkCommonExecutionModel import vtkStreamingDemandDrivenPipeline as SDDP

    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    write_xdmf(copy, fmt)
    r = xdmf2.vtkXdmfReader()
    r.SetFileName(str(copy / "fields.xdmf"))
    r.UpdateInformation()
    times = r.GetOutputInformation(0).Get(SDDP.TIME_STEPS())
    _, tri, snaps = load_run(copy)
    assert list(times) == [t for t, _ in snaps]
    for t, f in snaps:
        r.UpdateTimeStep(t)
        out = r.GetOutputDataObject(0)
        assert out.GetNumberOfCells() == len(tri)  # one grid: no static mesh block beside the series
        np.testing.assert_array_equal(vtk_to_numpy(out.GetPointData().GetArray("S")), f["S"])
        np.testing.assert_array_equal(vtk_to_numpy(out.GetCellData().GetArray("phi")), f["phi"])
        np.testing.assert_array_equal(vtk_to_numpy(out.GetPointData().GetArray("u"))[:, :2], f["u"])
