"""The checked numbers of a robot-uncertainty file: each refusal one :class:`ArgumentError` line naming the key."""

from __future__ import annotations

import math

from polyrob.errors import ArgumentError

__all__ = ["fail", "finite", "pair", "vector3"]


def fail(text: str):
    raise ArgumentError(f"robot uncertainty: {text}")


def finite(value, where: str) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        fail(f"{where}: {value!r} is not a number")
    if not math.isfinite(x):
        fail(f"{where}: {x:g} is not a finite number")
    return x


def pair(value, where: str, *, nonnegative: bool = False) -> tuple[float, float]:
    """``[lo, hi]`` (or one number ``v`` meaning ``[v, v]``) of finite numbers with ``lo <= hi``."""
    items = list(value) if isinstance(value, (list, tuple)) else [value]
    if len(items) not in (1, 2):
        fail(f"{where}: give [LO, HI], got {value!r}")
    lo, hi = finite(items[0], where), finite(items[-1], where)
    if nonnegative and lo < 0:
        fail(f"{where}: must be >= 0, got {lo:g}")
    if lo > hi:
        fail(f"{where}: [{lo:g}, {hi:g}] has its lower bound above its upper bound: give LO <= HI")
    return lo, hi


def vector3(value, where: str) -> tuple[float, float, float]:
    items = list(value) if isinstance(value, (list, tuple)) else None
    if items is None or len(items) != 3:
        fail(f"{where}: give 3 numbers [x, y, z] (m), got {value!r}")
    return tuple(finite(v, where) for v in items)
