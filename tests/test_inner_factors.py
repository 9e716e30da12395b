"""Computed torque with reflected rotor inertia (polyrob.plant.models.inner_factors): M = R + s L as an exact LFT.

A planar 2R with armature behind a computed-torque layer whose link inertias
are off by ±10 %: a few seconds.
"""

from __future__ import annotations

import numpy as np
import pytest

from polyrob import bound_pldi, load_robot
from polyrob.domains.task import TaskDomain
from polyrob.model.inner import inner_loop
from polyrob.plant.coverage import coverage_fraction, model_contains
from polyrob.plant.models.factor_membership import scaled_residuals
from polyrob.plant.models.inner_factors import factor_parameters
from polyrob.plant.uncertainty import uncertain_plant

ARMATURE = [0.4, 0.3]  # kg m^2: comparable to the links' own inertia, so G = M_hat^-1 L is far from I


def _task(arm):
    return TaskDomain.from_robot(arm, pose=[0.3, 1.2], q_radius=0.3, qdot_max=1.0, qddot_max=2.0)


@pytest.fixture(scope="module")
def problem():
    arm = inner_loop(load_robot("planar_2r", armature=ARMATURE), "computed-torque", model_error=0.1)
    dom = _task(arm)
    pldi = bound_pldi(arm, dom, samples=64, coverage=0, progress=False, workers=1, screen=0, verify_rounds=0)
    return arm, dom, uncertain_plant(pldi, model="auto", coverage=600, volume_samples=0)


def test_auto_takes_the_one_scalar_lft_and_it_covers_every_true_robot(problem):
    arm, dom, unc = problem
    assert unc.model == "inner-gain" and unc.info["factors"] == ("links",) and unc.n_params == 1
    assert unc.coverage == 1.0
    assert unc.block_structure[-1].tolist() == [-2, 0]  # sigma, repeated on both joints
    assert np.any(unc.D_vd != 0)  # G is fed back through sigma: not the one-gain model


def test_the_factor_g_is_the_identity_less_the_models_inverse_inertia_times_the_armature(problem):
    arm, dom, _ = problem
    q, qdot, v = dom.sample(5, method="uniform", seed=1)
    _, B = factor_parameters(arm)[0][2].jacobians_batch(q, qdot, v)
    for k in range(5):
        M_hat = arm.model_robot.mass_matrix(q[k])
        assert B[k, 2:] == pytest.approx(np.eye(2) - np.linalg.solve(M_hat, np.diag(ARMATURE)), abs=1e-9)


def _lft_reproduces(unc, true, dom, theta, seed):
    """The LFT at the true robot's ``theta`` and residual ``E = K_raw - sum theta_k K_k,c`` gives its Jacobians."""
    info, m = unc.info, unc.m
    q, qdot, qddot = dom.sample(3, method="uniform", seed=seed)
    A, B = true.jacobians_batch(q, qdot, true.inverse_dynamics(q, qdot, qddot))
    for k in range(3):
        inverse = np.linalg.inv(B[k, m:])
        E = np.hstack([inverse @ A[k, m:], np.eye(m) - inverse]) - np.tensordot(theta, info["K_centres"], axes=1)
        blocks = scaled_residuals(unc, E)
        assert max(np.linalg.norm(S, 2) for S in blocks) <= 1.0
        A_lft, B_lft = unc.matrices_at(np.asarray(theta) / info["theta_range"], residual=blocks)
        assert A_lft == pytest.approx(A[k], abs=1e-9) and B_lft == pytest.approx(B[k], abs=1e-9)
    assert model_contains(unc, A, B).all()


def test_a_true_robot_is_the_lft_at_its_own_factor_and_residual(problem):
    arm, dom, unc = problem
    for s in (0.9, 0.96, 1.07):
        _lft_reproduces(unc, arm.with_true(None, None, s), dom, [1.0 - s], seed=7)


def test_members_of_the_lft_are_contained_and_a_larger_model_error_is_not(problem):
    arm, _, unc = problem
    rng = np.random.default_rng(0)
    members = [unc.matrices_at(rng.uniform(-1, 1, 1), residual=unc.residual_samples(1, seed=i)[0]) for i in range(6)]
    assert model_contains(unc, np.array([a for a, _ in members]), np.array([b for _, b in members])).all()
    wider = inner_loop(load_robot("planar_2r", armature=ARMATURE), "computed-torque", model_error=0.3)
    assert coverage_fraction(unc, wider, _task(wider), 300) < 0.9


def test_a_torque_box_is_refused():
    from polyrob.domains.torque_box import Domain
    from polyrob.errors import NotApplicable
    from polyrob.plant.models.inner_factors import inner_factors_plant

    arm = inner_loop(load_robot("planar_2r", armature=ARMATURE), "computed-torque", model_error=0.1)
    pldi = bound_pldi(arm, Domain.from_robot(arm), samples=16, coverage=0, progress=False, workers=1, screen=0)
    with pytest.raises(NotApplicable, match="task domain"):
        inner_factors_plant(pldi, arm)


@pytest.fixture(scope="module")
def with_payload_problem():
    from polyrob.model.payload import PayloadRange

    robot = load_robot("planar_2r", armature=ARMATURE)
    arm = inner_loop(robot, "computed-torque", payload=PayloadRange(0.0, 2.0), model_error=0.1)
    dom = _task(arm)
    pldi = bound_pldi(arm, dom, samples=64, coverage=0, progress=False, workers=1, screen=0, verify_rounds=0)
    return arm, dom, uncertain_plant(pldi, model="auto", coverage=600, volume_samples=0)


def test_a_payload_mass_is_a_second_scalar_and_a_true_robot_is_the_lft_at_both(with_payload_problem):
    arm, dom, unc = with_payload_problem
    assert unc.info["factors"] == ("links", "payload") and unc.coverage == 1.0
    assert unc.block_structure[-2:].tolist() == [[-2, 0], [-2, 0]]
    assert unc.info["theta_range"].tolist() == [0.1, 1.0]  # the model carries the middle payload, 1 kg
    for s, mass in ((0.93, 0.2), (1.08, 1.9)):
        _lft_reproduces(unc, arm.with_true(mass, np.zeros(3), s), dom, [1.0 - s, mass - 1.0], seed=11)


def test_a_payload_whose_centre_of_mass_ranges_is_left_to_axes():
    from polyrob.model.payload import PayloadRange

    robot = load_robot("planar_2r", armature=ARMATURE)
    arm = inner_loop(robot, "computed-torque", payload=PayloadRange.parse("0:2", "0.05,0,0"), model_error=0.1)
    pldi = bound_pldi(arm, _task(arm), samples=32, coverage=0, progress=False, workers=1, screen=0, verify_rounds=0)
    assert uncertain_plant(pldi, model="auto", coverage=0, volume_samples=0).model == "axes"


def test_the_acceleration_columns_get_their_own_residual_block(with_payload_problem):
    """One block for J and one for G: a single block's rank-one entry bounds let G's small spread grow to J's."""
    from polyrob.analysis.mu.blocks import as_block_structure
    from polyrob.analysis.mu.bounds import mussv
    from polyrob.plant.models.axes import residual_of_radii

    _, _, unc = with_payload_problem
    m, spread = unc.m, unc.info["residual_spread"]
    blocks = unc.info["residual_blocks"]
    assert [bool(b["cols"].min() >= 2 * m) for b in blocks] == [False, True]  # J's columns, then G's
    # each block bounds its entries: |E_ij| <= W_l[i] W_r[j] >= the spread (the covering)
    for b in blocks:
        bound = np.outer(b["W_l"], b["W_r"])
        assert np.all(bound >= spread[np.ix_(b["rows"], b["cols"])] - 1e-12)
    # the static loop through the scalars and the residual (D_vd) is smaller than with one block
    two = mussv(unc.D_vd.astype(complex), as_block_structure(unc.block_structure), method="relaxed").upper
    Bf, Cf, _ = residual_of_radii(spread)
    k = Bf.shape[1]
    P = len(unc.info["factors"])
    to_a = np.hstack([Bf, np.tile(np.eye(m), P)])
    reads = np.vstack([Cf] + [r * K for r, K in zip(unc.info["theta_range"], unc.info["K_centres"])])
    one_block = np.array([[k, k]] + [[-m, 0]] * P)
    one = mussv((reads[:, 2 * m :] @ to_a).astype(complex), as_block_structure(one_block), method="relaxed").upper
    assert two < 0.85 * one  # 0.24 against 0.30 here; 0.16 against 0.67 on so101 with a 3 % payload


def test_membership_minimises_over_the_factors_past_a_kink_where_nelder_mead_stalls():
    """The residual's norm is convex in the factors but not smooth: Nelder-Mead alone stalled on ur5 with a
    payload (its model then held 0.953 of its own true robots' Jacobians; 1.0 with the grid first)."""
    from scipy.optimize import minimize

    from polyrob.plant.models.factor_membership import convex_box_minimum

    def ridge(t):  # minimum 0 at (0.25, 0.25), along a narrow valley
        return max(100 * abs(t[0] - t[1]), abs(t[0] + t[1] - 0.5))

    start, box = np.array([-1.0, 1.0]), np.array([1.0, 1.0])
    assert minimize(ridge, start, method="Nelder-Mead", bounds=[(-1, 1)] * 2).fun > 1.0  # stalls
    assert convex_box_minimum(ridge, start, box) < 1e-6


def test_members_whose_exact_entries_pin_the_factors_are_held_at_interior_factors():
    """ur5's default task: an entry no residual block reaches (the wrist's own ``G[5, 5]``) is moved by both
    factors, so a member's factors lie on a line; the box search never landed on it (half of these members,
    15 % of fresh true robots, were refused) and membership now solves for it.

    The model's factor ranges come from its own searches (one per factor, over the PLDI's domain); the PLDI's A, B
    intervals do not enter it, so they are sampled without local refinement (``refine=False``)."""
    from polyrob.domains.default_task import default_task_domain, default_task_robot
    from polyrob.plant.models.factor_membership import reached_entries

    arm = default_task_robot(load_robot("ur5"))
    dom = default_task_domain(arm)
    pldi = bound_pldi(
        arm,
        dom,
        samples=32,
        refine=False,
        screen=0,
        verify_rounds=0,
        coverage=0,
        progress=False,
        workers=1,
        describe_polytope=False,
    )
    unc = uncertain_plant(pldi, model="inner-gain", coverage=0, volume_samples=0)
    unreached = unc.info["K_centres"].reshape(2, -1).T[~reached_entries(unc).ravel()]
    assert (np.abs(unreached).max(axis=1) > 0).any()  # some exact entry moves with the factors
    rng = np.random.default_rng(0)
    members = [unc.matrices_at(rng.uniform(-1, 1, 2), residual=unc.residual_samples(1, seed=i)[0]) for i in range(20)]
    assert model_contains(unc, np.array([a for a, _ in members]), np.array([b for _, b in members])).all()
    off = [(a.copy(), b) for a, b in members[:3]]
    for a, _ in off:
        a[-1, -1] += 0.5  # a stiffness no factor or block gives
    assert not model_contains(unc, np.array([a for a, _ in off]), np.array([b for _, b in off])).any()


def test_coverage_draws_fresh_true_robots_half_at_vertices(with_payload_problem, monkeypatch):
    """Half of the coverage's points go to true robots drawn anew (10 each), half of those at vertices of the set."""
    from polyrob.model.inner import InnerLoopRobot

    arm, dom, unc = with_payload_problem
    calls = []
    drawn = InnerLoopRobot.drawn

    def spy(self, rng, *, extreme=False):
        calls.append(extreme)
        return drawn(self, rng, extreme=extreme)

    monkeypatch.setattr(InnerLoopRobot, "drawn", spy)
    assert coverage_fraction(unc, arm, dom, 400) == 1.0
    assert calls == [False] * 10 + [True] * 10


def test_a_member_the_pinned_segment_misses_is_found_by_the_box_search(with_payload_problem, monkeypatch):
    """The pinned segment is a shortcut: when it misses (kinova's inner-gain model refused 84 % of fresh
    points, 1.0 without it), the box search still finds the member's factors, and a wider set stays out."""
    import polyrob.plant.models.factor_membership as inner_factors

    _, _, unc = with_payload_problem
    rng = np.random.default_rng(3)
    members = [unc.matrices_at(rng.uniform(-1, 1, 2), residual=unc.residual_samples(1, seed=i)[0]) for i in range(4)]
    A, B = np.array([a for a, _ in members]), np.array([b for _, b in members])
    monkeypatch.setattr(inner_factors, "_pinned_line", lambda *args: "outside")
    assert model_contains(unc, A, B).all()
    # and it accepts a point only where its own residual norm is at most 1: a wider set is still refused
    wider = inner_loop(load_robot("planar_2r", armature=ARMATURE), "computed-torque", model_error=0.3)
    assert coverage_fraction(unc, wider, _task(wider), 100) < 0.9


def test_membership_of_two_factors_finds_a_narrow_oblique_valley(monkeypatch):
    """kinova's default task: a common link factor and a payload mass move the inertia nearly alike, so a member's
    residual norm stays below 1 only in a narrow oblique valley; the grid and its zoom missed one (1.36, against
    a minimum of 0.29), and the nested scalar searches find it."""
    import polyrob.plant.models.factor_membership as factors

    box = np.array([0.1, 0.02185])  # kinova's ranges: the link factor and the payload mass
    rng = np.random.default_rng(19)
    X, Y, Z = rng.normal(size=(3, 3, 3))
    E1, E2 = 1000 * X + 30 * Y, -4370 * X + 30 * Z  # nearly the same direction, as the two inertia effects
    centre = np.array([0.09083495, -0.0057519])
    E0 = 0.5 * np.eye(3) - centre[0] * E1 - centre[1] * E2

    def residual_norm(t):  # convex, minimum 0.5 at `centre`, near the box's edge
        return np.linalg.norm(E0 + t[0] * E1 + t[1] * E2, 2)

    start = np.zeros(2)
    assert factors.convex_box_minimum(residual_norm, start, box) == pytest.approx(0.5, abs=1e-5)
    monkeypatch.setattr(factors, "_nested_minimum", lambda f, r: np.inf)  # the grid, Nelder-Mead and the zoom alone
    assert factors.convex_box_minimum(residual_norm, start, box) > 1.0
