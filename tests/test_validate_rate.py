"""Validation at the rate: encoders, the computation delay, friction, the chatter figure, a run on planar_2r.

The controller ``tests/fixtures/planar_2r_ct_pid_K.json`` is the computed-torque PID of
``polyrob synth planar_2r --inner computed-torque --model-error 10 --pose 0.4,0.3 --q-radius 0.3
--qdot-max 0.5 --qddot-max 2 --structure pid`` (CERTIFIED, mu <= 0.677).
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from polyrob import load_robot
from polyrob.domains.task import TaskDomain
from polyrob.errors import ArgumentError
from polyrob.io.controller import load_controller
from polyrob.model.inner import inner_loop
from polyrob.validate.at_rate.figures import chatter_peak_to_peak, settling_time
from polyrob.validate.at_rate.loop import (
    CommandDelay,
    RealLoopConditions,
    encoder_lsb,
    joint_friction,
    quantize_position,
    simulate_real_loop,
)
from polyrob.validate.at_rate.runs import (
    default_uncertainty,
    set_words,
    task_references,
    true_plants,
    validate_at_rate,
)
from polyrob.validate.discretize import discretize

FIXTURE = Path(__file__).parent / "fixtures" / "planar_2r_ct_pid_K.json"
POSE = [0.4, 0.3]


@pytest.fixture(scope="module")
def arm():
    return inner_loop(load_robot("planar_2r"), "computed-torque", model_error=0.1)


@pytest.fixture(scope="module")
def domain(arm):
    return TaskDomain.from_robot(arm, pose=POSE, q_radius=0.3, qdot_max=0.5, qddot_max=2.0)


def test_encoder_quantisation_of_a_known_signal_is_within_half_an_lsb():
    lsb = encoder_lsb(18)
    assert lsb == pytest.approx(2 * math.pi / 2**18, rel=1e-15)
    q = np.linspace(-1.0, 1.0, 100_001)
    read = quantize_position(q, 18)
    error = np.abs(read - q)
    assert error.max() <= 0.5 * lsb * (1 + 1e-9)
    assert error.max() > 0.49 * lsb  # the bound is reached, the reading is not finer than the encoder
    assert np.allclose(read / lsb, np.round(read / lsb), atol=1e-6)  # multiples of the LSB
    assert np.array_equal(quantize_position(q, None), q)  # no encoder: exact


def test_the_delay_shifts_the_applied_torque_by_exactly_one_sample(arm):
    K = discretize(load_controller(FIXTURE), 1000.0).system
    q0 = np.array(POSE)
    zero = np.zeros((1, 2))
    v_eq = arm.inverse_dynamics(q0[None], zero, zero)[0]
    ref = lambda t: q0 + np.array([0.01, -0.01])  # noqa: E731
    runs = {
        d: simulate_real_loop(
            arm, K, ref, q0=q0, t_final=0.05, v_eq=v_eq, conditions=RealLoopConditions(delay_samples=d, saturate=False)
        )
        for d in (0, 1)
    }
    late, now = runs[1], runs[0]
    assert np.array_equal(late.tau_applied[:, 1:], late.tau_commanded[:, :-1])
    rest = arm.torque(quantize_position(q0, 18), np.zeros(2), v_eq)[0]
    assert np.array_equal(late.tau_applied[:, 0], rest)
    assert np.array_equal(now.tau_applied, now.tau_commanded)
    # the first command (from the same first reading) is the same; it acts one sample later
    assert np.array_equal(late.tau_commanded[:, 0], now.tau_commanded[:, 0])
    assert not np.allclose(late.q[:, -1], now.q[:, -1])
    d = CommandDelay(2, np.zeros(1))
    assert [float(d.push(np.array([k]))[0]) for k in (1.0, 2.0, 3.0)] == [0.0, 0.0, 1.0]


def test_coulomb_friction_at_rest_and_moving_against_its_formula():
    b, c, vs = 1.0, 2.0, 0.01
    at_rest = joint_friction(np.zeros(3), viscous=b, coulomb=c, velocity_scale=vs)
    assert np.array_equal(at_rest, np.zeros(3))
    qdot = np.array([0.5, -0.5, 3 * vs])
    moving = joint_friction(qdot, viscous=b, coulomb=c, velocity_scale=vs)
    assert moving[0] == pytest.approx(-(b * 0.5 + c), rel=1e-12)  # tanh(50) = 1 to double precision
    assert moving[1] == pytest.approx(b * 0.5 + c, rel=1e-12)
    assert moving[2] == pytest.approx(-(b * 3 * vs + c * math.tanh(3.0)), rel=1e-12)
    assert abs(moving[2] + b * 3 * vs) > 0.99 * c  # within 1 % of the full level beyond 3 v_s


def test_chatter_of_a_known_square_wave_is_its_peak_to_peak():
    t = np.arange(0.0, 2.0, 0.001)
    square = 3.0 * np.where((np.arange(len(t)) // 5) % 2 == 0, 1.0, -1.0)  # +-3 N m at 100 Hz
    assert chatter_peak_to_peak(t, square[None], start=0.0)[0] == pytest.approx(6.0, abs=1e-12)
    # a slow trend (the move itself) is not chatter; before `start` nothing counts
    trend = 40.0 * t
    assert chatter_peak_to_peak(t, (square + trend)[None], start=0.0)[0] == pytest.approx(6.0, abs=0.03)
    quiet = np.where(t < 1.0, square, 0.0)
    assert chatter_peak_to_peak(t, quiet[None], start=1.0)[0] == pytest.approx(0.0, abs=1e-12)
    assert settling_time(t, np.where(t < 0.5, 1.0, 0.0)[None], [0.1]) == pytest.approx(0.5)


def test_conditions_refuse_bad_values_in_one_line():
    with pytest.raises(ArgumentError, match="--encoder-bits"):
        RealLoopConditions(encoder_bits=2)
    with pytest.raises(ArgumentError, match="--friction-coulomb"):
        RealLoopConditions(friction_coulomb=-1.0)


def test_the_default_set_of_ur5_is_the_instrument_off_the_flange():
    spec = default_uncertainty(inner_loop(load_robot("ur5"), "computed-torque", model_error=0.1))
    assert spec.link_error == pytest.approx(0.1)
    assert (spec.payload.mass_lower, spec.payload.mass_upper, spec.payload.com_radius) == (0.0, 1.5, 0.1)


def test_the_set_words_name_the_friction_the_runs_apply():
    """A set without friction: the words said "friction: not stated" while every run had the loop's friction."""
    spec = default_uncertainty(inner_loop(load_robot("planar_2r"), "computed-torque", model_error=0.1))
    words = set_words(replace(spec, friction=()), RealLoopConditions(friction_viscous=1.0, friction_coulomb=2.0))
    assert "not stated" not in words
    assert "every run applies the validation's own (viscous 1 N m s/rad + Coulomb 2 N m per joint" in words


def test_true_plants_keep_the_nominal_inner_model(arm):
    plants = true_plants(arm, default_uncertainty(arm).bound(load_robot("planar_2r")), 2, seed=3)
    assert len(plants) == 2
    q = np.array([[0.4, 0.3]])
    for plant, _ in plants:
        assert plant.model_robot is arm.model_robot  # no payload in planar_2r's set: the arm's own model
        assert not np.allclose(plant.true_robot.mass_matrix(q[0]), arm.true_robot.mass_matrix(q[0]))


def test_half_the_validations_true_robots_sit_at_vertices_of_the_set(arm, domain):
    """Each link's factors at ``1 ± p`` on a vertex robot: its inertia is the nominal one times an end factor."""
    spec = default_uncertainty(arm).bound(load_robot("planar_2r"))
    plants = true_plants(arm, spec, 4, seed=3, extremes=0.5)
    assert [w.endswith("at a vertex of the set") for _, w in plants] == [False, False, True, True]
    nominal = load_robot("planar_2r").model
    for plant, words in plants:
        masses = np.array([plant.true_robot.model.inertias[j].mass / nominal.inertias[j].mass for j in (1, 2)])
        at_end = np.allclose(np.abs(masses - 1.0), 0.1, rtol=1e-12)
        assert at_end == words.endswith("at a vertex of the set")
    refs = task_references(domain, np.array(POSE), settle_time=0.2)[:1]
    res = validate_at_rate(arm, load_controller(FIXTURE), domain, true_robots=2, q0=POSE, references=refs)
    assert "2 true robot(s) drawn from" in res.verdict() and "(1 of 2 at vertices of the set)" in res.verdict()
    assert res.summary()["at_vertices"] == 1


def test_task_trajectory_stays_at_half_the_task_bounds(domain):
    (_, step, t_step, _), (_, move, t_move, duration) = task_references(domain, np.array(POSE), settle_time=1.0)
    r = move.bind(np.array(POSE))
    t = np.linspace(0, duration, 2001)
    path = np.array([r(tk) for tk in t])
    qdot = np.gradient(path, t, axis=0)
    qddot = np.gradient(qdot, t, axis=0)
    assert np.abs(qdot).max() <= 0.5 * 0.5 * 1.01
    assert np.abs(qddot).max() <= 0.5 * 2.0 * 1.02
    assert t_move == pytest.approx(duration + 1.0) and t_step == 1.0


def test_planar_2r_at_1_khz_settles_without_friction_and_not_with_coulomb(arm, domain):
    K = load_controller(FIXTURE)
    refs = task_references(domain, np.array(POSE), settle_time=3.0)[:1]  # the step
    clean = validate_at_rate(
        arm,
        K,
        domain,
        conditions=RealLoopConditions(friction_viscous=0.0, friction_coulomb=0.0),
        true_robots=1,
        q0=POSE,
        references=refs,
    )
    (fig,) = clean.figures
    assert fig.settled and fig.inside_task and fig.success
    assert fig.final_tracking_error < 0.02 * 0.0012 + 1e-12  # inside its 2 % band of the 1.2 mrad step
    assert 0.0 < fig.chatter_percent_max < 5.0  # quantisation does chatter, far below 5 %
    assert clean.meets_bar
    # Coulomb 2 N m that the inner model does not have: this slow integrator holds the joints off target
    rough = validate_at_rate(arm, K, domain, true_robots=1, q0=POSE, references=refs)
    (fig,) = rough.figures
    assert not fig.settled and fig.final_tracking_error > 0.3 * 0.0012
    assert not rough.meets_bar
    doc = rough.summary()
    assert doc["by_reference"]["step"]["settled"] == 0 and doc["conditions"]["encoder_bits"] == 18
    # not converging slowly: held, and the verdict says so with what the friction asks of the joints
    assert fig.stuck and doc["by_reference"]["step"]["stuck"] == 1
    budget = doc["friction_budget"]
    inertia = np.diag(arm.model_robot.mass_matrix(np.array(POSE)))
    assert np.allclose(budget["coulomb_acceleration"], 2.0 / inertia, rtol=1e-12)
    assert budget["rest_damping"] == pytest.approx(2.0 / 0.01)
    assert "stuck" in rough.verdict() and "rad/s^2 on joint" in rough.verdict()
    assert "friction_budget" in clean.summary() and "rad/s^2 on joint" not in clean.verdict()


def test_run_reads_the_validation_options_and_refuses_bad_ones_in_one_line(capsys, tmp_path):
    from polyrob.cli import build_parser, main
    from polyrob.cli.options import rate_conditions_from_args

    argv = ["run", "planar_2r", "--encoder-bits", "16", "--friction-coulomb", "0.5", "--true-robots", "3"]
    args = build_parser().parse_args(argv)
    c = rate_conditions_from_args(args)
    assert (c.rate, c.delay_samples, c.encoder_bits, c.friction_viscous, c.friction_coulomb) == (
        1000.0,
        1,
        16,
        1.0,
        0.5,
    )
    assert args.true_robots == 3
    assert rate_conditions_from_args(build_parser().parse_args(["run", "--true-robots", "0"])) is None
    # run and batch validate 20 true robots by default; synth and report only when asked (minutes on an arm)
    defaults = {
        cmd: build_parser().parse_args([cmd, *rest]).true_robots
        for cmd, rest in (("run", []), ("batch", []), ("synth", []), ("report", ["run_dir"]))
    }
    assert defaults == {"run": 20, "batch": 20, "synth": 0, "report": 0}
    for bad, option in (
        (["--friction-coulomb", "-1"], "--friction-coulomb"),
        (["--encoder-bits", "2"], "--encoder-bits"),
    ):
        try:  # argparse's refusal exits; a refusal after parsing (the weights' check) returns the code
            code = main(["run", "planar_2r", *bad, "-o", str(tmp_path / "run")])
        except SystemExit as stop:
            code = stop.code
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1 and option in err[0]
        assert not (tmp_path / "run").exists()


def test_the_report_shows_the_validation_at_the_rate(arm, domain, tmp_path):
    import json

    from polyrob.report.html import ReportOptions, write_report

    refs = task_references(domain, np.array(POSE), settle_time=1.0)[:1]
    summary = validate_at_rate(arm, load_controller(FIXTURE), domain, true_robots=1, q0=POSE, references=refs).summary()
    files = write_report(tmp_path, ReportOptions(robot_name="planar_2r", rate_validation=summary))
    doc = json.loads(files.validation.read_text())
    assert doc["at_rate"]["by_reference"]["step"]["runs"] == 1
    assert doc["at_rate"]["conditions"]["friction_coulomb"] == 2.0
    md = files.markdown.read_text()
    assert "Validation at the rate" in md and "a simulation, not a certificate" in md
    header = next(line for line in md.splitlines() if line.startswith("| reference |"))
    assert header.count("|") == 10  # nine columns: no pipe inside a heading


def test_a_run_that_stopped_early_is_neither_inside_nor_settled(arm, domain):
    from polyrob.validate.at_rate.figures import run_figures
    from polyrob.validate.at_rate.loop import RealLoopTrace

    t = 0.001 * np.arange(3)
    q = np.tile(np.array(POSE)[:, None], (1, 3))
    zero = np.zeros((2, 3))
    trace = RealLoopTrace(t, q, zero, zero, q, q, zero, zero, np.zeros(2), False, {"message": "diverged"})
    fig = run_figures(trace, domain, arm, reference="step", true_robot="x", move_end=0.0, lsb=encoder_lsb(18))
    assert not fig.inside_task and not fig.settled and fig.final_tracking_error == 0.0
