"""Flow-regime classifier for one snapshot of an annulus simulation.

Units: lengths in mm, angles in radians unless the name says ``_deg``, areas in mm^2.

The classifier works on fields given as arrays on any triangulation of an annulus
(``points`` (N, 2) in mm, ``triangles`` (M, 3)), the saturation ``S`` (nodal) and the
porosity ``phi`` (nodal or per element).  All the geometry is done on a square raster
of pixel size ``pixel`` (default 0.4 h, h = median edge length of the mesh) built once
per mesh (``build_raster``, cached): every pixel centre is located in its triangle and
nodal fields are interpolated linearly (barycentric weights), element fields are
sampled piecewise constant.  On the raster:

* open regions and cracks come from connected components (``scipy.ndimage.label``);
* crack branches are the significant maxima of the radius r over the crack pixels,
  found with ``skimage.morphology.h_maxima`` (0-dimensional persistence: a tip counts
  when one must descend by at least ``min_branch_length`` in r before reaching a
  farther tip); this counts separate cracks and the arms of forked cracks alike, and
  cracks joined by an open ring around the cavity are still counted separately;
* the front is the S = 0.5 contour (``skimage.measure.find_contours``) of the invaded
  region connected to the inner cavity, written r(theta) as its outer envelope;
* fingers are the peaks of r(theta) of prominence >= ``finger_prominence``
  (``scipy.signal.find_peaks`` on the periodic signal);
* the invasion reach outside the cracks is a Euclidean distance transform.

The regime rules are in ``REGIME_RULES`` (also copied into ``classify_fields``).
Choices the paper leaves open (Sec. 3.6: "longest crack longer than an arbitrarily
small length", crack = region with phi = 1 measured from the centre; Sec. 3.8: the five
regimes described in words) are made explicit there, with their defaults.
"""
from __future__ import annotations

import hashlib
import math
from collections import OrderedDict
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from types import MappingProxyType
from typing import Any, Mapping, NamedTuple

import numpy as np
from scipy import ndimage as ndi

from solver.tomlio import read_toml

__all__ = [
    "REGIMES",
    "FRACTURING_REGIMES",
    "REGIME_RULES",
    "ClassifierOptions",
    "Classification",
    "MeshRaster",
    "RunClassification",
    "build_raster",
    "classify_fields",
    "front_of_fields",
    "classify_run",
    "select_snapshot",
    "list_snapshots",
    "classification_to_dict",
]

REGIMES = (
    "uniform_invasion",
    "viscous_fingering",
    "invasive_fracturing",
    "non_invasive_fracturing",
    "fracturing_fingering",
)
FRACTURING_REGIMES = frozenset(REGIMES[2:])

REGIME_RULES = """\
Regime rules (sweep.classify; one snapshot; h = median mesh edge length, mm)
Definitions
  * Open region: phi >= phi_open (0.99). The paper measures cracks on the porosity
    field (phi = 1 regions), not on the damage field (Sec. 3.5, 3.6).
  * Crack: 8-connected open region on the raster whose area is at least
    min_open_area (default 3 median element areas, so isolated open elements of the
    random porosity field never count) and which comes within inner_tol (default 2 h)
    of the inner cavity. crack_tip_radius = largest distance from the centre reached by
    a crack; crack_length = crack_tip_radius - r_inner (0 when there is no crack).
  * Crack branches (n_cracks): maxima of r over the crack pixels whose dynamic (depth
    in r of the saddle to any farther tip) is >= min_branch_length (default
    max(min_crack_length, l_d)); a crack longer than min_crack_length counts at least
    once. Separate cracks and the arms of a fork are branches alike.
  * Front: outer boundary of the region S >= 0.5 that is connected to the inner
    cavity (invaded patches not connected to the inlet are ignored), written r(theta)
    as its outer envelope (n_theta = 720 bins).
  * Fingers (n_fingers): peaks of r(theta) with prominence >= finger_prominence
    (default max(l_S, 2 h)): a bump of the S = 0.5 contour smaller than the diffuse
    interface width l_S is not resolved as a finger by the model.
  * Invasion reach outside the cracks: largest distance from an invaded point to the
    nearest source of invading fluid (inner cavity or crack).
  * A finger is explained by the cracks when its angle is within alignment_tol_deg
    (default 15 deg) of the direction of a crack-branch tip (an invasion lobe ahead
    of / along a crack).
Rules
  1. fracturing iff crack_length > min_crack_length (L_min, default max(2 mm, 2 h)):
     the two regimes of the Ca*-C diagram (porous invasion / fracturing).  crack_length is
     the classified snapshot's (crack_record = "snapshot"), or the longest the run made up
     to it (crack_record = "longest").
  2. Not fracturing: viscous_fingering iff n_fingers >= min_fingers (default 2),
     otherwise uniform_invasion.
  3. Fracturing: non_invasive_fracturing iff the invasion reach outside the cracks is
     <= confined_distance (default l_S/2 + l_d = 6 mm: half a diffuse interface around
     the open channel plus a process zone of about l_d ahead of a tip), i.e. the
     invading fluid is confined to the open cracks; otherwise fracturing_fingering iff
     at least min_fingers fingers are not explained by the cracks; otherwise
     invasive_fracturing (this includes one invasion branch along each crack, as in
     the paper's reference run: three main invasion branches over three cracks).
"""


# --------------------------------------------------------------------------- options
CRACK_RECORDS = ("snapshot", "longest")
HISTORY_PHI_OPEN = 0.99  # the level of the time series' open_tip_radius (solver.metrics.open_tip_radius)


@dataclass(frozen=True)
class ClassifierOptions:
    """Thresholds of the classifier (lengths in mm). ``None`` = default derived from h.

    phi_open: porosity above which a region is open (default 0.99).
    s_front: saturation level of the front (0.5, as the paper's white contours).
    l_S, l_d: regularisation lengths of S and d (mm, Table A: 4.0 and 4.0).
    pixel: raster pixel size (default 0.4 h, clipped to [0.15, 1.0] mm).
    min_crack_length: L_min of rule 1 (default max(2.0, 2 h)).
    min_branch_length: dynamic of a crack-branch tip (default max(L_min, l_d)).
    min_open_area: smallest open component kept as a crack (default 3 element areas).
    inner_tol: a crack must come within this distance of the cavity (default 2 h).
    finger_prominence: smallest prominence of a finger of r(theta) (default max(l_S, 2 h)).
    min_fingers: number of (unexplained) fingers that makes fingering (default 2).
    confined_distance: invasion reach under which fracturing is non-invasive
        (default l_S/2 + l_d).
    alignment_tol_deg: angular tolerance of a crack-aligned invasion lobe (deg).
    n_theta: number of angular bins of r(theta).
    crack_record: which crack rule 1 reads.  "snapshot" (default, the paper's Sec. 3.6): the crack of the
        classified snapshot.  "longest": the longest crack the run made up to the classified time, the larger of
        the snapshot's crack and the time series' open_tip_radius - r_inner over the accepted steps at
        t <= t_classified (``classify_run`` only; needs phi_open = 0.99, the level of that time-series column).
        The experiment's cracks are broken cement bonds and stay; the model's dilated crack zones can close
        elastically after about 2 s, so a label read on the snapshot depends on when it is read.
    """

    phi_open: float = 0.99
    s_front: float = 0.5
    l_S: float = 4.0
    l_d: float = 4.0
    pixel: float | None = None
    min_crack_length: float | None = None
    min_branch_length: float | None = None
    min_open_area: float | None = None
    inner_tol: float | None = None
    finger_prominence: float | None = None
    min_fingers: int = 2
    confined_distance: float | None = None
    alignment_tol_deg: float = 15.0
    n_theta: int = 720
    crack_record: str = "snapshot"

    def __post_init__(self) -> None:
        _check_range("phi_open", self.phi_open, 0.0, 1.0, lo_open=True)
        _check_range("s_front", self.s_front, 0.0, 1.0, lo_open=True, hi_open=True)
        for name in ("l_S", "l_d"):
            _check_range(name, getattr(self, name), 0.0, math.inf, lo_open=True, hi_open=True)
        for name in ("pixel", "min_crack_length", "min_branch_length", "min_open_area",
                     "inner_tol", "finger_prominence", "confined_distance"):
            v = getattr(self, name)
            if v is not None:
                _check_range(name, v, 0.0, math.inf, lo_open=name == "pixel", hi_open=True)
        if not isinstance(self.min_fingers, (int, np.integer)) or self.min_fingers < 1:
            raise ValueError(f"min_fingers={self.min_fingers!r}: must be an integer >= 1")
        _check_range("alignment_tol_deg", self.alignment_tol_deg, 0.0, 180.0)
        if not isinstance(self.n_theta, (int, np.integer)) or not 16 <= self.n_theta <= 100_000:
            raise ValueError(f"n_theta={self.n_theta!r}: must be an integer in [16, 100000]")
        if self.crack_record not in CRACK_RECORDS:
            raise ValueError(f"crack_record={self.crack_record!r}: must be one of {CRACK_RECORDS}")
        if self.crack_record == "longest" and self.phi_open != HISTORY_PHI_OPEN:
            raise ValueError(f"crack_record='longest' with phi_open={self.phi_open!r}: the time series records "
                             f"the open region at phi_open = {HISTORY_PHI_OPEN} only")

    def resolved(self, h: float) -> dict[str, float]:
        """Numerical thresholds for a mesh of median edge length ``h`` (mm)."""
        l_min = self.min_crack_length if self.min_crack_length is not None else max(2.0, 2.0 * h)
        return {
            "h": h,
            "phi_open": self.phi_open,
            "s_front": self.s_front,
            "min_crack_length": l_min,
            "min_branch_length": (self.min_branch_length if self.min_branch_length is not None
                                  else max(l_min, self.l_d)),
            "inner_tol": self.inner_tol if self.inner_tol is not None else 2.0 * h,
            "finger_prominence": (self.finger_prominence if self.finger_prominence is not None
                                  else max(self.l_S, 2.0 * h)),
            "confined_distance": (self.confined_distance if self.confined_distance is not None
                                  else 0.5 * self.l_S + self.l_d),
            "min_fingers": int(self.min_fingers),
            "alignment_tol_deg": self.alignment_tol_deg,
        }


def _check_range(name: str, value: Any, lo: float, hi: float, *,
                 lo_open: bool = False, hi_open: bool = False) -> None:
    """Raise ValueError naming ``name`` unless lo <= value <= hi (open ends as flagged)."""
    allowed = f"{'(' if lo_open else '['}{lo}, {hi}{')' if hi_open else ']'}"
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}={value!r}: must be a number in {allowed}") from None
    ok = (not math.isnan(v) and (v > lo if lo_open else v >= lo)
          and (v < hi if hi_open else v <= hi))
    if not ok:
        raise ValueError(f"{name}={value!r}: must be a number in {allowed}")


# --------------------------------------------------------------------------- result
@dataclass(frozen=True)
class Classification:
    """Result of ``classify_fields`` (lengths mm, angles rad, areas mm^2).

    crack_tip_radius: farthest distance from the centre reached by a crack (r_inner if none).
    crack_length: crack_tip_radius - r_inner (0 if none).
    n_cracks: number of open crack branches; crack_tip_angles: their tip angles.
    open_area: area of the cracks.
    front_radius_mean / _min / _max: angular mean / min / max of the front r(theta).
    n_fingers: fingers of the front; finger_angles, finger_radii: their tip angles and
        radii r(theta) (sorted by angle; the paper's reference front distance of 45 mm is
        the mean over the three main invasion branches).
    n_unexplained_fingers: fingers not aligned with a crack tip (= n_fingers without cracks).
    invasion_reach: largest distance of an invaded point to the cavity or a crack.
    outside_fraction: invaded area farther than confined_distance from cavity/cracks,
        over the invaded area (0..1).
    invaded_area: area of the invaded region connected to the cavity (without cavity).
    fracturing: rule 1 of REGIME_RULES; regime: one of REGIMES.
    front_theta, front_r: r(theta) samples (bin centres, radii).
    thresholds: the resolved thresholds used.
    """

    crack_tip_radius: float
    crack_length: float
    n_cracks: int
    crack_tip_angles: tuple[float, ...]
    open_area: float
    front_radius_mean: float
    front_radius_min: float
    front_radius_max: float
    n_fingers: int
    finger_angles: tuple[float, ...]
    finger_radii: tuple[float, ...]
    n_unexplained_fingers: int
    invasion_reach: float
    outside_fraction: float
    invaded_area: float
    fracturing: bool
    regime: str
    front_theta: np.ndarray = field(repr=False, compare=False)
    front_r: np.ndarray = field(repr=False, compare=False)
    thresholds: Mapping[str, float] = field(repr=False, compare=False,
                                            default_factory=lambda: MappingProxyType({}))


_DICT_SCALARS = (
    "regime", "fracturing", "crack_tip_radius", "crack_length", "n_cracks", "open_area",
    "front_radius_mean", "front_radius_min", "front_radius_max", "n_fingers",
    "n_unexplained_fingers", "invasion_reach", "outside_fraction", "invaded_area",
)


def classification_to_dict(c: Classification, prefix: str = "") -> dict[str, Any]:
    """Flat dict of the scalar results of ``c`` for tables (lengths mm, areas mm^2).

    Angles are given in degrees as ';'-joined strings (``crack_tip_angles_deg``,
    ``finger_angles_deg``) so that the row stays flat; ``finger_radius_mean`` is the mean
    tip radius of the fingers / invasion branches (NaN without fingers).
    """
    if not isinstance(c, Classification):
        raise ValueError(f"c={type(c).__name__}: must be a Classification")
    out: dict[str, Any] = {}
    for name in _DICT_SCALARS:
        v = getattr(c, name)
        if isinstance(v, (bool, np.bool_)):
            v = bool(v)
        elif isinstance(v, (int, np.integer)):
            v = int(v)
        elif isinstance(v, (float, np.floating)):
            v = float(v)
        out[prefix + name] = v
    out[prefix + "finger_radius_mean"] = float(np.mean(c.finger_radii)) if c.finger_radii else math.nan
    out[prefix + "crack_tip_angles_deg"] = ";".join(f"{math.degrees(a):.1f}" for a in c.crack_tip_angles)
    out[prefix + "finger_angles_deg"] = ";".join(f"{math.degrees(a):.1f}" for a in c.finger_angles)
    return out


# --------------------------------------------------------------------------- raster
@dataclass(frozen=True, eq=False)
class MeshRaster:
    """Pixel -> triangle map of a triangulation (mm).

    ``tri`` (ny, nx) triangle of each pixel centre, -1 outside the mesh; ``nodes`` and
    ``weights`` (ny, nx, 3) its vertices and barycentric weights; ``r``/``theta`` polar
    coordinates of the pixel centres about ``centre``; ``x``/``y`` pixel-centre
    coordinates; ``h`` median edge length; ``element_area`` median triangle area.
    """

    pixel: float
    centre: tuple[float, float]
    x: np.ndarray
    y: np.ndarray
    tri: np.ndarray
    nodes: np.ndarray
    weights: np.ndarray
    r: np.ndarray
    theta: np.ndarray
    h: float
    element_area: float
    n_points: int
    n_triangles: int

    @property
    def inside(self) -> np.ndarray:
        return self.tri >= 0

    def nodal(self, f: np.ndarray, fill: float = np.nan) -> np.ndarray:
        """Linear interpolation of the nodal field ``f`` (N,) on the raster."""
        img = np.einsum("ijk,ijk->ij", f[self.nodes], self.weights)
        img[~self.inside] = fill
        return img

    def elemental(self, f: np.ndarray, fill: float = np.nan) -> np.ndarray:
        """Piecewise-constant sampling of the element field ``f`` (M,) on the raster."""
        img = f[np.maximum(self.tri, 0)].astype(float)
        img[~self.inside] = fill
        return img


def _validate_mesh(points: Any, triangles: Any) -> tuple[np.ndarray, np.ndarray]:
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] != 2 or p.shape[0] < 3:
        raise ValueError(f"points shape={p.shape}: must be (N, 2) with N >= 3 (mm)")
    if not np.all(np.isfinite(p)):
        raise ValueError("points: contains non-finite coordinates; all must be finite (mm)")
    t = np.asarray(triangles)
    if t.ndim != 2 or t.shape[1] != 3 or t.shape[0] < 1:
        raise ValueError(f"triangles shape={t.shape}: must be (M, 3) with M >= 1")
    if not np.issubdtype(t.dtype, np.integer):
        if not np.all(np.equal(np.mod(t, 1), 0)):
            raise ValueError("triangles: must hold integer node indices")
    t = t.astype(np.int64)
    if t.min() < 0 or t.max() >= len(p):
        raise ValueError(f"triangles: node indices span [{t.min()}, {t.max()}]; allowed range "
                         f"[0, {len(p) - 1}]")
    return p, t


def _mesh_stats(p: np.ndarray, t: np.ndarray) -> tuple[float, float, np.ndarray]:
    a, b, c = p[t[:, 0]], p[t[:, 1]], p[t[:, 2]]
    area2 = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    if np.any(np.abs(area2) <= 1e-14 * max(1.0, float(np.ptp(p)) ** 2)):
        raise ValueError("triangles: contains degenerate (zero-area) triangles")
    edges = np.concatenate([np.linalg.norm(b - a, axis=1), np.linalg.norm(c - b, axis=1),
                            np.linalg.norm(a - c, axis=1)])
    return float(np.median(edges)), float(np.median(np.abs(area2)) / 2), np.abs(area2) / 2


def _locate_pixels(p: np.ndarray, t: np.ndarray, lo: np.ndarray, pixel: float, nx: int,
                   ny: int) -> tuple[np.ndarray, np.ndarray]:
    """Triangle containing each pixel centre (-1 if none) and its barycentric weights.

    Vectorised over triangles: the pixel centres of each triangle's bounding box are
    enumerated at once (about 2x the number of pixels in total) and kept when their
    barycentric coordinates are all >= -1e-9; a pixel on a shared edge goes to one of
    the two triangles (the interpolated values agree there)."""
    P = p[t]  # (M, 3, 2)
    i0 = np.ceil((P[:, :, 0].min(axis=1) - lo[0]) / pixel).astype(np.int64)
    i1 = np.floor((P[:, :, 0].max(axis=1) - lo[0]) / pixel).astype(np.int64)
    j0 = np.ceil((P[:, :, 1].min(axis=1) - lo[1]) / pixel).astype(np.int64)
    j1 = np.floor((P[:, :, 1].max(axis=1) - lo[1]) / pixel).astype(np.int64)
    cx = np.maximum(i1 - i0 + 1, 0)
    cy = np.maximum(j1 - j0 + 1, 0)
    cnt = cx * cy
    tri_rep = np.repeat(np.arange(len(t)), cnt)
    local = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    ci = i0[tri_rep] + local % np.maximum(cx[tri_rep], 1)
    rj = j0[tri_rep] + local // np.maximum(cx[tri_rep], 1)
    qx = lo[0] + ci * pixel
    qy = lo[1] + rj * pixel
    a, b, c = P[tri_rep, 0], P[tri_rep, 1], P[tri_rep, 2]
    v0x, v0y = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
    v1x, v1y = c[:, 0] - a[:, 0], c[:, 1] - a[:, 1]
    v2x, v2y = qx - a[:, 0], qy - a[:, 1]
    den = v0x * v1y - v0y * v1x
    w1 = (v2x * v1y - v2y * v1x) / den
    w2 = (v0x * v2y - v0y * v2x) / den
    w0 = 1.0 - w1 - w2
    ok = (w0 >= -1e-9) & (w1 >= -1e-9) & (w2 >= -1e-9) & (ci < nx) & (rj < ny) & (ci >= 0) & (rj >= 0)
    tri_idx = np.full((ny, nx), -1, dtype=np.int64)
    weights = np.zeros((ny, nx, 3))
    tri_idx[rj[ok], ci[ok]] = tri_rep[ok]
    wk = np.clip(np.stack([w0[ok], w1[ok], w2[ok]], axis=1), 0.0, 1.0)
    weights[rj[ok], ci[ok]] = wk / wk.sum(axis=1, keepdims=True)
    return tri_idx, weights


_RASTER_CACHE: "OrderedDict[tuple, MeshRaster]" = OrderedDict()
_RASTER_CACHE_SIZE = 4


def build_raster(points: Any, triangles: Any, pixel: float | None = None,
                 centre: tuple[float, float] | None = None) -> MeshRaster:
    """Raster (pixel -> triangle, barycentric weights) of a triangulation.

    points (N, 2) mm; triangles (M, 3); pixel: pixel size in mm (default 0.4 h clipped to
    [0.15, 1.0], h = median edge length); centre: annulus centre in mm (default: the
    area-weighted centroid of the triangles, which is the centre of any annulus mesh).
    Results are cached on the mesh bytes (the last few meshes).
    """
    p, t = _validate_mesh(points, triangles)
    if pixel is not None:
        _check_range("pixel", pixel, 0.0, math.inf, lo_open=True, hi_open=True)
    key = (hashlib.sha1(p.tobytes()).hexdigest(), hashlib.sha1(t.tobytes()).hexdigest(),
           None if pixel is None else float(pixel),
           None if centre is None else (float(centre[0]), float(centre[1])))
    hit = _RASTER_CACHE.get(key)
    if hit is not None:
        _RASTER_CACHE.move_to_end(key)
        return hit
    h, area_med, areas = _mesh_stats(p, t)
    if pixel is None:
        pixel = float(np.clip(0.4 * h, 0.15, 1.0))
    if centre is None:
        cen = p[t].mean(axis=1)
        centre = (float(np.sum(cen[:, 0] * areas) / areas.sum()),
                  float(np.sum(cen[:, 1] * areas) / areas.sum()))
    cx, cy = float(centre[0]), float(centre[1])
    lo = p.min(axis=0) - pixel
    hi = p.max(axis=0) + pixel
    nx = int(np.ceil((hi[0] - lo[0]) / pixel)) + 1
    ny = int(np.ceil((hi[1] - lo[1]) / pixel)) + 1
    if nx * ny > 25_000_000:
        raise ValueError(f"pixel={pixel}: gives a {nx}x{ny} raster; use a pixel >= "
                         f"{max(hi - lo) / 5000:.3g} mm")
    xs = lo[0] + pixel * np.arange(nx)
    ys = lo[1] + pixel * np.arange(ny)
    X, Y = np.meshgrid(xs, ys)
    tri_idx, w = _locate_pixels(p, t, lo, pixel, nx, ny)
    nodes = t[np.maximum(tri_idx, 0)]  # (ny, nx, 3)
    dx, dy = X - cx, Y - cy
    raster = MeshRaster(pixel=float(pixel), centre=(cx, cy), x=xs, y=ys, tri=tri_idx,
                        nodes=nodes, weights=w, r=np.hypot(dx, dy), theta=np.arctan2(dy, dx),
                        h=h, element_area=area_med, n_points=len(p), n_triangles=len(t))
    _RASTER_CACHE[key] = raster
    while len(_RASTER_CACHE) > _RASTER_CACHE_SIZE:
        _RASTER_CACHE.popitem(last=False)
    return raster


# --------------------------------------------------------------------------- helpers
def _field_image(raster: MeshRaster, f: Any, name: str, location: str | None) -> np.ndarray:
    a = np.asarray(f, dtype=float)
    if a.ndim != 1:
        raise ValueError(f"{name} shape={a.shape}: must be 1-D, (N,)={raster.n_points} nodal "
                         f"or (M,)={raster.n_triangles} per element")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: contains non-finite values; all must be finite")
    if location is None:
        if len(a) == raster.n_points:
            location = "node"
        elif len(a) == raster.n_triangles:
            location = "element"
        else:
            raise ValueError(f"{name} length={len(a)}: must be N={raster.n_points} (nodal) or "
                             f"M={raster.n_triangles} (per element)")
    if location == "node":
        if len(a) != raster.n_points:
            raise ValueError(f"{name} length={len(a)}: nodal field must have N={raster.n_points}")
        return raster.nodal(a)
    if location == "element":
        if len(a) != raster.n_triangles:
            raise ValueError(f"{name} length={len(a)}: element field must have M={raster.n_triangles}")
        return raster.elemental(a)
    raise ValueError(f"{name}_location={location!r}: must be None, 'node' or 'element'")


def _circ_dist(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    d = np.abs(np.asarray(a)[:, None] - np.asarray(b)[None, :]) % (2 * np.pi)
    return np.minimum(d, 2 * np.pi - d)


_EIGHT = np.ones((3, 3), dtype=bool)


def _front(raster: MeshRaster, S_img: np.ndarray, r_inner: float, r_outer: float,
           s_front: float, n_theta: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Front r(theta) of the invaded region connected to the cavity.

    Returns (theta_bins, r_of_theta, main_mask, cavity_mask)."""
    inside = raster.inside
    cavity = ~inside & (raster.r < 0.5 * (r_inner + r_outer))
    S = np.where(inside, S_img, np.where(cavity, 1.0, 0.0))
    invaded = S >= s_front
    lab, _ = ndi.label(invaded)  # 4-connectivity, consistent with find_contours 'low'
    seeds = lab[(raster.r <= r_inner + raster.pixel) & invaded]
    seeds = np.unique(seeds[seeds > 0])
    main = np.isin(lab, seeds) if seeds.size else np.zeros_like(invaded)
    S_main = np.where(invaded & ~main, 0.0, S)
    # pad so that contours are always closed
    S_pad = np.pad(S_main, 1, constant_values=0.0)
    from skimage.measure import find_contours

    contours = find_contours(S_pad, s_front)
    bins = (np.arange(n_theta) + 0.5) * (2 * np.pi / n_theta) - np.pi
    if not contours:
        return bins, np.full(n_theta, r_inner), main, cavity
    areas = [abs(0.5 * np.sum(c[:-1, 0] * c[1:, 1] - c[1:, 0] * c[:-1, 1])) for c in contours]
    c = contours[int(np.argmax(areas))]
    # densify so that every angular bin gets points even at small radii
    seg = np.diff(c, axis=0)
    nsub = np.maximum(1, np.ceil(np.hypot(seg[:, 0], seg[:, 1]) / 0.25).astype(int))
    if nsub.max() > 1:
        idx = np.repeat(np.arange(len(seg)), nsub)
        frac = (np.arange(nsub.sum()) - np.repeat(np.cumsum(nsub) - nsub, nsub)) / np.repeat(nsub, nsub)
        c = c[idx] + seg[idx] * frac[:, None]
    y = raster.y[0] + (c[:, 0] - 1.0) * raster.pixel - raster.centre[1]
    x = raster.x[0] + (c[:, 1] - 1.0) * raster.pixel - raster.centre[0]
    r = np.hypot(x, y)
    th = np.arctan2(y, x)
    k = np.floor((th + np.pi) / (2 * np.pi) * n_theta).astype(int) % n_theta
    env = np.full(n_theta, -np.inf)
    np.maximum.at(env, k, r)
    ok = np.isfinite(env)
    if not ok.all():
        env[~ok] = np.interp(bins[~ok], bins[ok], env[ok], period=2 * np.pi)
    return bins, env, main, cavity


def _fingers(theta: np.ndarray, r: np.ndarray, prominence: float) -> np.ndarray:
    """Indices of the peaks of the periodic r(theta) with prominence >= ``prominence``."""
    n = len(r)
    if np.ptp(r) < prominence:
        return np.empty(0, dtype=int)
    from scipy.signal import find_peaks

    tiled = np.concatenate([r, r, r])
    peaks, _ = find_peaks(tiled, prominence=prominence)
    return np.sort(peaks[(peaks >= n) & (peaks < 2 * n)] - n)


# --------------------------------------------------------------------------- classifier
class _Cracks(NamedTuple):
    """The open components kept as cracks: label image, per-component keep flag and largest radius (mm)."""

    lab: np.ndarray
    keep: np.ndarray
    rmax: np.ndarray
    mask: np.ndarray


def _cracks(raster: MeshRaster, phi_img: np.ndarray, r_inner: float, phi_open: float, min_area: float,
            inner_tol: float) -> _Cracks:
    """Open components (phi >= phi_open, 8-connected) of at least ``min_area`` (mm²) that come within
    ``inner_tol`` (mm) of the cavity."""
    lab, nlab = ndi.label(raster.inside & (phi_img >= phi_open), structure=_EIGHT)
    if not nlab:
        return _Cracks(lab, np.zeros(0, bool), np.zeros(0), np.zeros(lab.shape, bool))
    idx = np.arange(1, nlab + 1)
    area = np.bincount(lab.ravel(), minlength=nlab + 1)[1:] * raster.pixel**2
    rmin = np.asarray(ndi.minimum(raster.r, lab, idx))
    rmax = np.asarray(ndi.maximum(raster.r, lab, idx))
    keep = (area >= min_area) & (rmin <= r_inner + inner_tol)
    return _Cracks(lab, keep, rmax, np.concatenate([[False], keep])[lab])


def _branch_tips(raster: MeshRaster, cracks: _Cracks, r_inner: float, min_branch_length: float,
                 min_crack_length: float) -> list[float]:
    """Angles (rad) of the crack-branch tips: h-maxima of (r - r_inner) over the crack pixels, plus the tip of
    every crack longer than ``min_crack_length`` (mm) that has none (a crack longer than L_min counts once)."""
    if not cracks.mask.any():
        return []
    from skimage.morphology import h_maxima

    rr = raster.r
    hm = h_maxima(np.where(cracks.mask, rr - r_inner, 0.0), min_branch_length).astype(bool) & cracks.mask
    hl, nh = ndi.label(hm, structure=_EIGHT)
    tip_angles: list[float] = []
    counted = set()
    if nh:
        rows, cols = np.nonzero(hl)
        lbl = hl[rows, cols]
        cnt = np.bincount(lbl, minlength=nh + 1)[1:]
        cy = np.bincount(lbl, raster.y[rows], minlength=nh + 1)[1:] / cnt - raster.centre[1]
        cx = np.bincount(lbl, raster.x[cols], minlength=nh + 1)[1:] / cnt - raster.centre[0]
        tip_angles = [float(a) for a in np.arctan2(cy, cx)]
        counted = set(np.unique(cracks.lab[hm]).tolist())
    for comp in np.flatnonzero(cracks.keep) + 1:
        if comp not in counted and cracks.rmax[comp - 1] - r_inner > min_crack_length:
            j = np.argmax(np.where(cracks.lab == comp, rr, -np.inf))
            tip_angles.append(float(raster.theta.ravel()[j]))
    return tip_angles


def _invasion_reach(raster: MeshRaster, sources: np.ndarray, invaded: np.ndarray,
                    confined_distance: float) -> tuple[float, float]:
    """Largest distance (mm) of an invaded pixel to a source (cavity or crack), and the invaded fraction farther
    than ``confined_distance`` (mm)."""
    if not invaded.any():
        return 0.0, 0.0
    dist = ndi.distance_transform_edt(~sources, sampling=raster.pixel)
    d_inv = dist[invaded & ~sources]
    reach = float(d_inv.max()) if d_inv.size else 0.0
    return reach, float(np.count_nonzero(d_inv > confined_distance) / np.count_nonzero(invaded))


def _regime(fracturing: bool, n_fingers: int, n_unexplained: int, reach: float, th: Mapping[str, float]) -> str:
    """Rules 1-3 of ``REGIME_RULES``."""
    if not fracturing:
        return "viscous_fingering" if n_fingers >= th["min_fingers"] else "uniform_invasion"
    if reach <= th["confined_distance"]:
        return "non_invasive_fracturing"
    return "fracturing_fingering" if n_unexplained >= th["min_fingers"] else "invasive_fracturing"


def _classify_images(raster: MeshRaster, S_img: np.ndarray, phi_img: np.ndarray,
                     r_inner: float, r_outer: float, opts: ClassifierOptions,
                     longest: float = 0.0) -> Classification:
    th = opts.resolved(raster.h)
    px2 = raster.pixel**2
    min_area = opts.min_open_area if opts.min_open_area is not None else 3.0 * raster.element_area
    cracks = _cracks(raster, phi_img, r_inner, opts.phi_open, min_area, th["inner_tol"])
    crack = cracks.mask
    tip_r = float(raster.r[crack].max()) if crack.any() else float(r_inner)
    crack_length = max(0.0, tip_r - r_inner)
    if longest > crack_length:  # crack_record = "longest": an earlier, longer crack (mm)
        tip_r, crack_length = float(r_inner) + longest, longest
    fracturing = crack_length > th["min_crack_length"]
    tip_angles = _branch_tips(raster, cracks, r_inner, th["min_branch_length"], th["min_crack_length"])

    theta_b, r_env, main, cavity = _front(raster, S_img, r_inner, r_outer, opts.s_front, opts.n_theta)
    ipk = _fingers(theta_b, r_env, th["finger_prominence"])
    finger_angles, finger_radii = theta_b[ipk], r_env[ipk]
    invaded = main & raster.inside
    reach, outside_fraction = _invasion_reach(raster, cavity | crack, invaded, th["confined_distance"])
    # explained fingers (invasion lobes along cracks): near a crack-tip direction
    if finger_angles.size and tip_angles:
        dmin = _circ_dist(finger_angles, np.asarray(tip_angles)).min(axis=1)
        n_unexplained = int(np.count_nonzero(dmin > math.radians(th["alignment_tol_deg"])))
    else:
        n_unexplained = int(finger_angles.size)
    regime = _regime(fracturing, int(finger_angles.size), n_unexplained, reach, th)

    n_cracks = len(tip_angles)
    px = raster.pixel
    th = dict(th, pixel=px, min_open_area=min_area, finger_prominence=th["finger_prominence"])
    return Classification(
        crack_tip_radius=tip_r,
        crack_length=crack_length,
        n_cracks=n_cracks,
        crack_tip_angles=tuple(float(a) for a in sorted(tip_angles)),
        open_area=float(np.count_nonzero(crack) * px2),
        front_radius_mean=float(np.mean(r_env)),
        front_radius_min=float(np.min(r_env)),
        front_radius_max=float(np.max(r_env)),
        n_fingers=int(finger_angles.size),
        finger_angles=tuple(float(a) for a in finger_angles),
        finger_radii=tuple(float(a) for a in finger_radii),
        n_unexplained_fingers=n_unexplained,
        invasion_reach=reach,
        outside_fraction=outside_fraction,
        invaded_area=float(np.count_nonzero(invaded) * px2),
        fracturing=bool(fracturing),
        regime=regime,
        front_theta=theta_b,
        front_r=r_env,
        thresholds=MappingProxyType(th),
    )


def _options(options: ClassifierOptions | None, kw: Mapping[str, Any]) -> ClassifierOptions:
    opts = options if options is not None else ClassifierOptions()
    if not isinstance(opts, ClassifierOptions):
        raise ValueError(f"options={type(opts).__name__}: must be a ClassifierOptions")
    if kw:
        names = {f.name for f in fields(ClassifierOptions)}
        bad = sorted(set(kw) - names)
        if bad:
            raise ValueError(f"unknown classifier option(s) {bad}; allowed: {sorted(names)}")
        opts = replace(opts, **kw)
    return opts


def _check_radii(r_inner: float, r_outer: float) -> tuple[float, float]:
    _check_range("r_inner", r_inner, 0.0, math.inf, lo_open=True, hi_open=True)
    _check_range("r_outer", r_outer, float(r_inner), math.inf, lo_open=True, hi_open=True)
    return float(r_inner), float(r_outer)


def classify_fields(points: Any, triangles: Any, S: Any, phi: Any, r_inner: float = 5.0,
                    r_outer: float = 53.0, *, options: ClassifierOptions | None = None,
                    raster: MeshRaster | None = None, centre: tuple[float, float] | None = None,
                    phi_location: str | None = None, longest_crack: float = 0.0,
                    **thresholds: Any) -> Classification:
    """Classify one snapshot into a flow regime.

    points (N, 2) mm; triangles (M, 3) node indices; S (N,) nodal saturation of the
    invading fluid; phi porosity, nodal (N,) or per element (M,) (``phi_location``
    forces 'node' or 'element'); r_inner, r_outer: annulus radii (mm).
    Thresholds: keyword arguments of ``ClassifierOptions`` (e.g. ``min_crack_length=3.0``)
    or ``options=ClassifierOptions(...)``. ``raster`` reuses a ``build_raster`` result;
    ``centre`` is the annulus centre (default: centroid of the mesh).  ``longest_crack`` (mm): the longest
    crack of the run up to this snapshot, which rule 1 reads when it exceeds the snapshot's (crack_record =
    "longest"; ``classify_run`` passes it from the time series).
    Returns a frozen ``Classification``.

    """
    p, t = _validate_mesh(points, triangles)
    r_inner, r_outer = _check_radii(r_inner, r_outer)
    opts = _options(options, thresholds)
    if raster is None:
        raster = build_raster(p, t, pixel=opts.pixel, centre=centre)
    elif raster.n_points != len(p) or raster.n_triangles != len(t):
        raise ValueError(f"raster: built for {raster.n_points} points/{raster.n_triangles} "
                         f"triangles, got {len(p)}/{len(t)}")
    S_img = _field_image(raster, S, "S", "node")
    phi_img = _field_image(raster, phi, "phi", phi_location)
    if not (isinstance(longest_crack, (int, float)) and math.isfinite(longest_crack) and longest_crack >= 0.0):
        raise ValueError(f"longest_crack={longest_crack!r}: must be a finite length >= 0 (mm)")
    return _classify_images(raster, S_img, phi_img, r_inner, r_outer, opts, float(longest_crack))


classify_fields.__doc__ = (classify_fields.__doc__ or "") + "\n" + REGIME_RULES


def front_of_fields(points: Any, triangles: Any, S: Any, r_inner: float = 5.0,
                    r_outer: float = 53.0, *, s_front: float = 0.5, n_theta: int = 720,
                    raster: MeshRaster | None = None,
                    centre: tuple[float, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Front r(theta) (mm) of the S >= s_front region connected to the cavity.

    Returns (theta (n_theta,) rad bin centres, r (n_theta,) mm, outer envelope)."""
    p, t = _validate_mesh(points, triangles)
    r_inner, r_outer = _check_radii(r_inner, r_outer)
    opts = ClassifierOptions(s_front=s_front, n_theta=n_theta)
    if raster is None:
        raster = build_raster(p, t, centre=centre)
    S_img = _field_image(raster, S, "S", "node")
    th, r, _, _ = _front(raster, S_img, r_inner, r_outer, opts.s_front, opts.n_theta)
    return th, r


# --------------------------------------------------------------------------- run folders
class RunClassification(NamedTuple):
    """``classify_run`` result: the classification and the snapshot time t (s)."""

    classification: Classification
    t: float


def list_snapshots(run_dir: str | Path) -> list[tuple[float, Path]]:
    """(t in s, path) of the snapshots of a run folder, sorted by time."""
    snapdir = Path(run_dir) / "snapshots"
    if not (snapdir / "mesh.npz").is_file():
        raise ValueError(f"run_dir={str(run_dir)!r}: no snapshots/mesh.npz (not a run folder)")
    out = []
    for f in sorted(snapdir.glob("snap_*.npz")):
        with np.load(f) as z:
            out.append((float(np.asarray(z["t"])), f))
    if not out:
        raise ValueError(f"run_dir={str(run_dir)!r}: no snapshots/snap_*.npz")
    out.sort(key=lambda x: x[0])
    return out


def _load_mesh(run_dir: Path) -> tuple[np.ndarray, np.ndarray]:
    with np.load(run_dir / "snapshots" / "mesh.npz") as z:
        return np.asarray(z["points"], float), np.asarray(z["triangles"], np.int64)


def _run_params(run_dir: Path) -> dict[str, Any]:
    f = run_dir / "params.toml"
    if not f.is_file():
        return {}
    data = read_toml(f)
    flat: dict[str, Any] = {}
    for k, v in data.items():  # accept flat or one level of tables
        if isinstance(v, dict):
            flat.update({kk: vv for kk, vv in v.items() if not isinstance(vv, dict)})
        else:
            flat[k] = v
    return flat


_PARAM_ALIASES = {
    "r_inner": ("r_inner", "inner_radius", "r_i"),
    "r_outer": ("r_outer", "outer_radius", "r_o"),
    "l_S": ("l_S", "l_s", "ls"),
    "l_d": ("l_d", "ld"),
}


def _param(params: Mapping[str, Any], key: str) -> float | None:
    for k in _PARAM_ALIASES[key]:
        v = params.get(k)
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            return float(v)
    return None


def select_snapshot(run_dir: str | Path, at: Any = "last", *, r_inner: float | None = None,
                    r_outer: float | None = None, s_front: float = 0.5) -> tuple[float, Path]:
    """Choose a snapshot of a run folder; returns (t in s, snapshot path).

    at = "last": the last snapshot; at = <float t> (s): the snapshot nearest in time;
    at = {"front_radius": R (mm), "measure": "max" | "mean"}: the first snapshot whose
    front (S = s_front contour connected to the cavity) reaches radius R (default measure
    "max", the leading edge: the paper compares runs whose fronts stand at a similar
    distance from the outer boundary), else the last snapshot.
    """
    run_dir = Path(run_dir)
    snaps = list_snapshots(run_dir)
    if isinstance(at, str):
        if at != "last":
            raise ValueError(f"at={at!r}: must be 'last', a time (s) or {{'front_radius': R}}")
        return snaps[-1]
    if isinstance(at, (int, float, np.floating, np.integer)) and not isinstance(at, bool):
        tq = float(at)
        if not math.isfinite(tq):
            raise ValueError(f"at={at!r}: a time must be finite (s)")
        i = int(np.argmin([abs(t - tq) for t, _ in snaps]))
        return snaps[i]
    if isinstance(at, Mapping):
        extra = set(at) - {"front_radius", "measure"}
        if "front_radius" not in at or extra:
            raise ValueError(f"at={dict(at)!r}: mapping must be {{'front_radius': R, "
                             f"'measure': 'max'|'mean'}}")
        R = at["front_radius"]
        _check_range("at['front_radius']", R, 0.0, math.inf, lo_open=True, hi_open=True)
        measure = at.get("measure", "max")
        if measure not in ("max", "mean"):
            raise ValueError(f"at['measure']={measure!r}: must be 'max' or 'mean'")
        points, tris = _load_mesh(run_dir)
        params = _run_params(run_dir)
        ri, ro = _radii(points, tris, params, r_inner, r_outer)
        raster = build_raster(points, tris)
        for t, f in snaps:
            with np.load(f) as z:
                S = np.asarray(z["S"], float)
            _, r = front_of_fields(points, tris, S, ri, ro, s_front=s_front, raster=raster)
            val = r.max() if measure == "max" else r.mean()
            if val >= float(R):
                return t, f
        return snaps[-1]
    raise ValueError(f"at={at!r}: must be 'last', a time (s) or {{'front_radius': R}}")


def _radii(points: np.ndarray, tris: np.ndarray, params: Mapping[str, Any],
           r_inner: float | None, r_outer: float | None) -> tuple[float, float]:
    if r_inner is None:
        r_inner = _param(params, "r_inner")
    if r_outer is None:
        r_outer = _param(params, "r_outer")
    if r_inner is None or r_outer is None:
        raster = build_raster(points, tris)
        rn = np.hypot(points[:, 0] - raster.centre[0], points[:, 1] - raster.centre[1])
        r_inner = float(rn.min()) if r_inner is None else r_inner
        r_outer = float(rn.max()) if r_outer is None else r_outer
    return float(r_inner), float(r_outer)


def classify_run(run_dir: str | Path, at: Any = "last", *, r_inner: float | None = None,
                 r_outer: float | None = None, options: ClassifierOptions | None = None,
                 **thresholds: Any) -> RunClassification:
    """Classify one snapshot of a run folder (format of /tmp/common.md).

    ``at`` selects the snapshot (see ``select_snapshot``: "last", a time in s, or
    {"front_radius": R mm}). r_inner/r_outer (mm) default to params.toml
    (r_inner/r_outer or inner_radius/outer_radius) and else to the extreme node radii;
    l_S and l_d default to params.toml when present. Returns (classification, t [s]).
    """
    run_dir = Path(run_dir)
    list_snapshots(run_dir)  # validates the folder before any work
    params = _run_params(run_dir)
    defaults = {}
    for key in ("l_S", "l_d"):
        v = _param(params, key)
        if v is not None and key not in thresholds and options is None:
            defaults[key] = v
    opts = _options(options, {**defaults, **thresholds})
    points, tris = _load_mesh(run_dir)
    ri, ro = _radii(points, tris, params, r_inner, r_outer)
    t, f = select_snapshot(run_dir, at, r_inner=ri, r_outer=ro, s_front=opts.s_front)
    with np.load(f) as z:
        S = np.asarray(z["S"], float)
        phi = np.asarray(z["phi"], float)
    longest = longest_open_crack(run_dir, t, ri) if opts.crack_record == "longest" else 0.0
    c = classify_fields(points, tris, S, phi, ri, ro, options=opts, longest_crack=longest)
    return RunClassification(c, float(t))


def longest_open_crack(run_dir: str | Path, t: float, r_inner: float) -> float:
    """The longest crack (mm) of a run up to time t (s): the largest open_tip_radius - r_inner of its
    ``timeseries.csv`` over the accepted steps at t' <= t (0 while no open region reaches beyond the cavity).
    open_tip_radius is the largest radius of the phi >= 0.99 region connected to the inlet (solver.metrics)."""
    f = Path(run_dir) / "timeseries.csv"
    if not f.is_file():
        raise FileNotFoundError(f"{f}: crack_record='longest' reads the run's time series, which is missing")
    import pandas as pd

    ts = pd.read_csv(f)
    missing = {"t", "open_tip_radius"} - set(ts.columns)
    if missing:
        raise ValueError(f"{f}: crack_record='longest' needs the columns {sorted(missing)}")
    upto = ts["open_tip_radius"][ts["t"] <= float(t) * (1.0 + 1e-9)].to_numpy(float)
    upto = upto[np.isfinite(upto)]
    return max(float(upto.max()) - float(r_inner), 0.0) if upto.size else 0.0
