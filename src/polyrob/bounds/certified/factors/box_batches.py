"""The branch and bound's batches of boxes, enclosed on worker processes.

:func:`~polyrob.bounds.certified.factors.proof.prove_factor_ranges` encloses
its boxes :data:`~polyrob.bounds.certified.factors.proof.BATCH` at a time
(vectorised); :func:`enclose_batch` splits each batch among the workers of a
:class:`~polyrob.bounds.parallel.WorkerPool` (the problem sent to each worker
once) and joins the parts in the batch's order.  Every box's enclosure is
computed on its own, except for the grid of the cells the open entries'
Taylor form is bounded on (:func:`~polyrob.bounds.certified.factors.taylor2.cell_grid`:
finer when a call holds fewer open entries), so a worker's share of a
batch may get a slightly tighter bound; each is a proof either way.

Examples
--------
>>> import numpy as np
>>> from polyrob.bounds.parallel import WorkerPool
>>> def scaled(scale, item):          # a module-level fn(state, (parts, *extra)) returning arrays
...     (part,), offset = item
...     return (scale * part + offset,)
>>> with WorkerPool(2.0, workers=1) as pool:
...     split_map(pool, scaled, (np.arange(3.0),), 1.0)[0].tolist()
[1.0, 3.0, 5.0]
"""

from __future__ import annotations

import numpy as np

from polyrob.bounds.certified.factors.attained import vertex_ascent

__all__ = ["enclose_batch", "split_map", "NEAR"]

#: A box's vertex ascent searches the open sides whose bound is within this many tolerances of the value
#: attained: a better inner value closes those; a wider gap is the enclosure's, and only a split closes it.
NEAR = 3.0


def split_map(pool, fn, arrays: tuple, *extra) -> tuple:
    """``fn(pool.state, (parts, *extra))`` on parts of ``arrays`` (sharing their first axis), results joined.

    The arrays are cut into at most ``pool.workers`` consecutive parts, and
    each result (a tuple of arrays with that leading axis) is concatenated
    in order.  With one part the call runs in this process.
    """
    n = len(arrays[0])
    cuts = [c for c in np.array_split(np.arange(n), max(1, min(pool.workers, n))) if len(c)]
    items = [(tuple(x[c] for x in arrays), *extra) for c in cuts]
    if len(items) == 1:
        return fn(pool.state, items[0])
    parts = pool.map(fn, items, own_progress=False)  # one step of the caller's loop, which reports its progress
    return tuple(np.concatenate([p[k] for p in parts]) for k in range(len(parts[0])))


def _enclose_part(problem, item) -> tuple:
    boxes, a_lo, a_hi, taylor, *ascent = item
    entries = boxes[4] if len(boxes) > 4 else None
    check = boxes[5] if len(boxes) > 5 else None
    out = problem.enclose(*boxes[:4], a_lo, a_hi, taylor=taylor, attained=True, entries=entries, check_inverse=check)
    if ascent and ascent[0] is not None and len(boxes) > 6:
        _ascend_open_sides(problem, boxes, out, a_lo, a_hi, *ascent[0])
    return out


def _ascend_open_sides(problem, boxes, out, a_lo, a_hi, rounds, p_lo, p_hi, tol) -> None:
    """Add to each box's values attained those :func:`~polyrob.bounds.certified.factors.attained.vertex_ascent` finds on its sides still open.

    A side is searched when it was open on the box (``boxes[6]``) and its
    bound here is more than ``tol`` and at most :data:`NEAR` times ``tol``
    past the values attained so far (``p_lo``, ``p_hi``, as the batch
    began; the bound before the intersection with the parent's): the sides
    whose closing waits for a better inner value.  Their extremes often lie
    at the box's own vertices, where no centre lands; the values only steer
    (``out[3]``, ``out[4]``, in place).
    """
    lo, hi, _, seen_lo, seen_hi, _ = out
    for b in np.flatnonzero(np.isfinite(hi).all((1, 2, 3)) & np.isfinite(lo).all((1, 2, 3))):
        gap = np.stack([p_lo - lo[b], hi[b] - p_hi], -1) / tol[..., None]  # in tolerances
        still = boxes[6][b] & (gap > 1) & (gap <= NEAR)
        if still.any():
            x_lo, x_hi = np.concatenate([boxes[0][b], boxes[2][b]]), np.concatenate([boxes[1][b], boxes[3][b]])
            at_lo, at_hi = vertex_ascent(problem, x_lo, x_hi, a_lo, a_hi, rounds=rounds, sides=still)
            seen_lo[b], seen_hi[b] = np.fmin(seen_lo[b], at_lo), np.fmax(seen_hi[b], at_hi)


def enclose_batch(pool, boxes, a_lo, a_hi, *, taylor: bool, ascent=None) -> tuple:
    """``pool.state.enclose(*boxes[:4], a_lo, a_hi, taylor=taylor, attained=True, entries=boxes[4], check_inverse=boxes[5])``, shared among the workers.

    ``pool``: a :class:`~polyrob.bounds.parallel.WorkerPool` whose state is
    the :class:`~polyrob.bounds.certified.factors.ranges.FactorProblem`;
    ``boxes``: ``(q_lo, q_hi, qd_lo, qd_hi)``, each ``(B, m)``, and
    optionally the entries still open on each box ``(B, F, m, 3m)``, the
    boxes whose inverse is checked first ``(B,)`` (``check_inverse``) and
    the sides open on each box ``(B, F, m, 3m, 2)``.  ``ascent``, with the
    open sides: ``(rounds, p_lo, p_hi, tol)``, a vertex ascent of that
    many rounds on each box's sides that its enclosure leaves open against
    the values attained ``p_lo``, ``p_hi`` (:func:`_ascend_open_sides`),
    on the workers too.
    """
    return split_map(pool, _enclose_part, tuple(boxes), a_lo, a_hi, taylor, ascent)
