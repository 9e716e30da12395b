"""Numbers a user can read: round-off printed as 0, no "unstable pole 1e-09", no "gamma nan", a named M."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest

from polyrob.analysis.limits import PerformanceLimit, pole_bound
from polyrob.bounds.pldi_result import PLDI
from polyrob.cli import main
from polyrob.pipeline.reports import format_matrix

#: A double integrator computed with round-off: its double pole at 0 splits into +-1.14e-9 rad/s.
ROUNDED_DOUBLE_INTEGRATOR = np.array([[0.0, 1.0], [1.3e-18, 0.0]])


def test_a_double_integrators_round_off_is_not_an_unstable_pole():
    assert np.linalg.eigvals(ROUNDED_DOUBLE_INTEGRATOR).real.max() == pytest.approx(1.14e-9, rel=0.01)
    bound, pole, direction = pole_bound(ROUNDED_DOUBLE_INTEGRATOR, 2.0, 1)
    assert (bound, pole, direction) == (0.0, None, None)
    from polyrob.analysis.limits import marginal_tolerance

    assert marginal_tolerance(ROUNDED_DOUBLE_INTEGRATOR) > 1.14e-9
    limit = PerformanceLimit(bound, pole, direction, None, None, None, points=1)
    assert "no unstable open-loop pole" in limit.summary() and "e-09" not in limit.summary()
    # a real unstable pole, as small as the scale allows, is still one
    bound, pole, _ = pole_bound(np.array([[0.0, 1.0], [1e-6, 0.0]]), 2.0, 1)
    assert bound == 2.0 and pole.real == pytest.approx(1e-3)


def test_round_off_entries_print_as_zero():
    assert format_matrix([[1.0, -1.944e-42], [1.9874e-16, 60.625]]) == "[     1      0]\n[     0 60.625]"
    fake = SimpleNamespace(
        entries=["A21", "B22"],
        lower=np.array([-5.0, 0.03]),
        upper=np.array([5.0, 0.2]),
        nominal=np.array([-1.944e-42, 0.1]),
        enclosure="sampled",
    )
    rows = PLDI.table(fake).splitlines()
    assert rows[1].split() == ["A21", "-5", "5", "0", "sampled"]
    assert rows[2].split() == ["B22", "0.03", "0.2", "0.1", "sampled"]
    from polyrob.report.numbers import zero_round_off

    assert zero_round_off([[2.0, -1e-13]]).tolist() == [[2.0, 0.0]]
    # a small but real entry (1e-6 of the scale) keeps its digits
    assert zero_round_off([[2.0, 1e-6]]).tolist() == [[2.0, 1e-6]]


def test_iteration_table_says_no_hinf_step_instead_of_gamma_nan():
    from polyrob.cli.synth import print_design

    result = SimpleNamespace(
        gamma_history=np.array([np.nan, 1.234567]),
        mu_history=[1.2, 0.95],
        structure="full order",
        order=8,
        peak_mu_lower=0.94,
        peak_mu=0.95,
        peak_frequency=3.0,
        iterations=2,
        seconds=1.0,
        certificate=None,
        info={},
    )
    lines = []
    print_design(SimpleNamespace(result=result, reduced=None, notes=()), SimpleNamespace(line=lines.append))
    text = "\n".join(lines)
    assert "nan" not in text
    assert lines[1].split()[:2] == ["1", "1.2"] and lines[1].endswith("no H-inf step")
    assert lines[2].split() == ["2", "0.95", "1.235"]
    assert "not made by an H-inf K-step" in text


def test_info_names_the_mass_matrix_it_prints(capsys):
    """panda's default task has a computed-torque inner layer: its M_hat^-1 M = I is named, the robot's M shown."""
    assert main(["info", "panda"]) == 0
    out = capsys.readouterr().out
    assert "M(q) of the robot (panda, the nominal robot; the physical mass matrix) =" in out
    assert "normalised mass matrix M_hat(q)^-1 M(q), the identity I for the nominal robot" in out
    block = out.split("M_hat(q)^-1 M(q), the identity")[1].splitlines()[1:8]
    assert [row.strip("[]").split() for row in block] == [["1" if i == j else "0" for j in range(7)] for i in range(7)]
    assert "e-1" not in out  # no round-off printed as a coupling
    assert main(["info", "panda", "--json"]) == 0
    neutral = json.loads(capsys.readouterr().out)["neutral"]
    robot_M = np.array(neutral["M_robot"])
    assert robot_M[1, 1] == pytest.approx(1.8017, abs=1e-4) and np.allclose(neutral["M"], np.eye(7), atol=1e-12)


def test_info_without_inner_layer_names_the_robots_mass_matrix(capsys):
    assert main(["info", "planar_2r"]) == 0
    out = capsys.readouterr().out
    assert "M(q) of the robot (planar_2r; the physical mass matrix) =\n[60.625 19.375]" in out
