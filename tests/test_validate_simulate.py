"""The nonlinear robot in closed loop: settling, torque, and the domain check behind the certificate."""

from __future__ import annotations

import functools
from pathlib import Path

import control
import numpy as np
import pytest

import polyrob
from polyrob.io.controller import load_controller
from polyrob.validate.simulate import equilibrium_torque, simulate, smooth_reference, step_reference

FIXTURE = Path(__file__).parent / "fixtures" / "validate_planar_2r_K.json"


@functools.cache
def _setup():
    robot = polyrob.load_robot("planar_2r")
    return robot, polyrob.Domain.from_robot(robot), load_controller(FIXTURE)


@pytest.mark.parametrize(
    "q0, step",
    [
        ([0.0, 0.0], [0.01, -0.005]),
        ([0.5, 1.0], [-0.008, 0.01]),
        ([-1.0, -2.0], [0.005, 0.005]),
        ([2.0, 0.3], [0.0, -0.01]),
    ],
)
def test_synthesised_controller_settles_inside_domain(q0, step):
    """polyrob's own controller for planar_2r (fixture: D-G-K + reduction) on the Pinocchio model."""
    robot, dom, K = _setup()
    target = np.add(q0, step)
    sim = simulate(robot, K, dom, step_reference(target), q0=q0, t_final=15.0)
    assert sim.success
    assert sim.stayed_in_domain, sim.verdict()
    assert sim.settled(0.02), [m.steady_state_error for m in sim.metrics]
    assert np.allclose(sim.q[:, -1], target, atol=2e-4)
    assert sim.torque_within_limits
    for mt in sim.metrics:
        assert mt.peak_torque <= robot.effort_limit[0]
        if abs(mt.step) > 0:
            assert 0 < mt.rise_time < 2.0 and mt.settling_time < 10.0 and mt.overshoot < 50.0
    # the torque reported is what the controller commanded: u = u_eq + K e, u_eq = 0 (no gravity)
    assert np.array_equal(sim.u_eq, [0.0, 0.0])


def test_large_step_is_reported_as_leaving_the_domain():
    robot, dom, K = _setup()
    sim = simulate(robot, K, dom, step_reference([0.3, 0.0]), t_final=3.0)
    assert sim.left_domain and not sim.stayed_in_domain
    assert any(x.startswith("u[joint1]") for x in sim.domain_exits)
    assert sim.verdict().endswith("no certificate applies to this trajectory")
    assert not sim.torque_within_limits
    assert sim.summary()["stayed_in_domain"] is False


def test_reference_outside_the_position_range_leaves_the_domain():
    robot, dom, K = _setup()
    assert dom.q_upper[1] == pytest.approx(np.pi)
    sim = simulate(robot, K, dom, smooth_reference([0.0, 3.3], duration=5.0), q0=[0.0, 3.0], t_final=12.0)
    assert sim.left_domain
    assert any(x.startswith("q[joint2]") for x in sim.domain_exits)
    # it left when q2 crossed pi, not before
    k = np.argmax(sim.q[1] > np.pi)
    assert sim.first_exit_time <= sim.t[k] + 1e-12


def test_sampled_and_held_controller_tracks_like_the_continuous_one():
    robot, dom, K = _setup()
    ref = step_reference([0.01, -0.005])
    cont = simulate(robot, K, dom, ref, t_final=4.0)
    disc = simulate(robot, K, dom, ref, t_final=4.0, rate=1000.0)
    assert disc.controller == "discrete" and disc.rate == 1000.0
    assert disc.stayed_in_domain
    q_c = np.array([np.interp(disc.t, cont.t, cont.q[j]) for j in range(2)])
    assert np.max(np.abs(disc.q - q_c)) < 0.05 * 0.01  # within 5 % of the step


def test_analytic_robot_with_paper_controller():
    robot = polyrob.load_robot("paper_2r")
    dom = polyrob.Domain.from_robot(robot)  # the paper's domain: u = 0 exactly
    sim = simulate(robot, polyrob.paper_controller(), dom, step_reference([0.002, 0.0]), t_final=8.0)
    assert sim.success and abs(sim.q[0, -1] - 0.002) < 1e-4
    # the paper's domain has u in [0, 0]: any torque leaves it, and the result says so
    assert sim.left_domain and any(x.startswith("u[") for x in sim.domain_exits)


def test_damping_is_included(tmp_path):
    """Pinocchio's aba ignores model.damping; the simulation must not."""
    text = (Path(polyrob.__file__).parent / "urdf" / "planar_2r.urdf").read_text()
    path = tmp_path / "damped_2r.urdf"
    path.write_text(text.replace('damping="0.0"', 'damping="5.0"'))
    robot = polyrob.load_robot(str(path))
    assert np.array_equal(robot.damping, [5.0, 5.0])
    dom = polyrob.Domain.from_robot(robot)
    zero = control.ss([], [], [], np.zeros((2, 2)))
    kinetic = lambda s, k: 0.5 * s.qdot[:, k] @ robot.mass_matrix(s.q[:, k]) @ s.qdot[:, k]  # noqa: E731
    damped = simulate(robot, zero, dom, lambda t: np.zeros(2), qdot0=[1.0, -0.5], t_final=2.0)
    free = simulate(polyrob.load_robot("planar_2r"), zero, dom, lambda t: np.zeros(2), qdot0=[1.0, -0.5], t_final=2.0)
    assert kinetic(free, -1) == pytest.approx(kinetic(free, 0), rel=1e-5)  # no gravity, no damping: conserved
    # dE/dt = -qdot' D qdot: the energy lost equals the integral of the damping power
    power = np.array([5.0 * damped.qdot[:, k] @ damped.qdot[:, k] for k in range(len(damped.t))])
    lost = kinetic(damped, 0) - kinetic(damped, -1)
    assert lost == pytest.approx(np.trapezoid(power, damped.t), rel=1e-3)
    assert lost > 0.3 * kinetic(damped, 0)


def test_equilibrium_torque_is_gravity():
    robot = polyrob.load_robot("ur5")
    q = np.array([0.1, -0.7, 0.5, 0.0, 0.2, 0.0])
    u = equilibrium_torque(robot, q)
    assert np.allclose(robot.acceleration(q, np.zeros(6), u), 0.0, atol=1e-9)


def test_time_budget_keeps_the_result_of_a_run_that_finishes():
    """Integrated in pieces under a budget, the trajectory is the one-piece one."""
    robot, dom, K = _setup()
    ref = step_reference([0.01, -0.005])
    whole = simulate(robot, K, dom, ref, t_final=5.0)
    pieces = simulate(robot, K, dom, ref, t_final=5.0, max_evaluations=10**7)
    assert pieces.success and pieces.stayed_in_domain
    assert np.allclose(pieces.q[:, -1], whole.q[:, -1], atol=1e-7)
    q_w = np.array([np.interp(pieces.t, whole.t, whole.q[j]) for j in range(2)])
    assert np.max(np.abs(pieces.q - q_w)) < 1e-6


@pytest.mark.parametrize("rate", [None, 1000.0])
def test_the_time_limit_you_set_stops_a_simulation_and_says_so(rate, monkeypatch):
    """A fake clock 1 s further at each reading: a limit of 50 s fires early in the run, whatever the load."""
    from clocks import FakeClock

    robot, dom, K = _setup()
    FakeClock(step=1.0).install(monkeypatch)
    sim = simulate(robot, K, dom, step_reference([0.01, -0.005]), t_final=50.0, rate=rate, time_budget=50.0)
    assert not sim.success and not sim.stayed_in_domain
    assert "stopped by the time limit of 50 s you set" in sim.verdict()
    assert sim.t[-1] < 50.0 and sim.q.shape[1] == len(sim.t)


@pytest.mark.parametrize("rate", [None, 1000.0])
def test_a_simulation_is_bounded_by_its_evaluations_and_not_by_the_clock(rate, monkeypatch):
    """Before: the batch's and the report's simulations stopped after 120 s / 300 s of wall clock, so a
    loaded machine reported "not finished" where an idle one validated.  Now a count of evaluations: a
    clock running 1000x faster gives the same trajectory, and the limit names itself."""
    from clocks import slowed_clock

    robot, dom, K = _setup()
    ref = step_reference([0.01, -0.005])
    normal = simulate(robot, K, dom, ref, t_final=5.0, rate=rate, max_evaluations=2000)
    slowed_clock(monkeypatch, 1000.0)
    slowed = simulate(robot, K, dom, ref, t_final=5.0, rate=rate, max_evaluations=2000)
    assert not normal.success and "limit of 2000 evaluations of the dynamics" in normal.verdict()
    assert 0 < normal.t[-1] < 5.0
    assert np.array_equal(slowed.t, normal.t) and np.array_equal(slowed.q, normal.q)


def test_time_budget_must_be_positive():
    robot, dom, K = _setup()
    with pytest.raises(polyrob.PolyrobError, match="time_budget"):
        simulate(robot, K, dom, step_reference([0.01, 0.0]), t_final=1.0, time_budget=0.0)


def test_a_hold_start_keeps_the_true_robot_at_rest_behind_computed_torque():
    """ur5 behind computed torque from a model 10 % off: the nominal input accelerates the true robot
    at t = 0 by the gravity mismatch (the batch saw |qddot| > 2 rad/s^2 at t = 0 on so101); from the
    input that holds it (a settled integral action) it stays at rest, with no controller at all."""
    from polyrob.domains.task import TaskDomain
    from polyrob.model.inner import inner_loop

    arm = inner_loop(polyrob.load_robot("ur5"), "computed-torque", model_error=0.1)
    dom = TaskDomain.from_robot(arm, q_radius=0.2, qdot_max=0.5, qddot_max=2.0)
    q0 = 0.5 * (dom.q_lower + dom.q_upper)
    K = np.zeros((arm.m, arm.m))
    true = arm.drawn(np.random.default_rng(0))
    assert true.scenario and np.abs(true.acceleration(q0, 0 * q0, 0 * q0)).max() > 0.5  # the model error pulls
    held = simulate(arm, K, dom, q0, t_final=0.5, q0=q0, u_eq="hold")
    assert held.info["u_eq_source"] == "the input holding q0 at rest"
    assert np.abs(held.q - q0[:, None]).max() < 1e-6 and not held.left_domain
    free = simulate(arm, K, dom, q0, t_final=0.5, q0=q0, u_eq=np.zeros(arm.m))
    assert np.abs(free.q - q0[:, None]).max() > 1e-2
