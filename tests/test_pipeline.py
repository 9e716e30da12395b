"""polyrob.pipeline: one problem builder, one decision (decide_mu), controller files compared with their problem."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import pytest
from conftest import cached_robot, paper_pldi

from polyrob.analysis.certificate import Status, decide_mu
from polyrob.errors import ArgumentError, ControllerFileError, DomainError, PolyrobError
from polyrob.pipeline import (
    build_problem,
    check_controller_problem,
    controller_differences,
    default_hyperparameters,
    make_uncertain_plant,
)


@pytest.fixture(scope="module")
def problem():
    return build_problem(cached_robot("paper_2r"), pldi=paper_pldi(), uncertainty="box")


def test_default_hyperparameters_are_the_papers_per_channel():
    h = default_hyperparameters(2)
    assert h["omega_b"] == (0.5, 0.1) and h["M_t"] == (2.1, 3.0)
    # another joint count: the paper's first channel repeated
    assert default_hyperparameters(3)["M_s"] == (2.0, 2.0, 2.0)
    assert default_hyperparameters(2, {"A_s": [0.05]}, bandwidth_scale=2.0)["A_s"] == (0.05, 0.05)
    assert default_hyperparameters(2, bandwidth_scale=2.0)["omega_bt"] == (20.0, 24.0)


def test_wrong_weights_are_argument_errors_not_domain_errors():
    with pytest.raises(ArgumentError, match="give 1 or 2 values.*got 3") as info:
        default_hyperparameters(2, {"M_s": [1, 2, 3]})
    assert isinstance(info.value, ValueError) and isinstance(info.value, PolyrobError)
    assert not isinstance(info.value, DomainError)
    with pytest.raises(ArgumentError, match="unknown weight"):
        default_hyperparameters(2, {"Ms": [1]})


def test_init_starts_from_the_papers_controller_or_a_controller_file(tmp_path):
    """--init FILE: a synthesis warm-started from a controller designed elsewhere (e.g. another bandwidth)."""
    import numpy as np

    from polyrob.io.controller import save_controller
    from polyrob.pipeline import synthesis_options
    from polyrob.plant.generalized import paper_controller

    assert synthesis_options(structure="tf3", init="paper")["init"] == "paper"
    with pytest.raises(ArgumentError, match="fixed structure"):
        synthesis_options(structure="full", init="paper")
    path = save_controller(paper_controller(), tmp_path / "K0.json")
    for structure in ("full", "tf3"):
        K0 = synthesis_options(structure=structure, init=str(path))["initial_controller"]
        w = 1j * np.logspace(-2, 2, 7)
        assert np.allclose(K0(w[3]), paper_controller()(w[3]))
    with pytest.raises(ControllerFileError, match="no such controller file"):
        synthesis_options(structure="tf3", init=str(tmp_path / "missing.json"))


def test_build_problem_matches_the_stage_functions(problem):
    """The pipeline gives the same generalized plant as the three calls it replaces."""
    import numpy as np

    from polyrob.plant.generalized import generalized_plant
    from polyrob.plant.uncertainty import uncertain_plant
    from polyrob.plant.weights import paper_weights

    P = generalized_plant(uncertain_plant(paper_pldi(), model="box"), *paper_weights())
    assert problem.unc.n_params == 10 and problem.model == "box"
    np.testing.assert_allclose(problem.P.system.A, P.system.A)
    np.testing.assert_allclose(problem.P.system.D, P.system.D)
    d = problem.description()
    assert d["robot"] == "paper_2r" and d["domain"]["name"] == "paper"
    assert d["weights"]["omega_b"] == [0.5, 0.1] and d["uncertainty"]["model"] == "box"


def test_pldi_of_another_robot_is_refused_by_name():
    other = dataclasses.replace(paper_pldi(), robot_name="ur5")
    with pytest.raises(ArgumentError, match="robot 'ur5'.*not 'paper_2r'"):
        build_problem(cached_robot("paper_2r"), pldi=other)


def test_unknown_uncertainty_model():
    with pytest.raises(ArgumentError, match="unknown uncertainty model"):
        make_uncertain_plant(paper_pldi(), "ellipsoid")


def test_controller_problem_differences_name_the_options(problem):
    info = problem.description()
    assert check_controller_problem(info, problem) == []
    other = dict(info, weights=dict(info["weights"], omega_b=[1.0, 0.2]))
    (diff,) = controller_differences(other, problem)
    assert "omega_b" in diff and "--wb 1,0.2" in diff
    # a computed weight (the effort weight from the task's torques) is named to every digit it has, so the
    # option the message gives reproduces it (six digits did not: "effort = 1.3341 (given 1.3341)")
    effort = [1.3341049827418956, 0.055602604851169295]
    (diff,) = controller_differences(dict(info, weights={"effort": effort}), {"weights": {"effort": [1.3341, 0.0556]}})
    option = diff.split("--effort-weight ")[1].rstrip(")")
    assert [float(v) for v in option.split(",")] == effort
    other = dict(info, uncertainty={"model": "lft", "merge_symmetric": False})
    assert "--uncertainty lft" in controller_differences(other, problem)[0]
    dom = dict(info["domain"], u={"joint1": [-5.0, 5.0], "joint2": info["domain"]["u"]["joint2"]})
    diffs = controller_differences(dict(info, domain=dom), problem)
    assert any("--u-max=joint1=5" in d for d in diffs)
    with pytest.raises(ControllerFileError, match="robot 'planar_2r'"):
        check_controller_problem(dict(info, robot="planar_2r"), problem, "K.json")


def test_task_domain_without_torque_box_matches_itself():
    """A task domain has no torque box (u None on both sides) and is compared on its accelerations."""
    joints = ["j1", "j2"]
    task = {"joints": joints, "kind": "task", "q": {j: [-0.2, 0.2] for j in joints},
            "qdot": {j: [-0.5, 0.5] for j in joints}, "qddot": {j: [-2.0, 2.0] for j in joints}}  # fmt: skip
    info = {"robot": "r", "domain": task}
    assert controller_differences(info, {"robot": "r", "domain": dict(task)}) == []
    faster = dict(task, qddot={"j1": [-4.0, 4.0], "j2": [-2.0, 2.0]})
    (diff,) = controller_differences(info, {"robot": "r", "domain": faster})
    assert "--qddot-max=j1=2" in diff


STABLE = SimpleNamespace(stable=True, unstable=False, verdict="stable")
UNSTABLE = SimpleNamespace(stable=False, unstable=True, verdict="unstable")
UNDECIDED = SimpleNamespace(stable=False, unstable=False, verdict="undecided (eigenvalues within error of the axis)")


def between(holds, level=float("nan"), peak_upper=0.9, failed_at=None, reason=""):
    """A stand-in for the check between grid points (polyrob.analysis.mu.between)."""
    return SimpleNamespace(holds=holds, level=level, peak_upper=peak_upper, failed_at=failed_at, reason=reason)


PROVED = between(True, level=0.91)


@pytest.mark.parametrize(
    "stability, upper, lower, check, status",
    [
        # below one on a stable loop: CERTIFIED only when proved between the grid points
        (STABLE, 0.9, 0.85, PROVED, Status.CERTIFIED),
        (STABLE, 0.9, 0.85, None, Status.GRID_ONLY),  # not checked
        (STABLE, 0.9, 0.85, between(False, reason="gave up after 200 intervals"), Status.GRID_ONLY),
        # a member of the set breaks it
        (STABLE, 2.227, 2.226, None, Status.VIOLATED),
        (STABLE, 1.2, 1.0, None, Status.VIOLATED),
        # the loop at Delta = 0 (a member of the set) is unstable: nothing below one saves it
        (UNSTABLE, 0.5, 0.4, PROVED, Status.VIOLATED),
        (UNSTABLE, 2.227, 2.226, None, Status.VIOLATED),
        # stability undecided (or not checked): neither proved nor disproved, even with mu < 1 everywhere
        (UNDECIDED, 0.5, 0.4, PROVED, Status.NOT_CERTIFIED),
        (None, 0.5, 0.4, PROVED, Status.NOT_CERTIFIED),
        # mu straddles one on the grid
        (STABLE, 1.2, 0.9, None, Status.NOT_CERTIFIED),
        # mu < 1 at the grid points, >= 1 between them
        (STABLE, 0.9, 0.85, between(True, level=1.2), Status.NOT_CERTIFIED),
        (STABLE, 0.9, 0.85, between(False, peak_upper=1.3, failed_at=7.7, reason="1.3 at 7.7"), Status.NOT_CERTIFIED),
    ],
)
def test_decide_mu_certifies_only_below_one_everywhere_on_a_stable_loop(stability, upper, lower, check, status):
    got, reasons = decide_mu(stability, upper, lower, check)
    assert got is status
    # a status other than CERTIFIED always says why; CERTIFIED needs no excuse
    assert (reasons == ()) == (status is Status.CERTIFIED)
    assert all(isinstance(r, str) and r and "\n" not in r for r in reasons)


def test_decide_mu_reasons_name_what_is_missing():
    _, (why,) = decide_mu(STABLE, 0.9, 0.85, between(False, reason="gave up after 200 intervals"))
    assert "between the grid points" in why and "gave up after 200 intervals" in why
    _, (why,) = decide_mu(STABLE, 0.9, 0.85, None)
    assert "not checked" in why
    _, (why,) = decide_mu(STABLE, 0.9, 0.85, between(True, level=1.2))
    assert "1.2" in why and "between the points" in why
    _, (why,) = decide_mu(STABLE, 2.227, 2.226, None)
    assert "2.226 >= 1" in why
    _, (why,) = decide_mu(UNSTABLE, 0.5, 0.4, PROVED)
    assert "Delta = 0" in why and "unstable" in why
    _, reasons = decide_mu(UNDECIDED, 0.5, 0.4, PROVED)
    assert "not proved stable" in reasons[0] and "undecided" in reasons[0]


def _certificate(status: Status, reasons=()):
    from polyrob.analysis.certificate import Certificate, Scope

    sweep = SimpleNamespace(between=None)  # a mu certificate (not an L2 gain)
    return Certificate(status, 0.9, 0.9, 0.85, STABLE, Scope(model="box", robot="paper_2r"), tuple(reasons), sweep)


#: decide_mu's inputs that give each status
CASES = {
    Status.CERTIFIED: (STABLE, 0.9, 0.85, PROVED),
    Status.GRID_ONLY: (STABLE, 0.9, 0.85, None),
    Status.NOT_CERTIFIED: (UNDECIDED, 0.9, 0.85, PROVED),
    Status.VIOLATED: (UNSTABLE, 0.9, 0.85, PROVED),
}


@pytest.mark.parametrize("status", list(Status))
def test_the_analysis_verdict_and_summary_read_the_one_certificate(status):
    """ControllerAnalysis: its verdict, status and "certified" are the robust-performance certificate's."""
    import numpy as np

    from polyrob.pipeline import ControllerAnalysis

    got, reasons = decide_mu(*CASES[status])
    assert got is status
    cert = _certificate(status, reasons)
    rp = SimpleNamespace(certificate=cert, summary=lambda: {"certificate": cert.summary()})
    rs = SimpleNamespace(nominally_stable=True, summary=lambda: {})
    sampling = SimpleNamespace(
        random=1, random_stable=1.0, corners=1, corners_stable=1.0, worst_delta=np.zeros(1), worst_abscissa=-1.0
    )
    a = ControllerAnalysis(rs, rp, 0.5, sampling, 3, cert.scope.sentence())
    assert a.certificate is cert and a.verdict == "verdict: " + cert.verdict
    doc = a.summary()
    assert doc["status"] == status.value and doc["certified"] is (status is Status.CERTIFIED)
    assert doc["verdict"] == a.verdict
    # the word CERTIFIED is printed only for that status (NOT_CERTIFIED reads "NOT certified")
    assert ("CERTIFIED" in a.verdict) == (status is Status.CERTIFIED)
    assert "CERTIFIED" not in cert.details() or status is Status.CERTIFIED


def test_a_certificate_is_reused_only_for_its_own_loop_on_its_own_grid(problem):
    """The batch hands the design's certificate to the analysis; it is decided again (same figures, the
    problem's scope) only when it is of the same closed loop on the loop's own grid, else swept anew."""
    import numpy as np

    from polyrob.analysis.certificate import certify_loop
    from polyrob.pipeline.analysis import reusable_certificate
    from polyrob.plant.generalized import paper_controller

    P, K = problem.P, paper_controller()
    own = certify_loop(P, K, scope=problem.scope())
    again = reusable_certificate(own, P, K, problem.scope())
    assert again is not None and again.status is own.status and again.bound == own.bound
    assert again.scope.sentence() == own.scope.sentence() and again.mu is own.mu  # no new sweep
    assert reusable_certificate(own, P, 1.01 * K, problem.scope()) is None  # another controller
    on_a_grid = certify_loop(P, K, None, np.logspace(-1, 2, 7), scope=problem.scope())
    assert reusable_certificate(on_a_grid, P, K, problem.scope()) is None  # not the loop's own grid
    assert reusable_certificate(None, P, K, problem.scope()) is None
