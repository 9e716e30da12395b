"""The independent frozen check: its own Jacobians, weights and norm agree with polyrob's, and it can fail.

The controller ``tests/fixtures/planar_2r_ct_pid_K.json`` is ``polyrob synth planar_2r --inner
computed-torque --model-error 10 --pose 0.4,0.3 --q-radius 0.3 --qdot-max 0.5 --qddot-max 2
--structure pid`` (CERTIFIED, mu <= 0.677).
"""

from __future__ import annotations

from pathlib import Path

import control
import numpy as np
import pytest

from polyrob import load_robot
from polyrob.domains.task import TaskDomain
from polyrob.io.controller import load_controller
from polyrob.model.inner import inner_loop
from polyrob.plant.weights import paper_weights
from polyrob.uncertainty_set.draw import draw_true_robots
from polyrob.uncertainty_set.spec import RobotUncertainty
from polyrob.validate.independent import frozen_check, frozen_jacobians, weights_from_hyperparameters

FIXTURE = Path(__file__).parent / "fixtures" / "planar_2r_ct_pid_K.json"
HYPER = {"omega_b": (0.5, 0.1), "M_s": (2.0, 3.0), "A_s": (0.01, 0.02), "omega_bt": (10.0, 12.0), "M_t": (2.1, 3.0)}
HYPER["A_t"] = (0.01, 0.01)


def test_the_check_reproduces_the_certificates_nominal_weighted_norm():
    from polyrob.analysis.robust import nominal_performance
    from polyrob.pipeline import build_problem

    arm = inner_loop(load_robot("planar_2r"), "computed-torque", model_error=0.1)
    dom = TaskDomain.from_robot(arm, pose=[0.4, 0.3], q_radius=0.3, qdot_max=0.5, qddot_max=2.0)
    # the nominal plant does not depend on the search's effort: the cheapest bounds give the same P's nominal
    cheap = {"samples": 32, "coverage": 0, "refine": 0, "verify_rounds": 0, "screen": 0, "workers": 1}
    problem = build_problem(arm, dom, progress=False, bound_options={**cheap, "describe_polytope": False})
    polyrobs = nominal_performance(problem.P, load_controller(FIXTURE))
    check = frozen_check(FIXTURE, RobotUncertainty(link_error=0.0), nominal_only=True, at_pose=True)
    (own,) = check.weighted_norm
    assert abs(own - polyrobs) <= 1e-6
    assert own <= polyrobs  # polyrob quotes AB13DD's peak raised by its tolerance: a bound from above
    assert check.unstable == 0 and check.bound == pytest.approx(0.6773241094692622)


def test_its_jacobians_are_polyrobs_on_a_drawn_robot():
    robot = load_robot("planar_2r")
    arm = inner_loop(robot, "computed-torque", model_error=0.1)
    (true,) = draw_true_robots(robot, RobotUncertainty(link_error=0.1), 1, seed=5)
    q, qdot, qddot = np.array([0.5, 0.2]), np.array([0.3, -0.4]), np.array([1.5, -1.0])
    A, B, v = frozen_jacobians(true.model, true.viscous, robot.model, robot.damping, "computed-torque", q, qdot, qddot)
    from dataclasses import replace

    theirs = replace(arm, true_robot=true.robot, _scenarios=())
    assert np.allclose(theirs.acceleration(q, qdot, v), qddot, atol=1e-10)  # v gives the point's qddot
    A2, B2 = theirs.jacobians_batch(q[None], qdot[None], v[None])
    assert np.allclose(A, A2[0], atol=1e-9) and np.allclose(B, B2[0], atol=1e-12)
    assert not np.allclose(A[2:, :2], 0.0, atol=1e-6)  # the drawn links are not the model's: residual stiffness


def test_its_weights_are_the_papers():
    (As, Bs, Cs, Ds), (At, Bt, Ct, Dt) = weights_from_hyperparameters(HYPER, 2)
    WS, WT = paper_weights(HYPER)
    for w in (0.01, 0.3, 7.0, 300.0):
        s = 1j * w
        own_s = Cs @ np.linalg.solve(s * np.eye(2) - As, Bs) + Ds
        own_t = Ct @ np.linalg.solve(s * np.eye(2) - At, Bt) + Dt
        assert np.allclose(own_s, WS(s), rtol=1e-12) and np.allclose(own_t, WT(s), rtol=1e-12)


def test_the_check_flags_an_unstable_loop():
    K = control.ss(load_controller(FIXTURE))
    flipped = control.ss(K.A, K.B, -K.C, -K.D)  # positive feedback
    bad = frozen_check(FIXTURE, RobotUncertainty(link_error=0.1), n=10, controller=flipped)
    doc = bad.summary()
    assert doc["unstable"] == 10 and doc["worst_pole_real"] > 0
    assert doc["every_loop_stable_and_below_bound"] is False
    good = frozen_check(FIXTURE, RobotUncertainty(), n=50, points=2, common_factor=0.1).summary()  # its set
    assert good["loops"] == 100 and good["unstable"] == 0
    assert good["weighted_norm_worst"] < good["bound"] and good["every_loop_stable_and_below_bound"]


def test_on_the_certified_set_every_loop_is_below_the_bound_and_the_per_link_set_is_another():
    """The fixture is certified for one factor on both links within ±10 %: drawn from that set (half at its
    ends, at the task's corners), every frozen loop stays below mu's bound (the certificate's promise); drawn
    per link at ±30 %, some do not, and per link at ±10 % the robots at the set's vertices do not either,
    though those drawn inside it do: the per-link set is another set, and uniform draws miss its worst."""
    own = frozen_check(FIXTURE, RobotUncertainty(), n=100, common_factor=0.1).summary()
    assert own["unstable"] == 0 and own["above_bound"] == 0 and own["weighted_norm_worst"] < own["bound"]
    assert "50 of 100 at vertices of the set" in own["uncertainty"]
    wider = frozen_check(FIXTURE, RobotUncertainty(link_error=0.3), n=100, points=2).summary()
    assert wider["above_bound"] > 0 and not wider["every_loop_stable_and_below_bound"]
    inside = frozen_check(FIXTURE, RobotUncertainty(link_error=0.1), n=100, points=2, extremes=0.0).summary()
    vertices = frozen_check(FIXTURE, RobotUncertainty(link_error=0.1), n=100, points=2, extremes=1.0).summary()
    assert inside["above_bound"] == 0 and vertices["above_bound"] > 0
    assert vertices["weighted_norm_worst"] > inside["weighted_norm_worst"]


def _with_limit_weights(tmp_path, effort=(1.3, 0.9), noise=(1.2e-5, 1.2e-5)):
    import json

    doc = json.loads(FIXTURE.read_text(encoding="utf-8"))
    doc["info"]["weights"].update({"effort": list(effort), "noise": list(noise)})
    path = tmp_path / "K.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
    return path, doc["info"]["weights"]


def test_a_file_with_limit_weights_is_checked_with_its_effort_weight_as_polyrob_states_it(tmp_path):
    """The limit weights are rebuilt from their formula: the check's frozen loop is polyrob's generalized plant
    with ``W_KS = W_u max(W_n)`` on the outer input closed with the controller (its nominal norm to AB13DD's
    tolerance), and at every frequency its gain is that of ``[W_S S; W_T T; W_KS K S]`` computed from the
    transfer matrices; ``paper_block`` leaves the effort rows out (a lower bound, said)."""
    from polyrob.analysis.robust import nominal_performance
    from polyrob.pipeline import build_problem
    from polyrob.plant.generalized import generalized_plant
    from polyrob.plant.weights import plant_weights

    path, weights = _with_limit_weights(tmp_path, effort=(600.0, 400.0))  # W_KS 7e-3, 5e-3: the norm doubles
    full = frozen_check(path, RobotUncertainty(link_error=0.0), nominal_only=True, at_pose=True)
    plain = frozen_check(FIXTURE, RobotUncertainty(link_error=0.0), nominal_only=True, at_pose=True)
    block = frozen_check(path, RobotUncertainty(link_error=0.0), nominal_only=True, at_pose=True, paper_block=True)
    assert block.weighted_norm[0] == pytest.approx(plain.weighted_norm[0], rel=1e-12)  # the same W_S/W_T loop
    assert full.weighted_norm[0] > plain.weighted_norm[0] * 1.01  # the effort rows add to the norm
    assert "W_KS u" in full.summary()["weights_rebuilt"] and "weighted_norm_of" not in full.summary()

    arm = inner_loop(load_robot("planar_2r"), "computed-torque", model_error=0.1)
    dom = TaskDomain.from_robot(arm, pose=[0.4, 0.3], q_radius=0.3, qdot_max=0.5, qddot_max=2.0)
    cheap = {"samples": 32, "coverage": 0, "refine": 0, "verify_rounds": 0, "screen": 0, "workers": 1}
    problem = build_problem(arm, dom, progress=False, bound_options={**cheap, "describe_polytope": False})
    hp = {k: tuple(v) for k, v in weights.items()}
    P = generalized_plant(problem.unc, **plant_weights(hp))
    assert full.weighted_norm[0] == pytest.approx(nominal_performance(P, load_controller(path)), rel=1e-6)

    # by hand: the nominal loop at the pose is the double integrator behind computed torque
    K = control.ss(load_controller(path))
    WS, WT = paper_weights(hp)
    W_KS = np.diag(np.asarray(weights["effort"]) * max(weights["noise"]))
    for w in (0.05, 1.0, 20.0):
        s = 1j * w
        G = np.eye(2) / s**2
        Ks = K(s)
        S = np.linalg.inv(np.eye(2) + G @ Ks)
        stacked = np.vstack([WS(s) @ S, WT(s) @ G @ Ks @ S, W_KS @ Ks @ S])
        top = np.linalg.svd(stacked, compute_uv=False)[0]
        assert top <= full.weighted_norm[0] * (1 + 1e-6)
        assert np.linalg.svd(stacked[:4], compute_uv=False)[0] <= top


def test_a_file_whose_weights_the_check_cannot_rebuild_is_refused(tmp_path):
    import json

    from polyrob.errors import ArgumentError

    doc = json.loads(FIXTURE.read_text(encoding="utf-8"))
    doc["info"]["weights"]["friction"] = [0.1, 0.1]
    path = tmp_path / "K.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
    with pytest.raises(ArgumentError, match="check that controller another way"):
        frozen_check(path, RobotUncertainty(link_error=0.0), nominal_only=True, at_pose=True)
    only_effort, _ = _with_limit_weights(tmp_path)
    doc = json.loads(only_effort.read_text(encoding="utf-8"))
    del doc["info"]["weights"]["noise"]
    only_effort.write_text(json.dumps(doc), encoding="utf-8")
    with pytest.raises(ArgumentError, match="need both"):
        frozen_check(only_effort, RobotUncertainty(link_error=0.0), nominal_only=True, at_pose=True)
