"""The ``inner-links`` model: a computed-torque loop over a per-link robot-uncertainty set (issue 38 item 3)."""

from __future__ import annotations

import functools
import re
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import light_model_once

from polyrob import load_robot
from polyrob.domains.default_task import default_task_domain
from polyrob.model.inner import inner_loop_of_set
from polyrob.plant.models import MODELS
from polyrob.plant.models import inner_links as links
from polyrob.uncertainty_set.draw import draw_true_robots
from polyrob.uncertainty_set.spec import RobotUncertainty

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "uncertainty" / "panda.yaml"
#: issue 38's default set: per-link ±10 %, an instrument of 0-1.5 kg whose CoM lies within 0.1 m of the flange
DEFAULT_SET = {
    "links": {"error_percent": 10},
    "payload": {
        "mass": [0.0, 1.5],
        "com_ball": {"centre": [0, 0, 0], "radius": 0.1},
        "inertia": {"solid_sphere": 0.05},
    },
}
SHRUNK_SET = {
    "links": {"error_percent": 5},
    "payload": {
        "mass": [0.0, 0.75],
        "com_ball": {"centre": [0, 0, 0], "radius": 0.05},
        "inertia": {"solid_sphere": 0.05},
    },
}


def spec_of(name: str, doc=None) -> RobotUncertainty:
    if doc is None and name == "panda":
        return RobotUncertainty.from_file(EXAMPLE)
    return RobotUncertainty.from_dict(doc or DEFAULT_SET)


def carried_set(name: str) -> RobotUncertainty:
    """Issue 38's default set: per-link ±10 %, a 0-1.5 kg instrument within 0.1 m of the flange (panda: with its friction)."""
    return spec_of(name)


def model_of(robot, spec, *, samples=64):
    """The model on a light stand-in for a PLDI: the model reads only its domain, size, nominal and enclosure."""
    loop = inner_loop_of_set(robot, "computed-torque", spec, draws=2)
    domain = default_task_domain(loop)
    q, qdot, a = domain.split(domain.sample_box(1, method="uniform", seed=0))
    A0, B0 = loop.jacobians_batch(q, qdot, loop.inverse_dynamics(q, qdot, a))
    pldi = SimpleNamespace(m=robot.m, domain=domain, A0=A0[0], B0=B0[0], enclosure="sampled", robot_name=robot.name)
    return loop, domain, links.inner_links_plant(pldi, loop, samples=samples)


@functools.cache
def carried_model(name: str):
    """The model of :func:`carried_set`, built once per robot and session for the tests that read it.

    ``links.light_model`` builds what :func:`model_of` does (the same stand-in), through
    :func:`conftest.light_model_once`: also what ``links.carried`` measures panda's set on.
    """
    loop = inner_loop_of_set(load_robot(name), "computed-torque", carried_set(name), draws=2)
    domain = default_task_domain(loop)
    return loop, domain, light_model_once(loop, domain, samples=64)


@functools.cache
def carried_frobenius_model():
    """ur5's model of :func:`carried_set` with the state residual's block covering its entry box (``rho = 1``)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(links, "state_residual_norm_bound", lambda *args, **kwargs: None)
        return model_of(load_robot("ur5"), carried_set("ur5"))


def witnesses(unc, loop, domain, trues, points=3, seed=0):
    rng = np.random.default_rng(seed)
    out = []
    for true in trues:
        q, qdot, a = domain.split(domain.sample_box(points, method="uniform", seed=int(rng.integers(2**31))))
        out.append(links.set_witness(unc, loop, true, q, qdot, a))
    return np.array(out)


def test_the_loop_factor_is_exactly_linear_in_the_parameters():
    ur5 = load_robot("ur5")
    spec = spec_of("ur5")
    loop = inner_loop_of_set(ur5, "computed-torque", spec, draws=0)
    domain = default_task_domain(loop)
    q, qdot, a = domain.split(domain.sample_box(4, method="uniform", seed=3))
    scalars = links.set_scalars(loop)
    assert len(scalars) == 34  # 6 links x 4 (mass, moment, inertia, parallel axis) + payload 1 + 3 + 6
    unit = links.unit_factors(loop, scalars, q, qdot, a)
    for true in draw_true_robots(ur5, spec, 3, seed=5):
        u = links.scalars_of_true(loop, true)
        assert np.abs(u).max() <= 1.0 + 1e-12  # a draw inside the set is inside the box
        K = links.factor_of(loop, true.robot, q, qdot, a)
        assert np.abs(K).max() > 1.0  # the off-flange payload moves the loop a lot ...
        assert np.abs(K - np.tensordot(u, unit, axes=1)).max() < 1e-9 * np.abs(K).max()  # ... and exactly linearly


def test_a_links_parallel_axis_term_moves_with_its_mass_and_moment():
    # b^2/a = 1 + 2 (b - 1) - (a - 1) + (b - a)^2 / a: the curvature alone is a scalar of its own, 4 p^2 / (1 - p)
    ur5 = load_robot("ur5")
    spec = RobotUncertainty.from_dict({"links": {"error_percent": 10}})
    loop = inner_loop_of_set(ur5, "computed-torque", spec, draws=0)
    domain = default_task_domain(loop)
    q, qdot, a = domain.split(domain.sample_box(2, method="uniform", seed=1))
    scalars = links.set_scalars(loop)
    parallel = [k for k, s in enumerate(scalars) if s.name.endswith(".parallel")]
    assert len(parallel) == 6 and all(scalars[k].half_range == pytest.approx(0.04 / 0.9) for k in parallel)
    unit = links.unit_factors(loop, scalars, q, qdot, a)
    vertices = draw_true_robots(ur5, spec, 40, seed=2, extremes=1.0)
    us = np.array([links.scalars_of_true(loop, true) for true in vertices])
    assert np.abs(us).max() <= 1.0 + 1e-12  # every vertex of the set is inside the box ...
    assert np.abs(us[:, parallel]).max() == pytest.approx(1.0)  # ... the curvature's range reached at a = 0.9, b = 1.1
    assert us[:, parallel].min() >= -1e-12  # and never below 0
    for true, u in zip(vertices[:3], us):
        K = links.factor_of(loop, true.robot, q, qdot, a)
        assert np.abs(K - np.tensordot(u, unit, axes=1)).max() < 1e-9 * np.abs(K).max()


@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_every_true_robot_drawn_inside_the_carried_set_is_a_member(name):
    robot = load_robot(name)
    spec = carried_set(name)
    loop, domain, unc = carried_model(name)
    trues = draw_true_robots(robot, spec, 200, seed=38)
    assert np.all(witnesses(unc, loop, domain, trues, points=2) <= 1.0 + 1e-9)
    # the membership test of the registry finds them too, from the Jacobians alone
    q, qdot, a = domain.split(domain.sample_box(20, method="uniform", seed=4))
    for true in trues[:20:4]:
        one = replace(loop, true_robot=true.robot, _scenarios=())
        A, B = one.jacobians_batch(q, qdot, one.inverse_dynamics(q, qdot, a))
        assert MODELS["inner-links"].contains(unc, A, B).all()


@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_the_coverage_falls_below_one_when_the_set_is_shrunk(name):
    robot = load_robot(name)
    shrunk_spec = RobotUncertainty.from_dict(SHRUNK_SET)
    if name == "panda":
        shrunk_spec = replace(shrunk_spec, friction=carried_set("panda").friction, robot="panda")
    shrunk_loop, domain, shrunk = model_of(robot, shrunk_spec)
    trues = draw_true_robots(robot, carried_set(name), 20, seed=7)
    q, qdot, a = domain.split(domain.sample_box(3, method="uniform", seed=9))
    inside = []
    for true in trues:
        one = replace(shrunk_loop, true_robot=true.robot, _scenarios=())
        A, B = one.jacobians_batch(q, qdot, one.inverse_dynamics(q, qdot, a))
        inside.append(MODELS["inner-links"].contains(shrunk, A, B).all())
    assert np.mean(inside) < 0.9


def test_panda_s_default_set_is_carried_once_the_block_keeps_its_skew_part_s_signs(light_models_once):
    # with the task's corners sampled the fixed weighting's block is not symmetric; its symmetric part's spectrum
    # plus the skew parts' norms bounded it by 1.35 against the 1.33 its centre left (refused: the record
    # default_set-20261129T224539), the Hermitian dilation by 1.22 against 1.54 (inner_links_inertia.g_norm_bound;
    # python benchmarks/default_set.py panda); measured once a session: carried_model("panda") builds the same
    panda = load_robot("panda")
    loop = inner_loop_of_set(panda, "computed-torque", spec_of("panda"), draws=0)
    assert links.carried(loop, default_task_domain(loop)) is None


def test_true_robots_at_the_set_s_vertices_frozen_at_the_task_s_corners_are_members():
    # where the directions' reach is largest: on uniform samples alone 9 of 100 such robots of ur5 fell outside
    from polyrob.uncertainty_set.draw import draw_true_robot

    robot = load_robot("ur5")
    loop, domain, unc = carried_model("ur5")
    rng = np.random.default_rng(5)
    lower, upper = np.asarray(domain.lower, float), np.asarray(domain.upper, float)
    worst = 0.0
    for _ in range(60):
        q, qdot, a = domain.split(np.where(rng.integers(0, 2, size=(2, len(lower))) == 1, upper, lower))
        true = draw_true_robot(robot, carried_set("ur5"), rng, extreme=True)
        worst = max(worst, links.set_witness(unc, loop, true, q, qdot, a))
    assert 0.5 < worst <= 1.0 + 1e-9


def test_panda_with_its_rated_payload_far_off_the_flange_is_refused_with_the_measured_reason():
    panda = load_robot("panda")
    rated = dict(
        DEFAULT_SET,
        payload=dict(DEFAULT_SET["payload"], mass=[0.0, 3.0], com_ball={"centre": [0, 0, 0], "radius": 0.3}),
    )
    loop = inner_loop_of_set(panda, "computed-torque", spec_of("panda", rated), draws=0)
    why = links.carried(loop, default_task_domain(loop))
    assert why is not None and why.startswith("the relative inertia error is too large")
    bound, room = (float(w) for w in re.findall(r"bound ([0-9.]+) .* the ([0-9.]+) the centre", why)[0])
    assert bound > room > 1.0  # the inner layer's middle payload leaves room above 1 (centred), but not enough


def test_channels_and_the_sizes_mu_sees():
    _, _, unc = carried_model("ur5")
    assert unc.model == "inner-links" and unc.n_params == links.DEFAULT_DIRECTIONS
    blocks = unc.block_structure.tolist()
    repeated = [b for b in blocks if b[1] == 0]
    full = [b for b in blocks if b[1] > 0]
    assert repeated == [[-6, 0]] * links.DEFAULT_DIRECTIONS  # each direction one real scalar on the 6 joints
    assert len(full) == 2 and full[-1] == [6, 6]  # the state columns' residual, then the inertia's norm block
    assert full[0][0] <= 2 * 6  # square: the larger of its rows (joints) and columns (states)
    # the inertia block is shaped like the set and well posed: I - G0 - g H Delta H never singular (small gain)
    assert unc.info["inertia_block"] == "shaped"
    W = unc.info["residual_weighting"]
    G0 = W @ unc.info["K_offset"][:, 12:] @ np.linalg.inv(W)  # the block's centre in its weighted coordinates
    values, vectors = np.linalg.eigh(unc.info["residual_g_shape"])
    H_inv = (vectors / np.sqrt(values)) @ vectors.T
    room = np.linalg.svd(H_inv @ (np.eye(6) - G0) @ H_inv, compute_uv=False)[-1]
    assert 0.0 < unc.info["residual_g_norm"] < room
    assert values.max() == pytest.approx(1.0) and values.min() < 0.5  # thin where the set is
    assert unc.B_d.shape[1] == 6 * links.DEFAULT_DIRECTIONS + sum(b[0] for b in full)
    assert len(unc.info["scalars"]) < 34  # scalars that move nothing (a first moment on a joint's axis) dropped
    text = MODELS["inner-links"].describe(unc)
    assert "per-link ±10 %" in text and "payload 0-1.5 kg" in text and "sampled enclosure" in text
    assert "S shaped like the set's inertia errors" in text
    # the payload's CoM ball is sampled, not proved: the description and the certificate's scope note say how
    sampled = "sampled at its 2 end masses x 641 centres of mass (the ball's centre and 4 spheres of 160 points)"
    assert sampled in text
    loop, _, _ = carried_model("ur5")
    assert sampled in loop.words()


def test_the_model_computes_with_the_middle_of_the_payload_set():
    ur5 = load_robot("ur5")
    spec = spec_of("ur5").bound(ur5)
    loop = inner_loop_of_set(ur5, "computed-torque", spec, draws=0)
    last = ur5.model.njoints - 1
    added = loop.model_robot.model.inertias[last].mass - ur5.model.inertias[last].mass
    assert added == pytest.approx(0.75)
    # the payload's own inertia about the flange's z axis: the solid sphere plus the middle of m (cx^2 + cy^2)
    lo, hi = spec.payload.second_moment_range()
    assert lo[5] == 0.0 and hi[5] == pytest.approx(1.5 * 0.1**2)


# ----------------------------------------------------------------------------- inner-links-real


@functools.cache
def real_residual_model(name: str):
    """The ``inner-links-real`` model of :func:`carried_set` (the state columns' residual one real per entry)."""
    robot, spec = load_robot(name), carried_set(name)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(links, "inner_links_plant", functools.partial(links.inner_links_plant, residual="real"))
        return model_of(robot, spec)


def test_the_real_residual_holds_drawn_true_robots_and_catches_shrunk_radii():
    loop, domain, unc = real_residual_model("ur5")
    assert unc.model == "inner-links-real"
    entries = unc.info["residual_entries"]
    assert len(entries) > 30 and unc.n_params == len(unc.info["theta_range"]) + len(entries)
    trues = draw_true_robots(loop.uncertainty_robot, loop.uncertainty, 20, seed=5)
    assert witnesses(unc, loop, domain, trues).max() <= 1.0  # every drawn true robot is a member
    shrunk = replace(unc, info={**unc.info, "residual_entry_radii": 0.1 * unc.info["residual_entry_radii"]})
    assert witnesses(shrunk, loop, domain, trues).max() > 1.0  # the entries' bounds are what is checked


def test_the_complex_block_s_norm_bound_reaches_the_real_residual_s_robust_stability_mu():
    # a complex block lets the stiffness residual act as a damping of either sign, real entries cannot; with
    # its norm bounded by the dilation (inner_links_inertia.residual_norm_bounds) the block is as small as the
    # real entries at the PID's peak: both models' mu upper bounds 1.33-1.34, the block's own members reach 1.33
    from polyrob.analysis.robust import robstab
    from polyrob.plant.generalized import generalized_plant
    from polyrob.synthesis.pid_tuning import pid_controller, pid_gains

    K = pid_controller(pid_gains(np.full(6, 9.39), 16.0, 20.0, np.ones(6)))  # ur5's tuned PID start's shape
    omega = np.array([2.0])  # where the block model's robust stability peaks for it
    block = robstab(generalized_plant(carried_model("ur5")[2], W_T=1.0), K, omega, refine_peak=False)
    real = robstab(generalized_plant(real_residual_model("ur5")[2], W_T=1.0), K, omega, refine_peak=False)
    assert block.mu_lower > 1.2  # a member of the block model's set: not robustly stable
    assert block.mu_upper_grid < 1.01 * block.mu_lower  # and mu is what its members reach
    assert abs(block.mu_upper_grid / real.mu_upper_grid - 1.0) < 0.02


def test_the_state_residual_block_carries_its_sampled_norm_not_the_entry_box(monkeypatch):
    # the entry box takes each entry's largest value over the samples, which no sample reaches together:
    # its Frobenius covering is a ball of norm 1 in the block's weights, where the residual's norm stays below 0.5
    from polyrob.analysis.robust import robstab
    from polyrob.plant.generalized import generalized_plant
    from polyrob.synthesis.pid_tuning import pid_controller, pid_gains

    loop, domain, unc = carried_model("ur5")
    rho = unc.info["state_residual_norm"]
    assert (
        0.35 < rho < 0.5
    )  # ur5's default set: 0.42 with the sampling margin of 1.25 (0.67 by the triangle inequality)
    assert np.allclose(
        unc.info["residual_blocks"][0]["W_l"] / rho, carried_frobenius_model()[2].info["residual_blocks"][0]["W_l"]
    )
    K = pid_controller(pid_gains(np.full(6, 9.39), 16.0, 20.0, np.ones(6)))
    omega = np.array([2.0])
    normed = robstab(generalized_plant(unc, W_T=1.0), K, omega, refine_peak=False)
    boxed = robstab(generalized_plant(carried_frobenius_model()[2], W_T=1.0), K, omega, refine_peak=False)
    assert normed.mu_upper_grid < 0.95 * boxed.mu_lower  # proved below what members of the entry box reach (1.22, 1.37)


def test_the_shaped_inertia_block_of_per_link_errors_is_thin_where_the_links_are_and_holds_the_true_robots():
    """ur5 with ±10 % per link alone: the links' inertia errors are large in one direction (the upper arm's
    parallel-axis term) and small in the others, so the shaped block is under half the ball's radius in at
    least four of six directions (the ball: one radius for all), and every drawn true robot, half of them at
    the set's vertices, is still a member."""
    import polyrob.plant.models.inner_links_inertia as inertia

    robot = load_robot("ur5")
    spec = RobotUncertainty.from_dict({"links": {"error_percent": 10}})
    loop, domain, unc = model_of(robot, spec)
    assert unc.info["inertia_block"] == "shaped"
    widths = unc.info["residual_g_norm"] * np.linalg.eigvalsh(unc.info["residual_g_shape"])
    ball = unc.info["inertia_ball"]  # relative to its room, with the centre at I: the ball's radius here
    assert np.sum(widths < 0.5 * ball) >= 4 and widths.max() < 1.1 * ball
    trues = draw_true_robots(robot, spec, 40, seed=11, extremes=0.5)
    assert np.all(witnesses(unc, loop, domain, trues, points=2) <= 1.0 + 1e-9)
    with pytest.MonkeyPatch.context() as mp:  # without a shape the same set takes the ball
        mp.setattr(inertia, "shape_of", lambda *args, **kwargs: None)
        assert model_of(robot, spec)[2].info["inertia_block"] == "ball"


def test_the_shaped_block_s_lft_and_its_membership_read_one_residual_alike():
    """The LFT (``factor_lft_plant`` with a matrix centre and ``g_shape``) and the membership test
    (``scaled_residuals``) agree: the member the LFT gives at an inertia residual of 0.8 times the shaped block's
    size has the factor ``K_offset + E`` and is held; at 1.3 times (scaled norm 1.04) it is refused."""
    from polyrob.plant.models.factor_membership import scaled_residuals

    _, _, unc = carried_model("ur5")
    m = 6
    W, g = unc.info["residual_weighting"], unc.info["residual_g_norm"]
    values, vectors = np.linalg.eigh(unc.info["residual_g_shape"])
    H = (vectors * np.sqrt(values)) @ vectors.T
    Delta = np.linalg.qr(np.random.default_rng(3).standard_normal((m, m)))[0]  # orthogonal: norm 1
    E = np.zeros((m, 3 * m))
    E[:, 2 * m :] = np.linalg.solve(W, 0.8 * g * H @ Delta @ H @ W)  # the weighted block's member, in K's coordinates

    def member(E):
        blocks = scaled_residuals(unc, E)
        A, B = unc.matrices_at(np.zeros(unc.n_params), residual=blocks)
        return blocks, A, B

    blocks, A, B = member(E)
    assert np.linalg.norm(blocks[-1], 2) == pytest.approx(0.8)
    inverse = np.linalg.inv(B[m:])
    K_raw = np.hstack([inverse @ A[m:], np.eye(m) - inverse])
    assert np.allclose(K_raw, unc.info["K_offset"] + E, rtol=0, atol=1e-9 * np.abs(K_raw).max())
    assert MODELS["inner-links"].contains(unc, A, B).all()
    _, A, B = member(1.3 * E)
    assert not MODELS["inner-links"].contains(unc, A, B).any()


def test_the_cli_offers_every_named_model():
    from polyrob.cli.options import MODEL_CHOICES
    from polyrob.pipeline.problem import UNCERTAINTY_MODELS

    assert list(UNCERTAINTY_MODELS) == MODEL_CHOICES
    assert set(MODEL_CHOICES) - {"auto"} <= set(MODELS)
