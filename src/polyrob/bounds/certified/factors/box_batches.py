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

__all__ = ["enclose_batch", "split_map"]


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
    boxes, a_lo, a_hi, taylor = item
    entries = boxes[4] if len(boxes) > 4 else None
    check = boxes[5] if len(boxes) > 5 else None
    return problem.enclose(*boxes[:4], a_lo, a_hi, taylor=taylor, attained=True, entries=entries, check_inverse=check)


def enclose_batch(pool, boxes, a_lo, a_hi, *, taylor: bool) -> tuple:
    """``pool.state.enclose(*boxes[:4], a_lo, a_hi, taylor=taylor, attained=True, entries=boxes[4], check_inverse=boxes[5])``, shared among the workers.

    ``pool``: a :class:`~polyrob.bounds.parallel.WorkerPool` whose state is
    the :class:`~polyrob.bounds.certified.factors.ranges.FactorProblem`;
    ``boxes``: ``(q_lo, q_hi, qd_lo, qd_hi)``, each ``(B, m)``, and
    optionally the entries still open on each box ``(B, F, m, 3m)`` and the
    boxes whose inverse is checked first ``(B,)`` (``check_inverse``).
    """
    return split_map(pool, _enclose_part, tuple(boxes), a_lo, a_hi, taylor)
