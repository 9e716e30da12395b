"""Joint-space references for the closed-loop simulations: steps and minimum-jerk moves."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from polyrob.errors import ArgumentError

__all__ = ["Reference", "step_reference", "smooth_reference"]


@dataclass(frozen=True, eq=False)
class Reference:
    """A joint-space reference ``r(t)`` (shape (m,)).

    Attributes
    ----------
    kind : {"step", "smooth", "custom"}
    start, target : ndarray or None
        For steps and smooth moves: where it starts (``None``: the initial
        ``q``) and where it ends.
    duration : float
        Duration of a smooth move (0 for a step).
    function : callable or None
        ``r(t)`` for custom references.
    """

    kind: str
    target: np.ndarray | None = None
    start: np.ndarray | None = None
    duration: float = 0.0
    function: Callable | None = field(default=None, repr=False)

    def bind(self, q0) -> Callable:
        """``r(t)`` given the initial position (used as the start of a smooth move)."""
        if self.kind == "custom":
            return lambda t: np.asarray(self.function(t), float)
        target = np.asarray(self.target, float)
        if self.kind == "step":
            return lambda t: target
        start = np.asarray(q0 if self.start is None else self.start, float)
        T = float(self.duration)

        def r(t):
            s = min(max(t / T, 0.0), 1.0)
            # minimum-jerk (quintic) profile: zero velocity and acceleration at both ends
            return start + (target - start) * (10 * s**3 - 15 * s**4 + 6 * s**5)

        return r


def step_reference(target) -> Reference:
    """A step to ``target`` at ``t = 0``."""
    return Reference("step", target=np.asarray(target, float))


def smooth_reference(target, duration: float, start=None) -> Reference:
    """A minimum-jerk move from ``start`` (default: the initial ``q``) to ``target`` in ``duration`` s."""
    if not duration > 0:
        raise ArgumentError(f"a smooth reference needs a positive duration, got {duration}")
    return Reference(
        "smooth",
        target=np.asarray(target, float),
        start=None if start is None else np.asarray(start, float),
        duration=float(duration),
    )
