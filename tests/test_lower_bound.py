"""The moving robot's gain from below: gains found along admissible trajectories never exceed the proved bound.

The finite-horizon gain of a frozen loop stays below its H-infinity norm even on a coarse step (the output's
energy integrated exactly, no aliasing); the trajectories keep ``dq/dt = qdot``, the velocity box and the
acceleration bounds; on paper_2r the gain found lies between the frozen peak at rest and the proved bound;
a loop whose gain exceeds 1 along a trajectory of the domain is not certified and its lower bound shows it.
"""

from __future__ import annotations

from types import SimpleNamespace as NS

import numpy as np
import pytest
from test_moving_robot import pd_controller

import polyrob
from polyrob.analysis.certificate import Status
from polyrob.analysis.lpv.moving import moving_robot_certificate
from polyrob.analysis.lpv.robot import rate_bounds, scheduling
from polyrob.analysis.norms import hinf_norm
from polyrob.analysis.time_varying.trajectory_gains import admissible_trajectories, trajectory_gains
from polyrob.domains.torque_box import Domain

#: A short search for the tests (the defaults are the benchmark's).
FAST = {"horizon": 4.0, "iterations": 8, "random_runs": 1}


@pytest.fixture(scope="module")
def robot():
    return polyrob.load_robot("paper_2r")


@pytest.fixture(scope="module")
def small(robot):
    d = Domain.from_robot(robot, "paper")
    return d.with_bounds(q_lower=np.full(2, -0.3), q_upper=np.full(2, 0.3), qdot_lower=d.qdot_lower * 0.05,
                         qdot_upper=d.qdot_upper * 0.05)  # fmt: skip


def test_a_frozen_loop_gains_at_most_its_hinf_norm_even_on_a_coarse_step():
    """A resonance at 2 rad/s, 0.4 s steps: the output's energy sampled at the steps would overshoot."""
    A = np.array([[0.0, 1.0], [-4.0, -0.2]])
    B, C, D = np.array([[0.0], [1.0]]), np.array([[4.0, 0.0]]), np.zeros((1, 1))
    norm = hinf_norm((A, B, C, D))
    t = np.arange(200) * 0.4
    g = trajectory_gains(lambda rho: (A, B, C, D), [("rest", np.zeros((t.size, 1)))], 0.4, iterations=40)
    assert 0.8 * norm < g[0] <= norm * (1 + 1e-9)



def test_a_stiff_loop_gains_at_most_its_hinf_norm():
    """Poles at 0.01 and 5000 rad/s on 0.05 s steps (|A| h = 250): the step's Gramian must not overflow.

    Van Loan's exponential on the whole step forms exp(5000 * 0.05): the main job's 16-state loop read a
    gain of 5e13 that way.  Its peak sits at 0 rad/s: 0.9 (the slow pole's DC gain).
    """
    A = np.diag([-0.01, -5000.0])
    B, C, D = np.array([[0.01], [5000.0]]), np.array([[0.9, 0.5]]), np.zeros((1, 1))
    norm = hinf_norm((A, B, C, D))
    assert 1.39 < norm < 1.41  # both paths in phase at 0 rad/s: 0.9 + 0.5
    t = np.arange(400) * 0.05
    g = trajectory_gains(lambda rho: (A, B, C, D), [("rest", np.zeros((t.size, 1)))], 0.05, iterations=30)
    assert g[0] <= norm * (1 + 1e-9)
    assert g[0] > 0.5  # the fast path alone passes 0.5 at every frequency below 5000 rad/s

def test_the_trajectories_are_admissible(robot):
    domain = Domain.from_robot(robot, "paper")
    model = scheduling(robot, domain, points=(5, 3))
    rates, _ = rate_bounds(model, domain)
    h = 1e-3
    t = np.arange(1500) * h
    trajs = admissible_trajectories(model, rates, t)
    assert len(trajs) >= 10
    lo = np.array([a[0] for a in model.axes])
    hi = np.array([a[-1] for a in model.axes])
    for name, rho in trajs:
        assert np.all(rho >= lo - 1e-12) and np.all(rho <= hi + 1e-12), name
        for i, kind in enumerate(model.kinds):
            if kind == "qdot":  # accelerations within the rate bound (finite differences of the velocity)
                assert np.abs(np.diff(rho[:, i])).max() <= rates[i][1] * h * (1 + 1e-9), name
        dq = np.angle(np.exp(1j * np.diff(rho[:, 0])))  # q2 moves at qdot2 (wrapped on the circle)
        v = 0.5 * (rho[1:, 2] + rho[:-1, 2])
        assert np.allclose(dq, v * h, atol=1e-9), name



def test_a_tasks_accelerations_follow_its_velocities_and_rest_means_none():
    """On a task the loop depends on qddot: a trajectory whose qddot is not d qdot/dt is not one the robot makes."""
    from polyrob.analysis.lpv.task import task_rate_bounds, task_scheduling
    from polyrob.analysis.time_varying.trajectory_gains import rest_peak
    from polyrob.domains.task import TaskDomain

    robot = polyrob.load_robot("planar_2r")
    task = TaskDomain.from_robot(robot, pose=[0.0, 1.5708], q_radius=0.5, qdot_max=1.0, qddot_max=2.0)
    model = task_scheduling(robot, task, points=(3, 3))
    rates = task_rate_bounds(model, task)
    h = 2e-3
    t = np.arange(3000) * h
    trajs = admissible_trajectories(model, rates, t)
    assert len(trajs) >= 4
    pairs = [(model.names.index(f"qdot{j}"), model.names.index(f"qddot{j}")) for j in (1, 2)]
    for name, rho in trajs:
        for v, a in pairs:
            assert np.abs(rho[:, a]).max() <= 2.0 * (1 + 1e-9), name
            slope = np.diff(rho[:, v]) / h  # the velocity's change over each step
            mean = 0.5 * (rho[1:, a] + rho[:-1, a])
            off = np.abs(slope - mean) > 2e-3 * 2.0 + 1e-9
            assert off.mean() < 0.01, (name, v, off.mean())  # a switch of a bang-bang or random run at most
    A, B, C, D = np.eye(1) * -1.0, np.ones((1, 1)), np.ones((1, 1)), np.zeros((1, 1))
    seen = []

    def system(rho):
        seen.append(np.array(rho))
        return A, B, C, D

    rest_peak(model, system, points=3)
    at_rest = np.array(seen)
    for _v, a in pairs:
        assert np.all(at_rest[:, a] == 0.0)  # at rest every acceleration is 0
    assert np.all(at_rest[:, model.names.index("qdot2")] == 0.0)  # q2 enters: its velocity is 0 at rest

def test_the_lower_bound_never_exceeds_the_proved_bound(robot, small):
    problem = NS(robot=robot, domain=small, P=NS(W_S=0.5 * np.eye(2), W_T=None, W_KS=None))
    c = moving_robot_certificate(problem, pd_controller(), points=(4, 2), tensor=False, velocities="bounded",
                                 recheck=None, lower_bound=FAST)  # fmt: skip
    assert c.result.proved and c.lower
    low = c.lower["gamma"]
    assert c.lower["frozen_gamma"] <= low <= c.gamma
    assert low > 0.5 * c.gamma  # a real gain, not a token
    assert "fails" not in c.verdict  # below 1: nothing refuted
    assert all(g <= c.gamma for _, g in c.lower["gains"])
    assert f"L2 gain >= {low:.4g} found along" in c.verdict
    assert c.summary()["lower"]["gamma"] == low and c.summary()["lower_bound"] == low
    from polyrob.report.certificates import lower_bound_words

    assert lower_bound_words({"moving": c.summary(), "scope": {}}).startswith(f"gain >= {low:.4g}")


def test_a_loop_whose_gain_exceeds_1_along_a_trajectory_is_not_certified(robot, small):
    problem = NS(robot=robot, domain=small, P=NS(W_S=4.0 * np.eye(2), W_T=None, W_KS=None))
    c = moving_robot_certificate(problem, pd_controller(), points=(4, 2), tensor=False, velocities="bounded",
                                 recheck=None, lower_bound=FAST)  # fmt: skip
    moving = max(g for _, g in c.lower["gains"])
    assert moving > 1.0 and c.lower["gamma"] > 1.0  # a trajectory of the domain along which the gain exceeds 1
    assert c.certificate.status is Status.NOT_CERTIFIED
    assert not c.certificate.certified
    assert not (c.gamma < 1.0)
    assert "robust performance fails for the linearised robot along that motion (simulated)" in c.verdict


def _mixing_loop(rho, eps=0.01, k=0.02):
    """A slow state that integrates the velocity times a high-passed input, beside a resonance at 10 rad/s.

    Frozen, no input reaches the slow state at 0 rad/s (the high pass) and the peak is 0.25 (either path);
    moving, a velocity that switches in step with the input rectifies it, and the slow state (time constant
    1/eps = 100 s) builds a gain of up to k/eps = 2 over hundreds of seconds.
    """
    v = float(rho[0])
    A = np.array([[-1.0, 0, 0, 0], [-v, -eps, 0, 0], [0, 0, 0, 1.0], [0, 0, -100.0, -2.0]])
    B = np.array([[1.0], [v], [0.0], [1.0]])
    C = np.array([[0, k, 0, 0], [0, 0, 0, 0.5]])
    return A, B, C, np.zeros((2, 1))


def test_a_slow_loop_s_gain_along_a_bang_bang_velocity_is_found_by_the_long_runs():
    """The short horizon (tens of seconds, from the frozen peak at 10 rad/s) sees only the frozen 0.25.

    A bound from above: ||v hp(d)|| <= ||d|| (|v| <= 1, |s/(s+1)| <= 1), so the slow path gains at most
    k/eps = 2 and the whole loop at most sqrt(2^2 + 0.25^2): no gain found may pass it.
    """
    from polyrob.analysis.time_varying.trajectory_gains import trajectory_lower_bound

    model = NS(names=("qdot1",), kinds=("qdot",), joints=(0,), axes=(np.linspace(-1.0, 1.0, 3),))
    short = trajectory_lower_bound(model, _mixing_loop, [(-2.0, 2.0)], long_horizon=False)
    assert short.frozen_gamma == pytest.approx(0.25, rel=1e-3)
    assert short.gamma < 0.26
    found = trajectory_lower_bound(model, _mixing_loop, [(-2.0, 2.0)])
    assert found.gamma > 0.8 > 3 * found.frozen_gamma  # the rectified input, built up over the long run
    assert found.gamma <= np.hypot(2.0, 0.25)
    assert found.worst.startswith("bang-bang qdot1") and found.worst.endswith("over 400 s")  # 4 time constants
    assert found.horizon == pytest.approx(400.0) and found.step >= short.step


def test_the_long_runs_hold_each_still_position_at_its_ends_and_midpoint():
    from polyrob.analysis.lpv.task import task_rate_bounds, task_scheduling
    from polyrob.analysis.time_varying.trajectory_gains import admissible_trajectories
    from polyrob.domains.task import TaskDomain

    robot = polyrob.load_robot("planar_2r")
    task = TaskDomain.from_robot(robot, pose=[0.0, 1.5708], q_radius=0.5, qdot_max=1.0, qddot_max=2.0)
    model = task_scheduling(robot, task, points=(3, 3))
    t = np.arange(400) * 0.05
    trajs = dict(admissible_trajectories(model, task_rate_bounds(model, task), t, levels=True,
                                         families=("bang-bang",)))  # fmt: skip
    q2, v1, v2, a1 = (model.names.index(n) for n in ("q2", "qdot1", "qdot2", "qddot1"))
    held = {name: rho for name, rho in trajs.items() if "at q2 =" in name}
    assert len(held) == 3 and len(trajs) == 4  # qdot1 at three q2; qdot2 moves q2 itself
    assert sorted(float(rho[0, q2]) for rho in held.values()) == pytest.approx([1.0708, 1.5708, 2.0708])
    for rho in held.values():
        assert np.ptp(rho[:, q2]) == 0.0 and np.all(rho[:, v2] == 0.0)
        assert np.abs(rho[:, v1]).max() == pytest.approx(1.0, abs=0.05) and set(np.abs(rho[:, a1])) == {2.0}
