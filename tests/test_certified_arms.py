"""Proved factor ranges of an arm's computed-torque loop (bounds/certified/factors/ and its ball arithmetic).

Small boxes of ur5's default task keep every test within seconds; the full
task is the benchmark's (benchmarks/certified_arms.py).
"""

from __future__ import annotations

from dataclasses import replace
from fractions import Fraction

import numpy as np
import pinocchio as pin
import pytest

from polyrob import load_robot
from polyrob.bounds.certified.ball_jets import BallJet, ball_inverse, ball_sin_cos, jet_layout, lower, upper
from polyrob.bounds.certified.factors import FactorProblem, attained_range, factor_directions, prove_factor_ranges
from polyrob.bounds.certified.factors.proof import REL_TOL
from polyrob.bounds.certified.factors.width_ratio import closing_tolerance, width_ratios
from polyrob.bounds.certified.jet_rnea import Chain, rnea
from polyrob.domains.default_task import default_task_domain, default_task_robot
from polyrob.errors import CertificationError
from polyrob.plant.models.inner_factors import factor_parameters


@pytest.fixture(scope="module")
def ur5():
    robot = load_robot("ur5")
    loops = [(name, loop) for name, _, loop in factor_parameters(default_task_robot(robot))]
    return robot, loops, FactorProblem.from_loops(loops), default_task_domain(robot)


def _reference(loops, q, qd, a):
    """The factors by Pinocchio: FactorLoop's Jacobians at (q, qd, v(a)), ``(n, F, m, 3m)``."""
    m = q.shape[1]
    out = []
    for _, loop in loops:
        A, B = loop.jacobians_batch(q, qd, loop.inverse_dynamics(q, qd, a))
        out.append(np.concatenate([A[:, m:], B[:, m:]], axis=2))
    return np.stack(out, axis=1)


def _small_box(domain, q_radius, qd_radius, a_radius):
    pose = 0.5 * (domain.q_lower + domain.q_upper)
    return replace(
        domain,
        q_lower=pose - q_radius,
        q_upper=pose + q_radius,
        qdot_lower=np.full(len(pose), -qd_radius),
        qdot_upper=np.full(len(pose), qd_radius),
        qddot_lower=np.full(len(pose), -a_radius),
        qddot_upper=np.full(len(pose), a_radius),
    )


def _points(domain, n, seed):
    rng = np.random.default_rng(seed)
    return tuple(rng.uniform(lo, hi, (n, len(lo))) for lo, hi in (
        (domain.q_lower, domain.q_upper), (domain.qdot_lower, domain.qdot_upper),
        (domain.qddot_lower, domain.qddot_upper)))  # fmt: skip


def test_outward_rounding_contains_the_exact_rational_results():
    x = BallJet.constant(np.array([0.1, 1e308, 2.0 / 3.0]), 0.0, 0, 0)
    y = BallJet.constant(np.array([3.0, 1.0, 3.0]), 0.0, 0, 0)
    for result, exact in ((x * y, [Fraction(0.1) * 3, Fraction(1e308), Fraction(2.0 / 3.0) * 3]),
                          (x + y, [Fraction(0.1) + 3, Fraction(1e308) + 1, Fraction(2.0 / 3.0) + 3])):  # fmt: skip
        lo, hi = lower(result.mid[0], result.rad[0]), upper(result.mid[0], result.rad[0])
        for k, e in enumerate(exact):
            assert Fraction(lo[k]) <= e <= Fraction(hi[k])
        assert np.all(hi - lo <= 1e-13 * np.abs(result.mid[0]) + 1e-300)  # tight: a few ulps, not a sloppy margin
    # 1/3 is no float: the ball inverse of [[3]] must hold it, and [[2, 1], [1, 1]]^-1 = [[1, -1], [-1, 2]]
    Ym, Yr = ball_inverse(np.array([[[3.0]], [[2.0]]])[:1], np.zeros((1, 1, 1)))
    assert Fraction(lower(Ym, Yr)[0, 0, 0]) <= Fraction(1, 3) <= Fraction(upper(Ym, Yr)[0, 0, 0])
    Ym, Yr = ball_inverse(np.array([[[2.0, 1.0], [1.0, 1.0]]]), np.zeros((1, 2, 2)))
    assert np.all(lower(Ym, Yr) <= [[1, -1], [-1, 2]]) and np.all(upper(Ym, Yr) >= [[1, -1], [-1, 2]])
    # sin over a ball holds sin at its ends and its middle; cos(0.3) within its radius of libm's
    s, c = ball_sin_cos(np.array([[0.3]]), np.array([[0.2]]), 0)
    for t in (0.1, 0.3, 0.5):
        assert lower(s.mid[0], s.rad[0])[0, 0] <= np.sin(t) <= upper(s.mid[0], s.rad[0])[0, 0]
        assert lower(c.mid[0], c.rad[0])[0, 0] <= np.cos(t) <= upper(c.mid[0], c.rad[0])[0, 0]


def test_newton_euler_in_balls_agrees_with_pinocchio_at_a_point(ur5):
    robot, _, _, _ = ur5
    model, data = robot.model, robot.model.createData()
    rng = np.random.default_rng(3)
    q, v, a = rng.normal(size=6), rng.normal(size=6), rng.normal(size=6)
    x = np.concatenate([q, v])[None]
    s, c = ball_sin_cos(x, np.zeros_like(x), 1)
    qd = BallJet.variables(x, np.zeros_like(x), 1)[:, 6:]
    tau = rnea(Chain.from_model(model), s[:, :6], c[:, :6], qd, a[None], True, Chain.parameters(model)[None])
    dq, dv, _ = pin.computeRNEADerivatives(model, data, q, v, a)
    ref = pin.rnea(model, data, q, v, a)
    assert np.abs(tau.mid[0, 0, 0, 0] - ref).max() <= 1e-12 * (1 + np.abs(ref).max())
    assert np.all(np.abs(tau.mid[0, 0, 0, 0] - ref) <= tau.rad[0, 0, 0, 0])  # the ball holds Pinocchio's value
    assert np.abs(tau.mid[1:7, 0, 0, 0].T - dq).max() <= 1e-12 * (1 + np.abs(dq).max())
    assert np.abs(tau.mid[7:13, 0, 0, 0].T - dv).max() <= 1e-12 * (1 + np.abs(dv).max())


def test_factors_at_degenerate_boxes_agree_with_pinocchio(ur5):
    robot, loops, problem, domain = ur5
    # the bounds' own directions (no import of the plant) are the plant's factors
    own = FactorProblem.from_loops(factor_directions(default_task_robot(robot)))
    assert own.names == problem.names and np.array_equal(own.params, problem.params)
    q, qd, a = _points(domain, 3, seed=1)
    K_ref = _reference(loops, q, qd, a)
    scale = 1.0 + np.abs(K_ref).max()
    assert np.abs(problem.values(q, qd, a) - K_ref).max() <= 1e-12 * scale
    for k, taylor in ((0, False), (1, False), (2, True)):  # a box of width 0: a few ulps of propagated margins wide
        lo, hi, _ = problem.enclose(q[k : k + 1], q[k : k + 1], qd[k : k + 1], qd[k : k + 1], a[k], a[k], taylor=taylor)
        # Pinocchio's floats carry their own rounding (about 1e-13 here): the enclosure holds them up to that
        slack = 1e-12 * scale
        assert np.all(lo[0] - slack <= K_ref[k]) and np.all(K_ref[k] <= hi[0] + slack)
        assert (hi - lo).max() <= 1e-8 * scale
        assert np.abs(0.5 * (hi + lo)[0] - K_ref[k]).max() <= 1e-11 * scale


def _agrees_with_pinocchio_at_points(robot, seed):
    """The factors at two points of the default task and a width-0 box's enclosure hold FactorLoop's floats."""
    loops = [(name, loop) for name, _, loop in factor_parameters(default_task_robot(robot))]
    problem, domain = FactorProblem.from_loops(loops), default_task_domain(robot)
    q, qd, a = _points(domain, 2, seed=seed)
    K_ref = _reference(loops, q, qd, a)
    scale = 1.0 + np.abs(K_ref).max()
    assert np.abs(problem.values(q, qd, a) - K_ref).max() <= 1e-11 * scale
    lo, hi, _ = problem.enclose(q[:1], q[:1], qd[:1], qd[:1], a[0], a[0])
    assert np.all(lo[0] - 1e-12 * scale <= K_ref[0]) and np.all(K_ref[0] <= hi[0] + 1e-12 * scale)


def test_the_rotors_armature_is_in_the_proofs_inertia():
    # talos' arm has armature 0.1 on every joint: Pinocchio adds it to M(q)'s diagonal, so must the proof's M_hat
    robot = load_robot("talos_left_arm")
    assert np.all(np.asarray(robot.model.armature) == 0.1)
    model, data = robot.model, robot.model.createData()
    rng = np.random.default_rng(4)
    q, a = rng.normal(size=6), rng.normal(size=6)
    s, c = ball_sin_cos(q[None], np.zeros((1, 6)), 0)
    tau = rnea(Chain.from_model(model), s, c, None, a[None], False, Chain.parameters(model)[None])
    ref = pin.rnea(model, data, q, np.zeros(6), a) - pin.computeGeneralizedGravity(model, data, q)
    assert np.all(np.abs(tau.mid[0, 0, 0] - ref) <= tau.rad[0, 0, 0] + 1e-12 * np.abs(ref).max())
    _agrees_with_pinocchio_at_points(robot, seed=5)  # without the armature: off by 5 times the largest entry
    # the benchmark's check: Pinocchio's values at points of a box inside the proved intervals (outside = 0), and
    # the proof without the armature caught by it
    loops = [(name, loop) for name, _, loop in factor_parameters(default_task_robot(robot))]
    problem, box = FactorProblem.from_loops(loops), default_task_domain(robot).scaled(0.01)
    corners = (box.q_lower, box.q_upper, box.qdot_lower, box.qdot_upper, box.qddot_lower, box.qddot_upper)
    s_lo, s_hi = attained_range(problem, *corners, 200, np.random.default_rng(1))
    without = replace(problem, params=problem.params.copy())
    without.params[0, :, 13] = 0.0
    for proof, outside in ((problem, 0), (without, None)):
        lo, hi, _ = proof.enclose(*(x[None] for x in corners[:4]), *corners[4:])
        found = width_ratios(lo[0], hi[0], s_lo, s_hi)["outside"]
        assert found == 0 if outside == 0 else found > 50


def test_continuous_joints_are_revolute_joints_to_the_proof():
    # three of kinova's joints are continuous (Pinocchio stores (cos q, sin q)); before, the proof refused them
    robot = load_robot("kinova")
    assert robot.joint_kinds.count("continuous") == 3
    _agrees_with_pinocchio_at_points(robot, seed=6)


def test_random_points_of_a_small_box_lie_in_its_enclosure_and_a_shrunk_interval_is_caught(ur5):
    _, loops, problem, domain = ur5
    box = _small_box(domain, 2e-3, 5e-3, 0.02)
    lo, hi, _ = problem.enclose(box.q_lower[None], box.q_upper[None], box.qdot_lower[None], box.qdot_upper[None],
                                box.qddot_lower, box.qddot_upper)  # fmt: skip
    q, qd, a = _points(box, 200, seed=2)
    K = _reference(loops, q, qd, a)
    assert np.all((K >= lo[0]) & (K <= hi[0]))
    # the same check catches an upper bound moved below the largest value attained
    f, i, e = np.unravel_index(np.argmax(K.max(0) - K.min(0)), K.shape[1:])
    shrunk = hi[0].copy()
    shrunk[f, i, e] = K[:, f, i, e].max() - 0.1 * (K[:, f, i, e].max() - K[:, f, i, e].min())
    assert not np.all((K >= lo[0]) & (K <= shrunk))


def test_branch_and_bound_proves_a_small_box_and_gives_up_on_counted_work(ur5):
    _, loops, _, domain = ur5
    box = _small_box(domain, 1e-6, 2e-6, 1e-5)  # where one box suffices (the full task is the benchmark's)
    reports = []
    enc = prove_factor_ranges(loops, box, rel_tol=1.0, max_boxes=20, progress=lambda *r: reports.append(r))
    q, qd, a = _points(box, 100, seed=4)
    assert enc.contains(_reference(loops, q, qd, a)).all()
    assert enc.names == ("links", "payload") and enc.boxes >= 1
    assert reports and reports[-1][0] == pytest.approx(1.0)  # the whole job's fraction ends at 1
    with pytest.raises(CertificationError, match="limit of 1 boxes"):
        prove_factor_ranges(loops, _small_box(domain, 0.2, 0.5, 2.0), rel_tol=1e-3, max_boxes=1)


def test_boxes_shared_among_workers_give_the_same_proof():
    """Each batch of boxes split between two worker processes: the same proof as in one, up to the cells.

    A worker's half of a batch may get finer cells (taylor2.cell_grid), which may close a side a box sooner
    and so change which sides the next boxes' vertex ascent searches: the path may differ by a few boxes.
    """
    robot = load_robot("finger_edu")  # a 3-joint arm: many cheap boxes (ur5's small boxes close in one or need ~20)
    loops = [(name, loop) for name, _, loop in factor_parameters(default_task_robot(robot))]
    box = default_task_domain(robot).scaled(0.3)  # 29 boxes, each with its vertex ascent on the workers (at 0.2: 9)
    one, two = (
        prove_factor_ranges(loops, box, max_boxes=60, pilot=32, ascent_rounds=1, box_ascent_rounds=4, workers=w)
        for w in (1, 2)
    )
    assert one.boxes > 10 and two.boxes > 10 and abs(one.boxes - two.boxes) <= 0.2 * one.boxes  # measured 29, 27
    # each side closes between the true extreme and the tolerance past its values attained (which never pass
    # the extreme): the two differ by at most the larger tolerance (measured 0.0043 on an entry of width 1.35)
    tol = closing_tolerance(
        np.minimum(one.attained_lower, two.attained_lower), np.maximum(one.attained_upper, two.attained_upper), REL_TOL
    )
    assert np.all(np.abs(one.lower - two.lower) <= tol) and np.all(np.abs(one.upper - two.upper) <= tol)
    assert one.tightness()["outside"] == two.tightness()["outside"] == 0


def test_the_slope_form_tightens_the_acceleration_columns_and_still_holds_every_point(ur5):
    _, loops, problem, domain = ur5
    m = problem.m
    box = _small_box(domain, 2e-3, 5e-3, 0.02)
    lo, hi, _ = problem.enclose(box.q_lower[None], box.q_upper[None], box.qdot_lower[None], box.qdot_upper[None],
                                box.qddot_lower, box.qddot_upper)  # fmt: skip
    s_lo, s_hi = attained_range(problem, box.q_lower, box.q_upper, box.qdot_lower, box.qdot_upper, box.qddot_lower,
                                box.qddot_upper, 200, np.random.default_rng(5))  # fmt: skip
    assert np.all(lo[0] <= s_lo) and np.all(s_hi <= hi[0])
    # G = -Y M_k: the mean-value form alone gave a ratio of 5.2 and an excess of 1.2 % of the factor's scale here,
    # the slope form (Y once, against M_hat's and M_k's own derivatives) 2.3 and 0.15 %
    G = width_ratios(lo[0][..., 2 * m :], hi[0][..., 2 * m :], s_lo[..., 2 * m :], s_hi[..., 2 * m :])
    assert G["entries"] >= 10 and G["max"] <= 3.0 and G["excess_max"] <= 4e-3
    q, qd, a = _points(box, 100, seed=6)
    assert np.all((_reference(loops, q, qd, a) >= lo[0]) & (_reference(loops, q, qd, a) <= hi[0]))


def test_width_ratios_leave_thin_entries_to_their_excess():
    # entry 0 varies (ratio 1.1); entry 1 is 1e-7 wide, far below 1e-3 of the scale 1: its 2e-3 excess is reported
    # relative to the scale, not as a ratio of 1e4
    r = width_ratios(np.array([[0.0, -1e-3]]), np.array([[1.1, 1e-3]]), np.array([[0.0, -5e-8]]),
                     np.array([[1.0, 5e-8]]))  # fmt: skip
    assert r["max"] == pytest.approx(1.1) and r["entries"] == 1 and r["thin_entries"] == 1
    assert r["excess_max"] == pytest.approx(2e-3 - 1e-7)
    # each factor has its own scale: the same 1e-7 wide entry in a factor of its own is significant (ratio 2)
    r = width_ratios(np.array([[0.0], [-1e-7]]), np.array([[1.1], [1e-7]]), np.array([[0.0], [-5e-8]]),
                     np.array([[1.0], [5e-8]]))  # fmt: skip
    assert r["entries"] == 2 and r["max"] == pytest.approx(2.0) and r["thin_entries"] == 0


def test_third_order_jets_agree_with_differences_of_hessians_and_hold_a_box():
    def f(c, r, order):
        x = BallJet.variables(c[None], r[None], order)
        s, co = ball_sin_cos(c[None], r[None], order)
        return (x[:, 0] * s[:, 1]) * (co[:, 2] * x[:, 1] * x[:, 0]) + s[:, 0] * s[:, 0] * co[:, 0]

    n, c, h = 3, np.array([0.3, -0.7, 1.1]), 1e-5
    zero = np.zeros(n)
    third = f(c, zero, 3).mid[1 + n + n * n :, 0].reshape(n, n, n)
    for k in range(n):
        e = h * np.eye(n)[k]
        diff = (f(c + e, zero, 2).mid[1 + n :, 0] - f(c - e, zero, 2).mid[1 + n :, 0]).reshape(n, n) / (2 * h)
        assert np.abs(third[:, :, k] - diff).max() <= 1e-8 * np.abs(third).max()
    r = np.array([0.05, 0.02, 0.03])
    box = f(c, r, 3)
    for point in c + np.random.default_rng(7).uniform(-r, r, (30, n)):
        at = f(point, zero, 3).mid[:, 0]
        assert np.all(np.abs(at - box.mid[:, 0]) <= box.rad[:, 0])  # value, gradient, Hessian and third derivatives


def test_packed_jets_give_the_whole_products_floats_at_the_sorted_multi_indices():
    # the Newton-Euler recursion runs on packed jets (ball_jets.symmetric_indices): its inputs' D_pl and D_lp
    # are the same floats, and so the product rule at p <= l (<= r) gives the whole computation's floats there
    rng, n, order = np.random.default_rng(4), 4, 3
    layout = jet_layout(n, order)

    def jet(shape):  # derivatives symmetric as floats: a packed jet made whole
        C = len(layout.distinct)
        return BallJet(rng.normal(size=(C, *shape)), rng.uniform(0, 1e-3, (C, *shape)), n, order, True).unpack()

    for form, xs, ys in (("mul", (5,), (5,)), ("cross", (2, 3), (2, 3)), ("matvec", (2, 3, 3), (2, 3))):
        x, y = jet(xs), jet(ys)
        whole, packed = x.form(form, y), x.pack().form(form, y.pack())
        assert packed.packed and np.array_equal(whole.mid[layout.distinct], packed.mid)
        assert np.array_equal(whole.rad[layout.distinct], packed.rad)
        back = packed.unpack()  # elsewhere the sorted entry's ball, whose sums are in another order only
        assert np.allclose(back.mid, whole.mid, rtol=1e-14, atol=1e-15) and np.allclose(back.rad, whole.rad, rtol=1e-13)
        assert np.array_equal(packed.truncated(2).unpack().mid, back.mid[:21])  # (packed, the orders come in turn)
    with pytest.raises(ValueError):
        x.pack().form("mul", y)


def test_the_taylor_form_holds_pinocchio_and_is_tight_on_a_small_box(ur5):
    _, loops, problem, domain = ur5
    box = _small_box(domain, 2e-3, 5e-3, 0.02)
    args = (box.q_lower[None], box.q_upper[None], box.qdot_lower[None], box.qdot_upper[None],
            box.qddot_lower, box.qddot_upper)  # fmt: skip
    lo, hi, _ = problem.enclose(*args, taylor=True)
    q, qd, a = _points(box, 100, seed=8)
    K = _reference(loops, q, qd, a)
    assert np.all((K >= lo[0]) & (K <= hi[0]))
    s_lo, s_hi = attained_range(problem, box.q_lower, box.q_upper, box.qdot_lower, box.qdot_upper, box.qddot_lower,
                                box.qddot_upper, 200, np.random.default_rng(5))  # fmt: skip
    # the mean-value and slope forms alone: ratio up to 3.6 (median 1.2) and an excess of 3.9 % of the scale
    r = width_ratios(lo[0], hi[0], s_lo, s_hi)
    assert r["entries"] >= 30 and r["max"] <= 1.3 and r["median"] <= 1.05 and r["excess_max"] <= 1e-3


def test_a_per_link_set_is_refused_by_the_proof_with_what_to_change():
    """Its models rest on sampled factors: the proof of the common factor says so, not "no factor to prove"."""
    import polyrob
    from polyrob.model.inner import inner_loop_of_set
    from polyrob.uncertainty_set.default_set import default_set

    robot = load_robot("finger_edu")
    loop = inner_loop_of_set(robot, "computed-torque", default_set(robot), draws=2)
    with pytest.raises(CertificationError, match="per-link robot-uncertainty set.*drop --certify"):
        polyrob.bound_pldi(loop, default_task_domain(loop), certify=True, progress=False)
