"""Branch and bound over boxes: prove a property on every box by bisecting the ones that fail.

Used by the moving robot's check between the grid points
(:mod:`polyrob.analysis.lpv.cells`): ``evaluate(lo, hi)`` returns a tuple whose
first item is a margin (``> 0``: proved on the box, ``-inf``: refuted at a
point, give up) and whose last item says why it failed; a box that fails is
bisected, along the coordinate of largest ``value[1]`` when
``by_contribution`` (a first-order bound per coordinate), else along the one
whose worse half does best (both halves evaluated).

Examples
--------
>>> import numpy as np
>>> def evaluate(lo, hi):              # x^2 <= 1.01 on [-1, 1], by the box's largest |x|, needs a few splits
...     top = max(abs(lo[0]), abs(hi[0]))
...     return 1.01 - top**2 * (1 + (hi[0] - lo[0])), "x^2 may exceed 1.01"
>>> ok, leaves, why = prove_on_boxes([(np.array([-1.0]), np.array([1.0]))], evaluate, np.array([2.0]),
...                                  min_width=1e-6, max_boxes=1000)
>>> ok, len(leaves) > 2
(True, True)
"""

from __future__ import annotations

import time
from collections import deque

import numpy as np

__all__ = ["prove_on_boxes", "prove_on_boxes_in_batches", "box_words"]


def _bisect(queue, evaluate, lo, hi, width0, min_width, contrib=None):
    """Split ``[lo, hi]``: along the coordinate of largest ``contrib`` when given, else the one whose worse half
    does best (both halves evaluated); queue both halves."""
    rel = (hi - lo) / width0
    if contrib is not None:
        ok = (hi > lo) & (rel >= min_width)
        if not np.any(ok):
            return False
        i = int(np.argmax(np.where(ok, contrib, -np.inf)))
        h1, l2 = hi.copy(), lo.copy()
        h1[i] = l2[i] = 0.5 * (lo[i] + hi[i])
        queue.extend([(lo, h1, None), (l2, hi, None)])
        return True
    best = None
    for i in range(len(lo)):  # among the relatively widest coordinates, so that every one shrinks in turn
        if hi[i] == lo[i] or rel[i] < min_width or rel[i] < 0.5 * rel.max():
            continue
        h1, l2 = hi.copy(), lo.copy()
        h1[i] = l2[i] = 0.5 * (lo[i] + hi[i])
        a, b = evaluate(lo, h1), evaluate(l2, hi)
        if best is None or min(a[0], b[0]) > best[0]:
            best = (min(a[0], b[0]), (lo, h1, a), (l2, hi, b))
    if best is None:
        return False
    queue.extend(best[1:])
    return True


def prove_on_boxes(boxes, evaluate, width0, *, min_width, max_boxes, time_limit=None, bar=None, by_contribution=False,
                   on_proved=None):  # fmt: skip
    """Branch and bound: ``(True, leaves' values, "")`` when every leaf has a positive margin, else ``(False, ..., why)``.

    It gives up past ``max_boxes`` boxes (a count of work: the answer does not
    depend on the machine's load), or past ``time_limit`` wall-clock seconds,
    a safety net only a caller sets (``None``: none), which ``why`` then names.
    ``on_proved(lo, hi)`` is called on each leaf proved (e.g. to report the
    volume done).
    """
    t0 = time.perf_counter()
    queue, leaves = deque((lo, hi, None) for lo, hi in boxes), []
    while queue:
        lo, hi, known = queue.popleft()
        value = known if known is not None else evaluate(lo, hi)
        if value[0] == -np.inf:  # a point where it fails: no need to look further
            return False, leaves, value[-1]
        if value[0] > 0:
            leaves.append(value)
            if bar is not None:
                bar.update(1)
            if on_proved is not None:
                on_proved(lo, hi)
            continue
        stop = _stop(leaves, len(queue), max_boxes, time_limit, t0, value, lo, hi)
        if stop is not None:
            return stop
        if not _bisect(queue, evaluate, lo, hi, width0, min_width, value[1] if by_contribution else None):
            return False, leaves, f"{value[-1]} at rho in {box_words(lo, hi)} (a cell at the smallest width)"
        if bar is not None:
            bar.total += 1  # shown at the bar's next update (a refresh per split floods the terminal)
    return True, leaves, ""


def prove_on_boxes_in_batches(boxes, evaluate_many, width0, *, min_width, max_boxes, batch, observe=None,
                              time_limit=None, bar=None, on_proved=None):  # fmt: skip
    """:func:`prove_on_boxes` with ``by_contribution``, its boxes evaluated ``batch`` at a time by ``evaluate_many``.

    ``evaluate_many(list of (lo, hi)) -> list of values`` may run them in
    other processes.  The boxes leave the queue in the order the one-by-one
    search takes them (first in, first out), and the values are then read in
    that order by the same rules, so the answer is the one of
    :func:`prove_on_boxes`: the same leaves, the same reason, the same count
    at which the ``max_boxes`` limit gives up.  Only the work differs: up to
    ``batch - 1`` boxes past the one that ends a failed search are evaluated
    and ignored.  ``observe(value)`` is called on each value read, in that
    order (not on the ignored ones), ``on_proved(lo, hi)`` on each leaf proved.
    """
    t0 = time.perf_counter()
    queue, leaves = deque((lo, hi) for lo, hi in boxes), []
    while queue:
        taken = [queue.popleft() for _ in range(min(batch, len(queue)))]
        values = evaluate_many(taken)
        for index, ((lo, hi), value) in enumerate(zip(taken, values)):
            if observe is not None:
                observe(value)
            if value[0] == -np.inf:
                return False, leaves, value[-1]
            if value[0] > 0:
                leaves.append(value)
                if bar is not None:
                    bar.update(1)
                if on_proved is not None:
                    on_proved(lo, hi)
                continue
            waiting = len(taken) - index - 1 + len(queue)  # the one-by-one search's queue at this box
            stop = _stop(leaves, waiting, max_boxes, time_limit, t0, value, lo, hi)
            if stop is not None:
                return stop
            halves = deque()
            if not _bisect(halves, None, lo, hi, width0, min_width, value[1]):
                return False, leaves, f"{value[-1]} at rho in {box_words(lo, hi)} (a cell at the smallest width)"
            queue.extend((a, b) for a, b, _ in halves)
            if bar is not None:
                bar.total += 1
    return True, leaves, ""


def _stop(leaves, waiting, max_boxes, time_limit, t0, value, lo, hi):
    """The give-up answer of both searches at a box that needs splitting, or ``None`` (go on)."""
    if len(leaves) + waiting >= max_boxes:
        why = f"gave up after {len(leaves)} cells (the limit of {max_boxes} cells)"
    elif time_limit is not None and time.perf_counter() - t0 > time_limit:
        why = f"stopped by the time limit of {time_limit:g} s you set, after {len(leaves)} cells"
    else:
        return None
    return False, leaves, f"{why}: {value[-1]} at rho in {box_words(lo, hi)}"


def box_words(lo, hi) -> str:
    """``[a, b] x [c, d]``."""
    return " x ".join(f"[{a:.4g}, {b:.4g}]" for a, b in zip(lo, hi))
