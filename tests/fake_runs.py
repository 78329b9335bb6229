"""Shared pieces of hand-made run folders in the solver's format (for figure and animation tests)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd


def annulus_grid(nr: int = 9, nt: int = 24, r_inner: float = 5.0, r_outer: float = 53.0):
    """(points (N, 2) mm, triangles (M, 3)) of a structured annulus: nr radii x nt angles."""
    r, th = np.linspace(r_inner, r_outer, nr), np.linspace(0.0, 2 * np.pi, nt, endpoint=False)
    R, T = np.meshgrid(r, th, indexing="ij")
    pts = np.column_stack([(R * np.cos(T)).ravel(), (R * np.sin(T)).ravel()])
    i, j = np.meshgrid(np.arange(nr - 1), np.arange(nt), indexing="ij")
    a, b = (i * nt + j).ravel(), (i * nt + (j + 1) % nt).ravel()
    tri = np.vstack([np.column_stack([a, b, b + nt]), np.column_stack([a, b + nt, a + nt])])
    return pts, tri


def field_runner(params, options, run_dir):
    """A campaign runner writing one snapshot at t = 1 s: eps_v = C eta_o cos(theta) (both signs, a range per
    run), S = 1.5 - r / 20 mm clipped to [0, 1] (front at r = 20 mm); and a time series p_inj = 100 C eta_o t kPa."""
    pts, tri = annulus_grid()
    snaps = Path(run_dir, "snapshots")
    snaps.mkdir()
    np.savez(snaps / "mesh.npz", points=pts, triangles=tri)
    cx = pts[tri].mean(axis=1)
    amp = params["cement"] * params["eta_o"]
    z, ze = np.zeros(len(pts)), np.zeros(len(tri))
    np.savez(snaps / "snap_00000.npz", t=1.0, S=np.clip(1.5 - np.hypot(pts[:, 0], pts[:, 1]) / 20, 0, 1), mu=z, p=z,
             d=z, u=np.zeros((len(pts), 2)), phi=ze + 0.4, eps_v=amp * np.cos(np.arctan2(cx[:, 1], cx[:, 0])),
             hoop_stress=ze, k=ze, w1_mag=ze)
    pd.DataFrame({"t": [0.0, 1.0], "p_inj": [0.0, 100.0 * amp]}).to_csv(Path(run_dir, "timeseries.csv"), index=False)
    return {"status": "ok", "regime": "uniform_invasion"}


def sleepy_runner(params, options, run_dir):
    """A campaign runner that takes 1.5 s and returns x = eta_o * cement (a known answer per run)."""
    import time

    time.sleep(1.5)
    x = params["eta_o"] * params["cement"]
    Path(run_dir, "x.txt").write_text(repr(x))
    return {"status": "ok", "regime": "fracturing" if x > 1.0 else "porous_invasion", "metrics": {"x": x}}
