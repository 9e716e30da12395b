"""The polyrob command: listings, info, and one-line errors with a non-zero exit."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from conftest import BAD_URDFS

from polyrob.cli import main, parse_joint_values


def run(capsys, *argv):
    try:
        code = main(list(argv))
    except SystemExit as exc:  # argparse: --help, or a value of the wrong type
        code = exc.code
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
    code, out, _ = run(
        capsys,
        "info",
        "double_pendulum",
        "--q-range=-pi:pi",
        "--qdot-max",
        "5",
        "--u-max",
        "joint1=2,joint2=1",
        "--json",
    )
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
        (["synth", "--init", "no_such_K.json"], "no such controller file"),
        (["synth", "--init", "paper"], "--init paper starts a fixed structure"),
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


def test_robots_json_is_one_document(capsys):
    code, out, _ = run(capsys, "robots", "--json")
    rows = json.loads(out)
    assert code == 0 and {r["name"]: r["m"] for r in rows}["panda"] == 7


@pytest.mark.parametrize(
    "argv, option",
    [
        (["analyze", "--controller", "paper", "--mc", "0"], "--mc"),  # was ZeroDivisionError
        (["run", "--mc", "-2"], "--mc"),
        (["analyze", "--controller", "paper", "--omega", "1:0.1:5"], "--omega"),
        (["analyze", "--controller", "paper", "--omega", "0.1:inf:5"], "--omega"),
        (["analyze", "--controller", "paper", "--frozen-cells", "0"], "--frozen-cells"),
        (["analyze", "--controller", "paper", "--frozen-cells", "4"], "--frozen-cells"),  # no per-link set
        (["analyze", "--controller", "paper", "--cells-dir", "/tmp/x"], "--cells-dir"),  # without --frozen-cells
        (["synth", "--max-bandwidth", "--alphas", "0.5,-1"], "--alphas"),
        (["synth", "--max-bandwidth", "--scale-only", "bandwidth"], "--scale-only"),
        (["run", "--max-bandwidth", "--alphas", "0.5,-1"], "--alphas"),  # was: --max-bandwidth not an option of run
        (["synth", "--wb", "-1"], "--wb"),
        (["synth", "--ms", "nan"], "--ms"),
        (["synth", "--wb", "1,2,3"], "--wb"),
        (["synth", "--bandwidth-scale", "0"], "--bandwidth-scale"),
        (["synth", "--max-iter", "0"], "--max-iter"),
        (["synth", "--starts", "0"], "--starts"),
        (["synth", "--reduce-max-order", "0"], "--reduce-max-order"),
        (["bounds", "planar_2r", "--coverage", "-1"], "--coverage"),  # was ValueError: negative dimensions
        (["bounds", "planar_2r", "--samples", "-3"], "--samples"),  # was accepted silently
        (["bounds", "planar_2r", "--time-limit", "5"], "--certify"),
        (["bounds", "planar_2r", "--certify", "--rel-tol", "2"], "--rel-tol"),
        (["info", "--qdot-max", "-1"], "--qdot-max"),  # was silently [-1, 1]
        (["info", "--u-max", "inf"], "--u-max"),  # blamed the URDF
        (["info", "--q-range=-inf:inf"], "--q-range"),  # blamed the URDF
        (["info", "--q-range", "joint9=0:1"], "--q-range"),  # was "--q:"
        (["info", "--qdot-scale", "-1"], "--qdot-scale"),
        (["synth", "paper_2r", "--merge-symmetric"], "--uncertainty box"),
    ],
)
def test_every_numeric_option_is_validated_on_one_line(capsys, argv, option):
    code, out, err = run(capsys, *argv)
    assert code == 2 and out == ""
    assert err.startswith("polyrob: error: ") and err.count("\n") == 1, err
    assert option in err and "Traceback" not in err
    assert "URDF" not in err and "no torque limit" not in err and "--q:" not in err


def test_wrong_kind_errors_are_argument_errors_not_domain_errors():
    from polyrob.errors import ArgumentError, DomainError

    with pytest.raises(ArgumentError) as info:
        parse_joint_values("abc", "--qdot-max", ranges=False)
    assert isinstance(info.value, ValueError) and not isinstance(info.value, DomainError)


def test_help_texts_and_defaults(capsys):
    code, out, _ = run(capsys, "synth", "--help")
    assert code == 0
    flat = " ".join(out.split())
    assert "--starts STARTS fixed structure: optimisation starts (default: 5)" in flat
    assert "--reduce-max-order REDUCE_MAX_ORDER --reduce: largest controller order accepted (default: 20)" in flat
    assert "--quiet no progress bars" in flat
    code, out, _ = run(capsys, "bounds", "--help")
    flat = " ".join(out.split())
    assert "--time-limit TIME_LIMIT --certify:" in flat and "--rel-tol REL_TOL --certify:" in flat


@pytest.mark.parametrize(
    "argv, needle",
    [
        (["bounds", "planar_2r", "--coverage", "-1"], "--coverage"),
        (["info", "--u-max", "inf"], "--u-max"),
        (["analyze", "--controller", "paper", "--mc", "0"], "--mc"),
    ],
)
def test_console_script_one_line_errors(argv, needle):
    done = subprocess.run(["polyrob", *argv], capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and needle in done.stderr
    assert done.stderr.count("\n") == 1 and "Traceback" not in done.stderr and done.stdout == ""


def test_bounds_json_and_stage_line(tmp_path, capsys):
    code, out, err = run(
        capsys,
        "bounds",
        "paper_2r",
        "--domain",
        "paper",
        "--samples",
        "64",
        "--coverage",
        "0",
        "--json",
        "-o",
        str(tmp_path / "q.npz"),
    )
    doc = json.loads(out)
    assert code == 0 and err.startswith("[1/2] bounds: paper_2r")
    assert "[2/2] uncertainty models" in err
    # each model states its size and its coverage on fresh samples (1.0)
    models = doc["uncertainty_models"]
    assert set(models) == {"box", "lft"} and models["box"]["parameters"] == 10
    assert models["box"]["coverage"] == 1.0 and models["lft"]["coverage"] == 1.0
    assert models["lft"]["volume_over_polytope"] < 1 < models["box"]["volume_over_polytope"]
    names = [e["name"] for e in doc["entries"]]
    assert len(names) == 10 and doc["dropped_positions"] == ["joint1"]
    # -o q.npz: the JSON beside the arrays, not over them
    assert sorted(p.name for p in tmp_path.iterdir()) == ["q.json", "q.npz"]
    assert doc["files"] == [str(tmp_path / "q.json"), str(tmp_path / "q.npz")]
    meta = json.loads((tmp_path / "q.json").read_text())
    assert meta["format"] == "polyrob.pldi/1" and [e["name"] for e in meta["entries"]] == names


def test_export_writes_c_and_json(tmp_path, capsys):
    from polyrob.io.controller import save_controller
    from polyrob.plant.generalized import paper_controller

    K = save_controller(paper_controller(), tmp_path / "K.json")
    out = tmp_path / "ctrl"
    code, stdout, err = run(capsys, "export", str(K), "--rate", "1000", "--word-length", "35", "--json", "-o", str(out))
    doc = json.loads(stdout)
    assert code == 0 and err.startswith("[1/1] export")
    assert sorted(p.name for p in out.iterdir()) == ["controller.c", "controller.h", "controller.json"]
    assert doc["header"] == str(out / "controller.h")
    code, _, err = run(capsys, "export", str(K), "--rate", "0", "-o", str(out))
    assert code == 2 and "--rate" in err and err.count("\n") == 1


def test_certify_errors_name_the_cli_options(capsys):
    """Before: 'raise time_limit or rel_tol', options the CLI did not have."""
    code, _, err = run(
        capsys, "bounds", "finger_edu", "--qdot-max", "2", "--certify", "--time-limit", "0.01", "--quiet"
    )
    assert code == 2 and err.count("\n") == 1
    assert "time_limit" not in err and "rel_tol" not in err
    assert "--time-limit" in err
