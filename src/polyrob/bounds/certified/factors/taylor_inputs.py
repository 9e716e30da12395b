"""The Taylor-model jets the factors' Hessian starts from: the joint angles' sines and cosines, and models from ball jets.

Both build :class:`~polyrob.bounds.certified.taylor_jets.TaylorJet` s (the
arithmetic is there): :func:`taylor_sin_cos` from Taylor's theorem on
``sin`` and ``cos`` (whose derivatives are ``±sin``, ``±cos``), and
:func:`from_ball_jets` from a function's ball jets at a box's centre and
over the box.  With ``pairs``, the products of the first offsets are kept
as monomials (:class:`~polyrob.bounds.certified.taylor_jets.TaylorJet`):
the sine's and cosine's second-order terms then enter exactly.
"""

from __future__ import annotations

import numpy as np

from polyrob.bounds.certified.ball_jets import GAMMA, TINY, TRIG_MARGIN, BallJet
from polyrob.bounds.certified.taylor_jets import SUM_MARGIN, TaylorJet, monomials, pair_radii

__all__ = ["from_ball_jets", "taylor_sin_cos"]


def from_ball_jets(centre: BallJet, box: BallJet, radii, k: int) -> TaylorJet:
    """The order-3 :class:`TaylorJet` of a function from its jets at a box's centre and over the box (both order 3).

    For a component ``X_j`` (the ``j``-th derivatives, ``j <= 3``), Taylor's
    theorem on the segment from the centre ``c`` gives, for ``|d| <= r``::

        X_0(c + d) in X_0(c) + X_1(c).d + 1/2 X_2(Q)[d, d]
        X_1(c + d) in X_1(c) + X_2(c).d + 1/2 X_3(Q)[d, d]
        X_2(c + d) in X_2(c) + X_3(c).d + (X_3(Q) - X_3(c)).d
        X_3(c + d) in X_3(Q)

    with ``Q`` the box.  The linear coefficients kept are the midpoints of
    ``X_{j+1}(c)`` in the first ``k`` variables; their radii, the
    coefficients of the other variables and the second-order terms go into
    the ball.  ``radii``: ``(B, N)`` half-widths of the box's variables
    (the jets' ``n`` are its first ones); ``centre``, ``box``: ``(C, B, ...)``.
    """
    n = box.n
    B = box.mid.shape[1]
    tail = box.mid.shape[1:]
    extra = len(tail) - 1
    r = np.asarray(radii, float)[:, :n].T.reshape(n, B, *([1] * extra))  # (n, B, 1, ...)
    kk = min(k, n)

    def parts(J):
        out, start = [], 0
        for j in range(4):
            size = n**j
            out.append(
                (
                    J.mid[start : start + size].reshape(*(n,) * j, *tail),
                    J.rad[start : start + size].reshape(*(n,) * j, *tail),
                )
            )
            start += size
        return out

    cen, bx = parts(centre), parts(box)

    def absq(part):
        return np.abs(part[0]) + part[1]

    comps_c, comps_L, comps_R = [], [], []
    # order 0: value
    v, g, H, T = cen
    Hq, Tq = absq(bx[2]), absq(bx[3])
    r2 = r[:, None] * r[None, :]  # (n, n, B, 1...)
    lin_other = (np.abs(g[0][kk:]) * r[kk:]).sum(0) if kk < n else 0.0
    R0 = v[1] + (g[1] * r).sum(0) + lin_other + 0.5 * (Hq * r2).sum((0, 1))
    comps_c.append(v[0])
    comps_L.append(g[0][:kk])  # (k, B, ...)
    comps_R.append(R0)
    # order 1: gradient component q
    lin_other = (np.abs(H[0][:, kk:]) * r[kk:][None]).sum(1) if kk < n else 0.0
    R1 = g[1] + (H[1] * r[None]).sum(1) + lin_other + 0.5 * (Tq * r2[None]).sum((1, 2))
    comps_c.append(g[0])
    comps_L.append(np.moveaxis(H[0][:, :kk], 1, 0))  # (k, n, B, ...)
    comps_R.append(R1)
    # order 2: Hessian component (q, s)
    dev = np.abs(bx[3][0] - T[0]) + bx[3][1]
    lin_other = (np.abs(T[0][:, :, kk:]) * r[kk:][None, None]).sum(2) if kk < n else 0.0
    R2 = H[1] + (dev * r[None, None]).sum(2) + lin_other
    comps_c.append(H[0])
    comps_L.append(np.moveaxis(T[0][:, :, :kk], 2, 0))  # (k, n, n, B, ...)
    comps_R.append(R2)
    # order 3: the box's ball
    comps_c.append(bx[3][0])
    comps_L.append(np.zeros((kk, *bx[3][0].shape)))
    comps_R.append(bx[3][1])
    c = np.concatenate([x.reshape(-1, *tail) for x in comps_c])
    L = np.concatenate([x.reshape(kk, -1, *tail) for x in comps_L], 1)
    R = np.concatenate([(x * (1 + SUM_MARGIN) + TINY).reshape(-1, *tail) for x in comps_R])
    return TaylorJet(c, L, R, np.asarray(radii, float)[:, :kk].T.copy(), n, 3)


def taylor_sin_cos(centre, radius, order: int, k: int, box_radius=None, pairs: int = 0):
    """``(sin, cos)`` :class:`TaylorJet` s of the variables ``centre ± radius`` ``(B, n)``, linear in the first ``k``.

    ``box_radius`` (default ``radius``): the half-widths of the box's
    variables the models are linear in (a variable whose sine is not taken
    may have radius 0 here and its own half-width there).

    Every component of ``sin`` and ``cos`` of ``x_p = c_p + d_p`` is ``±sin``
    or ``±cos``, so ``f'' = -f`` and ``|f'''| <= 1``: by Taylor's theorem
    ``f(c + d) = f(c) + f'(c) d - f(c) d^2 / 2 + t``, ``|t| <= r^3 / 6``, and
    with ``d^2`` in ``[0, r^2]``::

        f(c_p + d_p) in f(c_p) (1 - r_p^2 / 4) + f'(c_p) d_p ± (|f(c_p)| r_p^2 / 4 + r_p^3 / 6)

    (for ``p < k``; else the linear term goes into the ball too; for
    ``p < pairs``, ``- f(c_p) d_p^2 / 2`` is kept as a monomial and only
    ``r_p^3 / 6`` is in the ball), plus the
    library's error on ``f(c_p)`` and ``f'(c_p)`` (:data:`~polyrob.bounds.certified.ball_jets.TRIG_MARGIN`
    each) and the rounding of the product.  Near ``sin(c_p) = 0`` (an arm's
    zero pose) the sine's ball is of third order in ``r_p``, not of second.
    """
    c, r = np.asarray(centre, float), np.asarray(radius, float)
    B, n = c.shape
    s0, c0 = np.sin(c), np.cos(c)
    # the derivatives of sin: sin, cos, -sin, -cos, sin; of cos: cos, -sin, -cos, sin, cos
    sin_seq, cos_seq = (s0, c0, -s0, -c0, s0), (c0, -s0, -c0, s0, c0)
    linear = np.arange(n) < k
    r_box = (r if box_radius is None else np.asarray(box_radius, float))[:, :k].T
    rows = np.concatenate([r_box, pair_radii(r_box, pairs)])
    pp, ll = monomials(pairs)
    square = k + np.flatnonzero(pp == ll)  # the rows of d_p^2, p < pairs
    out = []
    for seq in (sin_seq, cos_seq):
        C = BallJet.size(n, order)
        cm, R, L = np.zeros((C, B, n)), np.zeros((C, B, n)), np.zeros((len(rows), C, B, n))
        for j in range(order + 1):  # component j of variable p: index of d^j / dx_p^j
            for p in range(n):
                idx = 0 if j == 0 else 1 + sum(n**i for i in range(1, j)) + p * sum(n**i for i in range(j))
                f, rp = seq[j][:, p], r[:, p]
                margin = TRIG_MARGIN * (1 + rp + rp * rp) + 4 * GAMMA * np.abs(f)
                if p < pairs:  # - f d^2 / 2 kept: a monomial
                    cm[idx, :, p] = f
                    L[square[p], idx, :, p] = -0.5 * f
                    rest = rp**3 / 6 + margin
                else:
                    cm[idx, :, p] = f * (1.0 - 0.25 * rp * rp)
                    rest = 0.25 * np.abs(f) * rp**2 + rp**3 / 6 + margin
                if linear[p]:
                    L[p, idx, :, p] = seq[j + 1][:, p]
                    R[idx, :, p] = rest
                else:
                    R[idx, :, p] = np.abs(seq[j + 1][:, p]) * r[:, p] + rest
        out.append(TaylorJet(cm, L, (R * (1 + GAMMA) + TINY) * (R > 0), rows.copy(), n, order, pairs=pairs))
    return tuple(out)
