"""Synthesis never runs silently, stops at its time limit, and does not start when the limit rules it out."""

from __future__ import annotations

import json

import pytest
from conftest import paper_pldi

from polyrob.cli import main


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_a_problem_the_performance_limit_rules_out_stops_with_one_line(capsys):
    """TwoDofs' unstable pole (135 rad/s) puts every controller's mu above 4 at these weights."""
    code, out, _ = _run(capsys, "synth", "TwoDofs", "--json", "--quiet")
    doc = json.loads(out)
    assert code == 1 and doc["performance_limit"]["excludes_mu_below_one"]
    assert doc["verdict"].startswith("stopped: the performance limit proves mu >= ")
    assert "synthesis" not in doc  # nothing was synthesised


@pytest.mark.timeout(300)
def test_fixed_structure_progress_off_a_terminal_and_its_time_limit(capsys, tmp_path):
    """A line per iteration on stderr although stderr is not a terminal; no new iteration after --time-limit."""
    paper_pldi().save(tmp_path / "paper.json")
    argv = ["synth", "paper_2r", "--pldi", tmp_path / "paper.npz", "--uncertainty", "box", "--complex", "--structure", "tf3"]
    code, out, err = _run(capsys, *argv, "--init", "paper", "--starts", "2", "--max-iter", "40", "--time-limit", "10")
    assert "[fixed " in err and "peak mu" in err  # the library's progress lines, shown by the CLI
    assert "synthesis stopped by" in out or "stopped by the time limit" in out
    assert code in (0, 1)
    # --quiet: no progress lines
    code, _, err = _run(capsys, *argv, "--init", "paper", "--starts", "1", "--max-iter", "1", "--quiet")
    assert "[fixed " not in err


def test_run_into_a_place_for_no_results_names_the_file_it_would_write(capsys):
    code, _, err = _run(capsys, "run", "planar_2r", "-o", "/proc/polyrob_run")
    assert code == 2 and "K.json" in err and "controller.json" not in err
