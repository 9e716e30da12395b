"""The moving-robot certificate on an inner-gain model: the masses constant, the state moving at any rate (issue 19).

``polyrob.analysis.lpv.constant`` keeps the model's physical constant (the
link-mass factor ``eps``) a real block of μ and merges the residual blocks,
scaled by a constant, with the performance channels into one full block.
Checked here on the planar 2R with computed torque and a 10 % mass error:
its figure lies between the frozen robot's μ and the arbitrarily fast
small gain; the scaled loop's H-infinity norm at constant ``eps`` is below
it (main loop theorem); a simulated time-varying residual (the state
moving) with ``eps`` constant has an L2 gain below it; a model whose
parameters move with the state is sent to the rate-bounded route.

The controller ``tests/fixtures/planar_2r_ct_pid_K.json`` is ``polyrob synth
planar_2r --inner computed-torque --model-error 10 --pose 0.4,0.3
--q-radius 0.3 --qdot-max 0.5 --qddot-max 2 --structure pid -o ...``.
"""

from __future__ import annotations

from pathlib import Path

import control
import numpy as np
import pytest

from polyrob import load_robot
from polyrob.analysis.lpv.constant import (
    applies,
    constant_parameter_certificate,
    residual_scalings,
    robot_in_motion_certificate,
    scaled_plant,
    without_motion,
)
from polyrob.analysis.norms import hinf_norm
from polyrob.domains.task import TaskDomain
from polyrob.io.controller import load_controller
from polyrob.model.inner import inner_loop
from polyrob.pipeline import build_problem
from polyrob.plant.loops import lft

FIXTURE = Path(__file__).parent / "fixtures" / "planar_2r_ct_pid_K.json"


@pytest.fixture(scope="module")
def problem():
    arm = inner_loop(load_robot("planar_2r"), "computed-torque", model_error=0.1)
    dom = TaskDomain.from_robot(arm, pose=[0.4, 0.3], q_radius=0.3, qdot_max=0.5, qddot_max=2.0)
    return build_problem(arm, dom, progress=False, bound_options={"samples": 1024})


@pytest.fixture(scope="module")
def result(problem):
    return constant_parameter_certificate(problem, load_controller(FIXTURE))


def test_certified_between_the_frozen_and_the_arbitrarily_fast_figures(problem, result):
    from polyrob.analysis.certificate import certify_loop
    from polyrob.analysis.time_varying.smallgain import scaled_small_gain

    K = load_controller(FIXTURE)
    assert problem.P.uncertain.model == "inner-gain" and applies(problem) is None
    cert = result.certificate
    assert result.computed and cert.certified, result.verdict
    assert cert.bound == pytest.approx(0.98, abs=0.03)
    frozen = certify_loop(problem.P, K)  # every frozen robot: mu with the residual LTI too
    assert frozen.certified and frozen.bound <= cert.bound
    fast = scaled_small_gain(lft(problem.P, K), problem.P.block_structure_rp)  # the mass varying too
    assert fast.gamma > 1.0 > cert.bound
    assert "eps constant (rate 0), the state (q, qdot, qddot) moving at any rate" in result.verdict
    assert "CERTIFIED: mu <=" in result.verdict and "in motion inside the domain" in cert.scope.sentence()
    s = result.summary()
    assert s["certified"] and s["route"] == "mu, constant parameters" and s["mu_lower"] <= s["gamma"]
    assert s["frozen_gamma"] is None  # not a frozen peak: the mu lower bound of the scaled structure


def _scaled_loop(problem, result, delta):
    """The loop ``[d_full; r] -> [v_full; z]`` (scaled) at constant ``eps = delta`` (normalised)."""
    from polyrob.plant.lftplant import upper_lft_matrices

    assert "times 1)" in result.scope.notes[0]  # certified at the small gain's own scaling
    plant, blk = scaled_plant(problem.P, residual_scalings(problem.P, load_controller(FIXTURE))[0])
    m = problem.P.n_u
    N = lft(plant, load_controller(FIXTURE), n_u=m, n_y=m)
    r = -int(blk[0][0])
    return upper_lft_matrices(N.A, N.B, N.C, N.D, delta * np.eye(r))


def test_the_scaled_loop_at_each_constant_mass_is_below_the_bound(problem, result):
    """Main loop theorem: mu < beta at every frequency gives ||D N(delta) D^-1||_inf <= beta for each constant delta."""
    bound = result.certificate.bound
    norms = [hinf_norm(_scaled_loop(problem, result, delta)) for delta in np.linspace(-1.0, 1.0, 9)]
    assert max(norms) <= bound * (1 + 1e-6)
    assert max(norms) > 0.9 * bound  # and the bound is not loose: 0.967 at eps's lower end against 0.98


def test_a_time_varying_residual_at_constant_mass_keeps_the_gain_below_the_bound(problem, result):
    """The state moving: a residual Delta(t) (norm one, switching every 50 ms) closed around the scaled loop."""
    from scipy.integrate import solve_ivp, trapezoid

    A, B, C, D = _scaled_loop(problem, result, -1.0)
    n_f = B.shape[1] - problem.P.n_w  # residual channels (d side); v side
    n_v = C.shape[0] - problem.P.n_z
    rng = np.random.default_rng(3)
    T, h = 4.0, 0.05
    deltas = []
    for _ in range(int(T / h) + 1):
        U, _s, Vt = np.linalg.svd(rng.standard_normal((n_f, n_v)), full_matrices=False)
        deltas.append(U @ Vt)  # norm one: the residual at its bound
    assert np.abs(D[:n_v, :n_f]).max() < 1e-12  # no algebraic loop through the residual

    def r_of(t):
        return np.array([np.sin(3 * t + k) for k in range(problem.P.n_w)]) * (t < 2.0)

    def rhs(t, x):
        Dl = deltas[int(t / h)]
        w = Dl @ (C[:n_v] @ x)
        return A @ x + B[:, :n_f] @ w + B[:, n_f:] @ r_of(t)

    ts = np.linspace(0.0, T, 4001)
    sol = solve_ivp(rhs, (0.0, T), np.zeros(A.shape[0]), t_eval=ts, max_step=h / 4, rtol=1e-8, atol=1e-10)
    z = np.array([C[n_v:] @ sol.y[:, k] + D[n_v:, n_f:] @ r_of(t) for k, t in enumerate(ts)])
    r = np.array([r_of(t) for t in ts])
    gain = np.sqrt(trapezoid(np.sum(z**2, axis=1), ts) / trapezoid(np.sum(r**2, axis=1), ts))
    assert gain < result.certificate.bound


def test_a_model_whose_parameters_move_goes_to_the_rate_bounded_route():
    from types import SimpleNamespace

    from polyrob.analysis.lpv.moving_result import MovingRobotCertificate

    lft_problem = SimpleNamespace(P=SimpleNamespace(uncertain=SimpleNamespace(model="lft")))
    assert "move with the robot's state" in applies(lft_problem)
    out = constant_parameter_certificate(lft_problem, control.ss([], [], [], np.eye(2)))
    assert isinstance(out, MovingRobotCertificate) and not out.computed
    with pytest.raises(AttributeError):  # the other route reads the problem's robot and domain
        robot_in_motion_certificate(lft_problem, control.ss([], [], [], np.eye(2)))


def test_an_inner_loop_on_a_model_whose_parameters_move_names_the_time_varying_verdict(problem):
    """ur5's per-link set printed "not computed (an inner loop: its moving-robot verdict is the any-rate one
    (inner-gain model))": no such verdict was computed.  On a model whose direction scalars move with the state and
    that has no model of constants (inner-links-real; inner-links has inner-links-moving, tests/test_moving_links.py)
    only the time-varying verdict covers the moving robot, and the line says so; a jerk bound is refused with an
    inner layer."""
    from types import SimpleNamespace

    from polyrob.errors import ArgumentError

    links = SimpleNamespace(P=SimpleNamespace(uncertain=SimpleNamespace(model="inner-links-real")), robot=problem.robot,
                            domain=problem.domain)  # fmt: skip
    out = robot_in_motion_certificate(links, control.ss([], [], [], np.eye(2)))
    assert not out.computed and "'inner-links-real' model's parameters move" in out.notes[-1]
    assert "only the time-varying verdict" in out.notes[-1] and "inner-gain model)" not in out.notes[-1]
    with pytest.raises(ArgumentError, match="without an inner layer"):
        robot_in_motion_certificate(links, control.ss([], [], [], np.eye(2)), jerk=5.0)


def test_a_failed_test_is_not_certified_never_a_violation(problem):
    """Half the PID's gain: mu of the scaled structure >= 1 says the test fails, not that a robot violates it."""
    from polyrob.analysis.certificate import Status

    weak = constant_parameter_certificate(problem, load_controller(FIXTURE) * 0.5, tries=(1.0,))
    assert weak.certificate.status is Status.NOT_CERTIFIED
    assert weak.certificate.mu_lower >= 1.0 and "this test cannot prove it" in weak.verdict


def test_the_bandwidth_search_on_the_moving_criterion_ranks_by_it(problem):
    """``design_max_bandwidth(moving=True)``: the factor's figure is the moving robot's mu, not the frozen one's."""
    from types import SimpleNamespace

    from polyrob.errors import ArgumentError
    from polyrob.pipeline.design import design_max_bandwidth, moving_judge

    moving = design_max_bandwidth(problem, moving=True, alphas=(4.0,), structure="pid", progress=False)[1]
    frozen = moving.result.certificate  # the same controller's frozen-robot certificate
    assert moving.alpha == 4.0 and frozen.certified
    assert frozen.bound < moving.peak_mu < 1.0  # 0.66 and 0.82: the moving robot asks more
    lft_problem = SimpleNamespace(P=SimpleNamespace(uncertain=SimpleNamespace(model="lft")))
    with pytest.raises(ArgumentError, match="needs an inner-gain model"):
        moving_judge(lft_problem)


def test_searched_scalings_lower_the_merged_peak_and_are_those_of_the_scaled_plant(problem):
    """Any constant ``d`` gives a valid bound; the search keeps the best it saw, measured on the scaled plant itself."""
    from polyrob.analysis.lpv.constant import SEARCH_GRID, search_scalings
    from polyrob.analysis.mu.bounds import mussv
    from polyrob.analysis.mu.frequency import matrix_response

    K = load_controller(FIXTURE)
    d0, _ = residual_scalings(problem.P, K)
    omega = np.logspace(np.log10(SEARCH_GRID[0]), np.log10(SEARCH_GRID[1]), SEARCH_GRID[2])

    def peak(d):
        plant, blk = scaled_plant(problem.P, d)
        N = lft(plant, K, n_u=2, n_y=2)
        H = matrix_response(*(np.asarray(X, float) for X in (N.A, N.B, N.C, N.D)))(omega)
        return max(mussv(H[k], blk, lower=False).upper for k in range(len(omega)))

    found = search_scalings(problem.P, K, 3.0 * d0)  # a poor start: the search must come back down
    assert peak(found) < 0.95 * peak(3.0 * d0)


def test_tuning_for_the_moving_robot_wins_the_certificate_the_frozen_design_lost(problem, result):
    """The fixture's PID at half gain: frozen certified, the moving robot not; tuned on the merged structure, the moving
    robot's certificate (from the tuning's scalings) falls below the start's and the frozen robot stays certified."""
    from polyrob.analysis.certificate import certify_loop
    from polyrob.synthesis.moving import tune_for_moving

    start = load_controller(FIXTURE) * 0.5
    before = constant_parameter_certificate(problem, start, tries=(1.0,))
    tuning = tune_for_moving(problem, start, rounds=1, max_iter=2)
    after = constant_parameter_certificate(problem, tuning.controller, scalings=tuning.scalings, tries=(1.0,))
    assert not before.certificate.certified and after.certificate.certified  # 1.023 -> 0.817 (2026-12-01)
    assert after.gamma < before.gamma and tuning.history[0] < before.gamma
    assert certify_loop(problem.P, start).certified and certify_loop(problem.P, tuning.controller).certified


def test_tuning_for_the_moving_robot_needs_a_model_of_constants():
    from types import SimpleNamespace

    from polyrob.errors import ArgumentError
    from polyrob.synthesis.moving import tune_for_moving

    lft_problem = SimpleNamespace(P=SimpleNamespace(uncertain=SimpleNamespace(model="lft")))
    with pytest.raises(ArgumentError, match="needs a model of constants"):
        tune_for_moving(lft_problem, control.ss([], [], [], np.eye(2)))


def test_a_tuning_that_loses_the_frozen_certificate_and_wins_nothing_is_not_kept(problem, monkeypatch):
    """ur5 per link: three rounds left the merged mu at 1.967 and took the frozen mu from 0.931 to 1.465; the
    certified design is what the user keeps then, and the record says why."""
    import polyrob.synthesis.moving as moving
    from polyrob.analysis.certificate import certify_loop
    from polyrob.pipeline.design import Design, tuned_for_moving
    from polyrob.synthesis.moving import MovingTuning

    K = load_controller(FIXTURE)
    design = Design(controller=K, result=None, reduced=None, record={}).certified_by(certify_loop(problem.P, K))
    assert design.certificate.certified
    worse = K * 40.0  # a PID far off the weights: its frozen mu is far above 1
    monkeypatch.setattr(moving, "tune_for_moving", lambda *a, **k: MovingTuning(worse, np.ones(2), (1.5,), "pid", 0.0))
    kept = tuned_for_moving(problem, design, rounds=1)
    assert kept.controller is K and kept.certificate is design.certificate
    assert kept.record["moving_tuning"]["kept"] is False and kept.record["moving_tuning"]["frozen_mu"] > 1.0
    assert "the design kept" in kept.notes[-1]
    # a tuning that reached merged mu below 1 is kept even so
    monkeypatch.setattr(moving, "tune_for_moving", lambda *a, **k: MovingTuning(worse, np.ones(2), (0.9,), "pid", 0.0))
    assert tuned_for_moving(problem, design, rounds=1).controller is worse


def test_without_motion_keeps_the_constant_blocks_and_the_performance_channels():
    """Closing the moving blocks at zero drops their channels only; without flags every full block moves (``inner-gain``)."""
    from types import SimpleNamespace

    blk = np.array([[2, 2], [-1, 0], [3, 3], [-2, 0]])  # full (moving), real, full (constant), repeated real
    flags = [{"moving": True}, {"moving": False}]
    P = SimpleNamespace(
        block_structure_rs=blk, n_w=4, n_z=5, uncertain=SimpleNamespace(info={"residual_blocks": flags})
    )
    outs, ins, kept = without_motion(P)
    assert ins.tolist() == list(range(2, 12)) and outs.tolist() == list(range(2, 13))  # d 0-7, w 8-11; v 0-7, z 8-12
    assert kept.tolist() == [[-1, 0], [3, 3], [-2, 0], [4, 5]]
    gain = SimpleNamespace(block_structure_rs=blk, n_w=4, n_z=5, uncertain=SimpleNamespace(info={}))
    outs, ins, kept = without_motion(gain)
    assert ins.tolist() == [2, 6, 7, 8, 9, 10, 11] and outs.tolist() == [2, 6, 7, 8, 9, 10, 11, 12]
    assert kept.tolist() == [[-1, 0], [-2, 0], [4, 5]]


def test_the_moving_robots_worst_case_gain_is_bounded_on_the_same_structure(problem):
    """``worst_case=True``: the moving robot's weighted gain over the whole set, proved at every frequency.

    Robust performance is certified here (μ ≤ b < 1 on the merged
    structure), so the level is at most about ``b``; the nominal loop is one
    of the moving robots (the constants at their centre, the residual at
    zero), so the level is at least its gain.  No member is claimed.
    """
    from polyrob.analysis.robust import nominal_performance

    K = load_controller(FIXTURE)
    mv = constant_parameter_certificate(problem, K, worst_case=True)
    wc = mv.worst_case
    assert wc.proved and wc.certificate.certified and wc.lower == 0.0
    assert nominal_performance(problem.P, K) <= wc.upper <= 1.02 * mv.certificate.bound
    assert "in motion inside the domain" in wc.certificate.scope.variation
    assert "moving robot over the whole set: every motion stable, weighted gain <=" in mv.details()
    assert mv.summary()["worst_case"]["proved"] is True
