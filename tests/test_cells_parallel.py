"""The moving robot's cells on spawned worker processes: the verdict of the one-process search (cells.parallel)."""

import dataclasses
import multiprocessing
import pickle

import numpy as np
import pytest
from test_moving_robot import pd_controller

import polyrob
from polyrob.analysis.lpv.cells import check_cells
from polyrob.analysis.lpv.moving import _search
from polyrob.analysis.lpv.robot import closed_loop_system, rate_bounds, scheduling
from polyrob.bounds.certified.boxes import prove_on_boxes, prove_on_boxes_in_batches
from polyrob.domains.torque_box import Domain
from polyrob.errors import ArgumentError, BoundsError


@pytest.fixture(scope="module")
def searched():
    """tests/test_cells.py's small problem: ``X(rho)`` at level 1.2 on a 3 x 2 x 2 grid of a shrunk paper domain."""
    robot = polyrob.load_robot("paper_2r")
    d = Domain.from_robot(robot, "paper")
    tiny = d.with_bounds(q_lower=np.full(2, -0.05), q_upper=np.full(2, 0.05), qdot_lower=d.qdot_lower * 0.01,
                         qdot_upper=d.qdot_upper * 0.01)  # fmt: skip
    model = scheduling(robot, tiny, points=(3, 2))
    system = closed_loop_system(model, pd_controller(), 0.5 * np.eye(2), None)
    rates, _ = rate_bounds(model, tiny, scale=1.0)
    rates = [(2 * lo, 2 * hi) if k == "qdot" else (lo, hi) for (lo, hi), k in zip(rates, model.kinds)]
    r, sysf, c, basis, used = _search(model, system, rates, quadratic=False, velocities="bounded", tensor=True,
                                      level=1.2)  # fmt: skip
    assert r.proved and r.gamma < 1.2
    return model, system, r, sysf, c, basis, used


def _check(searched, gamma, **kw):
    model, system, r, sysf, c, basis, used = searched
    return check_cells(model, system, r.X, kw.pop("basis", basis), used, gamma, similarity=sysf.similarity, c=c,
                       **kw)  # fmt: skip


def _verdict(chk):
    """Everything but the time taken and the processes used."""
    return dataclasses.replace(chk, seconds=0.0, workers=0)


def test_two_workers_give_the_cell_check_of_one_process(searched):
    serial = _check(searched, 1.2, workers=1)
    parallel = _check(searched, 1.2, workers=2)
    assert serial.holds and serial.n_cells > 2  # bisected: the initial cells are 2
    assert parallel.workers == 2 and serial.workers == 1
    assert _verdict(parallel) == _verdict(serial)
    # a failure: the same reason, the same count where the limit of cells gives up
    s3, p3 = _check(searched, 1.2, workers=1, max_cells=3), _check(searched, 1.2, workers=2, max_cells=3)
    assert not s3.holds and "the limit of 3 cells" in s3.reason
    assert _verdict(p3) == _verdict(s3)
    # the first-order test too (its rates travel to the workers as a KinematicRates)
    s1, p1 = _check(searched, 1.2, workers=1, order=1), _check(searched, 1.2, workers=2, order=1)
    assert s1.holds and _verdict(p1) == _verdict(s1)


def _disc(kind):
    """A box test: proved once small (``"holds"``), refuted at a point when small (``"point"``), or never proved
    on a circle (``"circle"``: the limits give up)."""

    def evaluate(lo, hi):
        c, h = 0.5 * (lo + hi), 0.5 * (hi - lo)
        if kind == "point" and np.all(np.abs(c - [0.61, -0.23]) <= h) and h.max() < 0.2:
            return -np.inf, None, "refuted at a point"
        gap = abs(np.hypot(*c) - 0.7) if kind == "circle" else 0.15 + 0.05 * np.sin(5 * c[0])
        return gap - np.hypot(*h) - 1e-3, h * (1 + c**2), "not proved there"

    return evaluate


def test_the_batched_branch_and_bound_reads_values_in_the_one_by_one_order():
    boxes = [(np.array([-1.0, -1.0]), np.array([0.0, 1.0])), (np.array([0.0, -1.0]), np.array([1.0, 1.0]))]
    width0, outcomes = np.array([2.0, 2.0]), set()
    for kind in ("holds", "point", "circle"):
        evaluate = _disc(kind)
        for max_boxes, min_width in ((60, 1e-6), (100_000, 0.01), (5000, 1e-6)):
            opts = {"min_width": min_width, "max_boxes": max_boxes}
            want = prove_on_boxes(boxes, evaluate, width0, by_contribution=True, **opts)
            words = ("refuted at a point", "the limit of", "the smallest width")
            outcomes.add("holds" if want[0] else next(w for w in words if w in want[2]))
            for batch in (1, 7, 256):
                seen = []
                got = prove_on_boxes_in_batches(boxes, lambda cells, ev=evaluate: [ev(lo, hi) for lo, hi in cells],
                                                width0, batch=batch, observe=seen.append, **opts)  # fmt: skip
                assert got[0] == want[0] and got[2] == want[2]
                assert [v[0] for v in got[1]] == [v[0] for v in want[1]]
                assert len(seen) >= len(got[1]) + (not got[0])  # the values read, not the ones evaluated past the end
    # every way out was taken: proved, refuted at a point, the limit of cells, the smallest width
    assert len(outcomes) == 4, outcomes


def test_the_cell_work_is_picklable(searched):
    from polyrob.analysis.lpv.cells.parallel import CellWork

    model, system, r, sysf, c, basis, used = searched
    blob = pickle.dumps((system.of_plant, basis, model))
    of_plant, basis2, model2 = pickle.loads(blob)
    rho = np.array([0.01, 0.002, -0.003])
    assert [float(f(rho)) for f, _ in basis2] == [float(f(rho)) for f, _ in basis]
    assert all(np.array_equal(a, b) for a, b in zip(of_plant(*model2.plant(rho)), system.of_plant(*model.plant(rho))))
    assert CellWork.__dataclass_params__.frozen


def _raises_in_a_worker(r):
    if multiprocessing.parent_process() is not None:
        raise RuntimeError("a basis function that fails in workers")
    return 1.0


def _zero(r):
    return np.zeros(3)


def test_a_cell_test_that_raises_in_a_worker_is_a_clear_error(searched):
    basis = [(_raises_in_a_worker, _zero)] + list(searched[5][1:])  # the constant 1, failing in workers only
    with pytest.raises(BoundsError, match=r"cell test failed in a worker process at rho in \[.*RuntimeError: a basis"):
        _check(searched, 1.2, workers=2, basis=basis)
    with pytest.raises(ArgumentError, match="workers must be at least 1"):
        _check(searched, 1.2, workers=0)


def test_a_loop_with_state_space_weights_reaches_the_workers():
    """python-control's StateSpace does not pickle; the weights of a problem the CLI builds are StateSpace, and the
    loop the cells' workers receive must pickle anyway (it kept the CLI's cells on one process)."""
    import control

    robot = polyrob.load_robot("paper_2r")
    model = scheduling(robot, Domain.from_robot(robot, "paper"), points=(3, 2))
    W_S = control.ss(-0.01 * np.eye(2), np.eye(2), 0.5 * np.eye(2), 0.5 * np.eye(2))
    with pytest.raises(Exception):
        pickle.dumps(W_S)  # the premise: if this ever pickles, the test below proves less
    system = closed_loop_system(model, pd_controller(), W_S, control.tf([1.0, 1.0], [0.1, 1.0]))
    again = pickle.loads(pickle.dumps(system.of_plant))
    rho = np.array([a[1] for a in model.axes])
    A, B = model.plant(rho)
    for x, y in zip(system.of_plant(A, B), again(A, B)):
        assert np.array_equal(x, y)
