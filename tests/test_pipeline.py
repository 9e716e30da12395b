"""polyrob.pipeline: one problem builder, one verdict, controller files compared with their problem."""

from __future__ import annotations

import dataclasses

import pytest
from conftest import cached_robot, paper_pldi

from polyrob.errors import ArgumentError, ControllerFileError, DomainError, PolyrobError
from polyrob.pipeline import (
    build_problem,
    check_controller_problem,
    controller_differences,
    default_hyperparameters,
    make_uncertain_plant,
    verdict,
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
    other = dict(info, uncertainty={"model": "lft", "merge_symmetric": False})
    assert "--uncertainty lft" in controller_differences(other, problem)[0]
    dom = dict(info["domain"], u={"joint1": [-5.0, 5.0], "joint2": info["domain"]["u"]["joint2"]})
    diffs = controller_differences(dict(info, domain=dom), problem)
    assert any("--u-max=joint1=-5:5" in d for d in diffs)
    with pytest.raises(ControllerFileError, match="robot 'planar_2r'"):
        check_controller_problem(dict(info, robot="planar_2r"), problem, "K.json")


@pytest.mark.parametrize(
    "upper, lower, stable, word",
    [
        (0.9, 0.85, True, "CERTIFIED"),
        (2.227, 2.226, True, "VIOLATED"),
        (1.2, 0.9, True, "NOT certified"),
        (0.5, 0.4, False, "NOT certified"),
    ],
)
def test_verdict_certifies_only_below_one_on_a_stable_loop(upper, lower, stable, word):
    line = verdict(upper, lower, nominally_stable=stable, covers="the box")
    assert line.startswith("verdict: ") and word in line
    assert ("CERTIFIED" in line) == (upper < 1 and stable)
    if word != "CERTIFIED":
        assert "try" in line  # what to do next


def test_verdict_does_not_certify_when_the_analysis_says_why_not():
    line = verdict(0.8, 0.7, covers="the box", failed=("lft(P, K) at Delta = 0 not proved stable (unstable)",))
    assert "NOT certified" in line and "CERTIFIED" not in line and "Delta = 0" in line


def test_verdict_names_the_bound_between_grid_points():
    """mu < 1 on the grid certifies only if the bound checked between the points stays below 1 too."""
    everywhere = verdict(0.9, 0.85, covers="the box", everywhere=0.91)
    assert "CERTIFIED" in everywhere and "0.91 < 1 at every frequency" in everywhere
    between = verdict(0.9, 0.85, covers="the box", everywhere=1.2)
    assert "NOT certified" in between and "CERTIFIED" not in between and "up to 1.2 between its points" in between
    assert "on the frequency grid" in verdict(0.9, 0.85, covers="the box")  # not checked: says so
