"""Inner layers (gravity, computed torque) and a payload range: issue 21 items 3 and 1.

The inner loop's Jacobians against finite differences of ``f(x, u(x, v))``,
gravity compensation removing ``dg/dq``, the PLDI over the ranges holding
the Jacobians of random true robots, the frozen poles it moves, the options.
"""

from __future__ import annotations

import numpy as np
import pytest

from polyrob import bound_pldi, load_robot
from polyrob.cli import main
from polyrob.domains.task import TaskDomain
from polyrob.errors import ArgumentError, DomainError
from polyrob.model.inner import inner_loop
from polyrob.model.payload import PayloadRange


def _fd(robot, q, qdot, v, h=1e-6):
    m = robot.m
    x = np.r_[q, qdot]
    A = np.stack([(robot.f(x + h * e, v) - robot.f(x - h * e, v)) / (2 * h) for e in np.eye(2 * m)], axis=1)
    B = np.stack([(robot.f(x, v + h * e) - robot.f(x, v - h * e)) / (2 * h) for e in np.eye(m)], axis=1)
    return A, B


def _pendulum_domain(arm, qddot=2.0):
    """double_pendulum states no joint limits: a task domain around q = (0.4, 0.3) built directly."""
    one = np.ones(2)
    return TaskDomain(
        arm.joint_names, [0.4, 0.3], "a given pose", 0.3, [0.1, 0.0], [0.7, 0.6],
        -0.5 * one, 0.5 * one, -qddot * one, qddot * one, arm, "pendulum task",
    )  # fmt: skip


@pytest.fixture(scope="module")
def pendulum():
    return load_robot("double_pendulum")


@pytest.mark.parametrize("name", ["double_pendulum", "ur5"])
@pytest.mark.parametrize("inner", ["none", "gravity", "computed-torque"])
def test_inner_jacobians_match_finite_differences(name, inner):
    robot = load_robot(name)
    arm = inner_loop(robot, inner, payload=PayloadRange.parse("0:2", "0.05"), model_error=0.2)
    rng = np.random.default_rng(0)
    for true in (arm, arm.drawn(rng), arm.variants()[-1]):
        q, qdot, v = rng.normal(size=(3, robot.m))
        A, B = true.jacobians(q, qdot, v)
        A_fd, B_fd = _fd(true, q, qdot, v)
        assert np.abs(A - A_fd).max() <= 1e-6 * max(1.0, np.abs(A).max())
        assert np.abs(B - B_fd).max() <= 1e-6 * max(1.0, np.abs(B).max())
        # the inverse of the inner law: v that gives qddot on the true robot
        qddot = rng.normal(size=robot.m)
        assert np.allclose(true.acceleration(q, qdot, true.inverse_dynamics(q, qdot, qddot)[0]), qddot, atol=1e-9)


def test_gravity_layer_removes_dg_dq(pendulum):
    """No model error: A21 = -M^-1 d(C qdot)/dq (rnea's q-derivative at qddot = 0 without gravity's)."""
    import pinocchio

    arm = inner_loop(pendulum, "gravity")
    rng = np.random.default_rng(1)
    model, data = pendulum.model, pendulum.model.createData()
    for _ in range(3):
        q, qdot = rng.normal(size=(2, 2))
        v = arm.inverse_dynamics(q, qdot, np.zeros(2))[0]  # holds qddot = 0
        A, _ = arm.jacobians(q, qdot, v)
        drnea = pinocchio.computeRNEADerivatives(model, data, q, qdot, np.zeros(2))[0]
        dg = pinocchio.computeGeneralizedGravityDerivatives(model, data, q)
        expected = -np.linalg.solve(pendulum.mass_matrix(q), drnea - dg)
        assert np.allclose(A[2:, :2], expected, atol=1e-9)
        A_none, _ = pendulum.jacobians(q, qdot, pendulum.inverse_dynamics(q, qdot, np.zeros(2))[0])
        assert not np.allclose(A_none[2:, :2], expected, atol=1e-3)  # gravity is in the open loop's


def test_inner_pldi_holds_the_closed_loop_and_the_ranges(pendulum):
    """The PLDI of the inner loop holds its finite-difference Jacobians; the ranges widen it, and it holds
    the Jacobians of true robots drawn from them (payload mass and link inertias)."""
    options = {"samples": 128, "coverage": 1000, "progress": False, "verify_rounds": 1, "screen": 0}
    arm = inner_loop(pendulum, "gravity")
    pldi = bound_pldi(arm, _pendulum_domain(arm), **options)
    assert pldi.coverage == 1.0
    q, qdot, v = _pendulum_domain(arm).sample(40, method="uniform", seed=5)
    fd = [_fd(arm, *p) for p in zip(q, qdot, v)]
    A_fd, B_fd = np.array([a for a, _ in fd]), np.array([b for _, b in fd])
    assert pldi.contains(A_fd, B_fd, rtol=1e-6).all()
    assert np.allclose(pldi.A_lower[2:, :1], 0.0, atol=1e-9)  # no joint-1 gravity stiffness is left

    ranged = inner_loop(pendulum, "gravity", payload=PayloadRange.parse("0:0.3"), model_error=0.1)
    assert len(ranged.variants()) == 5  # nominal, 2 payloads x 2 inertia factors
    wide = bound_pldi(ranged, _pendulum_domain(ranged), **options)
    assert wide.coverage == 1.0
    assert np.all(wide.A_lower <= pldi.A_lower + 1e-9) and np.all(wide.A_upper >= pldi.A_upper - 1e-9)
    assert (wide.A_upper - wide.A_lower).sum() > 1.5 * (pldi.A_upper - pldi.A_lower).sum()
    rng = np.random.default_rng(7)
    for k in range(10):
        true = ranged.drawn(rng)
        A, B = true.jacobians_batch(*_pendulum_domain(true).sample(200, method="uniform", seed=k))
        inside = wide.contains(A, B) & wide.polytope.contains(wide.entry_values(A, B))
        assert inside.all(), true.scenario


def _largest_pole(robot, n=20000):
    dom = TaskDomain.from_robot(robot, q_radius=0.3, qdot_max=0.5, qddot_max=2.0)
    q, qd, u = dom.sample(n, method="uniform", seed=1)
    return np.linalg.eigvals(robot.jacobians_batch(q, qd, u)[0]).real.max()


def test_gravity_layer_lowers_the_largest_frozen_pole_on_ur5():
    ur5 = load_robot("ur5")
    assert _largest_pole(inner_loop(ur5, "none")) == pytest.approx(5.63, abs=0.02)
    assert _largest_pole(inner_loop(ur5, "gravity")) == pytest.approx(1.40, abs=0.02)
    assert _largest_pole(inner_loop(ur5, "computed-torque")) == pytest.approx(0.0, abs=1e-6)


def test_library_refuses_bad_ranges(pendulum):
    with pytest.raises(DomainError, match="must be >= 0"):
        PayloadRange.parse("-1:2")
    with pytest.raises(DomainError, match="inverted"):
        PayloadRange.parse("2:1")
    with pytest.raises(DomainError, match="not finite"):
        PayloadRange.parse("nan:1")
    with pytest.raises(ArgumentError, match="0, 100"):
        inner_loop(pendulum, "gravity", model_error=1.0)
    with pytest.raises(ArgumentError, match="unknown inner layer"):
        inner_loop(pendulum, "feedforward")


@pytest.mark.parametrize(
    ("extra", "expected"),
    [
        (["--payload-mass=-1:2"], "--payload-mass: a mass must be >= 0"),
        (["--payload-mass", "2:1"], "--payload-mass: range 2:1 is inverted"),
        (["--payload-mass", "nan"], "--payload-mass"),
        (["--inner", "gravity", "--model-error", "100"], "--model-error: give a percentage in [0, 100)"),
        (["--model-error", "nan"], "--model-error: NaN"),
        (["--payload-com", "0.1"], "--payload-com: give the payload's mass too"),
        (["--inner", "computed-torque"], "--inner computed-torque: the outer input v is an acceleration"),
    ],
)
def test_cli_refuses_bad_inner_options_in_one_line(capsys, extra, expected):
    assert main(["info", "planar_2r", *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and expected in err, err


def test_cli_parses_inner_options():
    from polyrob.cli import build_parser
    from polyrob.cli.common import robot_from_args

    args = build_parser().parse_args(
        ["info", "planar_2r", "--inner", "gravity", "--payload-mass", "0:1.5", "--payload-com", "0,0,0.02"]
        + ["--model-error", "10"]
    )
    arm = robot_from_args(args)
    assert arm.inner == "gravity" and arm.model_error == pytest.approx(0.1)
    assert arm.payload.mass_upper == 1.5 and arm.payload.com_upper == (0.0, 0.0, 0.02)
    assert "inner layer: gravity" in arm.words() and "payload 0-1.5 kg" in arm.words()


@pytest.mark.parametrize("inner", ["gravity", "computed-torque"])
def test_validation_simulates_a_true_robot_drawn_from_the_ranges(pendulum, inner):
    """The nonlinear validation closes the inner layer (model) on a true robot with a drawn payload and error."""
    import control

    from polyrob.validate.simulate import simulate, smooth_reference

    arm = inner_loop(pendulum, inner, payload=PayloadRange.parse("0:0.1"), model_error=0.05)
    dom = _pendulum_domain(arm, qddot=5.0)
    k = np.diag(pendulum.mass_matrix([0.4, 0.3])) if inner == "gravity" else np.ones(2)
    s = control.tf("s")
    K = control.append(*[control.ss(kj * (25 + 5 / s + 10 * s / (0.01 * s + 1))) for kj in k])
    v0 = arm.inverse_dynamics([0.4, 0.3], [0, 0], [0, 0])[0]  # the model's equilibrium input
    sim = simulate(arm, K, dom, smooth_reference([0.5, 0.35], 2.0), t_final=4.0, q0=[0.4, 0.3], u_eq=v0)
    assert sim.success and sim.stayed_in_domain, sim.domain_exits
    mass = float(sim.info["true_robot"].split()[1])
    assert 0.0 <= mass <= 0.1 and "links x" in sim.info["true_robot"] and sim.info["inner"] == inner
    assert sim.summary()["true_robot"] == sim.info["true_robot"]  # what a fleet row's validation names
    assert np.all(np.isfinite(sim.info["motor_torque_peak"]))
    assert abs(sim.q[0, -1] - 0.5) < 0.1  # a plain PID, slow integral action: near the target, not settled
    nominal = simulate(arm, K, dom, smooth_reference([0.5, 0.35], 2.0), t_final=0.5, q0=[0.4, 0.3], true_seed=None)
    assert nominal.info["true_robot"] == "nominal"


def test_export_header_says_what_the_inner_layer_needs(tmp_path, pendulum):
    import polyrob
    from polyrob.validate.export_c import export_controller

    arm = inner_loop(pendulum, "computed-torque", model_error=0.1)
    res = export_controller(polyrob.paper_controller(), 1000.0, tmp_path, inner=arm.words())
    header = res.header.read_text()
    assert "outer input v of an inner layer" in header and "M_hat(q) v + h_hat(q, qdot)" in header
    assert header.isascii()
    plain = export_controller(polyrob.paper_controller(), 1000.0, tmp_path / "p", inner=None).header.read_text()
    assert "inner layer" not in plain


def test_bounds_say_whose_jacobians_the_pldi_coverage_checks(capsys):
    """The PLDI's coverage line of an inner loop counts the true robots its bounds were taken over, and says so."""
    args = ["bounds", "planar_2r", "--inner", "gravity", "--model-error", "10", "--pose", "0.4,0.3", "--q-radius"]
    args += ["0.2", "--qdot-max", "0.5", "--qddot-max", "2", "--samples", "32", "--coverage", "200", "--no-models"]
    assert main(args) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("coverage:"))
    assert line.endswith("fresh points of the 3 true robots the bounds were taken over"), line
