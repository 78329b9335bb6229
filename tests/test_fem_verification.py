"""Verification of the P1 kit (solver/fem.py) on the annulus against exact solutions.

1. Laplace −Δu = 0 with u = ln r (harmonic everywhere but the origin, so it is
   exact on the *polygonal* mesh domain too: no geometric error), Dirichlet data
   on both circles.  P1 theory: L2 error O(h²), H1-seminorm error O(h).
2. Plane-strain thick cylinder (Lamé): inner pressure p on r = a, outer circle
   fixed (u = 0 at r = b):  u_r = A (r − b²/r), A = −p / (2(λ+μ) + 2μ b²/a²).
   P1 displacements converge at O(h²) in L2; the polygonal inner boundary adds
   an O(h²) perturbation (inscribed 31-gon at h = 1: effective radius −0.3 %).
   The solution is dominated by the b²/r term, whose curvature near the hole
   makes the P1 error ≈ c (h/a)² with c ≈ 0.4 (measured: relative L2 error
   5.9 %, 1.63 %, 0.42 % and max nodal error 6.4 %, 1.94 %, 0.59 % at h = 2, 1,
   0.5; the P1 interpolation error alone is 0.23 % at h = 1; the FE solution is
   1.5 % too stiff at the inner wall at h = 1, i.e. the compliance error
   (energy error)²).  So 1 % is reached at h = 0.5, not at h = 1 (2 % there).
3. The same cylinder on meshes graded towards the hole (``annulus_mesh(...,
   h_inner=...)``: size h_inner on r = a growing linearly to h at a + 5 mm).
   The error follows c (h_eff/a)² with the energy-weighted mean size
   h_eff² = ∫ h(r)² r⁻⁵ dr / ∫ r⁻⁵ dr (|u''|² r ∝ r⁻⁵ for the b²/r term),
   c = 0.33–0.42 for the L2 error and 0.40–0.72 for the max nodal error over
   all the uniform and graded meshes measured.  Measured (triangles, max nodal,
   relative L2):
       h = 1, uniform          20,410   1.94 %   1.63 %
       h = 1, h_inner = 0.5    20,788   0.77 %   0.67 %   (h_eff = 0.66)
       h = 1, h_inner = 0.25   21,761   0.62 %   0.36 %   (h_eff = 0.52)
       h = 1, h_inner = 0.125  23,360   0.49 %   0.28 %   (h_eff = 0.46)
       h = 2, uniform           5,101   6.42 %   5.88 %
       h = 2, h_inner = 1       5,194   2.98 %   2.65 %   (h_eff = 1.32)
   So grading to h_inner = 0.5 meets 1 % at h = 1 with 2 % more elements (the
   uniform mesh needs h = 0.5: 80,903 elements); the error then saturates at
   the contribution of the uniform part (h_eff -> 0.41 mm as h_inner -> 0).
"""
import functools
import math

import numpy as np
import pytest
import scipy.sparse.linalg as spla

fem = pytest.importorskip("solver.fem")
from solver.mesh import GRADING_LENGTH, annulus_mesh, annulus_size  # noqa: E402

RI, RO = 5.0, 53.0
HS = (4.0, 2.0, 1.0)

# Dunavant degree-5, 7-point rule on the reference triangle (barycentric, weights sum to 1)
_a1, _b1 = 0.059715871789770, 0.470142064105115
_a2, _b2 = 0.797426985353087, 0.101286507323456
DUNAVANT5_BARY = np.array([
    [1 / 3, 1 / 3, 1 / 3],
    [_a1, _b1, _b1], [_b1, _a1, _b1], [_b1, _b1, _a1],
    [_a2, _b2, _b2], [_b2, _a2, _b2], [_b2, _b2, _a2],
])
DUNAVANT5_W = np.array([0.225, *[0.132394152788506] * 3, *[0.125939180544827] * 3])


def test_quadrature_rule_is_degree_5():
    # ∫_T x^a y^b over the reference triangle = a! b! / (a + b + 2)!, area 1/2
    ref = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    q = DUNAVANT5_BARY @ ref
    for a in range(6):
        for b in range(6 - a):
            exact = math.factorial(a) * math.factorial(b) / math.factorial(a + b + 2)
            assert 0.5 * np.sum(DUNAVANT5_W * q[:, 0] ** a * q[:, 1] ** b) == pytest.approx(exact, rel=1e-12)


def _qp(mesh):
    x = mesh.points[mesh.triangles]  # (M, 3, 2)
    xq = np.einsum("qa,mad->mqd", DUNAVANT5_BARY, x)  # (M, nq, 2)
    w = mesh.areas[:, None] * DUNAVANT5_W[None, :]  # (M, nq)
    return xq, w


def _solve_laplace(h):
    m = annulus_mesh(RI, RO, h=h)
    pts, tri = np.asarray(m.points), np.asarray(m.triangles)
    A = fem.stiffness_matrix(pts, tri).tocsr()
    b_nodes = np.concatenate([m.boundary_nodes("inner"), m.boundary_nodes("outer")])
    free = np.setdiff1d(np.arange(m.n_nodes), b_nodes)
    u = np.zeros(m.n_nodes)
    u[b_nodes] = np.log(np.hypot(*pts[b_nodes].T))
    u[free] = spla.spsolve(A[free][:, free].tocsc(), -A[free][:, b_nodes] @ u[b_nodes])
    # errors by the degree-5 rule
    xq, w = _qp(m)
    uh_q = np.einsum("qa,ma->mq", DUNAVANT5_BARY, u[tri])
    r2 = (xq**2).sum(axis=2)
    e_l2 = math.sqrt(np.sum(w * (uh_q - 0.5 * np.log(r2)) ** 2))
    g = fem.geometry(pts, tri)
    grad_h = fem.element_gradient(u, tri, g)  # (M, 2)
    grad_ex = xq / r2[..., None]
    e_h1 = math.sqrt(np.sum(w * ((grad_h[:, None, :] - grad_ex) ** 2).sum(axis=2)))
    return m.h_mean, e_l2, e_h1


def _orders(h, e):
    h, e = np.asarray(h), np.asarray(e)
    return np.log(e[:-1] / e[1:]) / np.log(h[:-1] / h[1:])


def test_laplace_ln_r_convergence_orders():
    res = [_solve_laplace(h) for h in HS]
    hm, el2, eh1 = map(np.array, zip(*res))
    p_l2, p_h1 = _orders(hm, el2), _orders(hm, eh1)
    assert np.all(p_l2 > 1.8), (el2, p_l2)
    assert np.all(p_h1 > 0.9), (eh1, p_h1)
    # absolute size at h = 1: interpolation estimates |u - I_h u|_1 <~ C h |u|_2, ||u - I_h u|| <~ C h^2 |u|_2
    # with |u|_2 = ||D^2 ln r||_L2 = sqrt(2π (1/a² − 1/b²)) = 0.499 on the annulus and C <~ 1 for
    # well-shaped triangles (min angle > 25°)
    assert eh1[-1] < 0.5 * hm[-1]
    assert el2[-1] < 0.5 * hm[-1] ** 2


def _lame(p, E, nu, a, b):
    lam = E * nu / ((1 + nu) * (1 - 2 * nu))
    mu = E / (2 * (1 + nu))
    A = -p / (2 * (lam + mu) + 2 * mu * b**2 / a**2)
    return lambda r: A * (r - b**2 / r)


@functools.lru_cache(maxsize=None)
def _solve_cylinder(h, h_inner=None, p=10.0, E=331.0, nu=0.2):
    m = annulus_mesh(RI, RO, h=h, h_inner=h_inner)
    pts, tri = np.asarray(m.points), np.asarray(m.triangles)
    N = m.n_nodes
    K = fem.elasticity_matrix(pts, tri, E, nu).tocsr()
    # traction t = σ·n = −p n on the inner circle (n: outward normal of the domain, towards the origin)
    L, n = fem.outward_normals(pts, m.inner_edges, tri)
    F = np.zeros(2 * N)
    for c in range(2):
        F[c::2] = fem.edge_load(pts, m.inner_edges, N, -p * n[:, c])
    # u = 0 on the outer circle, imposed with the kit's structure-preserving Dirichlet rows
    asm = fem.BlockAssembler(tri, N, 2)
    outer = m.boundary_nodes("outer")
    dofs = np.concatenate([2 * outer, 2 * outer + 1])
    dr = asm.dirichlet_rows(dofs)
    Kd = dr.apply_matrix(K.copy())
    F[dr.dofs] = 0.0
    u = spla.spsolve(Kd.tocsc(), F).reshape(N, 2)
    # exact radial displacement at the nodes
    r = np.hypot(*pts.T)
    ur = _lame(p, E, nu, RI, RO)(r)
    u_ex = ur[:, None] * pts / r[:, None]
    err_max = np.abs(u - u_ex).max() / np.abs(u_ex).max()
    # L2 relative error by quadrature
    xq, w = _qp(m)
    uq = np.einsum("qa,mad->mqd", DUNAVANT5_BARY, u[tri])
    rq = np.hypot(xq[..., 0], xq[..., 1])
    uexq = _lame(p, E, nu, RI, RO)(rq)[..., None] * xq / rq[..., None]
    err_l2 = math.sqrt(np.sum(w * ((uq - uexq) ** 2).sum(axis=2)) / np.sum(w * (uexq**2).sum(axis=2)))
    return m.h_mean, err_max, err_l2, u


def test_thick_cylinder_lame():
    res = [_solve_cylinder(h) for h in HS + (0.5,)]
    hm, emax, el2, _ = map(list, zip(*res))
    assert emax[0] > emax[1] > emax[2] > emax[3]
    assert el2[0] > el2[1] > el2[2] > el2[3]
    assert np.all(_orders(hm, el2) > 1.7), (el2, _orders(hm, el2))
    # c (h/a)^2 with c ~ 0.4 (see module docstring): < 2 % at h = 1, < 1 % at h = 0.5
    assert emax[2] < 0.025 and el2[2] < 0.02, (emax, el2)
    assert emax[3] < 0.01 and el2[3] < 0.01, (emax, el2)


def _h_eff(h, h_inner):
    """Energy-weighted mean mesh size of the graded annulus: sqrt(∫ size² r⁻⁵ dr / ∫ r⁻⁵ dr), mm."""
    r = np.geomspace(RI, RO, 20001)
    w = r**-5.0
    size = annulus_size(r, h, h_inner, RI, GRADING_LENGTH)

    def trap(f):  # trapezoidal rule (np.trapezoid needs numpy >= 2)
        return float(np.sum(0.5 * (f[1:] + f[:-1]) * np.diff(r)))

    return math.sqrt(trap(size**2 * w) / trap(w))


def test_thick_cylinder_lame_graded_mesh():
    """Issue target: displacement error < 1 % at h = 1 with a mesh graded towards the hole.

    Tolerance: the error model c (h_eff/a)² of the module docstring.  h_inner = 0.5
    (h_eff = 0.66 mm, (h_eff/a)² = 1.75 %): L2 <= 0.42 · 1.75 % = 0.73 % with the largest
    c measured (0.67 % measured), max nodal 0.77 % measured (c = 0.44: with this choice the
    size is exactly 0.1 r in the transition zone, every ring up to r = 10 has 63 nodes and
    the mesh there has no defects; the largest c_max measured elsewhere, 0.72, would give
    1.26 %).  h_inner = 0.25 (h_eff = 0.52, (h_eff/a)² = 1.06 %) meets 1 % even with the
    largest c of either error (<= 0.45 % L2, <= 0.76 % max; measured 0.36 %, 0.62 %): the
    choice with margin for the 1 % claim.
    """
    his = (None, 0.5, 0.25, 0.125)
    res = [_solve_cylinder(1.0, hi) for hi in his]
    emax = np.array([r[1] for r in res])
    el2 = np.array([r[2] for r in res])
    assert emax[1] < 0.01 and el2[1] < 0.01, (emax, el2)
    assert emax[2] < 0.01 and el2[2] < 0.01, (emax, el2)
    # convergence in h_inner (None = uniform h = 1)
    assert np.all(np.diff(emax) < 0) and np.all(np.diff(el2) < 0), (emax, el2)
    # the error model: c_L2 = L2 error / (h_eff/a)² within the measured band, uniform and graded,
    # h = 1 and h = 2
    for h, hi in [(1.0, hi) for hi in his] + [(2.0, None), (2.0, 1.0)]:
        el2_h = _solve_cylinder(h, hi)[2]
        c = el2_h / (_h_eff(h, hi) / RI) ** 2
        assert 0.3 < c < 0.45, (h, hi, el2_h, c)


def test_thick_cylinder_is_axisymmetric_and_reacts_the_load():
    hm, _, _, u = _solve_cylinder(1.0)
    m = annulus_mesh(RI, RO, h=1.0)
    inner = m.boundary_nodes("inner")
    x = m.points[inner]
    r = np.hypot(*x.T)
    ur = (u[inner] * x).sum(axis=1) / r
    ut = (u[inner, 1] * x[:, 0] - u[inner, 0] * x[:, 1]) / r
    assert np.all(ur > 0)  # pressure pushes the inner wall outwards
    assert np.abs(ut).max() < 1e-2 * ur.mean()  # no spurious rotation
    assert ur.std() < 1e-2 * ur.mean()  # axisymmetric to 1 %
    # net force of the uniform pressure on a closed polygon vanishes
    L, n = fem.outward_normals(np.asarray(m.points), m.inner_edges, np.asarray(m.triangles))
    assert np.abs((L[:, None] * n).sum(axis=0)).max() < 1e-10
    assert L.sum() == pytest.approx(2 * math.pi * RI, rel=1e-2)


def test_edge_mass_and_load_integrate_the_boundary():
    """∫_Γ N_a N_b summed over a, b is the boundary length; ∫_Γ g N_a sums to g times it (polygon of the circle)."""
    from solver.mesh import annulus_mesh

    m = annulus_mesh(h=2.0)
    N = len(m.points)
    L = m.edge_lengths("inner").sum()
    assert abs(fem.edge_mass(m.points, m.inner_edges, N).sum() - L) < 1e-12 * L
    assert abs(fem.edge_load(m.points, m.inner_edges, N, 3.0).sum() - 3.0 * L) < 1e-12 * L
    assert abs(L - 2 * np.pi * 5.0) < 0.01 * 2 * np.pi * 5.0  # inscribed polygon, h = 2 on r = 5
