"""The moving-robot certificate: the linearised robot scheduled on its state, rate-bounded LPV analysis.

The LPV model at a grid point is the frozen weighted loop; the proved gain lies
between the frozen peak and the arbitrarily fast bound and grows with the rate
bound; the status follows :func:`polyrob.analysis.certificate.decide_gridded_gain`;
``analyze --json`` carries the third verdict.
"""

from __future__ import annotations

from types import SimpleNamespace as NS

import control
import numpy as np
import pytest
from test_cli_certificates import small_domain  # noqa: F401  (the shared small-domain PLDI, a fixture)

import polyrob
from polyrob.analysis.certificate import Status, decide_gridded_gain
from polyrob.analysis.lpv.moving import MovingRobotCertificate, moving_robot_gain
from polyrob.analysis.lpv.robot import closed_loop_system, rate_bounds, scheduling
from polyrob.domains.torque_box import Domain
from polyrob.pipeline import default_hyperparameters
from polyrob.plant.generalized import loop_functions
from polyrob.plant.weights import paper_weights


def pd_controller(wn: float = 12.0, zeta: float = 0.8, tau: float = 0.02) -> control.StateSpace:
    """``u = (kp + kd s / (tau s + 1)) e`` per joint, gains for inertias 40 and 8 (paper_2r's M(q) range)."""
    M = np.array([40.0, 8.0])
    kp, kd = M * wn**2, 2 * zeta * wn * M
    return control.ss(-np.eye(2) / tau, np.eye(2), np.diag(-kd / tau**2), np.diag(kp + kd / tau))


@pytest.fixture(scope="module")
def robot():
    return polyrob.load_robot("paper_2r")


@pytest.fixture(scope="module")
def small(robot):
    """The paper's domain shrunk around q = 0 and nearly at rest: a well-posed small LPV problem."""
    d = Domain.from_robot(robot, "paper")
    return d.with_bounds(q_lower=np.full(2, -0.3), q_upper=np.full(2, 0.3), qdot_lower=d.qdot_lower * 0.05,
                         qdot_upper=d.qdot_upper * 0.05)  # fmt: skip


def test_scheduling_of_the_planar_arm_leaves_out_q1(robot):
    model = scheduling(robot, Domain.from_robot(robot, "paper"), points=(5, 3))
    assert model.names == ("q2", "qdot1", "qdot2") and model.n_points == 45
    rates, source = rate_bounds(model, Domain.from_robot(robot, "paper"))
    assert rates[0] == (-9.9561, 9.9561) and source.startswith("sampled")
    assert 15 < rates[1][1] < 25 and 15 < rates[2][1] < 25  # |qddot| with u = 0, sampled x 1.05


def test_lpv_model_at_a_grid_point_is_the_frozen_weighted_loop(robot):
    """closed_loop_system(rho) against S, T of the plant linearised at that state (plant.loops), to 1e-9."""
    W_S, W_T = paper_weights(default_hyperparameters(2))
    K = pd_controller()
    model = scheduling(robot, Domain.from_robot(robot, "paper"), points=(5, 3))
    rho = np.array([0.7, -1.5, 4.0])
    A, B, C, D = closed_loop_system(model, K, W_S, W_T)(rho)
    Aj, Bj = robot.jacobians([0.0, 0.7], [-1.5, 4.0], [0.0, 0.0])
    G = control.ss(Aj, Bj, np.hstack([np.eye(2), np.zeros((2, 2))]), np.zeros((2, 2)))
    cl = loop_functions(G, K)
    for w in (0.01, 0.3, 2.0, 17.0, 300.0):
        s = 1j * w
        lpv = C @ np.linalg.solve(s * np.eye(A.shape[0]) - A, B) + D
        ref = np.vstack(
            [control.evalfr(W_S, s) @ control.evalfr(cl.S, s), control.evalfr(W_T, s) @ control.evalfr(cl.T, s)]
        )
        assert np.abs(lpv - ref).max() <= 1e-9 * max(1.0, np.abs(ref).max())


def test_moving_gain_lies_between_frozen_and_fast_and_grows_with_the_rate(robot, small):
    model = scheduling(robot, small, points=(4, 2))
    system = closed_loop_system(model, pd_controller(), 0.5 * np.eye(2), None)  # z = e / 2: a 6-state loop
    gammas = []
    for scale in (0.0, 20.0):
        rates, _ = rate_bounds(model, small, scale=scale)
        r = moving_robot_gain(model, system, rates, tensor=False)
        assert r.proved, r.reason
        gammas.append(r.gamma)
    fast = moving_robot_gain(model, system, [(-np.inf, np.inf)] * 3)
    frozen = r.frozen_gamma
    assert frozen <= gammas[0] * (1 + 1e-6)
    assert gammas[0] <= gammas[1] * (1 + 1e-4)
    if fast.proved:  # a constant X covers every rate: never below a rate-bounded X(rho) (up to the solver)
        assert gammas[1] <= fast.gamma * (1 + 1e-3)


@pytest.mark.parametrize(
    ("proved", "gamma", "whole_box", "status"),
    [(True, 0.5, False, Status.GRID_ONLY), (True, 0.5, True, Status.CERTIFIED), (True, 1.5, False, Status.NOT_CERTIFIED),
     (False, float("inf"), False, Status.NOT_CERTIFIED)],
)  # fmt: skip
def test_status_follows_decide_gridded_gain(proved, gamma, whole_box, status):
    # the coverage sentence says the opposite of the fact: the status follows the fact, not the words
    words = "on the grid of 4 points" if whole_box else "the whole parameter box"
    res = NS(proved=proved, whole_box=whole_box, coverage=words, reason="" if proved else "no X", summary=dict)
    cert = MovingRobotCertificate(True, gamma=gamma, result=res, rate_words="|dq2/dt| <= 1")
    assert decide_gridded_gain(proved, gamma, whole_box, "no X")[0] is status
    assert cert.certificate.status is status
    assert cert.verdict.startswith("moving robot with rates |dq2/dt| <= 1: robust performance ")
    assert cert.summary()["certified"] is (status is Status.CERTIFIED)


def test_not_computed_says_why():
    c = MovingRobotCertificate.not_computed("the closed loop has 80 states")
    assert c.certificate is None and not c.summary()["certified"]
    assert c.verdict == "moving robot: robust performance not computed (the closed loop has 80 states)"


def test_analyze_json_carries_the_moving_robot_verdict(tmp_path_factory, small_domain):  # noqa: F811
    """``analyze --json``: the third verdict, here not computed by default (a 10-state loop) and saying why."""
    from test_cli_synth import GRID, cli_json

    from polyrob.io.controller import save_controller

    folder = tmp_path_factory.mktemp("moving")
    kfile = save_controller(pd_controller(), folder / "pd.json")
    argv = ["analyze", "paper_2r", "--pldi", small_domain, "--controller", kfile, "--uncertainty", "box", "--mc", "5"]
    _, doc, _ = cli_json(tmp_path_factory, "moving_analyze", lambda d: [*argv, *GRID, "--no-time-varying", "--json"])
    mv = doc["moving"]
    assert mv["computed"] is False and mv["certified"] is False and mv["status"] is None
    assert mv["verdict"].startswith("moving robot: robust performance not computed (the closed loop has 10 states")
    assert "--moving" in mv["verdict"]


def test_a_position_moves_at_its_velocity_at_each_grid_point(robot):
    """kinematic_rates: dq2/dt = qdot2 exactly at a grid point (scaled like the velocity bound, divided by c)."""
    from polyrob.analysis.lpv.robot import kinematic_rates

    d = Domain.from_robot(robot, "paper")
    model = scheduling(robot, d, points=(5, 3))
    rates, _ = rate_bounds(model, d)
    at = kinematic_rates(model, rates, 2.0)
    box = at(np.array([0.3, -1.0, 4.0]))
    assert box[0] == (2.0, 2.0) and box[1] == (rates[1][0] / 2, rates[1][1] / 2)
    half, _ = rate_bounds(model, d, scale=0.5)
    assert kinematic_rates(model, half)(np.array([0.3, -1.0, 4.0]))[0] == (2.0, 2.0)
    assert kinematic_rates(model, half)(np.array([0.3, -1.0, -9.9561]))[0] == pytest.approx((-4.978, -4.978), rel=1e-3)


def test_arbitrary_velocities_cover_more_than_bounded_ones(robot, small):
    """velocities="arbitrary": X on (1, cos q2, sin q2) only, the velocities free: never below the bounded search."""
    model = scheduling(robot, small, points=(4, 2))
    system = closed_loop_system(model, pd_controller(), 0.5 * np.eye(2), None)
    rates, _ = rate_bounds(model, small, scale=20.0)
    bounded = moving_robot_gain(model, system, rates, velocities="bounded", tensor=False)
    free = moving_robot_gain(model, system, rates, velocities="arbitrary")
    assert bounded.proved and free.proved
    assert free.n_basis == 3 and bounded.n_basis == 5
    assert bounded.frozen_gamma * (1 - 1e-6) <= bounded.gamma <= free.gamma * (1 + 1e-3)


def test_conditioning_makes_a_strict_lyapunov_matrix_the_identity(robot):
    """conditioned(): on the stiff 20-state tf3 x 4 loop (poles 1.9e-3 to 1.4e4 rad/s) X = c I proves 1.5 x its norm.

    The former Riccati step failed on this loop (ordered Schur form: 19 stable eigenvalues of 40); the
    strict solution (C'C + delta I) is the identity in the new coordinates, so the LMI solver starts well posed.
    """
    from polyrob.analysis.lpv.check import grid_data, proved_gamma
    from polyrob.analysis.lpv.robot import conditioned
    from polyrob.analysis.norms import hinf_norm
    from polyrob.io.controller import load_controller

    W_S, W_T = paper_weights(default_hyperparameters(2, bandwidth_scale=4.0))
    K = load_controller("tests/fixtures/paper_2r_tf3_alpha4_K.json")
    model = scheduling(robot, Domain.from_robot(robot, "paper"), points=(5, 3))
    system = closed_loop_system(model, K, W_S, W_T)
    centre = np.zeros(3)
    system_c, c = conditioned(system, centre, method="riccati")
    A, B, C, D = system_c(centre)
    h = hinf_norm(system(centre))
    assert h == pytest.approx(0.7211, abs=1e-3) and A.shape == (20, 20)
    g, chk = proved_gamma(grid_data([A], [B], [C], [D]), [c * np.eye(20)], h)
    assert chk.holds and h < g <= 2.0 * h  # 1.5 h, plus what the strictness term delta I costs


def test_a_bound_that_holds_only_at_the_grid_points_is_not_reported(robot, small):
    """The tensor basis fits X to the grid: below the frozen peak on 4 x 3 x 3 points, broken between them.

    The finer re-check (the same X at the 13 x 5 x 5 points of the box: four times the search's intervals per position, float64) finds it: the certificate's
    gamma is the finer grid's, above the coarse grid's and the frozen peak, and robust performance is not
    certified (with the coarse figure alone it would have been GRID_ONLY).
    """
    from polyrob.analysis.lpv.moving import moving_robot_certificate

    problem = NS(robot=robot, domain=small, P=NS(W_S=0.5 * np.eye(2), W_T=None, W_KS=None))
    c = moving_robot_certificate(problem, pd_controller(), points=(4, 3), rate_scale=20.0, velocities="bounded")
    assert c.result.proved and c.result.n_basis == 9 and c.finer["points"] == 325
    assert c.result.gamma < 1 and c.result.gamma < c.frozen_gamma  # on the coarse grid alone
    assert c.gamma == c.finer["gamma"] and c.gamma > max(1.0, c.result.gamma, c.frozen_gamma)
    assert c.certificate.status is Status.NOT_CERTIFIED and not c.finer["holds_at_gamma"]
    assert "re-checked at the 325 points of a finer grid" in c.certificate.scope.sentence()
    assert "finer grid of 325 points" in c.details()


def test_tensor_basis_has_the_velocity_part_per_position(robot):
    """default_basis(tensor=True): {1, cos q2, sin q2} x {1, qdot1, qdot2}, gradients by the product rule."""
    from polyrob.analysis.lpv.basis import basis_size, default_basis

    model = scheduling(robot, Domain.from_robot(robot, "paper"), points=(5, 3))
    basis = default_basis(model, tensor=True)
    assert len(basis) == 9 == basis_size(model, tensor=True) and basis_size(model) == 5
    rho, h = np.array([0.4, -1.2, 3.0]), 1e-6
    values = [f(rho) for f, _ in basis]
    assert values[-1] == pytest.approx(np.sin(0.4) * 3.0)  # sin q2 * qdot2
    for f, g in basis:
        num = [(f(rho + h * e) - f(rho - h * e)) / (2 * h) for e in np.eye(3)]
        assert np.allclose(g(rho), num, atol=1e-8)


def test_synth_moving_prints_and_returns_the_moving_verdict(robot, small, capsys):
    """``synth --moving``: the option parses, and moving_check() prints the third verdict and returns its summary."""
    from polyrob.cli import build_parser
    from polyrob.cli.common import Output
    from polyrob.cli.synth import moving_check

    args = build_parser().parse_args(["synth", "paper_2r", "--moving", "--quiet"])
    assert args.moving is True and build_parser().parse_args(["synth", "paper_2r"]).moving is False
    problem = NS(robot=robot, domain=small, P=NS(W_S=0.5 * np.eye(2), W_T=None, W_KS=None))
    doc = moving_check(problem, pd_controller(), Output(args, stages=1))
    text = capsys.readouterr().out
    assert doc["computed"] and doc["finer_grid"]["points"] == 425 and doc["gamma"] is not None
    assert doc["verdict"] in text and "finer grid of 425 points" in text
    assert doc["status"] in ("GRID_ONLY", "NOT_CERTIFIED") and doc["certified"] is False


def test_moving_harmonics_asks_for_the_bounded_search_with_more_harmonics():
    """``--moving-harmonics 2`` (analyze, run, synth): bounded accelerations, X on the second harmonic, 9 x 3 points."""
    from polyrob.cli import build_parser
    from polyrob.cli.analyze import moving_options

    for cmd in ("analyze", "run", "synth"):
        extra = ["--controller", "K.json"] if cmd == "analyze" else []
        args = build_parser().parse_args([cmd, "paper_2r", "--moving-harmonics", "2", *extra])
        assert moving_options(args) == {"velocities": "bounded", "harmonics": 2, "points": (9, 3)}
    assert moving_options(build_parser().parse_args(["run"])) is None
