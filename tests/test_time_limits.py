"""Every give-up that decides a status counts work; a wall-clock limit is the user's and names itself.

Each test runs under a fake or a slowed clock (tests/clocks.py): none depends on this machine's load.
"""

from __future__ import annotations

import inspect

import control
import numpy as np
import pytest
from clocks import FakeClock, slowed_clock

from polyrob.analysis.mu.between import MAX_POINTS, verify_between
from polyrob.analysis.mu.bounds import mu_bounds
from polyrob.bounds.certified.boxes import prove_on_boxes
from polyrob.clock import UserTimeLimit
from polyrob.errors import ArgumentError


def _resonance():
    G = control.tf([1], [1, 0.02, 1])  # a sharp resonance the coarse grid misses
    return G, mu_bounds(G, [[1, 1]], [0.1, 0.5, 2.0, 10.0], refine_peak=False, progress=False)


def _needs_splits(lo, hi):  # x^2 <= 1.01 on [-1, 1]: proved only on small boxes
    top = max(abs(lo[0]), abs(hi[0]))
    return 1.01 - top**2 * (1 + (hi[0] - lo[0])), "x^2 may exceed 1.01"


def test_no_give_up_that_decides_a_status_has_a_default_in_seconds():
    """Before: between.py 120 s, the certified enclosure 120 s, the cells 900 s, the moving robot's cells 1800 s,
    the batch's search 600 s and its validation 120 s, all by default."""
    from polyrob.analysis.lpv.cells import check_cells
    from polyrob.analysis.lpv.moving import moving_robot_certificate
    from polyrob.bounds.certified.enclosure import certified_jacobian_bounds
    from polyrob.fleet.jobs import Settings
    from polyrob.synthesis.bandwidth import max_bandwidth_scaling
    from polyrob.synthesis.options import MusynOptions
    from polyrob.validate.simulate import simulate

    for fn, name in [
        (verify_between, "time_limit"),
        (certified_jacobian_bounds, "time_limit"),
        (check_cells, "time_limit"),
        (moving_robot_certificate, "cell_time_limit"),
        (max_bandwidth_scaling, "search_time_limit"),
        (simulate, "time_budget"),
    ]:
        assert inspect.signature(fn).parameters[name].default is None, fn.__name__
    assert Settings().search_time_limit is None and Settings().validate_budget is None
    assert MusynOptions().time_limit is None
    assert "max_seconds" not in inspect.signature(verify_between).parameters


def test_the_check_between_grid_points_is_the_same_under_a_clock_1000x_faster(monkeypatch):
    G, coarse = _resonance()
    normal = verify_between(G, coarse)
    slowed_clock(monkeypatch, 1000.0)
    slowed = verify_between(G, coarse)
    assert normal.holds and slowed.holds
    assert (slowed.level, slowed.points_added, slowed.intervals) == (
        normal.level,
        normal.points_added,
        normal.intervals,
    )


def test_the_check_between_grid_points_gives_up_after_its_points_and_says_how_many():
    G, coarse = _resonance()
    res = verify_between(G, coarse, max_points=1)  # infinity is the first; no middle point after it
    assert not res.holds and res.points_added == 1
    assert res.reason.startswith("1 point added (the check's limit of 1 point) and an interval near")
    assert MAX_POINTS == 200


def test_a_time_limit_set_on_the_check_between_grid_points_is_named(monkeypatch):
    G, coarse = _resonance()
    FakeClock(step=10.0).install(monkeypatch)  # 10 s per reading: the limit of 5 s fires before the first split
    res = verify_between(G, coarse, time_limit=5.0)
    assert not res.holds and "stopped by the time limit of 5 s you set, after 1 point added" in res.reason
    assert "not verified between the grid points: stopped by the time limit of 5 s you set" in res.sentence()
    with pytest.raises(ArgumentError, match="time_limit must be > 0"):
        verify_between(G, coarse, time_limit=0.0)


def test_branch_and_bound_counts_cells_and_names_a_time_limit(monkeypatch):
    box = [(np.array([-1.0]), np.array([1.0]))]
    slowed_clock(monkeypatch, 1e6)  # a second of work reads as 11 days: nothing changes without a limit
    ok, leaves, why = prove_on_boxes(box, _needs_splits, np.array([2.0]), min_width=1e-6, max_boxes=1000)
    assert ok and why == "" and len(leaves) > 2
    ok, _, why = prove_on_boxes(box, _needs_splits, np.array([2.0]), min_width=1e-6, max_boxes=2)
    assert not ok and "(the limit of 2 cells)" in why
    FakeClock(step=5.0).install(monkeypatch)
    ok, _, why = prove_on_boxes(box, _needs_splits, np.array([2.0]), min_width=1e-6, max_boxes=1000, time_limit=7)
    assert not ok and why.startswith("stopped by the time limit of 7 s you set, after 0 cells")


def test_a_user_time_limit_reads_the_clock_and_names_itself(monkeypatch):
    clock = FakeClock().install(monkeypatch)
    limit = UserTimeLimit.starting_now(90)
    clock.advance(89.0)
    assert not limit.passed()
    clock.advance(1.0)
    assert limit.passed() and limit.words == "the time limit of 90 s you set"
    assert UserTimeLimit.starting_now(None) is None
    with pytest.raises(ArgumentError, match="> 0 seconds"):
        UserTimeLimit.starting_now(0)
