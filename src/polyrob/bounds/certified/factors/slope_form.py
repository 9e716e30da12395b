"""The slope form of a factor over a box: ``K(q) - K(c) = Y(q) (g(q) - g(c))`` with ``g = W - M_hat K(c)``.

Every factor of :mod:`polyrob.bounds.certified.factors.ranges` is ``K = Y W``
with ``Y = M_hat^-1``: ``M_hat(q) K(q) = W(q)`` at every point.  Hence, for
the centre ``c`` of a box and ``g(q) = W(q) - M_hat(q) K(c)`` (so that
``g(c) = 0``), exactly::

    K(q) - K(c) = Y(q) g(q) = sum_p Y(q) dg/dx_p(xi_p) d_p,    d = q - c

and ``K(q)`` lies in ``K(c) + sum_p [Y(Q) dg/dx_p(Q)] [-r_p, r_p]``.

Why: the mean-value form ``K(c) + sum_p dK/dx_p(Q) [-r_p, r_p]`` encloses
``dK/dx_p = Y (dW/dx_p - dM_hat/dx_p K)`` through ``dY = -Y dM_hat Y``: the
wrists' small inertias put entries of tens in ``Y``, and a product of two
such balls over a box loses the cancellation that keeps the true ``dK`` of
order one (on ur5's task, scale 0.01: the interval gradient's radius is
5,700 ``r`` against a sampled second derivative of 16).  Here ``Y`` enters
once, multiplying ``dg/dx_p``, whose midpoint is ``M_hat dK/dx_p`` at the
centre and whose radius comes from the second derivatives of ``M_hat`` and
``W``.  ``K(c)`` is only known as a ball: ``g`` is computed with that ball
as its constant, so its enclosure holds the ``g`` of every value in it,
the exact ``K(c)`` included.

The factor is affine in the acceleration ``a`` (``K = K0 + Ka a`` on the
``q`` columns, and so are ``W`` and ``g``): :func:`slope_spread` takes the
vertices of the ``a``-box as :meth:`FactorProblem.enclose` does.
"""

from __future__ import annotations

import numpy as np

from polyrob.bounds.certified.ball_jets import GAMMA, TINY, BallJet

__all__ = ["residuals", "slope_spread", "vertex_gradients"]


def residuals(M_hat: BallJet, W0: BallJet, Wa: BallJet, K0c: BallJet, Kac: BallJet):
    """``(g0, ga)``: jets of ``W0 - M_hat K0c`` ``(B, F, i, 3m)`` and ``Wa - M_hat Kac`` ``(B, F, i, p, j)``.

    ``M_hat``: ``(B, i, l)``; ``K0c``, ``Kac``: the factor at the box's centre
    (order-0 balls of shapes ``(B, F, l, 3m)`` and ``(B, F, l, p, j)``), taken
    as constants with their radii.
    """
    Mb = M_hat[:, None]  # (B, 1, i, l)
    g0 = W0 - Mb.const_form("matmul", K0c.mid[0], K0c.rad[0], left=False)
    B, F, m, p, j = Kac.mid.shape[1:]
    flat = Mb.const_form("matmul", Kac.mid[0].reshape(B, F, m, p * j), Kac.rad[0].reshape(B, F, m, p * j), left=False)
    ga = Wa - BallJet(flat.mid.reshape(-1, B, F, m, p, j), flat.rad.reshape(-1, B, F, m, p, j), flat.n, flat.order)
    return g0, ga


def vertex_gradients(F0: BallJet, Fa: BallJet, V: np.ndarray, k: int):
    """``dF/dx_p`` over the box at each ``a``-vertex, for ``F = F0 + Fa a`` (``Fa`` on the ``q`` columns only).

    Returns ``(mid, rad)``, each ``(2m, B, F, i, 3m, nv)``: the ball of each
    gradient, its radius rounded outward for the ``k`` operations behind it.
    """
    m, Va = V.shape[1], np.abs(V)
    gm = F0.mid[1:][..., None].repeat(len(V), -1)
    gr = F0.rad[1:][..., None].repeat(len(V), -1)
    gmag = np.abs(gm).copy()
    bm, br = np.moveaxis(Fa.mid[1:], 0, -2), np.moveaxis(Fa.rad[1:], 0, -2)  # (B, F, i, p, 2m, j)
    gm[:, :, :, :, :m] += np.moveaxis(bm @ V.T, -2, 0)
    gr[:, :, :, :, :m] += np.moveaxis(br @ Va.T, -2, 0)
    gmag[:, :, :, :, :m] += np.moveaxis(np.abs(bm) @ Va.T, -2, 0)
    return gm, (gr + GAMMA * k * (gmag + np.abs(gm))) * (1 + GAMMA) + TINY


def slope_spread(g0: BallJet, ga: BallJet, Y: BallJet, V: np.ndarray, radii: np.ndarray):
    """Bounds of ``|K(q, qdot, a) - K(c, a)|`` over the box at each ``a``-vertex: ``(spread, contribution)``.

    Parameters
    ----------
    g0, ga : BallJet, order 1 over the box
        :func:`residuals` (gradients in ``(q, qdot)``, ``2m`` variables).
    Y : BallJet, order 0
        ``M_hat^-1`` over the box, ``(B, i, l)``.
    V : ndarray (nv, m)
        The vertices of the acceleration box.
    radii : ndarray (B, 2m)
        The box's half-widths in ``(q, qdot)``.

    Returns
    -------
    spread : ndarray (B, F, i, 3m, nv)
    contribution : ndarray (B, F, i, 3m, 2m)
        What each coordinate adds to ``spread`` (its largest over the vertices).
    """
    m = V.shape[1]
    k = 2 * m + 2
    gm, gr = vertex_gradients(g0, ga, V, k)  # dg/dx_p over the box at each vertex
    # Y(Q) times each column of dg/dx_p, a ball product over the rows l
    Ym, Yr = Y.mid[0], Y.rad[0]  # (B, i, l)
    prod = np.einsum("bil,xbflev->xbfiev", Ym, gm)
    rad = np.einsum("bil,xbflev->xbfiev", np.abs(Ym), gr) + np.einsum("bil,xbflev->xbfiev", Yr, np.abs(gm) + gr)
    mag = np.einsum("bil,xbflev->xbfiev", np.abs(Ym), np.abs(gm))
    rad = (rad + GAMMA * (m + 2) * mag) * (1 + GAMMA) + TINY
    per = (np.abs(prod) + rad) * radii.T[:, :, None, None, None, None]  # (2m, B, F, i, 3m, nv)
    spread = per.sum(0) * (1 + 8 * m * GAMMA) + TINY
    return spread, per.max(-1).transpose(1, 2, 3, 4, 0)
