"""The moving robot on a task domain: scheduled on (q, qdot, qddot), the jerk bound, the report's three rows."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

import polyrob
from polyrob.analysis.lpv.task import (
    TaskMotionModel,
    jerk_bounds,
    minimum_jerk_bound,
    task_motion_certificate,
    task_rate_bounds,
    task_scheduling,
)
from polyrob.domains.task import TaskDomain
from polyrob.errors import ArgumentError


@pytest.fixture(scope="module")
def robot():
    return polyrob.load_robot("planar_2r")


#: A short search for the gain found along the task's motions (the defaults are the benchmark's).
FAST = {"horizon": 4.0, "iterations": 8, "random_runs": 1}


def _task(robot, radius=0.2, v=0.3, a=0.5):
    return TaskDomain.from_robot(robot, pose=[0.0, 1.5708], q_radius=radius, qdot_max=v, qddot_max=a)


# ---------------------------------------------------------------------- --qdddot-max


@pytest.mark.parametrize("value", ["-1", "nan", "1,-2", "inf"])
def test_a_negative_or_nan_jerk_bound_is_refused_in_one_line(value, capsys):
    from polyrob.cli import main

    with pytest.raises(SystemExit) as exc:
        main(["run", f"--qdddot-max={value}", "--json"])
    err = capsys.readouterr().err.strip().splitlines()
    assert exc.value.code == 2 and len(err) == 1 and "--qdddot-max" in err[0], err


def test_synth_takes_the_jerk_bound_for_its_moving_check_and_refuses_it_without(capsys):
    from polyrob.cli import main

    code = main(["synth", "paper_2r", "--qdddot-max", "5"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "add --moving" in err[0], err


def test_a_jerk_bound_is_refused_where_the_certificate_does_not_use_it(robot):
    from polyrob.cli.analyze import check_jerk_applies
    from polyrob.domains.torque_box import Domain

    problem = SimpleNamespace(
        domain=Domain.from_robot(robot), P=SimpleNamespace(uncertain=SimpleNamespace(model="lft"))
    )
    with pytest.raises(ArgumentError, match="--qdddot-max bounds the jerk of a task domain"):
        check_jerk_applies(SimpleNamespace(qdddot_max=5.0), problem)
    check_jerk_applies(SimpleNamespace(qdddot_max=5.0), replace_domain(problem, _task(robot)))  # a task: accepted
    with pytest.raises(ArgumentError, match="finite and >= 0"):
        jerk_bounds([1.0, float("nan")], 2)
    with pytest.raises(ArgumentError, match="give 1 or 2"):
        jerk_bounds([1.0, 2.0, 3.0], 2)


def replace_domain(problem, domain):
    return SimpleNamespace(domain=domain, P=problem.P)


def test_every_command_s_moving_check_takes_a_task_to_the_task_certificate(robot, monkeypatch):
    """``synth --moving`` called the fixed-torque certificate, which refuses a task ("the torque varies"), where
    ``analyze`` and ``run`` called the task's: one dispatch now, and an option it does not take is refused."""
    import polyrob.analysis.lpv.task as task_module
    from polyrob.analysis.lpv.constant import robot_in_motion_certificate

    seen = {}
    monkeypatch.setattr(task_module, "task_motion_certificate", lambda problem, K, **kw: seen.update(kw) or "task")
    problem = SimpleNamespace(domain=_task(robot), P=SimpleNamespace(uncertain=SimpleNamespace(model="lft")))
    got = robot_in_motion_certificate(problem, None, jerk=5.0, points=(3, 2), symmetric="auto", cells=True)
    assert got == "task" and seen["jerk"] == 5.0 and seen["points"] == (3, 2) and "symmetric" not in seen
    with pytest.raises(ArgumentError, match="takes no rate_samples"):
        robot_in_motion_certificate(problem, None, rate_samples=4)


def test_the_default_jerk_is_the_fastest_minimum_jerk_move_of_the_task(robot):
    # (27/8) a^2 / v when the move reaching both bounds fits in the range
    assert minimum_jerk_bound(_task(robot, 0.5, 1.0, 2.0)) == pytest.approx([13.5, 13.5], rel=1e-12)
    assert minimum_jerk_bound(_task(robot, 0.5, 0.3, 0.5)) == pytest.approx([27 / 8 * 0.25 / 0.3] * 2, rel=1e-12)
    # that move checked on the trajectory itself: it peaks at v, a and the bound
    v, a = 1.0, 2.0
    T = 10 / np.sqrt(3) * v / (1.875 * a)
    D = v * T / 1.875
    s = np.linspace(0.0, 1.0, 100001)  # q = D (10 s^3 - 15 s^4 + 6 s^5), s = t / T, differentiated by hand
    qd = D / T * (30 * s**2 - 60 * s**3 + 30 * s**4)
    qdd = D / T**2 * (60 * s - 180 * s**2 + 120 * s**3)
    qddd = D / T**3 * (60 - 360 * s + 360 * s**2)
    assert np.abs(qd).max() == pytest.approx(v, rel=1e-8) and np.abs(qdd).max() == pytest.approx(a, rel=1e-8)
    assert np.abs(qddd).max() == pytest.approx(13.5, rel=1e-12)
    # a move longer than the range (2 r = 0.2 < 1.642 v^2/a): the range at the acceleration bound
    T = np.sqrt(10 / np.sqrt(3) * 0.2 / 0.5)
    assert minimum_jerk_bound(_task(robot, 0.1, 1.0, 0.5)) == pytest.approx([60 * 0.2 / T**3] * 2, rel=1e-12)


# ---------------------------------------------------------------------- the scheduled model


def test_the_scheduled_jacobians_are_the_task_pldis_at_random_points(robot):
    task = _task(robot, 0.5, 1.0, 2.0)
    model = task_scheduling(robot, task, points=(3, 3), jerk=7.0)
    assert isinstance(model, TaskMotionModel)
    assert model.names == ("q2", "qdot1", "qdot2", "qddot1", "qddot2")  # q1 does not enter a planar arm's
    pldi = polyrob.bound_pldi(robot, task, samples=512, progress=False)
    lo, hi = np.asarray(pldi.lower), np.asarray(pldi.upper)
    rng = np.random.default_rng(3)
    box_lo = np.array([a[0] for a in model.axes])
    box_hi = np.array([a[-1] for a in model.axes])
    for rho in rng.uniform(box_lo, box_hi, size=(20, 5)):
        q, qdot, qddot = np.array([0.0, rho[0]]), rho[1:3], rho[3:5]
        A, B = model.plant(rho)
        # the Jacobians the PLDI bounds: the forward dynamics at the task's inverse-dynamics torque
        A_ref, B_ref = robot.jacobians(q, qdot, task.inputs(q, qdot, qddot)[0])
        assert np.allclose(A, A_ref, rtol=1e-12, atol=1e-12) and np.allclose(B, B_ref, rtol=1e-12, atol=1e-12)
        assert np.allclose(robot.acceleration(q, qdot, model.torque(rho)), qddot, atol=1e-10)
        values = np.array([(A if mat == 0 else B)[i, j] for mat, i, j in np.asarray(pldi.entry_index, int)])
        width = hi - lo
        assert np.all(values >= lo - 1e-3 * width - 1e-12) and np.all(values <= hi + 1e-3 * width + 1e-12)
    rates = task_rate_bounds(model, task)
    assert [r[1] for r in rates] == [1.0, 2.0, 2.0, 7.0, 7.0]  # qdot, qddot, the jerk


# ---------------------------------------------------------------------- the certificate on a small loop


def _small_problem(robot, gain):
    import control

    task = _task(robot)
    k = control.tf([gain, gain], [1 / 20, 1])
    K = control.append(control.ss(k), control.ss(k))
    w = control.ss(control.tf([0.5], [1, 0.05]))
    P = SimpleNamespace(W_S=control.append(w, w), W_T=None, W_KS=None, uncertain=SimpleNamespace(model="lft"))
    return SimpleNamespace(robot=robot, domain=task, P=P), K


def test_a_loop_made_to_fail_is_not_certified_and_no_bound_is_below_its_frozen_peak(robot):
    problem, K = _small_problem(robot, 200.0)
    good = task_motion_certificate(problem, K, points=(3, 2), recheck=None, velocities="arbitrary", lower_bound=FAST)
    assert good.computed and good.result.proved and 0.3 < good.frozen_gamma <= good.gamma < np.inf
    assert good.certificate.status.value in ("GRID_ONLY", "NOT_CERTIFIED")  # a grid: never CERTIFIED
    assert "dqdot2/dt any" not in good.rate_words and "jerk not needed" in good.rate_words
    # found along motions of the task (at rest: 0.148; the grid's frozen peak 0.506 is at points no motion stays at)
    assert good.lower["frozen_gamma"] <= good.lower["gamma"] <= good.gamma and good.lower["gamma"] > 0.14
    problem, K = _small_problem(robot, 50.0)  # a quarter of the gain: the frozen loops' gain is above 1
    bad = task_motion_certificate(problem, K, points=(3, 2), recheck=None, velocities="arbitrary", lower_bound=FAST)
    assert bad.computed and bad.frozen_gamma > 1 and bad.gamma >= bad.frozen_gamma
    assert bad.certificate.status.value == "NOT_CERTIFIED"
    assert bad.lower["frozen_gamma"] <= bad.lower["gamma"] <= bad.gamma and "L2 gain >= " in bad.verdict
    # a quarter of the controller's gain: a larger gain found (the long runs find 0.32 on the good loop, whose
    # weight's pole at 0.05 rad/s keeps a bang-bang velocity's gain growing for a minute, and 0.59 on this one)
    assert bad.lower["gamma"] > 1.5 * good.lower["gamma"]


def test_a_loop_too_large_for_the_search_still_gets_the_gain_found(robot, monkeypatch):
    import polyrob.analysis.lpv.task as task_module

    monkeypatch.setattr(task_module, "AUTO_STATES", 2)
    problem, K = _small_problem(robot, 200.0)
    mv = task_motion_certificate(problem, K, points=(3, 2), recheck=None, auto=True, lower_bound=FAST)
    assert not mv.computed and mv.certificate is None
    assert "runs up to 2" in mv.verdict and "L2 gain >= " in mv.verdict
    assert mv.summary()["lower_bound"] == mv.lower["gamma"] > 0.14
    assert task_motion_certificate(problem, K, auto=True, lower_bound=False).lower == {}


def test_the_search_s_solver_is_the_structured_one_above_the_auto_states(robot, monkeypatch):
    """``solver="auto"``: Clarabel on a small loop, the structured interior point on a large one (ten times faster
    on the main job's 16-state loop); the small problem's loop has 8 states, the default limit."""
    import polyrob.analysis.lpv.norm as norm_module
    import polyrob.analysis.lpv.task as task_module

    seen, real = [], norm_module.lpvnorm

    def spy(*args, **options):
        seen.append(options.get("solver"))
        return real(*args, **options)

    monkeypatch.setattr(norm_module, "lpvnorm", spy)
    problem, K = _small_problem(robot, 200.0)
    small = task_motion_certificate(problem, K, points=(3, 2), recheck=None, velocities="arbitrary", lower_bound=False)
    assert small.result.proved and set(seen) == {"clarabel"}
    seen.clear()
    monkeypatch.setattr(task_module, "AUTO_STATES", 5)
    large = task_motion_certificate(problem, K, points=(3, 2), recheck=None, velocities="arbitrary", lower_bound=False)
    assert large.result.proved and seen and set(seen) == {"structured"}
    assert large.gamma == pytest.approx(small.gamma, rel=0.05)  # the same loop, the same bound to the solvers' gaps


@pytest.mark.slow
def test_the_rate_bounded_search_proves_the_good_loop_on_the_grid(robot):
    """X on (1, cos q2, sin q2) x (1, qdot): a bound below 1 on the grid (41-91 s measured on 2 cores at load 12-14)."""
    problem, K = _small_problem(robot, 200.0)
    good = task_motion_certificate(problem, K, points=(3, 2), recheck=None, velocities="bounded")
    assert good.frozen_gamma <= good.gamma < 1 and good.certificate.status.value == "GRID_ONLY"
    assert "dqdot2/dt = qddot2" in good.rate_words


def test_a_certified_arbitrarily_fast_certificate_decides_the_moving_robot(robot):
    from polyrob.analysis.certificate import ARBITRARY, Scope, gain_certificate

    problem, K = _small_problem(robot, 200.0)
    scope = Scope(kind="robust performance", variation=ARBITRARY)
    for holds in (True, False):
        cert = gain_certificate(scope, stable=holds, checked=True, gamma=0.8)
        tv = SimpleNamespace(certificate=cert, method="vertices", seconds=1.0)
        mv = task_motion_certificate(
            problem, K, points=(3, 2), recheck=None, velocities="arbitrary", auto=True, time_varying=tv, lower_bound=False
        )
        if holds:
            assert mv.certificate.certified and mv.gamma == 0.8 and "at any rate" in mv.certificate.scope.variation
        else:  # not certified at any rate: the rate-bounded search (8 states <= AUTO_STATES)
            assert mv.computed and mv.decided is None


# ---------------------------------------------------------------------- the report's verdict table


def test_the_report_shows_three_rows_with_their_lower_bounds(robot):
    from polyrob.analysis.certificate import FROZEN, Certificate, Scope, Status
    from polyrob.analysis.lpv.moving_result import MovingRobotCertificate
    from polyrob.cli.run import report_certificates
    from polyrob.report.certificates import (
        FROZEN_ROW,
        MOVING_ROW,
        TIME_VARYING_ROW,
        certificate_rows,
        lower_bound_words,
    )

    frozen = Certificate(Status.CERTIFIED, 0.94, 0.93, 0.93, None, Scope(variation=FROZEN), ())
    problem, K = _small_problem(robot, 200.0)
    moving = task_motion_certificate(problem, K, points=(3, 2), recheck=None, velocities="arbitrary")
    a = SimpleNamespace(certificate=frozen, time_varying=None, moving=moving)
    records = report_certificates(a)
    rows = certificate_rows(records)
    assert rows[0][0] == FROZEN_ROW and rows[1][0] == TIME_VARYING_ROW and rows[2][0].startswith(MOVING_ROW + " (")
    assert [r[1] for r in rows] == ["CERTIFIED", "NOT_CERTIFIED", moving.certificate.status.value]
    assert rows[2][2] == pytest.approx(moving.gamma) and "qddot" in rows[2][3]
    words = "(mu itself is at least this: no bound of this kind goes below)"
    assert [lower_bound_words(v) for v in records.values()][0] == f"mu >= 0.93 {words}"
    found = f"gain >= {moving.lower['gamma']:.4g} (the largest found along admissible trajectories)"
    assert [lower_bound_words(v) for v in records.values()][1:] == ["not computed", found]
    # a moving robot not computed is a row too, saying why
    a = SimpleNamespace(certificate=frozen, time_varying=None, moving=MovingRobotCertificate.not_computed("too big"))
    rows = certificate_rows(report_certificates(a))
    assert len(rows) == 3 and rows[2][1] == "NOT_CERTIFIED"
    # not computed, but with the gain found along the task's motions: the row shows it as its lower bound
    from dataclasses import replace

    found = replace(MovingRobotCertificate.not_computed("too big"), lower={"gamma": 0.7087, "words": ">= 0.7087 found"})
    records = report_certificates(SimpleNamespace(certificate=frozen, time_varying=None, moving=found))
    rows = certificate_rows(records)
    assert len(rows) == 3 and rows[2][1] == "NOT_CERTIFIED"
    assert lower_bound_words(list(records.values())[2]).startswith("gain >= 0.7087 (the largest found")


def test_the_task_s_recheck_grid_is_finer_than_its_search_grid_along_positions_and_velocities():
    """A fixed (9, 3) re-check was the search grid itself for a (9, 3) search: the X then failed between its q2
    points while its "finer grid" bound said 0.9653 (main job with --as 0.3); and with the velocities' 3 points
    kept, an X that fails midway between them passed."""
    from polyrob.analysis.lpv.task import DEFAULT_RECHECK, recheck_points

    for points in [(3, 2), (5, 3), (9, 3), (17, 5)]:
        q, v = recheck_points(points)
        assert q >= DEFAULT_RECHECK[0] and v >= DEFAULT_RECHECK[1]
        for n, search in ((q, points[0]), (v, points[1])):  # every search point, and one between each two
            assert (n - 1) % (search - 1) == 0 and (n - 1) // (search - 1) >= 2
