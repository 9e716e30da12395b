"""URDF robots of up to three joints as exact polynomials on Jets (polyrob.bounds.certified.symbolic_rbd)."""

import pickle

import numpy as np
import pytest

import polyrob
from polyrob.bounds.certified.analytic import analytic_jacobian_enclosure, task_jacobian_enclosure
from polyrob.bounds.certified.symbolic_rbd import SymbolicTwin
from polyrob.errors import NotApplicable


@pytest.fixture(scope="module", params=["planar_2r", "finger_edu"])
def robot(request):
    return polyrob.load_robot(request.param)  # finger_edu: three joints under gravity


def _box(robot, rng, width):
    q = rng.uniform(-1, 1, robot.m)
    return q - width, q + width


def test_the_twin_s_enclosure_at_a_point_is_pinocchio_s_jacobians(robot):
    twin = SymbolicTwin(robot)
    rng = np.random.default_rng(0)
    for _ in range(3):
        q, qd, u = rng.uniform(-1, 1, robot.m), rng.uniform(-1, 1, robot.m), rng.uniform(-1, 1, robot.m)
        enc = analytic_jacobian_enclosure(twin, q, q, qd, qd, u)
        A, B = robot.jacobians(q, qd, u)
        assert np.allclose(enc.A_lo, A, rtol=1e-9, atol=1e-9) and np.allclose(enc.A_hi, A, rtol=1e-9, atol=1e-9)
        assert np.allclose(enc.B_lo, B, rtol=1e-9, atol=1e-12)
        assert np.allclose(enc.qddot_lo, robot.acceleration(q, qd, u), rtol=1e-9, atol=1e-9)


def test_the_twin_s_enclosures_hold_pinocchio_s_jacobians_over_a_box(robot):
    twin = SymbolicTwin(robot)
    rng = np.random.default_rng(1)
    (ql, qh), (vl, vh), (al, ah) = (_box(robot, rng, 0.05) for _ in range(3))
    u = rng.uniform(-1, 1, robot.m)
    fixed = analytic_jacobian_enclosure(twin, ql, qh, vl, vh, u)
    task = task_jacobian_enclosure(twin, ql, qh, vl, vh, al, ah)
    for _ in range(100):
        q, qd, a = rng.uniform(ql, qh), rng.uniform(vl, vh), rng.uniform(al, ah)
        A, B = robot.jacobians(q, qd, u)
        assert np.all(fixed.A_lo <= A) and np.all(A <= fixed.A_hi) and np.all(fixed.B_lo <= B)
        A, B = robot.jacobians(q, qd, robot.inverse_dynamics(q, qd, a)[0])
        assert np.all(task.A_lo <= A) and np.all(A <= task.A_hi)
        assert np.all(task.B_lo <= B) and np.all(B <= task.B_hi)


def test_the_twin_pickles_and_rebuilds_its_polynomials():
    twin = SymbolicTwin(polyrob.load_robot("planar_2r"))
    q = np.array([0.2, 1.0])
    before = analytic_jacobian_enclosure(twin, q, q, q, q, q)
    again = pickle.loads(pickle.dumps(twin))  # the cells' worker processes receive it so
    after = analytic_jacobian_enclosure(again, q, q, q, q, q)
    assert np.array_equal(before.A_lo, after.A_lo) and np.array_equal(before.B_hi, after.B_hi)


def test_a_chain_of_more_than_three_joints_is_refused():
    with pytest.raises(NotApplicable, match="at most 3"):
        SymbolicTwin(polyrob.load_robot("ur5"))
