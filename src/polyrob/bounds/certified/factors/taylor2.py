"""The second-order Taylor form of a factor over a box: exact value and gradient at the centre, Hessian over the box.

For every entry ``f`` of a factor and ``x = c + d`` in the box ``|d_p| <= r_p``
(Taylor's theorem with the Lagrange remainder, on the segment from ``c``)::

    f(c + d) = f(c) + sum_p g_p d_p + 1/2 sum_pl H_pl(xi) d_p d_l,    xi in the box

with ``g = grad f(c)`` (a thin ball: the recursion's jet at the centre) and
``H(xi)`` in the Hessian enclosure over the box (the recursion's order-3
jets, :mod:`polyrob.bounds.certified.ball_jets`).  Each coordinate's own
part ``g_p d_p + H_pp d_p^2 / 2`` is a one-dimensional quadratic whose range
over ``[-r_p, r_p]`` is taken exactly (for the interval ``g_p`` and ``H_pp``:
the largest ``g`` on the side ``d_p > 0``, the smallest on the other, and the
largest ``H_pp``); the cross terms ``(H_pl + H_lp)/2 d_p d_l`` are bounded by
their magnitude.  The linear part, where the mean-value form's gradient over
the box loses the recursion's cancellations (docs/pldi.md), is exact here:
the over-estimation is second order in the box's size, from the Hessian's
enclosure alone, and third order where that Hessian is thin.

The factor is affine in the acceleration ``a`` (``K = K0 + Ka a`` on the
``q`` columns): value, gradient and Hessian are taken at each vertex of the
acceleration box (:func:`at_vertices`).
"""

from __future__ import annotations

import numpy as np

from polyrob.bounds.certified.ball_jets import GAMMA, TINY

__all__ = ["at_vertices", "taylor2_bounds"]


def at_vertices(mid, rad, a_mid, a_rad, V):
    """Balls of ``K0 + Ka a`` at each vertex ``a`` of ``V`` (``(nv, m)``): ``(mid, rad)`` with a last axis ``nv``.

    ``mid``, ``rad``: ``(C, B, F, i, 3m)``; ``a_mid``, ``a_rad``: ``(C, B, F, i, m, j)``
    (the ``a``-coefficients of the first ``m`` columns).
    """
    m = V.shape[1]
    Va = np.abs(V)
    out_m = np.repeat(mid[..., None], len(V), -1)
    out_r = np.repeat(rad[..., None], len(V), -1)
    mag = np.abs(out_m)
    out_m[..., :m, :] += a_mid @ V.T
    out_r[..., :m, :] += a_rad @ Va.T
    mag[..., :m, :] += np.abs(a_mid) @ Va.T
    k = m + 2
    return out_m, (out_r + GAMMA * k * (mag + np.abs(out_m))) * (1 + GAMMA) + TINY


def _side_max(b, h, r):
    """An upper bound of ``max_{0 <= t <= r} b t + h t^2 / 2`` (arrays; ``r`` broadcast)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(h < 0, np.clip(-b / np.where(h < 0, h, -1.0), 0.0, r), r)
    value = np.maximum(b * t + 0.5 * h * t * t, 0.0)
    return value + 4 * GAMMA * (np.abs(b) * r + np.abs(h) * r * r) + TINY


def taylor2_bounds(value, grad, hess, radii):
    """Proved ``(lower, upper, contribution)`` of entries over boxes from their centre value, centre gradient and box Hessian.

    ``contribution`` ``(n, B, ...)``: the second-order terms each coordinate
    adds (to steer where a box is split).

    Parameters
    ----------
    value : (mid, rad), arrays (B, ...)
        Balls of ``f(c)``.
    grad : (mid, rad), arrays (n, B, ...)
        Balls of ``grad f(c)``.
    hess : (mid, rad), arrays (n, n, B, ...)
        Balls holding the Hessian at every point of the box.
    radii : ndarray (B, n)
        The box's half-widths.
    """
    n = grad[0].shape[0]
    extra = grad[0].ndim - 2
    r = radii.T.reshape(n, -1, *([1] * extra))  # (n, B, 1, ...)
    g_lo, g_hi = grad[0] - grad[1], grad[0] + grad[1]
    diag = np.arange(n)
    h_lo = hess[0][diag, diag] - hess[1][diag, diag]
    h_hi = hess[0][diag, diag] + hess[1][diag, diag]
    up = np.maximum(_side_max(g_hi, h_hi, r), _side_max(-g_lo, h_hi, r)).sum(0)
    down = np.maximum(_side_max(-g_lo, -h_lo, r), _side_max(g_hi, -h_lo, r)).sum(0)
    # cross terms (H_pl + H_lp)/2 d_p d_l, p < l, bounded by their magnitude
    sym = 0.5 * (np.abs(hess[0] + np.swapaxes(hess[0], 0, 1)) + hess[1] + np.swapaxes(hess[1], 0, 1))
    upper_pairs = np.triu(np.ones((n, n), bool), 1).reshape(n, n, *([1] * (sym.ndim - 2)))
    pairs = np.where(upper_pairs, sym, 0.0) * r[:, None] * r[None, :]
    cross = pairs.sum((0, 1))
    spread_up = (up + cross) * (1 + 4 * n * n * GAMMA) + TINY
    spread_down = (down + cross) * (1 + 4 * n * n * GAMMA) + TINY
    v_mid, v_rad = value
    upper = v_mid + v_rad + spread_up
    lower = v_mid - v_rad - spread_down
    margin = GAMMA * (np.abs(v_mid) + v_rad + spread_up + spread_down) + TINY
    # what each coordinate's second-order terms add (its own quadratic beyond the linear part, half its cross terms):
    # the linear part is exact here, so splitting where the gradient is large gains nothing
    h_abs = np.maximum(np.abs(h_lo), np.abs(h_hi))
    contribution = 0.5 * h_abs * r * r + 0.5 * (pairs.sum(1) + pairs.sum(0))
    return lower - margin, upper + margin, contribution
