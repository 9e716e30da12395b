"""`polyrob synth`, `analyze` and `run` on the paper's problem: certificates reproduced, files compared.

One short synthesis (one D-K iteration, then reduction) on a PLDI file is
shared by the module; the certificate is what matters here, not how good
the controller is.
"""

from __future__ import annotations

import contextlib
import json

import pytest
from conftest import paper_pldi

from polyrob.cli import main

BOX = ["--uncertainty", "box"]  # the paper's model: one real parameter per varying entry
FAST = [*BOX, "--complex", "--max-iter", "1"]
GRID = ["--omega", "0.01:1000:40"]  # peak-refined; the automatic grid costs 10x more here


def run(capsys, *argv):
    try:
        code = main([str(a) for a in argv])
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """The paper's PLDI as a file, and a reduced D-K controller made on it (``synth --json``)."""
    d = tmp_path_factory.mktemp("synth")
    paper_pldi().save(d / "paper.json")
    K = d / "K.json"
    with open(d / "synth.out", "w") as stdout, contextlib.redirect_stdout(stdout):
        code = main(
            ["synth", "paper_2r", "--pldi", str(d / "paper.npz"), *FAST, "--reduce", "--json", "--quiet", "-o", str(K)]
        )
    assert code == 0
    return d, K


def test_synth_writes_the_problem_and_an_honest_certificate(files):
    d, K = files
    doc = json.loads(K.read_text())
    cert, info = doc["certificate"], doc["info"]
    assert cert["structure"].startswith("reduced:") and cert["order"] <= cert["full_order"]
    assert cert["peak_mu_lower"] <= cert["peak_mu_upper"]
    # what the controller was made for (before: no uncertainty model; run saved only the robot)
    assert info["robot"] == "paper_2r" and info["domain"]["name"] == "paper"
    assert info["weights"]["omega_b"] == [0.5, 0.1] and info["uncertainty"]["model"] == "box"


def test_synth_text_verdict_is_not_certified_when_mu_exceeds_one(files, capsys, monkeypatch):
    """The words printed for a synthesis with mu > 1 (the synthesis itself is stubbed: words only)."""
    from types import SimpleNamespace

    import polyrob.pipeline as pipeline
    from polyrob.pipeline import Design

    d, _ = files
    result = SimpleNamespace(
        mu_history=[2.5, 2.227],
        gamma_history=[3.0, 2.5],
        structure="full",
        order=8,
        peak_mu=2.227,
        peak_mu_lower=2.226,
        peak_frequency=7.8,
        iterations=2,
        seconds=1.0,
    )
    cert = {"structure": "full", "order": 8, "peak_mu_upper": 2.227, "peak_mu_lower": 2.226}
    monkeypatch.setattr(
        pipeline,
        "design_controller",
        lambda *a, **k: Design(controller=None, result=result, reduced=None, certificate=cert),
    )
    code, out, _ = run(capsys, "synth", "paper_2r", "--pldi", d / "paper.json", "--quiet")
    assert code == 0
    assert "certified peak mu" not in out  # before: "certified peak mu in [2.226, 2.227]"
    last = out.strip().splitlines()[-1]
    assert last.startswith("verdict: robust performance VIOLATED (mu lower bound 2.226 >= 1") and "try:" in last
    assert "--max-bandwidth" in last and "paper_2r over domain 'paper'" in last
    assert out.splitlines()[0].startswith("[1/2] reading the PLDI")


def test_synth_json_is_one_document(files):
    d, K = files
    doc = json.loads((d / "synth.out").read_text())
    assert doc["synthesis"]["structure"].startswith("reduced:") and doc["output"] == str(K)
    assert doc["problem"]["uncertainty"]["model"] == "box" and doc["verdict"].startswith("verdict: ")
    # the floor no controller beats at these weights: the arm's unstable pole near 7.5 rad/s
    limit = doc["performance_limit"]
    assert 0.6 < limit["bound"] < 1 and not limit["excludes_mu_below_one"] and limit["pole"][0] > 7


def test_analyze_reproduces_the_reduced_certificate(files, capsys):
    d, K = files
    cert = json.loads(K.read_text())["certificate"]
    code, out, _ = run(
        capsys,
        "analyze",
        "paper_2r",
        "--pldi",
        d / "paper.json",
        "--controller",
        K,
        "--mc",
        "5",
        *BOX,
        *GRID,
        "--quiet",
        "--json",
    )
    report = json.loads(out)
    assert code == 0 and report["problem_compared"] is True
    rp = report["robust_performance"]
    # two independent sweeps (synthesis grid vs analysis grid, both peak-refined)
    assert rp["mu_upper"] == pytest.approx(cert["peak_mu_upper"], rel=2e-3)
    assert rp["mu_lower"] == pytest.approx(cert["peak_mu_lower"], rel=2e-3)
    assert report["parameters"] == 10
    # one D-K iteration reduced to a few states: mu far above 1, and no certificate either way
    word = "VIOLATED" if report["nominal_stability"] else "NOT certified: the nominal closed loop is unstable"
    assert word in report["verdict"] and "CERTIFIED" not in report["verdict"]


def test_run_json_announces_stages_when_they_start_and_matches_synth(files, capsys, monkeypatch):
    import polyrob.pipeline as pipeline

    d, K = files
    seen = {}
    real_design, real_analyze = pipeline.design_controller, pipeline.analyze_controller

    def design(*args, **kwargs):
        seen["design"] = capsys.readouterr().err
        return real_design(*args, **kwargs)

    def analyze(*args, **kwargs):
        seen["analyze"] = capsys.readouterr().err
        return real_analyze(*args, **kwargs)

    monkeypatch.setattr(pipeline, "design_controller", design)
    monkeypatch.setattr(pipeline, "analyze_controller", analyze)
    out_file = d / "K_run.json"
    code, out, _ = run(
        capsys, "run", "paper_2r", "--pldi", d / "paper.json", *FAST, "--mc", "5", *GRID, "--json", "-o", out_file
    )
    assert code == 0
    doc = json.loads(out)  # stage lines went to stderr, stdout holds one document
    # before: "[1/3] bounds" was printed after the synthesis, nothing during the analysis
    assert seen["design"].startswith("[1/3] ") and "[2/3] synthesis" in seen["design"]
    assert "[3/3] analysis" in seen["analyze"]
    assert doc["verdict"] == doc["analysis"]["verdict"] and "CERTIFIED" not in doc["verdict"]
    assert doc["output"] == str(out_file) and len(doc["bounds"]["entries"]) == 10
    assert doc["performance_limit"]["bound"] == pytest.approx(0.65, abs=0.01)
    saved = json.loads(out_file.read_text())
    cert_full = json.loads(K.read_text())["certificate"]["full_peak_mu_upper"]
    # run's analysis of its (deterministic) synthesis = synth's certificate of the same synthesis
    assert saved["certificate"]["robust_performance"]["mu_upper"] == pytest.approx(cert_full, rel=2e-3)
    assert saved["info"]["uncertainty"]["model"] == "box" and saved["info"]["weights"]["M_s"] == [2.0, 3.0]


def _edit(K, tmp_path, **info):
    doc = json.loads(K.read_text())
    doc["info"].update(info)
    path = tmp_path / f"K_{'_'.join(info)}.json"
    path.write_text(json.dumps(doc))
    return path


def test_analyze_refuses_a_controller_made_for_another_problem(files, tmp_path, capsys):
    d, K = files
    pldi = ["--pldi", d / "paper.json", *BOX]
    cases = [
        # the file says box; analyze's default model (auto) resolves to another one on this robot
        (["--pldi", d / "paper.json", "--controller", K], ["--uncertainty box"]),
        ([*pldi, "--controller", K, "--wb", "1"], ["omega_b", "--wb 0.5,0.1"]),
        (["--domain", "paper", "--qdot-max", "1", "--controller", K], ["domain qdot", "--qdot-max=joint1="]),
        ([*pldi, "--controller", _edit(K, tmp_path, robot="planar_2r")], ["robot 'planar_2r'"]),
        ([*pldi, "--controller", _edit(K, tmp_path, uncertainty={"model": "lft"})], ["--uncertainty lft"]),
    ]
    for argv, needles in cases:
        code, out, err = run(capsys, "analyze", "paper_2r", *argv, "--quiet")
        assert code == 2 and err.count("\n") == 1 and "made for another problem" in err, err
        assert all(n in err for n in needles), err
        assert "[2/2]" not in out  # refused before the analysis


def test_analyze_refuses_a_pldi_of_another_robot(tmp_path, capsys):
    import dataclasses

    dataclasses.replace(paper_pldi(), robot_name="ur5").save(tmp_path / "ur5.json")
    code, _, err = run(capsys, "analyze", "paper_2r", "--pldi", tmp_path / "ur5.json", "--controller", "paper")
    # before: a complaint about weight sizes
    assert code == 2 and "robot 'ur5'" in err and "weight" not in err and err.count("\n") == 1


def test_analyze_nan_controller_is_one_line(tmp_path, capsys):
    path = tmp_path / "K.json"
    path.write_text(
        '{"format": "polyrob.controller/1", "type": "ss", "A": [[NaN]], "B": [[1, 0, 0, 0]], '
        '"C": [[1], [0]], "D": [[0, 0, 0, 0], [0, 0, 0, 0]]}'
    )
    code, _, err = run(capsys, "analyze", "paper_2r", "--controller", path)
    assert code == 2 and "non-finite" in err and err.count("\n") == 1  # before: LinAlgError


def test_bad_structure_leaves_no_controller_file(files, tmp_path, capsys):
    d, _ = files
    out = tmp_path / "K.json"
    code, _, err = run(
        capsys, "synth", "paper_2r", "--pldi", d / "paper.json", "--structure", "tf0x", "--quiet", "-o", out
    )
    assert code == 2 and err.count("\n") == 1 and "structure" in err
    assert not out.exists() and list(tmp_path.iterdir()) == []
