"""Dense screens of the domain for start positions: one Jacobian per point, no inner maximisation.

:func:`polyrob.bounds.pldi.bound_pldi` screens the whole domain (and later the
neighbourhood of its witnesses) for positions near narrow peaks that the
position design straddles; the local search starts from the best of them.
"""

from __future__ import annotations

import numpy as np

from polyrob.bounds.search import Problem

__all__ = ["screen", "SCREEN_BATCH"]


def _screen_task(problem: Problem, item):
    b, seed, directions, index, axis, other, col, coef, around = item
    m, n = problem.m, SCREEN_BATCH
    if around is None:
        q, qdot, u = problem.domain.split(problem.domain.sample_box(n, method="uniform", seed=[seed, b]))
    else:
        rng = np.random.default_rng([seed, b])
        base = around[rng.integers(len(around), size=n)]
        sigma = np.exp(rng.uniform(np.log(0.03), np.log(0.3), size=(n, 1)))
        step = rng.standard_normal(base.shape) * sigma * (problem.hi - problem.lo)
        x = np.clip(base + step, problem.lo, problem.hi)
        q, qdot, u = x[:, :m], x[:, m : 2 * m], x[:, 2 * m :]
    v = np.empty((len(q), len(directions)))
    # one Jacobian per point, of the variants (an inner loop's true robots) in turn: the screen
    # looks for positions, and theirs peak where the robot's do (the same arm, masses within a few %)
    V = len(problem.variants)
    for i in range(V):
        e = problem.entries_at(q[i::V], qdot[i::V], u[i::V], index, i)
        v[i::V, axis] = e[:, col] * coef
        v[i::V, other] = e @ directions[other].T
    arg = np.argmax(v, axis=0)
    return v[arg, np.arange(len(directions))], q[arg]


#: Points per screening batch; each batch gives its best point per direction.
SCREEN_BATCH = 16384


def screen(problem: Problem, directions, index, n: int, per_direction: int, seed, pool, around=None):
    """The best positions of ``n`` random points of the domain, per direction.

    One Jacobian per point (no inner maximisation) makes this ~40 times
    cheaper per position than :func:`inner_maxima`: a dense, coarse look for
    narrow peaks (near-singular mass matrices) that the position design
    straddles.  Each batch of 16,384 points gives its best point; the
    ``per_direction`` best batches' points are returned, positions (D, s, m).

    Parameters
    ----------
    around : ndarray (w, 3m), optional
        Draw the points near these (the witnesses found so far) instead of
        uniformly: each point is a random one of them plus a normal step of
        3-30 % of the domain's width (log-uniform), clipped into the domain.
        The peaks of the entries gather where the mass matrix is nearly
        singular, so the witnesses of all directions mark where to look.
    """
    m = problem.m
    batches = max(per_direction, int(np.ceil(n / SCREEN_BATCH)))
    # directions along one entry (the intervals) need a column, not a product
    nonzero = directions != 0
    axis = np.flatnonzero(nonzero.sum(axis=1) == 1)
    other = np.setdiff1d(np.arange(len(directions)), axis)
    col = np.argmax(nonzero[axis], axis=1)
    coef = directions[axis, col]
    items = [(b, seed, directions, index, axis, other, col, coef, around) for b in range(batches)]
    out = pool.map(_screen_task, items, label="screening")
    vals = np.array([o[0] for o in out])  # (batches, D)
    pos = np.array([o[1] for o in out])  # (batches, D, m)
    top = np.argsort(-vals, axis=0)[:per_direction]  # (s, D)
    return np.moveaxis(pos[top, np.arange(len(directions))[None]], 0, 1).reshape(len(directions), -1, m)
