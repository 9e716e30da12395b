"""Exact witnesses: the maximiser over the velocity/torque box at given positions, per direction.

Split from :mod:`polyrob.bounds.search` (which re-exports :func:`exact_witnesses`);
``problem`` is its :class:`~polyrob.bounds.search.Problem`.  With several
variants (the true robots of an inner loop, :mod:`polyrob.model.inner`)
the best of them gives each value and point.
"""

from __future__ import annotations

import numpy as np

from polyrob.bounds.extremes import box_maximum, polynomial_coefficients

__all__ = ["exact_witnesses", "witness_task"]


def witness_task(problem, item):
    """The exact maximiser over the velocity/torque box of ``d . p`` per position, best of the variants."""
    qq, d, index = item  # one polynomial d . p per position
    best, x = None, None
    for i in range(len(problem.variants)):  # the best of the true robots
        c, a, b, Q = polynomial_coefficients(
            lambda x, y, z, i=i: problem.entries_at(x, y, z, index, i),
            qq,
            problem.t_centre,
            problem.t_scale,
            problem.u_centre,
            problem.u_scale,
        )
        val, t, u = box_maximum(
            np.einsum("nk,nk->n", c, d)[:, None],
            np.einsum("nmk,nk->nm", a, d)[..., None],
            np.einsum("nmk,nk->nm", b, d)[..., None],
            np.einsum("nijk,nk->nij", Q, d)[..., None],
            problem.t_scale > 0,
            problem.u_scale > 0,
            exact=True,
        )
        xi = np.hstack([qq, problem.t_centre + problem.t_scale * t[:, 0], problem.u_centre + problem.u_scale * u[:, 0]])
        if best is None:
            best, x = val[:, 0], xi
        else:
            up = val[:, 0] > best
            best, x = np.where(up, val[:, 0], best), np.where(up[:, None], xi, x)
    return best, x


def exact_witnesses(problem, positions, directions, index, pool):
    """The exact maximiser over the velocity/torque box at given positions, per direction.

    Parameters
    ----------
    positions : ndarray (D, S, m)
        ``S`` positions for each of the ``D`` directions.

    Returns
    -------
    points : ndarray (D, S, 3m)
        ``(q, qdot, u)``, per direction sorted best first.
    values : ndarray (D, S)
    """
    m = problem.m
    D, S, _ = positions.shape
    pair_dir = np.repeat(np.arange(D), S)
    pair_q = positions.reshape(D * S, m)
    chunks = np.array_split(np.arange(D * S), max(1, int(np.ceil(D * S / 64))))
    out = pool.map(witness_task, [(pair_q[c], directions[pair_dir[c]], index) for c in chunks], label="witnesses")
    vals = np.concatenate([o[0] for o in out]).reshape(D, S)
    points = np.vstack([o[1] for o in out]).reshape(D, S, 3 * m)
    order = np.argsort(-vals, axis=1, kind="stable")
    return np.take_along_axis(points, order[..., None], axis=1), np.take_along_axis(vals, order, axis=1)
