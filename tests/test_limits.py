"""The performance limit of unstable poles: a true floor under every controller's ||W_T T||."""

from __future__ import annotations

from types import SimpleNamespace

import control
import numpy as np
import pytest

import polyrob
from polyrob import Domain
from polyrob.analysis.certificate import Certificate, Scope, decide_gain
from polyrob.analysis.limits import performance_limit, pole_bound
from polyrob.plant.weights import complementary_weight, paper_weights
from polyrob.synthesis.bandwidth import max_bandwidth_scaling


def _unstable_mass(a: float = 4.0) -> np.ndarray:
    """``qddot = a q + u``: poles at ±sqrt(a)."""
    return np.array([[0.0, 1.0], [a, 0.0]])


def test_pole_bound_is_the_weight_at_the_unstable_pole():
    W_T = complementary_weight(10.0, 2.0, 0.01)
    bound, pole, direction = pole_bound(_unstable_mass(4.0), W_T, 1)
    assert pole == pytest.approx(2.0)
    assert np.abs(direction) == pytest.approx([1.0])
    assert bound == pytest.approx(abs(complex(W_T(2.0))), rel=1e-12)
    assert pole_bound(np.array([[0.0, 1.0], [-4.0, -1.0]]), W_T, 1) == (0.0, None, None)  # stable: no floor


@pytest.mark.parametrize("kp, kd", [(8.0, 3.0), (20.0, 6.0), (60.0, 12.0), (200.0, 30.0)])
def test_every_stabilising_controller_stays_above_the_bound(kp, kd):
    """||W_T T|| of stabilising PD loops on 1/(s^2 - 4) is never below |W_T(2)| (what a floor must be)."""
    W_T = complementary_weight(10.0, 2.0, 0.01)
    bound = pole_bound(_unstable_mass(4.0), W_T, 1)[0]
    G = control.tf([1.0], [1.0, 0.0, -4.0])
    K = control.tf([kd, kp], [0.01, 1.0])  # PD with a filter
    T = control.feedback(G * K, 1)
    assert np.all(np.real(control.poles(T)) < 0)
    w = np.logspace(-3, 4, 4000)
    peak = np.max(np.abs((W_T * T)(1j * w)))
    assert peak >= bound * (1 - 1e-9)


def test_paper_2r_limit_is_the_value_at_a_point_of_the_domain():
    robot = polyrob.load_robot("paper_2r")
    dom = Domain.from_robot(robot, "paper")
    W_T = paper_weights()[1]
    lim = performance_limit(robot, dom, W_T, samples=512, starts=1)
    assert dom.contains(lim.q[None], lim.qdot[None], lim.u[None]).all()
    A, _ = robot.jacobians(lim.q, lim.qdot, lim.u)
    assert lim.bound == pytest.approx(pole_bound(A, W_T, 2)[0], rel=1e-12)
    assert lim.pole.real > 0 and lim.bound > 0.6
    # a weight twice as demanding doubles the floor: then mu < 1 is provably out of reach
    twice = performance_limit(robot, dom, 2 * W_T, samples=512, starts=1)
    assert twice.bound == pytest.approx(2 * pole_bound(A, W_T, 2)[0], rel=0.05)
    assert twice.excludes_mu_below_one and "out of reach" in twice.summary()


def test_bandwidth_scan_skips_factors_the_limit_excludes():
    calls = []

    def fake(P, K0):
        calls.append(P.alpha)
        mu = P.alpha**2 / 8 + 0.5 / P.alpha
        cert = Certificate(decide_gain(True, mu, True)[0], mu, mu, float("nan"), None, Scope())
        return SimpleNamespace(certificate=cert, controller=None, order=0)

    res = max_bandwidth_scaling(
        None,
        synthesize=fake,
        plant=lambda a, h: SimpleNamespace(alpha=a),
        floor=lambda a, h: 2.0 if a > 3 else 0.0,
        progress=False,
    )
    assert all(a <= 3 for a in calls)  # nothing synthesised where the floor is >= 1
    assert [a for a, _ in res.excluded] == [32.0, 16.0, 8.0, 4.0]
    assert res.alpha == pytest.approx(2.484, abs=0.01)


def test_a_coordinate_the_domain_fixes_stays_fixed_in_the_search():
    import numpy as np

    robot = polyrob.load_robot("paper_2r")
    dom = Domain.from_robot(robot, "paper")
    fixed = dom.with_bounds(u_lower=np.full(2, 3.0), u_upper=np.full(2, 3.0))
    lim = performance_limit(robot, fixed, paper_weights()[1], samples=256, starts=1)
    assert np.all(lim.u == 3.0) and lim.bound > 0
