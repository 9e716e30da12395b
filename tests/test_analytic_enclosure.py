"""Guaranteed enclosures of an analytic robot's Jacobians (polyrob.bounds.certified.analytic)."""

import math

import numpy as np
import pytest
from flint import arb

import polyrob
from polyrob.bounds.certified.analytic import Jet, analytic_jacobian_enclosure, interval_cos, interval_sin
from polyrob.bounds.certified.balls import arb_lower, arb_upper, ball
from polyrob.errors import CertificationError, DomainError


@pytest.fixture(scope="module")
def robot():
    return polyrob.load_robot("paper_2r")


@pytest.mark.parametrize(("lo", "hi"), [(0.1, 0.4), (1.0, 2.0), (-0.3, 0.2), (2.0, 4.5), (-7.0, 0.0)])
def test_cos_and_sin_of_a_ball_are_tight_and_contain_the_range(lo, hi):
    t = np.linspace(lo, hi, 20001)
    for fn, f in ((interval_cos, np.cos), (interval_sin, np.sin)):
        b = fn(ball(lo, hi))
        assert arb_lower(b) <= f(t).min() and f(t).max() <= arb_upper(b)
        assert arb_upper(b) - arb_lower(b) <= (f(t).max() - f(t).min()) + 1e-6  # the exact range, up to rounding


def test_jet_derivatives_match_the_formulas():
    x = Jet(arb(0.7), (arb(1),), ((arb(0),),))
    y = (x * x.sin()) / (2.0 + x.cos())  # f = x sin x / (2 + cos x)
    f = lambda t: t * math.sin(t) / (2 + math.cos(t))  # noqa: E731
    h = 1e-4
    d1 = (f(0.7 + h) - f(0.7 - h)) / (2 * h)
    d2 = (f(0.7 + h) - 2 * f(0.7) + f(0.7 - h)) / h**2
    assert abs(float(y.value.mid()) - f(0.7)) < 1e-14
    assert abs(float(y.grad[0].mid()) - d1) < 1e-7
    assert abs(float(y.hess[0][0].mid()) - d2) < 1e-5


def test_the_enclosure_holds_the_jacobians_and_their_derivatives_over_the_box(robot):
    rng = np.random.default_rng(3)
    ql, qh = np.array([0.0, -1.2]), np.array([0.0, -0.9])
    vl, vh = np.array([-1.0, 2.0]), np.array([-0.5, 3.0])
    enc = analytic_jacobian_enclosure(robot, ql, qh, vl, vh, [0.0, 0.0])
    h = 1e-6
    for _ in range(300):
        q, v = rng.uniform(ql, qh), rng.uniform(vl, vh)
        A, B = robot.jacobians(q, v, [0, 0])
        assert np.all(enc.A_lo <= A) and np.all(A <= enc.A_hi) and np.all(enc.B_lo <= B) and np.all(B <= enc.B_hi)
        acc = robot.acceleration(q, v, [0, 0])
        assert np.all(enc.qddot_lo <= acc) and np.all(acc <= enc.qddot_hi)
        for col, (dq, dv) in {1: ([0, h], [0, 0]), 2: ([0, 0], [h, 0]), 3: ([0, 0], [0, h])}.items():
            A1, B1 = robot.jacobians(q + dq, v + np.array(dv), [0, 0])
            A0, B0 = robot.jacobians(q - np.array(dq), v - np.array(dv), [0, 0])
            dA, dB = (A1 - A0) / (2 * h), (B1 - B0) / (2 * h)  # central differences: error ~1e-9
            assert np.all(enc.dA_lo[:, :, col] - 1e-6 <= dA) and np.all(dA <= enc.dA_hi[:, :, col] + 1e-6)
            assert np.all(enc.dB_lo[:, :, col] - 1e-6 <= dB) and np.all(dB <= enc.dB_hi[:, :, col] + 1e-6)


def test_a_point_box_is_tight(robot):
    q, v = [0.0, 0.5], [1.0, -2.0]
    enc = analytic_jacobian_enclosure(robot, q, q, v, v, [0.0, 0.0])
    A, B = robot.jacobians(q, v, [0, 0])
    assert np.allclose(enc.A_lo, A, atol=1e-12) and np.allclose(enc.A_hi, A, atol=1e-12)
    assert np.allclose(enc.B_lo, B, atol=1e-14) and np.allclose(enc.B_hi, B, atol=1e-14)


def test_a_malformed_box_and_an_unprovable_inertia_are_refused(robot):
    with pytest.raises(DomainError):
        analytic_jacobian_enclosure(robot, [0, 1], [0, 0], [0, 0], [0, 0], [0, 0])
    with pytest.raises(DomainError):
        analytic_jacobian_enclosure(robot, [0, np.nan], [0, 0], [0, 0], [0, 0], [0, 0])
    bad = polyrob.model.analytic.AnalyticRobot(
        name="indefinite", joint_names=("a",), M=lambda q: np.cos(q)[:, :, None] * np.ones((1, 1, 1)),
        C=lambda q, qd: np.zeros((q.shape[0], 1, 1), dtype=object),
    )  # fmt: skip
    with pytest.raises(CertificationError):
        analytic_jacobian_enclosure(bad, [1.0], [2.0], [0.0], [0.0], [0.0])
