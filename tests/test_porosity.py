"""Initial porosity fields (paper Sec. 3.3)."""
import math

import numpy as np
import pytest

from solver.mesh import annulus_mesh, rectangle_mesh
from solver.params import Parameters
from solver.porosity import (POCKET_RADIUS, POCKET_SUBDIVISION, POCKET_VALUE, _subtriangle_barycentric,
                             constant_porosity, initial_porosity, pocket_centers, pocket_fraction,
                             pocket_porosity, random_porosity)


@pytest.fixture(scope="module")
def m1():
    return annulus_mesh(5.0, 53.0, h=1.0)


def test_random_porosity_mean_bounds_determinism(m1):
    phi = random_porosity(m1, 0.4, 0.2, seed=0)
    M = m1.n_elements
    assert phi.shape == (M,)
    assert phi.min() >= 0.2 and phi.max() <= 0.6
    # mean of M uniform samples on a width-0.4 interval: sd = 0.4 / sqrt(12 M); 4 sd
    assert abs(phi.mean() - 0.4) < 4 * 0.4 / math.sqrt(12 * M)
    # variance of U(0.2, 0.6) = 0.4^2 / 12; relative sd of the sample variance ~ sqrt(0.8 / M)
    assert phi.var() == pytest.approx(0.4**2 / 12, rel=4 * math.sqrt(0.8 / M))
    # the range is covered: extremes within a few 1/M of the bounds
    assert phi.min() < 0.2 + 0.4 * 10 / M and phi.max() > 0.6 - 0.4 * 10 / M
    assert np.array_equal(phi, random_porosity(m1, 0.4, 0.2, seed=0))
    assert not np.array_equal(phi, random_porosity(m1, 0.4, 0.2, seed=1))
    assert np.array_equal(phi, np.random.default_rng(0).uniform(0.4 - 0.2, 0.4 + 0.2, M))


def test_constant(m1):
    assert np.all(constant_porosity(m1, 0.35) == 0.35)
    assert random_porosity(m1, 0.3, 0.0, seed=5) == pytest.approx(np.full(m1.n_elements, 0.3))


@pytest.mark.parametrize("call,name", [
    (lambda m: random_porosity(m, 1.2, 0.1), "mean"),
    (lambda m: random_porosity(m, 0.4, 0.5), "half_range"),
    (lambda m: random_porosity(m, 0.4, -0.1), "half_range"),
    (lambda m: random_porosity(m, 0.4, 0.2, seed=-3), "seed"),
    (lambda m: constant_porosity(m, 1.0), "value"),
    (lambda m: pocket_porosity(m, pocket_value=1.5), "pocket_value"),
    (lambda m: pocket_porosity(m, radius=0.0), "radius"),
    (lambda m: random_porosity(np.zeros((3, 2))), "mesh"),
])
def test_validation(m1, call, name):
    with pytest.raises(ValueError, match=name):
        call(m1)


def test_subtriangle_rule_is_exact_for_linear_functions():
    bary = _subtriangle_barycentric(POCKET_SUBDIVISION)
    assert bary.shape == (POCKET_SUBDIVISION**2, 3)
    assert np.allclose(bary.sum(axis=1), 1.0) and bary.min() > 0
    assert np.allclose(bary.mean(axis=0), 1 / 3)  # equal-area midpoint rule integrates P1 exactly
    # the sample points are distinct
    assert len(np.unique(np.round(bary, 12), axis=0)) == len(bary)


def test_pocket_fraction_of_a_covered_square():
    # a unit square fully inside a disc -> fraction 1; far away -> 0
    m = rectangle_mesh(1.0, 1.0, 4, 4, x0=-0.5, y0=-0.5)
    assert np.all(pocket_fraction(m, [[0.0, 0.0]], 1.0) == 1.0)
    assert np.all(pocket_fraction(m, [[10.0, 0.0]], 1.0) == 0.0)
    # disc of radius 0.3 centred in the square: area fraction sum -> pi r^2
    fine = rectangle_mesh(1.0, 1.0, 40, 40, x0=-0.5, y0=-0.5)
    frac = pocket_fraction(fine, [[0.0, 0.0]], 0.3)
    assert (frac * fine.areas).sum() == pytest.approx(math.pi * 0.09, rel=2e-3)


def _pocket_integral_error(h):
    m = annulus_mesh(5.0, 53.0, h=h)
    A = m.areas
    phi = pocket_porosity(m)
    exact = 0.4 * A.sum() + (POCKET_VALUE - 0.4) * 3 * math.pi * POCKET_RADIUS**2
    return (phi * A).sum() - exact, (phi * A).sum(), m


def test_pocket_field_integral_converges():
    errs, ints = {}, {}
    for h in (4.0, 2.0, 1.0):
        err, integral, m = _pocket_integral_error(h)
        errs[h], ints[h] = err, integral
        # Derived bound: only sub-triangles crossing a pocket circle can be misclassified; they lie in the
        # band | |x - c| - R | <= d_sub, d_sub = (longest element edge) / n, of area 2 pi R * 2 d_sub; each
        # costs at most (pocket - base) times its area.
        x = m.points[m.triangles]
        longest = np.linalg.norm(x - np.roll(x, 1, axis=1), axis=2).max()
        d_sub = longest / POCKET_SUBDIVISION
        bound = (POCKET_VALUE - 0.4) * 3 * 2 * math.pi * POCKET_RADIUS * 2 * d_sub
        assert abs(err) <= bound
    # Cauchy-type convergence: successive differences shrink with h
    assert abs(ints[1.0] - ints[2.0]) < abs(ints[2.0] - ints[4.0])
    # at the reference mesh the pocket mass 0.2 * 3 pi 1.5^2 = 4.24 is captured to better than 0.5 %
    assert abs(errs[1.0]) < 5e-3 * 0.2 * 3 * math.pi * 1.5**2


def test_pockets_are_three_and_120_degrees_apart(m1):
    phi = pocket_porosity(m1)
    assert phi.min() == pytest.approx(0.4) and phi.max() == pytest.approx(POCKET_VALUE)
    assert np.all((phi >= 0.4 - 1e-15) & (phi <= POCKET_VALUE + 1e-15))
    c = m1.centroids
    excess = (phi - 0.4) * m1.areas
    ctr = pocket_centers(7.0)
    assert np.allclose(np.hypot(*ctr.T), 7.0)
    angles = []
    for k in range(3):
        near = np.linalg.norm(c - ctr[k], axis=1) < POCKET_RADIUS + 2.0
        # each pocket carries one third of the excess mass, centred at its centre
        assert excess[near].sum() == pytest.approx(excess.sum() / 3, rel=0.02)
        g = (excess[near, None] * c[near]).sum(axis=0) / excess[near].sum()
        assert np.linalg.norm(g - ctr[k]) < 0.1  # h = 1 mesh, mass centre accurate to ~h/10
        angles.append(math.degrees(math.atan2(g[1], g[0])) % 360)
    gaps = np.diff(np.sort(angles + [min(angles) + 360]))
    assert gaps == pytest.approx([120, 120, 120], abs=1.0)
    # everything outside the pockets is exactly the base value
    far = np.min(np.linalg.norm(c[:, None] - ctr[None], axis=2), axis=1) > POCKET_RADIUS + 2.0
    assert np.all(phi[far] == 0.4)
    # pocket mass centres at r_inner + 2 mm = 7 mm, near the inner boundary
    assert np.allclose([math.hypot(*pocket_centers(7.0)[k]) for k in range(3)], 7.0)


def test_initial_porosity_dispatch(m1):
    p = Parameters()
    assert np.array_equal(initial_porosity(m1, p), random_porosity(m1, 0.4, 0.2, 0))
    assert np.array_equal(initial_porosity(m1, p.replace(seed=7, phi_range=0.1)), random_porosity(m1, 0.4, 0.1, 7))
    assert np.array_equal(initial_porosity(m1, p.replace(porosity_field="pockets")), pocket_porosity(m1))
    assert np.all(initial_porosity(m1, p.replace(porosity_field="constant", phi_mean=0.3)) == 0.3)
    # pockets follow the inner radius
    m = annulus_mesh(8.0, 40.0, h=2.0)
    phi = initial_porosity(m, Parameters(r_inner=8.0, r_outer=40.0, porosity_field="pockets"))
    assert np.array_equal(phi, pocket_porosity(m, center_radius=10.0))
