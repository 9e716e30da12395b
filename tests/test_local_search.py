"""The local search of the bounds (polyrob.bounds.local_search) over several true robots (variants)."""

from __future__ import annotations

import numpy as np
import pytest

from polyrob.bounds.local_search import _local_search


class _TwoRobots:
    """A stand-in search problem: one joint, ``x = (q, qdot, w)``, two variants given as functions of ``q``."""

    m = 1
    lo, hi = np.array([-1.0, -1.0, -1.0]), np.array([1.0, 1.0, 1.0])

    def __init__(self, *functions):
        self.variants = functions
        self.calls = [0] * len(functions)

    def along(self, q, qdot, w, index, d, variant=None):
        if variant is None:
            return np.max([self.along(q, qdot, w, index, d, i) for i in range(len(self.variants))], axis=0)
        self.calls[variant] += len(q)
        return self.variants[variant](q[:, 0])

    def best_variant(self, x, index, d):
        vals = [float(f(np.array([x[0]]))[0]) for f in self.variants]
        return max(vals), int(np.argmax(vals))


FREE = np.array([True, False, False])


def test_the_search_follows_the_larger_robot_and_switches_where_another_is_larger():
    # f0 = q is larger at the start q = 0, and climbs to q = 1, where f1 = 2q - 0.5 = 1.5 is larger
    p = _TwoRobots(lambda q: q, lambda q: 2 * q - 0.5)
    value, x = _local_search(p, None, 1.0, None, np.zeros(3), FREE, 100)
    assert x[0] == pytest.approx(1.0) and value == pytest.approx(1.5)
    assert value == pytest.approx(max(f(np.array([x[0]]))[0] for f in p.variants))


def test_each_start_climbs_its_own_robots_hill_and_evaluates_one_robot_per_step():
    # two hills: robot 0 peaks at q = 0.2 (value 0), robot 1 at q = -0.5 (value 0.1)
    p = _TwoRobots(lambda q: -((q - 0.2) ** 2), lambda q: 0.1 - (q + 0.5) ** 2)
    value, x = _local_search(p, None, 1.0, None, np.array([0.1, 0.0, 0.0]), FREE, 100)
    assert x[0] == pytest.approx(0.2, abs=1e-5) and value == pytest.approx(0.0, abs=1e-9)
    assert p.calls[1] == 0  # robot 1 was never the larger one on the way: never evaluated in the search
    value, x = _local_search(p, None, 1.0, None, np.array([-0.2, 0.0, 0.0]), FREE, 100)
    assert x[0] == pytest.approx(-0.5, abs=1e-5) and value == pytest.approx(0.1, abs=1e-9)
