"""Independent checks for the synthesis tests, and tests of the checks themselves.

The synthesis tests must not check a result with the code that produced it.
These helpers are written from the textbook definitions with numpy, scipy,
cvxpy and python-control only (no polyrob code):

* :func:`closed_loop` - ``Fl(P, K)`` by python-control's ``StateSpace.lft``;
* :func:`hamiltonian_below` - the Hamiltonian test ``‖G‖∞ < γ``
  (Boyd, Balakrishnan & Kabamba 1989);
* :func:`dense_peak` - ``max σ̄(G(jω))`` on a dense grid (a lower bound);
* :func:`dscaled_mu` - ``min_D σ̄(D M D⁻¹)`` over complex full blocks: equal
  to μ for at most three blocks (Doyle 1982), and convex in ``log d``;
* :func:`dg_mixed_upper` - the D-G upper bound of mixed μ by an LMI
  bisection (Fan, Tits & Doyle 1991), solved by cvxpy;
* :func:`stable_under` - eigenvalues of the loop closed with a constant
  ``Δ`` on the uncertainty channels and ``K`` on the control channels.
"""

from __future__ import annotations

import warnings

import control
import numpy as np
import pytest
import scipy.linalg as sla
from scipy.optimize import minimize


def _lti(K):
    if isinstance(K, control.LTI):
        return control.ss(K)
    Dk = np.atleast_2d(np.asarray(K, float))
    return control.ss(np.zeros((0, 0)), np.zeros((0, Dk.shape[1])), np.zeros((Dk.shape[0], 0)), Dk)


def closed_loop(P: control.StateSpace, K, n_u: int, n_y: int) -> control.StateSpace:
    """``Fl(P, K)`` with ``u = K y`` (python-control's LFT, Skogestad's convention)."""
    return P.lft(_lti(K), nu=n_u, ny=n_y)


def response(sys, w) -> np.ndarray:
    """``sys(jω)`` as ``(n, p, m)``."""
    H = np.asarray(sys(1j * np.asarray(w, float), squeeze=False))
    return np.moveaxis(H.reshape(sys.noutputs, sys.ninputs, -1), -1, 0)


def dense_peak(sys, w=None) -> float:
    """Largest singular value on a dense log grid (a lower bound of ``‖G‖∞``)."""
    w = np.logspace(-5, 5, 20001) if w is None else w
    return float(np.max(np.linalg.norm(response(sys, w), 2, axis=(1, 2))))


def hamiltonian_below(sys, gamma: float) -> bool:
    """``‖G‖∞ < γ`` for a stable ``G``: ``σ̄(D) < γ`` and no imaginary eigenvalue of ``H_γ``."""
    A, B, C, D = (np.asarray(X, float) for X in (sys.A, sys.B, sys.C, sys.D))
    if A.size and np.max(np.linalg.eigvals(A).real) >= 0:
        return False
    if np.linalg.norm(D, 2) >= gamma:
        return False
    R = gamma**2 * np.eye(D.shape[1]) - D.T @ D
    S = gamma**2 * np.eye(D.shape[0]) - D @ D.T
    Ri = np.linalg.inv(R)
    H = np.block(
        [[A + B @ Ri @ D.T @ C, B @ Ri @ B.T], [-C.T @ (gamma**2 * np.linalg.inv(S)) @ C, -(A + B @ Ri @ D.T @ C).T]]
    )
    lam = sla.eigvals(H)
    return bool(np.all(np.abs(lam.real) > 1e-8 * np.maximum(1.0, np.abs(lam))))


def dscaled_mu(M: np.ndarray, sizes, x0=None) -> tuple[float, np.ndarray]:
    """``min_d σ̄(D M D⁻¹)``, ``D = diag(d_i I_{n_i})`` (last block ``d = 1``), and the optimal ``log d``."""
    sizes = list(sizes)
    idx = np.repeat(np.arange(len(sizes)), sizes)

    def f(x):
        ld = np.append(x, 0.0)[idx]
        return np.log(np.linalg.norm(np.exp(ld)[:, None] * M / np.exp(ld)[None, :], 2))

    x0 = np.zeros(len(sizes) - 1) if x0 is None else x0
    best = minimize(f, x0, method="Nelder-Mead", options={"xatol": 1e-9, "fatol": 1e-12, "maxiter": 4000})
    return float(np.exp(best.fun)), best.x


def dg_mixed_upper(M: np.ndarray, n_real: int, tol: float = 1e-4) -> float:
    """Mixed-μ D-G upper bound for ``n_real`` real scalars then one complex full block (LMI bisection).

    ``M`` maps the block outputs to the block inputs (``N = Fl(P, K)``): rows
    ``n_real + p``, columns ``n_real + q`` for a ``q x p`` full block.
    """
    import cvxpy as cp

    # a non-square full block: pad with zero rows/columns (μ unchanged)
    n = max(M.shape)
    Mp = np.zeros((n, n), complex)
    Mp[: M.shape[0], : M.shape[1]] = M
    # a diagonal similarity commuting with Δ (block-wise Osborne balancing) leaves μ
    # unchanged and brings the optimal D near 1: the scalings of robot loops span 1e-8
    blk = np.r_[np.arange(n_real), np.full(n - n_real, n_real)]
    s = np.ones(n_real + 1)
    for _ in range(50):
        for b in range(n_real + 1):
            m = blk == b
            sv = s[blk]
            row = np.linalg.norm((sv[:, None] * Mp / sv[None, :])[m])
            col = np.linalg.norm((sv[:, None] * Mp / sv[None, :])[:, m])
            if row > 0 and col > 0:
                s[b] *= np.sqrt(col / row)
    s = s / s[-1]
    M = s[blk][:, None] * Mp / s[blk][None, :]
    nf = n - n_real
    d = cp.Variable(n_real + 1)
    g = cp.Variable(n_real)
    Dm = cp.diag(cp.hstack([d[:n_real], d[n_real] * np.ones(nf)]))
    Gm = cp.diag(cp.hstack([g, np.zeros(nf)]))
    b2 = cp.Parameter(nonneg=True)
    # M^H D M + j (G M - M^H G) - β² D ⪯ 0 as a real symmetric LMI
    Mr, Mi = M.real, M.imag
    ReL = Mr.T @ Dm @ Mr + Mi.T @ Dm @ Mi - (Gm @ Mi + Mi.T @ Gm) - b2 * Dm
    ImL = Mr.T @ Dm @ Mi - Mi.T @ Dm @ Mr + (Gm @ Mr - Mr.T @ Gm)
    big = cp.bmat([[ReL, -ImL], [ImL, ReL]])
    prob = cp.Problem(cp.Minimize(0), [(big + big.T) / 2 << 0, d >= 1e-6, d[n_real] == 1.0])
    lo, hi = 0.0, float(np.linalg.norm(M, 2)) * 1.0001
    while hi - lo > tol * hi:
        mid = 0.5 * (lo + hi)
        b2.value = mid**2
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # "optimal_inaccurate" counts as infeasible below
                prob.solve(solver="CLARABEL")
            ok = prob.status == "optimal"
        except cp.error.SolverError:
            ok = False  # counted as infeasible: the bound can only grow
        if ok:
            hi = mid
        else:
            lo = mid
    return hi


def stable_under(P: control.StateSpace, K, delta: np.ndarray, n_u: int, n_y: int) -> bool:
    """Is the loop with ``w_Δ = Δ z_Δ`` (first channels) and ``u = K y`` (last channels) stable?"""
    return loop_stable(closed_loop(P, K, n_u, n_y), delta)


def loop_stable(N: control.StateSpace, delta: np.ndarray) -> bool:
    """Is ``N`` closed with the constant ``w_Δ = Δ z_Δ`` on its first channels stable?"""
    A, B, C, D = (np.asarray(X, float) for X in (N.A, N.B, N.C, N.D))
    delta = np.asarray(delta, float)
    nd_in, nd_out = delta.shape  # w_Δ (nd_in) = Δ z_Δ (nd_out)
    # w_Δ = Δ (C_1 x + D_11 w_Δ)  =>  w_Δ = (I - Δ D_11)^{-1} Δ C_1 x
    gain = np.linalg.solve(np.eye(nd_in) - delta @ D[:nd_out, :nd_in], delta @ C[:nd_out])
    Acl = A + B[:, :nd_in] @ gain
    return bool(np.max(np.linalg.eigvals(Acl).real) < 0)


# ------------------------------------------------------------------ the checks' own tests


def test_hamiltonian_and_dense_peak_on_a_resonance():
    z, w0 = 0.01, 2.0
    G = control.ss(control.tf([w0**2], [1, 2 * z * w0, w0**2]))
    peak = 1 / (2 * z * np.sqrt(1 - z * z))
    assert hamiltonian_below(G, peak * (1 + 1e-6)) and not hamiltonian_below(G, peak * (1 - 1e-6))
    assert dense_peak(G) == pytest.approx(peak, rel=1e-3)
    assert not hamiltonian_below(control.ss(control.tf([1], [1, -1])), 10.0)  # unstable


def test_dscaled_mu_is_mu_for_two_blocks():
    # for a rank-one M = a b^H, μ = Σ |a_i| |b_i| over scalar blocks
    rng = np.random.default_rng(0)
    a = rng.standard_normal(2) + 1j * rng.standard_normal(2)
    b = rng.standard_normal(2) + 1j * rng.standard_normal(2)
    mu, _ = dscaled_mu(np.outer(a, b.conj()), [1, 1])
    assert mu == pytest.approx(np.sum(np.abs(a) * np.abs(b)), rel=1e-6)


def test_dg_bound_of_block_diagonal_matrices():
    # block-diagonal M: μ is the largest per-block μ; a real scalar sees only a real gain
    assert dg_mixed_upper(np.diag([0.7, 0.2]).astype(complex), 1) == pytest.approx(0.7, rel=1e-3)
    assert dg_mixed_upper(np.diag([0.7j, 0.2]), 1) == pytest.approx(0.2, rel=1e-2)


def test_stable_under_detects_a_destabilising_gain():
    # x' = -x + δ x: stable for δ < 1
    P = control.ss([[-1.0]], [[1.0, 0.0]], [[1.0], [0.0]], np.zeros((2, 2)))
    assert stable_under(P, np.zeros((1, 1)), np.array([[0.9]]), 1, 1)
    assert not stable_under(P, np.zeros((1, 1)), np.array([[1.1]]), 1, 1)
