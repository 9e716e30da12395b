"""Guaranteed enclosures of an analytic robot's Jacobians (polyrob.bounds.certified.analytic)."""

import itertools
import math

import numpy as np
import pytest
from flint import arb

import polyrob
from polyrob.bounds.certified.analytic import (
    Jet,
    analytic_jacobian_enclosure,
    function_balls,
    interval_cos,
    interval_sin,
)
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


def _jets3(lo, hi):
    """Variables ``x_i`` over ``[lo_i, hi_i]`` as Jets that track third derivatives."""
    k = len(lo)
    zeros = (arb(0),) * (k * (k + 1) * (k + 2) // 6)
    return [Jet(ball(lo[i], hi[i]), [arb(float(i == j)) for j in range(k)], None, zeros) for i in range(k)]


def _at(fn, *point):
    """``fn`` on point Jets and its third derivatives ``T[a][b][c]`` (balls)."""
    f = fn(*_jets3(point, point))
    k = len(point)
    return f, [[[f.d3(a, b, c) for c in range(k)] for b in range(k)] for a in range(k)]


def _mid(b):
    return float(b.mid())


def test_third_order_jets_match_closed_forms_and_hold_them_over_a_box():
    # closed forms: d3/dx3 (sin x / x); for x y cos y: x (y cos y)_yyy = x (-3 cos y + y sin y), (y cos y)_yy
    t = 0.9
    (x,) = _jets3([t], [t])
    d3 = -math.cos(t) / t + 3 * math.sin(t) / t**2 + 6 * math.cos(t) / t**3 - 6 * math.sin(t) / t**4
    assert abs(_mid((x.sin() / x).d3(0, 0, 0)) - d3) < 1e-13
    x, y = _jets3([0.4, t], [0.4, t])
    f = x * y * y.cos()
    assert abs(_mid(f.d3(1, 1, 1)) - 0.4 * (-3 * math.cos(t) + t * math.sin(t))) < 1e-13
    assert abs(_mid(f.d3(1, 0, 1)) - (-2 * math.sin(t) - t * math.cos(t))) < 1e-13
    assert f.d3(0, 0, 1) == 0 and f.d3(0, 0, 0) == 0
    # f(x, y) = sin(x) y / (2 + cos(x y)): the third derivatives are the derivatives of the (tested) Hessian
    fn = lambda x, y: x.sin() * y / (2 + (x * y).cos())  # noqa: E731
    x0, y0, h = 0.7, -1.3, 1e-3
    T = _at(fn, x0, y0)[1]
    for c, e in enumerate(np.eye(2) * h):
        H = {
            s: np.array([[_mid(b) for b in r] for r in _at(fn, *(np.array([x0, y0]) + s * e))[0].hess])
            for s in (-2, -1, 1, 2)
        }
        dH = (H[-2] - 8 * H[-1] + 8 * H[1] - H[2]) / (12 * h)  # 4th order: error ~1e-12
        for a, b in itertools.product(range(2), repeat=2):
            assert abs(_mid(T[a][b][c]) - dH[a, b]) < 1e-9 and T[a][b][c].rad() < 1e-13
    # over a box the balls hold the third derivatives at its points (with a reciprocal and a constant factor too)
    lo, hi = [0.6, -1.4], [0.65, -1.3]
    other = lambda x, y: y * (2 + x.cos()).reciprocal() - 3.0 * x * y * y  # noqa: E731
    for g in (fn, other):
        box = g(*_jets3(lo, hi))
        for point in np.random.default_rng(0).uniform(lo, hi, (30, 2)):
            T = _at(g, *point)[1]
            for a, b, c in itertools.product(range(2), repeat=3):
                assert box.d3(a, b, c).contains(T[a][b][c].mid())


def test_third_order_is_tracked_only_when_asked():
    x, y = _jets3([0.5, 0.2], [0.5, 0.2])
    plain = Jet(arb(0.3), (arb(1), arb(0)))
    assert plain.third is None and (plain * plain.cos() + 1.0).third is None and (x * plain).third is None
    assert len((2.0 - x / y).third) == 4  # the triples a <= b <= c: 000, 001, 011, 111


def _second_differences(robot, q, v, h=1e-3):
    """``d2A, d2B`` at ``(q, v)`` by central differences of the complex-step ``A, B``, 4th order in ``h``."""
    m = len(q)
    k = 2 * m
    x0, e = np.concatenate([q, v]), np.eye(k) * h
    d2A, d2B = np.zeros((k, k, k, k)), np.zeros((k, m, k, k))
    for l1, l2 in itertools.combinations_with_replacement(range(k), 2):
        if l1 == l2:
            w, xs, scale = [-1, 16, -30, 16, -1], [x0 + s * e[l1] for s in (-2, -1, 0, 1, 2)], 12 * h * h
        else:  # Richardson (16 D(h) - D(2h)) of the 4-point mixed difference
            w, xs, scale = [], [], 48 * h * h
            for f, wt in ((1, 16), (2, -1)):
                for s1, s2 in itertools.product((1, -1), repeat=2):
                    w.append(wt * s1 * s2)
                    xs.append(x0 + f * (s1 * e[l1] + s2 * e[l2]))
        xs = np.array(xs)
        A, B = robot.jacobians_batch(xs[:, :m], xs[:, m:], np.zeros(m))
        d2A[:, :, l1, l2] = d2A[:, :, l2, l1] = np.tensordot(w, A, 1) / scale
        d2B[:, :, l1, l2] = d2B[:, :, l2, l1] = np.tensordot(w, B, 1) / scale
    return d2A, d2B


@pytest.mark.parametrize(("a", "v_lo"), [(-2.0, (3.8, -9.9)), (0.3, (-1.0, 4.0)), (1.4, (-3.9, 9.8))])
def test_order_3_encloses_the_second_derivatives_of_A_and_B(robot, a, v_lo):
    ql, qh = np.array([0.0, a]), np.array([0.0, a + 0.05])
    vl = np.array(v_lo)
    vh = vl + 0.1
    enc = analytic_jacobian_enclosure(robot, ql, qh, vl, vh, [0.0, 0.0], order=3)
    assert enc.d2A_lo.shape == enc.d2A_hi.shape == (4, 4, 4, 4) and enc.d2B_lo.shape == enc.d2B_hi.shape == (4, 2, 4, 4)
    assert not np.any(enc.d2A_lo[:2]) and not np.any(enc.d2A_hi[:2]) and not np.any(enc.d2B_hi[:2])
    two = analytic_jacobian_enclosure(robot, ql, qh, vl, vh, [0.0, 0.0])
    assert two.d2A_lo is None and two.d2B_hi is None
    for name in ("A_lo", "A_hi", "B_lo", "B_hi", "qddot_lo", "qddot_hi", "dA_lo", "dA_hi", "dB_lo", "dB_hi"):
        assert np.array_equal(getattr(enc, name), getattr(two, name)), name  # order 3 changes none of them
    rng = np.random.default_rng(1)
    for _ in range(4):
        d2A, d2B = _second_differences(robot, rng.uniform(ql, qh), rng.uniform(vl, vh))  # error ~1e-8
        assert np.all(enc.d2A_lo - 1e-6 <= d2A) and np.all(d2A <= enc.d2A_hi + 1e-6)
        assert np.all(enc.d2B_lo - 1e-9 <= d2B) and np.all(d2B <= enc.d2B_hi + 1e-9)
    # a point box: tight, and on the finite differences
    q, v = (ql + qh) / 2, (vl + vh) / 2
    pt = analytic_jacobian_enclosure(robot, q, q, v, v, [0.0, 0.0], order=3)
    d2A, d2B = _second_differences(robot, q, v)
    for lo, hi, fd in ((pt.d2A_lo, pt.d2A_hi, d2A), (pt.d2B_lo, pt.d2B_hi, d2B)):
        assert np.all(hi - lo <= 1e-12 * (1 + np.abs(hi)))
        assert np.allclose(lo, fd, rtol=1e-6, atol=1e-7 * np.abs(fd).max())


def test_function_balls_of_order_2_hold_the_hessians():
    functions = [(lambda r: np.cos(2 * r[0]) * r[1], None), (lambda r: 3.0, None), (lambda r: r[0] * r[0] * r[2], None)]
    lo, hi = np.array([0.1, -1.0, 0.5]), np.array([0.2, -0.9, 0.6])
    f, g = function_balls(functions, lo, hi)
    f2, g2, h = function_balls(functions, lo, hi, order=2)
    assert np.array_equal(f, f2) and np.array_equal(g, g2) and h.shape == (2, 3, 3, 3)
    assert not np.any(h[:, 1]) and np.array_equal(h, h.transpose(0, 1, 3, 2))
    for r in np.random.default_rng(4).uniform(lo, hi, (50, 3)):
        c, s = math.cos(2 * r[0]), math.sin(2 * r[0])
        H0 = [[-4 * c * r[1], -2 * s, 0], [-2 * s, 0, 0], [0, 0, 0]]
        H2 = [[2 * r[2], 0, 2 * r[0]], [0, 0, 0], [2 * r[0], 0, 0]]
        for j, H in ((0, H0), (2, H2)):
            assert np.all(h[0, j] <= H) and np.all(np.array(H) <= h[1, j])
