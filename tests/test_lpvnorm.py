"""polyrob.lpvnorm: rate-bounded induced-L2 analysis of gridded LPV systems (issue 19, item 1).

The published figures reproduced here come from the LPVTools documentation
(Balas, Packard, Seiler, Hjartarson; MUSYN / University of Minnesota, LPVTools
V1.00, demo page "Worst-Case Gain Analysis of LPV System"): the first-order plant of Tan,
Hang & Chai (Automatica 33, 1997) with a 2nd-order Padé delay and a
gain-scheduled PI loop, posed as an LPV analysis problem by Pfifer & Seiler
(ACC 2014).  With the worst-case multiplicative uncertainty Delta = +0.1
inserted, the page prints ``lpvnorm`` of the nominal closed loop on the grid
rho = 2:7:

* constant X (arbitrarily fast rho):                        Gamma = 20.1476
* basis [1, rho, rho^2, 1/rho, sqrt(rho)], |drho/dt| <= 0.1:  Gamma = 1.2968
"""

from __future__ import annotations

import importlib
import json

import control
import numpy as np
import pytest

import polyrob
from polyrob.analysis.lpv import check_solution, proved_gamma
from polyrob.analysis.lpv.check import GridData
from polyrob.analysis.lpv.data import evaluate
from polyrob.errors import ArgumentError, SolverError

norm_module = importlib.import_module("polyrob.analysis.lpv.norm")


# --------------------------------------------------------------------------- the LPVTools demo system


def _pade_delay(Td=0.5):
    T = control.ss(control.tf([Td**2 / 12, -Td / 2, 1], [Td**2 / 12, Td / 2, 1]))
    return tuple(np.asarray(m, dtype=float) for m in (T.A, T.B, T.C, T.D))


def lpvtools_demo_loop(delta=0.1):
    """e = d - G Tdel (1 + delta) C e, states (x_G, x_Tdel (2), x_C); rho in [2, 7]."""
    At, Bt, Ct, Dt = _pade_delay()

    def system(rho):
        p = rho[0]
        tau, K = np.sqrt(133.6 - 16.8 * p), np.sqrt(4.8 * p - 8.6)
        zeta, wcl = 0.7, 0.25
        Kp, Ki = (2 * zeta * wcl * tau - 1) / K, wcl**2 * tau / K
        A, B = np.zeros((4, 4)), np.zeros((4, 1))
        ce, de = np.array([-K, 0.0, 0.0, 0.0]), 1.0  # e = d - K x_G
        cw = (1 + delta) * (np.array([0.0, 0.0, 0.0, 1.0]) + Kp * ce)  # w = (1 + delta)(x_C + Kp e)
        dw = (1 + delta) * Kp * de
        A[1:3] += Bt @ cw[None, :]
        A[1:3, 1:3] += At
        B[1:3, 0] += Bt[:, 0] * dw
        cv = np.zeros(4)
        cv[1:3] = Ct[0]
        cv += Dt[0, 0] * cw  # v = Tdel w
        A[0] += cv / tau
        A[0, 0] -= 1 / tau
        B[0, 0] += Dt[0, 0] * dw / tau
        A[3] += Ki * ce
        B[3, 0] += Ki * de
        return A, B, ce[None, :], np.array([[de]])

    return system


GRID = [np.arange(2.0, 8.0)]  # pgrid('p', 2:7)
BASIS4 = [
    (lambda r: 1.0, lambda r: [0.0]),
    (lambda r: r[0], lambda r: [1.0]),
    (lambda r: r[0] ** 2, lambda r: [2 * r[0]]),
    (lambda r: 1 / r[0], lambda r: [-1 / r[0] ** 2]),
    (lambda r: np.sqrt(r[0]), lambda r: [0.5 / np.sqrt(r[0])]),
]
BASIS2 = BASIS4[:3]


@pytest.fixture(scope="module")
def demo_fast():
    return polyrob.lpvnorm(lpvtools_demo_loop(), GRID)


@pytest.fixture(scope="module")
def demo_slow():
    return polyrob.lpvnorm(lpvtools_demo_loop(), GRID, [(-0.1, 0.1)], BASIS4)


# --------------------------------------------------------------------------- 1. published figures


def test_lpvtools_demo_constant_x(demo_fast):
    """LPVTools V1.00 doc, 'Worst-Case Gain Analysis of LPV System': lpvnorm(wc_CL) = 20.1476."""
    r = demo_fast
    assert r.proved and r.status == "PROVED"
    assert r.gamma == pytest.approx(20.1476, rel=0.02)
    assert r.variation.startswith("arbitrarily fast")
    assert r.coverage == "on the grid of 6 points"


def test_lpvtools_demo_rate_bounded_parameter_dependent_x(demo_slow):
    """Same page: lpvnorm(wc_CLrb, basis4) with |drho/dt| <= 0.1 = 1.2968 (Xb = [1, p, p^2, 1/p, sqrt(p)])."""
    r = demo_slow
    assert r.proved and r.n_basis == 5 and r.n_rate_vertices == 2
    assert r.gamma == pytest.approx(1.2968, rel=0.02)
    assert r.variation == "rate-bounded: drho_1/dt in [-0.1, 0.1]"
    # the proved number is never below the solver's optimum by more than the re-check's bisection step
    assert r.gamma >= r.gamma_solver * (1 - 1e-6)


def test_the_other_sign_of_delta_is_not_the_published_loop():
    """The page's wc_delta is the +0.1 end: -0.1 gives another number (17.3), so the match is no accident."""
    r = polyrob.lpvnorm(lpvtools_demo_loop(-0.1), GRID)
    assert abs(r.gamma / 20.1476 - 1) > 0.1


# --------------------------------------------------------------------------- 2. ordering


def test_frozen_le_rate_bounded_le_arbitrarily_fast_and_monotone(demo_fast):
    system = lpvtools_demo_loop()
    gammas = [polyrob.lpvnorm(system, GRID, [(-b, b)], BASIS2).gamma for b in (0.01, 0.1, 1.0, 10.0)]
    assert all(np.isfinite(gammas))
    frozen = demo_fast.frozen_gamma
    assert frozen == pytest.approx(1.2252, rel=1e-3)
    assert frozen <= gammas[0] * (1 + 1e-6)
    for a, b in zip(gammas, gammas[1:]):
        assert a <= b * (1 + 1e-3)  # non-decreasing (within the solver's accuracy)
    assert gammas[-1] <= demo_fast.gamma * (1 + 1e-3)
    assert gammas[0] < 0.2 * demo_fast.gamma  # the rate bound matters here


# --------------------------------------------------------------------------- 3. nothing unverified


def test_a_perturbed_x_is_not_verified(demo_fast):
    ev = evaluate(lpvtools_demo_loop(), GRID)
    X = np.array(demo_fast.X)
    assert check_solution(ev.data, X, demo_fast.gamma).holds
    assert not check_solution(ev.data, X, demo_fast.gamma * 0.999).holds  # below its own proved level
    assert not check_solution(ev.data, -X, demo_fast.gamma * 10).holds  # not positive definite
    bad = X - 1.01 * np.linalg.eigvalsh(X[0])[0] * np.eye(4)  # X just indefinite
    chk = check_solution(ev.data, bad, demo_fast.gamma * 10)
    assert not chk.holds and "positive definite" in chk.reason
    g, _ = proved_gamma(ev.data, bad, demo_fast.gamma)
    assert g == np.inf


def test_a_bad_solver_answer_is_not_reported(monkeypatch):
    system = lpvtools_demo_loop()

    def liar(data, **kwargs):  # claims gamma = 0.5 with an X that proves nothing
        n = data.A.shape[1]
        return np.array([np.eye(n) * 1e-3]), 0.5, "optimal"

    monkeypatch.setattr(norm_module, "solve_lmis", liar)
    r = polyrob.lpvnorm(system, GRID)
    assert not r.proved and r.gamma == np.inf and r.status == "NOT_PROVED"
    assert r.gamma_solver == 0.5 and r.X == ()
    assert "NOT proved" in str(r)
    s = json.loads(json.dumps(r.summary(), allow_nan=False))
    assert s["gamma"] is None and s["proved"] is False


def test_a_solver_answer_below_the_verified_level_is_raised(monkeypatch):
    """The solver's X with a too-optimistic gamma: the reported gamma is the verified one, above it."""
    real = norm_module.solve_lmis

    def optimist(data, **kwargs):
        Xs, g, st = real(data, **kwargs)
        return Xs, 0.9 * g, st

    monkeypatch.setattr(norm_module, "solve_lmis", optimist)
    r = polyrob.lpvnorm(lpvtools_demo_loop(), GRID)
    assert r.proved and r.gamma > r.gamma_solver / 0.9 * (1 - 1e-4)


def test_an_unstable_system_proves_nothing():
    sysf = lambda r: (np.array([[r[0]]]), np.ones((1, 1)), np.ones((1, 1)), np.zeros((1, 1)))  # noqa: E731
    r = polyrob.lpvnorm(sysf, [np.array([-1.0, 0.5])])
    assert not r.proved and r.gamma == np.inf and r.frozen_gamma == np.inf
    json.dumps(r.summary(), allow_nan=False)


# --------------------------------------------------------------------------- 4. conditioning


def _scaled(system, t):
    T = np.diag(t)
    Ti = np.diag(1 / np.asarray(t))

    def scaled(rho):
        A, B, C, D = system(rho)
        return Ti @ A @ T, Ti @ B, C @ T, D

    return scaled


def test_conditioning_does_not_change_the_answer(demo_slow):
    system = lpvtools_demo_loop()
    rb = [(-0.1, 0.1)]
    scaled = _scaled(system, [1e3, 1.0, 1e-2, 10.0])
    r_scaled = polyrob.lpvnorm(scaled, GRID, rb, BASIS4)
    assert r_scaled.gamma == pytest.approx(demo_slow.gamma, rel=1e-3)
    r_nobal = polyrob.lpvnorm(system, GRID, rb, BASIS4, balance=False)
    assert r_nobal.gamma == pytest.approx(demo_slow.gamma, rel=1e-3)
    # a well-conditioned basis: the orthonormalisation changes nothing
    r1 = polyrob.lpvnorm(system, GRID, rb, BASIS2[:2])
    r2 = polyrob.lpvnorm(system, GRID, rb, BASIS2[:2], orthonormalize=False)
    assert r1.gamma == pytest.approx(r2.gamma, rel=1e-3)
    # X comes back in the user's coordinates: X~ = T^T X T
    t = np.array([1e3, 1.0, 1e-2, 10.0])
    X0 = np.array(demo_slow.X[0])
    assert np.allclose(np.array(r_scaled.X[0]), X0 * t[:, None] * t[None, :], rtol=0.2, atol=1e-6 * np.abs(X0).max())


# --------------------------------------------------------------------------- between grid points


def _oscillator(rho):
    A = np.array([[0.0, 1.0], [-2.0 - rho[0], -0.5 - 0.2 * rho[0]]])
    return A, np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]]), np.zeros((1, 1))


def test_affine_system_covers_the_box():
    grid = [np.linspace(0.0, 1.0, 3)]
    r = polyrob.lpvnorm(_oscillator, grid, affine=True)
    assert r.proved and r.coverage.startswith("the whole parameter box [0, 1]")
    on_grid = polyrob.lpvnorm(_oscillator, grid)
    assert on_grid.coverage == "on the grid of 3 points"
    assert r.whole_box and not on_grid.whole_box  # the fact the moving-robot status reads, not the words
    assert r.gamma == pytest.approx(on_grid.gamma, rel=1e-3)  # constant X: M affine, the vertices suffice
    basis = [(lambda r: 1.0, lambda r: [0.0]), (lambda r: r[0], lambda r: [1.0])]
    ra = polyrob.lpvnorm(_oscillator, grid, [(-0.5, 0.5)], basis, affine=True)
    assert ra.proved and ra.coverage.startswith("the whole parameter box")
    assert ra.frozen_gamma <= ra.gamma * (1 + 1e-6) and ra.gamma <= r.gamma * (1 + 1e-3)


def test_affine_declared_for_a_nonaffine_system_is_refused():
    sysf = lambda r: (np.array([[-1.0 - r[0] ** 2]]), np.ones((1, 1)), np.ones((1, 1)), np.zeros((1, 1)))  # noqa: E731
    with pytest.raises(ArgumentError, match="not affine"):
        polyrob.lpvnorm(sysf, [np.linspace(0.0, 1.0, 3)], affine=True)


# --------------------------------------------------------------------------- errors


@pytest.mark.parametrize(
    "grid, rate_bounds, basis, options, match",
    [
        ([np.array([0.0, np.nan])], None, None, {}, "non-finite"),
        (np.array([0.0, 1.0]), None, None, {}, "sequence of p 1-D arrays"),
        ([np.array([0.0, 1.0])], [(1.0, -1.0)], None, {}, "lo > hi"),
        ([np.array([0.0, 1.0])], [(-1.0, 1.0), (0.0, 0.0)], None, {}, "2 pairs for 1"),
        ([np.array([0.0, 1.0])], None, [(lambda r: 1.0, lambda r: [0.0])], {}, "needs rate_bounds"),
        ([np.array([0.0, 1.0])], [(-1, 1)], [(lambda r: 1.0, lambda r: [0.0, 0.0])], {}, "gradient"),
        ([np.array([0.0, 1.0])], None, None, {"tolerance": 1}, "unknown option"),
    ],
)
def test_bad_input_is_an_argument_error(grid, rate_bounds, basis, options, match):
    with pytest.raises(ArgumentError, match=match):
        polyrob.lpvnorm(_oscillator, grid, rate_bounds, basis, **options)


def test_wrong_system_shapes_are_an_argument_error():
    with pytest.raises(ArgumentError, match="shape"):
        polyrob.lpvnorm(lambda r: (np.eye(2), np.ones((3, 1)), np.ones((1, 2)), np.zeros((1, 1))), [np.zeros(1)])


def test_a_solver_crash_is_a_solver_error(monkeypatch):
    import cvxpy as cp

    def crash(self, *a, **k):
        raise cp.error.SolverError("boom")

    monkeypatch.setattr(cp.Problem, "solve", crash)
    with pytest.raises(SolverError, match="boom"):
        polyrob.lpvnorm(_oscillator, [np.array([0.0, 1.0])], solver="cvxpy")


def test_a_crash_of_the_direct_solver_is_a_solver_error(monkeypatch):
    import clarabel

    def crash(*a, **k):
        raise RuntimeError("boom")

    monkeypatch.setattr(clarabel, "DefaultSolver", crash)
    with pytest.raises(SolverError, match="boom"):
        polyrob.lpvnorm(_oscillator, [np.array([0.0, 1.0])])


def test_summary_and_text(demo_slow):
    s = json.loads(json.dumps(demo_slow.summary(), allow_nan=False))
    assert s["status"] == "PROVED" and s["gamma"] == pytest.approx(demo_slow.gamma)
    assert s["frozen_gamma"] <= s["gamma"] and s["coverage"] == "on the grid of 6 points"
    text = str(demo_slow)
    assert "PROVED" in text and "frozen (LTI) peak" in text and "rate-bounded" in text
    assert isinstance(demo_slow, GridData) is False


def test_lpvtools_lpv_analysis_demo_order_of_magnitude():
    """LPVTools doc 'LPV Analysis' (Peni & Seiler, ACC 2015): H = delta G - G delta, G = 1/(s+1).

    The page prints no number for the rate-bounded loop, only that the
    difference of the two paths is "on the order of 1% when |d delta/dt| <= 0.01"
    and "on the order of 20% when ... 0.2"; frozen, H is 0.  (Here: z = x2 -
    delta x1 obeys z' = -z - delta' x1, so the gain is at most the rate bound.)
    """

    def H(r):
        d = r[0]
        return np.diag([-1.0, -1.0]), np.array([[1.0], [d]]), np.array([[d, -1.0]]), np.zeros((1, 1))

    grid = [np.linspace(-1, 1, 10)]
    basis = [(lambda r, k=k: r[0] ** k, lambda r, k=k: [k * r[0] ** (k - 1) if k else 0.0]) for k in range(4)]
    slow, fast = (polyrob.lpvnorm(H, grid, [(-b, b)], basis) for b in (0.01, 0.2))
    assert slow.frozen_gamma == pytest.approx(0.0, abs=1e-9)
    assert 0.005 < slow.gamma <= 0.01 * (1 + 1e-6) and 0.1 < fast.gamma <= 0.2 * (1 + 1e-6)


# --------------------------------------------------------------------------- the direct assembly (assemble.py)


def test_direct_assembly_agrees_with_cvxpy(demo_slow):
    """The conic data written directly (Clarabel) and cvxpy's canonicalisation give the same proved gamma."""
    via_cvxpy = polyrob.lpvnorm(lpvtools_demo_loop(), GRID, [(-0.1, 0.1)], BASIS4, solver="cvxpy")
    assert via_cvxpy.proved and via_cvxpy.gamma == pytest.approx(demo_slow.gamma, rel=2e-3)


def test_svec_orders_of_the_two_solvers():
    from polyrob.analysis.lpv.assemble import svec_index

    r, c, w = svec_index(3, "scs")  # SCS: lower triangle by columns
    assert list(zip(r.tolist(), c.tolist())) == [(0, 0), (1, 0), (2, 0), (1, 1), (2, 1), (2, 2)]
    assert np.allclose(w, [1, np.sqrt(2), np.sqrt(2), 1, np.sqrt(2), 1])


def test_scs_route_proves_or_says_not_proved():
    r = polyrob.lpvnorm(_oscillator, [np.linspace(0.0, 1.0, 3)], solver="scs")
    ref = polyrob.lpvnorm(_oscillator, [np.linspace(0.0, 1.0, 3)])
    assert not r.proved or r.gamma >= ref.gamma * (1 - 1e-3)


def test_restricted_x_is_a_smaller_search_never_below_the_full_one():
    """x_factor: the basis functions after the first carry L^T Y_j L; the proof is the same re-check."""
    sysf = lpvtools_demo_loop()
    full = polyrob.lpvnorm(sysf, GRID, [(-0.1, 0.1)], BASIS2)
    part = polyrob.lpvnorm(sysf, GRID, [(-0.1, 0.1)], BASIS2, x_factor=np.eye(4)[:2])
    assert full.proved and part.proved
    assert part.gamma >= full.gamma * (1 - 1e-3)
    assert np.allclose(part.X[1][2:, :], 0.0) and np.allclose(part.X[2][:, 2:], 0.0)


def test_rates_per_point_lie_between_frozen_and_the_global_box():
    """rates_at(rho): a smaller rate box at each grid point (here 0 at the ends) gives no more than the global one."""
    sysf = lpvtools_demo_loop()
    box = [(-0.1, 0.1)]
    glob = polyrob.lpvnorm(sysf, GRID, box, BASIS2)
    local = polyrob.lpvnorm(sysf, GRID, box, BASIS2, rates_at=lambda r: [(-0.1 * (7 - r[0]) / 5, 0.0)])
    assert local.proved and local.frozen_gamma * (1 - 1e-6) <= local.gamma <= glob.gamma * (1 + 1e-3)
    assert "rates_at" in local.variation
    with pytest.raises(ArgumentError, match="outside rate_bounds"):
        polyrob.lpvnorm(sysf, GRID, box, BASIS2, rates_at=lambda r: [(-1.0, 1.0)])


def test_fixed_level_with_maximised_margin_proves_that_level():
    """conic_data(level=...): gamma fixed, margin maximised: a point inside the feasible set, proved <= level."""
    from polyrob.analysis.lpv.assemble import solve_direct
    from polyrob.analysis.lpv.check import grid_data

    A, B, C, D = _oscillator(np.array([0.5]))
    data = grid_data([A], [B], [C], [D])
    _, g_opt, _ = solve_direct(data)
    Xs, g, status = solve_direct(data, level=1.5 * g_opt)
    assert g == 1.5 * g_opt and status == "solved"
    proved, chk = proved_gamma(data, Xs, g_opt)
    assert np.isfinite(proved) and proved <= 1.5 * g_opt and chk.lmi_margin > 0


def test_a_fixed_level_maximises_the_margin_and_still_proves_a_bound_below_it():
    """``level``: gamma fixed, the LMIs' margin maximised -- the X proves a level at most ``level``, above the optimum."""
    import polyrob
    from polyrob.errors import ArgumentError

    def system(rho):
        A = np.array([[0.0, 1.0], [-2.0 - rho[0], -0.5]])
        return A, np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]]), np.zeros((1, 1))

    grid = [np.linspace(0.0, 1.0, 4)]
    basis = [(lambda r: 1.0, lambda r: [0.0]), (lambda r: r[0], lambda r: [1.0])]
    best = polyrob.lpvnorm(system, grid, [(-0.1, 0.1)], basis)
    fixed = polyrob.lpvnorm(system, grid, [(-0.1, 0.1)], basis, level=2 * best.gamma)
    assert fixed.proved and best.gamma * (1 - 1e-6) <= fixed.gamma <= 2 * best.gamma
    assert any("margin maximised" in n for n in fixed.notes)
    with pytest.raises(ArgumentError, match="level"):
        polyrob.lpvnorm(system, grid, [(-0.1, 0.1)], basis, level=1.0, solver="cvxpy")


def test_a_parameter_the_basis_does_not_use_adds_no_rate_vertices():
    """A second parameter the basis ignores: its rate's two ends give one LMI, so one vertex, and the same bound."""
    from polyrob.analysis.lpv.data import evaluate

    loop = lpvtools_demo_loop()

    def system(rho):  # the demo loop, scheduled on p only; rho_2 moves but nothing depends on it
        return loop(rho[:1])

    basis = [(f, lambda r, g=g: [g(r)[0], 0.0]) for f, g in BASIS2]
    grid = [GRID[0], np.array([0.0, 1.0])]
    rates = [(-0.1, 0.1), (-5.0, 5.0)]
    ev = evaluate(system, grid, rates, basis)
    assert ev.data.nus.shape == (2, 2)  # (-0.1, 0.1) only: the ignored rate is not enumerated
    two = polyrob.lpvnorm(system, grid, rates, basis)
    one = polyrob.lpvnorm(loop, GRID, rates[:1], BASIS2)
    assert two.proved and two.gamma == pytest.approx(one.gamma, rel=1e-3)
    assert "[-5, 5]" in two.variation  # the stated rate box is the user's


def test_extra_points_join_the_grid_s_lmis_and_points_outside_its_box_are_refused():
    """lpvnorm(points=...): the LMIs of more points join the grid's (their frozen gain counts), inside the box only."""

    def system(rho):  # 1/(s + a(rho)), a from 1 at rho = 0 to 0.5 at rho = 0.5 and back to 1 at rho = 1
        a = 1.0 - 2.0 * rho[0] * (1.0 - rho[0])
        return np.array([[-a]]), np.array([[1.0]]), np.array([[1.0]]), np.zeros((1, 1))

    grid = [np.array([0.0, 1.0])]
    plain = polyrob.lpvnorm(system, grid, solver="structured")
    more = polyrob.lpvnorm(system, grid, solver="structured", points=[[0.5]])
    assert plain.gamma == pytest.approx(1.0, rel=1e-4) and more.gamma == pytest.approx(2.0, rel=1e-4)
    assert more.n_points == 3
    with pytest.raises(ArgumentError, match="inside the grid's box"):
        polyrob.lpvnorm(system, grid, points=[[1.5]])
