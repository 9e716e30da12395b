"""Rigorous maxima of quadratics over boxes, in ball arithmetic: the inner step of the certified bounds.

For a fixed q-box vertex, a Jacobian entry is a quadratic ``a0 + a.v + v' H v``
in the velocities ``v``; :func:`quad_max` bounds its maximum over a box of
``v`` from above by enumerating the faces of the box (the maximum lies in the
relative interior of one of them).

Examples
--------
>>> from flint import arb
>>> H = [[arb(-1), arb(0)], [arb(0), arb(0)]]          # -v1^2 + v2
>>> ub, x = quad_max(arb(0), [arb(0), arb(1)], H, [-1.0, -1.0], [1.0, 1.0])
>>> ub >= 1.0, x
(True, [0.0, 1.0])
"""

from __future__ import annotations

import itertools

import numpy as np
from flint import arb, arb_mat

from polyrob.bounds.certified.balls import arb_upper, ball, sq

__all__ = ["negative_definite", "quad_max", "quad_naive"]


def negative_definite(H, F):
    """Is ``H[F, F]`` negative definite?  True / False / None (undecided).

    Sylvester's criterion on ``-H[F, F]``: all leading minors > 0.
    """
    N = arb_mat([[-H[j][l] for l in F] for j in F])
    minors = [N[0, 0]]
    if len(F) >= 2:
        minors.append(N[0, 0] * N[1, 1] - N[0, 1] * N[1, 0])
    if len(F) == 3:
        minors.append(N.det())
    if any(mn <= 0 for mn in minors):
        return False
    return True if all(mn > 0 for mn in minors) else None


def quad_max(a0, a, H, lo, hi, stop=None):
    """Rigorous max of ``a0 + a.x + x^T H x`` over the box ``[lo, hi]``.

    ``a0``, ``a``, ``H`` (symmetric) are thin balls, ``lo``/``hi`` floats.
    The maximum lies in the relative interior of some face of the box: on a
    face it is either a vertex, or the stationary point of the restriction
    when that is provably negative definite (otherwise the maximum is on the
    face's boundary), or, when definiteness cannot be decided, we bound the
    face by naive interval evaluation.  Returns ``(upper bound, point)`` where
    ``point`` is where the (approximate) maximum is attained, for inner bounds.
    With ``stop``, returns early (with a partial, too low bound) once the
    bound exceeds it: callers then only need to know that it does.
    """
    m = len(a)
    free = [j for j in range(m) if lo[j] < hi[j]]
    # definiteness depends only on the set of free coordinates of a face
    status = {F: negative_definite(H, F) for r in range(1, len(free) + 1) for F in itertools.combinations(free, r)}
    best_ub, best_val, best_x = -np.inf, -np.inf, None
    ends = [(arb(lo[j]), arb(hi[j])) for j in range(m)]
    for choice in itertools.product((0, 1, 2), repeat=len(free)):
        F = tuple(j for j, c in zip(free, choice) if c == 2)
        if F and status[F] is False:
            continue  # not negative definite: no interior maximum on this face
        x = [ends[j][0] for j in range(m)]
        for j, c in zip(free, choice):
            if c == 1:
                x[j] = ends[j][1]
        X = [j for j in range(m) if j not in F]
        # f = const + lin . x_F + x_F^T H_FF x_F on the face
        hx = {j: sum((H[j][l] * x[l] for l in X), arb(0)) for j in range(m)}
        const = a0 + sum((x[j] * (a[j] + hx[j]) for j in X), arb(0))
        val = const if not F else None
        sol = None
        if F:
            lin = [a[j] + 2 * hx[j] for j in F]
        if F and status[F]:
            k = len(F)
            try:
                xs = (-2 * arb_mat([[H[j][l] for l in F] for j in F])).solve(arb_mat([[c] for c in lin]))
                sol = [xs[n, 0] for n in range(k)]
            except ZeroDivisionError:
                sol = None
            if sol is not None:
                if any(sol[n] < lo[j] or sol[n] > hi[j] for n, j in enumerate(F)):
                    continue  # stationary point outside the face
                val = const + sum((lin[n] * sol[n] for n in range(k)), arb(0)) / 2
        if val is None:  # undecided: naive enclosure over the face
            B = [ball(lo[j], hi[j]) for j in F]
            val = const + sum((lin[n] * B[n] for n in range(len(F))), arb(0))
            for n, j in enumerate(F):
                val += H[j][j] * sq(B[n])
                for n2 in range(n + 1, len(F)):
                    val += 2 * H[j][F[n2]] * B[n] * B[n2]
        ub = arb_upper(val)
        best_ub = max(best_ub, ub)
        vm = float(val.mid())
        if vm > best_val:
            best_val = vm
            best_x = [float(x[j].mid()) for j in range(m)]
            for n, j in enumerate(F):
                best_x[j] = 0.5 * (lo[j] + hi[j]) if sol is None else min(max(float(sol[n].mid()), lo[j]), hi[j])
        if stop is not None and best_ub > stop:
            break
    return best_ub, best_x


def quad_naive(a0, a, H, S):
    """Interval enclosure of ``a0 + a.x + x^T H x`` for ``x`` in the balls ``S``."""
    m = len(a)
    val = a0 + sum((a[j] * S[j] for j in range(m)), arb(0))
    for j in range(m):
        val += H[j][j] * sq(S[j]) + 2 * sum((H[j][l] * S[j] * S[l] for l in range(j + 1, m)), arb(0))
    return val
