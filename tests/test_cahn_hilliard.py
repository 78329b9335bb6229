"""Verification of the Cahn–Hilliard pair of the model (solver/model.py) on a planar interface.

Continuum: μ = 12γ/l_S (f'(S) − l_S²/8 S''), f = S²(1 − S)².  Two coexisting bulk
phases S = 0 and S = 1 have μ = 0 (f'(0) = f'(1) = 0); multiplying
f'(S) = l_S²/8 S'' by S' and integrating gives S' = (4/l_S) S(1 − S), i.e. the
planar equilibrium profile

    S(x) = ½ (1 + tanh(2x / l_S)),

and, since then f(S) = (l_S²/16) S'², the interface energy per unit length is

    ∫ 12γ/l_S (f + l_S²/16 S'²) dx = (12γ/l_S)(l_S/2) ∫0^1 S(1 − S) dS = γ.

Discretization: the μ-equation rows are P1 with f'(S) integrated by the
3-point Strang rule (degree 2); the nodal error of the profile is O(h²)
(measured below: halving h divides it by ~4.5), so we assert
max |S_h − S| < 2 % at h = l_S/8 and an observed order > 1.7 between
h = l_S/4, l_S/8, l_S/16; the energy, evaluated exactly (degree-5 rule) on the
discrete profile, is within 2 % of γ at h = l_S/8 (O(h²) too).

The strip runs over x in [−3 l_S, 3 l_S]: the Dirichlet data S = 0, 1 at the
ends differ from the tanh profile by e^{−12} ≈ 6e-6, negligible.  One element
across (structured, all diagonals alike, so the mesh is invariant under the
half-turn (x, y) -> (−x, −y), which maps the problem onto itself with
S -> 1 − S: the interface stays centred).
"""
import dataclasses

import numpy as np
import pytest

from solver import Parameters, linsolve
from solver.mesh import Mesh, rectangle_mesh
from solver.model import MU, P, S, UX, UY, build_discretization, residual_and_jacobian, step_data

PAR = Parameters(korteweg_factor=0.0)  # 5 fields: ux, uy, p, S, mu
LS = PAR.l_S
HALF = 3 * LS

# Dunavant degree-5 rule (barycentric, weights summing to 1): exact for f(S) (degree 4 in x)
_a1, _b1 = 0.059715871789770, 0.470142064105115
_a2, _b2 = 0.797426985353087, 0.101286507323456
D5_BARY = np.array([[1 / 3, 1 / 3, 1 / 3], [_a1, _b1, _b1], [_b1, _a1, _b1], [_b1, _b1, _a1],
                    [_a2, _b2, _b2], [_b2, _a2, _b2], [_b2, _b2, _a2]])
D5_W = np.array([0.225, *[0.132394152788506] * 3, *[0.125939180544827] * 3])


def exact(x):
    return 0.5 * (1 + np.tanh(2 * x / LS))


def strip(h):
    nx = int(round(2 * HALF / h))
    m = rectangle_mesh(2 * HALF, h, nx, 1, x0=-HALF, y0=-h / 2, diagonal="right")
    edges = dict(m.boundary_edges)
    edges["inner"], edges["outer"] = edges["left"], edges["right"]
    return Mesh(m.points, m.triangles, edges)


def _ends(disc):
    x = disc.points[:, 0]
    return x < -HALF + 1e-9, x > HALF - 1e-9


def equilibrium_from_mu_rows(h):
    """Solve the model's μ-equation rows for S with μ = 0 (coexistence) and S = 0 / 1 at the ends."""
    mesh = strip(h)
    disc = build_discretization(mesh, PAR, np.full(len(mesh.triangles), 0.4))
    nf, N = disc.n_fields, disc.n_nodes
    x = disc.points[:, 0]
    left, right = _ends(disc)
    U = np.zeros((N, nf))
    U[:, S] = exact(0.7 * x)  # start from a too-wide profile
    U[left, S], U[right, S] = 0.0, 1.0
    free = np.flatnonzero(~(left | right))
    rows, cols = nf * free + MU, nf * free + S
    data = step_data(disc, PAR, U, np.zeros(N), 1.0)
    scale = 12 * PAR.gamma / LS * h * h  # μ-row residual scale (kPa·mm²)
    for _ in range(25):
        R, J = residual_and_jacobian(disc, PAR, U, data)
        r = R[rows]
        if np.abs(r).max() < 1e-12 * scale:
            break
        U[free, S] += linsolve.factorize(J[rows][:, cols], "superlu").solve(-r)
    else:
        raise AssertionError("Newton on the μ rows did not converge")
    return disc, U


def interface_energy(disc, Sn):
    """∫ 12γ/l_S (f(S) + l_S²/16 |∇S|²) dx per unit interface length (kPa·mm), exact for P1 S."""
    tri = disc.triangles
    Sq = np.einsum("qa,ma->mq", D5_BARY, Sn[tri])
    f = (Sq * (1 - Sq)) ** 2
    gS = np.einsum("ma,mai->mi", Sn[tri], disc.geom.grads)
    dens = (f * D5_W).sum(axis=1) + LS**2 / 16 * (gS**2).sum(axis=1)
    width = np.ptp(disc.points[:, 1])
    return 12 * PAR.gamma / LS * float(np.sum(disc.geom.areas * dens)) / width


@pytest.fixture(scope="module")
def profiles():
    return {k: equilibrium_from_mu_rows(LS / k) for k in (4, 8, 16)}


def test_planar_profile_is_discrete_equilibrium(profiles):
    errs = {}
    for k, (disc, U) in profiles.items():
        errs[k] = np.abs(U[:, S] - exact(disc.points[:, 0])).max()
    # measured: 3.5e-3, 7.9e-4, 1.7e-4 at h = l_S/4, /8, /16
    assert errs[8] < 0.02
    order = np.log2([errs[4] / errs[8], errs[8] / errs[16]])
    assert np.all(order > 1.7), (errs, order)
    assert errs[16] < 1e-3


def test_interface_energy_equals_surface_tension(profiles):
    err = {}
    for k in (4, 8, 16):
        disc, U = profiles[k]
        err[k] = interface_energy(disc, U[:, S]) / PAR.gamma - 1.0
    # measured: +0.79 %, +0.20 %, +0.05 % at h = l_S/4, /8, /16 (O(h²))
    assert abs(err[8]) < 0.02 and abs(err[16]) < 0.02, err
    e8, e16 = abs(err[8]), abs(err[16])
    assert e16 < e8


def test_time_stepping_the_coupled_pair_relaxes_to_the_tanh_profile():
    """The model's invading-fluid and μ rows together (u = 0, p = 0 fixed: pure Cahn–Hilliard,
    φ0 Ṡ = ∇·(M∇μ)), backward Euler from a too-steep profile with S = 0 / 1 at the ends and
    natural (no-flux, ∇S·n = 0) conditions elsewhere, reach the planar equilibrium: μ -> 0 and
    S -> tanh within the same 2 % as the static solve at h = l_S/8."""
    h = LS / 8
    mesh = strip(h)
    disc = build_discretization(mesh, PAR, np.full(len(mesh.triangles), 0.4))
    nf, N = disc.n_fields, disc.n_nodes
    x = disc.points[:, 0]
    left, right = _ends(disc)
    nodes = np.arange(N)
    dofs = np.concatenate([nf * nodes + UX, nf * nodes + UY, nf * nodes + P, nf * np.flatnonzero(left) + S,
                           nf * np.flatnonzero(right) + S])
    vals = np.concatenate([np.zeros(3 * N), np.zeros(left.sum()), np.ones(right.sum())])
    order = np.argsort(dofs)
    zero_op = disc.boundary_op * 0.0
    disc = dataclasses.replace(disc, dirichlet=disc.asm.dirichlet_rows(dofs[order]), dirichlet_values=vals[order],
                               inject=np.zeros(disc.asm.ndof), boundary_op=zero_op,
                               boundary_vals=np.zeros_like(disc.boundary_vals))
    U = np.zeros((N, nf))
    U[:, S] = exact(2.0 * x)
    U[left, S], U[right, S] = 0.0, 1.0
    # CH relaxation time of the interface ~ φ0 l_S² / (M 12γ/l_S) with M = k(φ0)/η̄
    dt, t = 1e-4, 0.0
    d = np.zeros(N)
    for _ in range(200):
        data = step_data(disc, PAR, U, d, dt)
        X = U.ravel().copy()
        for _ in range(20):
            R, J = residual_and_jacobian(disc, PAR, X.reshape(N, nf), data)
            disc.dirichlet.apply_residual(R, X, disc.dirichlet_values)
            disc.dirichlet.apply_matrix(J)
            dx = linsolve.factorize(J, "superlu").solve(-R)
            X += dx
            if np.abs(dx).max() < 1e-12:
                break
        else:
            raise AssertionError("Newton did not converge")
        change = np.abs(X.reshape(N, nf)[:, S] - U[:, S]).max()
        U = X.reshape(N, nf).copy()
        t += dt
        dt *= 1.3
        if change < 1e-10:
            break
    else:
        raise AssertionError("no steady state reached")
    err = np.abs(U[:, S] - exact(x)).max()
    assert err < 0.02, err
    # the same discrete equilibrium as the static solve (μ = 0 there), up to the solver tolerances
    disc8, U8 = equilibrium_from_mu_rows(h)
    assert np.abs(U[:, S] - U8[:, S]).max() < 1e-4
    # equilibrium chemical potential is uniform and ~0 (scale 12γ/l_S = 0.09 kPa)
    assert np.abs(U[:, MU]).max() < 1e-4 * 12 * PAR.gamma / LS
