"""Local search from the starts of :mod:`polyrob.bounds.search`: refining each support value.

:func:`refine` runs a bounded L-BFGS-B search from every start of every
direction; :func:`cross_seed` searches each direction again from the other
directions' witnesses.  Both never lower a support value, and run their
per-direction tasks on the bound's :class:`~polyrob.bounds.parallel.WorkerPool`.
"""

from __future__ import annotations

import numpy as np
from scipy import optimize

from polyrob.bounds.search import Problem, exact_witnesses, inner_maxima
from polyrob.bounds.witnesses import witness_task

__all__ = ["refine", "cross_seed"]


def cross_seed(
    problem: Problem, directions, values, witnesses, index, dropped, depends, progress, pool, rounds: int = 3
):
    """Search each direction again from the other directions' witnesses where those are higher.

    The entries share their sharp peaks (where the mass matrix is nearly
    singular, ``M^-1`` and everything it multiplies is large), so the position
    where one direction's maximum was found is often a better start for
    another than any of its own.  Repeats while something improves.
    """
    values, witnesses = values.copy(), witnesses.copy()
    m = problem.m
    for _ in range(rounds):
        q = np.unique(witnesses[:, :m], axis=0)
        vals, _ = inner_maxima(problem, q, directions, index, False, pool)  # (W, D)
        best = np.argmax(vals, axis=0)
        better = np.flatnonzero(vals[best, np.arange(len(directions))] > values + 1e-9 * (1.0 + np.abs(values)))
        if not better.size:
            break
        starts, start_vals = exact_witnesses(problem, q[best[better]][:, None], directions[better], index, pool)
        v_ref, w_ref = refine(
            problem, directions[better], start_vals[:, 0], starts, index, dropped, progress, pool, depends[better]
        )
        up = v_ref > values[better]
        values[better[up]], witnesses[better[up]] = v_ref[up], w_ref[up]
    return values, witnesses


def _local_search(problem: Problem, d, value, index, x0, free, maxiter, coarse=False):
    """L-BFGS-B on ``d . p`` over the free coordinates of ``x0``, best of the variants.

    With several variants (the true robots of an inner loop) the search
    follows the one that is largest at its start, a smooth function, instead
    of their maximum (kinked where they cross, and one Jacobian per variant
    per evaluation); where another variant is larger at the end, it goes on
    from there with that one.
    """
    x = x0
    best, variant = problem.best_variant(x0, index, d)
    for _ in range(len(problem.variants)):
        x = _variant_search(problem, d, value, index, x, free, maxiter, coarse, variant)
        best, following = problem.best_variant(x, index, d)
        if following == variant:
            break
        variant = following
    return best, x


def _variant_search(problem: Problem, d, value, index, x0, free, maxiter, coarse, variant):
    """L-BFGS-B on one variant's ``d . p`` (central-difference gradients): the point reached."""
    m = problem.m
    lo, hi = problem.lo, problem.hi
    span = np.where(hi > lo, hi - lo, 1.0)
    scale = max(abs(value), 1e-12)
    step = 1e-6
    pos = np.flatnonzero(free)
    nfree = len(pos)

    def fun(y):
        x = x0.copy()
        x[free] = y
        # value and central-difference gradient in one batched evaluation
        pts = np.tile(x, (1 + 2 * nfree, 1))
        h = step * span[pos]
        pts[1 + np.arange(nfree), pos] += h
        pts[1 + nfree + np.arange(nfree), pos] -= h
        pts = np.clip(pts, lo, hi)
        vals = problem.along(pts[:, :m], pts[:, m : 2 * m], pts[:, 2 * m :], index, d, variant)
        dh = pts[1 + np.arange(nfree), pos] - pts[1 + nfree + np.arange(nfree), pos]
        grad = (vals[1 : 1 + nfree] - vals[1 + nfree :]) / np.where(dh > 0, dh, 1.0)
        return -vals[0] / scale, -grad / scale

    res = optimize.minimize(
        fun,
        x0[free],
        jac=True,
        method="L-BFGS-B",
        bounds=list(zip(lo[free], hi[free])),
        # a coarse search only ranks its start; the best is then polished
        options={"maxiter": maxiter, "ftol": 1e-9, "gtol": 1e-6}
        if coarse
        else {"maxiter": maxiter, "ftol": 1e-14, "gtol": 1e-11},
    )
    x = x0.copy()
    x[free] = np.clip(res.x, lo[free], hi[free])
    return x


def _exact_inner(problem: Problem, d, index, x):
    """The exact maximum over the velocity/torque box at the position of ``x`` (best variant)."""
    val, y = witness_task(problem, (x[None, : problem.m], d[None], index))
    return float(
        problem.along(y[:1, : problem.m], y[:1, problem.m : 2 * problem.m], y[:1, 2 * problem.m :], index, d)[0]
    ), y[0]


def _refine_task(problem: Problem, item):
    """Refine one direction: searches from its starts, then from the exact inner maximiser."""
    d, value, starts, free, index, maxiter = item
    best_val, best_x = value, starts[0]
    if not free.any():
        return best_val, best_x
    tried, found = [], []
    for x0 in starts:
        if any(np.array_equal(x0, y) for y in tried):
            continue
        tried.append(x0)
        found.append(_local_search(problem, d, value, index, x0, free, maxiter, coarse=len(starts) > 1))
    val, x = max(found, key=lambda f: f[0])
    if len(found) > 1:
        val, x = _local_search(problem, d, value, index, x, free, maxiter)
    if val > best_val:
        best_val, best_x = val, x
    # the local search may leave the velocities at a lower face maximum
    val, x = _exact_inner(problem, d, index, best_x)
    if val > best_val + 1e-12 * (1.0 + abs(best_val)):
        val, x = _local_search(problem, d, value, index, x, free, maxiter)
        if val > best_val:
            best_val, best_x = val, x
    return best_val, best_x


def refine(problem: Problem, directions, values, starts, index, dropped, progress, pool, depends=None, maxiter=200):
    """Bounded local search (L-BFGS-B) from every start; never lowers a support value.

    Each search moves the positions that matter and only the velocities and
    torques the direction depends on (``depends`` (D, 2m); all by default).
    The best point found is then checked with the exact maximum over the
    velocity/torque box at its position, and searched from again if that is higher.
    """
    m = problem.m
    lo, hi = problem.lo, problem.hi
    q_free = hi > lo
    q_free[list(dropped)] = False
    q_free[m:] = False
    if depends is None:
        depends = np.ones((len(directions), 2 * m), bool)
    tu_active = np.concatenate([problem.t_scale > 0, problem.u_scale > 0])
    items = []
    for k in range(len(directions)):
        free = q_free.copy()
        free[m:] = depends[k] & tu_active
        items.append((directions[k], values[k], starts[k], free, index, maxiter))
    out = pool.map(_refine_task, items, progress=progress, label="refining")
    new_values = np.array([o[0] for o in out])
    new_witness = np.array([o[1] for o in out])
    return new_values, new_witness
