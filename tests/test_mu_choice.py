"""The μ upper-bound method is chosen by the structure, never by the clock.

A slow AB13MD (a busy machine) must give the same figures as a fast one; the
wall-clock limit of :func:`polyrob.analysis.mu.bounds.mu_bounds` is only a
safety net against a hung call, and says so in the notes when it fires.
"""

from __future__ import annotations

import inspect
import time

import control
import numpy as np
import pytest

from polyrob.analysis.mu import upper as mu_upper
from polyrob.analysis.mu.blocks import as_block_structure
from polyrob.analysis.mu.bounds import mu_bounds, mussv, resolve_method
from polyrob.analysis.mu.sweep import AB13MD_SAFETY_TIMEOUT, DESCENT_ABOVE, LARGE_AB13MD_TIMEOUT, MANY_REAL_SCALARS

#: seconds the stand-in below sleeps before each AB13MD call: above the old 1 s limit
SLOW = 1.5
OMEGA = np.array([0.3, 1.0, 3.0])


def _slow_ab13md(Z, nblock, itype, x=None):
    """AB13MD on a busy machine: the real routine, late (module level, so a worker process can unpickle it)."""
    time.sleep(SLOW)
    import slycot

    return slycot.ab13md(Z, nblock, itype) if x is None else slycot.ab13md(Z, nblock, itype, x)


def _loop(seed: int = 3, scale: float = 1.0) -> control.StateSpace:
    """A fixed stable 2x2 system with 4 states (lightly damped, so mu varies over OMEGA)."""
    rng = np.random.default_rng(seed)
    A = np.array([[-0.2, 1.0, 0, 0], [-1.0, -0.2, 0, 0], [0, 0, -0.5, 2.0], [0, 0, -2.0, -0.5]])
    B, C = rng.normal(size=(4, 2)), rng.normal(size=(2, 4))
    return control.ss(A, scale * B, C, 0.1 * rng.normal(size=(2, 2)))


@pytest.mark.parametrize(
    "blk",
    [
        pytest.param([[-1, 0], [1, 0]], id="real+complex scalar (AB13MD in a worker)"),
        pytest.param([[1, 1], [1, 1]], id="two complex scalars (AB13MD in-process)"),
    ],
)
def test_slow_ab13md_gives_the_same_bounds(monkeypatch, blk):
    idle = mu_bounds(_loop(), blk, OMEGA, refine_peak=False, progress=False)
    monkeypatch.setattr(mu_upper, "ab13md_call", _slow_ab13md)
    t0 = time.perf_counter()
    busy = mu_bounds(_loop(), blk, OMEGA, refine_peak=False, progress=False)
    # the stand-in really ran at every frequency (the old 1 s limit would have replaced it by the LMI)
    assert time.perf_counter() - t0 >= OMEGA.size * SLOW
    assert idle.method == busy.method == "ab13md"
    assert idle.notes == busy.notes == ()  # no fallback, nothing to report
    np.testing.assert_allclose(busy.upper, idle.upper, rtol=1e-9)
    np.testing.assert_allclose(busy.lower, idle.lower, rtol=1e-9)
    assert busy.peak_upper == pytest.approx(idle.peak_upper, rel=1e-9)
    assert idle.peak_upper > 0


def test_safety_net_fires_only_on_a_hung_call_and_says_so(monkeypatch):
    """A limit below the call's time (here set on purpose) replaces AB13MD, and the notes say where and why."""
    blk = [[-1, 0], [1, 0]]
    omega = OMEGA[:2]
    idle = mu_bounds(_loop(), blk, omega, refine_peak=False, progress=False)
    monkeypatch.setattr(mu_upper, "ab13md_call", _slow_ab13md)
    hung = mu_bounds(_loop(), blk, omega, refine_peak=False, progress=False, ab13md_timeout=0.3)
    assert hung.method == "ab13md"  # the method chosen; the notes say it did not answer
    assert len(hung.notes) >= 1
    note = hung.notes[0]
    assert "safety limit" in note and f"at {omega.size} frequencies" in note and "D-G LMI" in note
    # the LMI's is a true upper bound too, but another number (here up to about 1 % below AB13MD's):
    # the reason the limit must never fire on a merely slow call
    assert np.all(hung.upper >= idle.lower * (1 - 1e-9)) and np.all(hung.upper >= hung.lower * (1 - 1e-9))
    np.testing.assert_allclose(hung.upper, idle.upper, rtol=0.05)


def test_default_limits_are_safety_nets_not_method_switches():
    params = inspect.signature(mu_bounds).parameters
    assert params["ab13md_timeout"].default == AB13MD_SAFETY_TIMEOUT >= 30
    assert params["warm_timeout"].default == AB13MD_SAFETY_TIMEOUT
    assert LARGE_AB13MD_TIMEOUT >= AB13MD_SAFETY_TIMEOUT


@pytest.mark.parametrize(
    "blk, expected",
    [
        ([[1, 1], [1, 1]], "ab13md"),
        ([[-1, 0], [1, 0]], "ab13md"),
        ([[-1, 0]] * 8, "ab13md"),  # all real: AB13MD however slow it is at some frequencies
        ([[-1, 0]] * 10 + [[2, 4]], "ab13md"),
        ([[-1, 0]] * MANY_REAL_SCALARS + [[6, 12]], "ab13md"),  # large, no repeated block, few real scalars
        ([[-1, 0]] * (MANY_REAL_SCALARS + 1), "gradient"),  # an axes model's dozens: AB13MD takes seconds each
        ([[-2, 0], [1, 0]], "gradient"),  # repeated: descent, the LMI by name only (same bound, 10-400x slower)
        ([[2, 0], [1, 1]], "gradient"),
        ([[-3, 0]] * (DESCENT_ABOVE // 3 + 1), "gradient"),
    ],
)
def test_method_is_a_function_of_the_structure(blk, expected):
    assert resolve_method(as_block_structure(blk), "auto") == expected
    # nothing else goes in: no matrix, no time limit
    assert list(inspect.signature(resolve_method).parameters) == ["st", "method"]


def test_sweeps_of_different_loops_on_one_structure_use_one_method():
    blk = [[-1, 0], [1, 0]]
    expected = resolve_method(as_block_structure(blk), "auto")
    loops = [_loop(1, 1.0), _loop(2, 1e3), _loop(3, 1e-3)]
    methods = {mu_bounds(G, blk, OMEGA, refine_peak=False, progress=False).method for G in loops}
    rng = np.random.default_rng(0)
    methods.add(mussv(rng.normal(size=(2, 2)) + 1j * rng.normal(size=(2, 2)), blk, lower=False).method)
    assert methods == {expected}


def test_a_descent_that_stalls_is_answered_by_the_relaxed_ab13md_bound(monkeypatch):
    """xarm7's PID loop: descent gave 1.08 where AB13MD on the relaxed structure proves 0.53 (the lower bound)."""
    from polyrob.analysis.mu import sweep
    from polyrob.analysis.mu.gradient import GradientUpper

    sys = _loop(seed=5)
    blk = [[-1, 0], [1, 1]]  # no repeated scalar: the relaxed structure is this one, AB13MD's bound the best
    relaxed = mu_bounds(sys, blk, OMEGA, method="relaxed", progress=False, refine_peak=False)
    real_call = GradientUpper.__call__

    def stalled(self, Ms, x0=None):  # a true bound, three times too high
        beta, D, G, x = real_call(self, Ms, x0)
        return 3.0 * beta + 1.0, D, G, x

    monkeypatch.setattr(GradientUpper, "__call__", stalled)
    res = mu_bounds(sys, blk, OMEGA, method="gradient", progress=False, refine_peak=False)
    assert res.upper == pytest.approx(relaxed.upper, rel=1e-6)
    monkeypatch.setattr(sweep, "MANY_REAL_SCALARS", 0)  # one real scalar is too many now: AB13MD is not asked
    stalled_only = mu_bounds(sys, blk, OMEGA, method="gradient", progress=False, refine_peak=False)
    assert np.all(stalled_only.upper > 2.0 * relaxed.upper)


def test_a_warm_start_that_settles_high_is_answered_by_a_cold_descent(monkeypatch):
    """ur5's engineer's set with a PID tuned on true robots: warm-started descent gave 4.51 at 0.46 rad/s, cold 1.17."""
    from polyrob.analysis.mu import sweep
    from polyrob.analysis.mu.gradient import GradientUpper

    sys = _loop(seed=5)
    blk = [[-1, 0], [1, 1]]
    cold = [
        mussv(M, blk, method="gradient", lower=False).upper
        for M in control.frequency_response(sys, OMEGA).frdata.transpose(2, 0, 1)
    ]
    real_call = GradientUpper.__call__

    def settles_high(self, Ms, x0=None):  # from the previous frequency's scalings: a true bound, three times too high
        beta, D, G, x = real_call(self, Ms, x0)
        return (3.0 * beta + 1.0 if x0 is not None else beta), D, G, x

    monkeypatch.setattr(GradientUpper, "__call__", settles_high)
    monkeypatch.setattr(sweep, "MANY_REAL_SCALARS", 0)  # AB13MD on the relaxed structure is not asked
    res = mu_bounds(sys, blk, OMEGA, method="gradient", progress=False, refine_peak=False)
    # the peak is retried cold until it is a cold bound: every point above it was retried, the others are below
    assert res.peak_upper == pytest.approx(max(cold), rel=1e-6)
    assert np.all(res.upper >= res.lower)
