"""Clocks for the tests of time limits: no test depends on how fast this machine is today.

:func:`slowed_clock` makes ``time.perf_counter`` and ``time.monotonic`` run
``factor`` times faster than the wall clock, as a machine ``factor`` times
more loaded would see them; :class:`FakeClock` is a clock that moves only
when told (or by a fixed step per reading).
"""

from __future__ import annotations

import time


def slowed_clock(monkeypatch, factor: float = 1000.0) -> None:
    """Every second of work reads as ``factor`` seconds on ``time.perf_counter`` and ``time.monotonic``."""
    for name in ("perf_counter", "monotonic"):
        real = getattr(time, name)
        start = real()
        monkeypatch.setattr(time, name, lambda real=real, start=start: start + factor * (real() - start))


class FakeClock:
    """A clock at ``now`` that moves by ``step`` at each reading and by :meth:`advance`."""

    def __init__(self, now: float = 1000.0, step: float = 0.0):
        self.now, self.step = float(now), float(step)

    def __call__(self) -> float:
        self.now += self.step
        return self.now

    def advance(self, seconds: float) -> None:
        self.now += float(seconds)

    def install(self, monkeypatch) -> FakeClock:
        """Make it ``time.perf_counter`` and ``time.monotonic``."""
        monkeypatch.setattr(time, "perf_counter", self)
        monkeypatch.setattr(time, "monotonic", self)
        return self
