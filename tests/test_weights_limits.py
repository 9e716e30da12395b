"""The weights of what limits a real loop: effort limit, encoder noise, sample rate (docs/synthesis.md)."""

from __future__ import annotations

import functools
import math
from types import SimpleNamespace

import control
import numpy as np
import pytest

import polyrob
from polyrob.analysis.certificate import Certificate, Scope, decide_gain
from polyrob.errors import ArgumentError
from polyrob.fleet.autoweights import TASK_TORQUE_MARGIN, automatic_hyperparameters, limit_hyperparameters
from polyrob.pipeline import default_hyperparameters
from polyrob.plant.generalized import generalized_plant, lft, paper_controller
from polyrob.plant.weights import (
    CHANNEL_FLOOR,
    channel_budgets,
    effort_level,
    encoder_lsb,
    encoder_noise_level,
    limit_weight,
    paper_weights,
    plant_weights,
)
from polyrob.synthesis.bandwidth import channel_peaks, crossover_cap, loop_crossover, max_bandwidth_scaling


# --------------------------------------------------------------------------- levels
def test_encoder_levels_are_the_lsb_and_half_of_it():
    assert encoder_lsb(18) == 2 * math.pi / 262144  # 2.397e-5 rad: an 18-bit encoder
    assert encoder_noise_level(18) == math.pi / 262144
    assert encoder_noise_level(12) == pytest.approx(7.67e-4, rel=1e-3)
    for bad in (0, -3, 1.5, float("nan"), float("inf"), 65, "x"):
        with pytest.raises(ArgumentError):
            encoder_lsb(bad)


def test_effort_level_is_the_budget_formula():
    # a_j = min(0.05 tau_max / 2, tau_max - tau_task): 3.75 N m on joint 0; 0.5 N m left by the task on joint 1
    assert effort_level([150.0, 28.0], [20.0, 27.5]).tolist() == pytest.approx([1 / 3.75, 1 / 0.5])
    # through M_hat, uncoupled: each channel its own row's a_j / N_jj
    w = effort_level([150.0, 28.0], [20.0, 5.0], [[3.0, 0.0], [0.0, 0.1]])
    assert w.tolist() == pytest.approx([3.0 / 3.75, 0.1 / 0.7], rel=1e-6)
    assert effort_level([150.0], [0.0], fraction=0.1).tolist() == pytest.approx([1 / 7.5])
    with pytest.raises(ArgumentError, match="no torque is left"):
        effort_level([150.0, 28.0], [20.0, 28.0])
    for bad in ([float("nan"), 1.0], [0.0, 1.0], [float("inf"), 1.0]):
        with pytest.raises(ArgumentError):
            effort_level(bad, [0.0, 0.0])


def test_the_v_channels_share_the_rows_budgets_and_keep_every_joint_within_its_own():
    # a shoulder, an elbow and a wrist: one weight for all three is set by the shoulder's row
    N = np.array([[4.9, 0.15, 0.02], [0.15, 1.8, 0.03], [0.02, 0.03, 0.025]])
    a = np.array([3.75, 3.75, 0.7])
    uniform = 1 / np.min(a / np.linalg.norm(N, axis=1))
    W_u = effort_level([150.0, 150.0, 28.0], [0.0, 0.0, 0.0], N)
    c = 1 / W_u
    assert np.all(W_u <= uniform / CHANNEL_FLOOR * (1 + 1e-6))  # no channel much tighter than the uniform weight
    assert W_u[2] < uniform / 10  # the wrist's v hardly moves the shoulder: ten times the room
    # every v with ||diag(1/c) v|| <= 1 keeps |N_j . |v|| within a_j (Cauchy-Schwarz, rows re-checked)
    assert np.all(np.linalg.norm(N * c, axis=1) <= a * (1 + 1e-12))
    rng = np.random.default_rng(0)
    v = rng.normal(size=(2000, 3))
    v = c * v / np.linalg.norm(v, axis=1, keepdims=True)
    assert np.all(np.abs(v) @ N.T <= a * (1 + 1e-12))
    # an extreme v: all the shoulder row's budget, each term at its largest
    worst = np.linalg.norm(N[0] * c)
    assert worst == pytest.approx(a[0], rel=1e-3)
    with pytest.raises(ArgumentError, match="positive diagonal"):
        effort_level([150.0, 28.0], [0.0, 0.0], [[1.0, 0.0], [0.0, 0.0]])
    assert channel_budgets([1.0, 1.0], [[1.0, 0.0], [0.0, 0.5]]) == pytest.approx([1.0, 2.0], rel=1e-6)


def test_limit_weight_folds_the_largest_noise_into_w_u():
    W = limit_weight({"effort": (2.0, 4.0), "noise": (1e-5, 2e-5)})
    assert W.tolist() == [[4e-5, 0.0], [0.0, 8e-5]]
    assert limit_weight({"omega_b": (1.0,)}) is None
    with pytest.raises(ArgumentError, match="missing"):
        limit_weight({"effort": (1.0,)})
    w = plant_weights(default_hyperparameters(2, {"effort": [3.0], "noise": [1e-4]}))
    assert float(np.asarray(w["W_KS"])[1, 1]) == pytest.approx(3e-4)
    assert plant_weights()["W_KS"] is None  # the paper's problem is unchanged


# --------------------------------------------------------------------------- the generalized plant
def test_noise_input_gains_at_dc_and_high_frequency(pldi):
    """n enters the measurement only: open loop -W_n into e; closed loop n -> z is -W_n (r -> z) on W_T, W_KS."""
    from polyrob.plant.uncertainty import uncertain_plant

    unc = uncertain_plant(pldi, model="box")
    W_S, W_T = paper_weights()
    wn = 1e-3
    P = generalized_plant(unc, W_S, W_T, W_KS=2.0, W_n=wn)
    nd, m = P.n_delta, P.n_u
    assert (P.n_w, P.block_structure_rp[-1].tolist()) == (2 * m, [2 * m, P.n_z])
    assert P.system.input_labels[nd + m : nd + 2 * m] == ["n[0]", "n[1]"]
    at0 = P.at(np.zeros(unc.n_params))
    for w in (0.0, 1e6):  # open loop: n -> e_meas = -W_n, n -> z = 0 at every frequency
        H = np.asarray(at0(1j * w))
        assert np.allclose(H[-m:, m : 2 * m], -wn * np.eye(m))
        assert np.allclose(H[: P.n_z, m : 2 * m], 0.0)
    # closed loop with a static K = k I: at high frequency S = I, so n -> z_KS = -W_KS k W_n = -2 k 1e-3
    k = 7.0
    N = lft(P, np.eye(m) * k)
    rows_ks = slice(nd + 2 * m, nd + 3 * m)  # z = [z_S, z_T, z_KS]
    H = np.asarray(N(1e7j))
    assert np.allclose(H[rows_ks, nd + m : nd + 2 * m], -2 * k * wn * np.eye(m), rtol=1e-4, atol=1e-9)
    # near DC and at high frequency against the hand formula n -> z_KS = -W_KS k (I + G k)^-1 W_n,
    # G read off P's own u -> e_meas = -G
    for w in (1e-4, 1.0, 1e4):
        G = -np.asarray(at0(1j * w))[-m:, 2 * m :]
        expect = 2.0 * k * np.linalg.inv(np.eye(m) + G * k) * wn
        np.testing.assert_allclose(-np.asarray(N(1j * w))[rows_ks, nd + m : nd + 2 * m], expect, rtol=1e-6, atol=1e-12)
    N2 = lft(P, paper_controller())
    for w in (1e-3, 1.0, 1e3):  # with any K: n -> z_T and z_KS are -W_n times r -> z_T, z_KS
        H2 = np.asarray(N2(1j * w))
        for rows in (slice(nd + m, nd + 2 * m), rows_ks):
            # equal up to rounding on the block's own scale (an entry of 1e-7 beside 0.2 carries 1e-12 of it)
            scale = np.abs(H2[rows, nd : nd + m]).max()
            np.testing.assert_allclose(H2[rows, nd + m : nd + 2 * m], -wn * H2[rows, nd : nd + m], atol=1e-9 * scale)


# --------------------------------------------------------------------------- a one-joint arm on a task
@functools.cache
def one_joint():
    """planar_2r with joint2 locked over a small task: bounded in seconds."""
    from polyrob.domains.task import TaskDomain
    from polyrob.plant.uncertainty import uncertain_plant

    robot = polyrob.load_robot("planar_2r", lock=["joint2"])
    dom = TaskDomain.from_robot(robot, pose=[0.0], q_radius=0.1, qdot_max=0.5, qddot_max=0.5)
    pldi = polyrob.bound_pldi(robot, dom, samples=64, coverage=0, progress=False)
    return robot, dom, uncertain_plant(pldi, model="box")


def test_limit_hyperparameters_of_a_task():
    robot, dom, _ = one_joint()
    budget = limit_hyperparameters(robot, dom)
    M = float(robot.mass_matrix(np.zeros(1))[0, 0])  # 60.625 kg m^2, no gravity in the arm's plane
    # the task's torque: inertia times the acceleration bound (plus a little velocity term), raised by the margin
    assert TASK_TORQUE_MARGIN * M * 0.5 <= budget.task_torque[0] <= TASK_TORQUE_MARGIN * M * 0.5 * 1.01
    assert budget.effort == pytest.approx((1 / 2.5,))  # 5 % of 100 N m peak to peak: 2.5 N m amplitude
    assert budget.noise == (encoder_noise_level(18),) and budget.binds == ("encoder noise",)
    assert limit_hyperparameters(robot, dom, encoder_bits=12).noise == (encoder_noise_level(12),)
    h = automatic_hyperparameters(1, dom, robot=robot)
    assert h["effort"] == budget.effort and h["noise"] == budget.noise
    assert automatic_hyperparameters(1, dom, {"effort": [9.0]}, robot=robot)["effort"] == (9.0,)
    assert "effort" not in automatic_hyperparameters(1, dom)


def _pd(M, wc):
    """A PD with its filter at 10 wc: crosses over near 2 wc on 1/(M s^2); K(inf) = 20 M wc^2."""
    return control.tf([M * 2 * wc, M * wc**2], [1 / (10 * wc), 1])


def _stand_in(M, rate_of_alpha):
    """A synthesis whose certificate is the largest nominal channel peak (a stand-in: fast and known)."""

    def synthesize(P, K0):
        K = _pd(M, rate_of_alpha * P.info["alpha"])
        mu = max(p for p, _ in channel_peaks(P, K).values())
        cert = Certificate(decide_gain(True, mu, True)[0], mu, mu, float("nan"), None, Scope())
        return SimpleNamespace(certificate=cert, controller=K, order=1)

    return synthesize


def _plant(unc):
    def plant(alpha, h):
        P = generalized_plant(unc, **plant_weights(h))
        P.info["alpha"] = alpha
        return P

    return plant


def test_bandwidth_search_stops_at_the_encoder_noise_and_names_it():
    robot, dom, unc = one_joint()
    M = float(robot.mass_matrix(np.zeros(1))[0, 0])
    h = default_hyperparameters(1, limit_hyperparameters(robot, dom).hyperparameters())
    res = max_bandwidth_scaling(unc, h, synthesize=_stand_in(M, 1.0), plant=_plant(unc), rate=1000.0, progress=False)
    # the noise channel at high frequency: W_u W_n K(inf) = 0.4 * 1.198e-5 * 20 M wc^2 = 1 at wc = 13.1 rad/s
    wc_noise = 1 / math.sqrt(0.4 * encoder_noise_level(18) * 20 * M)
    assert res.alpha <= wc_noise <= res.bracket[1] and res.bracket[1] / res.alpha < 1.06
    assert res.bound_hit.startswith(f"at alpha = {res.bracket[1]:.4g}: encoder noise against the effort limit")
    assert res.crossover == pytest.approx(2 * res.alpha, rel=0.05) and res.crossover_limit == 100.0
    summary = res.summary()
    assert summary["bound_hit"] == res.bound_hit and summary["crossover_limit_rad_s"] == 100.0


def test_bandwidth_search_stops_at_the_sample_rate_and_names_it():
    robot, dom, unc = one_joint()
    M = float(robot.mass_matrix(np.zeros(1))[0, 0])
    h = default_hyperparameters(1, limit_hyperparameters(robot, dom).hyperparameters())
    # 50 Hz and one sample: crossovers above 5 rad/s are not implementable; the PD crosses near 2 alpha
    res = max_bandwidth_scaling(unc, h, synthesize=_stand_in(M, 1.0), plant=_plant(unc), rate=50.0, progress=False)
    assert crossover_cap(50.0) == pytest.approx(5.0)
    assert res.bound_hit.startswith(f"sample rate: at alpha = {res.bracket[1]:.4g} the certified loop crosses over")
    assert res.crossover <= 5.0 < loop_crossover(_plant(unc)(res.bracket[1], h), _pd(M, res.bracket[1]))
    # without a rate the same search runs on to the noise bound (the continuous-time problem)
    free = max_bandwidth_scaling(unc, h, synthesize=_stand_in(M, 1.0), plant=_plant(unc), progress=False)
    assert free.alpha > res.bracket[1] and math.isnan(free.crossover_limit)


def test_crossover_cap_refuses_bad_rates():
    assert crossover_cap(1000.0, 1.0) == pytest.approx(100.0)
    for rate, delay in ((0.0, 1.0), (float("nan"), 1.0), (1000.0, -1.0), (float("inf"), 1.0)):
        with pytest.raises(ArgumentError):
            crossover_cap(rate, delay)


# --------------------------------------------------------------------------- the command line
@pytest.mark.parametrize(
    "option",
    [
        ["--encoder-bits", "nan"],
        ["--encoder-bits", "0"],
        ["--encoder-bits", "-4"],
        ["--encoder-bits", "17.5"],
        ["--effort-weight", "nan"],
        ["--effort-weight", "0"],
        ["--effort-weight", "-1"],
        ["--encoder-bits", "65"],
        ["--no-limit-weights", "--effort-weight", "2"],
    ],
)
def test_cli_refuses_bad_limit_options(option, capsys):
    from polyrob.cli import main

    try:
        rc = main(["synth", "planar_2r", "--q-range=-0.1:0.1", *option])
    except SystemExit as exc:  # argparse's own refusal (a bad --encoder-bits): exit status 2 as well
        rc = exc.code
    assert rc == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err and ("--encoder-bits" in err[-1] or "--effort-weight" in err[-1] or "--no-limit" in err[-1])
