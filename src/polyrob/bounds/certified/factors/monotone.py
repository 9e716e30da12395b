"""The monotonicity test of the factors' branch and bound: where an entry's extreme over a box must lie.

An entry's largest value over a box lies on the face ``x_p = hi_p`` when its
derivative in ``x_p`` is proved non-negative on the whole box (at every
vertex of the acceleration box), and on ``x_p = lo_p`` when it is proved
non-positive; its smallest value on the other face.  So a side of an entry
that is monotone in ``x_p`` needs only that face: the classical monotonicity
test of interval global optimisation (Hansen and Walster, *Global
Optimization Using Interval Analysis*, 2nd ed., 2004), written here
because the factors' boxes carry hundreds of sides (every entry's lower and
upper bound) with their own faces.

Why it matters for the arms: an entry's extreme over the task lies at a
corner of the ``(q, qdot)`` box, and without the test every side still open
there is carried by both halves of every split until the boxes are a few
per cent of the task in *every* coordinate (docs/pldi.md: 60-80 splits per
branch).  With it, a side that is monotone in a coordinate drops the half
away from its face, and a box whose open sides all lie on one face of a
coordinate is replaced by that face (one dimension fewer, no split).

The result stays rigorous: a face is a subset of the box, its enclosure is
proved like any box's, and the side's extreme over the box is its extreme
over the face.

Examples
--------
One entry increasing in ``x_0`` (not proved monotone in ``x_1``), both sides
open, split along ``x_0``: its largest value is on the face ``x_0 = 1``,
its smallest on ``x_0 = 0``; neither face is split.

>>> import numpy as np
>>> lo, hi = np.zeros(2), np.ones(2)
>>> sign = np.array([[1, 0]])
>>> for c_lo, c_hi, sides, share in replace_box(lo, hi, np.array([[True, True]]), sign, 0, 1.0):
...     print(c_lo, c_hi, sides, share)
[1. 0.] [1. 1.] [[False  True]] 1.0
[0. 0.] [0. 1.] [[ True False]] 1.0

With only its upper side open the box is replaced by that face, whatever
the coordinate chosen for a split:

>>> [(c_lo.tolist(), c_hi.tolist()) for c_lo, c_hi, _, _ in replace_box(lo, hi, np.array([[False, True]]), sign, 1, 1.0)]
[([1.0, 0.0], [1.0, 1.0])]
"""

from __future__ import annotations

import numpy as np

__all__ = ["gradient_signs", "side_ends", "collapse", "replace_box"]


def gradient_signs(g_lo, g_hi) -> np.ndarray:
    """The proved sign of each derivative over the box at every acceleration vertex.

    ``g_lo``, ``g_hi``: proved bounds ``(n, B, ..., nv)`` of the derivative in
    each of the ``n`` coordinates at each of the ``nv`` vertices.  Returns
    int8 ``(B, ..., n)``: ``+1`` where it is ``>= 0`` at every vertex, ``-1``
    where ``<= 0`` at every vertex, ``0`` where neither is proved.
    """
    increasing = (g_lo >= 0).all(-1)
    decreasing = (g_hi <= 0).all(-1)
    sign = np.where(increasing, 1, np.where(decreasing, -1, 0)).astype(np.int8)
    return np.moveaxis(sign, 0, -1)


def side_ends(sign) -> np.ndarray:
    """The face of each coordinate where each side's extreme lies: ``(..., 2, n)``, sides ``(lower, upper)``.

    ``+1``: the upper face, ``-1``: the lower face, ``0``: not known.  The
    largest value of an increasing entry is on the upper face, its smallest
    on the lower one.
    """
    sign = np.asarray(sign, np.int8)
    return np.stack([-sign, sign], axis=-2)


def collapse(lo, hi, ends, sides):
    """The box with each coordinate set to a face where every side in ``sides`` has its extreme there.

    ``ends``: :func:`side_ends` ``(..., 2, n)``; ``sides``: bool ``(..., 2)``.
    Coordinates of zero width are left as they are.
    """
    if not sides.any():
        return lo, hi
    chosen = ends[sides]  # (k, n)
    wide = hi > lo
    up = (chosen == 1).all(0) & wide
    down = (chosen == -1).all(0) & wide
    lo, hi = lo.copy(), hi.copy()
    lo[up] = hi[up]
    hi[down] = lo[down]
    return lo, hi


def replace_box(lo, hi, still, sign, p: int, share: float) -> list:
    """The boxes that replace a box with open sides ``still``: ``[(lo, hi, sides, share), ...]``.

    Parameters
    ----------
    lo, hi : ndarray (n,)
        The box.
    still : bool ndarray (..., 2)
        The sides still open on it (``lower``, ``upper`` of every entry).
    sign : int ndarray (..., n)
        :func:`gradient_signs` on the box.
    p : int
        The coordinate to split along when no face replaces the whole box.
    share : float
        The box's share of the work (the progress line's volume); each side
        keeps its share: a face carries the box's, a half half of it.

    Returns
    -------
    list of (lo, hi, sides, share)
        If every open side has its extreme on one face of some coordinates,
        the box reduced to those faces, with every side.  Otherwise a split
        along ``p``: the sides with their extreme on a face of ``p`` go to that
        face, the others to both halves; each child then reduced to the
        faces its own sides share.
    """
    ends = side_ends(sign)
    c_lo, c_hi = collapse(lo, hi, ends, still)
    if np.any(c_hi - c_lo < hi - lo):
        return [(c_lo, c_hi, still, share)]
    end_p = ends[..., p]
    to_hi, to_lo, both = still & (end_p == 1), still & (end_p == -1), still & (end_p == 0)
    children = []
    if to_hi.any():
        f_lo = lo.copy()
        f_lo[p] = hi[p]
        children.append((*collapse(f_lo, hi, ends, to_hi), to_hi, share))
    if to_lo.any():
        f_hi = hi.copy()
        f_hi[p] = lo[p]
        children.append((*collapse(lo, f_hi, ends, to_lo), to_lo, share))
    if both.any():
        mid = 0.5 * (lo[p] + hi[p])
        for half in (0, 1):
            h_lo, h_hi = lo.copy(), hi.copy()
            (h_hi if half == 0 else h_lo)[p] = mid
            children.append((*collapse(h_lo, h_hi, ends, both), both, 0.5 * share))
    return children
