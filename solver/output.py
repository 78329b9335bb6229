"""Run folders: every file written atomically (temporary name, then rename).

Layout of ``run_dir``::

    params.toml, options.toml        inputs (round-trip through Parameters / RunOptions)
    timeseries.csv                   one row per accepted step
    summary.json                     status, reason, wall time, t reached, versions, complete
    log.txt                          rejected steps, warnings, tracebacks
    snapshots/mesh.npz               points (N, 2) mm, triangles (M, 3)
    snapshots/snap_00000.npz ...     t; nodal S, mu, p, d, u; element phi, eps_v, hoop_stress, k, w1_mag
    fields.xdmf                      the snapshots for ParaView (meshio, inline XML data)

While a run is in progress ``summary.json`` says ``"status": "running"`` and
``"complete": false``; a failed run keeps what it wrote and says why.
"""
from __future__ import annotations

import json
import os
import platform
import tempfile
from pathlib import Path

import numpy as np


def atomic_write_bytes(path: Path, data: bytes) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix="." + path.name + ".")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


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


def atomic_write_text(path: Path, text: str) -> None:
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

    def start(self, params, options) -> None:
        self.dir.mkdir(parents=True, exist_ok=True)
        self.snap_dir.mkdir(exist_ok=True)
        for old in self.snap_dir.glob("snap_*.npz"):
            old.unlink()
        tmp = self.dir / ".params.toml.tmp"
        params.to_toml(tmp)
        os.replace(tmp, self.dir / "params.toml")
        tmp = self.dir / ".options.toml.tmp"
        options.to_toml(tmp)
        os.replace(tmp, self.dir / "options.toml")
        self._summary({"status": "running", "reason": None, "complete": False})
        atomic_write_text(self.dir / "log.txt", "")

    def log(self, line: str) -> None:
        with open(self.dir / "log.txt", "a") as f:
            f.write(line.rstrip() + "\n")

    def write_mesh(self, points, triangles) -> None:
        _atomic_npz(self.snap_dir / "mesh.npz", points=points, triangles=triangles)

    def write_snapshot(self, index: int, t: float, fields: dict) -> None:
        _atomic_npz(self.snap_dir / f"snap_{index:05d}.npz", t=np.float64(t), **fields)

    def write_timeseries(self, df) -> None:
        atomic_write_text(self.dir / "timeseries.csv", df.to_csv(index=False))

    def finish(self, df, status, reason, wall, t_reached, rejected, factorizations, xdmf: bool = True) -> None:
        """Final time series, XDMF (when ``xdmf``: RunOptions.write_xdmf) and the summary, which comes last."""
        self.write_timeseries(df)
        if xdmf:
            try:
                write_xdmf(self.dir)
            except Exception as exc:  # ParaView output is a convenience, never a failure
                self.log(f"XDMF not written: {exc}")
        self._summary({
            "status": status, "reason": reason, "complete": status == "ok",
            "wall_time_s": wall, "t_reached": t_reached, "accepted_steps": int(len(df)),
            "rejected_steps": len(rejected), "factorizations": int(factorizations),
        })

    def _summary(self, d: dict) -> None:
        d = dict(d)
        d["versions"] = versions()
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


def write_xdmf(run_dir) -> Path:
    """Write ``fields.xdmf`` (ParaView) from the NPZ snapshots with meshio's time-series writer."""
    import meshio

    pts, tri, snaps = load_run(run_dir)
    path = Path(run_dir) / "fields.xdmf"
    tmp = Path(run_dir) / ".fields_tmp.xdmf"
    # XML (inline) data: meshio's HDF5 time-series writer puts the .h5 file in the
    # current directory, not beside the .xdmf; inline data keeps the run folder self-contained
    with meshio.xdmf.TimeSeriesWriter(str(tmp), data_format="XML") as w:
        w.write_points_cells(np.column_stack([pts, np.zeros(len(pts))]), [("triangle", tri)])
        for t, f in snaps:
            pdata = {k: f[k] for k in ("S", "mu", "p", "d")}
            pdata["u"] = np.column_stack([f["u"], np.zeros(len(pts))])
            cdata = {k: [f[k]] for k in ("phi", "eps_v", "hoop_stress", "k", "w1_mag")}
            w.write_data(t, point_data=pdata, cell_data=cdata)
    os.replace(tmp, path)
    return path
