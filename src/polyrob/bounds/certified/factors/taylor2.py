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

__all__ = ["at_vertices", "taylor2_bounds", "taylor2_cells", "cell_grid", "gradient_bounds"]

#: Instances times cells :func:`cell_grid` allows one call of :func:`taylor2_cells` (numpy's work).
CELL_BUDGET = 2**17


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


def gradient_bounds(grad, hess, radii):
    """Proved ``(lower, upper)`` of every gradient component over the box: ``g(c) + H(box) d``.

    The mean-value theorem on each component ``g_p``: ``g_p(c + d) - g_p(c) =
    sum_l H_pl(xi) d_l`` with ``xi`` in the box, so ``|g_p(x) - g_p(c)| <=
    sum_l |H_pl| r_l``.  Used by the monotonicity test of the branch and bound
    (:mod:`~polyrob.bounds.certified.factors.monotone`): the Hessian of the
    Taylor models keeps the recursion's cancellations that the ball gradient
    over the box loses.  Arguments as :func:`taylor2_bounds`; returns arrays
    ``(n, B, ...)``.
    """
    n = grad[0].shape[0]
    extra = grad[0].ndim - 2
    r = radii.T.reshape(1, n, -1, *([1] * extra))  # (1, l, B, 1, ...)
    spread = ((np.abs(hess[0]) + hess[1]) * r).sum(1) * (1 + 4 * n * GAMMA) + TINY
    margin = GAMMA * (np.abs(grad[0]) + grad[1] + spread) + TINY
    return grad[0] - grad[1] - spread - margin, grad[0] + grad[1] + spread + margin


def taylor2_cells(value, grad, hess, radii, split: int = 4, parts: int = 2):
    """Tighter ``(lower, upper)`` of the same Taylor model, its quadratic bounded on cells of the box.

    The model says ``f(c + d) = f(c) + g.d + d' H(xi) d / 2`` with ``g`` and
    ``H`` in balls, so ``f(c + d)`` lies within ``T(d) = g_mid.d + d' S d / 2``
    (``S`` the symmetric part of ``H``'s midpoint, a float quadratic) of
    ``f(c)`` up to ``g_rad.|d| + |d|' S_rad |d| / 2``.  :func:`taylor2_bounds`
    bounds the cross terms of ``T`` by their magnitude and each coordinate's
    own quadratic apart from them, which on an entry whose linear and cross
    terms oppose each other at the corner the linear part picks (an arm's
    nearly constant entries) over-estimates by several times the proof's
    tolerance.  Here ``T`` is re-expanded, exactly (it is a quadratic), at the
    centres ``d0`` of the ``parts**split`` cells that cut each of the ``split``
    coordinates carrying most of its cross terms into ``parts``: on each cell ``T(d0)`` and
    ``g_mid + S d0`` are exact up to rounding (added to the balls) and the
    cross terms shrink with the cells' radii.  The extremes over the cells,
    plus the ball parts over the whole box, bound ``f``.  No dynamics are
    re-evaluated: the cost is numpy on ``n x n`` matrices.

    Parameters
    ----------
    value : (mid, rad), arrays (N,)
    grad : (mid, rad), arrays (N, n)
    hess : (mid, rad), arrays (N, n, n)
        The Hessian's balls over the box.
    radii : ndarray (N, n)
    split, parts : int
        Coordinates cut, and into how many parts each (:func:`cell_grid`).

    Returns
    -------
    lower, upper : ndarray (N,)

    Examples
    --------
    ``f = x0 - x1 + x0 x1`` on ``[-1, 1]^2`` is at most 1: the magnitude bound says 3, the four cells 1.5.

    >>> import numpy as np
    >>> value, grad = (np.zeros(1), np.zeros(1)), (np.array([[1.0, -1.0]]), np.zeros((1, 2)))
    >>> hess = (np.array([[[0.0, 1.0], [1.0, 0.0]]]), np.zeros((1, 2, 2)))
    >>> radii = np.ones((1, 2))
    >>> float(taylor2_bounds(value, (grad[0].T, grad[1].T), (hess[0].transpose(1, 2, 0), hess[1].transpose(1, 2, 0)), radii)[1][0])
    3.0...
    >>> round(float(taylor2_cells(value, grad, hess, radii)[1][0]), 6)
    1.5
    """
    vm, vr = value
    gm, gr = grad
    n_inst, n = gm.shape
    S = 0.5 * (hess[0] + np.swapaxes(hess[0], 1, 2))
    S_rad = 0.5 * (hess[1] + np.swapaxes(hess[1], 1, 2)) + GAMMA * np.abs(S)
    S_abs = np.abs(S)
    r = np.asarray(radii, float)
    # the ball parts over the whole box: f(c), g's radius and the Hessian's
    fixed = vr + (gr * r).sum(-1) + 0.5 * np.einsum("np,npl,nl->n", r, S_rad, r)
    weight = r * np.einsum("npl,nl->np", S_abs, r) - np.einsum("np,np,np->np", r, np.diagonal(S_abs, 0, 1, 2), r)
    k = min(split, n)
    chosen = np.argsort(-weight, axis=-1)[:, :k]  # (N, k)
    cut = np.take_along_axis(r, chosen, -1) / parts  # the cells' radii in the chosen coordinates
    rho = r.copy()
    np.put_along_axis(rho, chosen, cut, -1)
    offsets = 2.0 * np.arange(parts) - (parts - 1)  # cell centres in units of the cells' radii
    zeros = np.zeros((n, n, n_inst))
    S_t = np.moveaxis(S, 0, -1)
    upper, lower = np.full(n_inst, -np.inf), np.full(n_inst, np.inf)
    for steps in np.array(np.meshgrid(*([offsets] * k), indexing="ij")).reshape(k, -1).T:
        d0 = np.zeros_like(r)
        np.put_along_axis(d0, chosen, steps * cut, -1)
        Sd0 = np.einsum("npl,nl->np", S, d0)
        g0 = gm + Sd0
        T0 = (gm * d0).sum(-1) + 0.5 * (d0 * Sd0).sum(-1)
        a0 = np.abs(d0)
        Sa = np.einsum("npl,nl->np", S_abs, a0)
        t_err = GAMMA * (n + 3) * (np.abs(vm) + (np.abs(gm) * a0).sum(-1) + 0.5 * (a0 * Sa).sum(-1)) + TINY
        g_err = GAMMA * (n + 2) * (np.abs(gm) + Sa) + TINY
        lo, hi, _ = taylor2_bounds((vm + T0, t_err), (g0.T, g_err.T), (S_t, zeros), rho)
        upper, lower = np.maximum(upper, hi), np.minimum(lower, lo)
    margin = GAMMA * (np.abs(upper) + np.abs(lower) + fixed) + TINY
    return lower - fixed - margin, upper + fixed + margin


def cell_grid(instances: int) -> tuple[int, int]:
    """``(split, parts)`` of :func:`taylor2_cells` for ``instances`` quadratics within :data:`CELL_BUDGET`.

    Few instances (the last open sides of a box) get fine cells, many (a
    large box where every entry is open) coarse ones.

    >>> cell_grid(64), cell_grid(2000), cell_grid(30000)
    ((4, 6), (4, 2), (2, 2))
    """
    cells = CELL_BUDGET / max(instances, 1)
    for parts in (6, 4, 3, 2):
        if parts**4 <= cells:
            return 4, parts
    return max(1, int(np.log2(max(cells, 2)))), 2
