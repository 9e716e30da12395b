"""Values the factors attain on a task box: the inner values that steer the branch and bound.

A side of an entry closes on a box when its proved bound is within the
tolerance of the largest value *attained* so far
(:func:`~polyrob.bounds.certified.factors.proof.prove_factor_ranges`).
On an arm's task box the entries' extremes sit at or near the box's
vertices in ``(q, qdot)`` (the box is small against the arm's curvature),
where neither random points nor the centres of the boxes the search
splits ever land: a side whose attained value stays a few tolerances
below the true extreme cannot close, however tight the enclosures, and
the search keeps splitting the corner (``tests/test_certified_attained.py``:
on a tenth of finger_edu's task the proof gives up with the random pilot
alone and closes in a few boxes with :func:`vertex_ascent`'s values).

The values here are float evaluations (Pinocchio's,
:meth:`~polyrob.bounds.certified.factors.ranges.FactorProblem.value_parts`):
they only steer, and never enter a proved bound.
"""

from __future__ import annotations

import numpy as np

__all__ = ["attained_range", "extremes_over_accelerations", "vertex_ascent", "CHUNK"]

#: Points evaluated at a time (a few megabytes of jets each).
CHUNK = 64


def attained_range(problem, q_lo, q_hi, qd_lo, qd_hi, a_lo, a_hi, n, rng):
    """Attained (float) values of the factors at ``n`` points with ``qdot`` and ``a`` at vertices: ``(F, m, 3m)`` min and max."""
    m = problem.m
    lo = hi = None
    for start in range(0, n, CHUNK):
        k = min(CHUNK, n - start)
        q = rng.uniform(q_lo, q_hi, (k, m))
        v = np.where(rng.random((k, m)) < 0.5, qd_lo, qd_hi)
        a = np.where(rng.random((k, m)) < 0.5, a_lo, a_hi)
        K = problem.values(q, v, a)
        lo = K.min(0) if lo is None else np.minimum(lo, K.min(0))
        hi = K.max(0) if hi is None else np.maximum(hi, K.max(0))
    return lo, hi


def extremes_over_accelerations(problem, x, a_lo, a_hi):
    """The smallest and largest value of every entry over the acceleration box, at points ``x = (q, qdot)`` ``(n, 2m)``.

    The factor is affine in ``a`` (on its ``q`` columns), so each extreme
    is a sum over the joints of the better end.  Returns ``(n, F, m, 3m)``
    twice.
    """
    m = problem.m
    lows, highs = [], []
    for start in range(0, len(x), CHUNK):
        chunk = x[start : start + CHUNK]
        K0, Ka = problem.value_parts(chunk[:, :m], chunk[:, m:])
        at_lo, at_hi = Ka * a_lo, Ka * a_hi  # (n, F, i, p, j)
        low, high = K0.copy(), K0.copy()
        low[..., :m] += np.minimum(at_lo, at_hi).sum(-1)
        high[..., :m] += np.maximum(at_lo, at_hi).sum(-1)
        lows.append(low)
        highs.append(high)
    return np.concatenate(lows), np.concatenate(highs)


def vertex_ascent(problem, x_lo, x_hi, a_lo, a_hi, *, rounds: int = 8, sides=None):
    """Extremes attained at vertices of the box ``[x_lo, x_hi]`` of ``x = (q, qdot)``, found by flipping one coordinate at a time.

    Every side of every entry (its largest and its smallest value) starts
    at the vertex its gradient at the box's centre points to (central
    differences) and moves to the best of its neighbours (one coordinate
    flipped) while that is better, for at most ``rounds`` rounds: a local
    search, which finds the extremes where they lie at vertices and the
    entry is monotone near them, and a lower bound of the true extremes
    always.  Sides that share a vertex share its evaluation.

    ``sides`` (bool ``(F, m, 3m, 2)``: the smallest, then the largest
    value) restricts the search to those sides, which costs less: the
    branch and bound's boxes search only their open sides
    (:func:`~polyrob.bounds.certified.factors.box_batches.enclose_batch`).

    Returns
    -------
    lower, upper : ndarray (F, m, 3m)
        The smallest and largest values attained at the vertices visited
        (``+inf`` and ``-inf`` on the sides not searched).
    """
    x_lo, x_hi = np.asarray(x_lo, float), np.asarray(x_hi, float)
    n = len(x_lo)
    centre, radius = 0.5 * (x_lo + x_hi), 0.5 * (x_hi - x_lo)
    step = np.where(radius > 0, 1e-4 * radius, 0.0)
    free = np.flatnonzero(radius > 0)
    pts = np.vstack([centre + step[p] * np.eye(n)[p] for p in free] + [centre - step[p] * np.eye(n)[p] for p in free])
    low, high = extremes_over_accelerations(problem, pts, a_lo, a_hi)
    objective = np.stack([-low, high], -1)  # maximise both: (n_pts, F, i, e, 2)
    shape = objective.shape[1:]
    slope = (objective[: len(free)] - objective[len(free) :]).reshape(len(free), -1)  # (free, S)
    searched = np.arange(slope.shape[1]) if sides is None else np.flatnonzero(np.asarray(sides, bool).reshape(-1))
    bits = np.zeros((len(searched), n), bool)
    bits[:, free] = (slope[:, searched] > 0).T
    best = np.full(len(bits), -np.inf)
    flips = np.eye(n, dtype=bool)[free]
    seen: dict[bytes, np.ndarray] = {}  # a vertex is evaluated once, however many rounds and sides visit it
    for _ in range(rounds if len(searched) else 0):
        candidates = np.concatenate([bits[None], bits[None] ^ flips[:, None]])  # (1 + free, S, n)
        unique, where = np.unique(candidates.reshape(-1, n), axis=0, return_inverse=True)
        new = [u for u in unique if u.tobytes() not in seen]
        if new:
            low, high = extremes_over_accelerations(problem, np.where(np.array(new), x_hi, x_lo), a_lo, a_hi)
            for u, row in zip(new, np.stack([-low, high], -1).reshape(len(new), -1)[:, searched]):
                seen[u.tobytes()] = row
        values = np.array([seen[u.tobytes()] for u in unique])
        S = len(bits)
        at = values[where.reshape(len(candidates), S), np.arange(S)]  # (1 + free, S)
        pick = np.argmax(at, 0)
        gained = at[pick, np.arange(S)] > best
        best = np.maximum(best, at[pick, np.arange(S)])
        bits = candidates[pick, np.arange(S)]
        if not gained.any():
            break
    full = np.full(int(np.prod(shape)), -np.inf)
    full[searched] = best
    full = full.reshape(shape)
    return -full[..., 0], full[..., 1]
