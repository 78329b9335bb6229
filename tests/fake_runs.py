"""Shared pieces of hand-made run folders in the solver's format (for figure and animation tests)."""
from __future__ import annotations

import numpy as np


def annulus_grid(nr: int = 9, nt: int = 24, r_inner: float = 5.0, r_outer: float = 53.0):
    """(points (N, 2) mm, triangles (M, 3)) of a structured annulus: nr radii x nt angles."""
    r, th = np.linspace(r_inner, r_outer, nr), np.linspace(0.0, 2 * np.pi, nt, endpoint=False)
    R, T = np.meshgrid(r, th, indexing="ij")
    pts = np.column_stack([(R * np.cos(T)).ravel(), (R * np.sin(T)).ravel()])
    i, j = np.meshgrid(np.arange(nr - 1), np.arange(nt), indexing="ij")
    a, b = (i * nt + j).ravel(), (i * nt + (j + 1) % nt).ravel()
    tri = np.vstack([np.column_stack([a, b, b + nt]), np.column_stack([a, b + nt, a + nt])])
    return pts, tri
