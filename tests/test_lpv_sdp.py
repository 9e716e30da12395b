"""The structured interior-point solver of the bounded-real LMIs (polyrob.analysis.lpv.sdp).

Its operators are checked against brute force (the adjoint identity, the
Schur complement column by column, the LMI matrices against the re-check's
own ``brl_matrices``), and its answers against Clarabel's and the published
LPVTools figures.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

import polyrob
from polyrob.analysis.lpv.check import brl_matrices, grid_data
from polyrob.analysis.lpv.sdp.family import BoundedRealFamily, smat, svec, symmetric_basis
from polyrob.analysis.lpv.sdp.interior import solve
from polyrob.errors import ArgumentError

sys.path.insert(0, str(Path(__file__).parent))
from test_lpvnorm import BASIS4, GRID, lpvtools_demo_loop  # noqa: E402


def _random_data(seed=1, N=3, n=3, m=2, q=2, k=2):
    rng = np.random.default_rng(seed)
    A, B = rng.normal(size=(N, n, n)), rng.normal(size=(N, n, m))
    C, D = rng.normal(size=(N, q, n)), rng.normal(size=(N, q, m))
    F, G = rng.normal(size=(N, k)), rng.normal(size=(N, k, 1))
    return grid_data(list(A), list(B), list(C), list(D), F=F, G=G, nus=np.array([[-1.0], [2.0]]))


@pytest.mark.parametrize("level", [None, 0.7])
def test_forward_is_the_adjoint_of_adjoint(level):
    fam = BoundedRealFamily(_random_data(), level=level)
    rng = np.random.default_rng(2)
    S = [(lambda M: M + np.transpose(M, (0, 2, 1)))(rng.normal(size=c.shape)) for c in fam.C]
    y = rng.normal(size=fam.n_variables)
    lhs = sum(float(np.sum(a * s)) for a, s in zip(fam.adjoint(y), S))
    assert lhs == pytest.approx(float(y @ fam.forward(S)), rel=1e-12)


@pytest.mark.parametrize("level", [None, 0.7])
def test_schur_complement_equals_its_definition(level):
    fam = BoundedRealFamily(_random_data(), level=level)
    rng = np.random.default_rng(3)
    W = []
    for c in fam.C:
        R = rng.normal(size=c.shape)
        W.append(R @ np.transpose(R, (0, 2, 1)) + np.eye(c.shape[1]))
    H = fam.schur(W)
    brute = np.array([fam.forward([w @ a @ w for w, a in zip(W, fam.adjoint(e))]) for e in np.eye(fam.n_variables)])
    assert np.allclose(H, brute, rtol=1e-11, atol=1e-11 * np.abs(brute).max())
    assert np.allclose(H, H.T, atol=1e-11 * np.abs(H).max())


@pytest.mark.parametrize("level", [None, 0.7])
def test_the_blocks_are_the_bounded_real_matrices_of_the_recheck(level):
    data = _random_data()
    fam = BoundedRealFamily(data, level=level, eps=1e-7, x_bounds=(1e-6, 1e6))
    y = np.random.default_rng(4).normal(size=fam.n_variables)
    Z = [c - a for c, a in zip(fam.C, fam.adjoint(y))]
    M = brl_matrices(data, fam.matrices(y), y[0] if level is None else level)[0]
    M = M.reshape(-1, *M.shape[2:])
    if level is not None:
        M = M + y[0] * np.eye(M.shape[1])  # the margin t
    assert np.allclose(Z[0], -1e-7 * np.eye(M.shape[1]) - M, atol=1e-12)
    X = np.einsum("aj,jbc->abc", data.F, fam.matrices(y))
    assert np.allclose(Z[1], X - 1e-6 * np.eye(3)) and np.allclose(Z[2], 1e6 * np.eye(3) - X)


def test_svec_and_smat_are_inverse_isometries():
    b = symmetric_basis(4)
    rng = np.random.default_rng(5)
    S = rng.normal(size=(4, 4))
    S = S + S.T
    v = svec(S, b)
    assert np.allclose(smat(v, b, 4), S)
    assert float(v @ v) == pytest.approx(float(np.sum(S * S)))


def test_first_order_lag_has_gain_one():
    data = grid_data([np.array([[-1.0]])], [np.array([[1.0]])], [np.array([[1.0]])], [np.array([[0.0]])])
    res = solve(BoundedRealFamily(data, eps=0.0))
    assert res.status == "solved" and -res.dual_objective == pytest.approx(1.0, abs=1e-6)
    assert res.dual_residual < 1e-12


@pytest.mark.parametrize(
    "args, published",
    [((), 20.1476), (([(-0.1, 0.1)], BASIS4), 1.2968)],
    ids=["constant X", "rate-bounded basis4"],
)
def test_lpvtools_demo_with_the_structured_solver(args, published):
    """LPVTools V1.00 'Worst-Case Gain Analysis of LPV System': the same proved bounds as Clarabel's."""
    mine = polyrob.lpvnorm(lpvtools_demo_loop(), GRID, *args, solver="structured")
    clarabel = polyrob.lpvnorm(lpvtools_demo_loop(), GRID, *args)
    assert mine.proved and mine.gamma == pytest.approx(published, rel=0.02)
    assert mine.gamma == pytest.approx(clarabel.gamma, rel=1e-5)


def test_a_fixed_level_maximises_the_margin():
    system = lpvtools_demo_loop()
    r = polyrob.lpvnorm(system, GRID, [(-0.1, 0.1)], BASIS4, solver="structured", level=1.5)
    assert r.proved and 1.2968 * 0.98 <= r.gamma <= 1.5


def test_an_unstable_loop_is_not_proved():
    def system(rho):
        return np.array([[0.1 * rho[0]]]), np.array([[1.0]]), np.array([[1.0]]), np.array([[0.0]])

    r = polyrob.lpvnorm(system, [np.linspace(1.0, 2.0, 3)], solver="structured")
    assert not r.proved and not np.isfinite(r.gamma)


def test_options_it_does_not_take_are_refused():
    with pytest.raises(ArgumentError, match="structured"):
        polyrob.lpvnorm(lpvtools_demo_loop(), GRID, solver="structured", x_factor=np.eye(4))


def test_a_step_that_overflows_ends_with_the_last_finite_iterate(monkeypatch):
    """A scaling that overflows (a block near singular) stops the solve; the y returned is the last finite one."""
    import polyrob.analysis.lpv.sdp.interior as interior

    data = grid_data([np.array([[-1.0]])], [np.array([[1.0]])], [np.array([[1.0]])], [np.array([[0.0]])])
    calls = {"n": 0}
    real = interior._nt_scaling

    def overflowing(X, Z):
        calls["n"] += 1
        G, Ginv, lam = real(X, Z)
        return (G * 1e300, Ginv, lam) if calls["n"] > 9 else (G, Ginv, lam)  # from the fourth iteration on

    monkeypatch.setattr(interior, "_nt_scaling", overflowing)
    res = solve(BoundedRealFamily(data, eps=0.0))
    assert res.status == "numerical_error" and np.all(np.isfinite(res.y)) and res.iterations == 4
    assert res.dual_residual < 1e-9  # the last iterate is still inside the dual cones
