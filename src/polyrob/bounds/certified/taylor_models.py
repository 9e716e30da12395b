"""Order-2 matrix Taylor models over a q-box, in ball arithmetic (``arb``).

A Taylor model keeps the polynomial part of a product exactly (up to
rounding) and pushes only third- and higher-order terms into an interval
remainder: this is what defeats the dependency problem of plain interval
evaluation of ``M(q)^-1`` and the Jacobians (see :mod:`polyrob.bounds.certified.interval_rbd`).
"""

from __future__ import annotations

from itertools import combinations_with_replacement

import numpy as np
from flint import arb, arb_mat

from polyrob.bounds.certified.balls import arb_upper, sq

__all__ = ["TaylorModel", "TaylorContext", "poly_tm", "const_tm", "inverse_tm", "interval_inverse"]


def interval_inverse(A: arb_mat):
    """Enclosure of ``A^-1`` for every matrix in the interval matrix ``A``, or None.

    Preconditioned (Hansen/Krawczyk-style) form: with ``R`` the float inverse of
    ``mid(A)`` and ``E = I - R A``, ``A^-1 = (I + E + Z) R`` where
    ``|Z_ij| <= ||E||^2 / (1 - ||E||)``.  Unlike interval Gaussian elimination
    this stays first-order tight on wide boxes.  None when ``||E|| >= 1``.
    """
    n = A.nrows()
    mid = np.array([[float(A[i, j].mid()) for j in range(n)] for i in range(n)])
    try:
        Rf = np.linalg.inv(mid)
    except np.linalg.LinAlgError:
        return None
    if not np.all(np.isfinite(Rf)):
        return None
    R = arb_mat([[arb(float(Rf[i, j])) for j in range(n)] for i in range(n)])
    I = arb_mat([[arb(1 if i == j else 0) for j in range(n)] for i in range(n)])
    E = I - R * A
    # (Python's max() on overlapping balls may pick the wrong one: compare floats)
    beta = arb(max(arb_upper(sum(abs(E[i, j]) for j in range(n))) for i in range(n)))
    if not beta < 1:
        return None
    z = beta * beta / (1 - beta)
    zr = arb(0, arb_upper(z)) if z.is_finite() else None
    if zr is None:
        return None
    Z = arb_mat([[zr for _ in range(n)] for _ in range(n)])
    return (I + E + Z) * R


class TaylorModel:
    """Matrix Taylor model of order 2 in ``delta = q - qc`` over a q-box.

    ``X(qc + delta) in c0 + sum_p c1[p] delta_p + sum_{p<=q} c2[p, q] delta_p delta_q + R``
    for every ``delta`` in the box, entrywise; ``c0``, ``c1``, ``c2`` are thin
    ``arb_mat`` (balls around exact values), ``R`` an interval ``arb_mat``.
    Products keep the polynomial part exactly (up to rounding) and push only
    third- and higher-order terms into ``R``: this is what defeats the
    dependency problem of plain interval evaluation (with ``M^-1`` of an
    ill-conditioned ``M`` plain intervals over-estimate derivative ranges 10-100x).
    """

    __slots__ = ("c0", "c1", "c2", "R", "ctx")

    def __init__(self, c0, c1, c2, R, ctx):
        self.c0, self.c1, self.c2, self.R, self.ctx = c0, c1, c2, R, ctx

    def _enc1(self):
        D = self.ctx.delta
        return sum((x * D[p] for p, x in self.c1.items()), arb_mat(self.c0.nrows(), self.c0.ncols()))

    def _enc2(self):
        D2 = self.ctx.delta2
        return sum((x * D2[k] for k, x in self.c2.items()), arb_mat(self.c0.nrows(), self.c0.ncols()))

    def enclosure(self):
        return self.c0 + self._enc1() + self._enc2() + self.R

    def __add__(self, o):
        return TaylorModel(
            self.c0 + o.c0,
            {p: x + o.c1[p] for p, x in self.c1.items()},
            {k: x + o.c2[k] for k, x in self.c2.items()},
            self.R + o.R,
            self.ctx,
        )

    def __sub__(self, o):
        return TaylorModel(
            self.c0 - o.c0,
            {p: x - o.c1[p] for p, x in self.c1.items()},
            {k: x - o.c2[k] for k, x in self.c2.items()},
            self.R - o.R,
            self.ctx,
        )

    def __neg__(self):
        return TaylorModel(
            -self.c0, {p: -x for p, x in self.c1.items()}, {k: -x for k, x in self.c2.items()}, -self.R, self.ctx
        )

    def __mul__(self, o):
        A, B = self, o
        c1 = {p: A.c0 * B.c1[p] + A.c1[p] * B.c0 for p in A.c1}
        c2 = {}
        for (p, q), x in A.c2.items():
            cross = A.c1[p] * B.c1[p] if p == q else A.c1[p] * B.c1[q] + A.c1[q] * B.c1[p]
            c2[p, q] = A.c0 * B.c2[p, q] + x * B.c0 + cross
        a1, a2, b1, b2 = A._enc1(), A._enc2(), B._enc1(), B._enc2()
        aP = A.c0 + a1 + a2
        R = a1 * b2 + a2 * b1 + a2 * b2 + aP * B.R + A.R * (B.c0 + b1 + b2 + B.R)
        return TaylorModel(A.c0 * B.c0, c1, c2, R, A.ctx)


class TaylorContext:
    def __init__(self, dims, delta):
        self.dims, self.delta = dims, delta
        self.pairs = [(p, q) for p in dims for q in dims if p <= q]
        self.delta2 = {(p, q): sq(delta[p]) if p == q else delta[p] * delta[q] for p, q in self.pairs}


def poly_tm(ctx, get_c, get_b, key_of, shape, shift=()):
    """Taylor model of the matrix of polynomials ``key_of(i, j)`` (derivative ``shift``).

    Coefficients from exact derivatives at the centre (``get_c``); remainder
    ``1/6 sum d3 p(Q) delta^3`` from third derivatives over the box (``get_b``).
    """
    n, k = shape

    def mat(get, o):
        return arb_mat([[get(key_of(i, j), shift + o) for j in range(k)] for i in range(n)])

    dims = ctx.dims
    c1 = {p: mat(get_c, (p,)) for p in dims}
    c2 = {(p, q): mat(get_c, (p, q)) * (arb(0.5) if p == q else arb(1)) for p, q in ctx.pairs}
    R = arb_mat(n, k)
    D = ctx.delta
    for p, q, r in combinations_with_replacement(dims, 3):
        distinct = len({p, q, r})
        weight = arb(1) if distinct == 3 else (arb(1) / 2 if distinct == 2 else arb(1) / 6)
        R += mat(get_b, (p, q, r)) * (weight * D[p] * D[q] * D[r])
    return TaylorModel(mat(get_c, ()), c1, c2, R, ctx)


def const_tm(ctx, A):
    n, k = A.nrows(), A.ncols()
    return TaylorModel(
        A, {p: arb_mat(n, k) for p in ctx.dims}, {pq: arb_mat(n, k) for pq in ctx.pairs}, arb_mat(n, k), ctx
    )


def inverse_tm(Mt):
    """Taylor model of ``M^-1`` from one of ``M``.

    ``M = M0 + N`` with ``N`` of order >= 1, so ``M^-1 = (I + X)^-1 M0^-1`` with
    ``X = M0^-1 N`` and ``(I + X)^-1 = I - X + X^2 - X^3 (I + X)^-1``, whose last
    term is bounded entrywise by ``b^3 / (1 - b)``, ``b = ||X||_inf < 1``.
    """
    ctx, n = Mt.ctx, Mt.c0.nrows()
    M0inv = interval_inverse(Mt.c0)
    if M0inv is None:
        return None
    Nt = TaylorModel(arb_mat(n, n), Mt.c1, Mt.c2, Mt.R, ctx)
    X = const_tm(ctx, M0inv) * Nt
    Xe = X.enclosure()
    b = arb(max(arb_upper(sum(abs(Xe[i, j]) for j in range(n))) for i in range(n)))
    if not b < 1:
        return None
    tail = arb_upper(b**3 / (1 - b))
    I = arb_mat([[arb(1 if i == j else 0) for j in range(n)] for i in range(n)])
    Y = const_tm(ctx, I) - X + X * X
    Y.R += arb_mat([[arb(0, tail) for _ in range(n)] for _ in range(n)])
    return Y * const_tm(ctx, M0inv)
