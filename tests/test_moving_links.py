"""``inner-links-moving``: a per-link set's computed-torque loop split at the task's centre (issue 38 item 4).

Each true robot keeps its parameters while it moves: its direction scalars
and the rest of its factor at the task's centre are constants, and only the
motion ``K(u, x) - K(u, x_c)`` varies in time.  Checked on ur5 with issue
38's default set (each link ±10 %, a 0-1.5 kg instrument within 0.1 m of
the flange): drawn true robots are members with one set of constants over
the whole task, a model of a smaller set misses them, and the
moving-robot certificate merges only the motion blocks with the
performance channels.
"""

from __future__ import annotations

import functools
from types import SimpleNamespace

import numpy as np
import pytest
from test_arm_uncertainty_model import SHRUNK_SET, carried_model, carried_set, spec_of

from polyrob import load_robot
from polyrob.domains.default_task import default_task_domain
from polyrob.errors import ArgumentError
from polyrob.model.inner import inner_loop_of_set
from polyrob.plant.models import MODELS
from polyrob.plant.moving_links import motion_coverage, motion_witness, moving_links_plant, task_centre
from polyrob.uncertainty_set.draw import draw_true_robots


@functools.cache
def moving_model(shrunk: bool = False, exact_payload: bool = False):
    """ur5's loop over the default set, its task, and the moving model of that set (or of the shrunk one), with the
    instrument's part at the centre in the constant blocks or (``exact_payload``) as its exact LFT."""
    robot = load_robot("ur5")
    loop = inner_loop_of_set(robot, "computed-torque", carried_set("ur5"), draws=2)
    domain = default_task_domain(loop)
    built = loop if not shrunk else inner_loop_of_set(robot, "computed-torque", spec_of("ur5", SHRUNK_SET), draws=2)
    pldi = SimpleNamespace(m=robot.m, domain=domain, A0=None, B0=None, enclosure="sampled", robot_name=robot.name)
    return loop, domain, moving_links_plant(pldi, built, samples=64, exact_payload=exact_payload)


def drawn_points(domain, rng, corners: bool):
    """Three uniform points of the task, or three of its corners."""
    if not corners:
        return domain.split(domain.sample_box(3, method="uniform", seed=int(rng.integers(2**31))))
    lower, upper = np.asarray(domain.lower, float), np.asarray(domain.upper, float)
    return domain.split(np.where(rng.integers(0, 2, (3, len(lower))) == 1, upper, lower))


def witnesses(unc, loop, domain, seed: int) -> np.ndarray:
    """The largest scaled part of 16 true robots of ur5's default set (half at its vertices) at task points."""
    robots = draw_true_robots(loop.uncertainty_robot, carried_set("ur5"), 16, seed=seed, extremes=0.5)
    rng = np.random.default_rng(seed)
    return np.array(
        [motion_witness(unc, loop, true, *drawn_points(domain, rng, k >= 8)).max() for k, true in enumerate(robots)]
    )


@pytest.mark.parametrize("exact_payload", [False, True])
def test_each_true_robot_is_a_member_with_its_parameters_constant_over_the_task(exact_payload):
    loop, domain, unc = moving_model(exact_payload=exact_payload)
    assert unc.model == "inner-links-moving"
    assert witnesses(unc, loop, domain, seed=3).max() <= 1.0


@pytest.mark.parametrize("exact_payload", [False, True])
def test_a_model_of_a_smaller_set_misses_true_robots_of_the_set(exact_payload):
    loop, domain, _ = moving_model()
    _loop, _domain, shrunk = moving_model(shrunk=True, exact_payload=exact_payload)
    assert witnesses(shrunk, loop, domain, seed=3).max() > 1.0


def test_the_frozen_model_cannot_hold_a_robot_s_motion_with_its_scalars_constant():
    """Without the motion blocks the frozen ``inner-links`` model's residual, with each robot's direction scalars
    held at the task's centre, misses the robots: the split is what the constants need."""
    from polyrob.plant.models import inner_links as links
    from polyrob.plant.models.factor_membership import reached_entries, scaled_residual_norm

    loop, domain, _ = moving_model()
    _loop, _domain, frozen = carried_model("ur5")
    robots = draw_true_robots(loop.uncertainty_robot, carried_set("ur5"), 16, seed=3, extremes=0.5)
    rng = np.random.default_rng(3)
    centre = task_centre(domain)
    worst = 0.0
    for k, true in enumerate(robots):
        q, qdot, a = drawn_points(domain, rng, k >= 8)
        K_c = links.factor_of(loop, true.robot, *centre)
        W = frozen.info["residual_weighting"]
        J = links.weighted_factor(K_c, W, np.linalg.inv(W))[0, :, : 2 * loop.m].ravel() / frozen.info["direction_scale"]
        t = frozen.info["state_directions"] @ J
        for K in links.factor_of(loop, true.robot, q, qdot, a):
            worst = max(worst, scaled_residual_norm(frozen, K, t, 1e-9, reached_entries(frozen)))
    assert worst > 1.0


@pytest.mark.parametrize("exact_payload", [False, True])
def test_the_blocks_that_move_are_the_motion_s_and_the_links_are_exact_at_the_centre(exact_payload):
    """Each link's scalar is a real block of its own whose factor is the link's own at the task's centre (exact:
    no direction and no residual for the links), repeated only as often as that factor's rank; the instrument's part
    at the centre stays in the constant blocks, or (``exact_payload``) is its exact LFT, four scalars after the
    links', and then the only full blocks are the motion's."""
    from polyrob.plant.models import inner_links as links
    from polyrob.plant.payload_lft import PAYLOAD_SCALARS

    loop, domain, unc = moving_model(exact_payload=exact_payload)
    flags = [b["moving"] for b in unc.info["residual_blocks"]]
    names = unc.info["exact_scalars"]
    assert not any(n.startswith("payload") for n in names)
    reals = [-int(r) for r, c in unc.block_structure if c == 0]
    if exact_payload:
        assert flags == [True, True]  # the motion's state and acceleration blocks, nothing constant
        assert unc.parameter_names[len(names) :] == PAYLOAD_SCALARS
        assert reals[len(names) :] == list(unc.info["payload_lft"].sizes)
        assert unc.info["inertia_block"] == "none (the payload's exact LFT)"
    else:
        assert flags[:2] == [False, False] and all(flags[2:]) and len(flags) > 2  # the instrument's at the centre
        assert len(names) == unc.n_params
    assert np.all(unc.info["theta_range"] == 1.0)
    scalars = {s.name: s for s in links.set_scalars(loop)}
    K = links.unit_factors(loop, [scalars[n] for n in names], *task_centre(domain))[:, 0]
    assert np.allclose(unc.info["K_centres"], K, atol=1e-9 * np.abs(K).max())
    values = np.linalg.svd(K, compute_uv=False)
    ranks = [max(1, int(np.sum(v > 1e-9 * values.max()))) for v in values]
    assert reals[: len(names)] == ranks
    assert sum(ranks) < loop.m * len(names)  # fewer channels than m repeats each: a wrist's mass moves few joints


def test_the_instrument_s_lft_is_its_factor_at_every_mass_and_centre_of_mass_of_the_box():
    """Closed at a payload's scalars, the LFT is the factor's payload part there, computed from the ten parameters
    by Pinocchio (one true robot per parameter), to rounding; at the box's corners too (the cube around the ball)."""
    from polyrob.plant.models import inner_links as links
    from polyrob.uncertainty_set.payload_body import payload_coordinates

    loop, domain, unc = moving_model(exact_payload=True)
    lft = unc.info["payload_lft"]
    body = loop.uncertainty.payload
    on = [s for s in links.set_scalars(loop) if s.name.startswith("payload.")]
    K = links.unit_factors(loop, on, *task_centre(domain))[:, 0]
    rng = np.random.default_rng(5)
    for delta in np.vstack([rng.uniform(-1, 1, (6, 4)), rng.choice([-1.0, 1.0], (4, 4))]):
        mass, com = lft.mass[0] + lft.mass[1] * delta[0], lft.com[0] + lft.com[1] * delta[1:]
        coords = payload_coordinates(body, mass, com)
        direct = np.tensordot([coords[s.name] / s.half_range for s in on], K, axes=1)
        assert np.allclose(lft.closed(delta), direct, rtol=0, atol=1e-9 * np.abs(direct).max())
        assert np.allclose(lft.units(mass, com), delta)
    assert "the cube around its ball" in lft.covers


def test_membership_needs_the_true_robot():
    _loop, _domain, unc = moving_model()
    with pytest.raises(ArgumentError, match="needs the true robot"):
        MODELS["inner-links-moving"].contains(unc, np.zeros((1, 12, 12)), np.zeros((1, 12, 6)))


def test_the_coverage_counts_members_among_fresh_robots_and_points():
    loop, domain, unc = moving_model()
    assert motion_coverage(unc, loop, domain, 40, points=5) == 1.0
    _loop, _domain, shrunk = moving_model(shrunk=True)
    assert motion_coverage(shrunk, loop, domain, 40, points=5) < 1.0


@pytest.mark.parametrize("exact_payload", [False, True])
def test_the_moving_certificate_merges_only_the_motion_blocks(exact_payload):
    from polyrob.analysis.lpv.constant import _moving_flags, scaled_plant
    from polyrob.analysis.mu.blocks import as_block_structure
    from polyrob.pipeline.problem import default_hyperparameters
    from polyrob.plant.generalized import generalized_plant
    from polyrob.plant.weights import plant_weights

    _loop, _domain, unc = moving_model(exact_payload=exact_payload)
    P = generalized_plant(unc, **plant_weights(default_hyperparameters(6)))
    assert _moving_flags(P) == [b["moving"] for b in unc.info["residual_blocks"]]
    _plant, blk = scaled_plant(P, np.ones(sum(_moving_flags(P))))
    kinds = [b.kind for b in as_block_structure(blk).blocks]
    full = [b for b in as_block_structure(P.block_structure_rs).blocks if b.kind != "real"]
    moving = sum(f.rows for f, flag in zip(full, _moving_flags(P)) if flag)
    if exact_payload:  # the links' and the instrument's scalars, and only the merged full block
        assert kinds.count("real") == len(unc.info["factors"]) + 4 and kinds.count("full") == 1
    else:
        assert kinds.count("real") == len(unc.info["factors"]) and kinds.count("full") == 3  # two constant, one merged
    assert as_block_structure(blk).blocks[-1].rows == moving + P.n_w


def test_a_file_s_friction_and_a_link_s_intervals_off_the_urdf_are_read_as_the_model_has_them():
    """panda's example file (per-link ±10 %, an instrument, viscous friction ranges) with its forearm given as
    ten-parameter intervals whose centre is 5 % heavier than the URDF's link: each drawn robot's scalars are read
    against the inner layer's own links (the interval's centre) and the friction's middle, and it is a member."""
    from dataclasses import replace
    from pathlib import Path

    from polyrob.uncertainty_set.links import LinkInterval, link_names
    from polyrob.uncertainty_set.spec import RobotUncertainty

    robot = load_robot("panda")
    path = Path(__file__).resolve().parents[1] / "examples" / "uncertainty" / "panda.yaml"
    spec = RobotUncertainty.from_file(path)
    theta = np.asarray(robot.model.inertias[link_names(robot)["panda_link5"]].toDynamicParameters(), float)
    centre = 1.05 * theta  # a rigid body still: every parameter scaled by one factor
    interval = LinkInterval("panda_link5", tuple(centre - 0.05 * np.abs(theta)), tuple(centre + 0.05 * np.abs(theta)))
    spec = replace(spec, links=(interval,)).bound(robot)
    loop = inner_loop_of_set(robot, "computed-torque", spec, draws=2)
    domain = default_task_domain(loop)
    pldi = SimpleNamespace(m=robot.m, domain=domain, A0=None, B0=None, enclosure="sampled", robot_name=robot.name)
    unc = moving_links_plant(pldi, loop, samples=32)
    names = unc.info["exact_scalars"]
    assert any(n.startswith("panda_link5.") and n[-1].isdigit() for n in names)
    assert any(n.endswith(".viscous") for n in names)
    assert motion_coverage(unc, loop, domain, 40, points=5) == 1.0
