"""What the bounds stage refuses or reports instead of failing raw: bad M(q), absurd
default velocities, failed LPs, uncomputed volume ratios; certified entries in the plant."""

from __future__ import annotations

import inspect

import numpy as np
import pytest

from polyrob import AnalyticRobot, Domain, bound_pldi, load_robot
from polyrob.bounds import polytope as polytope_module
from polyrob.bounds.polytope import build_polytope, principal_directions
from polyrob.errors import ArgumentError, BoundsError, DomainError


def cos_inertia(q):
    """A one-joint 'robot' whose inertia cos(q) turns negative beyond pi/2."""
    return np.cos(q)[:, :, None]


def no_coriolis(q, qdot):
    return np.zeros(q.shape + (1,))


def test_a_mass_matrix_that_is_not_positive_definite_is_refused_naming_the_configuration():
    robot = AnalyticRobot(
        name="bad",
        joint_names=("j",),
        M=cos_inertia,
        C=no_coriolis,
        position_lower=[-3.0],
        position_upper=[3.0],
        velocity_limit=[1.0],
        effort_limit=[1.0],
    )
    with pytest.raises(BoundsError, match=r"M\(q\) is not positive definite at q = \(j=(-?\d\.\d+)") as info:
        bound_pldi(robot, samples=16, screen=0, refine=False, coverage=0, progress=False, workers=1)
    q = float(info.value.args[0].split("j=")[1].split(")")[0])
    assert abs(q) > np.pi / 2  # where cos q < 0


@pytest.mark.parametrize("name, value", [("finger_edu", 1000), ("borinot_flying_arm_2", 10000)])
def test_placeholder_velocity_limits_are_refused_as_defaults_naming_the_option(name, value):
    robot = load_robot(name)
    with pytest.raises(DomainError, match=rf"default velocity limit of {value} .*--qdot-max"):
        Domain.from_robot(robot)
    dom = Domain.from_robot(robot, qdot_max=5.0)  # the user's range is taken
    np.testing.assert_array_equal(dom.qdot_upper, 5.0)


def test_a_failed_polytope_lp_is_a_bounds_error_naming_what_to_change(monkeypatch):
    class Failed:
        status, message, x = 4, "Numerical difficulties", None

    monkeypatch.setattr(polytope_module.optimize, "linprog", lambda *a, **k: Failed())
    rng = np.random.default_rng(0)
    cloud = rng.standard_normal((200, 3))
    scale = np.ptp(cloud, axis=0)
    k = cloud.shape[1]
    directions = np.vstack([np.eye(k), -np.eye(k)])
    values = np.r_[cloud.max(axis=0), -cloud.min(axis=0)]
    with pytest.raises(BoundsError, match=r"LP failed \(HiGHS status 4: Numerical difficulties\).*--qdot-max"):
        build_polytope(directions, values, 2 * k, cloud, scale, principal_directions(cloud, scale), rng)


def test_an_entry_with_a_tiny_range_still_bounds_its_direction():
    """ur10's task: an entry varying over 1e-12 of the others' range gave a column HiGHS rounds to 0.

    The bounding-box LP was "unbounded" and the bound failed; scaled rows and columns keep it.
    """
    rng = np.random.default_rng(0)
    k = 3
    cloud = rng.uniform(-1, 1, (400, k)) * np.array([2.0, 1.0, 1e-12])
    scale = np.ptp(cloud, axis=0)
    directions = np.vstack([np.eye(k), -np.eye(k)])
    values = np.r_[cloud.max(axis=0), -cloud.min(axis=0)]
    poly = build_polytope(directions, values, 2 * k, cloud, scale, principal_directions(cloud, scale), rng)
    assert poly.reduced_dim == 3 and len(poly.vertices) == 8
    # the vertices are the box's corners, the tiny entry's included
    np.testing.assert_allclose(np.sort(poly.vertices[:, 2]), np.repeat([cloud[:, 2].min(), cloud[:, 2].max()], 4))


def test_a_volume_ratio_that_was_not_computed_says_so():
    # 30 independent entries: the interval box's section fills a vanishing part
    # of its bounding box, and 50 draws all miss it
    rng = np.random.default_rng(1)
    k = 30
    cloud = rng.uniform(-1, 1, (400, k)) @ rng.standard_normal((k, k))
    scale = np.ptp(cloud, axis=0)
    directions = np.vstack([np.eye(k), -np.eye(k)])
    values = np.r_[cloud.max(axis=0), -cloud.min(axis=0)]
    poly = build_polytope(directions, values, 2 * k, cloud, scale, principal_directions(cloud, scale), rng, n_mc=50)
    assert poly.volume_samples == 0
    assert poly.volume_ratio is None and poly.volume_ratio_bound is None
    assert "not computed" in poly.volume_note and "30 reduced dimensions" in poly.volume_note


@pytest.mark.parametrize("option, value", [("samples", -3), ("coverage", -1), ("workers", 0), ("screen", 1.5)])
def test_counts_are_checked_before_any_work(option, value):
    robot = load_robot("planar_2r")
    with pytest.raises(ArgumentError, match=option):
        bound_pldi(robot, progress=False, **{option: value})


PENDULUM = """<?xml version="1.0"?><robot name="pendulum">
<link name="base"/>
<link name="arm"><inertial><origin xyz="0.3 0 0"/><mass value="2"/>
<inertia ixx="0.01" iyy="0.02" izz="0.02" ixy="0" ixz="0" iyz="0"/></inertial></link>
<joint name="j1" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 1 0"/>
<dynamics damping="0.5"/><limit lower="-1" upper="1" velocity="2" effort="5"/></joint></robot>"""


def test_every_certified_interval_is_covered_by_the_uncertain_plant(tmp_path):
    """A damped pendulum: B = 1/I and a22 = -d/I are constant, but their certified
    intervals have a (rounding) width; the plant must still cover them."""
    from polyrob.plant.uncertainty import uncertain_plant

    path = tmp_path / "pendulum.urdf"
    path.write_text(PENDULUM)
    robot = load_robot(str(path))
    pldi = bound_pldi(robot, samples=64, screen=0, coverage=200, certify=True, progress=False, workers=1)
    kwargs = {"model": "box"} if "model" in inspect.signature(uncertain_plant).parameters else {}
    unc = uncertain_plant(pldi, **kwargs)
    # the plant's entrywise range, from its own matrices: affine in each parameter
    A_c, B_c = unc.matrices_at(np.zeros(unc.n_params))
    rad_A, rad_B = np.zeros_like(A_c), np.zeros_like(B_c)
    for i in range(unc.n_params):
        e = np.zeros(unc.n_params)
        e[i] = 1.0
        A_i, B_i = unc.matrices_at(e)
        rad_A += np.abs(A_i - A_c)
        rad_B += np.abs(B_i - B_c)
    assert np.all(A_c - rad_A <= pldi.A_lower) and np.all(A_c + rad_A >= pldi.A_upper)
    assert np.all(B_c - rad_B <= pldi.B_lower) and np.all(B_c + rad_B >= pldi.B_upper)
    # and the constant-looking entries are parameters now
    assert {"a22", "b21"} <= set(pldi.entries)
    assert pldi.B_upper[1, 0] > pldi.B_lower[1, 0]
    I = 0.02 + 2 * 0.3**2  # about the axis: I_yy + m r^2
    assert pldi.B_lower[1, 0] <= 1 / I <= pldi.B_upper[1, 0]


def roundoff_coupled_inertia(q):
    """``M(q)`` whose off-diagonal is roundoff-sized (1e-12 of the diagonal), as ``M_hat^-1 M`` behind computed torque."""
    M = np.zeros(q.shape[:1] + (2, 2))
    M[:, 0, 0] = 1.0
    M[:, 1, 1] = 2.0 + np.cos(q[:, 1])
    M[:, 0, 1] = M[:, 1, 0] = 1e-12 * np.sin(q[:, 0])
    return M


def test_entries_varying_by_roundoff_of_their_matrix_are_constant():
    """ur10's task: B = M_hat^-1 M = s I had off-diagonal entries spreading by 1e-12, so the inner-gain model
    (B = t I) did not apply and the batch fell back on a model with dozens of real parameters."""
    from polyrob.bounds.search import Problem, pilot

    robot = AnalyticRobot(
        name="roundoff",
        joint_names=("a", "b"),
        M=roundoff_coupled_inertia,
        C=lambda q, qdot: np.zeros(q.shape + (2,)),
        position_lower=[-3.0, -3.0],
        position_upper=[3.0, 3.0],
        velocity_limit=[1.0, 1.0],
        effort_limit=[1.0, 1.0],
    )
    problem = Problem(robot, Domain.from_robot(robot))
    _, varying = pilot(problem, seed=0, n=512)
    entry = {tuple(int(x) for x in idx): bool(v) for idx, v in zip(problem.all_index, varying)}
    assert entry[(1, 3, 1)]  # B[1, 1] = 1 / (2 + cos q2): varies
    assert not entry[(1, 2, 1)] and not entry[(1, 3, 0)]  # B's off-diagonal: roundoff of its matrix
    assert not entry[(1, 2, 0)]  # B[0, 0] = 1


def test_behind_computed_torque_a_heavy_payload_is_no_inertia_that_is_not_positive_definite():
    """``B_low = M^-1 M_hat`` is no inverse inertia: with a payload it is not symmetric, its symmetric part
    indefinite where ``M`` and ``M_hat`` are both positive definite (ur10 with 0.57 kg hit this)."""
    from polyrob.domains.task import TaskDomain
    from polyrob.model.inner import inner_loop
    from polyrob.model.payload import PayloadRange

    arm = inner_loop(load_robot("planar_2r"), "computed-torque", payload=PayloadRange(0.0, 50.0))
    dom = TaskDomain.from_robot(arm, pose=[0.3, 0.5], q_radius=0.3, qdot_max=1.0, qddot_max=2.0)
    q = np.array([[0.3, 0.5]])
    B = arm.with_true(0.0, np.zeros(3), 1.0).jacobians_batch(q, np.zeros((1, 2)), np.zeros((1, 2)))[1][0, 2:]
    assert np.linalg.eigvalsh(0.5 * (B + B.T))[0] < 0  # the old check, on B, refused this robot
    pldi = bound_pldi(arm, dom, samples=32, coverage=0, progress=False, workers=1, screen=0, verify_rounds=0)
    assert np.all(np.isfinite(pldi.upper))
