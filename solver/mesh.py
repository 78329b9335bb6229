"""Triangle meshes (mm): the annulus of the Hele–Shaw cell and structured rectangles.

:func:`annulus_mesh` builds a quasi-uniform (or, optionally, graded towards the
inner circle) unstructured P1 mesh of the annulus
r_inner <= r <= r_outer (paper Sec. 3.4: r_i = 5 mm, r_o = 53 mm, h = 1 mm,
20,672 elements in the paper's reference mesh) without any external mesher:

1. nodes on concentric rings: ``n_r = ceil((r_o - r_i) / (h √3/2))`` equal
   radial steps (the height of an equilateral triangle of side h), ring j gets
   ``round(2π r_j / h)`` equally spaced nodes, consecutive rings rotated by
   half a node spacing (hexagonal-like stagger); the two boundary rings lie
   exactly on the circles;
2. ``scipy.spatial.Delaunay``, triangles inside the hole removed;
3. a few sweeps of Laplacian smoothing of the interior nodes (boundary nodes
   fixed) alternated with re-triangulation, which evens out the defects where
   the number of nodes per ring changes;
4. if ``seed`` is given, the interior nodes are first displaced randomly by up
   to 0.15 h (a different, equally valid mesh per seed).

Measured on the reference annulus (5, 53) mm: minimum angle 31.5–32° without
seed (>= 26° over seeds 0–9 at h = 1), 20,410 triangles / 10,387 nodes at
h = 1 (0.2–0.5 s), 80,903 triangles at h = 0.5 (~1.5 s).  The quality holds
for h up to about 2 r_inner; much coarser h than the inner radius gives
slivers at the hole (the inner circle keeps at least 6 nodes).

Graded meshes (``h_inner``, mm): the target size grows linearly in r from
h_inner on the inner circle to h at r_inner + ``grading_length`` (default
5 mm) and is h beyond.  Step 1 then uses ring radii spaced by the local row
height (size √3/2, closed-form inverse of the row count s(r)) and
``round(2π r_j / size(r_j))`` nodes per ring; step 3 replaces the plain
Laplacian (which drags nodes towards the finer side, where they have more
neighbours, and flattens the first rows onto the hole) by a size-weighted
centroid smoothing (weights |T| / size²).  The edge lengths follow the size
function to ~2 % on average at every radius.  Measured on (5, 53) mm:

    h    h_inner  triangles  nodes   min angle (seeds 0–9)  time
    1    None     20,410     10,387  31.7° (26.6°)          0.16 s  (uniform, bit for bit)
    1    0.5      20,788     10,592  33.1° (29.6°)          0.19 s
    1    0.25     21,761     11,110  33.1° (30.3°)          0.26 s
    1    0.125    23,360     11,972  31.3° (29.0°)          0.27 s
    2    None      5,101      2,642  31.9° (28.1°)          0.04 s
    2    1         5,194      2,696  33.6° (30.6°)          0.05 s

and min angle >= 26.5° even for size gradients (h − h_inner)/grading_length
up to 0.75 (h = 4 with h_inner = 0.5 or 0.25).

Outer grading (``h_outer``, mm) mirrors it: the target size grows linearly from
h_outer on the outer circle to h at r_outer − ``outer_grading_length`` (default
5 mm), to resolve the boundary layer at the drained outer wall.  With both, the
size is the smaller of the two ramps; the ring radii then come from the same
row count inverted piecewise between the ramps' knots.  Measured on (5, 53) mm:

    h    h_outer  triangles  nodes   min angle (seeds)      time (loaded machine)
    2    0.5       8,126      4,404  32.9° (32.4°, 0–9)     0.6 s
    2    0.25     11,858      6,603  33.6° (31.6°, 0–9)     0.7 s
    1    0.25     31,887     16,625  30.9° (29.3°, 0–2)     3.3 s

Boundary edges are stored per tag, oriented like their triangle
(counter-clockwise: the domain lies to the left of each edge, the outward
normal to the right) and ordered by polar angle.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np


class _FrozenDict(dict):
    """A dict that refuses mutation (the memoized meshes are shared); picklable."""

    def _ro(self, *a, **k):
        raise TypeError("Mesh.boundary_edges is read-only")

    __setitem__ = __delitem__ = update = pop = popitem = clear = setdefault = _ro

    def __reduce__(self):
        return (_FrozenDict, (dict(self),))


@dataclass(frozen=True, eq=False)
class Mesh:
    """Triangle mesh in mm.

    Attributes
    ----------
    points : (N, 2) float64 node coordinates, mm.
    triangles : (M, 3) int64 node ids, counter-clockwise.
    boundary_edges : {tag: (E, 2) int64 node ids}, each edge oriented with the
        domain on its left (annulus tags: "inner", "outer"; rectangle: "left",
        "right", "bottom", "top").
    """

    points: np.ndarray
    triangles: np.ndarray
    boundary_edges: dict

    def __post_init__(self):
        pts = np.ascontiguousarray(self.points, dtype=np.float64)
        tri = np.ascontiguousarray(self.triangles, dtype=np.int64)
        if pts.ndim != 2 or pts.shape[1] != 2:
            raise ValueError(f"points must have shape (N, 2), got {pts.shape}")
        if tri.ndim != 2 or tri.shape[1] != 3:
            raise ValueError(f"triangles must have shape (M, 3), got {tri.shape}")
        if tri.size and (tri.min() < 0 or tri.max() >= len(pts)):
            raise ValueError(f"triangles must index nodes in [0, {len(pts) - 1}]")
        edges = {}
        for name, e in dict(self.boundary_edges).items():
            e = np.ascontiguousarray(e, dtype=np.int64).reshape(-1, 2)
            e.setflags(write=False)
            edges[str(name)] = e
        pts.setflags(write=False)
        tri.setflags(write=False)
        object.__setattr__(self, "points", pts)
        object.__setattr__(self, "triangles", tri)
        object.__setattr__(self, "boundary_edges", _FrozenDict(edges))

    # ------------------------------------------------------------ basics
    @property
    def n_nodes(self) -> int:
        return int(len(self.points))

    @property
    def n_elements(self) -> int:
        return int(len(self.triangles))

    @property
    def inner_edges(self) -> np.ndarray:
        """Edges on the inner circle (annulus), (E, 2)."""
        return self.boundary_edges["inner"]

    @property
    def outer_edges(self) -> np.ndarray:
        """Edges on the outer circle (annulus), (E, 2)."""
        return self.boundary_edges["outer"]

    @property
    def areas(self) -> np.ndarray:
        """Signed element areas (M,), mm² (positive for counter-clockwise triangles)."""
        x = self.points[self.triangles]
        e1 = x[:, 1] - x[:, 0]
        e2 = x[:, 2] - x[:, 0]
        return 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])

    @property
    def centroids(self) -> np.ndarray:
        """Element centroids (M, 2), mm."""
        return self.points[self.triangles].mean(axis=1)

    def _tag(self, name: str) -> np.ndarray:
        if name not in self.boundary_edges:
            raise ValueError(f"unknown boundary tag {name!r}; available: {sorted(self.boundary_edges)}")
        return self.boundary_edges[name]

    def boundary_nodes(self, name: str) -> np.ndarray:
        """Sorted unique node ids on boundary ``name``."""
        return np.unique(self._tag(name))

    def edge_lengths(self, name: str) -> np.ndarray:
        """Lengths (E,) of the edges of boundary ``name``, mm."""
        e = self._tag(name)
        return np.linalg.norm(self.points[e[:, 1]] - self.points[e[:, 0]], axis=1)

    def edges(self) -> np.ndarray:
        """All unique edges (K, 2), sorted node ids per edge."""
        return _unique_edges(self.triangles)

    def min_angle_deg(self) -> np.ndarray:
        """Smallest interior angle of every element (M,), degrees."""
        return _min_angles_deg(self.points, self.triangles)

    @property
    def h_mean(self) -> float:
        """Mean length of the unique edges, mm."""
        e = self.edges()
        return float(np.linalg.norm(self.points[e[:, 1]] - self.points[e[:, 0]], axis=1).mean())


# ---------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------
def _unique_edges(tri: np.ndarray) -> np.ndarray:
    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    lo, hi = e.min(axis=1), e.max(axis=1)
    n = int(hi.max()) + 1 if len(hi) else 1
    key = np.unique(lo * n + hi)  # 1-D integer keys: much faster than unique(axis=0)
    return np.column_stack([key // n, key % n])


def _min_angles_deg(points: np.ndarray, tri: np.ndarray) -> np.ndarray:
    x = points[tri]
    a = np.linalg.norm(x[:, 1] - x[:, 2], axis=1)
    b = np.linalg.norm(x[:, 2] - x[:, 0], axis=1)
    c = np.linalg.norm(x[:, 0] - x[:, 1], axis=1)
    # smallest angle is opposite the shortest side; law of cosines
    s = np.sort(np.stack([a, b, c], axis=1), axis=1)
    cosang = (s[:, 1] ** 2 + s[:, 2] ** 2 - s[:, 0] ** 2) / (2.0 * s[:, 1] * s[:, 2])
    return np.degrees(np.arccos(np.clip(cosang, -1.0, 1.0)))


def _boundary_edges_oriented(tri: np.ndarray) -> np.ndarray:
    """Edges that belong to exactly one triangle, oriented as in that triangle."""
    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    n = int(e.max()) + 1
    key = e.min(axis=1) * n + e.max(axis=1)
    _, inv, counts = np.unique(key, return_inverse=True, return_counts=True)
    return e[counts[inv.ravel()] == 1]


def _ccw(points: np.ndarray, tri: np.ndarray) -> np.ndarray:
    x = points[tri]
    e1 = x[:, 1] - x[:, 0]
    e2 = x[:, 2] - x[:, 0]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    tri = tri.copy()
    neg = det < 0
    tri[neg] = tri[neg][:, [0, 2, 1]]
    return tri


def _check_finite(name, v):
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not math.isfinite(v):
        raise ValueError(f"{name}={v!r} is out of range: allowed a finite number")
    return float(v)


# ---------------------------------------------------------------------------
# annulus
# ---------------------------------------------------------------------------
GRADING_LENGTH = 5.0  # mm, default transition distance of the graded annulus mesh


def annulus_mesh(r_inner: float = 5.0, r_outer: float = 53.0, h: float = 1.0, seed: int | None = None,
                 h_inner: float | None = None, grading_length: float = GRADING_LENGTH,
                 h_outer: float | None = None, outer_grading_length: float = GRADING_LENGTH) -> Mesh:
    """Triangle mesh of the annulus r_inner <= r <= r_outer (all mm), uniform or graded.

    Parameters
    ----------
    r_inner, r_outer : radii, mm, 0 < r_inner < r_outer.
    h : target edge length, mm, 0 < h < (r_outer - r_inner)/2.  h = 1 gives ~20,000
        triangles for the paper's annulus (5, 53).
    seed : None (deterministic reference mesh) or int >= 0 (random perturbation of
        the interior nodes before smoothing, a different mesh per seed).
    h_inner : None (quasi-uniform mesh of size h) or the target edge length on the
        inner circle, mm, 0 < h_inner <= h.  The target size then grows linearly
        in r from h_inner at r_inner to h at r_inner + grading_length and is h
        beyond (see :func:`annulus_size`).  h_inner = None or h_inner == h gives
        exactly (bit for bit) the quasi-uniform mesh.
    grading_length : transition distance of the grading, mm, > 0 (default 5 mm,
        one inner radius of the paper's annulus); ignored when the mesh is uniform.
        The size gradient is (h - h_inner) / grading_length; minimum angles
        >= 26.5° were measured for gradients up to 0.75 (h = 4, h_inner = 0.25)
        and >= 32° for h = 1 with h_inner from 0.5 down to 0.05 mm.
    h_outer : None or the target edge length on the outer circle, mm, 0 < h_outer <= h,
        mirroring h_inner: the target size grows linearly from h_outer at r_outer to h
        at r_outer - outer_grading_length (it resolves the boundary layer at the
        drained outer wall).  Combinable with h_inner (the size is the smaller of the
        two ramps).  None or h_outer == h gives exactly (bit for bit) the mesh without it.
    outer_grading_length : transition distance of the outer grading, mm, > 0
        (default 5 mm); ignored when h_outer is None.

    Returns a frozen :class:`Mesh` with boundary tags "inner" and "outer"; boundary
    nodes lie exactly on the circles.  Results are memoized on the arguments (the
    arrays are read-only).
    """
    ri = _check_finite("r_inner", r_inner)
    ro = _check_finite("r_outer", r_outer)
    hh = _check_finite("h", h)
    if not ri > 0:
        raise ValueError(f"r_inner={r_inner!r} is out of range: allowed > 0")
    if not ro > ri:
        raise ValueError(f"r_outer={r_outer!r} is out of range: allowed > r_inner = {r_inner}")
    if not (0 < hh < (ro - ri) / 2):
        raise ValueError(f"h={h!r} is out of range: allowed (0, (r_outer - r_inner)/2 = {(ro - ri) / 2})")
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0):
        raise ValueError(f"seed={seed!r} is out of range: allowed None or an integer >= 0")
    hi, gl = _check_grading(hh, h_inner, grading_length)
    ho, glo = _check_grading(hh, h_outer, outer_grading_length, "h_outer", "outer_grading_length")
    seed = None if seed is None else int(seed)
    if ho is None:  # positional key: the meshes (and cache entries) without h_outer are unchanged
        return _annulus_cached(ri, ro, hh, seed, hi, gl)
    return _annulus_cached(ri, ro, hh, seed, hi, gl, ho, glo)


def _check_grading(h: float, h_side, grading_length, name="h_inner", length_name="grading_length"):
    """Validated (h_side, grading_length) cache key of one side; (None, None) when that side is ungraded."""
    if h_side is not None:
        if isinstance(h_side, bool) or not isinstance(h_side, (int, float, np.integer, np.floating)) \
                or not math.isfinite(h_side) or not (0 < h_side <= h):
            raise ValueError(f"{name}={h_side!r} is out of range: allowed (0, h = {h}]")
    if isinstance(grading_length, bool) or not isinstance(grading_length, (int, float, np.integer, np.floating)) \
            or not math.isfinite(grading_length) or not grading_length > 0:
        raise ValueError(f"{length_name}={grading_length!r} is out of range: allowed a finite number > 0")
    if h_side is None or float(h_side) == h:
        return None, None  # ungraded side: one cache entry, whatever grading_length
    return float(h_side), float(grading_length)


def annulus_size(r, h: float, h_inner: float | None = None, r_inner: float = 5.0,
                 grading_length: float = GRADING_LENGTH, h_outer: float | None = None,
                 r_outer: float = 53.0, outer_grading_length: float = GRADING_LENGTH) -> np.ndarray:
    """Target edge length (mm) at radius ``r`` (mm) of :func:`annulus_mesh`.

    The smaller of h_inner + (h - h_inner) min(1, (r - r_inner) / grading_length) and
    h_outer + (h - h_outer) min(1, (r_outer - r) / outer_grading_length); a side whose
    size is None contributes h.
    """
    r = np.asarray(r, dtype=np.float64)
    if h_inner is None and h_outer is None:
        return np.full(r.shape, float(h))
    if h_inner is None:
        size = np.full(r.shape, float(h))
    else:
        t = np.clip((r - r_inner) / grading_length, 0.0, 1.0)
        size = h_inner + (h - h_inner) * t
    if h_outer is not None:
        t = np.clip((r_outer - r) / outer_grading_length, 0.0, 1.0)
        size = np.minimum(size, h_outer + (h - h_outer) * t)
    return size


def _graded_radii(ri: float, ro: float, h: float, hi: float, gl: float) -> np.ndarray:
    """Ring radii with steps ~ size(r) √3/2 (size linear from hi at ri to h at ri + gl).

    s(r) = ∫_ri^r dr' / (size(r') √3/2) counts equilateral rows; it is inverted in
    closed form at n_r = ceil(s(ro)) equally spaced values, so every step is the
    local row height scaled by the same factor s(ro)/n_r <= 1.
    """
    k = 2.0 / math.sqrt(3.0)
    g = (h - hi) / gl  # size gradient dh/dr (> 0)
    s_gl = k * math.log1p((h - hi) / hi) / g  # rows in the transition zone

    def s_of(r):
        return k * math.log1p(g * min(r - ri, gl) / hi) / g + k * max(r - ri - gl, 0.0) / h

    s_tot = s_of(ro)
    n_r = max(2, int(math.ceil(s_tot - 1e-9)))
    s = np.linspace(0.0, s_tot, n_r + 1)
    r_in = ri + hi * np.expm1(g * s / k) / g
    r_out = ri + gl + (s - s_gl) * h / k
    radii = np.where(s <= s_gl, r_in, r_out)
    radii[0], radii[-1] = ri, ro  # boundary rings exactly on the circles
    return radii


def _piecewise_graded_radii(ri: float, ro: float, h: float, size, hi, gl, ho, glo) -> np.ndarray:
    """Ring radii with steps ~ size(r) √3/2 for any size(r) linear between the grading knots.

    The knots are r_inner + gl, r_outer - glo and the crossing of the two ramps
    (each clipped to the annulus).  On a segment [a, b] with sizes s_a, s_b the row
    count ∫ dr / (size √3/2) is (b - a) ln(s_b/s_a) / (s_b - s_a) · 2/√3 (or
    (b - a)/s_a · 2/√3 when s_a = s_b), inverted in closed form at n_r =
    ceil(s(ro)) equally spaced values, as in :func:`_graded_radii`.
    """
    k = 2.0 / math.sqrt(3.0)
    knots = [ri, ro]
    if gl is not None:
        knots.append(ri + gl)
    if glo is not None:
        knots.append(ro - glo)
    if gl is not None and glo is not None:  # where the rising and the falling ramp cross
        a, b = (h - hi) / gl, (h - ho) / glo
        knots.append((ho + b * ro - hi + a * ri) / (a + b))
    knots = np.unique(np.clip(knots, ri, ro))
    sk = size(knots)
    da, ds = np.diff(knots), np.diff(sk)
    flat = np.abs(ds) <= 1e-12 * sk[:-1]
    g = np.where(flat, 1.0, ds / da)  # size gradient per segment (1.0: placeholder on flat ones)
    rows = np.where(flat, k * da / sk[:-1], k * np.log(sk[1:] / sk[:-1]) / g)
    s_knot = np.concatenate([[0.0], np.cumsum(rows)])
    n_r = max(2, int(math.ceil(s_knot[-1] - 1e-9)))
    s = np.linspace(0.0, s_knot[-1], n_r + 1)
    j = np.clip(np.searchsorted(s_knot, s, side="right") - 1, 0, len(da) - 1)
    ds_in = s - s_knot[j]
    radii = knots[j] + np.where(flat[j], ds_in * sk[j] / k, sk[j] * np.expm1(g[j] * ds_in / k) / g[j])
    radii[0], radii[-1] = ri, ro  # boundary rings exactly on the circles
    return radii


N_RETRIANGULATE = 2  # smoothing rounds, each followed by a Delaunay re-triangulation
N_SWEEPS = 3  # Laplacian sweeps per round


@lru_cache(maxsize=16)
def _annulus_cached(ri: float, ro: float, h: float, seed, hi=None, gl=None, ho=None, glo=None) -> Mesh:
    """Rings of nodes, a random perturbation, smoothing with re-triangulation, and the boundary tags."""
    graded = hi is not None or ho is not None

    def size(r):
        return annulus_size(r, h, hi, ri, gl, ho, ro, glo)

    radii, ring_h = _ring_radii(ri, ro, h, size, graded, hi, gl, ho, glo)
    pts, ring_id = _ring_nodes(radii, ring_h)
    n_r = len(radii) - 1
    inner, outer = ring_id == 0, ring_id == n_r
    free = ~(inner | outer)
    if seed is not None:
        _perturb(pts, free, ring_h[ring_id[free]] / h if graded else 1.0, h, seed)
    # keep perturbed / smoothed interior nodes strictly inside the annulus
    margins = (0.25 * ring_h[0], 0.25 * ring_h[-1])
    tri = _smooth(pts, free, inner, ri, ro, margins, size if graded else None)
    return Mesh(points=pts, triangles=tri, boundary_edges=_tag_boundary(pts, tri, inner, outer))


def _ring_radii(ri, ro, h, size, graded, hi, gl, ho, glo):
    """Radii of the node rings (mm) and the target size on each (mm)."""
    if graded:
        # inner grading alone keeps its closed form (its meshes stay bit for bit)
        radii = _graded_radii(ri, ro, h, hi, gl) if ho is None else _piecewise_graded_radii(ri, ro, h, size, hi, gl, ho, glo)
        return radii, size(radii)
    n_r = max(2, int(math.ceil((ro - ri) / (h * math.sqrt(3.0) / 2.0) - 1e-9)))
    return np.linspace(ri, ro, n_r + 1), np.full(n_r + 1, h)


def _ring_nodes(radii, ring_h):
    """Nodes evenly spaced on each ring at its target size, odd rings rotated by half a spacing; (points, ring id)."""
    rings, ring_id = [], []
    for j, r in enumerate(radii):
        n = max(6, int(round(2.0 * math.pi * r / ring_h[j])))
        theta = 2.0 * math.pi * (np.arange(n) + 0.5 * (j % 2)) / n
        rings.append(np.column_stack([r * np.cos(theta), r * np.sin(theta)]))
        ring_id.append(np.full(n, j))
    return np.concatenate(rings), np.concatenate(ring_id)


def _perturb(pts, free, local, h, seed):
    """Move the free nodes in place by up to 0.15 of the local target size (``local`` h_local / h), seeded."""
    rng = np.random.default_rng(seed)
    rad = rng.uniform(0.0, 0.15 * h, free.sum())
    rad *= local
    ang = rng.uniform(0.0, 2.0 * math.pi, free.sum())
    pts[free] += np.column_stack([rad * np.cos(ang), rad * np.sin(ang)])


def _triangulate(p, inner, ri):
    """Delaunay triangles of p without those in the hole (centroid inside r_inner, or all nodes on it), ccw."""
    from scipy.spatial import Delaunay  # here, not at the top: solver.budget reads this module's sizes only

    tri = Delaunay(p).simplices.astype(np.int64)
    c = p[tri].mean(axis=1)
    keep = (np.hypot(c[:, 0], c[:, 1]) > ri) & ~inner[tri].all(axis=1)
    return _ccw(p, tri[keep])


def _smooth(pts, free, inner, ri, ro, margins, size=None):
    """Smooth the free nodes in place (``N_RETRIANGULATE`` rounds of ``N_SWEEPS`` sweeps on fixed
    connectivity, each round re-triangulated: Delaunay dominates the cost); returns the triangles.

    Uniform meshes (``size`` None): each free node -> the mean of its edge neighbours.  Graded meshes: plain
    Laplacian smoothing would pull the nodes towards the side with more neighbours (the fine side) and
    collapse the first rows onto the boundary.  Instead, each free node -> the weighted mean of the
    centroids c_T of its triangles, weights |T| / size(c_T)² (the number of target-size elements T covers):
    the small triangles of the fine side are many but light, and a mesh that follows the size function is
    at equilibrium.
    """
    tri = _triangulate(pts, inner, ri)
    n = len(pts)
    for _ in range(N_RETRIANGULATE):
        e = _unique_edges(tri)
        src = np.concatenate([e[:, 0], e[:, 1]])
        dst = np.concatenate([e[:, 1], e[:, 0]])
        deg = np.bincount(src, minlength=n)
        v = tri.ravel()
        for _ in range(N_SWEEPS):
            if size is not None:
                x = pts[tri]
                c = x.mean(axis=1)
                e1, e2 = x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]
                w = 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
                w /= size(np.hypot(c[:, 0], c[:, 1])) ** 2
                w3 = np.repeat(w, 3)
                wsum = np.bincount(v, w3, minlength=n)
                c_sum = np.column_stack([np.bincount(v, w3 * np.repeat(c[:, k], 3), minlength=n) for k in range(2)])
                new = c_sum[free] / wsum[free, None]
            else:
                nb_sum = np.column_stack([np.bincount(src, pts[dst, k], minlength=n) for k in range(2)])
                new = nb_sum[free] / deg[free, None]
            r = np.hypot(new[:, 0], new[:, 1])
            rc = np.clip(r, ri + margins[0], ro - margins[1])
            new *= (rc / r)[:, None]
            pts[free] = new
        tri = _triangulate(pts, inner, ri)
    return tri


def _tag_boundary(pts, tri, inner, outer) -> dict:
    """Boundary edges tagged "inner" and "outer", each sorted by angle; raises if the rings were not recovered."""
    bnd = _boundary_edges_oriented(tri)
    mid = pts[bnd].mean(axis=1)
    on_inner = inner[bnd].all(axis=1)
    on_outer = outer[bnd].all(axis=1)
    if not (on_inner | on_outer).all() or on_inner.sum() != inner.sum() or on_outer.sum() != outer.sum():
        raise RuntimeError("annulus_mesh: boundary recovery failed (mesh too coarse for the radii?)")
    ang = np.arctan2(mid[:, 1], mid[:, 0])
    edges = {}
    for name, mask in (("inner", on_inner), ("outer", on_outer)):
        sel = bnd[mask]
        edges[name] = sel[np.argsort(ang[mask], kind="stable")]
    return edges


# ---------------------------------------------------------------------------
# rectangle
# ---------------------------------------------------------------------------
def rectangle_mesh(lx: float, ly: float, nx: int, ny: int, x0: float = 0.0, y0: float = 0.0,
                   diagonal: str = "alternate") -> Mesh:
    """Structured triangles on [x0, x0+lx] x [y0, y0+ly] (mm), nx x ny cells, 2 triangles each.

    ``diagonal``: "right" (every cell split along its (x0,y0)-(x1,y1) diagonal),
    "left" (the other diagonal) or "alternate" (checkerboard of both: no
    preferred direction).  Tags "left", "right", "bottom", "top"; nodes are
    numbered row by row (node id = j (nx+1) + i).
    """
    lx = _check_finite("lx", lx)
    ly = _check_finite("ly", ly)
    x0 = _check_finite("x0", x0)
    y0 = _check_finite("y0", y0)
    if lx <= 0:
        raise ValueError(f"lx={lx!r} is out of range: allowed > 0")
    if ly <= 0:
        raise ValueError(f"ly={ly!r} is out of range: allowed > 0")
    for name, v in (("nx", nx), ("ny", ny)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise ValueError(f"{name}={v!r} is out of range: allowed an integer >= 1")
    if diagonal not in ("alternate", "right", "left"):
        raise ValueError(f"diagonal={diagonal!r} is out of range: allowed one of ('alternate', 'right', 'left')")
    nx, ny = int(nx), int(ny)
    xs = x0 + lx * np.arange(nx + 1) / nx
    ys = y0 + ly * np.arange(ny + 1) / ny
    X, Y = np.meshgrid(xs, ys)
    pts = np.column_stack([X.ravel(), Y.ravel()])
    I, J = np.meshgrid(np.arange(nx), np.arange(ny))
    I, J = I.ravel(), J.ravel()
    n00 = J * (nx + 1) + I
    n10, n01, n11 = n00 + 1, n00 + nx + 1, n00 + nx + 2
    if diagonal == "right":
        flip = np.zeros(len(n00), bool)
    elif diagonal == "left":
        flip = np.ones(len(n00), bool)
    else:
        flip = (I + J) % 2 == 1
    t1 = np.where(flip[:, None], np.column_stack([n00, n10, n01]), np.column_stack([n00, n10, n11]))
    t2 = np.where(flip[:, None], np.column_stack([n10, n11, n01]), np.column_stack([n00, n11, n01]))
    tri = np.concatenate([t1, t2])
    ii = np.arange(nx)
    jj = np.arange(ny)
    edges = {
        "bottom": np.column_stack([ii, ii + 1]),
        "right": np.column_stack([jj * (nx + 1) + nx, (jj + 1) * (nx + 1) + nx]),
        "top": np.column_stack([ny * (nx + 1) + ii + 1, ny * (nx + 1) + ii])[::-1],
        "left": np.column_stack([(jj + 1) * (nx + 1), jj * (nx + 1)])[::-1],
    }
    return Mesh(points=pts, triangles=tri, boundary_edges=edges)


# ---------------------------------------------------------------------------
# I/O
# ---------------------------------------------------------------------------
_TAG_PREFIX = "bnd_"


def write_mesh(mesh: Mesh, path) -> None:
    """Write ``mesh`` with meshio (format from the suffix: .xdmf (+ .h5), .vtu, ...).

    Triangles are one cell block; each boundary tag's edges are "line" cells in a
    second block.  Cell data: ``boundary_id`` (0 for triangles, 1 + index of the
    tag in sorted order for edges, for colouring in ParaView) and one indicator
    array ``bnd_<tag>`` per tag (the tag names survive the round trip this way).
    """
    import meshio

    names = sorted(mesh.boundary_edges)
    lines = [mesh.boundary_edges[n] for n in names]
    cells = [("triangle", np.asarray(mesh.triangles))]
    cell_data = {"boundary_id": [np.zeros(mesh.n_elements, dtype=np.int64)]}
    if names:
        line_cells = np.concatenate(lines) if lines else np.zeros((0, 2), np.int64)
        ids = np.concatenate([np.full(len(l), k + 1, dtype=np.int64) for k, l in enumerate(lines)])
        if len(line_cells):
            cells.append(("line", line_cells))
            cell_data["boundary_id"].append(ids)
            for k, n in enumerate(names):
                cell_data[_TAG_PREFIX + n] = [np.zeros(mesh.n_elements, np.int64), (ids == k + 1).astype(np.int64)]
    m = meshio.Mesh(np.asarray(mesh.points), cells, cell_data=cell_data)
    path = Path(path)
    if path.suffix.lower() == ".vtu":
        # VTU stores 3-D points; pad explicitly (meshio would warn)
        m.points = np.column_stack([m.points, np.zeros(len(m.points))])
    meshio.write(str(path), m)
    # tags with no edges at all cannot be stored as cells: record them
    empty = [n for n in names if len(mesh.boundary_edges[n]) == 0]
    side = path.with_name(path.name + ".empty_tags.json")
    if empty:
        side.write_text(json.dumps(empty))
    elif side.exists():
        side.unlink()


def read_mesh(path) -> Mesh:
    """Read a mesh written by :func:`write_mesh` (identical arrays and tags)."""
    import meshio

    path = Path(path)
    m = meshio.read(str(path))
    pts = np.asarray(m.points, dtype=np.float64)[:, :2]
    tri, lines, line_block = None, None, None
    for k, block in enumerate(m.cells):
        if block.type == "triangle":
            tri = np.asarray(block.data, dtype=np.int64)
        elif block.type == "line":
            lines, line_block = np.asarray(block.data, dtype=np.int64), k
    if tri is None:
        raise ValueError(f"{path}: no triangle cells")
    edges = {}
    for key, data in m.cell_data.items():
        if key.startswith(_TAG_PREFIX) and line_block is not None:
            mask = np.asarray(data[line_block]).astype(bool)
            edges[key[len(_TAG_PREFIX):]] = lines[mask]
    side = path.with_name(path.name + ".empty_tags.json")
    if side.exists():
        for n in json.loads(side.read_text()):
            edges[n] = np.zeros((0, 2), np.int64)
    return Mesh(points=pts, triangles=tri, boundary_edges=edges)
