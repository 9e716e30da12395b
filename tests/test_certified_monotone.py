"""The factors' branch and bound on faces and cells: the monotonicity test (factors/monotone.py) and the Taylor form on cells (factors/taylor2.py)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from polyrob import load_robot
from polyrob.bounds.certified.factors import FactorProblem, prove_factor_ranges
from polyrob.bounds.certified.factors.monotone import replace_box
from polyrob.bounds.certified.factors.taylor2 import cell_grid, taylor2_bounds, taylor2_cells
from polyrob.domains.default_task import default_task_domain, default_task_robot
from polyrob.plant.models.inner_factors import factor_parameters


@pytest.fixture(scope="module")
def ur5():
    robot = load_robot("ur5")
    loops = [(name, loop) for name, _, loop in factor_parameters(default_task_robot(robot))]
    return loops, FactorProblem.from_loops(loops), default_task_domain(robot)


def test_replace_box_keeps_every_open_side_on_a_part_of_the_box_that_holds_its_extreme():
    rng = np.random.default_rng(0)
    n = 5
    for _ in range(200):
        lo, hi = -rng.random(n), rng.random(n)
        still = rng.random((7, 2)) < 0.6
        sign = rng.choice([-1, 0, 1], size=(7, n)).astype(np.int8)
        p = int(rng.integers(n))
        children = replace_box(lo, hi, still, sign, p, 1.0)
        covered = np.zeros(still.shape)
        for c_lo, c_hi, sides, share in children:
            assert np.all(c_lo >= lo) and np.all(c_hi <= hi) and np.all(c_lo <= c_hi)
            assert not np.any(sides & ~still)
            covered += sides * share
            # every side's extreme lies on the child: a coordinate cut to a face is that side's face
            for k, side in np.argwhere(sides):
                ends = sign[k] * (1 if side == 1 else -1)
                cut = c_hi - c_lo < hi - lo
                assert np.all(~cut | (ends != 0) | (np.arange(n) == p))
                assert np.all(~cut | (ends != 1) | (c_hi == hi))
                assert np.all(~cut | (ends != -1) | (c_lo == lo))
        # the work is conserved: each open side is carried by faces of the box's share or halves of half of it
        assert np.allclose(covered, still)


def test_the_cells_hold_every_point_of_a_quadratic_and_are_tighter_than_the_magnitude_bound():
    rng = np.random.default_rng(1)
    N, n = 40, 6
    vm, vr = rng.normal(size=N), np.full(N, 1e-3)
    gm, gr = rng.normal(size=(N, n)), np.full((N, n), 1e-3)
    A = rng.normal(size=(N, n, n))
    hm, hr = A + np.swapaxes(A, 1, 2), np.full((N, n, n), 1e-2)
    radii = rng.uniform(0.1, 1.0, (N, n))
    lo, hi = taylor2_cells((vm, vr), (gm, gr), (hm, hr), radii, *cell_grid(N))
    p_lo, p_hi, _ = taylor2_bounds((vm, vr), (gm.T, gr.T), (hm.transpose(1, 2, 0), hr.transpose(1, 2, 0)), radii)
    assert np.all(hi <= p_hi) and np.all(lo >= p_lo)
    assert np.median((hi - lo) / (p_hi - p_lo)) < 0.8
    # a function of the model: value, gradient and Hessian anywhere in their balls, at every vertex and random points
    vertices = np.array(list(itertools.product([-1.0, 1.0], repeat=n)))
    for k in range(N):
        d = np.vstack([vertices, rng.uniform(-1, 1, (2000, n))]) * radii[k]
        for _ in range(5):
            U = rng.uniform(-1, 1, (n, n))
            H = hm[k] + hr[k] * (U + U.T) / 2
            g = gm[k] + gr[k] * rng.uniform(-1, 1, n)
            v = vm[k] + vr[k] * rng.uniform(-1, 1)
            f = v + d @ g + 0.5 * np.einsum("bi,ij,bj->b", d, H, d)
            assert lo[k] <= f.min() and f.max() <= hi[k]
        # and tight: within a tenth of the magnitude bound's excess of the thin quadratic's sampled extremes
        f = vm[k] + d @ gm[k] + 0.5 * np.einsum("bi,ij,bj->b", d, hm[k], d)
        assert hi[k] - f.max() <= 0.5 * (p_hi[k] - f.max())


def test_proved_gradient_signs_agree_with_finite_differences_on_a_box(ur5):
    _, problem, domain = ur5
    box = domain.scaled(0.02)
    m = problem.m
    out = problem.enclose(box.q_lower[None], box.q_upper[None], box.qdot_lower[None], box.qdot_upper[None],
                          box.qddot_lower, box.qddot_upper, taylor=True, attained=True)  # fmt: skip
    sign = out[5][0]  # (F, m, 3m, 2m)
    assert (sign != 0).mean() > 0.1  # many entries are proved monotone in some coordinates on a small box
    rng = np.random.default_rng(3)
    h = 1e-6
    for _ in range(5):
        q = rng.uniform(box.q_lower, box.q_upper)
        qd = rng.uniform(box.qdot_lower, box.qdot_upper)
        a = np.where(rng.random(m) < 0.5, box.qddot_lower, box.qddot_upper)
        for p in range(2 * m):
            step = np.zeros(2 * m)
            step[p] = h
            up = problem.values((q + step[:m])[None], (qd + step[m:])[None], a[None])[0]
            down = problem.values((q - step[:m])[None], (qd - step[m:])[None], a[None])[0]
            slope = (up - down) / (2 * h)
            scale = 1e-5 * (1 + np.abs(up))
            assert np.all(slope[sign[..., p] == 1] >= -scale[sign[..., p] == 1])
            assert np.all(slope[sign[..., p] == -1] <= scale[sign[..., p] == -1])


def test_the_proof_on_faces_and_cells_holds_the_task_corners_and_random_points(ur5):
    loops, problem, domain = ur5
    box = domain.scaled(0.02)
    enc = prove_factor_ranges(loops, box, max_boxes=60, workers=1)
    assert enc.boxes > 1
    m = problem.m
    rng = np.random.default_rng(5)
    # the extremes lie at the corners of the (q, qdot) box: every corner with random accelerations, and inside
    corners = np.array(list(itertools.product([0, 1], repeat=2 * m)))
    x = np.where(corners == 1, np.r_[box.q_upper, box.qdot_upper], np.r_[box.q_lower, box.qdot_lower])
    a = np.where(rng.random((len(x), m)) < 0.5, box.qddot_lower, box.qddot_upper)
    assert enc.contains(problem.values(x[:, :m], x[:, m:], a)).all()
    q = rng.uniform(box.q_lower, box.q_upper, (500, m))
    qd = rng.uniform(box.qdot_lower, box.qdot_upper, (500, m))
    a = rng.uniform(box.qddot_lower, box.qddot_upper, (500, m))
    assert enc.contains(problem.values(q, qd, a)).all()
