"""Reflected rotor inertia (armature) from the SRDF, or given: in M(q), in the dynamics, in every result."""

from __future__ import annotations

import numpy as np
import pinocchio
import pytest

from polyrob import load_robot
from polyrob.errors import RobotError
from polyrob.model.srdf import find_srdf, read_srdf


@pytest.fixture(scope="module")
def talos():
    return load_robot("talos_left_arm"), load_robot("talos_left_arm", armature=0.0)


def test_talos_rotor_parameters_add_exactly_the_armature_to_the_diagonal(talos):
    robot, bare = talos
    assert robot.reflected_inertia.startswith("from the SRDF (talos.srdf)")
    assert bare.reflected_inertia == "given"
    # what Pinocchio's own reader makes of the same file, on the same reduced model
    model = bare.model.copy()
    pinocchio.loadRotorParameters(model, str(find_srdf(robot.source)), False)
    expected = model.rotorGearRatio**2 * model.rotorInertia
    np.testing.assert_allclose(robot.armature, expected, rtol=1e-12)
    np.testing.assert_allclose(robot.armature, 100.0**2 * 1e-5)  # talos.srdf: mass 1e-5, gear ratio 100
    rng = np.random.default_rng(1)
    for q in rng.uniform(robot.position_lower, robot.position_upper, (5, robot.m)):
        np.testing.assert_allclose(robot.mass_matrix(q) - bare.mass_matrix(q), np.diag(robot.armature), atol=1e-12)


def test_armature_conditions_talos_mass_matrix(talos):
    """The measured figure of the issue: cond(M) of talos' arm drops from ~1e3 to ~17."""
    robot, bare = talos
    qs = np.random.default_rng(0).uniform(robot.position_lower, robot.position_upper, (400, robot.m))
    bare_cond = max(np.linalg.cond(bare.mass_matrix(q)) for q in qs)
    cond = max(np.linalg.cond(robot.mass_matrix(q)) for q in qs)
    assert bare_cond > 1000 and cond < 20


def test_override_per_joint_and_errors():
    robot = load_robot("planar_2r", armature={"joint2": 0.5})
    bare = load_robot("planar_2r")
    assert bare.reflected_inertia == "not modelled (no rotor data in the URDF/SRDF)" and robot.reflected_inertia == "given"
    np.testing.assert_allclose(robot.mass_matrix([0.3, 0.2]) - bare.mass_matrix([0.3, 0.2]), np.diag([0.0, 0.5]))
    with pytest.raises(RobotError, match="unknown joint"):
        load_robot("planar_2r", armature={"elbow": 0.5})
    with pytest.raises(RobotError, match=">= 0"):
        load_robot("planar_2r", armature=-1.0)
    with pytest.raises(RobotError, match="analytic"):
        load_robot("paper_2r", armature=0.1)


def test_rnea_jacobian_matches_finite_differences():
    """With u = rnea(q, qdot, qddot), d qddot/dq of the forward dynamics is -M^-1 d tau/dq at fixed qddot."""
    robot = load_robot("talos_left_arm")
    model, data = robot.model, robot.model.createData()
    rng = np.random.default_rng(3)
    q = rng.uniform(robot.position_lower, robot.position_upper)
    qd, qdd = rng.uniform(-1, 1, robot.m), rng.uniform(-2, 2, robot.m)
    u = pinocchio.rnea(model, data, q, qd, qdd) + robot.damping * qd
    np.testing.assert_allclose(robot.acceleration(q, qd, u), qdd, atol=1e-9)
    A, _ = robot.jacobians(q, qd, u)
    dtau_dq = pinocchio.computeRNEADerivatives(model, data, q, qd, qdd)[0]
    M = robot.mass_matrix(q)
    np.testing.assert_allclose(A[robot.m :, : robot.m], -np.linalg.solve(M, dtau_dq), rtol=1e-7, atol=1e-8)
    h = 1e-6
    fd = np.column_stack(
        [
            (robot.acceleration(q + h * e, qd, u) - robot.acceleration(q - h * e, qd, u)) / (2 * h)
            for e in np.eye(robot.m)
        ]
    )
    np.testing.assert_allclose(A[robot.m :, : robot.m], fd, rtol=1e-5, atol=1e-6)


def test_srdf_poses_are_mapped_to_the_kept_joints():
    panda = load_robot("panda")
    assert list(panda.reference_poses) == ["default"]
    np.testing.assert_allclose(panda.reference_poses["default"], [0, -0.785398, 0, -2.35619, 0, 1.5707, 0.785398])
    assert sorted(read_srdf(find_srdf(load_robot("z1").source)).poses) == ["arm_up", "home"]
    assert load_robot("ur5").reference_poses == {} and load_robot("planar_2r").reference_poses == {}


def test_info_says_whether_reflected_inertia_is_included(capsys):
    from polyrob.cli import main

    assert main(["info", "talos_left_arm"]) == 0
    out = capsys.readouterr().out
    assert "reflected rotor inertia (armature): from the SRDF (talos.srdf)" in out and "half_sitting" in out
    assert main(["info", "planar_2r", "--armature", "joint1=0.2"]) == 0
    assert "(armature): given" in capsys.readouterr().out
