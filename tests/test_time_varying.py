"""The time-varying verdict of the pipeline (what `polyrob analyze` prints beside mu)."""

from __future__ import annotations

import json
from types import SimpleNamespace

import control
import numpy as np
import pytest
from conftest import paper_pldi

import polyrob
from polyrob.analysis.mu.bounds import mu_bounds
from polyrob.analysis.time_varying.certificate import covers_nonlinear, time_varying_certificate
from polyrob.cli import main
from polyrob.controller import Controller
from polyrob.pipeline import build_problem
from polyrob.plant.generalized import lft

B1 = np.array([[0.0], [1.0]])


def _toy_problem(stiffness, W_S=None):
    """A one-joint PLDI given by its vertices ``q'' = a q - q' + u``, ``a`` in ``stiffness``."""
    verts = [(np.array([[0.0, 1.0], [a, -1.0]]), B1) for a in stiffness]
    return SimpleNamespace(pldi=verts, P=SimpleNamespace(W_S=W_S, W_T=None, W_KS=None))


def robust_stability_mu_lower(P, K, omega) -> float:
    """The peak verified lower bound of robust-stability mu of ``lft(P, K)`` on ``omega``.

    The sweep :func:`~polyrob.analysis.robust.robstab` runs (the same figure as its ``mu_lower``), without
    the check between the grid points, which only the upper bound's certificate needs.
    """
    N = lft(P, Controller.of(K))[P.output_slices["v"], P.input_slices["d"]]
    return mu_bounds(N, P.block_structure_rs, omega, progress=False).peak_lower


@pytest.fixture(scope="module")
def paper_problem():
    return build_problem(polyrob.load_robot("paper_2r"), pldi=paper_pldi(), progress=False)


def test_stability_and_performance_hold_on_a_quadratically_stable_toy():
    # u = 4 (r - q): closed-loop stiffness 3..5, damping 1, every vertex and every switch stable
    W_S = control.ss([], [], [], [[0.2]])  # |W_S S| <= 0.2 |S|: below 1 when |S| < 5
    tv = time_varying_certificate(_toy_problem((-1.0, 1.0), W_S), np.array([[4.0]]))
    assert tv.method == "vertices" and tv.stability_holds and tv.performance_holds
    assert tv.stability.margin > 0 and 0 < tv.gamma < 1
    # independent: gamma bounds each frozen vertex's ||W_S S||_inf (dense grid, from below)
    w = np.logspace(-2, 3, 4000)
    for a in (-1.0, 1.0):
        S = control.tf([1, 1, -a], [1, 1, 4 - a])  # 1 / (1 + K G), G = 1 / (s^2 + s - a)
        assert 0.2 * np.max(np.abs(S(1j * w))) <= tv.gamma * (1 + 1e-9)
    assert "robust performance CERTIFIED" in tv.verdict and tv.certificate.status.value == "CERTIFIED"


def test_frozen_unstable_vertex_ends_the_test_and_says_why():
    # u = 0.5 (r - q) cannot stabilise stiffness +1: that vertex is unstable frozen
    tv = time_varying_certificate(_toy_problem((-1.0, 1.0)), np.array([[0.5]]))
    assert not tv.stability_holds and not tv.performance_holds and tv.performance is None
    assert "unstable (frozen)" in tv.notes[0] and tv.gamma == np.inf
    assert tv.verdict.startswith("time-varying verdict [vertices]: robust performance NOT certified: ")
    assert tv.certificate.status.value == tv.stability_certificate.status.value == "NOT_CERTIFIED"


def test_paper_controller_fails_the_vertex_test(paper_problem):
    tv = time_varying_certificate(paper_problem, polyrob.paper_controller())
    s = tv.summary()
    assert s["method"] == "vertices" and s["vertex_source"] == "polytope" and s["vertices"] > 1024
    assert not s["stability_holds"] and "unstable (frozen)" in s["notes"][0]
    assert s["covers_nonlinear"] == covers_nonlinear("vertices") and "moving nonlinear robot" in s["covers_nonlinear"]
    json.dumps(s)  # JSON-ready


def test_small_gain_when_the_vertices_are_too_many_bounds_mu_from_above(paper_problem):
    K = polyrob.paper_controller()
    tv = time_varying_certificate(paper_problem, K, max_vertices=1)
    assert tv.method == "scaled small gain" and "no vertex test" in tv.notes[0]
    # constant D covers time-varying parameters, so it can never be below constant-parameter mu
    assert tv.stability.gamma >= robust_stability_mu_lower(paper_problem.P, K, np.logspace(-1, 2, 25))
    # the constant-D bound of K* on the paper's box (1.687, docs/certificates.md): no certificate
    assert tv.stability.gamma == pytest.approx(1.687, rel=2e-3) and not tv.stability_holds


def test_cli_analyze_prints_both_verdicts_and_which_covers_the_robot(capsys, tmp_path_factory):
    from test_robust import PAPER_ANALYZE as argv
    from test_robust import paper_analyze_json

    assert main(argv) == 1  # ran; K* is not certified
    out = capsys.readouterr().out
    lines = out.strip().splitlines()
    tv_line = next(i for i, line in enumerate(lines) if line.startswith("time-varying verdict"))
    assert lines[tv_line].startswith("time-varying verdict [vertices]: robust performance NOT certified")
    assert lines[tv_line + 1] == "which covers the robot: " + covers_nonlinear("vertices")
    assert lines[tv_line + 2].startswith("verdict: robust performance VIOLATED: mu lower bound")
    assert "covers: for constant parameters (every frozen robot of the set)" in out
    code, doc = paper_analyze_json(tmp_path_factory)  # the same command with --json (test_robust's run)
    assert code == 1 and doc["time_varying"]["stability_holds"] is False
    # --no-time-varying: no time-varying document (a 3-frequency grid and one sample: only the option is checked)
    quick = ["analyze", "paper_2r", "--controller", "paper", "--mc", "1", "--quiet", "--omega", "1:10:3"]
    assert main([*quick, "--no-time-varying", "--json"]) == 1
    assert json.loads(capsys.readouterr().out)["time_varying"] is None


def test_a_loop_too_large_for_the_lmis_is_not_run_and_says_what_to_do(paper_problem):
    """A 92-state loop once took 24 GiB in the vertex LMIs; now it is routed, then refused, with a reason."""
    from polyrob.analysis.time_varying.quadratic import MAX_STATES, quadstab

    K = polyrob.paper_controller()
    for _ in range(8):  # 12 + 8 x 8 = 76 controller states, same transfer function
        K = control.ss(K) + control.ss(-1e-3 * np.eye(8), np.zeros((8, 2)), np.zeros((2, 8)), np.zeros((2, 2)))
    tv = time_varying_certificate(paper_problem, K)
    assert tv.method == "not run" and not tv.stability_holds
    assert "the closed loop has 80 states" in tv.notes[0] and "--reduce" in tv.notes[1]
    assert tv.verdict.startswith("time-varying verdict [not run]: robust performance NOT certified: ")
    assert "--reduce" in tv.verdict
    with pytest.raises(polyrob.PolyrobError, match=f"at most {MAX_STATES}"):
        quadstab(paper_problem.pldi, K)


def test_constant_d_small_gain_certifies_what_one_common_p_does_not():
    """tf3 at four times the paper's bandwidths (mu 0.78 on lft): no common P on the 2524 vertices (8 of them refute it),
    but a constant D on the LFT model proves time-varying robust stability (before: 'no verified scaling')."""
    from pathlib import Path

    from polyrob.io.controller import load_controller
    from polyrob.pipeline import default_hyperparameters

    robot = polyrob.load_robot("paper_2r")
    h = default_hyperparameters(2, bandwidth_scale=4.0)
    problem = build_problem(robot, pldi=paper_pldi(), hyperparameters=h, progress=False)
    K = load_controller(Path(__file__).parent / "fixtures" / "paper_2r_tf3_alpha4_K.json")
    K = getattr(K, "controller", K)
    tv = time_varying_certificate(problem, K)
    assert tv.method == "scaled small gain" and tv.stability_holds
    assert "no common Lyapunov matrix" in tv.notes[0]
    assert 0.4 < tv.stability.gamma < 0.6 and tv.stability.info["route"].startswith("frequency-domain D")
    # constant D covers time-varying parameters, so it is never below the constant-parameter mu
    mu_lower = robust_stability_mu_lower(problem.P, K, np.logspace(-1, 3, 40))
    assert mu_lower == pytest.approx(0.3933, abs=1e-4) and tv.stability.gamma >= mu_lower
    # robust performance for arbitrarily fast variation is not proved at these weights
    assert not tv.performance_holds and tv.performance.gamma > 1


def test_a_certified_pldi_s_vertex_certificate_says_its_polytope_was_sampled():
    """With --certify the intervals are proved, the polytope's other half-spaces are sampled supports:
    the vertex certificate's scope says so (it once read 'certified')."""
    from polyrob.pipeline import build_problem

    problem = build_problem(
        polyrob.load_robot("planar_2r"), bound_options={"samples": 256, "certify": True}, progress=False
    )
    assert problem.pldi.enclosure == "certified"
    tv = time_varying_certificate(problem, polyrob.paper_controller())
    assert tv.method == "vertices" and tv.stability.vertex_source == "polytope"
    assert tv.certificate.scope.enclosure == "sampled"
    assert "polytope's vertices of the PLDI (sampled)" in tv.certificate.details()
    assert tv.summary()["scope"]["enclosure"] == "sampled"


def test_an_exact_model_has_its_loop_s_own_h_infinity_norm_as_the_time_varying_test():
    """Computed torque with no model error: no uncertainty channel, so nothing varies (it crashed before).

    The small-gain test was handed an empty block structure and raised; the
    verdict is now the loop's stability and its H-infinity norm, the same
    figure as the frozen robot's mu (one performance block: mu is the norm).
    """
    from polyrob.analysis.norms import hinf_norm
    from polyrob.domains.task import TaskDomain
    from polyrob.model.inner import inner_loop

    arm = inner_loop(polyrob.load_robot("planar_2r"), "computed-torque", model_error=0.0)
    dom = TaskDomain.from_robot(arm, pose=[0.3, 1.2], q_radius=0.2, qdot_max=0.5, qddot_max=1.0)
    problem = build_problem(arm, dom, progress=False, bound_options={"samples": 64})
    assert problem.P.input_slices["d"].stop == problem.P.input_slices["d"].start  # no uncertainty channel
    wc = 2.0  # a PD on the double integrators: u = wc^2 e + 2 wc s e / (s/(20 wc) + 1)
    pd = control.tf([2 * wc + wc**2 / (20 * wc), wc**2], [1 / (20 * wc), 1])
    K = control.append(*[control.ss(pd)] * 2)
    tv = time_varying_certificate(problem, K)
    assert tv.stability_holds
    norm = hinf_norm(lft(problem.P, Controller.of(K)))
    assert tv.gamma == pytest.approx(norm, rel=2e-3) and tv.gamma >= norm * (1 - 1e-9)
    assert tv.performance_holds == (norm < 1)
    assert "no uncertainty channel" in " ".join(tv.notes)


def test_a_skew_multiplier_proves_what_no_constant_scaling_can():
    """``x' = -x + 2 delta(t) J x`` (``J`` a rotation): ``d|x|^2/dt = -2 |x|^2`` for every ``delta(t)``, so it is
    stable at any rate.  The loop ``N = 2 J / (s + 1)`` has ``||S N S^-1|| >= 2`` for every scaling ``S``; the
    skew multiplier of a real repeated scalar proves it, and a complex one (which may turn ``J`` into a negative
    gain) is rightly not helped by it."""
    from polyrob.analysis.time_varying.smallgain import scaled_small_gain

    J = np.array([[0.0, 1.0], [-1.0, 0.0]])
    N = control.ss(-np.eye(2), 2 * J, np.eye(2), np.zeros((2, 2)))
    real = scaled_small_gain(N, [[-2, 0]])
    assert real.holds and real.gamma < 0.5 and real.info["skew_multipliers"] == 1
    complex_ = scaled_small_gain(N, [[2, 0]])
    assert not complex_.holds and complex_.gamma == pytest.approx(2.0, rel=2e-3)
    # the complex scalar delta = j/2 makes I - N(0) delta = I - j J singular: gamma 2 is attained
    assert abs(np.linalg.det(np.eye(2) - 2 * J * (0.5j))) < 1e-12
