"""The default task of an arm (polyrob.domains.default_task): who gets it, what it is, how to leave it.

A few seconds: no bounds are computed here (the CLI tests read ``info --json``).
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from conftest import cached_robot

from polyrob.cli import main
from polyrob.domains.default_task import DEFAULT_TASK, DefaultTask, applies_to, default_task_domain, default_task_robot
from polyrob.domains.task import TaskDomain
from polyrob.domains.torque_box import Domain
from polyrob.fleet.jobs import Job, job_robot_and_domain


def _info(capsys, *argv):
    code = main(["info", *argv, "--json"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    return json.loads(captured.out), captured.err


def test_only_arms_of_three_joints_or_more_get_it():
    assert not applies_to(1) and not applies_to(2) and applies_to(3) and applies_to(7)


def test_the_default_task_is_a_task_domain_around_the_srdf_pose_with_computed_torque():
    panda = cached_robot("panda")
    arm = default_task_robot(panda)
    dom = default_task_domain(arm)
    assert isinstance(dom, TaskDomain) and dom.pose_source == "SRDF pose 'default'"
    assert np.allclose(dom.q_upper - dom.pose, DEFAULT_TASK.q_radius)  # the pose is well inside panda's limits
    assert np.allclose(dom.qdot_upper, DEFAULT_TASK.qdot_max) and np.allclose(dom.qddot_upper, DEFAULT_TASK.qddot_max)
    assert arm.inner == "computed-torque" and arm.model_error == pytest.approx(DEFAULT_TASK.model_error)
    assert "computed-torque" in arm.words() and "±10 %" in arm.words()


def test_computed_torque_with_one_inertia_factor_leaves_b_equal_to_the_identity_over_the_factor():
    # the true links are the model's times s: M = s M_hat, h = s h_hat (no damping, no armature on ur5),
    # so qddot = v / s + (1/s - 1) M_hat^-1 h_hat: B = I / s exactly, A moves with the same 1/s (affine in it);
    # without the default payload (a payload moves M by another scalar: polyrob.plant.models.inner_factors)
    arm = default_task_robot(cached_robot("ur5"), DefaultTask(payload_fraction=0.0))
    dom = default_task_domain(arm)
    q, qd, u = dom.sample(16, method="uniform", seed=3)
    for v in arm.variants():
        s = 1.0 if v.scenario == "nominal" else float(v.scenario.split("x ")[-1])
        A, B = v.jacobians_batch(q, qd, u)
        assert np.allclose(B[:, 6:, :], np.eye(6) / s, atol=1e-9)
        if s == 1.0:
            assert np.allclose(A[:, 6:, :], 0.0, atol=1e-9)  # an exact model: a double integrator
        else:
            assert np.abs(A[:, 6:, :6]).max() > 1e-3  # the gravity mismatch stays


def test_synth_options_pose_the_default_task_and_say_so(capsys):
    doc, err = _info(capsys, "ur5")
    assert "default task of ur5" in err and "--torque-box" in err
    assert doc["domain"]["kind"] == "task"


@pytest.mark.parametrize("argv", [["--torque-box"], ["--qdot-max", "1"], ["--model-error", "5"]])
def test_any_domain_or_model_error_option_keeps_todays_behaviour(capsys, argv):
    doc, err = _info(capsys, "ur5", *argv)
    assert "default task" not in err
    assert doc["domain"].get("kind", "box") != "task"


@pytest.mark.parametrize("layer", ["gravity", "none"])  # none: the paper's single layer
def test_an_inner_layer_alone_keeps_the_default_task_with_that_layer(capsys, layer):
    doc, err = _info(capsys, "ur5", "--inner", layer)
    assert "default task of ur5" in err and f"inner layer {layer}," in err
    assert doc["domain"]["kind"] == "task"
    robot, dom, task = job_robot_and_domain(Job(robot="ur5", inner=layer))
    assert task == replace(DEFAULT_TASK, inner=layer) and isinstance(dom, TaskDomain)
    assert robot.inner == layer and robot.model_error == 0.1 and robot.payload.mass_upper > 0.1


def test_a_payload_rides_on_the_default_task(capsys):
    doc, err = _info(capsys, "ur5", "--payload-mass", "0:0.5")
    assert "default task of ur5" in err and "payload 0:0.5 kg at the flange (given)" in err
    assert "% of the link mass" not in err  # the given range replaces the task's own
    assert doc["domain"]["kind"] == "task" and doc["inner"]["payload"]["mass"] == [0.0, 0.5]
    robot, dom, task = job_robot_and_domain(Job(robot="ur5", payload_mass="0:0.5"))
    assert task == DEFAULT_TASK and isinstance(dom, TaskDomain) and robot.inner == "computed-torque"
    assert (robot.payload.mass_lower, robot.payload.mass_upper) == (0.0, 0.5) and robot.model_error == 0.1


def test_two_joint_robots_keep_the_torque_box(capsys):
    doc, err = _info(capsys, "planar_2r")
    assert "default task" not in err and doc["domain"].get("kind", "box") != "task"


def test_fleet_jobs_use_the_same_default():
    robot, dom, task = job_robot_and_domain(Job(robot="ur5"))
    assert task == DEFAULT_TASK and isinstance(dom, TaskDomain) and robot.inner == "computed-torque"
    robot, dom, task = job_robot_and_domain(Job(robot="planar_2r"))
    assert task is None and isinstance(dom, Domain)
    robot, dom, task = job_robot_and_domain(Job(robot="ur5", torque_box=True))
    assert task is None and isinstance(dom, Domain) and not hasattr(robot, "inner")
    robot, dom, task = job_robot_and_domain(Job(robot="ur5", q_radius=0.1, qddot_max=1.0, inner="gravity"))
    assert task is None and isinstance(dom, TaskDomain) and robot.inner == "gravity"
    assert np.allclose(dom.q_upper - dom.q_lower, 0.2)


def test_a_task_words_say_every_figure():
    task = DefaultTask(
        q_radius=0.1, qdot_max=1.0, qddot_max=3.0, inner="gravity", model_error=0.0, payload_fraction=0.05
    )
    assert task.words() == (
        "task ±0.1 rad around the reference pose, |qdot| <= 1 rad/s, |qddot| <= 3 rad/s^2, inner layer gravity, "
        "payload 0-5 % of the link mass at the flange"
    )
    assert "payload" not in DefaultTask(payload_fraction=0.0).words()


def test_a_task_payload_is_a_mass_range_at_the_flange_scaled_by_the_arm():
    ur5 = cached_robot("ur5")
    task = DefaultTask(payload_fraction=0.05)
    payload = task.payload_range(ur5)
    total = sum(Y.mass for Y in ur5.model.inertias[1:])
    assert (payload.mass_lower, payload.mass_upper) == (0.0, pytest.approx(0.05 * total))
    assert payload.com_lower == payload.com_upper == (0.0, 0.0, 0.0) and payload.frame == "tool0"
    arm = default_task_robot(ur5, task)
    assert arm.payload == payload and len(arm.variants()) == 5  # nominal + {0, max} x {0.9, 1.1}
    # the default task carries 1 % of the arm's link mass; a task without one says so
    assert DEFAULT_TASK.payload_range(ur5).mass_upper == pytest.approx(0.01 * total)
    assert default_task_robot(ur5).payload == DEFAULT_TASK.payload_range(ur5)
    assert DefaultTask(payload_fraction=0.0).payload_range(ur5) is None


def test_batch_task_and_inner_options_reach_every_job():
    from polyrob.cli import PolyrobParser
    from polyrob.cli import batch as batch_cli
    from polyrob.errors import ArgumentError

    parser = PolyrobParser(prog="polyrob")
    batch_cli.register(parser.add_subparsers(dest="command", required=True, parser_class=PolyrobParser))
    argv = [
        "batch",
        "ur5",
        "panda",
        "--q-radius",
        "0.1",
        "--qddot-max",
        "1",
        "--inner",
        "gravity",
        "--model-error",
        "5",
    ]
    jobs = batch_cli.jobs_from_args(parser.parse_args(argv))
    assert [j["robot"] for j in jobs] == ["ur5", "panda"]
    assert all(
        (j["q_radius"], j["qddot_max"], j["inner"], j["model_error"]) == (0.1, 1.0, "gravity", 0.05) for j in jobs
    )
    assert "torque_box" not in jobs[0] and "pose" not in jobs[0]
    assert batch_cli.jobs_from_args(parser.parse_args(["batch", "ur5", "--torque-box"]))[0]["torque_box"] is True
    with pytest.raises(ArgumentError, match="--model-error"):
        batch_cli.jobs_from_args(parser.parse_args(["batch", "ur5", "--model-error", "120"]))


def test_the_model_coverage_of_an_inner_loop_is_measured_on_the_inner_loop_and_its_true_robots():
    # the PLDI remembers the robot it was bounded for (an inner loop), so the uncertainty model's
    # coverage check draws the inner loop's Jacobians, over its true robots, not the bare robot's
    from polyrob import bound_pldi
    from polyrob.model.inner import inner_loop
    from polyrob.plant.coverage import coverage_fraction
    from polyrob.plant.uncertainty import uncertain_plant

    arm = inner_loop(cached_robot("planar_2r"), "computed-torque", model_error=0.1)
    dom = TaskDomain.from_robot(arm, pose=[0.3, 1.2], q_radius=0.2, qdot_max=0.5, qddot_max=1.0)
    pldi = bound_pldi(arm, dom, samples=64, coverage=0, progress=False, workers=1, screen=0, verify_rounds=0)
    assert pldi.robot is arm
    unc = uncertain_plant(pldi, model="box", coverage=500)
    assert unc.coverage == 1.0
    # the bare robot's Jacobians (no inner layer) are not those of this problem: far outside
    assert coverage_fraction(unc, cached_robot("planar_2r"), dom, 200) < 0.5


def _ct_pldi(error=0.1):
    from polyrob import bound_pldi
    from polyrob.model.inner import inner_loop

    arm = inner_loop(cached_robot("planar_2r"), "computed-torque", model_error=error)
    dom = TaskDomain.from_robot(arm, pose=[0.3, 1.2], q_radius=0.3, qdot_max=1.0, qddot_max=2.0)
    return arm, dom, bound_pldi(arm, dom, samples=64, coverage=0, progress=False, workers=1, screen=0, verify_rounds=0)


def test_the_inner_gain_model_holds_the_computed_torque_loop_with_one_parameter():
    from polyrob.plant.coverage import coverage_fraction
    from polyrob.plant.models.inner_gain import gain_range
    from polyrob.plant.uncertainty import uncertain_plant

    arm, dom, pldi = _ct_pldi(0.1)
    unc = uncertain_plant(pldi, model="auto", coverage=600, volume_samples=0)
    assert unc.model == "inner-gain" and unc.n_params == 1 and unc.coverage == 1.0
    assert unc.block_structure[-1].tolist() == [-2, 0]  # eps, repeated on both joints
    assert gain_range(0.1) == pytest.approx((1 / 1.1 - 1, 1 / 0.9 - 1))
    # a computed-torque loop with a larger model error than the model was built for leaves it
    wider = default_task_robot(cached_robot("planar_2r"), DefaultTask(model_error=0.3))
    assert (
        coverage_fraction(
            unc, wider, TaskDomain.from_robot(wider, pose=[0.3, 1.2], q_radius=0.3, qdot_max=1.0, qddot_max=2.0), 600
        )
        < 0.9
    )


def test_auto_falls_back_to_axes_where_the_inner_gain_model_does_not_apply():
    from polyrob import bound_pldi
    from polyrob.model.inner import inner_loop
    from polyrob.plant.models.inner_gain import applies
    from polyrob.plant.uncertainty import uncertain_plant

    assert "computed-torque" in applies(inner_loop(cached_robot("planar_2r"), "gravity", model_error=0.1))
    assert "model error" in applies(inner_loop(cached_robot("planar_2r"), "computed-torque"))
    arm = inner_loop(cached_robot("planar_2r"), "gravity", model_error=0.1)
    dom = TaskDomain.from_robot(arm, pose=[0.3, 1.2], q_radius=0.3, qdot_max=1.0, qddot_max=2.0)
    pldi = bound_pldi(arm, dom, samples=64, coverage=0, progress=False, workers=1, screen=0, verify_rounds=0)
    assert uncertain_plant(pldi, model="auto", coverage=0, volume_samples=0).model != "inner-gain"


def test_the_default_task_brings_the_automatic_weights_of_its_domain_and_the_users_win():
    from types import SimpleNamespace

    from polyrob.cli.common import WEIGHT_OPTIONS, hyperparameters_from_args
    from polyrob.fleet.autoweights import automatic_hyperparameters

    robot = default_task_robot(cached_robot("ur5"))
    domain = default_task_domain(robot)
    args = SimpleNamespace(
        default_task=DEFAULT_TASK.words(), bandwidth_scale=1.0, **{k: None for k, _ in WEIGHT_OPTIONS}
    )
    assert hyperparameters_from_args(6, args, domain) == automatic_hyperparameters(6, domain)
    # level 2.5 / 1.998 on this task: omega_b of joint 1 is the paper's 0.5 times it
    assert hyperparameters_from_args(6, args, domain)["omega_b"][0] == pytest.approx(0.5 * 2.5 / 1.998, rel=2e-3)
    args.bandwidth_scale, args.M_s = 2.0, "2.5"
    h = hyperparameters_from_args(6, args, domain)
    assert h["omega_b"] == pytest.approx([2 * w for w in automatic_hyperparameters(6, domain)["omega_b"]])
    assert h["M_s"] == (2.5,) * 6
    args.default_task = None  # no default task: the paper's joint-1 weights on every joint
    assert hyperparameters_from_args(6, args, domain)["omega_b"] == (1.0,) * 6


def test_the_lft_model_refuses_an_inner_loop():
    """talos' computed-torque loop (rotor inertia: inner-gain does not apply) fell to `lft`, a model of one
    robot's M(q)^-1: coverage 1/3 of the loop's three true robots, so no bandwidth could certify it."""
    from types import SimpleNamespace

    from polyrob.errors import NotApplicable
    from polyrob.model.inner import inner_loop
    from polyrob.plant.models.inertia_lft import inertia_lft_plant

    arm = inner_loop(cached_robot("planar_2r"), "computed-torque", model_error=0.1)
    with pytest.raises(NotApplicable, match="inner closed loop"):
        inertia_lft_plant(SimpleNamespace(robot=arm, domain=None), robot=arm)
