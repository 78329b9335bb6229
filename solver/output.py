"""Run folders: every file written atomically (temporary name, then rename).

Layout of ``run_dir``::

    params.toml, options.toml        inputs (round-trip through Parameters / RunOptions)
    timeseries.csv                   one row per accepted step
    timeseries_columns.csv           its column dictionary: name, unit, meaning (TIMESERIES_COLUMNS)
    summary.json                     status, reason, wall time, t reached, versions, code_hash, complete, path
                                     (linear solver, precision and kernels that ran), resumed_from_t (the
                                     times a resumed run continued from, s)
    checkpoint.npz                   while a run is in progress: its last checkpoint (solver.checkpoint)
    log.txt                          rejected steps, warnings, tracebacks
    snapshots/mesh.npz               points (N, 2) mm, triangles (M, 3)
    snapshots/snap_00000.npz ...     t; nodal S, mu, p, d, u; element phi, eps_v, hoop_stress, k, w1_mag
    fields.xdmf, fields.h5           the snapshots for ParaView / meshio.xdmf.TimeSeriesReader: XDMF 3 with
                                     the arrays in fields.h5 beside it (RunOptions.xdmf_format "hdf5"),
                                     or inline ("xml"); default: hdf5 when h5py is installed

While a run is in progress ``summary.json`` says ``"status": "running"`` and
``"complete": false``; a failed run keeps what it wrote and says why.
"""
from __future__ import annotations

import contextlib
import json
import os
import platform
import tempfile
from pathlib import Path

import numpy as np


# columns of timeseries.csv (one row per accepted step): name -> (unit, meaning). The one declaration
# of their units: the campaign column dictionary and the figures' axis labels read it.
TIMESERIES_COLUMNS = {
    "t": ("s", "time at the end of the step"),
    "dt": ("s", "time step"),
    "p_inj": ("kPa", "injection pressure: mean p on the inner circle"),
    "injected_volume": ("mm²", "cumulative injected volume w_i x inner length x t (per unit cell height)"),
    "invading_volume": ("mm²", "invading fluid in the pores: integral of phi S"),
    "water_inflow_volume": ("mm²", "cumulative invading-fluid inflow through the inner circle"),
    "water_outflow_volume": ("mm²", "cumulative invading-fluid outflow through the outer circle"),
    "outflow_volume": ("mm²", "cumulative total outflow through the outer circle"),
    "stored_volume": ("mm²", "fluid in the pores (and the elastic cell's gap) as the balance counts it: integral of "
                             "the storage fraction at the quadrature points"),
    "source_volume": ("mm²", "cumulative second-order volume source c_v integral of phi d(eps_v)/dt"),
    "line_stored_volume": ("mm²", "volume stored in the injection line and cavity (line_compliance; 0 when off)"),
    "mass_error": ("-", "relative error of the total mass balance since t = 0 (injected = stored change + "
                        "source + outflow + line storage)"),
    "water_stored_volume": ("mm²", "invading fluid in the pores as the balance counts it: integral of phi S at the "
                                   "quadrature points of the scheme"),
    "water_source_volume": ("mm²", "cumulative second-order invading source c_v integral of phi S d(eps_v)/dt"),
    "water_mass_error": ("-", "relative error of the invading-fluid balance since t = 0 (inflow - outflow = "
                              "stored change + source), relative to the injected volume"),
    "mean_damage": ("-", "area-weighted mean damage d"),
    "max_damage": ("-", "largest nodal damage d"),
    "max_hoop_stress": ("kPa", "largest element hoop (circumferential) effective stress"),
    "front_radius_mean": ("mm", "mean radius of the S = 0.5 front connected to the inlet"),
    "front_radius_max": ("mm", "largest radius of the S = 0.5 front connected to the inlet"),
    "front_radius_branches": ("mm", "mean radius of the three main invasion branches of that front (Sec. 3.5)"),
    "open_tip_radius": ("mm", "largest radius of the open region (phi >= 0.99) connected to the inlet"),
    "outer_layer_area": ("mm²", "invaded area not connected to the inlet (outer water layer)"),
    "newton_its": ("", "Newton iterations of the step (all stagger iterations)"),
    "stagger_its": ("", "stagger iterations of the step"),
    "damage_kkt": ("-", "KKT residual of the damage bound constraints"),
    "step_change": ("-", "largest nodal change of S or d over the step (what the state-change step controller reads)"),
    "factorizations": ("", "cumulative sparse factorizations of the run"),
}

# fields of a snapshot (snapshots/snap_*.npz, fields.xdmf): name -> (unit, meaning, "node" | "element")
SNAPSHOT_FIELDS = {
    "S": ("-", "saturation of the invading fluid", "node"),
    "mu": ("kPa", "chemical potential", "node"),
    "p": ("kPa", "pore pressure", "node"),
    "d": ("-", "damage", "node"),
    "u": ("mm", "displacement (u_x, u_y)", "node"),
    "phi": ("-", "porosity", "element"),
    "eps_v": ("-", "volumetric strain", "element"),
    "hoop_stress": ("kPa", "hoop (circumferential) effective stress", "element"),
    "k": ("mm²", "permeability", "element"),
    "w1_mag": ("mm/s", "Darcy speed of the invading fluid", "element"),
}


@contextlib.contextmanager
def atomic_path(path):
    """The project's one atomic write: yields a temporary path beside ``path`` (same folder, so the rename
    stays on one file system); when the block ends without error the file is made readable (0644) and renamed
    onto ``path``, so a reader never sees a partial file; on error the temporary file is removed.  Creates the
    parent folder."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix="." + path.name + ".", suffix=path.suffix)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def atomic_write_bytes(path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (``atomic_path``)."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def check_writable_dir(path, what: str = "output folder") -> Path:
    """Check, before any work, that the folder ``path`` can be created (if absent) and written to.

    Nothing is created: a temporary file is made and removed in ``path`` or, when absent, in its nearest
    existing parent.  Raises ValueError naming ``what``, the path and the reason.  Returns ``Path(path)``.
    """
    path = Path(path)
    probe = path
    while not probe.exists():
        if probe.parent == probe:
            break
        probe = probe.parent
    if not probe.is_dir():
        raise ValueError(f"{what} {str(path)!r} cannot be written: {str(probe)!r} exists and is not a folder "
                         "(allowed: a writable folder, or a new one in a writable folder)")
    try:
        fd, tmp = tempfile.mkstemp(dir=probe, prefix=".write-check-")
    except OSError as exc:
        raise ValueError(f"{what} {str(path)!r} cannot be written ({exc.strerror} in {str(probe)!r}): "
                         "allowed a writable folder, or a new one in a writable folder") from None
    os.close(fd)
    os.unlink(tmp)
    return path


def atomic_write_text(path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically (``atomic_path``)."""
    atomic_write_bytes(path, text.encode())


def _atomic_npz(path: Path, **arrays) -> None:
    import io

    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    atomic_write_bytes(path, buf.getvalue())


def versions() -> dict:
    import numpy
    import scipy

    out = {"python": platform.python_version(), "numpy": numpy.__version__, "scipy": scipy.__version__}
    try:
        from importlib.metadata import version

        out["dchfrac"] = version("dchfrac")
    except Exception:
        out["dchfrac"] = "unknown"
    from importlib.util import find_spec

    if find_spec("pypardiso") is not None:  # without importing it (importing loads MKL)
        out["pypardiso"] = "installed"
    return out


class RunWriter:
    """Writes one run folder; see the module docstring for the layout."""

    def __init__(self, run_dir):
        self.dir = Path(run_dir)
        self.snap_dir = self.dir / "snapshots"

    def start(self, params, options, resume: bool = False) -> None:
        """Write the inputs and a "running" summary; a fresh run (not ``resume``) first removes the snapshots and
        the log of an earlier run in the folder, a resumed one (``solver.checkpoint``) keeps them."""
        self.xdmf_format = getattr(options, "xdmf_format", None)
        self.dir.mkdir(parents=True, exist_ok=True)
        self.snap_dir.mkdir(exist_ok=True)
        if not resume:
            self.remove_snapshots()
        for name, obj in (("params.toml", params), ("options.toml", options)):
            with atomic_path(self.dir / name) as tmp:
                obj.to_toml(tmp)
        self._summary({"status": "running", "reason": None, "complete": False})
        if not resume:
            atomic_write_text(self.dir / "log.txt", "")

    def remove_snapshots(self, first: int = 0) -> None:
        """Remove the snapshots of index ``first`` and later."""
        for old in self.snap_dir.glob("snap_*.npz"):
            if int(old.stem.split("_")[1]) >= first:
                old.unlink()

    def log(self, line: str) -> None:
        with open(self.dir / "log.txt", "a") as f:
            f.write(line.rstrip() + "\n")

    def write_mesh(self, points, triangles) -> None:
        _atomic_npz(self.snap_dir / "mesh.npz", points=points, triangles=triangles)

    def write_snapshot(self, index: int, t: float, fields: dict) -> None:
        _atomic_npz(self.snap_dir / f"snap_{index:05d}.npz", t=np.float64(t), **fields)

    def write_timeseries(self, df) -> None:
        atomic_write_text(self.dir / "timeseries.csv", df.to_csv(index=False))

    def finish(self, df, status, reason, wall, t_reached, rejected, factorizations, xdmf: bool = True,
               path: dict | None = None, resumed_from_t: list | None = None) -> None:
        """Final time series and its column dictionary, XDMF (when ``xdmf``: RunOptions.write_xdmf) and the
        summary, which comes last; ``wall``: the run's wall time, s (of every piece of a resumed run);
        ``path``: the linear solver, precision and kernels that ran (:func:`solver.simulate.run_path`);
        ``resumed_from_t``: the times (s) the run resumed from checkpoints, recorded when not empty."""
        self.write_timeseries(df)
        rows = ["name,unit,meaning"] + [f'{c},{TIMESERIES_COLUMNS[c][0]},"{TIMESERIES_COLUMNS[c][1]}"'
                                        for c in df.columns if c in TIMESERIES_COLUMNS]
        atomic_write_text(self.dir / "timeseries_columns.csv", "\n".join(rows) + "\n")
        if xdmf:
            try:
                write_xdmf(self.dir, getattr(self, "xdmf_format", None))
            except Exception as exc:  # ParaView output is a convenience, never a failure
                self.log(f"XDMF not written: {exc}")
        self._summary({
            "status": status, "reason": reason, "complete": status == "ok",
            "wall_time_s": wall, "t_reached": t_reached, "accepted_steps": int(len(df)),
            "rejected_steps": len(rejected), "factorizations": int(factorizations), "path": dict(path or {}),
            **({"resumed_from_t": list(resumed_from_t)} if resumed_from_t else {}),
        })

    def _summary(self, d: dict) -> None:
        d = dict(d)
        d["versions"] = versions()
        from solver.codehash import code_hash

        d["code_hash"] = code_hash()
        atomic_write_text(self.dir / "summary.json", json.dumps(d, indent=2, default=float))


def load_run(run_dir):
    """(points, triangles, [(t, fields), ...]) of a run folder's snapshots, in time order."""
    snap = Path(run_dir) / "snapshots"
    mesh = np.load(snap / "mesh.npz")
    out = []
    for f in sorted(snap.glob("snap_*.npz")):
        z = np.load(f)
        out.append((float(z["t"]), {k: z[k] for k in z.files if k != "t"}))
    return mesh["points"], mesh["triangles"], out


XDMF_FORMATS = ("auto", "hdf5", "xml")
_XI = "http://www.w3.org/2001/XInclude"


def xdmf_format(requested: str | None) -> str:
    """The XDMF data format to write: "hdf5" (heavy data in ``fields.h5``) or "xml" (inline text);
    None / "auto" picks "hdf5" when h5py is installed, else "xml"."""
    if requested not in (None, *XDMF_FORMATS):
        raise ValueError(f"xdmf_format={requested!r}: allowed None or one of {XDMF_FORMATS}")
    if requested in (None, "auto"):
        from importlib.util import find_spec

        return "hdf5" if find_spec("h5py") is not None else "xml"
    return requested


def _xdmf_frames(pts, snaps):
    """[(t, {name: (center, array)})] of the snapshots: nodal S, mu, p, d, u (3 components); element fields."""
    out = []
    for t, f in snaps:
        arrays = {k: ("Node", np.asarray(f[k], float)) for k in ("S", "mu", "p", "d") if k in f}
        if "u" in f:
            arrays["u"] = ("Node", np.column_stack([f["u"], np.zeros(len(pts))]))
        for k, (_, _, where) in SNAPSHOT_FIELDS.items():
            if where == "element" and k in f:
                arrays[k] = ("Cell", np.asarray(f[k], float))
        out.append((t, arrays))
    return out


def _data_item(parent, array, fmt: str, h5_ref: str):
    import xml.etree.ElementTree as ET

    kind = "Int" if np.issubdtype(array.dtype, np.integer) else "Float"
    item = ET.SubElement(parent, "DataItem", DataType=kind, Precision=str(array.dtype.itemsize),
                         Dimensions=" ".join(str(n) for n in array.shape), Format="HDF" if fmt == "hdf5" else "XML")
    if fmt == "hdf5":
        item.text = h5_ref
    else:
        import io

        buf = io.StringIO()
        np.savetxt(buf, array.reshape(len(array), -1), fmt="%.17g" if kind == "Float" else "%d")
        item.text = buf.getvalue()
    return item


def _xdmf_tree(pts3, tri, frames, fmt: str, h5_name: str):
    """The XDMF 3 document: one temporal collection of uniform grids; the mesh is stored once (the first
    grid in XML, one HDF5 dataset pair otherwise) and never as a separate static grid."""
    import xml.etree.ElementTree as ET

    root = ET.Element("Xdmf", Version="3.0")
    col = ET.SubElement(ET.SubElement(root, "Domain"), "Grid", Name="fields", GridType="Collection",
                        CollectionType="Temporal")
    for k, (t, arrays) in enumerate(frames):
        g = ET.SubElement(col, "Grid", Name=f"t{k}", GridType="Uniform")
        if k == 0 or fmt == "hdf5":
            topo = ET.SubElement(g, "Topology", TopologyType="Triangle", NumberOfElements=str(len(tri)))
            _data_item(topo, tri, fmt, f"{h5_name}:/mesh/triangles")
            geo = ET.SubElement(g, "Geometry", GeometryType="XYZ")
            _data_item(geo, pts3, fmt, f"{h5_name}:/mesh/points")
        else:
            ET.SubElement(g, f"{{{_XI}}}include",
                          xpointer='xpointer(//Grid[@Name="t0"]/*[self::Topology or self::Geometry])')
        ET.SubElement(g, "Time", Value=repr(float(t)))
        for name, (center, a) in arrays.items():
            att = ET.SubElement(g, "Attribute", Name=name, AttributeType="Vector" if a.ndim == 2 else "Scalar",
                                Center=center)
            _data_item(att, a, fmt, f"{h5_name}:/data/{k}/{name}")
    ET.register_namespace("xi", _XI)
    return ET.ElementTree(root)


def _write_h5(path: Path, pts3, tri, frames) -> None:
    import h5py

    with h5py.File(path, "w") as h:
        h.create_dataset("mesh/points", data=pts3)
        h.create_dataset("mesh/triangles", data=tri)
        for k, (_, arrays) in enumerate(frames):
            for name, (_, a) in arrays.items():
                h.create_dataset(f"data/{k}/{name}", data=a, compression="gzip", compression_opts=4)


def write_xdmf(run_dir, data_format: str | None = None) -> Path:
    """Write ``fields.xdmf`` (ParaView, meshio ``TimeSeriesReader``) from the run folder's NPZ snapshots.

    data_format : "hdf5" (the arrays in ``fields.h5`` beside the .xdmf), "xml" (inline) or None / "auto"
    (hdf5 with h5py installed). Both files are written under temporary names and renamed, the .h5 first.

    Written here, not by ``meshio.xdmf.TimeSeriesWriter`` (meshio 5.3.5), which cannot express three things
    of this layout: the heavy data beside the .xdmf (it opens ``<stem>.h5`` in the current working folder,
    meshio issue #1442), one temporal collection without a separate static mesh grid (it always writes the mesh
    as a second grid of the domain, which VTK/ParaView readers show beside the series), and compressed
    datasets under a temporary name.  meshio's ``TimeSeriesReader`` reads the result back exactly
    (tests/test_fields_output.py).
    """
    fmt = xdmf_format(data_format)
    run_dir = Path(run_dir)
    pts, tri, snaps = load_run(run_dir)
    pts3 = np.column_stack([pts, np.zeros(len(pts))]).astype(float)
    tri = np.asarray(tri, dtype=np.int64)
    frames = _xdmf_frames(pts, snaps)
    path, h5 = run_dir / "fields.xdmf", run_dir / "fields.h5"
    if fmt == "hdf5":
        with atomic_path(h5) as tmp:
            _write_h5(tmp, pts3, tri, frames)
    import io

    buf = io.BytesIO()
    _xdmf_tree(pts3, tri, frames, fmt, h5.name).write(buf, xml_declaration=True, encoding="utf-8")
    atomic_write_bytes(path, buf.getvalue())
    if fmt == "xml" and h5.exists():
        h5.unlink()  # a stale heavy-data file of an earlier hdf5 write
    return path
