"""Cheap per-step measures of a state (mm): front radius, open-crack tip, outer water layer.

The saturation front is the S = 0.5 level set *connected to the inlet*: nodes
with S >= 0.5 joined to the inner circle through mesh edges whose two ends
are invaded.  An invaded patch that is not connected to the inlet (such as
the spurious water layer that the Dirichlet μ_o condition can pull in at the
outer circle, see ``outer_layer_area``) is never taken for the front.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components


def mesh_edges(triangles: np.ndarray) -> np.ndarray:
    """Unique undirected edges (E, 2) of a triangulation."""
    e = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    e.sort(axis=1)
    return np.unique(e, axis=0)


def _components(n: int, edges: np.ndarray, keep: np.ndarray):
    sel = keep[edges[:, 0]] & keep[edges[:, 1]]
    e = edges[sel]
    g = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    return connected_components(g, directed=False)[1]


def invaded_from_inlet(S: np.ndarray, edges: np.ndarray, inner_nodes: np.ndarray, level: float = 0.5) -> np.ndarray:
    """Boolean mask of nodes with S >= level connected to the inner circle."""
    inv = S >= level
    labels = _components(len(S), edges, inv)
    seeds = inner_nodes[inv[inner_nodes]]
    return inv & np.isin(labels, np.unique(labels[seeds]))


def front_envelope(points, S, edges, inner_nodes, level: float = 0.5, nbins: int = 72) -> np.ndarray:
    """Outer envelope r(θ) (mm) of the S = level front connected to the inlet, over ``nbins`` angular sectors.

    The front points are the linear-interpolation crossings on edges leaving the connected invaded region;
    each sector holds its farthest crossing, or -inf when it has none.  All -inf when no front exists.
    """
    conn = invaded_from_inlet(S, edges, inner_nodes, level)
    a, b = edges[:, 0], edges[:, 1]
    out = (conn[a] & (S[b] < level)) | (conn[b] & (S[a] < level))
    rb = np.full(nbins, -np.inf)
    if not out.any():
        return rb
    a, b = a[out], b[out]
    t = (S[a] - level) / (S[a] - S[b])
    x = points[a] + t[:, None] * (points[b] - points[a])
    r = np.hypot(x[:, 0], x[:, 1])
    th = np.arctan2(x[:, 1], x[:, 0])
    k = np.minimum(((th + np.pi) / (2 * np.pi) * nbins).astype(int), nbins - 1)
    np.maximum.at(rb, k, r)
    return rb


def front_measures(points, S, edges, inner_nodes, level: float = 0.5, nbins: int = 72) -> tuple[float, float, float]:
    """Mean, max and main-branch radius (mm) of the S = level front connected to the inlet.

    The mean is over the sectors of :func:`front_envelope` that hold a crossing; the branch radius is the
    mean of the three main invasion branches (:func:`branch_radii`), the paper's front measure (Sec. 3.5:
    "mean over the three main invasion branches").  (nan, nan, nan) when no front exists.
    """
    rb = front_envelope(points, S, edges, inner_nodes, level, nbins)
    fin = rb[np.isfinite(rb)]
    if len(fin) == 0:
        return float("nan"), float("nan"), float("nan")
    return float(fin.mean()), float(fin.max()), float(branch_radii(rb).mean())


def branch_radii(envelope: np.ndarray, n_branches: int = 3, min_separation_deg: float = 45.0) -> np.ndarray:
    """Radii (mm) of the ``n_branches`` main invasion branches of an envelope r(θ), largest first.

    A branch is a local maximum of the circular envelope; branches are taken greedily by radius, each at
    least ``min_separation_deg`` away from those already taken (so one lobe is not counted twice).
    Fewer are returned when the envelope has fewer.
    """
    nb = len(envelope)
    r = np.where(np.isfinite(envelope), envelope, -np.inf)
    peaks = np.flatnonzero(np.isfinite(r) & (r >= np.roll(r, 1)) & (r >= np.roll(r, -1)))
    sep = int(np.ceil(min_separation_deg / (360.0 / nb)))
    taken: list[int] = []
    for i in peaks[np.argsort(-r[peaks], kind="stable")]:
        if all(min(abs(i - j), nb - abs(i - j)) >= sep for j in taken):
            taken.append(int(i))
        if len(taken) == n_branches:
            break
    return r[taken]


def outer_layer_area(points, triangles, areas, S, edges, inner_nodes, outer_nodes, level: float = 0.5) -> float:
    """Area (mm²) of invaded elements (all nodes S >= level) not connected to the inlet but touching the outer circle."""
    inv = S >= level
    labels = _components(len(S), edges, inv)
    conn_labels = np.unique(labels[inner_nodes[inv[inner_nodes]]])
    outer_labels = np.setdiff1d(np.unique(labels[outer_nodes[inv[outer_nodes]]]), conn_labels)
    if len(outer_labels) == 0:
        return 0.0
    in_layer = inv & np.isin(labels, outer_labels)
    el = in_layer[triangles].all(axis=1)
    return float(areas[el].sum())


def open_tip_radius(points, triangles, phi_elem, inner_nodes, phi_open: float = 0.99) -> float:
    """Farthest radius (mm) of open elements (φ >= phi_open) connected to the inner cavity; r_inner-like 0 if none."""
    open_el = phi_elem >= phi_open
    if not open_el.any():
        return 0.0
    n = len(points)
    node_open = np.zeros(n, bool)
    node_open[triangles[open_el].ravel()] = True
    tri = triangles[open_el]
    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    g = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    labels = connected_components(g, directed=False)[1]
    seeds = inner_nodes[node_open[inner_nodes]]
    if len(seeds) == 0:
        return 0.0
    keep = np.isin(labels, np.unique(labels[seeds])) & node_open
    r = np.hypot(points[keep, 0], points[keep, 1])
    return float(r.max())
