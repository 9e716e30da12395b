"""Traceability: controller files, PLDI files, certificates and reports carry polyrob's version, the libraries'
versions, the command, the date and the hashes of the URDF and of the problem's inputs; ``analyze`` names a
robot or a problem that differs from what a controller file was certified for.

One cheap synthesis (planar_2r on a PLDI file, one D-K iteration: its certificate is VIOLATED, which does not
matter here) is shared by the module.
"""

from __future__ import annotations

import datetime
import functools
import hashlib
import json
import platform
import shutil

import numpy as np
import pytest

import polyrob
from polyrob.cli import main
from polyrob.io.controller import load_controller, save_controller
from polyrob.model.robots import bundled_urdf_dir
from polyrob.provenance import DEPENDENCIES, Provenance, differences

SYNTH = ["--max-iter", "1", "--uncertainty", "box", "--complex", "--quiet"]
ANALYZE = ["--uncertainty", "box", "--mc", "1", "--no-time-varying", "--no-moving", "--omega", "0.1:10:4", "--quiet"]
PLANAR_URDF = bundled_urdf_dir() / "planar_2r.urdf"
WHEN = datetime.datetime(2026, 11, 28, 1, 2, 3, tzinfo=datetime.timezone.utc)


def sha256_of(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def canonical_sha256(obj) -> str:
    """The documented hash of the problem inputs: SHA-256 of their JSON with sorted keys and no spaces."""
    text = json.dumps(obj, sort_keys=True, separators=(",", ":"), ensure_ascii=False)
    return hashlib.sha256(text.encode()).hexdigest()


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def synthesised(tmp_path_factory):
    """``polyrob synth planar_2r --pldi pldi.json ... -o K.json``: ``(folder, argv)``."""
    d = tmp_path_factory.mktemp("provenance")
    pldi = polyrob.bound_pldi(polyrob.load_robot("planar_2r"), samples=256, coverage=0, progress=False)
    pldi.save(d / "pldi.json")
    argv = ["synth", "planar_2r", "--pldi", str(d / "pldi.json"), *SYNTH, "-o", str(d / "K.json")]
    assert main(argv) == 1  # the command ran (its certificate is not CERTIFIED: one D-K iteration)
    return d, argv


def test_controller_file_records_version_command_and_hashes(synthesised):
    d, argv = synthesised
    doc = json.loads((d / "K.json").read_text())
    p = doc["provenance"]
    assert p["polyrob_version"] == polyrob.__version__
    assert p["command"] == "polyrob " + " ".join(argv)
    assert set(p["dependencies"]) == set(DEPENDENCIES) and p["dependencies"]["numpy"] == np.__version__
    assert set(p["solvers"]) == {"clarabel", "scs"}
    assert p["machine"] == platform.machine() and p["platform"] == platform.platform()
    assert datetime.datetime.fromisoformat(p["created_utc"]).utcoffset() == datetime.timedelta(0)
    # the robot: the bytes of the bundled URDF
    assert p["robot"] == "planar_2r" and p["urdf_sha256"] == sha256_of(PLANAR_URDF)
    assert p["srdf_sha256"] is None  # planar_2r has no SRDF
    # the problem's inputs as the file's info records them, and their hash
    inputs = p["inputs"]
    assert inputs["weights"] == doc["info"]["weights"]
    assert inputs["domain"]["qdot"] == doc["info"]["domain"]["qdot"] == {"joint1": [-4.0, 4.0], "joint2": [-10.0, 10.0]}
    assert inputs["uncertainty"] == {"requested": "box", "merge_symmetric": False}
    assert p["inputs_sha256"] == canonical_sha256(inputs)
    # the PLDI file it was read from, both halves
    assert p["input_files"]["--pldi"]["sha256"] == sha256_of(d / "pldi.json")
    assert p["input_files"]["--pldi arrays"]["sha256"] == sha256_of(d / "pldi.npz")
    # and the controller reads back as before
    assert load_controller(d / "K.json").nstates > 0


def test_pldi_file_records_its_robot_and_domain(synthesised):
    d, _ = synthesised
    p = json.loads((d / "pldi.json").read_text())["provenance"]
    assert p["command"] == "library call: polyrob.bounds.pldi_result.save_pldi"
    assert p["urdf_sha256"] == sha256_of(PLANAR_URDF) and p["polyrob_version"] == polyrob.__version__
    controller = json.loads((d / "K.json").read_text())["provenance"]
    assert p["inputs"]["domain"] == controller["inputs"]["domain"]


def test_analyze_says_nothing_when_robot_and_problem_match(synthesised, capsys):
    d, _ = synthesised
    code, out, _ = run(
        capsys, "analyze", "planar_2r", "--pldi", d / "pldi.json", "--controller", d / "K.json", *ANALYZE
    )
    assert code == 1 and "verdict:" in out  # analysed (VIOLATED)
    assert "made for" not in out and "differ" not in out


def _stub_analysis(monkeypatch):
    """The mismatch lines come before the analysis: stop there (the analysis itself is tested elsewhere)."""
    import polyrob.pipeline as pipeline

    def stop(*_, **__):
        raise polyrob.PolyrobError("analysis stubbed by the test")

    monkeypatch.setattr(pipeline, "analyze_controller", stop)


def test_analyze_names_another_urdf(synthesised, tmp_path, capsys, monkeypatch):
    """The same robot name, a URDF with another link mass: one line naming the URDF and both hashes."""
    d, _ = synthesised
    edited = tmp_path / "planar_2r.urdf"
    text = PLANAR_URDF.read_text()
    assert '<mass value="10.0"/>' in text
    edited.write_text(text.replace('<mass value="10.0"/>', '<mass value="9.5"/>', 1))
    _stub_analysis(monkeypatch)
    code, out, err = run(capsys, "analyze", edited, "--pldi", d / "pldi.json", "--controller", d / "K.json", *ANALYZE)
    assert code == 2 and "stubbed" in err
    lines = [line for line in out.splitlines() if line.startswith(f"{d / 'K.json'}:")]
    assert len(lines) == 1, out
    assert "URDF differs from the one the file was made for" in lines[0]
    assert sha256_of(edited)[:12] in lines[0] and sha256_of(PLANAR_URDF)[:12] in lines[0]


def test_analyze_names_another_robot_and_domain(synthesised, capsys):
    """paper_2r (an analytic model, its own domain): the robot and the problem inputs named, then the refusal."""
    d, _ = synthesised
    code, out, err = run(capsys, "analyze", "paper_2r", "--controller", d / "K.json", *ANALYZE)
    assert code == 2 and "another problem" in err
    lines = [line for line in out.splitlines() if line.startswith(f"{d / 'K.json'}:")]
    assert any("robot 'paper_2r' given, the file was made for 'planar_2r'" in line for line in lines), out
    assert any("problem inputs differ" in line and "domain" in line for line in lines), out


def test_analyze_names_other_domain_options(synthesised, capsys):
    """--qdot-max 2 where the file was certified for the URDF's velocity limits: the inputs' hashes and the field."""
    d, _ = synthesised
    stored = json.loads((d / "K.json").read_text())["provenance"]
    code, out, err = run(capsys, "analyze", "planar_2r", "--qdot-max", "2", "--controller", d / "K.json", *ANALYZE)
    assert code == 2 and "another problem" in err  # refused, as before
    lines = [line for line in out.splitlines() if line.startswith(f"{d / 'K.json'}:")]
    assert len(lines) == 1, out
    assert "problem inputs differ from those the file was made for (domain qdot)" in lines[0]
    assert f"{stored['inputs_sha256'][:12]} recorded" in lines[0]


def test_report_and_certificate_record_the_command_and_hashes(synthesised, tmp_path, capsys, monkeypatch):
    """`polyrob report DIR` on a run directory: certificate.json, report.html and validation.json carry provenance."""
    import polyrob.analysis.certificate as certificate
    import polyrob.report.build as build

    d, synth_argv = synthesised
    for name in ("K.json", "pldi.json", "pldi.npz"):
        shutil.copy(d / name, tmp_path / name)
    fast = functools.partial(build.validate_controller, rate=None, scenarios=[], mc=3, mu_omega=np.logspace(-2, 2, 8))
    monkeypatch.setattr(build, "validate_controller", fast)
    monkeypatch.setattr(
        certificate, "certify_loop", functools.partial(certificate.certify_loop, omega=np.logspace(-2, 2, 5))
    )
    code, _, _ = run(capsys, "report", tmp_path, "--quiet")
    assert code == 1  # VIOLATED, decided again on the small grid
    stored = json.loads((tmp_path / "K.json").read_text())["provenance"]

    cert = json.loads((tmp_path / "certificate.json").read_text())["provenance"]
    assert cert["command"] == f"polyrob report {tmp_path} --quiet"
    assert cert["polyrob_version"] == polyrob.__version__
    assert cert["urdf_sha256"] == sha256_of(PLANAR_URDF)
    assert cert["inputs_sha256"] == stored["inputs_sha256"]  # the problem rebuilt from the files is the same

    page = (tmp_path / "report.html").read_text()
    assert "<h2>Provenance</h2>" in page and "<table id='provenance'>" in page
    for text in (cert["command"], stored["command"], sha256_of(PLANAR_URDF), stored["inputs_sha256"]):
        assert text in page
    footer = page.split("<footer>")[1]
    assert f"polyrob {polyrob.__version__}" in footer and sha256_of(PLANAR_URDF)[:12] in footer
    assert stored["inputs_sha256"][:12] in footer
    assert "## Provenance" in (tmp_path / "report.md").read_text()
    val = json.loads((tmp_path / "validation.json").read_text())["provenance"]
    assert val["this report"]["command"] == cert["command"]
    assert val["the controller file K.json"]["command"] == "polyrob " + " ".join(synth_argv)


def test_export_names_the_controller_file_it_came_from(synthesised, tmp_path, capsys):
    """`polyrob export`: the C's JSON records the export's command and the controller file's hash and provenance."""
    d, synth_argv = synthesised
    code, _, _ = run(capsys, "export", d / "K.json", "--rate", "1000", "-o", tmp_path, "--quiet")
    assert code == 0
    doc = json.loads((tmp_path / "controller.json").read_text())
    assert doc["provenance"]["command"] == f"polyrob export {d / 'K.json'} --rate 1000 -o {tmp_path} --quiet"
    source = doc["controller_file"]
    assert source["sha256"] == sha256_of(d / "K.json")
    assert source["provenance"]["command"] == "polyrob " + " ".join(synth_argv)
    assert source["provenance"]["urdf_sha256"] == sha256_of(PLANAR_URDF)


def test_library_calls_and_old_files(tmp_path):
    """A library call is named as one; a file written before provenance loads and records none."""
    import control

    K = control.ss([[-1.0]], [[1.0, 0.0]], [[1.0], [0.0]], [[0.0, 0.0], [0.0, 0.0]])
    path = save_controller(K, tmp_path / "K.json", info={"robot": "planar_2r"})
    p = Provenance.of_file(path)
    assert p.command == "library call: polyrob.io.controller.save_controller" and p.robot == "planar_2r"
    old = json.loads(path.read_text())
    del old["provenance"]
    (tmp_path / "old.json").write_text(json.dumps(old))
    assert Provenance.of_file(tmp_path / "old.json") is None
    assert load_controller(tmp_path / "old.json").nstates == 1


def test_round_trip_and_differences():
    robot = polyrob.load_robot("planar_2r")
    domain = polyrob.Domain.from_robot(robot)
    description = {"robot": "planar_2r", "domain": domain.to_dict(), "weights": {"omega_b": [0.5, 0.1]}}
    p = Provenance.capture(robot=robot, description=description, function="f", now=WHEN)
    assert p.created_utc == "2026-11-28T01:02:03+00:00" and p.urdf_sha256 == sha256_of(PLANAR_URDF)
    assert Provenance.from_dict(json.loads(json.dumps(p.to_dict()))) == p
    assert differences(p, p) == []
    # the domain's name is not an input: the same bounds from a file or from options are one problem
    renamed = dict(description, domain=dict(domain.to_dict(), name="from a file"))
    assert differences(p, Provenance.capture(robot=robot, description=renamed, function="f", now=WHEN)) == []
    wider = domain.with_bounds(u_lower=domain.u_lower * 2, u_upper=domain.u_upper * 2)
    other = Provenance.capture(robot=robot, description=dict(description, domain=wider.to_dict()), function="f")
    (line,) = differences(p, other)
    assert line.startswith("problem inputs differ from those the file was made for (domain u): sha256 ")


def test_srdf_is_hashed_and_compared():
    """panda's SRDF (its reference poses) is part of the robot: hashed, and a change named in one line."""
    import dataclasses
    from pathlib import Path

    robot = polyrob.load_robot("panda")
    p = Provenance.capture(robot=robot, function="f", now=WHEN)
    assert p.srdf_sha256 == sha256_of(Path(robot.srdf)) and p.urdf_sha256 == sha256_of(Path(robot.source))
    edited = dataclasses.replace(p, srdf_sha256="0" * 64)
    (line,) = differences(edited, p)
    assert line.startswith("SRDF differs from the one the file was made for: sha256 " + p.srdf_sha256[:12])
    assert line.endswith(f"{'0' * 12} ({robot.srdf}) recorded")
