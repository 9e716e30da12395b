"""The domain box: defaults from limits, overrides, files, refusals, sampling."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import cached_robot

from polyrob import Domain, DomainError


def test_defaults_come_from_the_urdf_limits():
    robot = cached_robot("ur5")
    d = Domain.from_robot(robot)
    np.testing.assert_array_equal(d.q_lower, robot.position_lower)
    np.testing.assert_array_equal(d.qdot_upper, robot.velocity_limit)
    np.testing.assert_array_equal(d.u_lower, -robot.effort_limit)
    assert d.dim == 18


def test_continuous_joints_default_to_a_full_turn():
    d = Domain.from_robot(cached_robot("kinova"))
    assert d.q_lower[0] == -np.pi and d.q_upper[0] == np.pi


def test_overrides_and_scales():
    robot = cached_robot("planar_2r")
    d = Domain.from_robot(
        robot,
        q_range={"joint2": [-1.0, 2.0]},
        qdot_max=[
            3.0,
            5.0,
        ][0],
        u_max={"joint1": 0.0},
        qdot_scale=0.5,
    )
    np.testing.assert_allclose(d.q_lower, [-np.pi, -1.0])
    np.testing.assert_allclose(d.qdot_upper, [1.5, 1.5])
    np.testing.assert_allclose(d.u_upper, [0.0, 100.0])  # a user may pin u to zero


def test_domain_file_json_and_yaml(tmp_path):
    robot = cached_robot("double_pendulum")
    spec = {"q": [-3.0, 3.0], "qdot": {"joint1": 4, "joint2": [-2, 5]}, "u": 1.5}
    (tmp_path / "d.json").write_text(json.dumps(spec))
    (tmp_path / "d.yaml").write_text("q: [-3.0, 3.0]\nqdot: {joint1: 4, joint2: [-2, 5]}\nu: 1.5\n")
    for name in ("d.json", "d.yaml"):
        d = Domain.from_file(robot, tmp_path / name)
        np.testing.assert_allclose(d.q_upper, [3, 3])
        np.testing.assert_allclose(d.qdot_lower, [-4, -2])
        np.testing.assert_allclose(d.u_upper, [1.5, 1.5])
    assert Domain.from_dict(d.to_dict()).to_dict() == d.to_dict()


def test_zero_urdf_limits_are_refused_with_the_joint_and_the_fix():
    with pytest.raises(DomainError, match=r"joint 'joint1' has a zero position limit.*--q-range"):
        Domain.from_robot(cached_robot("double_pendulum"))


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(qdot_max=float("nan")), "NaN"),
        (dict(q_range={"joint1": [1.0, -1.0]}), "inverted"),
        (dict(q_range={"elbow": [0, 1]}), "unknown joint 'elbow'"),
        (dict(u_max="x"), "not numeric"),
        (dict(qdot_scale=-1.0), "scale"),
    ],
)
def test_bad_domains_are_refused(kwargs, message):
    with pytest.raises(DomainError, match=message):
        Domain.from_robot(cached_robot("planar_2r"), **kwargs)


def test_direct_construction_is_validated():
    with pytest.raises(DomainError, match="no finite velocity limit"):
        Domain(("a",), [0], [1], [np.nan], [1], [0], [0])


def test_missing_domain_file():
    with pytest.raises(DomainError, match="no such domain file"):
        Domain.from_robot(cached_robot("planar_2r"), "nope.json")


def test_sampling_stays_in_the_box_and_is_low_discrepancy():
    d = Domain.from_robot(cached_robot("planar_2r"))
    q, qdot, u = d.sample(1024, seed=0)
    assert d.contains(q, qdot, u).all()
    # a scrambled Sobol design covers each coordinate evenly
    counts, _ = np.histogram(q[:, 1], bins=8, range=(-np.pi, np.pi))
    assert counts.min() >= 120
    q, qdot, u = d.sample(16, seed=0, groups=("q",))
    assert np.all(qdot == 0) and np.all(u == 0)


def test_paper_domain_is_named_and_default_for_paper_2r():
    robot = cached_robot("paper_2r")
    d = Domain.from_robot(robot)
    assert d.name == "paper"
    assert np.all(d.u_upper == 0) and np.all(d.u_lower == 0)


# a new user's trial: the error names the input that is wrong, not the URDF


@pytest.mark.parametrize(
    "name, text",
    [
        ("d.json", '{"qdot": {"joint1": Infinity, "joint2": 3}}'),
        ("d.json", '{"qdot": {"joint1": "inf"}}'),
        ("d.yaml", "qdot:\n  joint1: .inf\n"),
        ("d.yaml", "qdot:\n  joint1: [-1, .inf]\n"),
    ],
)
def test_inf_in_a_domain_file_names_the_file_group_and_joint(tmp_path, name, text):
    (tmp_path / name).write_text(text)
    with pytest.raises(DomainError) as err:
        Domain.from_file(cached_robot("planar_2r"), tmp_path / name)
    message = str(err.value)
    assert message.startswith(str(tmp_path / name))
    assert "'qdot' entry of joint 'joint1'" in message and "not finite" in message
    assert "planar_2r.urdf" not in message and "no velocity limit" not in message


def test_a_zero_scale_names_the_scale_not_the_urdf():
    robot = cached_robot("planar_2r")
    for kwargs, option in ((dict(qdot_scale=0.0), "--qdot-scale 0"), (dict(u_scale=0.0), "--u-scale 0")):
        with pytest.raises(DomainError) as err:
            Domain.from_robot(robot, **kwargs)
        message = str(err.value)
        assert message.startswith(option) and "give a scale > 0" in message
        assert "urdf" not in message.lower()


@pytest.mark.parametrize(
    "spec, where",
    [
        ({"qdot": {"joint1": -4}}, "'qdot' entry of joint 'joint1'"),
        ({"u": -1.5}, "'u' entry (every joint)"),
        ({"q": {"joint2": -3}}, "'q' entry of joint 'joint2'"),
    ],
)
def test_a_negative_single_number_in_a_file_is_refused_as_the_cli_refuses_it(tmp_path, spec, where):
    path = tmp_path / "d.json"
    path.write_text(json.dumps(spec))
    with pytest.raises(DomainError) as err:
        Domain.from_file(cached_robot("planar_2r"), path)
    assert str(err.value).startswith(f"{path}: {where}: a bound must be >= 0")
    assert "give a range [lo, hi] otherwise" in str(err.value)


def test_from_dict_refuses_infinite_entries_by_name():
    data = Domain.from_robot(cached_robot("planar_2r")).to_dict()
    data["u"]["joint2"] = [-np.inf, 1.0]
    with pytest.raises(DomainError, match=r"run.json: 'u' entry of joint 'joint2': torque range \[-inf, 1\]"):
        Domain.from_dict(data, source="run.json")
