"""The moving robot's LMIs proved between the grid points, by cells (polyrob.analysis.lpv.cells)."""

from types import SimpleNamespace

import numpy as np
import pytest
from test_moving_robot import pd_controller

import polyrob
from polyrob.analysis.lpv.cells import CellCheck, check_cells
from polyrob.analysis.lpv.check import GridData, brl_matrices
from polyrob.analysis.lpv.moving import _search, moving_robot_certificate
from polyrob.analysis.lpv.robot import closed_loop_system, kinematic_rates, rate_bounds, scheduling
from polyrob.domains.torque_box import Domain
from polyrob.workers import available_cores


@pytest.fixture(scope="module")
def tiny(robot):
    """The paper's domain shrunk to q2 in +-0.05 and 1 % of its velocities: a loop that barely varies."""
    d = Domain.from_robot(robot, "paper")  # the analytic 2R: its Jacobians have guaranteed enclosures
    return d.with_bounds(q_lower=np.full(2, -0.05), q_upper=np.full(2, 0.05), qdot_lower=d.qdot_lower * 0.01,
                         qdot_upper=d.qdot_upper * 0.01)  # fmt: skip


@pytest.fixture(scope="module")
def searched(robot, tiny):
    """``X(rho)`` at level 1.2 (margin maximised) on a 3 x 2 x 2 grid, accelerations bounded by twice the sampled peak."""
    model = scheduling(robot, tiny, points=(3, 2))
    system = closed_loop_system(model, pd_controller(), 0.5 * np.eye(2), None)
    rates, _ = rate_bounds(model, tiny, scale=1.0)
    rates = [(2 * lo, 2 * hi) if k == "qdot" else (lo, hi) for (lo, hi), k in zip(rates, model.kinds)]
    r, sysf, c, basis, used = _search(model, system, rates, quadratic=False, velocities="bounded", tensor=True,
                                      level=1.2)  # fmt: skip
    assert r.proved and r.gamma < 1.2
    return model, system, r, sysf, c, basis, used


@pytest.fixture(scope="module")
def robot():
    return polyrob.load_robot("paper_2r")


def _check(searched, gamma, **kw):
    model, system, r, sysf, c, basis, used = searched
    kw.setdefault("workers", 1)  # one process: tests/test_cells_parallel.py compares it with workers
    return check_cells(model, system, r.X, basis, kw.pop("rates", used), gamma, similarity=sysf.similarity, c=c,
                       **kw)  # fmt: skip


def test_the_lmis_are_proved_on_cells_covering_the_box_and_hold_at_random_points(searched):
    chk = _check(searched, 1.2)
    assert chk.holds, chk.reason
    assert chk.n_cells >= 4 and chk.smallest_margin > 0
    # soundness: the same X, evaluated at random points of the box (none of them grid points), passes
    model, system, r, sysf, c, basis, used = searched
    rng = np.random.default_rng(0)
    lo, hi = np.array([a[0] for a in model.axes]), np.array([a[-1] for a in model.axes])
    rates_at = kinematic_rates(model, used, c)
    for rho in rng.uniform(lo, hi, size=(200, 3)):
        A, B, C, D = sysf(rho)
        rc = np.array(rates_at(rho))
        nus = np.array(np.meshgrid(*[np.unique(x) for x in rc], indexing="ij")).reshape(3, -1).T
        F = np.array([[f(rho) for f, _ in basis]])
        G = np.array([[g(rho) for _, g in basis]])
        M, err, X, _ = brl_matrices(GridData(A[None], B[None], C[None], D[None], F, G, nus[None], rho[None]),
                                    np.asarray(r.X), 1.2)  # fmt: skip
        assert np.linalg.eigvalsh(M[0])[:, -1].max() < 0 and np.linalg.eigvalsh(X[0])[0] > 0


def test_a_level_below_the_proved_one_is_refused_at_a_cell_centre(searched):
    chk = _check(searched, 0.5 * searched[2].gamma)
    assert not chk.holds and "a cell's centre" in chk.reason


def test_a_sampled_acceleration_bound_below_the_robot_s_peak_is_caught(searched, robot):
    # on this box the sampled peak x 1.05 misses the robot's largest |qddot1| (at qdot1 = 0, |q2|, |qdot2| maximal)
    model, *_ = searched
    sampled, _ = rate_bounds(model, Domain.from_robot(robot, "paper").with_bounds(
        q_lower=np.full(2, -0.05), q_upper=np.full(2, 0.05), qdot_lower=model.axes[1][0] * np.array([1, 0]) +
        model.axes[2][0] * np.array([0, 1]), qdot_upper=model.axes[1][-1] * np.array([1, 0]) +
        model.axes[2][-1] * np.array([0, 1])))  # fmt: skip
    peak = abs(robot.acceleration([0.0, -0.05], [0.0, model.axes[2][-1]], [0.0, 0.0])[0])
    assert sampled[1][1] < peak  # the sampled bound is not a bound
    chk = _check(searched, 1.2, rates=sampled, max_cells=300)
    assert not chk.holds and "accelerations" in chk.reason


def test_the_certificate_with_cells_is_certified_and_says_what_it_covers(robot, tiny):
    problem = SimpleNamespace(robot=robot, domain=tiny, P=SimpleNamespace(W_S=0.4 * np.eye(2), W_T=None, W_KS=None))
    model = scheduling(robot, tiny, points=(3, 2))
    rates, _ = rate_bounds(model, tiny)
    qddot_max = [2 * rates[1][1], 2 * rates[2][1]]
    # three points per velocity: with two, X's slope in each velocity is free between them, and the structured
    # solver's X (same margin as Clarabel's) fails the finer grid at 2.59 where Clarabel's held at 0.80
    c = moving_robot_certificate(problem, pd_controller(), points=(3, 3), velocities="bounded", qddot_max=qddot_max,
                                 level=0.9, cells=True)  # fmt: skip
    assert c.cells["holds"], c.cells
    assert c.cells["workers"] == available_cores()  # the default reaches check_cells: every core
    cert = c.certificate
    assert cert.status.value == "CERTIFIED" and cert.bound == pytest.approx(0.9)
    assert "cells covering the whole box" in " ".join(cert.scope.notes)
    assert "between the grid points: proved at level 0.9" in c.details()
    plain = moving_robot_certificate(problem, pd_controller(), points=(3, 3), velocities="bounded",
                                     qddot_max=qddot_max, level=0.9)  # fmt: skip
    assert plain.certificate.status.value == "GRID_ONLY" and not plain.cells


def test_cell_check_words():
    assert "not proved between" in CellCheck(False, 1.0, 0, -1.0, (), "why", 0.0).words()


def test_the_half_box_of_an_even_loop_gives_the_same_verdict_with_half_the_points(robot, tiny):
    from polyrob.analysis.lpv.robot import even_half
    from polyrob.errors import NotApplicable

    problem = SimpleNamespace(robot=robot, domain=tiny, P=SimpleNamespace(W_S=0.4 * np.eye(2), W_T=None, W_KS=None))
    model = scheduling(robot, tiny, points=(5, 2))
    system = closed_loop_system(model, pd_controller(), 0.4 * np.eye(2), None)
    half = even_half(model, system)
    assert half.mirrored and half.n_points * 5 == model.n_points * 3 and half.axes[0][0] == 0.0
    assert "the other half by rho -> -rho" in half.words()
    rates, _ = rate_bounds(model, tiny)
    qddot_max = [2 * rates[1][1], 2 * rates[2][1]]
    c = moving_robot_certificate(problem, pd_controller(), points=(5, 2), velocities="bounded", qddot_max=qddot_max,
                                 level=0.9, cells=True, symmetric=True, cell_workers=1)  # fmt: skip
    assert c.certificate.status.value == "CERTIFIED" and c.result.n_basis == 4  # 1, cos q2, sin q2 qdot1, sin q2 qdot2
    lopsided = tiny.with_bounds(q_lower=np.array([-0.05, -0.05]), q_upper=np.array([0.05, 0.1]))
    with pytest.raises(NotApplicable, match="not symmetric"):
        even_half(scheduling(robot, lopsided, points=(5, 2)), system)
    # "auto" (what --moving-cells asks for): the half box when the loop is even, else the whole box
    whole = moving_robot_certificate(SimpleNamespace(robot=robot, domain=lopsided, P=problem.P), pd_controller(),
                                     points=(3, 2), velocities="bounded", qddot_max=qddot_max, level=0.9,
                                     symmetric="auto", recheck=None)  # fmt: skip
    assert whole.computed and "the other half" not in whole.grid_words


def test_moving_cells_asks_for_the_moving_robot_and_its_cells():
    from argparse import Namespace

    from polyrob.cli.analyze import moving_asked, moving_options

    args = Namespace(moving=None, moving_harmonics=None, moving_cells=True)
    assert moving_asked(args) is True
    assert moving_options(args) == {"cells": True, "progress": True, "level": 0.95, "symmetric": "auto"}
    both = Namespace(moving=None, moving_harmonics=2, moving_cells=True)
    assert moving_options(both)["harmonics"] == 2 and moving_options(both)["cells"]
    assert moving_options(both)["points"] == (17, 3)  # the half box of an even loop: as many points as (9, 3)
    assert moving_options(Namespace(moving=True, moving_harmonics=None, moving_cells=False)) is None


def test_the_cli_s_levels_reach_the_certificate_and_need_the_cells(capsys):
    from polyrob.cli import build_parser, main
    from polyrob.cli.analyze import moving_options

    argv = ["analyze", "paper_2r", "--controller", "paper", "--moving-harmonics", "2", "--moving-cells",
            "--moving-level", "0.8", "--moving-cells-level", "0.85"]  # fmt: skip
    opts = moving_options(build_parser().parse_args(argv))
    assert opts["level"] == 0.8 and opts["cell_level"] == 0.85 and opts["cells"]
    assert main(["analyze", "paper_2r", "--controller", "paper", "--moving-level", "0.8"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--moving-level sets a level of --moving-cells" in err[0]
    with pytest.raises(SystemExit):
        build_parser().parse_args(argv[:-1] + ["-1"])  # a level is a positive number


def test_the_cells_level_rule():
    from polyrob.analysis.lpv.robot import cells_level
    from polyrob.errors import ArgumentError

    assert cells_level(0.8155, level=0.8, cell_level=0.85) == 0.85  # asked for
    assert cells_level(0.9, level=0.95) == 0.95  # the search's level, above the grid's bound
    assert cells_level(0.9, level=0.85) == pytest.approx(0.95)  # halfway from the grid's bound to 1
    with pytest.raises(ArgumentError):
        cells_level(0.8, cell_level=float("nan"))


def _setting(searched):
    from polyrob.analysis.lpv.cells import cell_setting

    model, system, r, sysf, c, basis, used = searched
    return cell_setting(model, system, r.X, basis, used, similarity=sysf.similarity, c=c)


def _lmi(st, model, gamma, rho, nu):
    """The bounded-real matrix of the loop at ``rho`` with the rates ``nu`` (the loop's own coordinates)."""
    A, B, C, D = st.loop.at(*model.plant(rho))
    F = np.array([[f(rho) for f, _ in st.basis]])
    G = np.array([[g(rho) for _, g in st.basis]])
    return brl_matrices(GridData(A[None], B[None], C[None], D[None], F, G, nu[None, None], rho[None]), st.Xs,
                        gamma)[0][0, 0]  # fmt: skip


def test_the_second_order_expansion_bounds_the_lmi_over_a_cell_and_its_error_shrinks_as_h_squared(searched):
    from polyrob.analysis.lpv.cells.second_order import expansions

    st, model = _setting(searched), searched[0]
    exact, _ = st.rate_plan
    S = np.zeros((3, 3))
    for i, how in enumerate(exact):
        if how is not None:
            S[i, how[0]] = how[1]
    assert S[0, 2] > 0  # the rate of q2 is qdot2: the expansion must carry it
    lo0, hi0 = st.boxes[0]
    ctr, half = 0.5 * (lo0 + hi0), 0.5 * (hi0 - lo0)
    rng = np.random.default_rng(3)
    worst = []
    for scale in (1.0, 0.5):
        lo, hi = ctr - scale * half, ctr + scale * half
        ex, _, why = expansions(st.loop, model, st.enclose, st.basis, st.Xs, st.rate_plan, st.fixed, 1.2, lo, hi)
        assert not why and len(ex) == 4  # one per vertex of (d qdot1/dt, d qdot2/dt)
        h, seen = scale * half, 0.0
        for e in ex:
            # the centre derivative is the whole LMI's: central differences of W L W
            for a in range(3):
                t = 1e-6 * np.eye(3)[a]
                fd = e.W @ (_lmi(st, model, 1.2, ctr + t, e.nu + S @ t) - _lmi(st, model, 1.2, ctr - t, e.nu - S @ t)) @ e.W
                assert np.abs(fd / 2e-6 - e.D[a]).max() <= 1e-4 * (1 + np.abs(e.D[a]).max())
            bound = e.allowance + 0.5 * h @ e.K @ h
            for rho in rng.uniform(lo, hi, size=(40, 3)):
                d = rho - ctr
                R = e.W @ _lmi(st, model, 1.2, rho, e.nu + S @ d) @ e.W - e.WLW - np.einsum("a,aij->ij", d, e.D)
                r = np.linalg.norm(R, 2)
                assert r <= bound
                seen = max(seen, r)
        worst.append(seen)
    # the remainder is of second order: halving the cell quarters it (a wrong first derivative would halve it)
    assert 0.15 < worst[1] / worst[0] < 0.35


def test_the_second_order_test_sees_the_whole_derivative_where_the_first_adds_its_parts(searched):
    first, second = _check(searched, 1.2, order=1), _check(searched, 1.2, order=2)
    assert first.holds and second.holds
    # the parts of the LMI's derivative (plant, X, rates) bounded apart exceed the whole matrix's derivative
    assert all(a < b for a, b in zip(second.sensitivity, first.sensitivity))


def test_an_unknown_cell_order_is_refused(searched):
    from polyrob.errors import ArgumentError

    with pytest.raises(ArgumentError, match="order must be 1 or 2"):
        _check(searched, 1.2, order=3)
