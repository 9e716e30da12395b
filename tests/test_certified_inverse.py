"""Proved enclosures of M_hat(q)^-1 over task boxes (bounds/certified/factors/inverse.py)."""

from __future__ import annotations

from dataclasses import replace
from fractions import Fraction

import numpy as np
import pinocchio as pin
import pytest

from polyrob import load_robot
from polyrob.bounds.certified.ball_jets import lower, upper
from polyrob.bounds.certified.factors import FactorProblem
from polyrob.bounds.certified.factors.inverse import neumann_inverse, perron_bound
from polyrob.domains.default_task import default_task_domain, default_task_robot
from polyrob.plant.models.inner_factors import factor_parameters


def _arm(name):
    robot = load_robot(name)
    loops = [(n, loop) for n, _, loop in factor_parameters(default_task_robot(robot))]
    return loops, FactorProblem.from_loops(loops), default_task_domain(robot)


@pytest.fixture(scope="module")
def ur5():
    return _arm("ur5")


def _box(domain, scale):
    pose, half = 0.5 * (domain.q_lower + domain.q_upper), 0.5 * (domain.q_upper - domain.q_lower)
    return replace(domain, q_lower=pose - scale * half, q_upper=pose + scale * half)


def _pinocchio_inverses(loops, box, n, seed):
    model = loops[0][1].model_robot.model
    data = model.createData()
    out = []
    for q in np.random.default_rng(seed).uniform(box.q_lower, box.q_upper, (n, len(box.q_lower))):
        pin.computeMinverse(model, data, q)
        out.append(np.triu(data.Minv) + np.triu(data.Minv, 1).T)  # Pinocchio fills the upper triangle
    return np.array(out)


def test_the_enclosure_holds_pinocchios_inverse_on_ur5s_whole_task(ur5):
    loops, problem, domain = ur5
    # the full task (±0.2 rad): the earlier fixed point could not prove M_hat invertible on it, in any one box
    mid, rad, proved = problem.inverse_enclosure(domain.q_lower[None], domain.q_upper[None])
    assert proved[0]
    _, _, fixed = problem.inverse_enclosure(domain.q_lower[None], domain.q_upper[None], "fixed-point")
    assert not fixed[0]
    Y = _pinocchio_inverses(loops, domain, 100, seed=1)
    assert np.all((Y >= lower(mid, rad)[0]) & (Y <= upper(mid, rad)[0]))
    # and on a small box the enclosure is tight: within 1.6x of the sampled widths in the median entry
    box = _box(domain, 0.05)
    mid, rad, proved = problem.inverse_enclosure(box.q_lower[None], box.q_upper[None])
    Y = _pinocchio_inverses(loops, box, 200, seed=2)
    assert proved[0] and np.all((Y >= lower(mid, rad)[0]) & (Y <= upper(mid, rad)[0]))
    width = Y.max(0) - Y.min(0)
    varying = width > 1e-6 * np.abs(Y).max()
    assert np.median(2 * rad[0][varying] / width[varying]) <= 1.6


def test_it_is_tighter_than_the_fixed_point_where_both_prove(ur5):
    _, problem, domain = ur5
    box = _box(domain, 0.2)  # ±0.04 rad: both methods prove M_hat invertible
    _, rad_new, proved_new = problem.inverse_enclosure(box.q_lower[None], box.q_upper[None])
    _, rad_old, proved_old = problem.inverse_enclosure(box.q_lower[None], box.q_upper[None], "fixed-point")
    assert proved_new[0] and proved_old[0]
    # the fixed point multiplies two balls of Y over the box by dM_hat/dq over the box; the Taylor form keeps
    # the centre's exact gradient: 0.2 % against 5 % of the largest entry here
    assert rad_new.max() <= 0.1 * rad_old.max()
    assert np.median(rad_new / rad_old) <= 0.5


def test_a_box_is_refused_where_no_weighted_norm_of_E_is_below_one():
    # E = [[0.6, 0.6], [0.6, 0.6]] (a ball of radius 0): rho(|E|) = 1.2, so nothing is proved and the box is split
    C = np.eye(2)[None]
    E = np.full((1, 2, 2), 0.6)
    _, rad, alpha = neumann_inverse(C, None, (E, np.zeros_like(E)), np.zeros((1, 2)))
    assert alpha[0] >= 1.0 and np.all(np.isinf(rad))
    # E = [[0, 0.9], [0.5, 0]]: its max row sum is 0.9 but [[0, 3], [0.1, 0]] has 3; the Perron weighting
    # proves both (rho = 0.67 and 0.55), and (I - E)^-1 is held exactly
    for a, b in ((0.9, 0.5), (3.0, 0.1)):
        E = np.array([[[0.0, a], [b, 0.0]]])
        alpha, _ = perron_bound(np.abs(E))
        assert alpha[0] < 1.0 and alpha[0] == pytest.approx(np.sqrt(a * b), rel=1e-3)
        mid, rad, _ = neumann_inverse(C, None, (E, np.zeros_like(E)), np.zeros((1, 2)))
        det = 1 - Fraction(a) * Fraction(b)
        exact = [[1 / det, Fraction(a) / det], [Fraction(b) / det, 1 / det]]
        lo, hi = lower(mid, rad)[0], upper(mid, rad)[0]
        assert all(Fraction(lo[i, j]) <= exact[i][j] <= Fraction(hi[i, j]) for i in range(2) for j in range(2))


def test_panda_whole_task_is_split_not_proved_in_one_box():
    loops, problem, domain = _arm("panda")
    # panda's sampled |I - C M_hat(q)| over its task has a spectral radius above 1: no one box can prove it
    _, rad, proved = problem.inverse_enclosure(domain.q_lower[None], domain.q_upper[None])
    assert not proved[0] and np.all(np.isinf(rad))
    lo, hi, _ = problem.enclose(domain.q_lower[None], domain.q_upper[None], domain.qdot_lower[None],
                                domain.qdot_upper[None], domain.qddot_lower, domain.qddot_upper)  # fmt: skip
    assert np.all(np.isinf(hi)) and np.all(np.isinf(lo))  # the branch and bound splits such a box
    # a tenth of the task is proved, and holds Pinocchio's inverses
    box = _box(domain, 0.1)
    mid, rad, proved = problem.inverse_enclosure(box.q_lower[None], box.q_upper[None])
    Y = _pinocchio_inverses(loops, box, 100, seed=3)
    assert proved[0] and np.all((Y >= lower(mid, rad)[0]) & (Y <= upper(mid, rad)[0]))


@pytest.fixture(scope="module")
def panda():
    return _arm("panda")


def test_the_loewner_bound_holds_pinocchios_inverse_and_a_shrunk_one_is_caught(panda):
    loops, problem, domain = panda
    box = _box(domain, 0.25)
    mid, rad, proved = problem.inverse_enclosure(box.q_lower[None], box.q_upper[None], "loewner")
    Y = _pinocchio_inverses(loops, box, 200, seed=4)
    assert proved[0] and np.all((Y >= lower(mid, rad)[0]) & (Y <= upper(mid, rad)[0]))
    # the bound is not loose by more than a few times: half its radius misses some of Pinocchio's inverses
    assert not np.all((Y >= lower(mid, 0.5 * rad)[0]) & (Y <= upper(mid, 0.5 * rad)[0]))
    # at a point (width 0) it is Pinocchio's inverse to round-off
    pose = 0.5 * (domain.q_lower + domain.q_upper)
    mid, rad, proved = problem.inverse_enclosure(pose[None], pose[None], "loewner")
    Y = _pinocchio_inverses(loops, replace(domain, q_lower=pose, q_upper=pose), 1, seed=5)[0]
    assert proved[0] and np.all(rad[0] <= 1e-8 * np.abs(Y).max())
    assert np.all((Y >= lower(mid, rad)[0]) & (Y <= upper(mid, rad)[0]))


def test_the_branch_and_bound_proves_panda_on_half_its_task_where_the_neumann_bound_cannot(panda):
    loops, problem, domain = panda
    box = _box(domain, 0.5)
    # the Neumann bound needs a quarter of the task; the Loewner bounds (M_hat positive definite) prove half
    _, _, neumann = problem.inverse_enclosure(box.q_lower[None], box.q_upper[None], "taylor3")
    mid, rad, proved = problem.inverse_enclosure(box.q_lower[None], box.q_upper[None], "branch-and-bound")
    assert not neumann[0] and proved[0]
    Y = _pinocchio_inverses(loops, box, 200, seed=6)
    assert np.all((Y >= lower(mid, rad)[0]) & (Y <= upper(mid, rad)[0]))
    # a box proved by neither is split along the position that moves M_hat most, never along a velocity
    _, hi, contribution = problem.enclose(domain.q_lower[None], domain.q_upper[None], domain.qdot_lower[None],
                                          domain.qdot_upper[None], domain.qddot_lower, domain.qddot_upper)  # fmt: skip
    assert np.all(np.isinf(hi))
    m = len(domain.q_lower)
    assert np.all(contribution[..., m:] == 0) and contribution[..., :m].max() > 0
    assert np.argmax(contribution[0, 0, 0, 0]) != 0  # the base joint leaves panda's inertia as it is


def test_checking_the_inverse_first_skips_only_boxes_it_does_not_prove(panda):
    loops, problem, domain = panda
    whole = (domain.q_lower[None], domain.q_upper[None], domain.qdot_lower[None], domain.qdot_upper[None])
    # panda's whole task: M_hat^-1 is not proved, so the box gets infinite bounds and a split along a position
    lo, hi, contribution, seen_lo, _, sign = problem.enclose(
        *whole, domain.qddot_lower, domain.qddot_upper, taylor=True, attained=True, check_inverse=np.array([True])
    )
    m = len(domain.q_lower)
    assert np.all(np.isinf(hi)) and np.all(np.isinf(lo)) and np.all(np.isnan(seen_lo)) and not sign.any()
    assert np.all(contribution[..., m:] == 0) and np.argmax(contribution[0, 0, 0, 0]) != 0
    # on a box where it is proved the box gets its first finite enclosure: the first-order and slope forms,
    # which hold the second-order Taylor form's (both are proofs) and the factors at points of the box
    small = _box(domain, 0.02)
    box = (small.q_lower[None], small.q_upper[None], small.qdot_lower[None], small.qdot_upper[None])
    plain_lo, plain_hi, _ = problem.enclose(*box, small.qddot_lower, small.qddot_upper, taylor=True)
    lo, hi, _ = problem.enclose(*box, small.qddot_lower, small.qddot_upper, taylor=True, check_inverse=np.array([True]))
    assert np.all(np.isfinite(hi)) and np.all(lo <= plain_lo + 1e-12) and np.all(hi >= plain_hi - 1e-12)
    rng = np.random.default_rng(7)
    n = 50
    K = problem.values(
        rng.uniform(small.q_lower, small.q_upper, (n, m)),
        rng.uniform(small.qdot_lower, small.qdot_upper, (n, m)),
        rng.uniform(small.qddot_lower, small.qddot_upper, (n, m)),
    )
    assert np.all((K >= lo[0]) & (K <= hi[0]))
    # and a box proved with every form is not checked again (its parent's inverse was proved): as before
    again = problem.enclose(*box, small.qddot_lower, small.qddot_upper, taylor=True, check_inverse=np.array([False]))
    assert np.array_equal(again[0], plain_lo) and np.array_equal(again[1], plain_hi)
