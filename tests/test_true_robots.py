"""True robots drawn from a robot-uncertainty set: their frozen loops, the sampled lower bound, the multi-model tuning."""

from __future__ import annotations

import functools
from types import SimpleNamespace

import control
import numpy as np
import pytest

from polyrob import load_robot
from polyrob.domains.default_task import default_task_domain
from polyrob.errors import ArgumentError
from polyrob.model.inner import inner_loop, inner_loop_of_set
from polyrob.plant.weights import PAPER_HYPERPARAMETERS, plant_weights
from polyrob.synthesis import true_robots as tr
from polyrob.synthesis.pid_tuning import pid_controller, pid_gains
from polyrob.uncertainty_set.spec import RobotUncertainty
from polyrob.validate.independent import hinf, weighted_loop

WEIGHTS = dict(PAPER_HYPERPARAMETERS)


@functools.cache
def loop_and_task(link_error: float):
    robot = load_robot("planar_2r")
    loop = inner_loop_of_set(robot, "computed-torque", RobotUncertainty(link_error=link_error), draws=1)
    return loop, default_task_domain(loop)


def pid(crossover: float, sign: float = 1.0):
    return sign * pid_controller(pid_gains(np.full(2, crossover), 16.0, 20.0, np.ones(2)))


def test_exact_model_plants_are_double_integrators_and_per_link_errors_move_them():
    loop, task = loop_and_task(0.0)
    for A, B in tr.true_robot_plants(loop, task, 4, seed=3):
        np.testing.assert_allclose(A[2:], 0.0, atol=1e-9)  # computed torque with the true model: a = v
        np.testing.assert_allclose(B[2:], np.eye(2), atol=1e-9)
    loop, task = loop_and_task(0.1)
    gains = [B[2:] for _, B in tr.true_robot_plants(loop, task, 20, seed=3)]
    assert max(np.abs(g - np.eye(2)).max() for g in gains) > 0.01  # each true robot differs from the model
    assert not np.allclose(gains[0], gains[1])
    # B_low = M_true^-1 M_hat: its eigenvalues are real and positive (a ratio of inertias)
    assert all(np.linalg.eigvals(g).real.min() > 0 for g in gains)


def test_a_common_factor_loop_draws_from_the_set_its_certificate_states():
    """Without a robot-uncertainty set, an inner loop with a model error draws one factor on all links: B_low = I / s."""
    robot = load_robot("planar_2r")
    loop = inner_loop(robot, "computed-torque", model_error=0.3)
    task = default_task_domain(loop)
    factors = []
    for _, B in tr.true_robot_plants(loop, task, 12, seed=5):
        g = B[2:]
        np.testing.assert_allclose(g, g[0, 0] * np.eye(2), atol=1e-9)  # one factor on every link: M_true = s M_hat
        factors.append(1.0 / g[0, 0])
    assert 0.7 - 1e-9 <= min(factors) < max(factors) <= 1.3 + 1e-9
    assert np.ptp(factors) > 0.2  # spread over the range, not one robot
    problem = SimpleNamespace(robot=loop, domain=task, hyperparameters=WEIGHTS)
    check = tr.check_of_problem(problem, pid(2.0))
    assert check is not None and check.unstable == 0 and np.isfinite(check.worst)
    # a torque box fixes the outer input, not the acceleration a true robot is drawn at: no figure
    box = SimpleNamespace(robot=loop, domain=SimpleNamespace(kind="box"), hyperparameters=WEIGHTS)
    assert tr.check_of_problem(box, pid(2.0)) is None


def test_the_check_reads_the_weighted_norm_of_each_frozen_loop():
    loop, task = loop_and_task(0.0)  # every draw is the double integrator: one loop, its H-inf norm known
    K = pid(2.0)
    check = tr.true_robot_check(loop, task, K, WEIGHTS, n=3)
    W = plant_weights(WEIGHTS)
    A, B = tr.true_robot_plants(loop, task, 1, seed=0)[0]
    mats = [np.atleast_2d(np.asarray(X, float)) for X in (control.ss(K).A, control.ss(K).B, control.ss(K).C, control.ss(K).D)]
    weight_mats = [tuple(np.atleast_2d(np.asarray(X, float)) for X in (w.A, w.B, w.C, w.D))
                   for w in (control.ss(W["W_S"]), control.ss(W["W_T"]))]  # fmt: skip
    _, (Aw, Bw, Cw, Dw) = weighted_loop(A, B, tuple(mats), *weight_mats)
    exact = hinf(Aw, Bw, Cw, Dw)
    assert check.unstable == 0
    # a grid peak: never above the H-inf norm, and the grid is fine enough to come within 2 % of it
    assert exact * 0.98 <= check.worst <= exact * (1 + 1e-9)
    assert check.median == pytest.approx(check.worst)
    assert "lower bound of the set's worst case, not a certificate" in check.words()


def test_the_worst_loop_s_figure_by_weight_says_which_weight_it_misses():
    """Each weight alone on the worst loop: none above the stacked peak, and together they make it up (two
    stacked blocks: at most sqrt(2) times the larger); said when the worst loop misses the weights."""
    loop, task = loop_and_task(0.1)
    check = tr.true_robot_check(loop, task, pid(2.0), WEIGHTS, n=8)
    channels = check.worst_channels
    assert set(channels) == {"W_S S", "W_T T"}  # the paper's weights have no W_KS
    assert max(channels.values()) <= check.worst * (1 + 1e-9)
    assert max(channels.values()) >= check.worst / np.sqrt(2) * (1 - 1e-9)
    missing = tr.TrueRobotCheck(500, 0, 1.98, 1.69, 0, 250, {"W_S S": 1.16, "W_T T": 1.13, "W_KS K S": 1.71})
    assert "; the worst loop by weight: W_S S 1.16, W_T T 1.13, W_KS K S 1.71 (" in missing.words()
    assert "by weight" not in tr.TrueRobotCheck(500, 0, 0.9, 0.7, 0, 250, {"W_S S": 0.9}).words()


def test_a_destabilising_controller_is_counted_unstable_and_has_no_finite_figure():
    loop, task = loop_and_task(0.1)
    check = tr.true_robot_check(loop, task, pid(2.0, sign=-1.0), WEIGHTS, n=5)
    assert check.unstable == 5
    assert check.worst == float("inf")
    assert "5 UNSTABLE" in check.words()


def test_the_figure_says_whose_a_mu_above_one_is():
    """Unstable true robots: the controller's; true robots within the weights under a μ lower bound above 1: the
    model's; nothing to say when μ's lower bound is below 1 and the true robots meet the weights."""
    loop, task = loop_and_task(0.1)
    bad = tr.true_robot_check(loop, task, pid(2.0, sign=-1.0), WEIGHTS, n=5).to_dict()
    assert tr.share_of_mu(bad, 3.0).startswith("the controller fails true robots of the set too (5 of 5 unstable)")
    good = tr.true_robot_check(loop, task, pid(2.0), WEIGHTS, n=5).to_dict()
    assert good["worst"] < 1.0
    assert "a member of the uncertainty model that no drawn robot is" in tr.share_of_mu(good, 3.0)
    assert tr.share_of_mu(good, 0.9) is None and tr.share_of_mu(good, float("nan")) is None
    # both at once (ur5's PID tuned on true robots: 1.02 on the worst drawn robot, mu's lower bound 4.51)
    both = tr.share_of_mu({"worst": 1.02, "unstable": 0, "draws": 500}, 4.51)
    assert both.startswith("the controller fails true robots of the set too (worst weighted gain 1.02)")
    assert "beyond that, mu's lower bound 4.51 is above every one of the 500 true robots" in both


def test_tuning_lowers_the_worst_case_on_its_draws_and_is_checked_on_other_draws():
    loop, task = loop_and_task(0.1)
    start = pid(0.5)  # too slow for the weights' 0.5 rad/s bandwidth
    tuning = tr.tune_on_true_robots(loop, task, WEIGHTS, start, n=12, check_draws=30, max_iter=60)
    assert tuning.fitted_worst < 0.9 * tuning.start_worst
    assert tuning.check.draws == 30 and tuning.check.unstable == 0
    assert tuning.check.seed != tr.TUNING_SEED
    again = tr.true_robot_check(loop, task, tuning.controller, WEIGHTS, n=30)
    assert again.worst == pytest.approx(tuning.check.worst)  # the check is reproducible from its seed
    assert "tuned on 12 true robots" in tuning.words()


def test_a_loop_without_a_set_is_refused_in_one_line():
    robot = load_robot("planar_2r")
    loop = inner_loop(robot, "computed-torque")
    with pytest.raises(ArgumentError, match="robot-uncertainty set"):
        tr.true_robot_plants(loop, loop_and_task(0.0)[1], 3)


def test_true_robots_start_is_refused_in_the_bandwidth_search():
    from polyrob.pipeline.design import design_max_bandwidth, synthesis_options

    assert synthesis_options(init="true-robots")["initial_controller"] == "true-robots"
    assert synthesis_options(structure="ss:4", init="true-robots")["initial_controller"] == "true-robots"
    problem = SimpleNamespace(robot=SimpleNamespace(inner="computed-torque"))
    with pytest.raises(ArgumentError, match="--max-bandwidth"):
        design_max_bandwidth(problem, **synthesis_options(init="true-robots"))
    assert synthesis_options(init="true-robots+corners")["initial_controller"] == "true-robots+corners"
    with pytest.raises(ArgumentError, match="--max-bandwidth"):
        design_max_bandwidth(problem, **synthesis_options(init="true-robots+corners"))


def test_synth_and_analyze_say_the_true_robots_figure_on_a_set_and_nothing_without_one():
    from polyrob.cli.synth import true_robot_line

    lines = []
    out = SimpleNamespace(line=lines.append)
    loop, task = loop_and_task(0.1)
    problem = SimpleNamespace(robot=loop, domain=task, hyperparameters=WEIGHTS)
    design = SimpleNamespace(controller=pid(2.0), result=SimpleNamespace(info={}), reduced=None)
    doc = true_robot_line(problem, design, out)
    assert doc["draws"] == tr.CHECK_DRAWS and doc["unstable"] == 0 and np.isfinite(doc["worst"])
    assert lines == [doc["words"]] and lines[0].startswith("true robots: worst weighted gain")
    plain = SimpleNamespace(robot=inner_loop(load_robot("planar_2r"), "computed-torque"), domain=task, hyperparameters=WEIGHTS)
    assert true_robot_line(plain, design, out) is None and len(lines) == 1
    # a controller tuned on true robots brings its check along: said as it was, not drawn again
    tuned = SimpleNamespace(controller=pid(2.0), result=SimpleNamespace(info={"true_robots": doc}), reduced=None)
    assert true_robot_line(SimpleNamespace(robot=None), tuned, out) is doc and lines[-1] == doc["words"]


@pytest.mark.parametrize(
    "argv, words",
    [
        (("synth", "planar_2r", "--init", "true-robots"), "--robot-uncertainty FILE or --link-error P"),
        (("synth", "ur5", "--link-error", "10", "--init", "true-robots", "--max-bandwidth"), "--max-bandwidth"),
    ],
)
def test_synth_refuses_a_true_robots_start_it_cannot_make_before_any_work(capsys, argv, words):
    from polyrob.cli import main

    try:
        code = main(list(argv))
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    lines = [x for x in err.splitlines() if x.strip() and not x.startswith("progress")]
    assert code == 2 and out == ""
    assert len(lines) == 1 and words in lines[0] and "bounds" not in err


def test_a_state_space_structure_smaller_than_the_pid_is_refused_before_the_bounds(capsys):
    """panda's PID has 14 states: ss:12 from it stabilised none of the drawn robots, after minutes of work."""
    from polyrob.cli import main

    code = main(["synth", "panda", "--link-error", "10", "--init", "true-robots", "--structure", "ss:12"])
    err = capsys.readouterr().err
    last = [x for x in err.splitlines() if x.strip()][-1]
    assert code == 2 and "bounds" not in err
    assert last.endswith("the structure starts from the per-joint PID, 14 states on 7 joints; give --structure ss:14 or more")


def test_a_fixed_structure_is_tuned_on_true_robots_from_the_pid():
    loop, task = loop_and_task(0.1)
    start = pid(0.5)
    tuning = tr.tune_on_true_robots(loop, task, WEIGHTS, start, structure="ss:4", n=12, check_draws=30, max_iter=60)
    assert tuning.structure == "ss:4" and control.ss(tuning.controller).nstates == 4
    assert tuning.fitted_worst < 0.9 * tuning.start_worst and tuning.check.unstable == 0


def test_extreme_draws_sit_at_the_vertices_of_the_set_and_the_corners_of_the_task():
    from polyrob.uncertainty_set.draw import draw_true_robot
    from polyrob.uncertainty_set.links import link_names

    robot = load_robot("planar_2r")
    spec = RobotUncertainty.from_dict({"links": {"error_percent": 10},
                                       "payload": {"mass": [0.0, 1.0], "com_ball": {"centre": [0, 0, 0], "radius": 0.1},
                                                   "inertia": {"solid_sphere": 0.05}}})  # fmt: skip
    rng = np.random.default_rng(4)
    nominal = {name: robot.model.inertias[j].mass for name, j in link_names(robot).items()}
    for _ in range(10):
        true = draw_true_robot(robot, spec, rng, extreme=True)
        ratios = [true.link_parameters[name][0] / mass for name, mass in nominal.items()]
        np.testing.assert_allclose(np.abs(np.array(ratios) - 1.0), 0.1, rtol=1e-12)  # every mass factor at an end
        assert true.payload_mass in (0.0, 1.0)
        assert np.linalg.norm(true.payload_com) == pytest.approx(0.1)  # on the ball's surface
    # the check's second half: frozen at corners of the task
    loop, task = loop_and_task(0.1)
    plants = tr.true_robot_plants(loop, task, 8, seed=2, extremes=0.5)
    assert len(plants) == 8
    with pytest.raises(ArgumentError, match="share at vertices"):
        tr.true_robot_plants(loop, task, 8, extremes=1.5)


def test_vertices_of_ur5s_per_link_set_find_a_worse_frozen_loop_than_uniform_draws():
    # a PID tuned on uniform draws meets the weights on them; at the set's vertices and the task's corners it does not
    from pathlib import Path

    from polyrob.io.controller import load_controller, read_controller_file

    root = Path(__file__).resolve().parents[1]
    path = root / "benchmarks" / "controllers" / "ur5_per_link_true_robots.json"
    weights = {k: tuple(v) for k, v in read_controller_file(path)["info"]["weights"].items()}
    spec = RobotUncertainty.from_file(root / "examples" / "uncertainty" / "ur5.yaml")
    loop = inner_loop_of_set(load_robot("ur5"), "computed-torque", spec, draws=1)
    task = default_task_domain(loop)
    K = load_controller(path)
    inside = tr.true_robot_check(loop, task, K, weights, n=100, extremes=0.0)
    vertices = tr.true_robot_check(loop, task, K, weights, n=100, extremes=1.0)
    assert inside.worst < 1.2 < 1.5 < vertices.worst
    assert vertices.extremes == 100 and "100 at its vertices and the task's corners" in vertices.words()


class _StiffnessCorners:
    """A stand-in uncertainty model: two real parameters, each a joint stiffness of ±0.15 (1/s^2) no true robot has."""

    n_params = 2

    def delta_samples(self, n=None, *, kind="uniform", seed=None):
        assert kind == "corners" and n is None  # 2^2 corners: all of them
        return np.array([[-1.0, -1.0], [1.0, -1.0], [-1.0, 1.0], [1.0, 1.0]])

    def matrices_at(self, delta):
        A = np.zeros((4, 4))
        A[:2, 2:] = np.eye(2)
        A[2:, :2] = np.diag(0.15 * np.asarray(delta))
        return A, np.vstack([np.zeros((2, 2)), np.eye(2)])


def test_tuning_on_the_models_corners_too_makes_the_controller_robust_to_them():
    """``model=``: the model's corner plants join the true robots' (``--init true-robots+corners``); the tuned
    controller's worst over those corners is below the one tuned on true robots alone, and the words say so."""
    from polyrob.plant.weights import plant_weights
    from polyrob.synthesis.fixed.vertex import vertex_peak

    loop, task = loop_and_task(0.1)
    start, model = pid(0.5), _StiffnessCorners()
    alone = tr.tune_on_true_robots(loop, task, WEIGHTS, start, n=12, check_draws=30, max_iter=60)
    both = tr.tune_on_true_robots(loop, task, WEIGHTS, start, n=12, check_draws=30, max_iter=60, model=model)
    W = plant_weights(WEIGHTS)
    corners = [model.matrices_at(d) for d in model.delta_samples(kind="corners")]

    def on_corners(K):
        return vertex_peak(corners, K, W["W_S"], W["W_T"], W["W_KS"], omega=tr.check_omega(WEIGHTS))

    assert both.corners == 4 and alone.corners == 0
    assert on_corners(both.controller) < on_corners(alone.controller)
    assert both.fitted_worst >= on_corners(both.controller) * (1 - 1e-9)  # its figure includes the corners
    assert "and 4 corners of the uncertainty model" in both.words() and "corners" not in alone.words()
    assert both.check.unstable == 0
