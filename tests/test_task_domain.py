"""Task domains: (q, qdot, qddot) around a pose, torques by inverse dynamics; the PLDI covers the trajectories."""

from __future__ import annotations

import json

import numpy as np
import pytest

from polyrob import bound_pldi, load_robot
from polyrob.bounds.pldi_result import PLDI
from polyrob.domains.task import TaskDomain, domain_from_dict
from polyrob.domains.torque_box import Domain
from polyrob.errors import CertificationError, DomainError

POSE, RADIUS, QDOT, QDDOT = [0.4, 1.2], 0.3, 0.5, 2.0


@pytest.fixture(scope="module")
def robot():
    return load_robot("planar_2r")


@pytest.fixture(scope="module")
def domain(robot):
    return TaskDomain.from_robot(robot, pose=POSE, q_radius=RADIUS, qdot_max=QDOT, qddot_max=QDDOT)


def trajectories(robot, n=24, steps=300, seed=0):
    """Sums of three sinusoids per joint, scaled so |q - pose| <= radius, |qdot| <= qdot_max, |qddot| <= qddot_max."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 10.0, steps)
    out = []
    for _ in range(n):
        q, qd, qdd = (np.zeros((steps, robot.m)) for _ in range(3))
        for j in range(robot.m):
            a, w, phi = rng.uniform(-1, 1, 3), rng.uniform(2.0, 8.0, 3), rng.uniform(0, 2 * np.pi, 3)
            s = min(RADIUS / np.abs(a).sum(), QDOT / np.abs(a * w).sum(), QDDOT / np.abs(a * w**2).sum())
            arg = np.outer(t, w) + phi
            q[:, j] = POSE[j] + s * np.sin(arg) @ a
            qd[:, j] = s * np.cos(arg) @ (a * w)
            qdd[:, j] = -s * np.sin(arg) @ (a * w**2)
        out.append((q, qd, qdd))
    return [np.vstack(x) for x in zip(*out)]


def coverage_along(pldi, robot, q, qd, qdd) -> float:
    u = robot.inverse_dynamics(q, qd, qdd)
    A, B = robot.jacobians_batch(q, qd, u)
    inside = pldi.contains(A, B) & pldi.polytope.contains(pldi.entry_values(A, B))
    return float(inside.mean())


def test_pldi_over_a_task_domain_holds_the_trajectories_that_respect_it(robot, domain):
    q, qd, qdd = trajectories(robot)
    assert domain.contains(q, qd, qdd, atol=1e-12).all()
    assert np.abs(qdd).max() > 0.8 * QDDOT  # the acceleration bound is reached
    pldi = bound_pldi(robot, domain, samples=256, screen=16384, coverage=2000, progress=False)
    assert pldi.enclosure == "sampled" and pldi.coverage == 1.0
    assert coverage_along(pldi, robot, q, qd, qdd) == 1.0
    # the witnesses are points (q, qdot, u) of the domain: their u is the inverse dynamics of a box point
    w = pldi.witness_upper[0]
    assert domain.contains(w[:2], w[2:4], robot.acceleration(w[:2], w[2:4], w[4:]), atol=1e-9).all()
    # with half the acceleration bound the same trajectories leave the Jacobian set
    half = TaskDomain.from_robot(robot, pose=POSE, q_radius=RADIUS, qdot_max=QDOT, qddot_max=QDDOT / 2)
    smaller = bound_pldi(robot, half, samples=256, screen=16384, coverage=0, progress=False)
    assert coverage_along(smaller, robot, q, qd, qdd) < 0.95


def test_task_domain_shrinks_the_largest_frozen_pole_of_ur5():
    """Measured: ur5's largest real pole of A is ~34 rad/s over its torque box, ~5.6 around q = 0 (±0.3, 0.5, 2)."""
    ur5 = load_robot("ur5")

    def largest_pole(dom):
        q, qd, u = dom.sample(20000, method="uniform", seed=1)
        return np.linalg.eigvals(ur5.jacobians_batch(q, qd, u)[0]).real.max()

    box = largest_pole(Domain.from_robot(ur5))
    task = largest_pole(TaskDomain.from_robot(ur5, q_radius=0.3, qdot_max=0.5, qddot_max=2.0))
    assert box == pytest.approx(34.05, abs=1.5) and task == pytest.approx(5.63, abs=0.6)


def test_pose_from_the_srdf_or_the_midpoint_and_errors():
    panda = load_robot("panda")
    dom = TaskDomain.from_robot(panda, pose="default", q_radius=0.3, qdot_max=0.5, qddot_max=2)
    assert dom.pose_source == "SRDF pose 'default'" and np.allclose(dom.pose, panda.reference_poses["default"])
    assert np.all(dom.q_upper - dom.q_lower <= 0.6 + 1e-12)
    ur5 = load_robot("ur5")
    mid = TaskDomain.from_robot(ur5, qddot_max=1.0)
    assert mid.pose_source == "midpoint of the joint ranges" and np.allclose(
        mid.q_lower, Domain.from_robot(ur5).q_lower
    )
    with pytest.raises(DomainError, match=r"unknown pose 'nope' of panda \(poses: default\)"):
        TaskDomain.from_robot(panda, pose="nope", qddot_max=1)
    with pytest.raises(DomainError, match="--q-radius"):
        TaskDomain.from_robot(panda, q_radius=-0.1, qddot_max=1)
    with pytest.raises(DomainError, match="NaN"):
        TaskDomain.from_robot(panda, qddot_max=float("nan"))
    with pytest.raises(DomainError, match="--qddot-max"):
        TaskDomain.from_robot(panda, q_radius=0.1)
    with pytest.raises(DomainError, match="outside its range"):
        TaskDomain.from_robot(ur5, pose=[0, 0, 0, 0, 0, 9], qddot_max=1)


def test_certify_is_refused_and_files_round_trip(robot, domain, tmp_path):
    with pytest.raises(CertificationError, match="task domain"):
        bound_pldi(robot, domain, certify=True, progress=False)
    pldi = bound_pldi(robot, domain, samples=128, coverage=0, refine=False, screen=0, progress=False)
    pldi.save(tmp_path / "p.json")
    back = PLDI.load(tmp_path / "p.json")
    assert back.domain.kind == "task" and back.domain.to_dict() == domain.to_dict()
    np.testing.assert_allclose(back.domain.sample(8, seed=3)[2], domain.sample(8, seed=3)[2])
    assert json.loads((tmp_path / "p.json").read_text())["domain"]["kind"] == "task"
    assert domain_from_dict(Domain.from_robot(robot).to_dict()).kind == "box"


def test_cli_bounds_and_problem_scope_over_a_task_domain(robot, domain, capsys):
    from polyrob.cli import main
    from polyrob.pipeline import build_problem

    argv = ["bounds", "planar_2r", "--pose", "0.4,1.2", "--q-radius", "0.3", "--qdot-max", "0.5", "--qddot-max", "2"]
    assert main([*argv, "--samples", "128", "--coverage", "500", "--no-models"]) == 0
    out = capsys.readouterr().out
    assert "task around q = (0.4, 1.2): q ±0.3, qdot ±0.5, qddot ±2" in out and "coverage: 1.0000" in out
    assert main(["bounds", "planar_2r", "--pose", "elbow_up", "--qddot-max", "2"]) == 2
    assert "unknown pose 'elbow_up'" in capsys.readouterr().err
    prob = build_problem(
        robot,
        domain,
        uncertainty="box",
        bound_options={"samples": 128, "screen": 0, "verify_rounds": 0},
        progress=False,
    )
    scope = prob.scope()
    assert scope.domain.startswith("task domain around q = (0.4, 1.2) (±0.3 rad)")
    assert any(n.startswith("reflected rotor inertia: not modelled") for n in scope.notes)
    assert prob.description()["domain"]["kind"] == "task"


def test_validation_checks_the_accelerations_along_a_trajectory(robot, domain):
    from polyrob.validate.step_metrics import domain_check

    q, qd, qdd = trajectories(robot, n=1)
    t = np.arange(len(q)) * 0.01
    u = robot.inverse_dynamics(q, qd, qdd)
    assert domain_check(domain, robot, t, q.T, qd.T, u.T)[0] == ()
    exits, first, outside = domain_check(domain, robot, t, q.T, qd.T, robot.inverse_dynamics(q, qd, 2 * qdd).T)
    assert exits and all(e.startswith("qddot[") for e in exits) and 0 < outside < 1


def test_an_srdf_pose_outside_a_range_by_whole_turns_is_the_same_configuration():
    """kinova's SRDF poses give -pi/2 for a joint ranging over [0.33, 5.95]: the default task failed.
    An SRDF angle moved by whole turns is the same configuration; a pose the user gives is taken as given."""
    from polyrob.domains.task import _wrapped_into_range

    robot = load_robot("kinova")
    dom = TaskDomain.from_robot(robot, q_radius=0.2, qdot_max=0.5, qddot_max=2.0)
    assert "2 pi" in dom.pose_source and "2 pi" in dom.name
    assert np.all(dom.pose >= dom.q_lower) and np.all(dom.pose <= dom.q_upper)
    raw = np.asarray(next(iter(robot.reference_poses.values())), float)
    turns = np.round((dom.pose - raw) / (2 * np.pi))
    np.testing.assert_allclose(dom.pose - raw, 2 * np.pi * turns, atol=1e-12)
    assert np.any(turns != 0)
    pose, wrapped = _wrapped_into_range(
        [7.0, 0.5], np.array([-1.0, 0.0]), np.array([1.0, 1.0]), ("prismatic", "revolute")
    )
    assert wrapped == [] and pose[0] == 7.0  # a prismatic joint is never wrapped
    with pytest.raises(DomainError, match="outside its range"):
        TaskDomain.from_robot(robot, pose=np.full(robot.m, 100.5), q_radius=0.2, qdot_max=0.5, qddot_max=2.0)
