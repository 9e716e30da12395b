"""`polyrob synth`, `analyze` and `run` on the paper's problem: certificates reproduced, files compared.

One short synthesis (one D-K iteration, then reduction) on a PLDI file, and
its analysis, are shared by the session (tests/test_cli_certificates.py reads
them too); the certificate is what matters here, not how good the controller is.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import re
from pathlib import Path

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


def shared(tmp_path_factory, name: str, make) -> Path:
    """The folder ``make(folder)`` filled, once per test session (also across xdist workers).

    A worker waits for another that is making the same folder (a lock file): the
    synthesis below costs more than the tests that read it.
    """
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent  # the session's folder, above every worker's own
    folder = root / name
    with open(root / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        if not (folder / "done").exists():
            folder.mkdir(exist_ok=True)
            make(folder)
            (folder / "done").touch()
    return folder


def paper_file(tmp_path_factory) -> Path:
    """The paper's PLDI as a file (``paper.json`` + ``paper.npz``)."""
    return shared(tmp_path_factory, "paper_pldi", lambda d: paper_pldi().save(d / "paper.json")) / "paper.json"


def cli_json(tmp_path_factory, name: str, argv) -> tuple[int, dict, Path]:
    """``polyrob ARGV`` (``argv(folder)``, with ``--json``) once per session: exit status, document, folder."""

    def make(d):
        with open(d / "stdout", "w") as stdout, contextlib.redirect_stdout(stdout):
            (d / "status").write_text(str(main([str(a) for a in argv(d)])))

    d = shared(tmp_path_factory, name, make)
    return int((d / "status").read_text()), json.loads((d / "stdout").read_text()), d


def synth_reduced(tmp_path_factory):
    """``synth --json -o K.json`` (FAST, ``--reduce``) on the paper's PLDI file: ``(status, document, K.json)``.

    Shared with tests/test_cli_certificates.py (one synthesis per session).
    """
    pldi = paper_file(tmp_path_factory)
    code, doc, d = cli_json(
        tmp_path_factory,
        "synth_reduced",
        lambda d: (
            ["synth", "paper_2r", "--pldi", pldi.with_suffix(".npz"), *FAST, "--reduce"]
            + ["--json", "--quiet", "-o", d / "K.json"]
        ),
    )
    return code, doc, d / "K.json"


#: analyze's options for the synthesised controller (tests/test_cli_certificates.py uses the same run)
ANALYZE = [*BOX, *GRID, "--mc", "20", "--no-time-varying", "--quiet", "--json"]


def analysis_of_synth(tmp_path_factory):
    """``analyze --json`` of :func:`synth_reduced`'s controller file: ``(status, document)``."""
    pldi = paper_file(tmp_path_factory)
    _, _, K = synth_reduced(tmp_path_factory)
    argv = ["analyze", "paper_2r", "--pldi", pldi, "--controller", K, *ANALYZE]
    code, doc, _ = cli_json(tmp_path_factory, "analyze_synth_reduced", lambda d: argv)
    return code, doc


def run_full_order(tmp_path_factory):
    """``run --json --full-order -o K_run.json`` (FAST) on the paper's PLDI file, once per session.

    Returns ``(status, document, K_run.json, stages)``; ``stages`` maps ``"design"`` and
    ``"analyze"`` to what the command had written to stderr when that stage's function
    was called.  Shared with tests/test_cli_certificates.py (one run per session).
    """
    import io

    import polyrob.pipeline as pipeline

    pldi = paper_file(tmp_path_factory)

    def make(d):
        err, stages = io.StringIO(), {}
        real = {"design": pipeline.design_controller, "analyze": pipeline.analyze_controller}

        def when_called(stage):
            def call(*args, **kwargs):
                stages[stage] = err.getvalue()
                return real[stage](*args, **kwargs)

            return call

        argv = ["run", "paper_2r", "--pldi", pldi, *FAST, "--mc", "5", *GRID, "--json", "--full-order", "--coulomb", "0.5"]
        with pytest.MonkeyPatch.context() as patch, open(d / "stdout", "w") as stdout:
            patch.setattr(pipeline, "design_controller", when_called("design"))
            patch.setattr(pipeline, "analyze_controller", when_called("analyze"))
            with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(err):
                code = main([str(a) for a in [*argv, "-o", d / "K_run.json"]])
        (d / "stages.json").write_text(json.dumps(stages))
        (d / "status").write_text(str(code))

    d = shared(tmp_path_factory, "run_full_order", make)
    doc = json.loads((d / "stdout").read_text())
    return int((d / "status").read_text()), doc, d / "K_run.json", json.loads((d / "stages.json").read_text())


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """The paper's PLDI file, and a reduced D-K controller made on it (``synth --json``)."""
    code, doc, K = synth_reduced(tmp_path_factory)
    cert = doc["certificate"]
    # one D-K iteration reduced to a few states: mu far above 1 (lower bound too), on a loop stable at Delta = 0
    assert cert["status"] == "VIOLATED" and cert["certified"] is False
    assert code == (0 if cert["certified"] else 1) == 1  # the command ran; its certificate is not CERTIFIED
    return paper_file(tmp_path_factory), K, doc


def test_synth_writes_the_problem_and_an_honest_certificate(files):
    _, K, printed = files
    doc = json.loads(K.read_text())
    record, info = doc["certificate"], doc["info"]
    assert record["structure"].startswith("reduced:") and record["order"] <= record["full_order"]
    assert record["peak_mu_lower"] <= record["peak_mu_upper"]
    # the file's verdict is the certificate of the controller it holds (the one the command printed)
    printed = printed["certificate"]
    assert record["status"] == record["certificate"]["status"] == printed["status"] == "VIOLATED"
    assert record["certificate"]["certified"] is False and record["certificate"]["verdict"] == printed["verdict"]
    # what the controller was made for (before: no uncertainty model; run saved only the robot)
    assert info["robot"] == "paper_2r" and info["domain"]["name"] == "paper"
    assert info["weights"]["omega_b"] == [0.5, 0.1] and info["uncertainty"]["model"] == "box"


def test_synth_text_verdict_is_not_certified_when_mu_exceeds_one(tmp_path, capsys, monkeypatch):
    """The words printed for a synthesis with mu > 1 (the synthesis itself is stubbed: words only).

    The stub's certificate is decided by the one decision (decide_mu) from its figures, with the
    problem's own scope: the command prints it, and exits 1.
    """
    from types import SimpleNamespace

    import polyrob.pipeline as pipeline
    from polyrob.analysis.certificate import Certificate, Status, decide_mu
    from polyrob.pipeline import Design

    paper_pldi().save(tmp_path / "paper.json")
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
        info={},
    )
    record = {"structure": "full", "order": 8, "peak_mu_upper": 2.227, "peak_mu_lower": 2.226}
    stable = SimpleNamespace(stable=True, unstable=False, verdict="stable")

    def design(problem, *args, **kwargs):
        status, reasons = decide_mu(stable, 2.227, 2.226, None)
        assert status is Status.VIOLATED
        cert = Certificate(status, 2.227, 2.227, 2.226, stable, problem.scope(), reasons)
        return Design(controller=None, result=result, reduced=None, record=record).certified_by(cert)

    monkeypatch.setattr(pipeline, "design_controller", design)
    code, out, _ = run(capsys, "synth", "paper_2r", "--pldi", tmp_path / "paper.json", "--quiet")
    assert code == 1  # ran, not CERTIFIED
    assert "certified peak mu" not in out  # before: "certified peak mu in [2.226, 2.227]"
    assert "CERTIFIED" not in out
    lines = out.strip().splitlines()
    (i,) = [k for k, line in enumerate(lines) if line.startswith("verdict: ")]
    assert lines[i].startswith("verdict: robust performance VIOLATED: mu lower bound 2.226 >= 1")
    # below it, what the certificate covers and the loop it rests on
    assert lines[i + 1].startswith("covers: for constant parameters") and "paper_2r over domain 'paper: q ±(3.14, 3.14), qdot ±(3.96, 9.96), u 0'" in lines[i + 1]
    assert lines[-1] == "loop at Delta = 0: stable"
    assert out.splitlines()[0].startswith("[1/2] reading the PLDI")


def test_synth_json_is_one_document(files):
    _, K, doc = files
    assert doc["synthesis"]["structure"].startswith("reduced:") and doc["output"] == str(K)
    assert doc["problem"]["uncertainty"]["model"] == "box" and doc["verdict"].startswith("verdict: ")
    # one verdict: the certificate's, also in the synthesis record
    assert doc["verdict"] == "verdict: " + doc["certificate"]["verdict"]
    assert doc["synthesis"]["status"] == doc["certificate"]["status"] == "VIOLATED"
    assert doc["covers"].startswith("for constant parameters") and "'box' uncertainty model" in doc["covers"]
    # the floor no controller beats at these weights: the arm's unstable pole near 7.5 rad/s
    limit = doc["performance_limit"]
    assert 0.6 < limit["bound"] < 1 and not limit["excludes_mu_below_one"] and limit["pole"][0] > 7


def test_analyze_reproduces_the_reduced_certificate(files, tmp_path_factory):
    _, K, _ = files
    cert = json.loads(K.read_text())["certificate"]
    code, report = analysis_of_synth(tmp_path_factory)
    assert report["problem_compared"] is True
    assert code == (0 if report["certified"] else 1) == 1
    rp = report["robust_performance"]
    # two independent sweeps (synthesis grid vs analysis grid, both peak-refined)
    assert rp["mu_upper_grid"] == pytest.approx(cert["peak_mu_upper"], rel=2e-3)
    assert rp["mu_lower"] == pytest.approx(cert["peak_mu_lower"], rel=2e-3)
    assert report["parameters"] == 10
    # one D-K iteration reduced to a few states: mu far above 1, its lower bound too: disproved,
    # as the synthesis' own certificate of this controller said
    assert report["status"] == rp["certificate"]["status"] == cert["status"] == "VIOLATED"
    assert report["verdict"] == "verdict: " + rp["certificate"]["verdict"]
    assert report["verdict"].startswith("verdict: robust performance VIOLATED: mu lower bound ")
    assert "CERTIFIED" not in report["verdict"]


def test_run_json_announces_stages_when_they_start_and_matches_synth(files, tmp_path_factory):
    _, K, _ = files
    code, doc, out_file, seen = run_full_order(tmp_path_factory)  # stdout held one document: stage lines on stderr
    assert code == (0 if doc["analysis"]["certified"] else 1) == 1
    assert doc["analysis"]["status"] == doc["synthesis"]["status"] == "VIOLATED"
    # before: "[1/3] bounds" was printed after the synthesis, nothing during the analysis
    assert seen["design"].startswith("[1/3] ") and "[2/3] synthesis" in seen["design"]
    assert "[3/3] analysis" not in seen["design"] and "[3/3] analysis" in seen["analyze"]
    assert doc["verdict"] == doc["analysis"]["verdict"] and "CERTIFIED" not in doc["verdict"]
    # not certified: one line of what it certifies instead (the mu level proved at every frequency,
    # read as a share of the parameter ranges) and what stands in the way
    margin, instead = doc["analysis"]["margin"], doc["analysis"]["instead"]
    assert margin["proved"] and margin["level"] >= doc["analysis"]["robust_performance"]["mu_upper_grid"]
    assert margin["fraction_of_ranges"] == pytest.approx(1 / margin["level"])
    assert instead.startswith("instead: robust performance at level ") and "in the way: mu peaks at " in instead
    assert "\n" not in instead and len(instead) < 400
    # and which of the box's parameters carries mu at the peak: mu without each, the largest drop first
    said = instead.split("without one block mu there: ")[1].split(")")[0].split(", ")
    assert len(said) == 3 and all(re.fullmatch(r"[ab]\d\d [0-9.]+", x) for x in said)  # the box's entries a_ij, b_ij
    assert all(float(x.split()[1]) <= margin["level"] for x in said)  # a smaller problem: mu can only fall
    assert doc["output"] == str(out_file) and len(doc["bounds"]["entries"]) == 10
    assert doc["performance_limit"]["bound"] == pytest.approx(0.65, abs=0.01)
    saved = json.loads(out_file.read_text())
    cert_full = json.loads(K.read_text())["certificate"]["full_peak_mu_upper"]
    # run's analysis of its (deterministic) synthesis = synth's certificate of the same synthesis
    assert saved["certificate"]["robust_performance"]["mu_upper_grid"] == pytest.approx(cert_full, rel=2e-3)
    assert saved["info"]["uncertainty"]["model"] == "box" and saved["info"]["weights"]["M_s"] == [2.0, 3.0]


def test_run_states_what_coulomb_friction_does_as_synth_does(tmp_path_factory):
    """Before: only synth took --coulomb and printed the friction statement (run refused the option)."""
    from polyrob.analysis.certificate import friction_sentence
    from polyrob.synthesis.integral import CoulombChannel

    _, doc, _, _ = run_full_order(tmp_path_factory)
    friction = doc["friction"]
    assert friction["levels"] == [0.5, 0.5] and friction["source"] == "--coulomb"
    channel = CoulombChannel(**{k: v for k, v in friction.items() if k != "words"})
    assert friction["words"] == friction_sentence(channel)
    assert friction["stable"]  # the nominal loop: its figures are stated, not nan
    # the proved peak scales with the level (one N m on every joint vs 0.5)
    assert friction["peak"] == pytest.approx(0.5 * friction["peak_per_nm"], rel=1e-6)


def _edit(K, tmp_path, **info):
    doc = json.loads(K.read_text())
    doc["info"].update(info)
    path = tmp_path / f"K_{'_'.join(info)}.json"
    path.write_text(json.dumps(doc))
    return path


def test_analyze_refuses_a_controller_made_for_another_problem(files, tmp_path, capsys):
    paper, K, _ = files
    pldi = ["--pldi", paper, *BOX]
    cases = [
        # the file says box; analyze's default model (auto) resolves to another one on this robot
        (["--pldi", paper, "--controller", K], ["--uncertainty box"]),
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
    argv = ["analyze", "paper_2r", "--pldi", tmp_path / "ur5.json", "--controller", "paper", "--quiet"]
    code, _, err = run(capsys, *argv)  # --quiet: the job's progress line would start the stage that reads it
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


def test_bad_structure_leaves_no_controller_file(tmp_path_factory, tmp_path, capsys):
    out = tmp_path / "K.json"
    pldi = paper_file(tmp_path_factory)
    code, _, err = run(capsys, "synth", "paper_2r", "--pldi", pldi, "--structure", "tf0x", "--quiet", "-o", out)
    assert code == 2 and err.count("\n") == 1 and "structure" in err
    assert not out.exists() and list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("moving", ["certified", "not certified", "not computed"])
def test_synth_moving_decides_the_exit_status_when_it_was_computed(tmp_path, capsys, monkeypatch, moving):
    """`synth --moving`: exit 0 only when mu and the moving-robot certificate (once computed) both hold.

    Before, the exit status was the mu certificate's alone (0 here in every case).  The synthesis and
    the moving-robot test are stubbed: the decision is what is tested.
    """
    from types import SimpleNamespace

    import polyrob.analysis.lpv.constant as constant
    import polyrob.pipeline as pipeline
    from polyrob.analysis.certificate import Certificate, Status, decide_mu
    from polyrob.pipeline import Design

    paper_pldi().save(tmp_path / "paper.json")
    result = SimpleNamespace(mu_history=[0.9], gamma_history=[0.9], structure="full", order=8, peak_mu=0.9,
                             peak_mu_lower=0.89, peak_frequency=1.0, iterations=1, seconds=1.0, info={})  # fmt: skip
    record = {"structure": "full", "order": 8, "peak_mu_upper": 0.9, "peak_mu_lower": 0.89}
    stable = SimpleNamespace(stable=True, unstable=False, verdict="stable")

    def design(problem, *args, **kwargs):
        between = SimpleNamespace(holds=True, level=0.91, peak_upper=0.9, failed_at=None, reason="")
        status, reasons = decide_mu(stable, 0.9, 0.89, between)
        assert status is Status.CERTIFIED
        cert = Certificate(status, 0.9, 0.9, 0.89, stable, problem.scope(), reasons)
        return Design(controller=None, result=result, reduced=None, record=record).certified_by(cert)

    summary = {
        "certified": {"computed": True, "certified": True, "status": "CERTIFIED"},
        "not certified": {"computed": True, "certified": False, "status": "NOT_CERTIFIED"},
        "not computed": {"computed": False, "certified": False, "status": None},
    }[moving]
    fake = SimpleNamespace(verdict=f"moving robot: {moving} (stub)", computed=summary["computed"],
                           details=lambda: "", summary=lambda: dict(summary))  # fmt: skip
    monkeypatch.setattr(pipeline, "design_controller", design)
    monkeypatch.setattr(constant, "robot_in_motion_certificate", lambda *a, **k: fake)
    code, out, _ = run(capsys, "synth", "paper_2r", "--pldi", tmp_path / "paper.json", "--moving", "--quiet")
    assert "verdict: robust performance CERTIFIED" in out
    assert code == (1 if moving == "not certified" else 0)
    assert ("exit status 1: the moving-robot certificate asked for with --moving is not CERTIFIED" in out) == (
        moving == "not certified"
    )


def test_tune_moving_takes_a_number_of_rounds_and_a_model_of_constants(tmp_path_factory, tmp_path, capsys):
    """`synth --tune-moving N`: a negative count is refused before any work; the paper's lft model, whose
    parameters move with the state, has no structure to tune on: one line, exit 2, no controller file."""
    out = tmp_path / "K.json"
    code, _, err = run(capsys, "synth", "paper_2r", "--tune-moving", "-1", "-o", out)
    assert code == 2 and err.count("\n") == 1 and "--tune-moving" in err
    pldi = paper_file(tmp_path_factory)
    code, _, err = run(capsys, "synth", "paper_2r", "--pldi", pldi, "--tune-moving", "1", "--quiet", "-o", out)
    assert code == 2 and err.count("\n") == 1 and "model of constants" in err, err
    assert not out.exists()
