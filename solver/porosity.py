"""Initial porosity fields φ0, one value per element (dimensionless), paper Sec. 3.3.

* :func:`random_porosity` — the paper's default: uniform random per element in
  [0.2, 0.6] (mean 0.4).  It changes with the mesh by construction.
* :func:`pocket_porosity` — the mesh-independent field of the convergence study
  (Sec. 3.4, Fig. ini-poro-fields b): constant 0.4 with three small circular
  high-porosity pockets near the inner boundary, 120° apart.  The paper gives
  no numbers; our choice (module constants below): pocket centres at radius
  r_inner + 2 mm (7 mm for the reference annulus), polar angles 90°, 210°,
  330°, pocket radius 1.5 mm, pocket porosity 0.6 (the top of the random
  range).  An element's value is base + (pocket − base) × (area fraction of the
  element inside a pocket), the fraction estimated by the midpoint rule on the
  uniform refinement of the element into ``POCKET_SUBDIVISION``² congruent
  sub-triangles, so ∫ φ0 dA converges to the exact value as h -> 0.
* :func:`constant_porosity`, and :func:`initial_porosity` dispatching on
  ``Parameters.porosity_field``.
"""
from __future__ import annotations

import math

import numpy as np

from .mesh import Mesh

POCKET_VALUE = 0.6  # porosity inside a pocket, -
POCKET_RADIUS = 1.5  # mm
POCKET_OFFSET = 2.0  # mm, pocket centre radius = r_inner + POCKET_OFFSET
POCKET_ANGLE0_DEG = 90.0  # polar angle of the first pocket, degrees; others at +120°, +240°
POCKET_SUBDIVISION = 8  # sub-triangles per element edge for the area fraction (64 samples)


def _check_mesh(mesh):
    if not isinstance(mesh, Mesh):
        raise ValueError(f"mesh={type(mesh).__name__} is not allowed: expected a solver.mesh.Mesh")


def _num(name, v):
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not math.isfinite(v):
        raise ValueError(f"{name}={v!r} is out of range: allowed a finite number")
    return float(v)


def _open_unit(name, v):
    v = _num(name, v)
    if not 0.0 < v < 1.0:
        raise ValueError(f"{name}={v!r} is out of range: allowed the open interval (0, 1)")
    return v


def random_porosity(mesh: Mesh, mean: float = 0.4, half_range: float = 0.2, seed: int = 0) -> np.ndarray:
    """Uniform random porosity per element in [mean − half_range, mean + half_range] (M,), -.

    Drawn with ``numpy.random.default_rng(seed).uniform`` in element order (same
    mesh and seed -> same field).  The bounds must lie inside (0, 1).
    """
    _check_mesh(mesh)
    mean = _open_unit("mean", mean)
    half_range = _num("half_range", half_range)
    if not (half_range >= 0 and mean - half_range > 0 and mean + half_range < 1):
        raise ValueError(f"half_range={half_range!r} is out of range: allowed [0, {min(mean, 1 - mean)}) "
                         f"so that mean ± half_range stays inside (0, 1)")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed={seed!r} is out of range: allowed an integer >= 0")
    rng = np.random.default_rng(int(seed))
    return rng.uniform(mean - half_range, mean + half_range, mesh.n_elements)


def constant_porosity(mesh: Mesh, value: float = 0.4) -> np.ndarray:
    """Constant porosity ``value`` in (0, 1) on every element (M,), -."""
    _check_mesh(mesh)
    value = _open_unit("value", value)
    return np.full(mesh.n_elements, value)


def pocket_centers(center_radius: float = 5.0 + POCKET_OFFSET, angle0_deg: float = POCKET_ANGLE0_DEG) -> np.ndarray:
    """Centres (3, 2) in mm of the three pockets: radius ``center_radius``, angles angle0 + 0/120/240°."""
    ang = np.radians(angle0_deg + np.array([0.0, 120.0, 240.0]))
    return center_radius * np.column_stack([np.cos(ang), np.sin(ang)])


def _subtriangle_barycentric(n: int) -> np.ndarray:
    """Barycentric centroids (n², 3) of the n² congruent sub-triangles of a uniform refinement."""
    pts = []
    for i in range(n):
        for j in range(n - i):
            # "upward" sub-triangle with corner (i, j)
            pts.append(((i + 1 / 3), (j + 1 / 3)))
            if i + j < n - 1:  # "downward" sub-triangle
                pts.append(((i + 2 / 3), (j + 2 / 3)))
    ab = np.array(pts) / n
    return np.column_stack([1.0 - ab.sum(axis=1), ab[:, 0], ab[:, 1]])


def pocket_fraction(mesh: Mesh, centers: np.ndarray, radius: float, subdivision: int = POCKET_SUBDIVISION) -> np.ndarray:
    """Area fraction (M,) of each element inside the union of discs (``centers`` (P, 2), ``radius``), mm.

    Midpoint rule on the ``subdivision``² congruent sub-triangles of each element;
    only elements whose circumscribing disc can reach a pocket are sampled.
    """
    _check_mesh(mesh)
    centers = np.asarray(centers, dtype=float).reshape(-1, 2)
    x = mesh.points[mesh.triangles]  # (M, 3, 2)
    c = x.mean(axis=1)
    reach = np.linalg.norm(x - c[:, None, :], axis=2).max(axis=1)  # element "radius" about centroid
    d = np.linalg.norm(c[:, None, :] - centers[None, :, :], axis=2)  # (M, P)
    cand = np.nonzero((d <= radius + reach[:, None]).any(axis=1))[0]
    frac = np.zeros(mesh.n_elements)
    if len(cand) == 0:
        return frac
    bary = _subtriangle_barycentric(subdivision)  # (S, 3)
    samples = np.einsum("sa,mad->msd", bary, x[cand])  # (C, S, 2)
    inside = np.zeros(samples.shape[:2], dtype=bool)
    for ctr in centers:  # loop over the 3 pockets, vectorized over elements and samples
        inside |= ((samples - ctr) ** 2).sum(axis=2) <= radius**2
    frac[cand] = inside.mean(axis=1)
    return frac


def pocket_porosity(mesh: Mesh, base: float = 0.4, pocket_value: float = POCKET_VALUE,
                    radius: float = POCKET_RADIUS, center_radius: float = 5.0 + POCKET_OFFSET,
                    angle0_deg: float = POCKET_ANGLE0_DEG) -> np.ndarray:
    """Constant ``base`` porosity with three circular pockets of ``pocket_value`` (M,), -.

    Pockets: radius ``radius`` mm, centres at radius ``center_radius`` mm and polar
    angles angle0_deg + 0°, 120°, 240°.  Element value = base + (pocket_value − base)
    × area fraction inside a pocket (:func:`pocket_fraction`), so the field is the
    L2 projection-like average of a mesh-independent function and ∫ φ0 dA
    converges with h.
    """
    _check_mesh(mesh)
    base = _open_unit("base", base)
    pocket_value = _open_unit("pocket_value", pocket_value)
    radius = _num("radius", radius)
    center_radius = _num("center_radius", center_radius)
    angle0_deg = _num("angle0_deg", angle0_deg)
    if radius <= 0:
        raise ValueError(f"radius={radius!r} is out of range: allowed > 0")
    if center_radius < 0:
        raise ValueError(f"center_radius={center_radius!r} is out of range: allowed >= 0")
    frac = pocket_fraction(mesh, pocket_centers(center_radius, angle0_deg), radius)
    return base + (pocket_value - base) * frac


def initial_porosity(mesh: Mesh, params) -> np.ndarray:
    """φ0 per element (M,) for ``params`` (:class:`solver.params.Parameters`).

    "random": uniform in phi_mean ± phi_range with ``params.seed``;
    "pockets": base phi_mean, pockets of :data:`POCKET_VALUE` centred at
    r_inner + :data:`POCKET_OFFSET`; "constant": phi_mean everywhere.
    """
    kind = params.porosity_field
    if kind == "random":
        return random_porosity(mesh, params.phi_mean, params.phi_range, params.seed)
    if kind == "pockets":
        return pocket_porosity(mesh, base=params.phi_mean, center_radius=params.r_inner + POCKET_OFFSET)
    if kind == "constant":
        return constant_porosity(mesh, params.phi_mean)
    raise ValueError(f"porosity_field={kind!r} is out of range: allowed one of ('random', 'pockets', 'constant')")
