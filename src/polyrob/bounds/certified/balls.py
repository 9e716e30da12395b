"""Ball (``arb``) helpers of the certified bounds: outward conversion to floats, squares, hulls.

``float()`` of an ``arb`` rounds to nearest; :func:`arb_upper` and
:func:`arb_lower` move the result one ulp outward when an exact comparison
shows it fell inside, so every float they return is a rigorous bound.

Examples
--------
>>> from flint import arb
>>> x = arb(1) / 3
>>> arb_lower(x) <= 1 / 3 <= arb_upper(x)
True
>>> arb_upper(sq(ball(-1.0, 2.0))) >= 4.0   # the square of [-1, 2] is [0, 4]
True
"""

from __future__ import annotations

import numpy as np
from flint import arb

__all__ = ["arb_upper", "arb_lower", "sq", "ball"]


def arb_upper(x: arb) -> float:
    """Float >= every point of ``x`` (``float()`` rounds to nearest: fix up)."""
    u = x.upper()  # exact (radius-zero) ball
    f = float(u)
    if not arb(f) >= u:  # exact comparison of two exact balls
        f = float(np.nextafter(f, np.inf))
    return f


def arb_lower(x: arb) -> float:
    """Float <= every point of ``x``."""
    lo = x.lower()
    f = float(lo)
    if not arb(f) <= lo:
        f = float(np.nextafter(f, -np.inf))
    return f


def sq(x: arb) -> arb:
    """Tight enclosure of ``x^2`` (ball multiplication would allow negatives)."""
    a = x.abs_upper()
    if x > 0 or x < 0:
        b = x.abs_lower()
        return (b * b).union(a * a)
    return arb(0).union(a * a)


def ball(lo: float, hi: float) -> arb:
    """The ball holding ``[lo, hi]`` (exact when ``lo == hi``)."""
    return arb(lo) if lo == hi else arb(lo).union(arb(hi))
