"""PLDI bounds: the paper's intervals, coverage, witnesses, polytope, files."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import cached_robot

from polyrob import PLDI, Domain, bound_pldi
from polyrob.errors import BoundsError, CertificationError

PAPER_B = {"b31": (0.0286, 0.0312), "b32": (-0.0461, -0.0164), "b41": (-0.0461, -0.0164), "b42": (0.0848, 0.144)}
PAPER_A = {
    "a32": (-19.127, 19.6402),
    "a33": (-1.58, 1.58),
    "a34": (-3.56, 3.56),
    "a42": (-13.9637, 28.2362),
    "a43": (-5.42, 5.42),
    "a44": (-3.95, 3.95),
}


def printed_digits(x: float, like: float) -> float:
    """Round x to the number of decimals the paper prints for ``like``."""
    text = repr(like)
    decimals = len(text.split(".")[1]) if "." in text else 0
    return round(x, decimals)


@pytest.fixture(scope="module")
def planar():
    robot = cached_robot("planar_2r")
    return robot, bound_pldi(robot, Domain.from_robot(robot), coverage=10_000, progress=False)


def assert_paper_B(pldi):
    for name, (lo, hi) in PAPER_B.items():
        plo, phi = pldi.interval(name)
        assert (printed_digits(plo, lo), printed_digits(phi, hi)) == (lo, hi), name


def test_planar_2r_B_intervals_are_the_papers(planar):
    _, pldi = planar
    assert pldi.enclosure == "sampled"
    assert_paper_B(pldi)


def test_planar_2r_coverage_is_complete_on_10000_fresh_points(planar):
    _, pldi = planar
    assert pldi.coverage == 1.0 and pldi.coverage_points == 10_000


def test_planar_2r_drops_the_first_joint_angle(planar):
    assert planar[1].dropped_q == (0,)


def test_witnesses_attain_the_bounds(planar):
    robot, pldi = planar
    m = robot.m
    for wit, bound in ((pldi.witness_upper, pldi.upper), (pldi.witness_lower, pldi.lower)):
        A, B = robot.jacobians_batch(wit[:, :m], wit[:, m : 2 * m], wit[:, 2 * m :])
        vals = np.diagonal(pldi.entry_values(A, B))
        np.testing.assert_allclose(vals, bound, rtol=1e-12, atol=1e-15)
        assert pldi.domain.contains(wit[:, :m], wit[:, m : 2 * m], wit[:, 2 * m :]).all()


def test_nominal_is_the_equilibrium_and_midpoint_is_selectable(planar):
    robot, pldi = planar
    A, B = robot.jacobians([0, 0], [0, 0], [0, 0])
    np.testing.assert_array_equal(pldi.A0, A)
    assert pldi.nominal_point == {"q": [0.0, 0.0], "qdot": [0.0, 0.0], "u": [0.0, 0.0]}
    mid = bound_pldi(robot, pldi.domain, samples=64, coverage=0, nominal="midpoint", progress=False)
    np.testing.assert_allclose(mid.nominal, 0.5 * (mid.lower + mid.upper))


def test_polytope_is_smaller_than_the_box_and_holds_the_cloud(planar):
    robot, pldi = planar
    poly = pldi.polytope
    assert poly.n_halfspaces >= 2 * len(pldi.entries)
    assert 0 < poly.volume_ratio < 0.1  # the half-spaces cut most of the box away
    q, qdot, u = pldi.domain.sample(2000, method="uniform", seed=11)
    assert poly.contains(pldi.entry_values(*robot.jacobians_batch(q, qdot, u))).all()


def test_save_and_load_round_trip(planar, tmp_path):
    _, pldi = planar
    path, npz = pldi.save(tmp_path / "planar.json")
    meta = json.loads(path.read_text())
    assert meta["entries"][6]["name"] == "b31" and npz.exists()
    back = PLDI.load(path)
    np.testing.assert_array_equal(back.A_lower, pldi.A_lower)
    np.testing.assert_array_equal(back.polytope.normals, pldi.polytope.normals)
    assert back.entries == pldi.entries and back.domain.to_dict() == pldi.domain.to_dict()
    assert not list(tmp_path.glob(".*.tmp"))  # no temporary file left behind


def test_load_refuses_other_files(tmp_path):
    bad = tmp_path / "x.json"
    bad.write_text("{}")
    with pytest.raises(BoundsError, match="not a PLDI file"):
        PLDI.load(bad)


def test_paper_domain_reproduces_the_papers_intervals():
    """paper_2r (the printed Coriolis matrix) on --domain paper: within 1.5 % of each width."""
    robot = cached_robot("paper_2r")
    pldi = bound_pldi(robot, Domain.from_robot(robot, "paper"), coverage=1000, progress=False)
    for name, (lo, hi) in {**PAPER_A, **PAPER_B}.items():
        plo, phi = pldi.interval(name)
        assert max(abs(plo - lo), abs(phi - hi)) <= 0.015 * (hi - lo), name
    assert pldi.coverage == 1.0


@pytest.mark.slow  # 45-210 s on 2 cores (the screen near the witnesses varies): `pytest -m slow`
def test_ur5_coverage_is_complete_on_10000_fresh_points():
    robot = cached_robot("ur5")
    # a 512-point design: the local search and the screens, not the design, must find the extremes
    pldi = bound_pldi(robot, Domain.from_robot(robot), samples=512, coverage=10_000, progress=False)
    assert pldi.coverage == 1.0
    assert pldi.dropped_q == (0,)  # the base joint turns about gravity


def test_certified_planar_2r_contains_the_sampled_and_matches_the_paper():
    robot = cached_robot("planar_2r")
    pldi = bound_pldi(robot, Domain.from_robot(robot), certify=True, coverage=10_000, progress=False)
    assert pldi.enclosure == "certified"
    assert_paper_B(pldi)
    assert pldi.coverage == 1.0


def test_certify_refuses_a_seven_joint_robot():
    robot = cached_robot("panda")
    with pytest.raises(CertificationError, match="up to 3 joints"):
        bound_pldi(robot, Domain.from_robot(robot), samples=16, refine=False, coverage=0, certify=True, progress=False)


def test_certify_refuses_an_analytic_robot():
    robot = cached_robot("paper_2r")
    with pytest.raises(CertificationError, match="URDF robot"):
        bound_pldi(robot, samples=16, refine=False, coverage=0, certify=True, progress=False)


def test_cli_bounds_writes_the_pldi(tmp_path, capsys):
    from polyrob.cli import main

    out = tmp_path / "b.json"
    code = main(["bounds", "planar_2r", "--samples", "64", "--coverage", "500", "--quiet", "-o", str(out)])
    text = capsys.readouterr().out
    assert code == 0 and "b42" in text and "coverage: 1.0000 of 500" in text
    assert PLDI.load(out).interval("b31")[0] == pytest.approx(0.0285714, abs=1e-7)


def test_cli_bounds_certify_on_seven_joints_is_one_line(tmp_path, capsys):
    """panda keeps its default task under --certify (before: the URDF limits, then 'up to 3 joints'); one box of
    its whole task bounds no entry (M_hat is not proved invertible on it), which is one line naming the options
    (before: 'some entry could not be bounded'); a proof asked to complete that runs out of its counted work too."""
    from polyrob.cli import main

    out = tmp_path / "p.json"
    code = main(["bounds", "panda", "--certify", "--max-boxes", "1", "--quiet", "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and "proved factor ranges: 294 of 294 entries not bounded yet after 1 boxes" in err
    assert "M_hat is not proved invertible on the boxes where they are still open" in err
    assert err.count("\n") == 1 and "--max-boxes" in err and "max_boxes" not in err
    assert not out.exists() and not list(tmp_path.iterdir())  # nothing half-written
    code = main(
        ["bounds", "finger_edu", "--certify", "--max-boxes", "1", "--complete-proof", "--quiet", "-o", str(out)]
    )
    err = capsys.readouterr().err
    assert code == 2 and "proved factor ranges: the limit of 1 boxes" in err and err.count("\n") == 1
    assert "--max-boxes" in err and "--rel-tol" in err and "max_boxes" not in err
    assert not out.exists() and not list(tmp_path.iterdir())


def test_landscape_peaks_start_on_separate_hills():
    """Two hills of different heights: the peaks are both tops, the higher first."""
    from polyrob.bounds import search

    robot = cached_robot("planar_2r")
    problem = search.Problem(robot, Domain.from_robot(robot))
    lo, hi = problem.lo[1], problem.hi[1]
    q = np.zeros((201, 2))
    q[:, 1] = np.linspace(lo, hi, 201)
    x = (q[:, 1] - lo) / (hi - lo)
    vals = (np.exp(-(((x - 0.2) / 0.05) ** 2)) + 2 * np.exp(-(((x - 0.7) / 0.05) ** 2)))[:, None]
    peaks = search.landscape_peaks(problem, q, vals, 2)[0]
    np.testing.assert_allclose(x[peaks], [0.7, 0.2])
