"""The moving robot on a task domain proved between its grid points: the task's Jacobian enclosures and the cells."""

from types import SimpleNamespace

import numpy as np
import pytest
from test_moving_robot import pd_controller

import polyrob
from polyrob.analysis.lpv.check import GridData, brl_matrices
from polyrob.analysis.lpv.robot import kinematic_rates
from polyrob.analysis.lpv.task import task_motion_certificate, task_scheduling
from polyrob.bounds.certified.analytic import task_jacobian_enclosure
from polyrob.domains.task import TaskDomain
from polyrob.errors import DomainError


@pytest.fixture(scope="module")
def robot():
    return polyrob.load_robot("paper_2r")


def _jacobians(robot, z):
    q, qd, a = z[:2], z[2:4], z[4:]
    return robot.jacobians(q, qd, robot.inverse_dynamics(q, qd, a)[0])


def test_the_task_enclosure_holds_the_jacobians_at_random_points_of_its_box(robot):
    lo, hi = np.array([-0.3, 1.0, -1, -1, -2, -2]), np.array([0.3, 1.6, 1, 1, 2, 2])
    enc = task_jacobian_enclosure(robot, lo[:2], hi[:2], lo[2:4], hi[2:4], lo[4:], hi[4:], order=3)
    rng = np.random.default_rng(1)
    for z in rng.uniform(lo, hi, size=(300, 6)):
        A, B = _jacobians(robot, z)
        assert np.all(enc.A_lo <= A) and np.all(A <= enc.A_hi)
        assert np.all(enc.B_lo <= B) and np.all(B <= enc.B_hi)
    assert enc.qddot_lo.tolist() == [-2, -2] and enc.qddot_hi.tolist() == [2, 2]  # the accelerations: the box's


def test_at_a_point_the_enclosure_is_the_float_jacobians_and_its_derivatives_are_theirs(robot):
    z0 = np.array([0.2, 1.3, 0.5, -0.7, 1.0, -1.5])
    enc = task_jacobian_enclosure(robot, z0[:2], z0[:2], z0[2:4], z0[2:4], z0[4:], z0[4:], order=3)
    A, B = _jacobians(robot, z0)
    assert np.allclose(enc.A_lo, A, rtol=0, atol=1e-13) and np.allclose(enc.A_hi, A, rtol=0, atol=1e-13)
    assert np.allclose(enc.B_lo, B, rtol=0, atol=1e-13)
    h = 1e-6
    for col in range(6):  # d/d(q, qdot, qddot): central differences of the float Jacobians
        step = np.eye(6)[col] * h
        dA = (_jacobians(robot, z0 + step)[0] - _jacobians(robot, z0 - step)[0]) / (2 * h)
        dB = (_jacobians(robot, z0 + step)[1] - _jacobians(robot, z0 - step)[1]) / (2 * h)
        assert np.allclose(enc.dA_lo[..., col], dA, atol=1e-8) and np.allclose(enc.dB_lo[..., col], dB, atol=1e-8)
    # A is affine in the accelerations: its second derivative along them is an exact zero
    assert np.all(enc.d2A_lo[..., 4:, 4:] == 0) and np.all(enc.d2A_hi[..., 4:, 4:] == 0)


def test_a_malformed_task_box_is_refused(robot):
    with pytest.raises(DomainError):
        task_jacobian_enclosure(robot, [0, 1], [0, 0.5], [0, 0], [0, 0], [0, 0], [0, 0])
    with pytest.raises(DomainError):
        task_jacobian_enclosure(robot, [0, 1], [0, 1], [0, 0], [0, 0], [0, np.nan], [0, 0])


@pytest.fixture(scope="module")
def tiny_task(robot):
    task = TaskDomain.from_robot(robot, pose=[0.0, 1.5708], q_radius=0.05, qdot_max=0.05, qddot_max=0.1)
    return SimpleNamespace(robot=robot, domain=task, P=SimpleNamespace(W_S=0.4 * np.eye(2), W_T=None, W_KS=None))


#: The re-check grid of these tests' certificates: every search point of ``points=(3, 2)`` and one midway between
#: each two neighbours, along the positions and the velocities (what recheck_points gives before its floor,
#: DEFAULT_RECHECK (9, 5)): the midpoints where an X fitted at the grid's points fails, in 405 points instead of
#: 5625 (the re-check and its constraint generation were most of these tests' time).
RECHECK = (5, 3)


@pytest.fixture(scope="module")
def certified_run(tiny_task):
    """The certificate on cells, and the system and time scale its search returned (the coordinates of its X)."""
    from polyrob.analysis.lpv import task as task_module

    searched, search = [], task_module._search

    def recorded(*args):
        searched.append(search(*args))
        return searched[-1]

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(task_module, "_search", recorded)
        mv = task_motion_certificate(tiny_task, pd_controller(), points=(3, 2), velocities="bounded", level=0.9,
                                     cells=True, cell_workers=1, lower_bound=False, recheck=RECHECK)  # fmt: skip
    assert len(searched) == 1
    _, sysf, c = searched[0]
    return mv, sysf, c


@pytest.fixture(scope="module")
def certified(certified_run):
    return certified_run[0]


def test_the_task_s_moving_robot_is_certified_on_cells_and_says_so(certified):
    assert certified.cells["holds"], certified.cells
    assert certified.cells["accelerations"] == []  # on a task they are parameters: no acceleration bound is proved
    assert "accelerations proved" not in " ".join(certified.certificate.scope.notes)
    cert = certified.certificate
    assert cert.status.value == "CERTIFIED" and cert.bound == pytest.approx(0.9)
    assert cert.scope.enclosure == "proved"
    assert "cells covering the whole box" in " ".join(cert.scope.notes)


def test_the_proved_x_holds_at_random_points_and_exact_rates_of_the_task(tiny_task, certified_run):
    """Soundness: an X the cells prove, at random (q2, qdot, qddot) with dq2/dt = qdot2 and dqdot/dt = qddot.

    The X is the certificate's (the ``certified`` fixture's, whose cells prove it at level 0.9): the search, then the
    re-check grid's failing points added to it (constraint generation), as :func:`task_motion_certificate` runs them
    before the cells; checked here in the coordinates and time scale its search returned."""
    from polyrob.analysis.lpv.basis import default_basis
    from polyrob.analysis.lpv.task import task_rate_bounds

    mv, sysf, c = certified_run
    assert mv.cells["holds"] and mv.cells["gamma"] == 0.9, mv.cells  # the cells proved this X at 0.9
    r = mv.result
    model = task_scheduling(tiny_task.robot, tiny_task.domain, points=(3, 2))
    basis = default_basis(model, tensor=True)
    rates = task_rate_bounds(model, tiny_task.domain)
    used = [(-np.inf, np.inf) if k == "qddot" else b for b, k in zip(rates, model.kinds)]
    rates_at = kinematic_rates(model, used, c)
    lo, hi = np.array([a[0] for a in model.axes]), np.array([a[-1] for a in model.axes])
    rng = np.random.default_rng(2)
    for rho in rng.uniform(lo, hi, size=(150, len(lo))):
        A, B, C, D = sysf(rho)
        nu = np.array([b[0] if k != "qddot" else 0.0 for b, k in zip(rates_at(rho), model.kinds)])  # X free of qddot
        assert all(b[0] == b[1] for b, k in zip(rates_at(rho), model.kinds) if k != "qddot")  # the exact rates
        F = np.array([[f(rho) for f, _ in basis]])
        G = np.array([[g(rho) for _, g in basis]])
        M, _, X, _ = brl_matrices(GridData(A[None], B[None], C[None], D[None], F, G, nu[None, None], rho[None]),
                                  np.asarray(r.X), 0.9)  # fmt: skip
        assert np.linalg.eigvalsh(M[0])[:, -1].max() < 0 and np.linalg.eigvalsh(X[0])[0] > 0


def test_without_cells_the_task_certificate_stays_grid_only(tiny_task):
    """No cells: the X proved at the grid's points only (no finer re-check either: at level 0.9 the X may fail
    there, NOT_CERTIFIED, as Clarabel 0.11's did without the constraint generation the cells' certificate runs)."""
    plain = task_motion_certificate(tiny_task, pd_controller(), points=(3, 2), velocities="bounded", level=0.9,
                                    lower_bound=False, recheck=None)  # fmt: skip
    assert plain.certificate.status.value == "GRID_ONLY" and not plain.cells


def test_a_urdf_robot_s_task_is_proved_through_its_exact_polynomials():
    """planar_2r (Pinocchio) has no analytic callables: its cells enclose the Jacobians of its SymbolicTwin (which
    two spawned workers rebuild from the pickled robot, proving the same cells as one process)."""
    robot = polyrob.load_robot("planar_2r")
    task = TaskDomain.from_robot(robot, pose=[0.0, 1.5708], q_radius=0.05, qdot_max=0.05, qddot_max=0.1)
    problem = SimpleNamespace(robot=robot, domain=task, P=SimpleNamespace(W_S=0.4 * np.eye(2), W_T=None, W_KS=None))
    runs = [task_motion_certificate(problem, pd_controller(), points=(3, 2), velocities="bounded", level=0.9,
                                    cells=True, cell_workers=w, lower_bound=False, recheck=RECHECK)
            for w in (1, 2)]  # fmt: skip
    for c, workers in zip(runs, (1, 2)):
        assert c.cells["holds"], c.cells
        assert c.cells["workers"] == workers and c.certificate.status.value == "CERTIFIED"
    assert runs[0].cells["cells"] == runs[1].cells["cells"]


def test_the_search_and_the_cells_move_the_whole_job_s_progress_line(tiny_task, monkeypatch):
    """`analyze --moving` sat at one fraction for the minutes of a search: the interior point's gap and the part of
    the box the cells proved now move the job's line, each inside its part of the stage."""
    import io

    from polyrob.progress import JobProgress

    job = JobProgress(["moving-robot certificate"], stream=io.StringIO(), clock=lambda: 0.0)
    job.start()
    job._stop.set()  # no ticking thread: the test reads the shares itself
    shares, within = [], job.within
    monkeypatch.setattr(job, "within", lambda share: (shares.append(share), within(share))[1])
    import polyrob.analysis.lpv.cells as cells_module

    proved, reporter = [], cells_module.volume_reporter

    def counted(lo0, hi0):  # each proved cell: one report of the volume proved so far
        on_proved = reporter(lo0, hi0)
        return lambda lo, hi: (proved.append(1), on_proved(lo, hi))[1]

    monkeypatch.setattr(cells_module, "volume_reporter", counted)
    try:
        job.begin(1, "moving-robot certificate")
        # re-checked on RECHECK (along the velocities, the search's own three points): this test reads the search's
        # and the cells' shares, and the cells prove the X on the whole box
        mv = task_motion_certificate(tiny_task, pd_controller(), points=(3, 3), velocities="bounded", level=0.9,
                                     cells=True, cell_workers=1, lower_bound=False, solver="structured",
                                     recheck=RECHECK)  # fmt: skip
    finally:
        job.stop()
    assert mv.certificate.status.value == "CERTIFIED", mv.cells
    search = [s for s in shares if 0.0 < s < 0.4]  # the solves' own reports, inside the search's part
    cells = [s for s in shares if 0.45 < s < 0.9]  # the volume proved, inside the cells' part
    # every proved cell but the last (which reaches the part's end) moves the line.  Two .ci/run runs saw one
    # share there, 0.5, and a last share of 0.5, as if a loop in another thread of the worker (a Dask worker
    # thread of test_fleet.py's in-process cluster, presumably) narrowed the one global span: polyrob.progress
    # keeps a span per thread now, and counts the reports of the job's own thread only
    assert len(set(search)) >= 5 and proved and len(set(cells)) >= min(5, len(proved) - 1), (shares, len(proved))
    assert shares[-1] == 1.0 and job.share >= 0.9


def test_the_cells_allowance_bounds_what_an_inexact_inverse_of_the_similarity_changes(tiny_task):
    """The cells check X in the coordinates it was searched in (x = T x~), through the float inverse Ti of T: what
    Ti T != I and the products' rounding change in the LMI is bounded (similarity_allowance), here against a Ti a
    thousandth off, and the allowance of an accurate inverse on a 1e6-conditioned T is tiny."""
    from polyrob.analysis.lpv.basis import default_basis
    from polyrob.analysis.lpv.cells import cell_setting
    from polyrob.analysis.lpv.cells.loop import AffineLoop, SimilarTransform, similarity_allowance
    from polyrob.analysis.lpv.robot import closed_loop_system
    from polyrob.analysis.lpv.task import task_rate_bounds
    from polyrob.bounds.certified.analytic import function_balls

    model = task_scheduling(tiny_task.robot, tiny_task.domain, points=(3, 2))
    system = closed_loop_system(model, pd_controller(), tiny_task.P.W_S, None, None)
    centre = np.array([0.5 * (a[0] + a[-1]) for a in model.axes])
    n = system(centre)[0].shape[0]
    basis = default_basis(model, tensor=True)
    rates = [(-np.inf, np.inf) if k == "qddot" else r for r, k in zip(task_rate_bounds(model, tiny_task.domain),
                                                                       model.kinds)]  # fmt: skip
    rng = np.random.default_rng(0)
    Q = np.linalg.qr(rng.normal(size=(n, n)))[0]
    T = Q @ np.diag(np.logspace(-3, 3, n)) @ Q.T  # condition 1e6
    Xs = np.array([np.eye(n)] + [0.1 * np.eye(n)] * (len(basis) - 1))
    st = cell_setting(model, system, Xs, basis, rates)  # the box, its enclosure, the balancing
    lo, hi = st.lo, st.hi
    f_max = np.abs(function_balls(basis, lo, hi)[0]).max(axis=0)
    original = AffineLoop(system.of_plant, 1.0, np.ones(n), *model.plant(centre))
    enc = st.enclose(lo, hi)
    accurate = SimilarTransform(system.of_plant, T)
    loop = AffineLoop(accurate, st.loop.c, st.loop.sc, *model.plant(centre))
    scale = f_max @ np.linalg.norm(st.Xs, axis=(1, 2)) * max(np.linalg.norm(g[0]) for g in loop.G + [loop.at(
        *model.plant(centre))])  # fmt: skip
    assert 0.0 < similarity_allowance(accurate, original, loop, enc, st.Xs, f_max) < 1e-6 * scale

    off = SimilarTransform(system.of_plant, T)
    off.Ti = off.Ti * (1 + 1e-3)  # Ti T = (1 + 1e-3) I
    exact = SimilarTransform(system.of_plant, np.linalg.inv(off.Ti))  # the loop similar through Ti^-1
    exact.Ti = off.Ti
    loop_off = AffineLoop(off, st.loop.c, st.loop.sc, *model.plant(centre))
    loop_exact = AffineLoop(exact, st.loop.c, st.loop.sc, *model.plant(centre))
    allowance = similarity_allowance(off, original, loop_off, enc, st.Xs, f_max)
    worst = 0.0
    for rho in rng.uniform(lo, hi, size=(20, len(lo))):
        f = np.array([[float(fn(rho)) for fn, _ in basis]])
        g = np.array([[np.asarray(gr(rho), float) for _, gr in basis]])
        mats = []
        for loop in (loop_off, loop_exact):
            A, B, C, D = loop.at(*model.plant(rho))
            data = GridData(A[None], B[None], C[None], D[None], f, g, np.zeros((1, 1, len(lo))), rho[None])
            mats.append(brl_matrices(data, st.Xs, 0.9)[0][0, 0])
        worst = max(worst, np.linalg.norm(mats[0] - mats[1], 2))
    assert 1e-6 * scale < worst <= allowance


def test_constraint_generation_makes_the_structured_search_s_x_hold_between_its_points(tiny_task):
    """On two points per velocity the structured solver's X, of the same margin as Clarabel's, failed between the
    points (robot.SEARCH_SOLVER); the re-check grid's failing points added to the search make it hold there, and
    the cells then prove it on the whole box."""
    mv = task_motion_certificate(tiny_task, pd_controller(), points=(3, 2), velocities="bounded", level=0.9,
                                 cells=True, cell_workers=1, lower_bound=False, solver="structured",
                                 recheck=RECHECK)  # fmt: skip
    assert mv.certificate.status.value == "CERTIFIED", (mv.finer, mv.cells)
    assert np.isfinite(mv.finer["gamma"]) and "constraint generation" in " ".join(mv.certificate.scope.notes)
