"""Wall-clock time in polyrob: a time limit the user sets, and nothing else that decides.

Every give-up that decides a status is bounded by work (points, boxes,
iterations, evaluations), never by seconds: the same command gives the same
verdict on an idle and on a loaded machine.  A wall-clock limit is only a
safety net the user sets (``--time-limit``, ``time_limit=...``), and when it
fires the result names it: :meth:`UserTimeLimit.words`.

Progress lines and timings read the clock too (:mod:`polyrob.progress`), but
decide nothing.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

from polyrob.errors import ArgumentError

__all__ = ["UserTimeLimit"]


@dataclass(frozen=True)
class UserTimeLimit:
    """A wall-clock limit the user set: ``seconds`` counted from ``start`` (a ``time.perf_counter()`` value).

    Examples
    --------
    >>> limit = UserTimeLimit.starting_now(30)
    >>> limit.passed(), limit.words
    (False, 'the time limit of 30 s you set')
    """

    seconds: float
    start: float

    @classmethod
    def starting_now(cls, seconds: float | None) -> UserTimeLimit | None:
        """The limit from now, or ``None`` when no limit was set."""
        if seconds is None:
            return None
        if not seconds > 0:
            raise ArgumentError(f"a time limit must be > 0 seconds, got {seconds}")
        return cls(float(seconds), time.perf_counter())

    def passed(self) -> bool:
        return time.perf_counter() - self.start >= self.seconds

    @property
    def words(self) -> str:
        """What stopped the work, for a verdict: "the time limit of N s you set"."""
        return f"the time limit of {self.seconds:g} s you set"
