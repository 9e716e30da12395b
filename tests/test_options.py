"""Options objects instead of keyword flags: ``MusynOptions`` (its method a strategy) and ``BoundOptions``."""

from __future__ import annotations

import numpy as np
import pytest

import polyrob
from polyrob.bounds.options import BoundOptions, SearchEffort
from polyrob.errors import ArgumentError
from polyrob.synthesis.fixed.options import FixedStructureOptions
from polyrob.synthesis.options import FixedStructure, FullOrder, MusynOptions


def test_flat_musyn_keywords_become_one_options_object_with_its_method():
    opts = MusynOptions.build(
        structure="tf3", starts=2, seed=4, max_iter=7, options=FixedStructureOptions(kstep="frozen")
    )
    assert opts.method == FixedStructure("tf3", starts=2, seed=4, tuning=FixedStructureOptions(kstep="frozen"))
    assert opts.max_iter == 7 and opts.structure == "tf3"
    full = MusynOptions.build(d_order=(0, 1), patience=5, mixed=False)
    assert full.method == FullOrder(patience=5, d_order=(0, 1)) and full.mixed is False
    # keywords on top of an options object keep its method unless they choose another
    assert MusynOptions.build(opts, max_iter=3).method == opts.method
    assert MusynOptions.build(opts, structure="full").method == FullOrder()


def test_a_method_option_given_to_the_other_method_is_refused():
    with pytest.raises(ArgumentError, match=r"options \['d_order'\] apply to the full-order synthesis only"):
        MusynOptions.build(structure="pid", d_order=(0, 1))
    with pytest.raises(ArgumentError, match=r"unexpected options for a full-order synthesis: \['starts'\]"):
        MusynOptions.build(starts=3)
    with pytest.raises(ArgumentError, match=r"unknown musyn options \['max_iters'\]"):
        MusynOptions.build(max_iters=3)
    with pytest.raises(ArgumentError, match="must be a MusynOptions"):
        MusynOptions.build({"max_iter": 3})


def test_bound_options_sort_the_search_effort_and_check_counts():
    opts = BoundOptions.build(samples=256, verify_rounds=0, coverage=0, workers=1)
    assert opts.search == SearchEffort(samples=256, verify_rounds=0)
    assert (opts.coverage, opts.workers) == (0, 1)
    sized = SearchEffort().sized(active_positions=2)
    assert (sized.samples, sized.screen) == (1024, 131072)
    assert SearchEffort(samples=300).sized(8).samples == 300
    for bad, message in (({"samples": 0}, "samples must be >= 1"), ({"coverage": -1}, "coverage must be >= 0"),
                         ({"screen": 2.5}, "screen must be a whole number"), ({"sample": 3}, "unknown bound_pldi")):  # fmt: skip
        with pytest.raises(ArgumentError, match=message):
            BoundOptions.build(**bad)


def test_bound_pldi_takes_the_options_object_or_its_fields_flat():
    robot = polyrob.load_robot("paper_2r")
    opts = BoundOptions(search=SearchEffort(samples=256, verify_rounds=1), coverage=0, workers=1, progress=False)
    a = polyrob.bound_pldi(robot, options=opts)
    b = polyrob.bound_pldi(robot, samples=256, verify_rounds=1, coverage=0, workers=1, progress=False)
    assert a.entries == b.entries and a.info["samples"] == b.info["samples"] < 300  # 256 Sobol points + corners
    np.testing.assert_array_equal(a.lower, b.lower)
    np.testing.assert_array_equal(a.upper, b.upper)
    with pytest.raises(ArgumentError, match="samples must be >= 1"):
        polyrob.bound_pldi(robot, samples=0)
