"""Time-varying certificates: quadratic stability / performance over PLDI vertices."""

from __future__ import annotations

import control
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from polyrob.analysis.time_varying.quadratic import quadperf, quadstab
from polyrob.analysis.time_varying.results import COVERS_NONLINEAR
from polyrob.analysis.time_varying.vertices import performance_vertices, vertex_set

ZERO_K = np.zeros((1, 1))
NO_B = np.zeros((2, 1))

# Liberzon, "Switching in Systems and Control" (2003), sec. 2.1.1: both matrices
# are Hurwitz (eigenvalues -0.1 +- j sqrt(10)) but switching to the first one in
# quadrants 1 and 3 and to the second in 2 and 4 makes the state spiral outwards.
A1 = np.array([[-0.1, 1.0], [-10.0, -0.1]])
A2 = np.array([[-0.1, 10.0], [-1.0, -0.1]])


def _switched_final_norm(law) -> float:
    sol = solve_ivp(
        lambda t, x: (A1 if law(x) else A2) @ x, (0.0, 8.0), [1.0, 0.0], max_step=1e-2, rtol=1e-8, atol=1e-12
    )
    return float(np.linalg.norm(sol.y[:, -1]))


def test_switched_counterexample_is_rejected():
    # the vertices are each stable ...
    for A in (A1, A2):
        assert np.max(np.linalg.eigvals(A).real) < 0
    # ... but a switching law diverges (checked by simulation), so no common P can exist
    assert _switched_final_norm(lambda x: x[0] * x[1] > 0) < 1e-4
    assert _switched_final_norm(lambda x: x[0] * x[1] <= 0) > 1e2
    res = quadstab([(A1, NO_B), (A2, NO_B)], ZERO_K)
    assert not res.holds
    assert res.n_vertices == 2 and res.vertex_source == "given"


def test_a_small_subset_without_a_common_p_ends_the_search_and_a_feasible_one_changes_nothing():
    """Infeasible on a subset means infeasible on all: 8 vertices refute a common P for the 20 (before: all 20
    went into one LMI, 30 s on the 2524-vertex tf3 x4 problem of test_time_varying); with a common P the
    search runs on the same vertices as without the probe."""
    # convex combinations of the switched pair (each stable), the pair itself at the ends
    lams = np.linspace(0.0, 1.0, 20)
    res = quadstab([((1 - t) * A1 + t * A2, NO_B) for t in lams], ZERO_K)
    assert not res.holds and res.info["lmi_vertices"] <= 8 and "no common P" in res.solver_status
    # stiffness 1..2: a common P exists; every one of the 20 vertices is in the LMI, as before
    res = quadstab([(np.array([[0.0, 1.0], [-k, -1.0]]), NO_B) for k in np.linspace(1.0, 2.0, 20)], ZERO_K)
    assert res.holds and res.info["lmi_vertices"] == 20


def test_the_vertex_search_solves_the_probe_first_and_then_its_usual_first_set():
    from polyrob.analysis.time_varying.quadratic import _active_set

    calls = []

    def solve_subset(feasible):
        def solve(idx):
            calls.append(idx.tolist())
            return (np.zeros(1), "optimal") if feasible else (None, "no common P")

        return solve

    no_violation = lambda sol: np.zeros(10)  # noqa: E731
    sol, status, used = _active_set(10, solve_subset(False), no_violation, np.arange(6), probe=[0, 9])
    assert sol is None and status == "no common P" and used == 2 and calls == [[0, 9]]
    calls.clear()
    sol, status, used = _active_set(10, solve_subset(True), no_violation, np.arange(6), probe=[0, 9])
    assert sol is not None and used == 7 and calls == [[0, 9], [0, 1, 2, 3, 4, 5, 9]]
    calls.clear()  # a probe no smaller than the first set is not solved on its own
    _active_set(10, solve_subset(True), no_violation, np.arange(2), probe=[0, 1])
    assert calls == [[0, 1]]


def test_quadratically_stable_pair_is_accepted_with_a_verified_P():
    # damped oscillators with stiffness 1..2 and damping 1: V = 1.5 q^2 + q v + v^2 is common
    # (with stiffness 1..4 no quadratic V exists: 4 k b (1 - b) > (a - b - k)^2 fails at k = 1 or 4)
    verts = [(np.array([[0.0, 1.0], [-k, -1.0]]), NO_B) for k in (1.0, 2.0)]
    res = quadstab(verts, ZERO_K)
    assert res.holds and res.margin > 0
    P = res.P
    assert np.linalg.eigvalsh(P)[0] > 0  # independent re-check of the certificate
    for A, _ in verts:
        assert np.linalg.eigvalsh(A.T @ P + P @ A)[-1] < 0
    # the decay rate is bounded by the slowest vertex's: V decays at most at twice its abscissa
    assert res.margin <= 2 * min(-np.max(np.linalg.eigvals(A).real) for A, _ in verts) + 1e-9
    assert "arbitrarily fast" in res.covers


def test_a_stiff_loop_gets_its_common_P_from_the_centres_lyapunov_coordinates():
    # the main job's loop (2R task PLDI, its order-8 controller): time constants from 0.03 to 5000 rad/s.
    # In the diagonally balanced coordinates the solver stalls at a level of 8.6e-6 >= 0 (the slowest
    # decay rate's order) and the old code found no P; one with cond 2.5e4 exists.
    from pathlib import Path

    from polyrob.analysis.time_varying.vertices import closed_loop_vertices

    data = np.load(Path(__file__).parent / "fixtures" / "main_job_stiff_loop_vertices.npz")
    verts = list(zip(data["A"], data["B"]))
    K = (data["AK"], data["BK"], data["CK"], data["DK"])
    res = quadstab(verts, K)
    assert res.holds and res.margin > 0, res.solver_status
    assert res.n_vertices == 2432
    # independent re-check in the loop's own coordinates: P > 0 and every vertex decays
    P = res.P
    As = closed_loop_vertices(vertex_set(verts), K)
    assert np.linalg.eigvalsh(P)[0] > 0
    decay = np.array([np.linalg.eigvalsh(A.T @ P + P @ A)[-1] for A in As])
    assert decay.max() < 0


def _mass_spring_vertices(gains):
    A = np.array([[0.0, 1.0], [-1.0, -0.5]])
    return [(A, np.array([[0.0], [g]])) for g in gains]


def _grid_peak(A, B, C, D) -> float:
    """A lower bound of the H∞ norm: the largest sampled singular value."""
    w = np.logspace(-3, 3, 4000)
    return max(np.linalg.svd(C @ np.linalg.solve(1j * wi * np.eye(len(A)) - A, B) + D, compute_uv=False)[0] for wi in w)


def test_quadperf_gamma_bounds_every_vertex_and_is_exact_for_one():
    K = control.tf([2.0, 1.0], [0.1, 1.0])
    W_S = control.tf([0.5, 0.4], [1.0, 0.004])
    verts = _mass_spring_vertices([0.5, 1.0, 2.0])
    res = quadperf(verts, K, W_S=W_S, W_T=0.2)
    As, Bs, Cs, Ds = performance_vertices(vertex_set(verts), K, W_S, 0.2)
    lower = max(_grid_peak(*mats) for mats in zip(As, Bs, Cs, Ds))
    assert np.isfinite(res.gamma) and res.gamma >= lower * (1 - 1e-9)
    assert res.gamma >= res.worst_vertex_hinf * (1 - 1e-6)
    single = quadperf(verts[1:2], K, W_S=W_S, W_T=0.2)
    exact = float(control.linfnorm(control.ss(As[1], Bs[1], Cs[1], Ds[1]))[0])
    assert abs(single.gamma - exact) <= 0.01 * exact
    assert single.holds == (single.gamma < 1)


def test_performance_vertices_are_the_weighted_sensitivities(pldi):
    # independent check of the realisation: z = [W_S S; W_T T] r from frequency responses
    from polyrob.plant.generalized import paper_controller
    from polyrob.plant.weights import paper_weights

    W_S, W_T = paper_weights()
    K = paper_controller()
    vs = vertex_set([(pldi.A0, pldi.B0)])
    A, B, C, D = (X[0] for X in performance_vertices(vs, K, W_S, W_T))
    for w in (0.03, 1.0, 40.0):
        s = 1j * w
        G = vs.C @ np.linalg.solve(s * np.eye(4) - pldi.A0, pldi.B0)
        Kw, WSw, WTw = (np.asarray(X(s)) for X in (K, W_S, W_T))
        S = np.linalg.inv(np.eye(2) + G @ Kw)
        ref = np.vstack([WSw @ S, WTw @ G @ Kw @ S])
        mine = C @ np.linalg.solve(s * np.eye(len(A)) - A, B) + D
        assert np.allclose(mine, ref, rtol=1e-7, atol=1e-9 * np.abs(ref).max())


def test_paper_controller_has_unstable_frozen_vertices(pldi):
    from polyrob.plant.generalized import paper_controller

    res = quadstab(pldi, paper_controller(), which="box")
    # K* does not stabilise every corner of the paper's box (robust-stability mu > 1):
    # the certificate must say no, and say why
    assert not res.holds and "unstable" in res.solver_status
    assert res.vertex_source == "box" and res.n_vertices == 2 ** len(pldi.entries)


def test_covers_sentence_names_the_nonlinear_robot():
    assert "nonlinear robot" in COVERS_NONLINEAR and "frozen" in COVERS_NONLINEAR


def test_bad_vertices_are_refused():
    from polyrob.errors import PolyrobError

    with pytest.raises(PolyrobError):
        quadstab([(np.zeros((3, 3)), np.zeros((3, 1)))], ZERO_K)
    with pytest.raises(PolyrobError):
        quadstab([], ZERO_K)


# --------------------------------------------------------------------------- scaled small gain


def _switched_lft(spread: float):
    """xdot = (A0 + delta(t) spread dA) x, delta in [-1, 1], as an LFT with one repeated real scalar."""
    A0, dA = 0.5 * (A1 + A2), 0.5 * (A1 - A2)
    return control.ss(A0, spread * dA, np.eye(2), np.zeros((2, 2)))


def test_scaled_small_gain_rejects_the_switched_counterexample_and_accepts_a_small_spread():
    from polyrob.analysis.time_varying.smallgain import scaled_small_gain

    bad = scaled_small_gain(_switched_lft(1.0), [[-2, 0]])  # delta = +-1 are A1, A2: unstable switching
    assert not bad.holds and bad.gamma >= 1.0
    good = scaled_small_gain(_switched_lft(0.01), [[-2, 0]])
    assert good.holds and good.gamma < 1.0
    assert good.scaled_norm <= good.gamma * (1 + 1e-6)  # independent H∞ norm of D N D^-1


def test_scaled_small_gain_finds_the_optimal_diagonal_scaling():
    from polyrob.analysis.time_varying.smallgain import scaled_small_gain

    # N = [[0, 5], [0.1, 0]] / (s + 1): ||N|| = 5, but with D = diag(1, d) the off-diagonal gains
    # become 5/d and 0.1 d, balanced at sqrt(5 * 0.1) = 0.707 (the scaled bound of two real scalars)
    N = control.ss(-np.eye(2), np.eye(2), np.array([[0.0, 5.0], [0.1, 0.0]]), np.zeros((2, 2)))
    r = scaled_small_gain(N, [[-1, 0], [-1, 0]])
    assert abs(r.unscaled_norm - 5.0) < 1e-6
    assert r.holds and abs(r.gamma - np.sqrt(0.5)) < 2e-3 * np.sqrt(0.5)


def test_scaled_small_gain_on_a_loop_whose_poles_span_seven_decades():
    """Before: 'no verified scaling' (the KYP LMI fails on such loops, e.g. a tf3 controller's)."""
    from polyrob.analysis.time_varying.smallgain import scaled_small_gain

    # N = [[0, 5 / (s/1e-3 + 1)], [0.1 / (s/1e4 + 1), 0]], realised with a state similarity of 1e8:
    # the same transfer function, so the same optimal constant-D bound sqrt(5 * 0.1)
    A = np.diag([-1e-3, -1e4])
    B = np.array([[0.0, 1e-3], [1e4, 0.0]])
    C = np.array([[5.0, 0.0], [0.0, 0.1]])
    T = np.diag([1e-4, 1e4])
    Ti = np.linalg.inv(T)
    N = control.ss(Ti @ A @ T, Ti @ B, C @ T, np.zeros((2, 2)))
    r = scaled_small_gain(N, [[-1, 0], [-1, 0]])
    assert abs(r.unscaled_norm - 5.0) < 1e-4
    assert r.holds and abs(r.gamma - np.sqrt(0.5)) < 2e-3 * np.sqrt(0.5)
    assert r.scaled_norm <= r.gamma
