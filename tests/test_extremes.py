"""Exact extremes over the velocity/torque box against brute force."""

from __future__ import annotations

import numpy as np
import pytest

from polyrob.bounds.extremes import box_maximum, box_upper_bound, evaluate_polynomial, polynomial_coefficients


def random_polynomials(rng, N, m, D):
    c = rng.normal(size=(N, D))
    a = rng.normal(size=(N, m, D))
    b = rng.normal(size=(N, m, D))
    Q = rng.normal(size=(N, m, m, D))
    return c, a, b, Q + Q.transpose(0, 2, 1, 3)


@pytest.mark.parametrize("m", [1, 2, 3])
def test_face_enumeration_is_exact(m):
    rng = np.random.default_rng(m)
    c, a, b, Q = random_polynomials(rng, 3, m, 4)
    value, t, u = box_maximum(c, a, b, Q, np.ones(m, bool), np.ones(m, bool))
    grid = np.stack(np.meshgrid(*[np.linspace(-1, 1, 81)] * m), -1).reshape(-1, m)
    for n in range(3):
        for d in range(4):
            brute = (
                c[n, d]
                + np.abs(a[n, :, d]).sum()
                + grid @ b[n, :, d]
                + np.einsum("pi,ij,pj->p", grid, Q[n, :, :, d], grid)
            )
            # the exact maximum is at least the grid's and within its resolution
            assert brute.max() <= value[n, d] + 1e-12
            assert value[n, d] - brute.max() < 0.05 * np.abs(Q[n, :, :, d]).sum()
            at = c[n, d] + a[n, :, d] @ u[n, d] + b[n, :, d] @ t[n, d] + t[n, d] @ Q[n, :, :, d] @ t[n, d]
            assert at == pytest.approx(value[n, d], abs=1e-12)  # the argmax attains it


def test_pinned_coordinates_stay_at_the_centre():
    rng = np.random.default_rng(0)
    c, a, b, Q = random_polynomials(rng, 2, 3, 2)
    _, t, u = box_maximum(c, a, b, Q, np.array([True, False, True]), np.array([False, True, True]))
    assert np.all(t[..., 1] == 0) and np.all(u[..., 0] == 0)


def test_coefficients_reproduce_a_quadratic_exactly():
    rng = np.random.default_rng(1)
    m, k = 3, 5
    c0, a0, b0, Q0 = random_polynomials(rng, 1, m, k)

    def entries(q, qdot, u):  # polynomial in (qdot, u), independent of q
        n = len(q)
        return evaluate_polynomial(
            np.repeat(c0, n, 0), np.repeat(a0, n, 0), np.repeat(b0, n, 0), np.repeat(Q0, n, 0), qdot, u
        )

    q = np.zeros((2, m))
    c, a, b, Q = polynomial_coefficients(entries, q, np.zeros(m), np.ones(m), np.zeros(m), np.ones(m))
    np.testing.assert_allclose(c[0], c0[0], atol=1e-12)
    np.testing.assert_allclose(a[0], a0[0], atol=1e-12)
    np.testing.assert_allclose(b[0], b0[0], atol=1e-12)
    np.testing.assert_allclose(Q[0], Q0[0], atol=1e-12)


def test_seven_joints_exact_enumeration_against_multistart():
    """Indefinite quadratics in 7 velocities: all 3^7 faces against 150 local solves each."""
    from scipy import optimize

    rng = np.random.default_rng(7)
    m, D = 7, 2
    c, a, b, Q = random_polynomials(rng, 1, m, D)
    on = np.ones(m, bool)
    exact, t_exact, _ = box_maximum(c, a, b, Q, on, on, exact=True)
    ascent, t_ascent, _ = box_maximum(c, a, b, Q, on, on)
    for d in range(D):
        bd, Qd = b[0, :, d], Q[0, :, :, d]
        assert np.linalg.eigvalsh(Qd).min() < 0 < np.linalg.eigvalsh(Qd).max()  # indefinite

        def neg(t):
            return -(bd @ t + t @ Qd @ t), -(bd + 2 * Qd @ t)

        brute = max(
            -optimize.minimize(neg, t0, jac=True, method="L-BFGS-B", bounds=[(-1, 1)] * m).fun
            for t0 in rng.uniform(-1, 1, (150, m))
        )
        offset = c[0, d] + np.abs(a[0, :, d]).sum()
        assert exact[0, d] == pytest.approx(offset + brute, abs=1e-9)
        for value, t in ((exact, t_exact), (ascent, t_ascent)):
            tt = t[0, d]
            assert np.all(np.abs(tt) <= 1.0)
            assert offset + bd @ tt + tt @ Qd @ tt == pytest.approx(value[0, d], abs=1e-12)  # attained
        assert ascent[0, d] <= exact[0, d] + 1e-12  # the cheap maximum is a lower bound


def test_linear_polynomials_are_maximised_at_a_vertex():
    rng = np.random.default_rng(3)
    c, a, b, _ = random_polynomials(rng, 4, 6, 2)
    Q = np.zeros((4, 6, 6, 2))
    value, t, _ = box_maximum(c, a, b, Q, np.ones(6, bool), np.ones(6, bool))
    np.testing.assert_allclose(value, c + np.abs(a).sum(axis=1) + np.abs(b).sum(axis=1))
    assert np.all(np.abs(t) == 1.0)


@pytest.mark.parametrize("m", [2, 3])
def test_cheap_upper_bound_is_above_the_exact_maximum_and_tight_on_linear_parts(m):
    rng = np.random.default_rng(10 + m)
    c, a, b, Q = random_polynomials(rng, 6, m, 5)
    t_active, u_active = np.array([True] * (m - 1) + [False]), np.ones(m, bool)
    exact, _, _ = box_maximum(c, a, b, Q, t_active, u_active, exact=True)
    bound = box_upper_bound(c, a, b, Q, t_active, u_active)
    assert np.all(bound >= exact - 1e-12)
    linear = box_upper_bound(c, a, b, 0 * Q, t_active, u_active)  # no quadratic part: the bound is the maximum
    np.testing.assert_allclose(linear, box_maximum(c, a, b, 0 * Q, t_active, u_active, exact=True)[0], atol=1e-12)


def test_inner_maxima_with_a_floor_keeps_every_value_above_it():
    """The verification's pruning: values above the floor are the maxima; the rest are bounds at most the floor."""
    from polyrob import load_robot
    from polyrob.bounds import search
    from polyrob.bounds.parallel import WorkerPool
    from polyrob.domains.torque_box import Domain

    robot = load_robot("planar_2r")
    problem = search.Problem(robot, Domain.from_robot(robot))
    q = problem.domain.sample(64, seed=3)[0]
    directions = np.vstack([np.eye(len(problem.all_index)), -np.eye(len(problem.all_index))])
    with WorkerPool(problem, workers=1) as pool:
        full, dep = search.inner_maxima(problem, q, directions, problem.all_index, False, pool)
        floor = np.quantile(full, 0.9, axis=0)
        pruned, dep2 = search.inner_maxima(problem, q, directions, problem.all_index, False, pool, floor=floor)
    above = full > floor
    assert above.any() and (~above).any()
    np.testing.assert_allclose(pruned[above], full[above], rtol=1e-12, atol=1e-12)
    assert np.all(pruned[~above] <= floor[None, :].repeat(len(q), 0)[~above] + 1e-12)
    assert np.all(pruned >= full - 1e-12) and np.array_equal(dep, dep2)


def test_inner_maxima_top_only_finds_each_direction_s_largest_value_exactly():
    """The design pass with one start per direction: the column maxima and their attainment are the full pass's."""
    from polyrob import load_robot
    from polyrob.bounds import search
    from polyrob.bounds.parallel import WorkerPool
    from polyrob.domains.torque_box import Domain

    robot = load_robot("planar_2r")
    problem = search.Problem(robot, Domain.from_robot(robot))
    q = problem.domain.sample(300, seed=4)[0]  # three chunks of positions
    directions = np.vstack([np.eye(len(problem.all_index)), -np.eye(len(problem.all_index))])
    with WorkerPool(problem, workers=1) as pool:
        full, dep = search.inner_maxima(problem, q, directions, problem.all_index, False, pool)
        top, dep2 = search.inner_maxima(problem, q, directions, problem.all_index, False, pool, top_only=True)
    np.testing.assert_allclose(top.max(axis=0), full.max(axis=0), rtol=1e-12, atol=1e-12)
    best = np.argmax(top, axis=0)  # the start the landscape gives: a position that attains the maximum
    np.testing.assert_allclose(full[best, np.arange(full.shape[1])], full.max(axis=0), rtol=1e-12, atol=1e-12)
    assert np.all(top >= full - 1e-12) and np.array_equal(dep, dep2)
    assert np.any(top > full + 1e-9)  # some positions were pruned: they keep their upper bound
