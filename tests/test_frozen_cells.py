"""The frozen robot over a task cut into cells (:mod:`polyrob.analysis.frozen_cells`).

The union of the cells' certificates is decided in one place
(:func:`~polyrob.analysis.certificate.union_certificate`): certified only
when every cell is; the bisection keeps to its cell limit, splits where a
screen or a certificate fails, and each cell's model holds the set's true
robots at the points of its own cell (finger_edu with the engineer's set).
"""

from __future__ import annotations

import functools
import json
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from polyrob import load_robot
from polyrob.analysis import frozen_cells as fc
from polyrob.analysis.certificate import Certificate, Scope, Status, union_certificate
from polyrob.domains.default_task import default_task_domain
from polyrob.errors import ArgumentError
from polyrob.model.inner import inner_loop_of_set
from polyrob.uncertainty_set.default_set import default_set


@functools.cache
def finger():
    """finger_edu's loop over the engineer's set (its default) and its default task."""
    robot = load_robot("finger_edu")
    loop = inner_loop_of_set(robot, "computed-torque", default_set(robot), draws=2)
    return loop, default_task_domain(loop)


def cert(status: Status, bound: float, lower: float = 0.5) -> Certificate:
    reasons = () if status is Status.CERTIFIED else (f"mu in [{lower}, {bound}] on the grid",)
    return Certificate(status, bound, bound, lower, None, Scope(), reasons, bound_everywhere=status.certified)


def test_the_union_is_certified_only_when_every_cell_is_and_its_bound_is_the_largest():
    ok = [cert(Status.CERTIFIED, 0.91), cert(Status.CERTIFIED, 0.97)]
    both = union_certificate(ok, Scope())
    assert both.certified and both.mu_upper == 0.97
    one_fails = union_certificate(ok + [cert(Status.NOT_CERTIFIED, 1.02)], Scope())
    assert one_fails.status is Status.NOT_CERTIFIED and one_fails.mu_upper == np.inf
    assert one_fails.reasons[0].startswith("1 of 3 cells not certified")
    # a member of one cell's model breaks it: the union is violated as one model would be
    violated = union_certificate(ok + [cert(Status.NOT_CERTIFIED, 1.02), cert(Status.VIOLATED, 1.3, 1.1)], Scope())
    assert violated.status is Status.VIOLATED and violated.mu_lower == 1.1
    with pytest.raises(ArgumentError):
        union_certificate([], Scope())


def test_a_cell_keeps_the_task_s_velocities_and_accelerations_and_must_lie_inside_it():
    loop, task = finger()
    lo, hi = task.q_lower.copy(), task.q_upper.copy()
    hi[1] = 0.5 * (lo[1] + hi[1])
    cell = fc.cell_domain(task, lo, hi)
    assert np.allclose(cell.q_upper, hi) and np.allclose(cell.q_lower, lo)
    assert np.allclose(cell.lower[loop.m :], task.lower[loop.m :]) and np.allclose(
        cell.upper[loop.m :], task.upper[loop.m :]
    )
    with pytest.raises(ArgumentError, match="inside the task"):
        fc.cell_domain(task, lo - 0.1, hi)


def test_the_split_goes_along_the_only_position_that_ranges():
    loop, task = finger()
    for k in range(loop.m):
        lo, hi = task.q_lower.copy(), task.q_upper.copy()
        keep = np.arange(loop.m) != k
        lo[keep] = hi[keep] = 0.5 * (task.q_lower[keep] + task.q_upper[keep])
        assert fc.split_position(loop, fc.cell_domain(task, lo, hi)) == k


def test_each_cell_s_model_holds_the_set_s_true_robots_at_the_points_of_its_cell():
    from polyrob.plant.moving_links import motion_coverage, moving_links_plant

    loop, task = finger()
    k = fc.split_position(loop, task)
    width = task.q_upper[k] - task.q_lower[k]
    top_lo, bottom_hi = task.q_lower.copy(), task.q_upper.copy()
    top_lo[k], bottom_hi[k] = task.q_upper[k] - width / 4, task.q_lower[k] + width / 4
    top, bottom = fc.cell_domain(task, top_lo, task.q_upper), fc.cell_domain(task, task.q_lower, bottom_hi)
    pldi = SimpleNamespace(m=loop.m, A0=None, B0=None, enclosure="sampled", robot_name=loop.name)

    def model(cell):
        return moving_links_plant(SimpleNamespace(**vars(pldi), domain=cell), loop, samples=64, exact_payload=True)

    assert motion_coverage(model(top), loop, top, 60, points=6) == 1.0
    # a cell's model is its own: the other end of the task's robots are not all in it
    assert motion_coverage(model(bottom), loop, top, 60, points=6) < 1.0


def fake_problem():
    """A problem whose cells are decided by a fake certificate: certified when its widest position is <= 0.1 rad."""
    loop, task = finger()
    return SimpleNamespace(pldi=SimpleNamespace(domain=task), robot=loop, hyperparameters=None, scope=lambda: Scope())


@pytest.fixture
def fake_cells(monkeypatch):
    calls = {"certified": [], "screened": []}

    def certificate(problem, K, domain, unc, P, coverage_points):
        width = float(np.max(domain.q_upper - domain.q_lower))
        calls["certified"].append(width)
        c = cert(Status.CERTIFIED, 0.9) if width <= 0.1 + 1e-9 else cert(Status.NOT_CERTIFIED, 1.0 + width)
        return 1.0, replace(c, mu=SimpleNamespace(peak_upper_frequency=10.0))

    def screen(P, K, frequencies):  # mu's bound at the screen: 1 + the cell's width where it screens out
        calls["screened"].append(tuple(frequencies))
        return 1.0 + calls["width"] if len(frequencies) and calls["width"] > 0.2 + 1e-9 else 0.5

    def plant(problem, domain):
        calls["width"] = float(np.max(domain.q_upper - domain.q_lower))
        return None, None

    monkeypatch.setattr(fc, "_cell_certificate", certificate)
    monkeypatch.setattr(fc, "screen_bound", screen)
    monkeypatch.setattr(fc, "cell_plant", plant)
    monkeypatch.setattr(fc, "split_position", lambda loop, d: int(np.argmax(d.q_upper - d.q_lower)))
    return calls


def test_cells_are_split_until_each_holds_and_the_union_is_certified(fake_cells):
    log = []
    result = fc.frozen_cells_certificate(fake_problem(), None, max_cells=64, coverage_points=0, on_cell=log.append)
    assert len(log) == result.visited and sum("screened_out_at" in r for r in log) == result.screened
    # a screened cell's record keeps the bound that screened it out
    assert all(r["screen_mu_upper"] == pytest.approx(1 + max(np.subtract(r["q_upper"], r["q_lower"])), abs=1e-4)
               for r in log if "screened_out_at" in r)  # fmt: skip
    assert sum(r.get("status") == "CERTIFIED" for r in log) == 64
    # finger_edu's task is 0.4 rad wide on each of 3 joints: cells of 0.1 rad, 4 per joint
    assert result.certified and len(result.cells) == 4**3
    assert all(np.max(c.q_upper - c.q_lower) <= 0.1 + 1e-9 for c in result.cells)
    lo = np.min([c.q_lower for c in result.cells], axis=0)
    hi = np.max([c.q_upper for c in result.cells], axis=0)
    task = finger()[1]
    assert np.allclose(lo, task.q_lower) and np.allclose(hi, task.q_upper)
    volume = sum(np.prod(c.q_upper - c.q_lower) for c in result.cells)
    assert volume == pytest.approx(np.prod(task.q_upper - task.q_lower))  # they tile the task
    # after the first failure its peak screens the cells wider than 0.2 rad without a certificate
    assert result.screened > 0 and max(fake_cells["certified"][1:]) <= 0.2 + 1e-9
    assert "64 task cells" in result.certificate.scope.model and "1/4, 1/4, 1/4" in result.certificate.scope.notes[-1]
    assert result.verdict.startswith("frozen robot on 64 task cells: robust performance CERTIFIED")
    assert result.words().startswith("task cells: 64 of 64 certified (at most 64)")
    summary = json.loads(json.dumps(result.summary()))
    assert summary["certificate"]["certified"] and len(summary["cells"]) == 64


def test_at_the_cell_limit_the_failing_cells_are_kept_and_the_union_is_not_certified(fake_cells):
    result = fc.frozen_cells_certificate(fake_problem(), None, max_cells=8, coverage_points=0)
    assert not result.certified and len(result.cells) <= 8
    assert (
        result.certificate.reasons[0].endswith("on the grid") and "cells not certified" in result.certificate.reasons[0]
    )


def test_a_problem_without_a_task_is_refused():
    problem = SimpleNamespace(pldi=SimpleNamespace(domain=load_robot("paper_2r")))
    with pytest.raises(ArgumentError, match="task"):
        fc.frozen_cells_certificate(problem, None)
    with pytest.raises(ArgumentError, match="max_cells"):
        fc.frozen_cells_certificate(fake_problem(), None, max_cells=0)


def test_finished_cells_are_kept_and_a_second_run_decides_none_again(fake_cells, monkeypatch, tmp_path):
    monkeypatch.setattr(fc, "cell_fingerprint", lambda P, K, n, d: f"{d.q_lower.tolist()}{d.q_upper.tolist()}"[:200])
    first = fc.frozen_cells_certificate(fake_problem(), None, max_cells=8, coverage_points=0, cells_dir=tmp_path)
    decided = len(fake_cells["certified"])
    assert decided > 0 and first.kept == 0 and len(list(tmp_path.glob("*.pkl"))) == decided
    log = []
    again = fc.frozen_cells_certificate(
        fake_problem(), None, max_cells=8, coverage_points=0, cells_dir=tmp_path, on_cell=log.append
    )
    assert len(fake_cells["certified"]) == decided  # nothing decided anew
    assert again.kept == decided and "kept by an earlier run" in again.words()
    assert again.certificate.status is first.certificate.status and len(again.cells) == len(first.cells)
    assert [c.certificate.bound for c in again.cells] == [c.certificate.bound for c in first.cells]
    assert sum("kept_from" in r for r in log) == decided


def test_a_real_certificate_is_kept_whole_and_its_fingerprint_names_the_controller(tmp_path):
    import control

    from polyrob.analysis.certificate import certify_loop

    # a stable bare plant (inputs d, u; outputs v, y), one complex block, under a static gain
    G = control.ss([[-1.0]], [[1.0, 1.0]], [[1.0], [0.5]], [[0.0, 0.0], [0.0, 0.0]])
    blk = [[1, 1]]
    made = certify_loop(G, control.ss([], [], [], [[-0.5]]), blk=blk, n_u=1, n_y=1, progress=False)
    calls = []
    _, a, kept_a = fc._kept_certificate(tmp_path, "k1", lambda: calls.append(1) or (1.0, made))
    _, b, kept_b = fc._kept_certificate(tmp_path, "k1", lambda: calls.append(1) or (1.0, made))
    assert calls == [1] and (kept_a, kept_b) == (False, True)
    assert b.status is a.status and b.bound == a.bound and b.closed_loop is None
    assert b.mu.between is not None and np.allclose(b.mu.upper, a.mu.upper)
