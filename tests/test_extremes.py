"""Exact extremes over the velocity/torque box against brute force."""

from __future__ import annotations

import numpy as np
import pytest

from polyrob.bounds.extremes import box_maximum, evaluate_polynomial, polynomial_coefficients


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
