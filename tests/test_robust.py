"""robstab/robperf on the paper's problem: K* is not robust on the interval box."""

from __future__ import annotations

import dataclasses

import control
import numpy as np
import pytest
from conftest import paper_pldi

import polyrob
from polyrob.analysis.robust import nominal_performance, robperf, robstab, sample_stability
from polyrob.analysis.stability import stability_verdict
from polyrob.cli import main
from polyrob.plant.generalized import closed_loop, lft, nominal_closed_loop
from polyrob.plant.weights import paper_weights

OMEGA = np.logspace(-1, 2, 25)


@pytest.fixture(scope="module")
def paper():
    unc = polyrob.uncertain_plant(paper_pldi(), model="box")  # the paper's model
    P = polyrob.generalized_plant(unc, *paper_weights())
    return unc, P, polyrob.paper_controller()


def test_paper_controller_robust_stability_is_not_certified(paper):
    unc, P, K = paper
    rs = robstab(P, K, omega=OMEGA)
    assert rs.nominally_stable and rs.stability.verdict == "stable"
    assert rs.mu_lower <= rs.mu_upper_grid + 1e-9
    # the lower bound exceeds 1: a destabilising perturbation inside the box
    # AB13MD's upper bound and the power-iteration lower bound on this grid (deterministic: the
    # seeded PLDI); the lower bound is checked independently below (its delta destabilises)
    assert rs.mu_lower == pytest.approx(1.5366, rel=2e-3) and rs.mu_upper_grid == pytest.approx(1.7372, rel=2e-3)
    # a lower bound >= 1 disproves robust stability: VIOLATED, not merely "not certified"
    assert not rs.robust and rs.certificate.status.value == "VIOLATED"
    assert rs.failed == (
        f"mu lower bound {rs.mu_lower:.4g} >= 1: a member of the uncertainty model's set breaks it "
        "(the model holds the robot's set, maybe more)",
    )
    # the perturbation the lower bound returns has size 1/mu_lower and puts a
    # closed-loop pole on the jw axis, checked on the plant G(delta) itself
    assert np.max(np.abs(rs.worst_delta)) == pytest.approx(1 / rs.mu_lower, rel=1e-6)
    cl = closed_loop(unc, K, rs.worst_delta)
    assert abs(cl.poles.real.max()) < 1e-6
    # ... and 2 % more of it, still inside the box, destabilises the loop
    assert np.max(np.abs(1.02 * rs.worst_delta)) < 1
    assert stability_verdict(closed_loop(unc, K, 1.02 * rs.worst_delta).system).verdict == "unstable"


def test_paper_controller_robust_performance_bounds(paper):
    _, P, K = paper
    rp = robperf(P, K, omega=OMEGA)
    assert rp.mu_lower <= rp.mu_upper_grid + 1e-9
    # far from the paper's 0.9999
    assert rp.mu_lower == pytest.approx(2.3482, rel=2e-3) and rp.mu_upper_grid == pytest.approx(2.4319, rel=2e-3)
    assert not rp.robust


def test_paper_controller_nominal_performance_is_met(paper):
    _, P, K = paper
    gamma = nominal_performance(P, K)
    assert gamma < 1.0
    # independent: the largest singular value of w -> z on a dense grid, from the
    # upper LFT at the nominal delta (never above the H-inf norm, close to it)
    N = lft(P.at(P.uncertain.nominal_delta, strict=False), K, n_u=P.n_u, n_y=P.n_y)
    w = np.logspace(-3, 3, 2001)
    H = np.moveaxis(np.asarray(N(1j * w, squeeze=False)), -1, 0)
    peak = max(np.linalg.norm(h, 2) for h in H)
    assert peak <= gamma * (1 + 1e-9) and peak == pytest.approx(gamma, rel=1e-3)


def _with_unstable_hidden_mode(K):
    """K with an extra state at +1 that neither input nor output sees: same transfer function."""
    Ks = control.ss(K)
    n = Ks.nstates
    A = np.block([[Ks.A, np.zeros((n, 1))], [np.zeros((1, n)), np.ones((1, 1))]])
    B = np.vstack([Ks.B, np.zeros((1, Ks.ninputs))])
    C = np.hstack([Ks.C, np.zeros((Ks.noutputs, 1))])
    return control.ss(A, B, C, Ks.D)


def test_nominal_performance_of_an_unstable_loop_is_infinite(paper):
    _, P, K = paper
    Kbad = _with_unstable_hidden_mode(K)
    N = lft(P.at(P.uncertain.nominal_delta, strict=False), Kbad, n_u=P.n_u, n_y=P.n_y)
    # what the old check read: python-control returns a finite norm for an unstable loop
    assert np.isfinite(control.linfnorm(N)[0]) and control.linfnorm(N)[0] < 1
    assert stability_verdict(N).verdict == "unstable"
    assert nominal_performance(P, Kbad) == np.inf


def test_loop_unstable_at_delta0_with_small_mu_is_not_robust(paper):
    """The LFT centre (interval midpoints) matters, not the equilibrium plant."""
    unc, _, K = paper
    A = np.array(unc.A_mid, dtype=float)
    A[2, 0] += 20.0  # negative stiffness at the centre of the box only
    A[3, 1] += 20.0
    # a box 10x smaller than the paper's: mu far below 1
    u2 = dataclasses.replace(unc, A_mid=A, B_d=0.1 * np.asarray(unc.B_d))
    P2 = polyrob.generalized_plant(u2, *paper_weights())
    assert nominal_closed_loop(u2, K).stable  # the equilibrium loop is unchanged and stable
    rs = robstab(P2, K, omega=OMEGA, refine_peak=False)
    assert rs.mu_upper_grid < 0.5 and rs.nominally_stable
    assert rs.stability.verdict == "unstable" and rs.stability.abscissa > 0.1
    assert not rs.robust
    # Delta = 0 is a member of the set: a loop proved unstable there violates robust stability
    assert rs.certificate.status.value == "VIOLATED"
    assert rs.failed == ("the loop at Delta = 0 (a member of the set) is proved unstable",)
    assert "a grid of" in rs.covers


def test_monte_carlo_and_corners_find_unstable_plants(paper):
    unc, _, K = paper
    s = sample_stability(unc, K, n=200, seed=0)
    assert s.corners == 1024
    assert s.corners_stable * 1024 == 859  # 165 of the 1024 corners are unstable
    assert s.worst_abscissa == pytest.approx(9.2908, rel=1e-4)  # a real pole near +9.3
    assert s.undecided == 0
    # the worst corner: every a-entry at its upper bound, every b-entry at its lower
    np.testing.assert_array_equal(s.worst_delta, [1, 1, 1, 1, 1, 1, -1, -1, -1, -1])


#: ``polyrob analyze`` of K* on the paper's problem (tests/test_time_varying.py prints it as text too)
PAPER_ANALYZE = ["analyze", "paper_2r", "--controller", "paper", "--mc", "5", "--quiet", "--omega", "0.1:100:25"]


def paper_analyze_json(tmp_path_factory):
    """``PAPER_ANALYZE --json``, once per session (shared with tests/test_time_varying.py): exit status, document."""
    from test_cli_synth import cli_json

    code, doc, _ = cli_json(tmp_path_factory, "paper_analyze_json", lambda d: [*PAPER_ANALYZE, "--json"])
    return code, doc


def test_cli_analyze_json(tmp_path_factory):
    code, rep = paper_analyze_json(tmp_path_factory)
    assert code == 1 and rep["status"] == "VIOLATED" and rep["certified"] is False  # K* is not certified
    assert rep["robust_performance"]["mu_upper_grid"] > 2 and rep["nominal_stability"]


def test_cli_analyze_missing_controller_file(capsys):
    code = main(["analyze", "paper_2r", "--controller", "nope.json", "--quiet"])
    assert code == 2 and "no such controller file" in capsys.readouterr().err


def test_real_parameter_crossing_at_zero_frequency_is_on_the_grid():
    """N = 1/(s + 2) against one real scalar: mu = 0.5, reached only at omega = 0."""
    from polyrob.analysis.robust import loop_mu

    P = control.ss([[-1.0]], [[1.0, 1.0]], [[1.0], [1.0]], [[0.0, 0.0], [0.0, 0.0]])  # with u = -x: 1/(s+2)
    r = loop_mu(P, -1.0, [[-1, 0]], np.logspace(-2, 2, 41), n_u=1, n_y=1, kind="stability")
    # every positive frequency gives a complex N(jw): real mu is 0 there
    assert r.mu_upper_grid == pytest.approx(0.5, rel=1e-9) and r.mu_lower == pytest.approx(0.5, rel=1e-9)
    assert r.critical_frequency == 0.0 and 0.0 in r.mu.omega
    # proved at every frequency: the grid's scalings hold between its points too
    assert r.certificate.status.value == "CERTIFIED" and "every frequency" in r.covers
    assert r.certificate.bound == pytest.approx(0.505, rel=1e-9)
    # independent check: delta = 1/mu closes the loop x' = -2x + delta x on a pole at 0,
    # 1 % more puts it in the right half-plane
    delta = float(np.real(r.worst_perturbation[0, 0]))
    assert abs(delta) == pytest.approx(2.0, rel=1e-9)
    assert stability_verdict(np.array([[-2.0 + 1.01 * delta]])).verdict == "unstable"
