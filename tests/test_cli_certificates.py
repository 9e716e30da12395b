"""Every printed CERTIFIED comes from a Certificate whose status is CERTIFIED.

``synth``, ``analyze`` and ``run`` on the paper's problem (the fast options of
tests/test_cli_synth.py; its synthesis, analysis and run are shared, not run
again), with ``--json``: every JSON document is walked, and

- a mapping with ``"certified": true`` has ``"status": "CERTIFIED"`` beside it,
  and ``"certified"`` is false for every other status;
- a mapping with a status and a verdict line: the line names that status;
- a string with the word CERTIFIED (not ``NOT certified``, not ``NOT_CERTIFIED``)
  sits in a mapping whose status is CERTIFIED (the nearest one with a status;
  the command's verdict when there is none);
- the exit status is 0 if and only if the command's verdict is CERTIFIED.

The paper's K* on a small domain (positions within 0.05 rad, velocities at 1 %
of the paper's) is the CERTIFIED case; a 1x1 loop shows that a check between
grid points that cannot run leaves GRID_ONLY, not CERTIFIED.
"""

from __future__ import annotations

import json
import re

import pytest
from test_cli_synth import BOX, GRID, analysis_of_synth, cli_json, run_full_order, synth_reduced

from polyrob.analysis.certificate import Status

STATUSES = {s.value for s in Status}
#: how each status reads in a verdict line
NAMED = {"CERTIFIED": "CERTIFIED", "GRID_ONLY": "GRID_ONLY", "NOT_CERTIFIED": "NOT certified", "VIOLATED": "VIOLATED"}
WORD = re.compile(r"(?<![A-Za-z_])CERTIFIED(?![A-Za-z_])")  # not NOT_CERTIFIED, not "NOT certified"
#: analyze's options here
ANALYSIS = ["--mc", "20", *GRID, "--no-time-varying"]


def _statuses(mapping: dict) -> list[str]:
    """The statuses a mapping states: ``status`` and any ``*_status`` (a time-varying entry has two)."""
    return [v for k, v in mapping.items() if (k == "status" or k.endswith("_status")) and v in STATUSES]


def check_document(doc: dict, verdict_status: str) -> int:
    """Assert the rules of the module docstring on one JSON document; returns how many CERTIFIED words it holds."""
    assert verdict_status in STATUSES
    words = 0

    def walk(node, path: str, status: list[str]):
        nonlocal words
        if isinstance(node, dict):
            own = _statuses(node)
            if "certified" in node and isinstance(node["certified"], bool):
                assert "status" in node, f"{path}: 'certified' without a status beside it"
                assert node["certified"] is (node["status"] == "CERTIFIED"), f"{path}: {node['status']}"
            if isinstance(node.get("verdict"), str) and node.get("status") in STATUSES:
                assert NAMED[node["status"]] in node["verdict"], f"{path}: {node['status']} vs {node['verdict']!r}"
            for key, value in node.items():
                walk(value, f"{path}.{key}", own or status)
        elif isinstance(node, list):
            for i, value in enumerate(node):
                walk(value, f"{path}[{i}]", status)
        elif isinstance(node, str) and WORD.search(node):
            words += 1
            assert "CERTIFIED" in status, f"{path} says CERTIFIED under status {status}: {node!r}"

    walk(doc, "$", [verdict_status])
    if isinstance(doc.get("verdict"), str):  # the command's verdict line names its status
        assert NAMED[verdict_status] in doc["verdict"], (verdict_status, doc["verdict"])
    return words


def test_the_checker_catches_a_certified_word_without_a_certified_status():
    """The rules are not vacuous: each of them fails on a document that breaks it."""
    ok = {"status": "CERTIFIED", "certified": True, "verdict": "robust performance CERTIFIED: mu <= 0.9"}
    assert check_document({"analysis": ok, "verdict": "verdict: robust performance CERTIFIED"}, "CERTIFIED") == 3
    not_ok = [
        ({"a": {"status": "GRID_ONLY", "certified": True}}, "GRID_ONLY"),
        ({"a": {"certified": True}}, "CERTIFIED"),
        ({"a": {"status": "GRID_ONLY", "verdict": "robust performance CERTIFIED"}}, "CERTIFIED"),
        ({"verdict": "verdict: robust performance CERTIFIED"}, "NOT_CERTIFIED"),
        ({"a": {"status": "VIOLATED", "notes": ["CERTIFIED"]}}, "CERTIFIED"),
        ({"a": {"status": "VIOLATED", "verdict": "robust performance NOT certified"}}, "VIOLATED"),
        ({"verdict": "verdict: robust performance VIOLATED"}, "GRID_ONLY"),
    ]
    for doc, status in not_ok:
        with pytest.raises(AssertionError):
            check_document(doc, status)
    # the other statuses' words are not the word
    assert check_document({"s": "NOT_CERTIFIED", "v": "robust performance NOT certified"}, "VIOLATED") == 0


@pytest.mark.parametrize("status", list(Status))
def test_a_certificate_says_certified_only_with_that_status(status):
    """A certificate's own summary, verdict and details, for each status."""
    from types import SimpleNamespace

    from polyrob.analysis.certificate import Certificate, Scope

    stable = SimpleNamespace(verdict="stable")
    reasons = () if status is Status.CERTIFIED else ("a reason",)
    cert = Certificate(status, 0.9, 0.9, 0.8, stable, Scope(model="box"), reasons, SimpleNamespace(between=None))
    summary = cert.summary()
    assert summary["status"] == status.value and summary["certified"] is cert.certified
    assert cert.certified is (status is Status.CERTIFIED)
    check_document({"certificate": summary, "verdict": "verdict: " + cert.verdict, "details": cert.details()}, status)
    assert bool(WORD.search(cert.verdict)) is cert.certified


def test_synth_json(tmp_path_factory):
    code, doc, K = synth_reduced(tmp_path_factory)
    status = doc["certificate"]["status"]
    check_document(doc, status)
    assert code == (0 if status == "CERTIFIED" else 1)
    # one D-K iteration, reduced: mu far above 1 (lower bound too) on a loop stable at Delta = 0
    assert status == "VIOLATED" and doc["verdict"] == "verdict: " + doc["certificate"]["verdict"]
    # the controller file holds the same verdict
    record = json.loads(K.read_text())["certificate"]
    check_document(record, record["status"])
    same = ("status", "certified", "verdict", "reasons", "scope")
    assert record["status"] == status
    assert {k: record["certificate"][k] for k in same} == {k: doc["certificate"][k] for k in same}


def test_synth_and_analyze_of_its_controller_agree(tmp_path_factory):
    """``analyze`` of the file ``synth`` wrote (same PLDI, same model): the same status."""
    _, synth, _ = synth_reduced(tmp_path_factory)
    code, doc = analysis_of_synth(tmp_path_factory)
    status = doc["status"]
    check_document(doc, status)
    assert code == (0 if status == "CERTIFIED" else 1)
    assert doc["problem_compared"] is True
    assert status == doc["robust_performance"]["certificate"]["status"] == synth["certificate"]["status"]
    assert doc["verdict"] == "verdict: " + doc["robust_performance"]["certificate"]["verdict"]


def test_run_json(tmp_path_factory):
    """``run --json --full-order`` of tests/test_cli_synth.py (the same run, shared: with its time-varying verdict)."""
    code, doc, K, _ = run_full_order(tmp_path_factory)
    status = doc["analysis"]["status"]
    check_document(doc, status)
    assert code == (0 if status == "CERTIFIED" else 1)
    assert status == "VIOLATED"  # the full-order controller of one D-K iteration
    # one verdict: the analysis' certificate, also the design's and the saved file's
    assert doc["verdict"] == doc["analysis"]["verdict"] and doc["synthesis"]["status"] == status
    record = json.loads(K.read_text())["certificate"]
    check_document(record, record["status"])
    assert record["status"] == record["certificate"]["status"] == status


@pytest.fixture(scope="module")
def small_domain(tmp_path_factory):
    """A PLDI of paper_2r near q = 0 and nearly at rest: little uncertainty left around its plant."""
    code, _, d = cli_json(
        tmp_path_factory,
        "small_domain_pldi",
        lambda d: (
            ["bounds", "paper_2r", "--domain", "paper", "--q-range=-0.05:0.05", "--qdot-scale", "0.01"]
            + ["--samples", "64", "--coverage", "0", "--no-models", "--json", "--quiet", "-o", d / "small.json"]
        ),
    )
    assert code == 0
    return d / "small.json"


def test_analyze_certified_exits_zero_and_says_so_only_where_it_holds(small_domain, tmp_path_factory):
    """The paper's K* on the small domain: robust performance CERTIFIED (mu <= 0.91 at every frequency)."""
    code, doc, _ = cli_json(
        tmp_path_factory,
        "certificates_analyze_small",
        lambda d: (
            ["analyze", "paper_2r", "--pldi", small_domain, "--controller", "paper", *BOX, *ANALYSIS]
            + ["--json", "--quiet"]
        ),
    )
    status = doc["status"]
    assert check_document(doc, status) > 0
    assert code == (0 if status == "CERTIFIED" else 1) == 0
    rp = doc["robust_performance"]["certificate"]
    assert status == rp["status"] == "CERTIFIED" and doc["certified"] is True
    assert rp["bound"] < 1 and rp["scope"]["frequencies"] == "every frequency"
    assert doc["verdict"] == "verdict: " + rp["verdict"] and "CERTIFIED" in doc["verdict"]


LOOP = dict(a=[[-1.0]], b=[[1.0, 1.0]], c=[[1.0], [1.0]], d=[[0.0, 0.0], [0.0, 0.0]])


def test_a_loop_whose_check_between_grid_points_cannot_run_is_not_certified():
    """N = 1/(s + 2) (mu 0.5 at omega = 0): in 212-bit arithmetic the Hamiltonian test cannot run -> GRID_ONLY."""
    import control

    from polyrob.analysis.certificate import certify_loop

    P = control.ss(LOOP["a"], LOOP["b"], LOOP["c"], LOOP["d"])
    grid_only = certify_loop(P, -1.0, [[1, 1]], n_u=1, n_y=1, response_bits=212)
    assert grid_only.status is Status.GRID_ONLY and not grid_only.certified
    assert grid_only.summary()["certified"] is False and not WORD.search(grid_only.verdict)
    assert grid_only.mu_upper_grid < 1 and "between the grid points" in grid_only.reasons[0]
    certified = certify_loop(P, -1.0, [[1, 1]], n_u=1, n_y=1)
    assert certified.status is Status.CERTIFIED and certified.certified and certified.reasons == ()
    assert certified.bound == pytest.approx(0.504, abs=0.005) and certified.bound >= 0.5
    assert certified.verdict.startswith("robust performance CERTIFIED: mu <= ")


def test_analyze_wcgain_bounds_the_whole_sets_gain_beside_the_verdict(small_domain, tmp_path_factory):
    """``--wcgain``: the worst-case gain over the whole set (MATLAB's wcgain), its upper bound proved at every frequency.

    On the small domain robust performance is certified with ``mu <= b < 1``
    at every frequency, which itself bounds every member's gain by ``b``: the
    worst-case gain lies between the nominal loop's gain (a member) and
    about ``b``.
    """
    code, doc, _ = cli_json(
        tmp_path_factory,
        "certificates_analyze_wcgain",
        lambda d: (
            ["analyze", "paper_2r", "--pldi", small_domain, "--controller", "paper", *BOX, *ANALYSIS]
            + ["--no-moving", "--wcgain", "--json", "--quiet"]
        ),
    )
    check_document(doc, doc["status"])
    wc = doc["worst_case"]
    assert wc["proved"] is True and wc["certificate"]["status"] == "CERTIFIED"
    assert wc["certificate"]["scope"]["kind"] == "worst-case gain"
    assert wc["certificate"]["scope"]["frequencies"] == "every frequency"
    nominal, bound = doc["nominal_performance_hinf"], doc["robust_performance"]["certificate"]["bound"]
    assert nominal * (1 - 1e-2) <= wc["lower"] <= wc["upper"] <= 1.05 * bound  # the lower on the grid
    assert code == 0 and doc["status"] == "CERTIFIED"  # a figure beside the verdict, which stays the same
