"""A = df/dx and B = df/du against central finite differences of f."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import cached_robot

from polyrob import Domain

USER_DOMAINS = {
    # double_pendulum's URDF has zero limits: the user gives the domain
    "double_pendulum": dict(q_range=[-np.pi, np.pi], qdot_max=5.0, u_max=2.0),
}


def finite_difference_jacobians(robot, q, qdot, u, h=1e-6):
    x = np.concatenate([q, qdot])
    m = robot.m
    A = np.zeros((2 * m, 2 * m))
    B = np.zeros((2 * m, m))
    for k in range(2 * m):
        e = np.zeros(2 * m)
        e[k] = h
        A[:, k] = (robot.f(x + e, u) - robot.f(x - e, u)) / (2 * h)
    for k in range(m):
        e = np.zeros(m)
        e[k] = h
        B[:, k] = (robot.f(x, u + e) - robot.f(x, u - e)) / (2 * h)
    return A, B


def relative_error(X, Y):
    return np.abs(X - Y).max() / max(np.abs(Y).max(), 1.0)


@pytest.mark.parametrize("name", ["planar_2r", "double_pendulum", "ur5", "kinova", "z1", "panda", "paper_2r"])
def test_jacobians_match_central_finite_differences(name):
    robot = cached_robot(name)
    domain = Domain.from_robot(robot, **USER_DOMAINS.get(name, {}))
    q, qdot, u = domain.sample(5, method="uniform", seed=1)
    if name == "paper_2r":  # its default domain has u = 0; test a torque too
        u = np.random.default_rng(2).uniform(-20, 20, q.shape)
    A, B = robot.jacobians_batch(q, qdot, u)
    for k in range(len(q)):
        A_fd, B_fd = finite_difference_jacobians(robot, q[k], qdot[k], u[k])
        assert relative_error(A[k], A_fd) <= 1e-5
        assert relative_error(B[k], B_fd) <= 1e-5
        A1, B1 = robot.jacobians(q[k], qdot[k], u[k])
        np.testing.assert_array_equal(A1, A[k])
        np.testing.assert_array_equal(B1, B[k])


def test_damping_enters_the_velocity_jacobian():
    robot = cached_robot("panda")
    assert np.all(robot.damping > 0)
    q = np.zeros(7)
    q[3] = -1.5
    A, B = robot.jacobians(q, np.zeros(7), np.zeros(7))
    # at qdot = 0 the Coriolis part vanishes: d qddot / d qdot = -M^-1 D
    np.testing.assert_allclose(A[7:, 7:], -B[7:] @ np.diag(robot.damping), atol=1e-12)


def test_gravity_is_the_urdf_world_gravity():
    import pinocchio

    robot = cached_robot("double_pendulum")
    np.testing.assert_allclose(robot.model.gravity.linear, [0, 0, -9.81])
    q = np.array([0.5, -0.3])
    g = pinocchio.computeGeneralizedGravity(robot.model, robot.model.createData(), robot.configuration(q))
    assert np.abs(g).max() > 0.1
    # holding the gravity torque is an equilibrium; without it the arm falls
    np.testing.assert_allclose(robot.acceleration(q, [0.0, 0.0], g), 0.0, atol=1e-10)
    np.testing.assert_allclose(
        robot.acceleration(q, [0.0, 0.0], [0.0, 0.0]), -np.linalg.solve(robot.mass_matrix(q), g), atol=1e-10
    )


def test_physical_and_printed_coriolis_differ_only_in_the_velocity_terms():
    """planar_2r (physical C) and paper_2r (printed C) share M(q) and B."""
    phys, paper = cached_robot("planar_2r"), cached_robot("paper_2r")
    rng = np.random.default_rng(3)
    q, qdot = rng.uniform(-3, 3, (20, 2)), rng.uniform(-4, 4, (20, 2))
    u = np.zeros((20, 2))
    A1, B1 = phys.jacobians_batch(q, qdot, u)
    A2, B2 = paper.jacobians_batch(q, qdot, u)
    np.testing.assert_allclose(B1, B2, atol=1e-12)
    assert np.abs(A1[:, 2:, 1:] - A2[:, 2:, 1:]).max() > 0.1
    # the sign of C12 (a3 sin q2 (qdot1 + qdot2)) is the whole difference
    a3 = 6.25
    for k in range(20):
        s = a3 * np.sin(q[k, 1])
        c12_phys = -s * (qdot[k, 0] + qdot[k, 1])
        C_phys = np.array([[-s * qdot[k, 1], c12_phys], [s * qdot[k, 0], 0.0]])
        h = C_phys @ qdot[k]
        acc = np.linalg.solve(phys.mass_matrix(q[k]), -h)
        np.testing.assert_allclose(phys.acceleration(q[k], qdot[k], u[k]), acc, atol=1e-10)
