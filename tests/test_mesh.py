"""Meshes: annulus quality/size/geometry, structured rectangles, meshio round trip."""
import math
import pickle
import warnings

import numpy as np
import pytest

from solver.mesh import Mesh, annulus_mesh, read_mesh, rectangle_mesh, write_mesh

RI, RO = 5.0, 53.0


@pytest.fixture(scope="module")
def m1():
    return annulus_mesh(RI, RO, h=1.0)


def polygon_area_exact(r, n):
    """Area of the regular n-gon inscribed in a circle of radius r."""
    return 0.5 * n * r**2 * math.sin(2 * math.pi / n)


def test_area(m1):
    exact = math.pi * (RO**2 - RI**2)
    assert m1.areas.sum() == pytest.approx(exact, rel=5e-3)
    # sharper: the mesh is exactly the region between the two inscribed polygons
    n_in, n_out = len(m1.inner_edges), len(m1.outer_edges)
    poly = polygon_area_exact(RO, n_out) - polygon_area_exact(RI, n_in)
    assert m1.areas.sum() == pytest.approx(poly, rel=1e-12)


def test_boundary_nodes_on_circles(m1):
    for name, r in (("inner", RI), ("outer", RO)):
        ids = m1.boundary_nodes(name)
        rr = np.hypot(*m1.points[ids].T)
        assert np.abs(rr - r).max() < 1e-12
    # all other nodes strictly inside
    others = np.setdiff1d(np.arange(m1.n_nodes), np.concatenate([m1.boundary_nodes("inner"), m1.boundary_nodes("outer")]))
    rr = np.hypot(*m1.points[others].T)
    assert rr.min() > RI and rr.max() < RO


def test_boundary_edges_closed_and_oriented(m1):
    for name, sign in (("inner", -1), ("outer", 1)):
        e = m1.boundary_edges[name]
        # closed polygon: every node appears twice, as many edges as nodes
        assert len(e) == len(m1.boundary_nodes(name))
        assert np.all(np.bincount(e.ravel())[np.unique(e)] == 2)
        # domain on the left: outer circle traversed CCW (positive cross), inner CW
        p0, p1 = m1.points[e[:, 0]], m1.points[e[:, 1]]
        cross = p0[:, 0] * p1[:, 1] - p0[:, 1] * p1[:, 0]
        assert np.all(np.sign(cross) == sign)
    # every boundary edge of the triangulation is tagged
    tri = m1.triangles
    e = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    _, counts = np.unique(e, axis=0, return_counts=True)
    assert (counts == 1).sum() == len(m1.inner_edges) + len(m1.outer_edges)


def test_quality_and_size(m1):
    assert m1.min_angle_deg().min() >= 25.0
    assert 18_000 <= m1.n_elements <= 23_000
    assert np.all(m1.areas > 0)  # counter-clockwise
    assert m1.h_mean == pytest.approx(1.0, rel=0.15)
    for name in ("inner", "outer"):
        assert m1.edge_lengths(name).mean() == pytest.approx(1.0, rel=0.15)
    assert m1.points.dtype == np.float64 and m1.triangles.dtype == np.int64
    # Euler characteristic of an annulus: V - E + F = 0
    assert m1.n_nodes - len(m1.edges()) + m1.n_elements == 0


@pytest.mark.parametrize("h", [4.0, 2.0, 0.7])
def test_quality_other_sizes(h):
    m = annulus_mesh(RI, RO, h=h)
    assert m.min_angle_deg().min() >= 25.0
    assert m.h_mean == pytest.approx(h, rel=0.15)
    # triangle count ~ area / (sqrt(3)/4 h^2) for near-equilateral triangles
    expected = math.pi * (RO**2 - RI**2) / (math.sqrt(3) / 4 * h**2)
    assert m.n_elements == pytest.approx(expected, rel=0.1)


def test_seeded_meshes_differ_but_are_valid_and_deterministic():
    a = annulus_mesh(RI, RO, h=2.0, seed=1)
    b = annulus_mesh(RI, RO, h=2.0, seed=1)
    c = annulus_mesh(RI, RO, h=2.0, seed=2)
    ref = annulus_mesh(RI, RO, h=2.0)
    assert np.array_equal(a.points, b.points) and np.array_equal(a.triangles, b.triangles)
    assert not np.array_equal(a.points, c.points)
    assert not np.array_equal(a.points, ref.points)
    for m in (a, c):
        assert m.min_angle_deg().min() >= 25.0
        assert np.all(m.areas > 0)
        assert m.areas.sum() == pytest.approx(ref.areas.sum(), rel=1e-12)  # same boundary polygons


def test_determinism_without_cache():
    from solver import mesh as mod

    a = annulus_mesh(RI, RO, h=2.0)
    mod._annulus_cached.cache_clear()
    b = annulus_mesh(RI, RO, h=2.0)
    assert a is not b
    assert np.array_equal(a.points, b.points) and np.array_equal(a.triangles, b.triangles)
    for k in ("inner", "outer"):
        assert np.array_equal(a.boundary_edges[k], b.boundary_edges[k])


def test_frozen_read_only_and_picklable(m1):
    assert m1.points.flags.writeable is False and m1.triangles.flags.writeable is False
    with pytest.raises(ValueError):
        m1.points[0, 0] = 1.0
    with pytest.raises(TypeError):
        m1.boundary_edges["x"] = np.zeros((0, 2))
    m = pickle.loads(pickle.dumps(m1))
    assert np.array_equal(m.points, m1.points) and np.array_equal(m.outer_edges, m1.outer_edges)


@pytest.mark.parametrize("kw", [dict(h=0.0), dict(h=-1.0), dict(h=24.0), dict(h=float("nan")),
                                dict(r_inner=0.0), dict(r_inner=-1.0), dict(r_outer=5.0), dict(r_outer=4.0),
                                dict(seed=-1), dict(seed=1.5), dict(h="1")])
def test_annulus_validation(kw):
    name, value = next(iter(kw.items()))
    with pytest.raises(ValueError, match=name):
        annulus_mesh(**kw)


def test_min_angle_known_triangles():
    pts = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, math.sqrt(3) / 2], [0.0, 1.0]])
    m = Mesh(pts, np.array([[0, 1, 2], [0, 1, 3]]), {})
    assert m.min_angle_deg() == pytest.approx([60.0, 45.0])
    assert m.areas == pytest.approx([math.sqrt(3) / 4, 0.5])


@pytest.mark.parametrize("diagonal", ["alternate", "right", "left"])
def test_rectangle_mesh(diagonal):
    m = rectangle_mesh(3.0, 2.0, 6, 4, x0=-1.0, y0=0.5, diagonal=diagonal)
    assert m.n_elements == 2 * 6 * 4 and m.n_nodes == 7 * 5
    assert np.all(m.areas > 0) and m.areas.sum() == pytest.approx(6.0, rel=1e-14)
    assert m.areas == pytest.approx(np.full(48, 6.0 / 48))
    x, y = m.points.T
    for name, coord, val, n in (("left", x, -1.0, 4), ("right", x, 2.0, 4), ("bottom", y, 0.5, 6), ("top", y, 2.5, 6)):
        e = m.boundary_edges[name]
        assert len(e) == n
        assert np.all(coord[e] == val)
        assert m.edge_lengths(name).sum() == pytest.approx(3.0 if name in ("bottom", "top") else 2.0)
    # counter-clockwise boundary: sum of cross products = 2 * area
    allb = np.concatenate([m.boundary_edges[k] for k in ("bottom", "right", "top", "left")])
    p0, p1 = m.points[allb[:, 0]], m.points[allb[:, 1]]
    assert 0.5 * np.sum(p0[:, 0] * p1[:, 1] - p0[:, 1] * p1[:, 0]) == pytest.approx(6.0)
    assert m.min_angle_deg().min() == pytest.approx(math.degrees(math.atan(0.5 / 0.5)))  # square cells: 45°


def test_rectangle_validation():
    with pytest.raises(ValueError, match="nx"):
        rectangle_mesh(1.0, 1.0, 0, 2)
    with pytest.raises(ValueError, match="ly"):
        rectangle_mesh(1.0, -1.0, 2, 2)
    with pytest.raises(ValueError, match="diagonal"):
        rectangle_mesh(1.0, 1.0, 2, 2, diagonal="cross")


def test_unknown_tag(m1):
    with pytest.raises(ValueError, match="left"):
        m1.boundary_nodes("left")


@pytest.mark.parametrize("suffix", [".xdmf", ".vtu"])
def test_meshio_round_trip(tmp_path, suffix):
    m = annulus_mesh(RI, RO, h=2.0, seed=3)
    path = tmp_path / f"mesh{suffix}"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        write_mesh(m, path)
        r = read_mesh(path)
    assert np.array_equal(r.points, m.points) and r.points.dtype == np.float64
    assert np.array_equal(r.triangles, m.triangles) and r.triangles.dtype == np.int64
    assert sorted(r.boundary_edges) == ["inner", "outer"]
    for k in ("inner", "outer"):
        assert np.array_equal(r.boundary_edges[k], m.boundary_edges[k])
    rect = rectangle_mesh(1.0, 1.0, 3, 2)
    write_mesh(rect, tmp_path / f"rect{suffix}")
    rr = read_mesh(tmp_path / f"rect{suffix}")
    assert sorted(rr.boundary_edges) == ["bottom", "left", "right", "top"]
    assert all(np.array_equal(rr.boundary_edges[k], rect.boundary_edges[k]) for k in rect.boundary_edges)


# ---------------------------------------------------------------------------
# graded annulus (h_inner)
# ---------------------------------------------------------------------------
# sha256 of (points, triangles, inner edges, outer edges) of the quasi-uniform meshes, recorded
# with the generator as it was before the h_inner option existed (numpy 2.4 / scipy on the
# project machine): h_inner=None must keep giving these meshes bit for bit (stored results
# depend on them).  A different CPU/libm could change the last bits of the node coordinates
# (cos/sin); the triangles would still match.
_UNIFORM_SHA256 = {
    (1.0, None): "3326df9f2ec356d42ce75b842075af93baaadeeaee7e56df08d36be2156e2898",
    (2.0, None): "c514d918d6dcfdf28d3f971e5df212ccfb79f04a18622b641e5bd28a87fe5ac7",
    (4.0, None): "ca69e7b0519450563a593d0f61ba57ba993c0277ab10c60e54398252d8731d7d",
    (2.0, 1): "51a92cd85cb9c96740bd82708713d1a6cff312e810721ff7cdc7f09cdeb55bbb",
}


def _sha256(m):
    import hashlib

    d = hashlib.sha256()
    for a in (m.points, m.triangles, m.boundary_edges["inner"], m.boundary_edges["outer"]):
        d.update(np.ascontiguousarray(a).tobytes())
    return d.hexdigest()


@pytest.mark.parametrize("h,seed", list(_UNIFORM_SHA256))
def test_uniform_mesh_unchanged_by_grading_option(h, seed):
    from solver import mesh as mod

    mod._annulus_cached.cache_clear()
    m = annulus_mesh(RI, RO, h=h, seed=seed)
    assert _sha256(m) == _UNIFORM_SHA256[(h, seed)]
    # h_inner=None / == h (any grading_length) are the same (memoized) uniform mesh
    assert annulus_mesh(RI, RO, h=h, seed=seed, h_inner=None) is m
    assert annulus_mesh(RI, RO, h=h, seed=seed, h_inner=h, grading_length=2.0) is m


@pytest.fixture(scope="module", params=[0.5, 0.25])
def graded(request):
    return request.param, annulus_mesh(RI, RO, h=1.0, h_inner=request.param)


def test_graded_quality_area_boundary(graded):
    hi, m = graded
    assert m.min_angle_deg().min() >= 25.0
    assert np.all(m.areas > 0)
    assert m.areas.sum() == pytest.approx(math.pi * (RO**2 - RI**2), rel=5e-3)
    poly = polygon_area_exact(RO, len(m.outer_edges)) - polygon_area_exact(RI, len(m.inner_edges))
    assert m.areas.sum() == pytest.approx(poly, rel=1e-12)
    for name, r in (("inner", RI), ("outer", RO)):
        rr = np.hypot(*m.points[m.boundary_nodes(name)].T)
        assert np.abs(rr - r).max() < 1e-12
        e = m.boundary_edges[name]
        assert len(e) == len(m.boundary_nodes(name))
        assert np.all(np.bincount(e.ravel())[np.unique(e)] == 2)
    others = np.setdiff1d(np.arange(m.n_nodes), np.concatenate([m.boundary_nodes("inner"), m.boundary_nodes("outer")]))
    rr = np.hypot(*m.points[others].T)
    assert rr.min() > RI and rr.max() < RO
    assert m.n_nodes - len(m.edges()) + m.n_elements == 0  # annulus: Euler characteristic 0
    # every boundary edge of the triangulation is tagged
    assert len(m.inner_edges) + len(m.outer_edges) == len(m.boundary_nodes("inner")) + len(m.boundary_nodes("outer"))


def test_graded_local_edge_length(graded):
    from solver.mesh import GRADING_LENGTH, annulus_size

    hi, m = graded
    e = m.edges()
    L = np.linalg.norm(m.points[e[:, 1]] - m.points[e[:, 0]], axis=1)
    rm = np.hypot(*(0.5 * (m.points[e[:, 0]] + m.points[e[:, 1]])).T)
    # on and next to the inner circle: h_inner
    assert m.edge_lengths("inner").mean() == pytest.approx(hi, rel=0.05)
    assert np.all(np.abs(m.edge_lengths("inner") / hi - 1) < 0.25)
    assert L[rm < RI + hi].mean() == pytest.approx(hi, rel=0.1)
    # beyond the transition: h
    far = rm > RI + GRADING_LENGTH + 1.0
    assert L[far].mean() == pytest.approx(1.0, rel=0.05)
    assert m.edge_lengths("outer").mean() == pytest.approx(1.0, rel=0.05)
    # everywhere, the edges follow the size function: mean ratio per 1-mm ring within 5 %
    ratio = L / annulus_size(rm, 1.0, hi, RI, GRADING_LENGTH)
    k = np.floor(np.maximum(rm - RI, 0.0)).astype(int)  # chord midpoints lie just inside r = RI
    per_ring = np.bincount(k, ratio) / np.bincount(k)
    assert np.abs(per_ring - 1).max() < 0.05, per_ring
    # the refinement is local: a few % more elements than the uniform h = 1 mesh
    n_uniform = annulus_mesh(RI, RO, h=1.0).n_elements
    assert n_uniform < m.n_elements < 1.1 * n_uniform


def test_graded_other_sizes_and_seeds():
    from solver import mesh as mod

    for h, hi, gl, seed in [(2.0, 1.0, 5.0, None), (2.0, 1.0, 5.0, 4), (1.0, 0.5, 2.5, 1), (4.0, 0.5, 5.0, None)]:
        m = annulus_mesh(RI, RO, h=h, h_inner=hi, grading_length=gl, seed=seed)
        assert m.min_angle_deg().min() >= 25.0, (h, hi, gl, seed)
        assert np.all(m.areas > 0)
        assert m.edge_lengths("inner").mean() == pytest.approx(hi, rel=0.05)
        assert m.edge_lengths("outer").mean() == pytest.approx(h, rel=0.05)
    # deterministic without the cache; the cache key has h_inner and grading_length
    a = annulus_mesh(RI, RO, h=2.0, h_inner=1.0)
    mod._annulus_cached.cache_clear()
    b = annulus_mesh(RI, RO, h=2.0, h_inner=1.0)
    assert a is not b and _sha256(a) == _sha256(b)
    assert annulus_mesh(RI, RO, h=2.0, h_inner=1.0) is b
    assert annulus_mesh(RI, RO, h=2.0, h_inner=0.5) is not b
    c = annulus_mesh(RI, RO, h=2.0, h_inner=1.0, grading_length=10.0)
    assert c is not b and c.n_elements > b.n_elements


@pytest.mark.parametrize("kw,msg", [
    (dict(h_inner=0.0), "h_inner=0.0 is out of range: allowed (0, h = 1.0]"),
    (dict(h_inner=-0.5), "h_inner=-0.5 is out of range: allowed (0, h = 1.0]"),
    (dict(h_inner=1.5), "h_inner=1.5 is out of range: allowed (0, h = 1.0]"),
    (dict(h_inner=float("nan")), "h_inner=nan is out of range"),
    (dict(h_inner=float("inf")), "h_inner=inf is out of range"),
    (dict(h_inner="0.5"), "h_inner='0.5' is out of range"),
    (dict(h_inner=True), "h_inner=True is out of range"),
    (dict(h_inner=0.5, grading_length=0.0), "grading_length=0.0 is out of range: allowed a finite number > 0"),
    (dict(h_inner=0.5, grading_length=-1.0), "grading_length=-1.0 is out of range"),
    (dict(h_inner=0.5, grading_length=float("inf")), "grading_length=inf is out of range"),
    (dict(h_inner=0.5, grading_length=None), "grading_length=None is out of range"),
])
def test_graded_validation(kw, msg):
    with pytest.raises(ValueError) as e:
        annulus_mesh(RI, RO, h=1.0, **kw)
    assert msg in str(e.value)


# ---------------------------------------------------------------------------
# graded annulus towards the outer circle (h_outer)
# ---------------------------------------------------------------------------
# Inner-graded meshes pinned by a fingerprint: node, element and boundary-edge counts (exact) and the sum of the
# node radii and of their squares (mm, mm²; relative 1e-12).  The grading evaluates expm1 and log, which numpy's
# CPU-specific builds (AVX-512 against AVX2) may round differently by an ulp, so a bitwise hash of these meshes
# depends on the machine; any change of the grading itself moves the sums by far more than 1e-12.
_INNER_GRADED_FINGERPRINT = {
    (2.0, 1.0, None): (2696, 5194, 31, 167, 95373.24186396654, 3839312.2347898525),
    (1.0, 0.5, 3): (10592, 20788, 63, 333, 372465.52263512014, 14879914.842947446),
}


def _fingerprint(m):
    r = np.hypot(*m.points.T)
    return (m.n_nodes, m.n_elements, len(m.boundary_edges["inner"]), len(m.boundary_edges["outer"]),
            float(r.sum()), float((r**2).sum()))


@pytest.mark.parametrize("h,hi,seed", list(_INNER_GRADED_FINGERPRINT))
def test_inner_graded_mesh_unchanged_by_outer_option(h, hi, seed):
    from solver import mesh as mod

    mod._annulus_cached.cache_clear()
    m = annulus_mesh(RI, RO, h=h, h_inner=hi, seed=seed)
    *counts, s1, s2 = _INNER_GRADED_FINGERPRINT[(h, hi, seed)]
    got = _fingerprint(m)
    assert list(got[:4]) == counts
    assert got[4:] == pytest.approx((s1, s2), rel=1e-12)
    # h_outer=None / == h (any outer_grading_length) build the same mesh, bit for bit on one machine
    for kw in (dict(h_outer=None), dict(h_outer=h, outer_grading_length=2.0)):
        mod._annulus_cached.cache_clear()
        other = annulus_mesh(RI, RO, h=h, h_inner=hi, seed=seed, **kw)
        assert _sha256(other) == _sha256(m)
    assert annulus_mesh(RI, RO, h=h, h_inner=hi, seed=seed, h_outer=None) is other  # one memoized mesh


def test_uniform_mesh_unchanged_by_outer_option():
    from solver import mesh as mod

    mod._annulus_cached.cache_clear()
    m = annulus_mesh(RI, RO, h=2.0, h_outer=None)
    assert _sha256(m) == _UNIFORM_SHA256[(2.0, None)]
    assert annulus_mesh(RI, RO, h=2.0, h_outer=2.0) is m


def _check_valid_annulus(m):
    """Positive areas, boundary nodes exactly on the circles, interior nodes strictly inside, all tagged."""
    assert np.all(m.areas > 0)
    poly = polygon_area_exact(RO, len(m.outer_edges)) - polygon_area_exact(RI, len(m.inner_edges))
    assert m.areas.sum() == pytest.approx(poly, rel=1e-12)
    for name, r in (("inner", RI), ("outer", RO)):
        rr = np.hypot(*m.points[m.boundary_nodes(name)].T)
        assert np.abs(rr - r).max() < 1e-12
        assert len(m.boundary_edges[name]) == len(m.boundary_nodes(name))
    others = np.setdiff1d(np.arange(m.n_nodes), np.concatenate([m.boundary_nodes("inner"), m.boundary_nodes("outer")]))
    rr = np.hypot(*m.points[others].T)
    assert rr.min() > RI and rr.max() < RO
    assert m.n_nodes - len(m.edges()) + m.n_elements == 0  # annulus: Euler characteristic 0


@pytest.fixture(scope="module", params=[(2.0, 0.5), (1.0, 0.25)])
def graded_outer(request):
    h, ho = request.param
    return h, ho, annulus_mesh(RI, RO, h=h, h_outer=ho)


def test_outer_graded_quality_and_boundary(graded_outer):
    h, ho, m = graded_outer
    assert m.min_angle_deg().min() >= 25.0
    _check_valid_annulus(m)


def test_outer_graded_local_edge_length(graded_outer):
    from solver.mesh import GRADING_LENGTH, annulus_size

    h, ho, m = graded_outer
    e = m.edges()
    L = np.linalg.norm(m.points[e[:, 1]] - m.points[e[:, 0]], axis=1)
    rm = np.hypot(*(0.5 * (m.points[e[:, 0]] + m.points[e[:, 1]])).T)
    # on and next to the outer circle: h_outer; on the inner circle and far from r_o: h
    assert m.edge_lengths("outer").mean() == pytest.approx(ho, rel=0.05)
    assert np.all(np.abs(m.edge_lengths("outer") / ho - 1) < 0.25)
    ratio = L / annulus_size(rm, h, h_outer=ho, r_outer=RO)
    assert ratio[rm > RO - ho].mean() == pytest.approx(1.0, rel=0.1)
    assert m.edge_lengths("inner").mean() == pytest.approx(h, rel=0.05)
    assert L[rm < RO - GRADING_LENGTH - h].mean() == pytest.approx(h, rel=0.05)
    # everywhere, the edges follow the size function: mean ratio per h-wide ring within 5 %
    k = np.floor(np.clip(RO - rm, 0.0, None) / h).astype(int)
    per_ring = np.bincount(k, ratio) / np.bincount(k)
    assert np.abs(per_ring - 1).max() < 0.05, per_ring


def test_graded_both_sides_and_seeds():
    for h, hi, ho, gl, glo, seed in [(2.0, 1.0, 0.5, 5.0, 5.0, None), (2.0, None, 1.0, 5.0, 3.0, 4),
                                     (1.0, 0.5, 0.5, 5.0, 5.0, 1), (4.0, 0.5, 0.5, 30.0, 30.0, None)]:
        m = annulus_mesh(RI, RO, h=h, h_inner=hi, h_outer=ho, grading_length=gl, outer_grading_length=glo, seed=seed)
        assert m.min_angle_deg().min() >= 25.0, (h, hi, ho, gl, glo, seed)
        _check_valid_annulus(m)
        assert m.edge_lengths("inner").mean() == pytest.approx(hi or h, rel=0.05)
        assert m.edge_lengths("outer").mean() == pytest.approx(ho, rel=0.05)
    # overlapping ramps (h = 4, both over 30 mm of the 48-mm annulus): the size at mid-radius is the smaller ramp
    e = m.edges()
    rm = np.hypot(*(0.5 * (m.points[e[:, 0]] + m.points[e[:, 1]])).T)
    L = np.linalg.norm(m.points[e[:, 1]] - m.points[e[:, 0]], axis=1)
    mid = np.abs(rm - 29.0) < 1.0  # both ramps give 0.5 + 3.5 * 24/30 = 3.3 mm here
    assert L[mid].mean() == pytest.approx(3.3, rel=0.05)


@pytest.mark.parametrize("kw,msg", [
    (dict(h_outer=0.0), "h_outer=0.0 is out of range: allowed (0, h = 1.0]"),
    (dict(h_outer=1.5), "h_outer=1.5 is out of range: allowed (0, h = 1.0]"),
    (dict(h_outer=float("nan")), "h_outer=nan is out of range"),
    (dict(h_outer="0.5"), "h_outer='0.5' is out of range"),
    (dict(h_outer=True), "h_outer=True is out of range"),
    (dict(h_outer=0.5, outer_grading_length=0.0), "outer_grading_length=0.0 is out of range: allowed a finite number > 0"),
    (dict(h_outer=0.5, outer_grading_length=None), "outer_grading_length=None is out of range"),
])
def test_outer_graded_validation(kw, msg):
    with pytest.raises(ValueError) as e:
        annulus_mesh(RI, RO, h=1.0, **kw)
    assert msg in str(e.value)


def _boundary_layer_h1_error(h, h_outer, delta):
    """Relative H1-seminorm error of P1 for −Δu + u/δ² = 0, u = I0(r/δ)/I0(r_o/δ) (mm).

    The exact solution is a boundary layer of thickness δ at r_o; its K0 part is left out
    (relative size K0(r_o/δ) I0(r_i/δ) / (I0(r_o/δ) K0(r_i/δ)) < 1e-40 here), so u on r_i is
    that small instead of 0.  Errors by the mesh's element centroids and the exact gradient
    at the 3 edge midpoints (exact for quadratics).
    """
    import scipy.sparse.linalg as spla
    from scipy.special import ive

    from solver import fem

    m = annulus_mesh(RI, RO, h=h, h_outer=h_outer)
    pts, tri = np.asarray(m.points), np.asarray(m.triangles)

    def grad_ex(x):
        r = np.hypot(x[..., 0], x[..., 1])
        return (ive(1, r / delta) / ive(0, RO / delta) * np.exp((r - RO) / delta) / (delta * r))[..., None] * x

    A = (fem.stiffness_matrix(pts, tri) + fem.mass_matrix(pts, tri) / delta**2).tocsr()
    b = np.concatenate([m.boundary_nodes("inner"), m.boundary_nodes("outer")])
    free = np.setdiff1d(np.arange(m.n_nodes), b)
    u = np.zeros(m.n_nodes)
    rb = np.hypot(*pts[b].T)
    u[b] = ive(0, rb / delta) / ive(0, RO / delta) * np.exp((rb - RO) / delta)
    u[free] = spla.spsolve(A[free][:, free].tocsc(), -A[free][:, b] @ u[b])
    gh = fem.element_gradient(u, tri, fem.geometry(pts, tri))
    x = pts[tri]
    xq = 0.5 * (x + x[:, [1, 2, 0]])  # edge midpoints (M, 3, 2), weights |T|/3
    gq = grad_ex(xq)
    w = m.areas[:, None] / 3.0
    err = np.sqrt(np.sum(w * ((gh[:, None, :] - gq) ** 2).sum(-1)))
    return err / np.sqrt(np.sum(w * (gq ** 2).sum(-1)))


def _layer_h_eff(h, h_outer, delta):
    """Hessian-weighted mean size (mm) of the boundary-layer solution: h_eff² = ∫ size² |D²u|² r dr / ∫ |D²u|² r dr."""
    from scipy.special import ive

    from solver.mesh import annulus_size

    r = np.linspace(RO - 20 * delta, RO, 20001)
    u = ive(0, r / delta) * np.exp(r / delta - RO / delta)
    ur = ive(1, r / delta) * np.exp(r / delta - RO / delta) / delta
    hess2 = (u / delta**2 - ur / r) ** 2 + (ur / r) ** 2  # u_rr from the ODE, u_θθ/r² + u_r/r = u_r/r
    size = annulus_size(r, h, h_outer=h_outer, r_outer=RO)
    return math.sqrt(np.sum(size**2 * hess2 * r) / np.sum(hess2 * r))


def test_outer_grading_resolves_a_boundary_layer():
    """P1 H1 error = c h_eff (first order) for uniform and outer-graded meshes alike.

    A layer of thickness δ = 1 mm (the drained wall's √(c t) at 2 s) on meshes h = 2 with
    h_outer = None, 1, 0.5, 0.25: the error falls with the layer's effective mesh size at
    order 1 (slope 0.9–1.1) with one constant c, so the grading refines where the solution
    needs it; h = 2 graded to h_outer = 0.5 (h_eff < 1 mm) beats c · 1 mm, the uniform h = 1 error.
    """
    delta = 1.0
    cases = [(2.0, None), (2.0, 1.0), (2.0, 0.5), (2.0, 0.25)]
    e = np.array([_boundary_layer_h1_error(h, ho, delta) for h, ho in cases])
    he = np.array([_layer_h_eff(h, ho, delta) for h, ho in cases])
    assert np.all(np.diff(e) < 0), e
    slope = np.polyfit(np.log(he), np.log(e), 1)[0]
    assert 0.9 < slope < 1.1, (he, e, slope)
    c = e / he
    assert c.max() / c.min() < 1.2, c
    assert e[2] < c.mean() * 1.0  # below what the uniform h = 1 mesh gives (h_eff = 1)


@pytest.mark.parametrize("v,allowed", [(0.0, "(0, h = 1.0]"), (1.5, "(0, h = 1.0]"), (float("nan"), "a finite number"),
                                       ("fine", "a number"), (True, "a number")])
def test_run_option_h_outer_validation(v, allowed):
    from solver.options import RunOptions

    with pytest.raises(ValueError) as e:
        RunOptions(h_outer=v)
    assert f"run option h_outer={v!r} is out of range: allowed {allowed}" == str(e.value)


def test_run_option_h_outer_round_trips_and_is_omitted_when_none():
    from solver.options import RunOptions

    assert "h_outer" not in RunOptions().to_dict()
    o = RunOptions(h=2.0, h_outer=0.5, h_inner=1.0)
    assert o.to_dict()["h_outer"] == 0.5
    assert RunOptions.from_dict(o.to_dict()) == o


@pytest.mark.parametrize("kw,allowed", [
    (dict(h=2.0, h_inner=1.0, inner_grading_length=0.0), "> 0.0"),
    (dict(h=2.0, h_inner=1.0, inner_grading_length=-3.0), "> 0.0"),
    (dict(h=2.0, h_inner=1.0, inner_grading_length=float("inf")), "a finite number"),
    (dict(h=2.0, inner_grading_length=10.0), "None unless h_inner is given"),
])
def test_run_option_inner_grading_length_validation(kw, allowed):
    from solver.options import RunOptions

    with pytest.raises(ValueError) as e:
        RunOptions(**kw)
    assert f"run option inner_grading_length={kw['inner_grading_length']!r} is out of range: allowed {allowed}" \
        in str(e.value)


def test_run_option_inner_grading_length_reaches_the_run_mesh():
    """The simulation's mesh is the annulus graded over the option's length (edge sizes follow annulus_size), and
    the option is left out of the option dict (so of older run keys) when None."""
    from solver import Parameters
    from solver.mesh import annulus_size
    from solver.options import RunOptions
    from solver.simulate import _setup

    assert "inner_grading_length" not in RunOptions(h=2.0, h_inner=1.0).to_dict()
    o = RunOptions(h=2.0, h_inner=0.5, inner_grading_length=12.0)
    assert RunOptions.from_dict(o.to_dict()) == o
    p = Parameters()
    m = _setup(p, o, None, None).mesh
    assert m is annulus_mesh(p.r_inner, p.r_outer, 2.0, None, h_inner=0.5, grading_length=12.0)
    e = m.edges()
    L = np.linalg.norm(m.points[e[:, 1]] - m.points[e[:, 0]], axis=1)
    rm = np.hypot(*(0.5 * (m.points[e[:, 0]] + m.points[e[:, 1]])).T)
    band = (rm > p.r_inner + 5.5) & (rm < p.r_inner + 9.0)   # inside the 12 mm grading, beyond the 5 mm default
    ratio = L[band] / annulus_size(rm[band], 2.0, 0.5, p.r_inner, 12.0)
    assert abs(ratio.mean() - 1) < 0.05
    # the default 5 mm grading would have size h = 2 there: the option is what makes the band fine
    assert annulus_size(rm[band], 2.0, 0.5, p.r_inner, 5.0).min() == pytest.approx(2.0)
    assert L[band].mean() < 1.6
