"""Coulomb friction as a bounded torque disturbance: its channel, its steady-state error, a joint that sticks.

paper_2r (no gravity, no inner layer: ``u`` is the torque) keeps the formulas exact: behind a PD
``K(0) = Kp`` a constant torque ``d`` leaves ``e = -Kp^-1 d`` whatever the inertia.
"""

from __future__ import annotations

import control
import numpy as np
import pytest

import polyrob
from polyrob.analysis.certificate import friction_sentence
from polyrob.plant.generalized import generalized_plant, lft
from polyrob.plant.uncertainty import uncertain_plant
from polyrob.plant.weights import coulomb_weight
from polyrob.synthesis.integral import coulomb_channel, coulomb_levels, integral_rank
from polyrob.synthesis.pid_tuning import pid_controller
from polyrob.validate.at_rate.figures import run_figures, stuck_joints
from polyrob.validate.at_rate.loop import RealLoopConditions, simulate_real_loop
from polyrob.validate.discretize import discretize

KP = np.array([400.0, 100.0])  # N m/rad
KD = np.array([300.0, 80.0])  # N m s/rad
FC = np.array([2.0, 1.5])  # N m


def pd(kp=KP, kd=KD, tau=0.002):
    """Decentralised ``Kp + Kd s/(tau s + 1)``: no integral action."""
    m = len(kp)
    return control.ss(
        -np.eye(m) / tau, np.eye(m), -np.diag(kd) / tau**2, np.diag(np.asarray(kp) + np.asarray(kd) / tau)
    )


def pid(ki, kp=KP, kd=KD, tau=0.002):
    return pid_controller(np.column_stack([kp, ki, kd, np.full(len(kp), tau)]))


@pytest.fixture(scope="module")
def robot():
    return polyrob.load_robot("paper_2r")


@pytest.fixture(scope="module")
def unc(robot):
    pldi = polyrob.bound_pldi(robot, samples=256, coverage=0, progress=False)
    return uncertain_plant(pldi, model="box")


class _Pushed:
    """``robot`` with a constant torque ``d`` on its joints (a stuck joint's Coulomb torque, held)."""

    def __init__(self, robot, d):
        self._robot, self._d = robot, np.asarray(d, float)

    def __getattr__(self, name):
        return getattr(self._robot, name)

    def acceleration(self, q, qdot, tau):
        return self._robot.acceleration(q, qdot, np.asarray(tau, float) + self._d)


def _loop_roots(M, kp, ki, kd, tau):
    """Roots of ``det(s (tau s + 1) M s^2 + diag(kp s (tau s + 1) + ki (tau s + 1) + kd s^2))`` (all states)."""
    import numpy.polynomial.polynomial as npp

    m = len(kp)
    # matrix polynomial entries, coefficients in ascending powers
    entries = [[npp.polymul([0, 0, 0, 1], [1, tau]) * M[i, j] for j in range(m)] for i in range(m)]
    for i in range(m):
        diag = npp.polyadd(
            npp.polyadd(npp.polymul([0, kp[i]], [1, tau]), npp.polymul([ki[i]], [1, tau])), [0, 0, kd[i]]
        )
        entries[i][i] = npp.polyadd(entries[i][i], diag)
    det = npp.polysub(npp.polymul(entries[0][0], entries[1][1]), npp.polymul(entries[0][1], entries[1][0]))
    return npp.polyroots(det)


def _final_error(robot, K, d, q0, t_final=5.0):
    cond = RealLoopConditions(encoder_bits=None, friction_viscous=0.0, friction_coulomb=0.0, saturate=False)
    Kd = discretize(K, cond.rate).system
    trace = simulate_real_loop(
        _Pushed(robot, d), Kd, lambda t: q0, q0=q0, t_final=t_final, v_eq=np.zeros(len(q0)), conditions=cond
    )
    return (trace.r - trace.q)[:, -1], trace


def test_coulomb_weight_is_the_torque_box_or_its_acceleration_through_the_inverse_inertia():
    assert np.array_equal(coulomb_weight(FC), np.diag(FC))
    N = np.array([[4.0, -1.0], [1.0, 10.0]])
    # |(M^-1 d)_i| <= sum_j |N_ij| F_c,j, over 1 - p for a 10 % inertia error
    assert np.allclose(np.diag(coulomb_weight(FC, N, model_error=0.1)), [(8 + 1.5) / 0.9, (2 + 15) / 0.9])
    with pytest.raises(ValueError, match="--coulomb"):
        coulomb_weight([2.0, -1.0])


def test_the_friction_input_gain_at_dc_is_minus_the_inverse_proportional_gain(unc):
    # z_S = W_S e with W_S = 1: f -> z_S at DC is -(S G)(0) W_f = -Kp^-1 W_f (G has a double integrator)
    Wf = coulomb_weight(FC)
    P = generalized_plant(unc, W_S=1.0, W_f=Wf)
    assert P.n_w == 4 and P.system.input_labels[unc.n_delta + 2 : unc.n_delta + 4] == ["f[0]", "f[1]"]
    assert P.block_structure_rp[-1].tolist() == [4, 2]
    N = lft(P, pd())
    rows = slice(unc.n_delta, unc.n_delta + 2)
    nom = np.asarray(unc.nominal_delta, float)
    # close the uncertainty at the nominal point: the plant's own map f -> e
    from polyrob.plant.lftplant import upper_lft

    closed = upper_lft(N, unc.delta_matrix(nom))
    dc = np.asarray(closed.dcgain())[rows.start - unc.n_delta : rows.stop - unc.n_delta, 2:4]
    assert np.allclose(dc, -np.diag(FC / KP), rtol=1e-6, atol=1e-12)
    # the reference channel is unchanged by the new input: r -> e at DC is 0 (S(0) = 0)
    assert np.allclose(np.asarray(closed.dcgain())[0:2, 0:2], 0.0, atol=1e-9)
    # with the encoder noise too: w = [r; n; f], the friction columns the same
    Pn = generalized_plant(unc, W_S=1.0, W_n=1e-5, W_f=Wf)
    assert Pn.n_w == 6 and Pn.info["w_labels"] == ("r", "n", "f")
    f_cols = slice(unc.n_delta + 4, unc.n_delta + 6)
    assert np.array_equal(
        Pn.system.B[:, f_cols][: unc.n_x], P.system.B[:, unc.n_delta + 2 : unc.n_delta + 4][: unc.n_x]
    )


def test_a_loop_without_integral_action_states_its_steady_state_error_and_the_arm_agrees(robot, unc):
    K = pd()
    assert integral_rank(K) == 0
    ch = coulomb_channel(unc.nominal_system(), K, FC, source="--coulomb")
    assert not ch.integral and ch.stable
    assert np.allclose(ch.steady_state, FC / KP, rtol=1e-6)
    assert np.allclose(ch.steady_state_per_nm, 1.0 / KP, rtol=1e-6)
    assert ch.peak >= max(ch.steady_state) * (1 - 1e-9)  # the H-inf level includes DC
    words = friction_sentence(ch)
    assert "no integral action" in words and f"{max(FC / KP):.3g} rad" in words
    # the nonlinear arm at 1 kHz (one sample of delay) pushed by the worst signs of the box
    q0 = np.zeros(2)
    e, _ = _final_error(robot, K, FC * np.array([1.0, -1.0]), q0)
    assert np.allclose(np.abs(e), ch.steady_state, rtol=0.10)


def test_integral_action_leaves_no_steady_state_error(robot, unc):
    K = pid(ki=np.array([400.0, 100.0]))
    assert integral_rank(K) == 2
    ch = coulomb_channel(unc.nominal_system(), K, FC, source="--coulomb")
    assert ch.integral and ch.steady_state == (0.0, 0.0)
    assert "no steady-state error" in friction_sentence(ch)
    # how fast it fades: the slowest root of the loop's characteristic polynomial, joint by joint
    # (paper_2r at rest is M qddot = u with M coupled: det(M s^2 + K(s)) with K = Kp + Ki/s + Kd s/(tau s + 1))
    M = robot.mass_matrix(np.zeros(2))
    tau = 0.002
    s_roots = _loop_roots(M, KP, np.array([400.0, 100.0]), KD, tau)
    assert ch.slowest_rate == pytest.approx(np.min(np.abs(s_roots.real)), rel=1e-6)
    assert f"{ch.slowest_rate:.3g} 1/s" in friction_sentence(ch)
    e, _ = _final_error(robot, K, FC, np.zeros(2), t_final=3.0)
    assert np.abs(e).max() < 0.1 * (FC / KP).min()  # the PD leaves FC / KP; the integral is removing it


def test_coulomb_levels_come_from_the_option_or_the_set(robot):
    levels, source = coulomb_levels(robot, [2.0])
    assert levels.tolist() == [2.0, 2.0] and source == "--coulomb"
    assert coulomb_levels(robot, None) == (None, "")
    with pytest.raises(ValueError, match="one per joint"):
        coulomb_levels(robot, [1.0, 2.0, 3.0])


def test_a_joint_held_by_friction_is_reported_stuck_not_settled(robot):
    # a PD on paper_2r pushed by a constant torque: joint errors F_c/Kp, held (no integral to remove them)
    q0 = np.zeros(2)
    _, trace = _final_error(robot, pd(), FC, q0)
    trace = type(trace)(**{**trace.__dict__, "r": trace.r + np.array([[1e-3], [0.0]])})  # a move of 1 mrad
    figs = run_figures(trace, _Box(), robot, reference="step", true_robot="nominal", move_end=0.0, lsb=0.0)
    assert not figs.settled
    assert figs.stuck == [0, 1]
    t = trace.t
    assert stuck_joints(t, np.vstack([1e-3 * np.exp(-t)]), [1e-6]) == []  # converging is not stuck


class _Box:
    q_lower, q_upper = [-1.0, -1.0], [1.0, 1.0]
    qdot_lower, qdot_upper = [-5.0, -5.0], [5.0, 5.0]


def test_coulomb_levels_of_a_robot_uncertainty_set_follow_its_joint_names():
    from pathlib import Path
    from types import SimpleNamespace

    from polyrob.uncertainty_set.spec import RobotUncertainty

    spec = RobotUncertainty.from_file(Path(__file__).parents[1] / "examples" / "uncertainty" / "panda.yaml")
    names = [f"panda_joint{i}" for i in range(1, 8)]
    # the set's joints in reverse order: the levels must land on the named joints, not in file order
    robot = SimpleNamespace(m=7, joint_names=names[::-1], uncertainty=spec)
    levels, source = coulomb_levels(robot)
    assert source == "the robot-uncertainty set"
    assert levels.tolist() == [0.565, 0.303, 0.839, 1.279, 0.641, 0.872, 0.546]
    assert coulomb_levels(robot, [2.0])[0].tolist() == [2.0] * 7  # --coulomb wins
