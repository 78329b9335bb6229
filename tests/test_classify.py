"""Flow-regime classifier on synthetic fields with known answers.

Meshes: an annulus triangulation built here (scipy Delaunay on jittered ring points)
and solver.mesh.annulus_mesh, each at h = 2 and 1 mm.  Background porosity: uniform in
[0.2, 0.6] per element (Sec. 3.3).  Known answers: counts of fingers / cracks are exact;
lengths and radii are checked within one element size h (the open region is a union of
whole elements, the raster adds at most 0.4 h).
"""
import math

import numpy as np
import pytest
from scipy.spatial import Delaunay

from sweep.regimes.classify import (
    REGIME_RULES,
    REGIMES,
    Classification,
    ClassifierOptions,
    build_raster,
    classification_to_dict,
    classify_fields,
    classify_run,
    select_snapshot,
)

RI, RO = 5.0, 53.0
ROTATIONS = (0.0, 0.37, 2.1)


# --------------------------------------------------------------------------- meshes
def ring_annulus(h, ri=RI, ro=RO, seed=0, jitter=0.15):
    """Annulus triangulation: jittered points on rings, Delaunay, hole removed."""
    rng = np.random.default_rng(seed)
    nr = int(np.ceil((ro - ri) / (h * np.sqrt(3) / 2)))
    radii = np.linspace(ri, ro, nr + 1)
    pts = []
    for j, r in enumerate(radii):
        n = max(8, int(round(2 * np.pi * r / h)))
        inner = 0 < j < nr
        th = 2 * np.pi * (np.arange(n) + 0.5 * (j % 2) + (rng.uniform(-jitter, jitter, n) if inner else 0)) / n
        rj = r + (rng.uniform(-jitter, jitter, n) * 0.5 * h if inner else 0)
        pts.append(np.c_[rj * np.cos(th), rj * np.sin(th)])
    p = np.vstack(pts)
    tri = Delaunay(p).simplices
    c = p[tri].mean(axis=1)
    return p, tri[np.hypot(c[:, 0], c[:, 1]) > ri]


def solver_annulus(h):
    try:
        from solver.mesh import annulus_mesh
    except ImportError as exc:  # pragma: no cover - depends on the other helper's module
        pytest.skip(f"solver.mesh.annulus_mesh not importable yet: {exc}")
    m = annulus_mesh(RI, RO, h=h)
    return np.asarray(m.points), np.asarray(m.triangles)


MESHES = [("delaunay", 2.0), ("delaunay", 1.0), ("solver", 2.0), ("solver", 1.0)]


@pytest.fixture(scope="module", params=MESHES, ids=[f"{k}-h{h:g}" for k, h in MESHES])
def mesh(request):
    kind, h = request.param
    p, t = ring_annulus(h) if kind == "delaunay" else solver_annulus(h)
    return p, t, h


# --------------------------------------------------------------------------- fields
def centroids(p, t):
    return p[t].mean(axis=1)


def background_phi(t, seed=1):
    return np.random.default_rng(seed).uniform(0.2, 0.6, len(t))


def slot_mask(xy, angles, lengths, width=4.0):
    """Points of radial slots from the centre to r = RI + L (width in mm)."""
    m = np.zeros(len(xy), bool)
    for a, L in zip(angles, lengths):
        e = np.array([np.cos(a), np.sin(a)])
        along = xy @ e
        perp = np.abs(xy[:, 0] * e[1] - xy[:, 1] * e[0])
        m |= (along >= 0) & (along <= RI + L) & (perp <= width / 2)
    return m


def seg_dist(xy, angles, lengths):
    d = np.full(len(xy), np.inf)
    for a, L in zip(angles, lengths):
        e = np.array([np.cos(a), np.sin(a)])
        q = np.clip(xy @ e, 0, RI + L)[:, None] * e
        d = np.minimum(d, np.hypot(*(xy - q).T))
    return d


def front_S(p, R_of_theta, width=1.0):
    """Nodal saturation: 1 inside r < R(theta), 0 outside, tanh interface (S = 0.5 at R)."""
    r = np.hypot(p[:, 0], p[:, 1])
    th = np.arctan2(p[:, 1], p[:, 0])
    return 0.5 * (1 - np.tanh((r - R_of_theta(th)) / width))


def fingers_R(R0, A, n, rot=0.0, ripple=0.5):
    """R0 + A shape(n theta) + small ripples (amplitude 0.5 mm, 23 waves)."""
    def R(th):
        base = R0 + ripple * np.cos(23 * (th - rot))
        if n == 0:
            return base
        return base + A * ((1 + np.cos(n * (th - rot))) / 2) ** 3
    return R


def lobes_R(R0, A, angles, rot=0.0, width=0.25):
    def R(th):
        out = R0 + 0.5 * np.cos(23 * (th - rot))
        for a in angles:
            out = out + A * np.exp(-(np.angle(np.exp(1j * (th - a))) / width) ** 2)
        return out
    return R


def crack_angles(n, rot):
    return rot + np.arange(n) * 2 * np.pi / max(n, 1) + 0.1 * np.arange(n)


# --------------------------------------------------------------------------- fingers
@pytest.mark.parametrize("rot", ROTATIONS)
@pytest.mark.parametrize("nf", [0, 3, 5, 8])
def test_fingers_without_cracks(mesh, nf, rot):
    p, t, h = mesh
    c = classify_fields(p, t, front_S(p, fingers_R(20.0, 10.0, nf, rot)), background_phi(t))
    assert c.n_fingers == nf
    assert c.n_cracks == 0 and c.crack_length == 0.0 and not c.fracturing
    assert c.regime == ("uniform_invasion" if nf == 0 else "viscous_fingering")
    # leading edge R0 + A (+- ripple 0.5); within one element size
    assert abs(c.front_radius_max - (20.0 + (10.0 if nf else 0.0))) <= 0.5 + h
    if nf == 0:  # ripples average out over theta
        assert abs(c.front_radius_mean - 20.0) <= 0.5 * h
    # finger directions: maxima of the analytic R(theta) (near rot + 2 pi k / n, shifted
    # by the ripples), found on a fine grid
    if nf:
        th = np.linspace(-np.pi, np.pi, 36000, endpoint=False)
        R = fingers_R(20.0, 10.0, nf, rot)(th)
        expect = []
        for k in range(nf):
            a = rot + 2 * np.pi * k / nf
            near = np.abs(np.angle(np.exp(1j * (th - a)))) < np.pi / nf
            expect.append(th[near][np.argmax(R[near])])
        d = np.abs(np.angle(np.exp(1j * (np.array(c.finger_angles)[:, None] - np.array(expect)[None, :]))))
        # near a tip r = R0 + A (1 - 3 (n dtheta)^2 / 4): a radial error of h/2 (mesh
        # interpolation + raster) moves the peak by at most sqrt((h/2) / (0.75 A n^2))
        assert d.min(axis=0).max() < math.sqrt(0.5 * h / (0.75 * 10.0 * nf**2))


# --------------------------------------------------------------------------- cracks
SLOTS = {0: [], 1: [12.0], 3: [8.0, 14.0, 20.0], 5: [10.0, 12.0, 14.0, 16.0, 18.0]}


@pytest.mark.parametrize("rot", ROTATIONS)
@pytest.mark.parametrize("ns", sorted(SLOTS))
def test_radial_slots(mesh, ns, rot):
    p, t, h = mesh
    Ls = SLOTS[ns]
    phi = background_phi(t)
    phi[slot_mask(centroids(p, t), crack_angles(ns, rot), Ls)] = 1.0
    c = classify_fields(p, t, front_S(p, fingers_R(35.0, 0.0, 0, rot)), phi)
    assert c.n_cracks == ns
    L = max(Ls, default=0.0)
    assert abs(c.crack_length - L) <= h
    assert abs(c.crack_tip_radius - (RI + L)) <= h
    assert c.fracturing == (ns > 0)
    assert c.regime == ("invasive_fracturing" if ns else "uniform_invasion")
    if ns:  # each tip lies on the end face of its slot (half width 2 mm) within h
        expect = np.angle(np.exp(1j * crack_angles(ns, rot)))
        d = np.abs(np.angle(np.exp(1j * (np.array(c.crack_tip_angles)[:, None] - expect[None, :]))))
        tol = np.arctan((2.0 + h) / (RI + np.asarray(Ls)))
        assert np.all(d.min(axis=0) <= tol)


def test_rotation_invariance(mesh):
    p, t, h = mesh
    out = []
    for rot in (0.0, 0.9, 2.6, 4.4):
        phi = background_phi(t)
        phi[slot_mask(centroids(p, t), crack_angles(3, rot), [9.0, 15.0, 13.0])] = 1.0
        c = classify_fields(p, t, front_S(p, fingers_R(25.0, 9.0, 5, rot + 0.3)), phi)
        out.append(c)
    assert len({(c.n_cracks, c.n_fingers, c.regime) for c in out}) == 1
    assert np.ptp([c.crack_length for c in out]) <= h
    assert np.ptp([c.front_radius_max for c in out]) <= h
    assert np.ptp([c.front_radius_mean for c in out]) <= 0.5 * h


def test_isolated_open_elements_do_not_count(mesh):
    p, t, h = mesh
    rng = np.random.default_rng(5)
    phi = background_phi(t)
    phi[rng.random(len(t)) < 0.02] = 1.0  # 2 % isolated open elements
    # and a pair of open elements touching the cavity (below the minimum area)
    cen = centroids(p, t)
    r = np.hypot(*cen.T)
    first = np.argsort(np.where(np.abs(np.arctan2(cen[:, 1], cen[:, 0])) < 0.3, r, np.inf))[:2]
    phi[first] = 1.0
    c = classify_fields(p, t, front_S(p, fingers_R(30.0, 0.0, 0)), phi)
    assert c.crack_length == 0.0 and c.n_cracks == 0 and c.regime == "uniform_invasion"
    # the same noise next to 3 slots changes nothing
    phi[slot_mask(cen, crack_angles(3, 0.0), [9.0, 15.0, 13.0])] = 1.0
    c = classify_fields(p, t, front_S(p, fingers_R(30.0, 0.0, 0)), phi)
    assert c.n_cracks == 3 and abs(c.crack_length - 15.0) <= h


def test_fork_and_ring(mesh):
    p, t, h = mesh
    cen = centroids(p, t)
    S = front_S(p, fingers_R(40.0, 0.0, 0))
    # Y crack: stem to r = 20 then two 12 mm arms at +-26 deg
    a0 = 0.5
    base = (RI + 15.0) * np.array([np.cos(a0), np.sin(a0)])
    m = slot_mask(cen, [a0], [15.0])
    tips = []
    for da in (-0.45, 0.45):
        e = np.array([np.cos(a0 + da), np.sin(a0 + da)])
        q = cen - base
        m |= (q @ e >= 0) & (q @ e <= 12.0) & (np.abs(q[:, 0] * e[1] - q[:, 1] * e[0]) <= 2.0)
        tips.append(np.hypot(*(base + 12.0 * e)))
    phi = background_phi(t)
    phi[m] = 1.0
    c = classify_fields(p, t, S, phi)
    assert c.n_cracks == 2
    # farthest point of the arms: centre-line tip, plus at most the half width 2 mm
    assert max(tips) - RI - h <= c.crack_length <= max(tips) - RI + 2.0 + h
    # three slots joined by an open ring around the cavity are still three branches
    phi = background_phi(t)
    phi[slot_mask(cen, crack_angles(3, 0.0), [14.0, 18.0, 16.0]) | (np.hypot(*cen.T) < RI + 2.0)] = 1.0
    c = classify_fields(p, t, S, phi)
    assert c.n_cracks == 3 and abs(c.crack_length - 18.0) <= h


# --------------------------------------------------------------------------- regimes
@pytest.mark.parametrize("rot", ROTATIONS)
def test_fracturing_regimes(mesh, rot):
    p, t, h = mesh
    ang = rot + np.array([0.0, 2.1, 4.0])
    Ls = [14.0, 18.0, 16.0]
    phi = background_phi(t)
    phi[slot_mask(centroids(p, t), ang, Ls)] = 1.0
    r = np.hypot(p[:, 0], p[:, 1])

    # fluid confined to the cracks: S >= 0.5 within 3 mm of the slot centre lines
    d = np.minimum(seg_dist(p, ang, Ls), r - RI)
    c = classify_fields(p, t, 0.5 * (1 - np.tanh((d - 3.0) / 0.7)), phi)
    assert c.regime == "non_invasive_fracturing"
    assert c.n_cracks == 3 and abs(c.crack_length - 18.0) <= h
    assert c.invasion_reach <= 3.0 + h  # 3 mm ahead of the tips, 1 mm beside the slots

    # one invasion lobe along each crack (reference run: 3 branches over 3 cracks)
    c = classify_fields(p, t, front_S(p, lobes_R(22.0, 12.0, ang, rot)), phi)
    assert c.n_fingers == 3 and c.n_unexplained_fingers == 0
    assert c.regime == "invasive_fracturing"
    assert abs(c.front_radius_max - 34.5) <= h  # R0 + A (+ ripple <= 0.5)
    assert np.all(np.abs(np.array(c.finger_radii) - 34.0) <= 0.5 + h)
    assert c.invasion_reach > 10.0

    # 8 fingers that the 3 cracks do not explain
    c = classify_fields(p, t, front_S(p, fingers_R(22.0, 10.0, 8, rot + 0.2)), phi)
    assert c.n_fingers == 8 and c.n_unexplained_fingers >= 5
    assert c.regime == "fracturing_fingering"


def test_disconnected_invaded_layer_is_not_the_front(mesh):
    p, t, h = mesh
    r = np.hypot(p[:, 0], p[:, 1])
    S = np.maximum(front_S(p, fingers_R(20.0, 0.0, 0)), (r > 49.0).astype(float))
    c = classify_fields(p, t, S, background_phi(t))
    assert abs(c.front_radius_max - 20.5) <= h
    assert abs(c.front_radius_mean - 20.0) <= 0.5 * h
    assert c.regime == "uniform_invasion"


def test_nodal_porosity(mesh):
    """Nodal phi is interpolated linearly: a band of open nodes of width w is open
    (phi >= 0.99) on about w - 2h, so the nodal slots are 4 + 2h wide."""
    p, t, h = mesh
    rng = np.random.default_rng(3)
    phi = rng.uniform(0.2, 0.6, len(p))
    phi[slot_mask(p, crack_angles(3, 0.4), [10.0, 13.0, 17.0], width=4.0 + 2 * h)] = 1.0
    c = classify_fields(p, t, front_S(p, fingers_R(35.0, 0.0, 0)), phi)
    assert c.n_cracks == 3 and abs(c.crack_length - 17.0) <= h
    c2 = classify_fields(p, t, front_S(p, fingers_R(35.0, 0.0, 0)), phi, phi_location="node")
    assert c2 == c


# --------------------------------------------------------------------------- API
def test_thresholds_and_dict():
    p, t = ring_annulus(2.0)
    phi = background_phi(t)
    phi[slot_mask(centroids(p, t), [0.3], [6.0])] = 1.0
    S = front_S(p, fingers_R(30.0, 0.0, 0))
    c = classify_fields(p, t, S, phi)
    assert c.fracturing and abs(c.crack_length - 6.0) <= 2.0
    # raising L_min above the crack length turns it into porous invasion
    c = classify_fields(p, t, S, phi, min_crack_length=9.0)
    assert not c.fracturing and c.regime == "uniform_invasion"
    assert c.thresholds["min_crack_length"] == 9.0
    c = classify_fields(p, t, S, phi, options=ClassifierOptions(min_crack_length=9.0))
    assert not c.fracturing
    d = classification_to_dict(c)
    assert d["regime"] == "uniform_invasion" and d["fracturing"] is False
    assert set(d) >= {"crack_length", "crack_tip_radius", "n_cracks", "n_fingers",
                      "front_radius_mean", "front_radius_max", "invasion_reach"}
    assert isinstance(c, Classification) and c.regime in REGIMES
    for r in REGIMES:
        assert r in REGIME_RULES


def test_bad_input():
    p, t = ring_annulus(2.0)
    S, phi = np.zeros(len(p)), background_phi(t)
    with pytest.raises(ValueError, match="points"):
        classify_fields(p[:, :1], t, S, phi)
    with pytest.raises(ValueError, match="triangles"):
        classify_fields(p, t + len(p), S, phi)
    with pytest.raises(ValueError, match="phi length=7"):
        classify_fields(p, t, S, np.ones(7))
    with pytest.raises(ValueError, match="S"):
        classify_fields(p, t, np.full(len(p), np.nan), phi)
    with pytest.raises(ValueError, match="r_outer"):
        classify_fields(p, t, S, phi, r_inner=5.0, r_outer=4.0)
    with pytest.raises(ValueError, match="phi_open"):
        classify_fields(p, t, S, phi, phi_open=1.5)
    with pytest.raises(ValueError, match="unknown classifier option"):
        classify_fields(p, t, S, phi, bogus=1)
    with pytest.raises(ValueError, match="min_fingers"):
        ClassifierOptions(min_fingers=0)


def test_raster_cache_changes_no_result_h1():
    """One h = 1 mm snapshot (~10,400 nodes): a new mesh (cold raster cache) and the same mesh again (the
    cached raster) give the same classification.  Its speed is not asserted here (no timed tests)."""
    p, t = solver_annulus(1.0)
    phi = background_phi(t)
    phi[slot_mask(centroids(p, t), crack_angles(3, 0.0), [9.0, 15.0, 13.0])] = 1.0
    S = front_S(p, fingers_R(30.0, 8.0, 5))
    p2 = p + 1e-9  # new mesh bytes: cold raster cache
    cold = classification_to_dict(classify_fields(p2, t, S, phi))
    warm = classification_to_dict(classify_fields(p2, t, S, phi))
    assert cold == warm and cold["n_cracks"] == 3


# --------------------------------------------------------------------------- run folders
@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    """Synthetic run folder (format of the solver): 4 snapshots, fronts at 10..45 mm."""
    d = tmp_path_factory.mktemp("run")
    (d / "snapshots").mkdir()
    p, t = ring_annulus(2.0)
    np.savez(d / "snapshots" / "mesh.npz", points=p, triangles=t)
    (d / "params.toml").write_text("r_inner = 5.0\nr_outer = 53.0\nl_S = 4.0\nl_d = 4.0\n")
    ang = np.array([0.3, 2.4, 4.4])
    phi = background_phi(t)
    phi[slot_mask(centroids(p, t), ang, [10.0, 12.0, 11.0])] = 1.0
    for i, (tt, R0) in enumerate([(0.5, 10.0), (1.0, 20.0), (1.5, 30.0), (2.0, 40.0)]):
        S = front_S(p, lobes_R(R0, 6.0, ang))
        np.savez(d / "snapshots" / f"snap_{i:05d}.npz", t=tt, S=S, phi=phi)
    return d


def test_classify_run(run_dir):
    c, t = classify_run(run_dir)
    assert t == 2.0 and c.regime == "invasive_fracturing" and c.n_cracks == 3
    assert abs(c.front_radius_max - 46.5) <= 2.0
    assert classify_run(run_dir, at=1.2).t == 1.0
    # first snapshot whose leading edge reaches 25 mm: R0 = 20 (+6 lobe) at t = 1
    assert classify_run(run_dir, at={"front_radius": 25.0}).t == 1.0
    # mean radius reaches 25 mm only at R0 = 30 (t = 1.5)
    assert classify_run(run_dir, at={"front_radius": 25.0, "measure": "mean"}).t == 1.5
    # never reached: the last one
    assert classify_run(run_dir, at={"front_radius": 60.0}).t == 2.0
    assert select_snapshot(run_dir, 0.0)[0] == 0.5
    with pytest.raises(ValueError, match="at="):
        classify_run(run_dir, at="first")
    with pytest.raises(ValueError, match="measure"):
        classify_run(run_dir, at={"front_radius": 20.0, "measure": "median"})
    with pytest.raises(ValueError, match="run_dir"):
        classify_run(run_dir / "nope")


def test_raster_reuse():
    p, t = ring_annulus(2.0)
    ras = build_raster(p, t)
    assert build_raster(p, t) is ras  # cached
    assert abs(ras.centre[0]) < 1e-2 and abs(ras.centre[1]) < 1e-2
    # the rasterised area equals the mesh area within the boundary pixels
    u, v = p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]]
    area_mesh = 0.5 * np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]).sum()
    area_ras = ras.inside.sum() * ras.pixel**2
    perimeter = 2 * np.pi * (RI + RO)
    assert abs(area_ras - area_mesh) <= perimeter * ras.pixel


# --------------------------------------------------------------------------- crack_record = "longest"
@pytest.fixture()
def closing_run(tmp_path):
    """A run whose crack closed: the snapshots hold a 3 mm slot, the time series an open region that reached
    r_inner + 9 mm at t = 1.2 s and r_inner + 20 mm at t = 2.5 s, after the last snapshot (2.0 s)."""
    d = tmp_path / "run"
    (d / "snapshots").mkdir(parents=True)
    p, t = ring_annulus(2.0)
    np.savez(d / "snapshots" / "mesh.npz", points=p, triangles=t)
    (d / "params.toml").write_text("r_inner = 5.0\nr_outer = 53.0\n")
    phi = background_phi(t)
    phi[slot_mask(centroids(p, t), [0.3], [3.0])] = 1.0
    for i, tt in enumerate((0.5, 1.0, 2.0)):
        np.savez(d / "snapshots" / f"snap_{i:05d}.npz", t=tt, S=front_S(p, fingers_R(20.0 + 10 * i, 0.0, 0)), phi=phi)
    ts = [(0.25, RI), (0.5, RI + 2.0), (1.0, RI + 7.0), (1.2, RI + 9.0), (2.0, RI + 4.0), (2.5, RI + 20.0)]
    (d / "timeseries.csv").write_text("t,p_inj,open_tip_radius\n" + "".join(f"{a},1.0,{b}\n" for a, b in ts))
    return d


def test_longest_crack_record(closing_run):
    snap = classify_run(closing_run, min_crack_length=4.0).classification
    assert not snap.fracturing and snap.crack_length <= 4.0  # the 3 mm slot at the last snapshot
    c, t = classify_run(closing_run, min_crack_length=4.0, crack_record="longest")
    # the largest open_tip_radius - r_inner at t <= 2.0 s is the 9 mm of t = 1.2 s, not the 20 mm after it
    assert t == 2.0 and c.fracturing and c.crack_length == pytest.approx(9.0, abs=1e-12)
    assert c.crack_tip_radius == pytest.approx(RI + 9.0, abs=1e-12)
    assert classify_run(closing_run, at=1.0, crack_record="longest").classification.crack_length == pytest.approx(7.0)
    # at 0.5 s the history's 2 mm is shorter than the snapshot's slot: the snapshot's crack is read
    early = classify_run(closing_run, at=0.5, crack_record="longest").classification
    assert early.crack_length == pytest.approx(classify_run(closing_run, at=0.5).classification.crack_length)
    # a crack longer than L_min either way: the label does not depend on the record
    assert classify_run(closing_run, min_crack_length=2.0, crack_record="longest").classification.fracturing


def test_longest_crack_record_bad_input(closing_run):
    with pytest.raises(ValueError, match="crack_record='sometimes'"):
        ClassifierOptions(crack_record="sometimes")
    with pytest.raises(ValueError, match="phi_open=0.95"):
        ClassifierOptions(crack_record="longest", phi_open=0.95)
    p, t = ring_annulus(2.0)
    with pytest.raises(ValueError, match="longest_crack=-1"):
        classify_fields(p, t, np.zeros(len(p)), background_phi(t), longest_crack=-1.0)
    (closing_run / "timeseries.csv").unlink()
    with pytest.raises(FileNotFoundError, match="timeseries.csv"):
        classify_run(closing_run, crack_record="longest")


def test_run_metrics_keep_the_longest_open_crack():
    """The campaign table's open_tip_radius_max is the largest open_tip_radius of the run, _final the last one."""
    import pandas as pd

    from sweep.campaign.scheduler import _timeseries_metrics

    ts = pd.DataFrame({"t": [0.5, 1.0, 2.0, 2.5], "p_inj": [1.0, 2.0, 3.0, 2.5],
                       "open_tip_radius": [RI, RI + 9.0, RI + 4.0, RI + 3.0]})
    m = _timeseries_metrics(ts)
    assert m["open_tip_radius_max"] == RI + 9.0 and m["open_tip_radius_final"] == RI + 3.0
    assert m["p_inj_max"] == 3.0 and m["n_steps"] == 4
    assert "front_radius_max_last_step" not in m   # no front recorded, no step of it


def test_run_metrics_give_the_front_s_move_in_the_last_step():
    """front_radius_max_last_step (mm) is the last step's change of the front's angular maximum: 26.4 -> 41.6 mm
    in one step, as the eta line's C = 2 %, eta_o = 0.29 run ended; a single step has none."""
    import pandas as pd

    from sweep.campaign.scheduler import _timeseries_metrics

    ts = pd.DataFrame({"t": [1.8136, 1.8140, 1.8142], "front_radius_max": [26.36, 26.358, 41.593]})
    assert _timeseries_metrics(ts)["front_radius_max_last_step"] == pytest.approx(41.593 - 26.358)
    assert "front_radius_max_last_step" not in _timeseries_metrics(ts.iloc[:1])
