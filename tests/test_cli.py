"""The polyrob command: listings, info, and one-line errors with a non-zero exit."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from polyrob.cli import main, parse_joint_values

from conftest import BAD_URDFS


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_robots_lists_names_with_joint_counts(capsys):
    code, out, _ = run(capsys, "robots")
    assert code == 0
    rows = {line.split()[0]: line.split()[1] for line in out.splitlines()[1:]}
    assert rows["planar_2r"] == "2" and rows["panda"] == "7" and rows["kinova"] == "6"
    assert "solo12" not in rows  # a tree is not listed unless --all


def test_info_default_robot_json(capsys):
    code, out, _ = run(capsys, "info", "--json")
    assert code == 0
    info = json.loads(out)
    assert info["name"] == "planar_2r" and info["m"] == 2
    M = np.array(info["neutral"]["M"])
    np.testing.assert_allclose(M, [[60.625, 19.375], [19.375, 13.125]])
    assert info["domain"]["q"]["joint2"] == pytest.approx([-np.pi, np.pi])


def test_info_with_domain_options(capsys):
    code, out, _ = run(capsys, "info", "double_pendulum", "--q-range=-pi:pi", "--qdot-max", "5", "--u-max", "joint1=2,joint2=1", "--json")
    assert code == 0
    d = json.loads(out)["domain"]
    assert d["u"]["joint2"] == [-1.0, 1.0] and d["qdot"]["joint1"] == [-5.0, 5.0]


@pytest.mark.parametrize("kind", sorted(BAD_URDFS))
def test_bad_urdf_gives_one_line_and_exit_2(capsys, write_urdf, kind):
    path = write_urdf(BAD_URDFS[kind], f"{kind}.urdf")
    code, out, err = run(capsys, "info", str(path))
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("polyrob: error: ") and str(path) in err
    assert "Traceback" not in err


@pytest.mark.parametrize(
    "argv, needle",
    [
        (["info", "double_pendulum"], "zero position limit"),
        (["info", "--qdot-max", "nan"], "NaN"),
        (["info", "--q-range=2:1"], "inverted"),
        (["info", "--q-range", "joint9=0:1"], "unknown joint"),
        (["info", "robotron"], "unknown robot"),
        (["info", "panda", "--lock", "nope"], "cannot lock"),
    ],
)
def test_user_errors_are_one_line(capsys, argv, needle):
    code, _, err = run(capsys, *argv)
    assert code == 2 and needle in err and err.count("\n") == 1


def test_console_script_exit_status():
    done = subprocess.run(
        [sys.executable, "-m", "polyrob.cli", "info", "double_pendulum"], capture_output=True, text=True
    )
    assert done.returncode == 2
    assert done.stderr.strip().count("\n") == 0 and "zero position limit" in done.stderr


def test_parse_joint_values():
    assert parse_joint_values("4", "--qdot-max", ranges=False) == 4.0
    assert parse_joint_values("4,10", "--qdot-max", ranges=False) == [[-4.0, 4.0], [-10.0, 10.0]]
    assert parse_joint_values("j2=-pi:pi", "--q-range", ranges=True) == {"j2": [-np.pi, np.pi]}
    assert parse_joint_values("-2pi:0.5", "--q-range", ranges=True) == [-2 * np.pi, 0.5]
