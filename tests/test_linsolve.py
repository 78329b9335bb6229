"""The sparse-solve interface (solver/linsolve.py) on the real coupled Jacobian.

Every backend must solve the Newton system to round-off: relative residual
below 1e-10 (the solve checks it and refines), and both backends must agree.
PARDISO is an optional extra: its tests are skipped where it is not installed.
"""
import numpy as np
import pytest
import scipy.sparse as sp

from solver import Parameters, linsolve, paths
from solver.mesh import annulus_mesh
from solver.model import build_discretization, project_gradient, residual_and_jacobian, step_data
from solver.porosity import random_porosity


def _jacobian(h=4.0, scale=1.0):
    p = Parameters()
    mesh = annulus_mesh(p.r_inner, p.r_outer, h)
    disc = build_discretization(mesh, p, random_porosity(mesh, seed=0))
    N, nf = disc.n_nodes, disc.n_fields
    rng = np.random.default_rng(0)
    r = np.hypot(*disc.points.T)
    U = np.zeros((N, nf))
    U[:, 0:2] = 1e-3 * scale * rng.standard_normal((N, 2))
    U[:, 2] = 200 * scale * (p.r_outer - r) / (p.r_outer - p.r_inner)
    U[:, 3] = np.clip(1.5 - (r - p.r_inner) / 10, 0, 1)
    U[:, 5:7] = project_gradient(disc, U[:, 3])  # G = Π∇S: the Korteweg force couples G to p and S
    data = step_data(disc, p, 0.99 * U, np.zeros(N), 1e-2)
    R, J = residual_and_jacobian(disc, p, U, data)
    disc.dirichlet.apply_matrix(J)
    return sp.csr_matrix(J), R


def _rel_res(A, x, b):
    return np.linalg.norm(A @ x - b) / np.linalg.norm(b)


def test_superlu_solves_the_coupled_jacobian_to_round_off():
    J, R = _jacobian()
    x = linsolve.factorize(J, "superlu").solve(-R)
    assert _rel_res(J, x, -R) < 1e-10


def test_auto_keeps_superlu_for_small_systems_and_rejects_unknown_backends():
    assert paths.resolve("auto", paths.PARDISO_MIN_SIZE - 1) == "superlu"
    with pytest.raises(ValueError, match="linear_solver='mumps'"):
        paths.resolve("mumps")


def test_pardiso_matches_superlu_reuses_its_analysis_and_refactorizes_stale_factors():
    pytest.importorskip("pypardiso")
    J1, R1 = _jacobian()
    J2, R2 = _jacobian(scale=1.5)  # same pattern, other values: PARDISO's numerical phase only
    assert np.array_equal(J1.indices, J2.indices) and not np.allclose(J1.data, J2.data)
    x_ref1 = linsolve.factorize(J1, "superlu").solve(-R1)
    x_ref2 = linsolve.factorize(J2, "superlu").solve(-R2)
    f1 = linsolve.factorize(J1, "pypardiso")
    x1 = f1.solve(-R1)
    assert _rel_res(J1, x1, -R1) < 1e-10
    assert np.linalg.norm(x1 - x_ref1) <= 1e-8 * np.linalg.norm(x_ref1)
    n0 = linsolve.STATS["factorizations"]
    f2 = linsolve.factorize(J2, "pypardiso")  # takes over the process-wide PARDISO instance
    x2 = f2.solve(-R2)
    assert _rel_res(J2, x2, -R2) < 1e-10
    assert np.linalg.norm(x2 - x_ref2) <= 1e-8 * np.linalg.norm(x_ref2)
    # f1's factors were replaced: solving with it must factorize J1 again, not use J2's factors
    x1b = f1.solve(-R1)
    assert _rel_res(J1, x1b, -R1) < 1e-10
    assert linsolve.STATS["factorizations"] == n0 + 2


def test_backend_discovery_does_not_import_pypardiso():
    """Listing backends must not load MKL (pypardiso's import searches the file system for it)."""
    import subprocess
    import sys

    code = ("import sys; from solver import paths; b = paths.available_backends(); "
            "assert 'pypardiso' not in sys.modules, 'imported'; print(b)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "superlu" in out.stdout


@pytest.mark.skipif("pypardiso" not in paths.available_backends(), reason="pypardiso not installed")
def test_mkl_runtime_is_located_for_pypardiso(monkeypatch):
    """The MKL runtime is handed to pypardiso (PYPARDISO_MKL_RT) so it skips its recursive search."""
    import os

    monkeypatch.delenv("PYPARDISO_MKL_RT", raising=False)
    linsolve._locate_mkl_rt()
    path = os.environ.get("PYPARDISO_MKL_RT")
    if path is not None:  # a layout other than the pip wheel's falls back to pypardiso's own search
        assert os.path.isfile(path) and "mkl_rt" in os.path.basename(path)


@pytest.mark.parametrize("kind", ["superlu", "pypardiso"])
def test_factors_are_checked_on_their_first_solve_and_trusted_after_a_good_one(kind):
    if kind == "pypardiso":
        pytest.importorskip("pypardiso")
    J, R = _jacobian()
    f = linsolve.factorize(J, kind)
    assert not f.trusted
    x = f.solve(-R)
    assert f.trusted and _rel_res(J, x, -R) < 1e-10
    b = np.random.default_rng(2).standard_normal(len(R))  # another right-hand side, not checked: still to round-off
    assert _rel_res(J, f.solve(b), b) < 1e-10


def test_pardiso_factors_whose_first_solve_needs_refinement_stay_checked(monkeypatch):
    pytest.importorskip("pypardiso")
    J, R = _jacobian()
    f = linsolve.factorize(J, "pypardiso")
    exact = f._substitute
    monkeypatch.setattr(f, "_substitute", lambda s, b: exact(s, b) * (1.0 + 1e-6))  # a poor substitution
    before = linsolve.STATS.get("refinements", 0)
    x = f.solve(-R)
    assert not f.trusted and _rel_res(J, x, -R) < 1e-10  # refined to round-off
    f.solve(-R)
    assert linsolve.STATS.get("refinements", 0) - before >= 2  # the second solve was checked and refined too


# ---------------------------------------------------------------- single-precision factors (inexact Newton)
def _kinds():
    return ["superlu"] + (["pypardiso"] if "pypardiso" in paths.available_backends() else [])


@pytest.mark.parametrize("kind", _kinds())
def test_single_precision_factors_meet_the_forcing_tolerance_on_the_coupled_jacobian(kind):
    """Factors in float32 solve the Newton system to the inexact-Newton forcing tolerance (relative residual
    <= SINGLE_FORCING) in double output, and the solution differs from the double one by at most what that
    residual allows (||dx|| <= ||A^-1|| ||r||, bounded here by the double solution's own scale)."""
    J, R = _jacobian()
    x64 = linsolve.factorize(J, kind, precision="double").solve(-R)
    f = linsolve.factorize(J, kind, precision="single")
    assert f.single
    x32 = f.solve(-R)
    assert x32.dtype == np.float64
    assert _rel_res(J, x32, -R) <= linsolve.SINGLE_FORCING
    assert f.single  # met by the single factors (refined or not), with no fallback to double
    assert np.linalg.norm(x32 - x64) <= 1e-2 * np.linalg.norm(x64)
    assert np.linalg.norm(x32 - x64) > 0.0  # the factors really are single precision
    b = np.random.default_rng(2).standard_normal(len(R))  # another right-hand side meets it too
    assert _rel_res(J, f.solve(b), b) <= linsolve.SINGLE_FORCING


def test_single_precision_falls_back_to_double_when_refinement_cannot_reach_the_forcing_tolerance(monkeypatch):
    """Single factors whose substitutions are off by a factor 3 (an unstable factorization: refinement with
    them diverges) are replaced by double factors after the three refinement steps, and the solve is then
    exact to round-off."""
    J, R = _jacobian()
    f = linsolve.factorize(J, "superlu", precision="single")
    exact = f._substitute
    monkeypatch.setattr(f, "_substitute", lambda b: exact(b) * (3.0 if f.single else 1.0))
    n_fact, n_fall = linsolve.STATS["factorizations"], linsolve.STATS.get("precision_fallbacks", 0)
    n_ref = linsolve.STATS.get("refinements", 0)
    x = f.solve(-R)
    assert not f.single
    assert linsolve.STATS.get("refinements", 0) == n_ref + 3
    assert linsolve.STATS["factorizations"] == n_fact + 1
    assert linsolve.STATS.get("precision_fallbacks", 0) == n_fall + 1
    assert _rel_res(J, x, -R) < 1e-10


def test_precision_choice_is_validated_and_defaults_to_single_with_pardiso_only():
    assert paths.resolve_precision(None, "pypardiso") == "single"
    assert paths.resolve_precision(None, "superlu") == "double"
    assert paths.resolve_precision("double", "pypardiso") == "double"
    with pytest.raises(ValueError, match="linear_precision='half'"):
        paths.resolve_precision("half", "superlu")


def test_a_run_with_single_precision_factors_is_the_double_run_to_the_newton_tolerance():
    """The inexact Newton iteration converges to the same tests (update below newton_rtol = 1e-6, volume balance
    to newton_mass_tol): the same accepted steps, p_inj within 10x the Newton tolerance, and the cumulative
    volume balance to 1e-9 of the injected volume (SuperLU forced to float32 factors, h = 4 mm, to 0.05 s)."""
    from solver import RunOptions, simulate

    runs = {prec: simulate(Parameters(), RunOptions(h=4.0, t_end=0.05, snapshot_times=[], write_xdmf=False,
                                                    linear_solver="superlu", linear_precision=prec))
            for prec in ("double", "single")}
    a, b = (runs[k].timeseries for k in ("double", "single"))
    assert runs["single"].status == runs["double"].status == "ok"
    # the step controller is a continuous function of the accepted states: the same steps to their accuracy
    assert len(a) == len(b) and np.allclose(a["t"], b["t"], rtol=1e-5, atol=0.0)
    assert np.max(np.abs(b["p_inj"] - a["p_inj"]) / np.abs(a["p_inj"])) <= 1e-5
    assert np.max(np.abs(b["mass_error"])) <= 1e-9


def test_condensing_the_projected_gradient_solves_the_full_system_to_round_off():
    """Static condensation of G = Π∇S (diagonal block) is exact algebra: the condensed SuperLU solve meets the
    full system's residual test and equals the uncondensed solve to round-off, in double and single factors."""
    p = Parameters()
    mesh = annulus_mesh(p.r_inner, p.r_outer, 4.0)
    disc = build_discretization(mesh, p, random_porosity(mesh, seed=0))
    g = disc.projection_dofs
    assert disc.n_fields == 7 and len(g) == 2 * disc.n_nodes
    J, R = _jacobian()
    Jg = J[g][:, g].tocoo()
    assert np.all(Jg.row == Jg.col) or np.all(Jg.data[Jg.row != Jg.col] == 0)  # the premise: a diagonal block
    assert abs(J[np.setdiff1d(np.arange(J.shape[0]), g)][:, g]).max() > 0  # and a real coupling to eliminate
    x_full = linsolve.factorize(J, "superlu").solve(-R)
    f = linsolve.factorize(J, "superlu", condense=g)
    assert f.cond.K.shape[0] == J.shape[0] - len(g)
    x = f.solve(-R)
    assert _rel_res(J, x, -R) < 1e-10
    assert np.linalg.norm(x - x_full) <= 1e-10 * np.linalg.norm(x_full)
    x32 = linsolve.factorize(J, "superlu", "single", condense=g).solve(-R)
    assert _rel_res(J, x32, -R) <= linsolve.SINGLE_FORCING


def test_condensation_refuses_a_block_that_is_not_diagonal():
    J, R = _jacobian()
    not_diagonal = np.arange(0, 14)  # both displacements and p, S, μ of the first nodes: a coupled block
    with pytest.raises(ValueError, match="must be diagonal"):
        linsolve.factorize(J, "superlu", condense=not_diagonal)
