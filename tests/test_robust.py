"""robstab/robperf on the paper's problem: K* is not robust on the interval box."""

from __future__ import annotations

import json

import numpy as np
import pytest

import polyrob
from polyrob.cli import main
from polyrob.plant.generalized import closed_loop
from polyrob.analysis.robust import nominal_performance, robperf, robstab, sample_stability
from polyrob.plant.weights import paper_weights

from conftest import paper_pldi

OMEGA = np.logspace(-1, 2, 25)


@pytest.fixture(scope="module")
def paper():
    unc = polyrob.uncertain_plant(paper_pldi())
    P = polyrob.generalized_plant(unc, *paper_weights())
    return unc, P, polyrob.paper_controller()


def test_paper_controller_robust_stability_is_not_certified(paper):
    unc, P, K = paper
    rs = robstab(P, K, omega=OMEGA)
    assert rs.nominally_stable
    assert rs.mu_lower <= rs.mu_upper + 1e-9
    # the lower bound exceeds 1: a destabilising perturbation inside the box
    assert 1.4 < rs.mu_lower and rs.mu_upper < 1.9
    assert rs.margin_lower == pytest.approx(1 / rs.mu_upper)
    # the perturbation the lower bound returns puts a closed-loop pole on the jw axis
    cl = closed_loop(unc, K, rs.worst_delta)
    assert abs(cl.poles.real.max()) < 1e-6
    assert np.max(np.abs(rs.worst_delta)) == pytest.approx(1 / rs.mu_lower, rel=1e-6)


def test_paper_controller_robust_performance_bounds(paper):
    _, P, K = paper
    rp = robperf(P, K, omega=OMEGA)
    assert rp.mu_lower <= rp.mu_upper + 1e-9
    assert 2.2 < rp.mu_lower and rp.mu_upper < 2.6  # far from the paper's 0.9999
    assert not rp.robust


def test_paper_controller_nominal_performance_is_met(paper):
    _, P, K = paper
    assert nominal_performance(P, K) < 1.0


def test_monte_carlo_and_corners_find_unstable_plants(paper):
    unc, _, K = paper
    s = sample_stability(unc, K, n=200, seed=0)
    assert s.corners == 1024
    assert 0.80 < s.corners_stable < 0.90  # about 16 % of the corners are unstable
    assert s.worst_abscissa > 5  # a real pole near +9.3
    # the worst corner: every a-entry at its upper bound, every b-entry at its lower
    np.testing.assert_array_equal(s.worst_delta, [1, 1, 1, 1, 1, 1, -1, -1, -1, -1])


def test_cli_analyze_json(capsys):
    code = main(["analyze", "paper_2r", "--controller", "paper", "--mc", "20", "--json", "--quiet", "--omega", "0.1:100:25"])
    out = capsys.readouterr().out
    assert code == 0
    rep = json.loads(out)
    assert rep["robust_performance"]["mu_upper"] > 2 and rep["nominal_stability"]


def test_cli_analyze_missing_controller_file(capsys):
    code = main(["analyze", "paper_2r", "--controller", "nope.json", "--quiet"])
    assert code == 2 and "no such controller file" in capsys.readouterr().err
