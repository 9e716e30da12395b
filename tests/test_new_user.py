"""A new user's trial of the polyrob command: each error names the input to change, in one line."""

from __future__ import annotations

import json

import pytest
from conftest import urdf_text

from polyrob.cli import main


def run(capfd, *argv):
    try:
        code = main(list(argv))
    except SystemExit as exc:
        code = exc.code
    out, err = capfd.readouterr()
    return code, out, err


def one_error_line(err: str) -> str:
    assert err.startswith("polyrob: error: ") and err.count("\n") == 1, err
    return err[len("polyrob: error: ") :].strip()


@pytest.mark.parametrize(
    "name, text", [("d.json", '{"qdot": {"joint1": Infinity}}'), ("d.yaml", "qdot:\n  joint1: .inf\n")]
)
def test_inf_in_a_domain_file_names_the_file_not_the_urdf(tmp_path, capfd, name, text):
    path = tmp_path / name
    path.write_text(text)
    code, _, err = run(capfd, "info", "planar_2r", "--domain", str(path))
    message = one_error_line(err)
    assert code == 2 and message.startswith(f"{path}: 'qdot' entry of joint 'joint1': velocity range inf is not finite")
    assert "urdf" not in message.lower()


def test_qdot_scale_zero_names_the_option(capfd):
    code, _, err = run(capfd, "info", "planar_2r", "--qdot-scale", "0")
    message = one_error_line(err)
    assert code == 2 and message.startswith("--qdot-scale 0") and "give a scale > 0" in message
    assert "urdf" not in message.lower()


def test_a_negative_bound_is_refused_by_the_file_as_by_the_option(tmp_path, capfd):
    path = tmp_path / "d.json"
    path.write_text(json.dumps({"qdot": {"joint1": -4}}))
    _, _, err_file = run(capfd, "info", "planar_2r", "--domain", str(path))
    _, _, err_option = run(capfd, "info", "planar_2r", "--qdot-max", "joint1=-4")
    from_file, from_option = one_error_line(err_file), one_error_line(err_option)
    assert from_file.startswith(f"{path}: 'qdot' entry of joint 'joint1': a bound must be >= 0 (it means")
    assert from_option.startswith("--qdot-max: a bound must be >= 0 (it means")
    assert "give a range" in from_file and "give a range" in from_option


def test_a_xacro_file_gets_one_line_and_nothing_from_the_cpp_parser(tmp_path, capfd):
    from test_robots import XACRO_ARM

    path = tmp_path / "arm.urdf.xacro"
    path.write_text(XACRO_ARM)
    code, out, err = run(capfd, "info", str(path))
    assert code == 2 and out == ""
    assert (
        one_error_line(err)
        == f"{path}: a xacro file must be expanded to URDF first: xacro {path} > {tmp_path / 'arm.urdf'}"
    )


def test_robots_all_says_what_a_refused_urdf_lacks(tmp_path, capfd, monkeypatch):
    import polyrob.model.robots as robots

    text = urdf_text(["base", "l1"], [("j1", "revolute", "base", "l1")]).replace('<joint name="j1"', "<joint")
    path = tmp_path / "nameless.urdf"
    path.write_text(text)
    monkeypatch.setattr(robots, "available_robots", lambda: [(str(path), "test")])
    code, out, err = run(capfd, "robots", "--all")
    assert code == 0 and err == ""
    row = out.splitlines()[1]
    assert "malformed URDF: a <joint> without a name attribute (the 1st <joint>)" in row
    assert "KeyError" not in out


def test_info_refuses_a_mimic_joint_then_prints_it_locked_as_asked(tmp_path, capfd):
    from test_robots import _MIMIC

    path = tmp_path / "mimic.urdf"
    path.write_text(_MIMIC)
    code, out, err = run(capfd, "info", str(path))
    assert code == 2 and out == ""
    assert err.strip().endswith("give --lock j3 to run on the robot with 'j3' fixed at its neutral position (or --lock j3,j2 to fix both)")
    assert len(err.strip().splitlines()) == 1
    code, out, err = run(capfd, "info", str(path), "--lock", "j3")
    assert code == 0 and err == ""
    header = out.splitlines()[:5]
    assert header[2] == "locked  j3"
    assert header[3].startswith("NOTE    mimic joint 'j3' follows actuated joint 'j2'") and "locked as asked" in header[3]
    code, out, _ = run(capfd, "info", str(path), "--lock", "j3", "--json")
    assert json.loads(out)["notes"][0].startswith("mimic joint 'j3' follows actuated joint 'j2'")


def test_a_prismatic_joint_is_a_slider_in_metres_and_newtons(tmp_path, capfd):
    text = urdf_text(["base", "l1", "l2"], [("j1", "revolute", "base", "l1"), ("slide", "prismatic", "l1", "l2")])
    path = tmp_path / "rp.urdf"
    path.write_text(text)
    code, out, _ = run(capfd, "info", str(path), "--json")
    info = json.loads(out)
    assert code == 0 and [j["kind"] for j in info["joints"]] == ["revolute", "prismatic"]
    assert info["domain"]["q"]["slide"] == [-1.0, 1.0]  # metres, from the URDF <limit>


def test_a_wrong_size_controller_file_is_refused_for_its_size_first(tmp_path, capfd):
    """A 1x1 controller made (it says) with other weights: the size is what the user hears first."""
    import control

    from polyrob.io.controller import save_controller

    path = tmp_path / "K.json"
    info = {"robot": "planar_2r", "weights": {"omega_b": [9.0, 9.0]}}
    save_controller(control.ss([[-1.0]], [[1.0]], [[1.0]], [[0.0]]), path, info=info)
    code, _, err = run(capfd, "analyze", "planar_2r", "--controller", str(path))
    line = one_error_line(err)
    assert code == 2 and "1 input(s) and 1 output(s)" in line and "needs 2" in line and "weight" not in line
