"""The robot-uncertainty file (issue 38): refusals, round trip, drawn robots inside the set, and coverage."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pinocchio
import pytest
from conftest import cached_robot

from polyrob.cli import main
from polyrob.errors import ArgumentError
from polyrob.model.payload import PayloadRange, flange_frame
from polyrob.uncertainty_set.draw import TrueRobot, common_factor_covers, draw_true_robot, draw_true_robots
from polyrob.uncertainty_set.spec import (
    PARAMETER_NAMES,
    LinkInterval,
    RobotUncertainty,
    arm_length,
    link_names,
    physically_consistent,
    scaled_parameters,
)

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "uncertainty" / "panda.yaml"
CONTROLLER = Path(__file__).resolve().parent / "fixtures" / "planar_2r_ct_pid_K.json"  # any readable controller file


def run(capsys, *argv):
    try:
        code = main(list(argv))
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def write(tmp_path, doc, name="u.yaml"):
    import yaml

    path = tmp_path / name
    path.write_text(yaml.safe_dump(doc), encoding="utf-8")
    return str(path)


def one_error_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("polyrob: error: ")
    return lines[0]


# --------------------------------------------------------------------------- refusals through the CLI


@pytest.mark.parametrize(
    "doc, words",
    [
        ({"payload": {"mass": [-1.0, 1.5]}}, "payload.mass: must be >= 0, got -1"),
        ({"payload": {"mass": [2.0, 1.0]}}, "payload.mass: [2, 1] has its lower bound above its upper bound"),
        ({"payload": {"mass": [0.0, float("nan")]}}, "payload.mass: nan is not a finite number"),
        (
            {"payload": {"mass": [0.0, 1.0], "com_ball": {"centre": [0, 0, 0], "radius": 2.0}}},
            "farther than ur5's arm is long (1.24 m)",
        ),
        (
            {"payload": {"mass": [0.0, 1.0], "com_box": {"lower": [0, 0, 0], "upper": [1.0, 1.0, 0.5]}}},
            "may lie 1.5 m from the flange",
        ),
        ({"links": {"intervals": {"panda_link3": {k: [0, 1] for k in PARAMETER_NAMES}}}}, "unknown link 'panda_link3'"),
        ({"friction": {"joint9": {"viscous": [0, 1], "coulomb": 0.5}}}, "unknown joint 'joint9' of ur5"),
        ({"links": {"error_percent": 120}}, "links.error_percent: give a percentage in [0, 100), got 120"),
    ],
)
def test_file_refusals_are_one_line_exit_2(capsys, tmp_path, doc, words):
    path = write(tmp_path, doc)
    code, out, err = run(capsys, "synth", "ur5", "--robot-uncertainty", path)
    line = one_error_line(err)
    assert code == 2 and out == ""
    assert line.startswith(f"polyrob: error: --robot-uncertainty {path}: ")
    assert words in line
    assert "not yet certified" not in line  # refused for the file's content, before the set's status


def test_a_set_the_model_cannot_carry_is_refused_with_its_measured_reason(capsys, tmp_path, light_models_once):
    # panda with its rated payload (0-3 kg) whose CoM lies within 0.3 m: measured before any bounds are taken
    # (measured once: analyze poses the same loop and default task as synth, light_models_once keeps synth's)
    import yaml

    doc = yaml.safe_load(EXAMPLE.read_text(encoding="utf-8"))
    doc["payload"]["mass"] = [0.0, 3.0]
    doc["payload"]["com_ball"]["radius"] = 0.3
    path = write(tmp_path, doc)
    for argv in (
        ("synth", "panda", "--robot-uncertainty", path),
        ("analyze", "panda", "--controller", str(CONTROLLER), "--robot-uncertainty", path),
    ):
        code, out, err = run(capsys, *argv)
        # refused before the default task's log line is said (a progress line may come while it is measured)
        line = one_error_line("\n".join(x for x in err.splitlines() if not x.startswith("progress:")))
        assert "default task of" not in err and code == 2 and out == "", argv
        assert "not carried on panda's default task: the relative inertia error is too large" in line, argv
        # the set is echoed as a phrase
        assert "per-link ±10 %" in line and "payload 0-3 kg, centre of mass within 0.3 m" in line, argv
        assert "panda_link8" in line and "Coulomb <= 1.279 N m" in line, argv


def test_a_set_is_carried_on_computed_torque_only_and_not_twice_and_by_the_batch(capsys):
    code, _, err = run(capsys, "bounds", "panda", "--robot-uncertainty", str(EXAMPLE), "--inner", "gravity")
    line = one_error_line(err)
    assert code == 2 and "carried on a computed-torque inner layer only" in line and "not --inner gravity" in line
    code, _, err = run(capsys, "synth", "ur5", "--link-error", "10", "--payload-mass", "0:1")
    assert code == 2 and "--payload-mass 0:1 would state the uncertainty twice" in one_error_line(err)
    # the batch gives every job the set; a job poses it on its default task with the inner-links model
    from argparse import Namespace

    from polyrob.cli.batch import with_robot_uncertainty
    from polyrob.fleet.jobs import as_job, job_robot_and_domain

    args = Namespace(robot_uncertainty=None, link_error="10")
    (job,) = with_robot_uncertainty(args, [{"robot": "ur5"}])
    robot, domain, task = job_robot_and_domain(as_job(job))
    assert type(robot).__name__ == "SetLoopRobot" and robot.inner == "computed-torque" and task is not None
    assert robot.uncertainty.link_error == 0.1 and "per-link ±10 %" in robot.words()
    assert type(domain).__name__ == "TaskDomain"
    # a two-joint robot has no default task: its row says so (the set needs that task's computed-torque layer)
    (job,) = with_robot_uncertainty(args, [{"robot": "planar_2r"}])
    with pytest.raises(ArgumentError, match="planar_2r has 2 joints and no default task"):
        job_robot_and_domain(as_job(job))
    (job,) = with_robot_uncertainty(args, [{"robot": "ur5", "model_error": 0.1}])
    with pytest.raises(ArgumentError, match="holds the link errors and the payload: drop model_error$"):
        job_robot_and_domain(as_job(job))


def test_link_error_option(capsys):
    code, _, err = run(capsys, "synth", "ur5", "--link-error", "10", "--inner", "gravity")
    assert code == 2 and "--link-error 10 (per-link ±10 %" in one_error_line(err)
    code, _, err = run(capsys, "batch", "ur5", "--link-error", "-1")
    assert code == 2 and one_error_line(err).endswith("--link-error: give a percentage in [0, 100), got '-1'")
    code, _, err = run(capsys, "bounds", "ur5", "--link-error", "x")
    assert code == 2 and "--link-error: 'x' is not a number" in one_error_line(err)


def test_a_file_for_another_robot_is_refused(capsys):
    code, _, err = run(capsys, "bounds", "ur5", "--robot-uncertainty", str(EXAMPLE))
    assert code == 2 and "the file is for robot 'panda', not 'ur5'" in one_error_line(err)


# --------------------------------------------------------------------------- the file


def test_round_trip_of_the_example_through_yaml_and_json(tmp_path):
    spec = RobotUncertainty.from_file(EXAMPLE)
    assert spec.link_error == pytest.approx(0.10)
    assert spec.payload.mass_upper == 1.5 and spec.payload.com_radius == 0.1
    assert [f.coulomb for f in spec.friction] == [0.546, 0.872, 0.641, 1.279, 0.839, 0.303, 0.565]
    for name in ("again.yaml", "again.json"):
        spec.write(tmp_path / name)
        back = RobotUncertainty.from_file(tmp_path / name)
        assert back == spec
        assert back.to_dict() == spec.to_dict()
    assert json.loads((tmp_path / "again.json").read_text())["links"] == {"error_percent": 10.0}


def test_bound_fills_urdf_friction_and_notes_a_payload_above_the_rated_one():
    xarm = cached_robot("xarm7")
    spec = RobotUncertainty(link_error=0.1).bound(xarm)
    # xarm7's URDF: <dynamics damping="10" friction="1"/> on joint1: viscous 10 ± 20 %
    first = spec.friction[0]
    assert (first.joint, first.viscous, first.coulomb, first.source) == ("joint1", (8.0, 12.0), 1.0, "URDF <dynamics>")
    panda = cached_robot("panda")
    heavy = RobotUncertainty.from_dict({"payload": {"mass": [0, 4]}}).bound(panda)
    assert heavy.rated_payload.kg == 3.0
    assert heavy.notes == ("payload up to 4 kg exceeds the rated 3 kg (Franka Emika Panda datasheet: 3 kg)",)
    assert RobotUncertainty().bound(cached_robot("so101")).rated_payload.kg is None


def test_links_and_reach_of_an_arm():
    ur5 = cached_robot("ur5")
    assert list(link_names(ur5)) == [
        "shoulder_link",
        "upper_arm_link",
        "forearm_link",
        "wrist_1_link",
        "wrist_2_link",
        "wrist_3_link",
    ]
    # 0.136 + 0.425 + 0.392 + 0.093 + 0.095 + 0.0823 (tool0), rounded
    assert arm_length(ur5) == pytest.approx(1.24, abs=0.01)


def test_a_ten_parameter_box_with_non_physical_vertices_is_noted_and_its_draws_are_rigid_bodies():
    ur5 = cached_robot("ur5")
    j = link_names(ur5)["forearm_link"]
    theta = np.asarray(ur5.model.inertias[j].toDynamicParameters())
    box = LinkInterval("forearm_link", tuple(theta * 0.8 - 1e-4), tuple(theta * 1.2 + 1e-4))
    spec = RobotUncertainty(links=(box,)).bound(ur5)
    assert (
        len(spec.notes) == 1 and spec.notes[0].startswith("forearm_link: ") and "of 1024 box vertices" in spec.notes[0]
    )
    rng = np.random.default_rng(3)
    for _ in range(20):
        drawn = draw_true_robot(ur5, spec, rng).link_parameters["forearm_link"]
        assert physically_consistent(drawn)
        assert np.all(drawn >= np.array(box.lower)) and np.all(drawn <= np.array(box.upper))
    # a box whose centre is no rigid body (negative inertia) is refused
    lo, hi = np.array(box.lower), np.array(box.upper)
    lo[4], hi[4] = -2.0, -1.0
    with pytest.raises(ArgumentError, match="forearm_link: the centre of its box is not a rigid body"):
        RobotUncertainty(links=(LinkInterval("forearm_link", tuple(lo), tuple(hi)),)).bound(ur5)


# --------------------------------------------------------------------------- drawn robots


def test_drawn_robots_lie_inside_the_per_link_intervals_and_the_payload_set():
    panda = cached_robot("panda")
    spec = RobotUncertainty.from_file(EXAMPLE).bound(panda)
    nominal = {name: np.asarray(panda.model.inertias[j].toDynamicParameters()) for name, j in link_names(panda).items()}
    hull = spec.link_box(panda)
    last = panda.model.njoints - 1
    _, placement = flange_frame(panda)
    factors = []
    for true in draw_true_robots(panda, spec, 40, seed=1):
        assert isinstance(true, TrueRobot)
        for name, j in link_names(panda).items():
            drawn = np.asarray(true.link_parameters[name])
            lo, hi = hull[name]
            assert np.all(drawn >= lo - 1e-12) and np.all(drawn <= hi + 1e-12), name
            assert physically_consistent(drawn)
            # the three factors: mass, first moment (one vector factor), inertia about the CoM
            a = drawn[0] / nominal[name][0]
            b = np.linalg.norm(drawn[1:4]) / np.linalg.norm(nominal[name][1:4])
            assert 0.9 - 1e-12 <= a <= 1.1 + 1e-12 and 0.9 - 1e-12 <= b <= 1.1 + 1e-12
            factors.append(a)
            if j != last:  # Pinocchio's own model holds the drawn parameters (the last link carries the payload)
                assert np.allclose(true.model.inertias[j].toDynamicParameters(), drawn)
        # the payload: the last body minus the drawn link is the payload placed at the flange
        payload = true.model.inertias[last] - pinocchio.Inertia.FromDynamicParameters(
            true.link_parameters["panda_link7"]
        )
        assert payload.mass == pytest.approx(true.payload_mass, abs=1e-9)
        assert 0.0 <= true.payload_mass <= 1.5
        com = placement.actInv(pinocchio.SE3(np.eye(3), payload.lever)).translation
        assert np.allclose(com, true.payload_com, atol=1e-9)
        assert np.linalg.norm(com) <= 0.1 + 1e-12
        assert np.all((true.viscous >= 0.0024) & (true.viscous <= 0.0036))
        assert np.allclose(true.robot.damping, true.viscous)
    # independent and spread over the range, not at its corners
    assert 0.9 < min(factors) < 0.92 and 1.08 < max(factors) < 1.1
    assert np.std(factors) == pytest.approx(0.2 / np.sqrt(12), rel=0.15)


def test_the_common_factor_model_does_not_cover_a_per_link_draw():
    ur5 = cached_robot("ur5")
    assert not np.any(ur5.model.armature)  # M is the links' alone: a common factor scales all of it
    names = list(link_names(ur5))

    def robot_with(factors):
        model = ur5.model.copy()
        params = {}
        for name, f in zip(names, factors):
            j = link_names(ur5)[name]
            params[name] = scaled_parameters(model.inertias[j].toDynamicParameters(), f, f, f)
            model.inertias[j] = pinocchio.Inertia.FromDynamicParameters(params[name])
        from dataclasses import replace

        return TrueRobot(replace(ur5, model=model), params, 0.0, np.zeros(3), ur5.damping.copy(), np.zeros(ur5.m))

    def spread_from_a_multiple_of_identity(true, q):
        ratio = np.linalg.solve(true.robot.mass_matrix(q), ur5.mass_matrix(q))  # M_true^-1 M_hat
        s = np.trace(ratio) / ur5.m
        return np.linalg.norm(ratio - s * np.eye(ur5.m)) / np.linalg.norm(ratio), s

    q = np.array([0.3, -1.2, 1.0, -0.5, 0.7, 0.2])
    common = robot_with([1.05] * 6)
    spread, s = spread_from_a_multiple_of_identity(common, q)
    assert spread < 1e-10 and s == pytest.approx(1 / 1.05)
    assert common_factor_covers(common, ur5, model_error=0.1).covered

    opposite = robot_with([1.0, 1.1, 0.9, 1.0, 1.0, 1.0])  # upper arm heavier, forearm lighter
    spread, _ = spread_from_a_multiple_of_identity(opposite, q)
    assert spread > 1e-2
    verdict = common_factor_covers(opposite, ur5, model_error=0.1)
    assert not verdict.covered and verdict.reason.startswith("no one factor fits the links")

    # and drawn at random from the per-link set: none is covered, a payload off the flange's box neither
    drawn = draw_true_robots(ur5, RobotUncertainty(link_error=0.1), 10, seed=4)
    assert not any(common_factor_covers(t, ur5, model_error=0.1).covered for t in drawn)
    off_axis = RobotUncertainty.from_dict({"payload": {"mass": [0.5, 1.5], "com_ball": {"radius": 0.1}}})
    carried = draw_true_robots(ur5, off_axis, 5, seed=5)
    at_flange = PayloadRange(0.0, 1.5)
    assert all(
        common_factor_covers(t, ur5, model_error=0.1, payload=at_flange).reason.startswith("the payload is outside")
        for t in carried
    )
