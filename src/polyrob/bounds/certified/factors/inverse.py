"""Proved enclosures of ``M_hat(q)^-1`` over a task box: the model's mass matrix provably invertible on the whole box.

Three proved enclosures of ``Y(q) = M_hat(q)^-1`` for every ``q`` of a box
``|q - c| <= r``, each built from ``M_hat(c)``'s float inverse (or its root):

* :func:`taylor_neumann_inverse` (the one the branch and bound uses):
  ``E(q) = I - C M_hat(q)`` is enclosed by a Taylor form of ``M_hat`` (value
  and derivatives at the centre, thin; the highest derivative, second or
  third, over the box), with ``C`` multiplied into every term before its
  absolute value is taken.  If a positive vector ``v`` has
  ``|E| v <= alpha v`` with ``alpha < 1`` (``|E|`` the entrywise upper ends;
  ``v`` the Perron vector of ``|E|``, the inequality checked with outward
  rounding), then ``rho(E) <= alpha``: ``M_hat(q) = C^-1 (I - E(q))`` is
  invertible on the whole box, and ``Y = sum_k E^k C`` lies in
  ``C + E C + ... + E^(K-1) C`` (ball products) plus a tail bounded by
  ``(|E|^K v)_i max_l(|C|_lj / v_l) / (1 - alpha)``;
* :func:`loewner_inverse` (the branch and bound's where the first proves
  nothing): ``M_hat(q)`` is symmetric positive definite, and its spectrum
  relative to ``M_hat(c)`` is bounded over the box at the vertices of its
  affine Taylor part (plus a norm bound of the rest); the inverse follows
  from those Loewner bounds, wider, on boxes twice as wide as the first
  needs on panda;
* :func:`fixed_point_inverse` (the earlier one, kept for comparison): grow a
  ball ``Yhat`` around ``Y(c)`` until ``Y(c) + sum_p Yhat dM_hat/dq_p(Q) Yhat [-r_p, r_p]``
  lies inside it.

Why the first: on ur5's full task (±0.2 rad) the mean-value enclosure of
``dM_hat/dq`` over the box (ball Newton-Euler) is some 40 times the sampled
variation, and both the fixed point and ``I - C M_hat(Q)`` with ``M_hat(Q)``
by the mean-value form (``||E||`` about 10) or by the ball value (8) fail;
the Taylor form with the exact centre gradient gives 3.4 (second order) and
1.7 (third) in the max-row-sum norm, and the Perron weighting 1.09 and
0.57 (the sampled ``|I - C M_hat(q)|`` has a max row sum of 0.25 and a Perron
root of 0.13), so the third-order
form proves ur5's ``M_hat`` invertible on the whole task in one box.  On
panda's full task the sampled ``|I - C M_hat(q)|`` itself has a spectral
radius of 1.56: no entrywise enclosure around one centre's inverse can
prove it, and the box must be split (at a fifth of the task the third-order
form gives 0.35; the Loewner bounds prove half the task).  Where both methods prove, the first is also the tighter: the
first-order part of ``E C`` is ``-sum_p C dM_hat/dq_p(c) C d_p`` with thin
factors, so its cancellations are kept, where the fixed point multiplies
two balls of ``Y`` over the box by ``dM_hat/dq`` over the box (ur5 at 0.05
of the task: a worst ratio of 2.4 to the sampled widths against 172, the
benchmark's record).  These norms were measured by hand (2026-11-28, at the reference
pose); ``benchmarks/certified_arms.py`` (``inverse``) records which method
proves each box and its widths against Pinocchio's inverses.
"""

from __future__ import annotations

from math import factorial

import numpy as np

from polyrob.bounds.certified.ball_jets import GAMMA, TINY, BallJet, lower, upper

__all__ = [
    "taylor_residual",
    "residual_ball",
    "perron_bound",
    "neumann_inverse",
    "taylor_neumann_inverse",
    "fixed_point_inverse",
    "loewner_inverse",
]

#: Relative margin on a symmetric eigensolver's eigenvalues: LAPACK's ``syevd`` is backward stable, its
#: eigenvalues exact for ``X + E`` with ``||E||_2 <= p(m) u ||X||_2`` (``u = 2^-53``, ``p`` modest in ``m <= 7``).
EIGEN_MARGIN = 1e-11

#: Relative margin of a float sum of up to a few thousand nonnegative terms (``k u``, ``u = 2^-53``, ``k <= 9000``).
SUM_MARGIN = 1e-12


def _ball_product(C, mid, rad):
    """``C @ X`` for the float matrices ``C`` ``(B, m, m)`` and balls ``X`` ``(..., B, m, m)``: ``(mid, rad)``."""
    out = BallJet(mid[None], rad[None], 0, 0).const_form("matmul", C)
    return out.mid[0], out.rad[0]


def jet_parts(J: BallJet, upto: int):
    """``[(mid, rad)]`` of a mass-matrix jet's derivatives of orders ``0 .. upto``, of the model (parameter set 0).

    ``J``: ``(C, B, P, m, m)`` in ``m`` variables; the order-``j`` part has shape ``(m,)*j + (B, m, m)``.
    """
    m, out, start = J.n, [], 0
    for j in range(upto + 1):
        size = m**j
        shape = (m,) * j + J.mid.shape[1:2] + J.mid.shape[3:]
        out.append((J.mid[start : start + size, :, 0].reshape(shape), J.rad[start : start + size, :, 0].reshape(shape)))
        start += size
    return out


def taylor_residual(C, centre, box, radii):
    """``E(q) = I - C M(q)`` over each box: ``(linear, rest)``, ``E(c + d) = sum_p linear_p d_p + rest``.

    Taylor's theorem with the Lagrange remainder, entry by entry::

        M(c + d) = sum_{j < k} D^j M(c)[d]^j / j!  +  D^k M(xi)[d]^k / k!,   |d_p| <= r_p

    ``linear = (mid, rad)`` ``(m, B, m, m)``: the balls of ``-C dM/dq_p(c)``
    (kept apart: a product with them keeps its cancellations); ``rest =
    (mid, rad)`` ``(B, m, m)``: a ball holding ``I - C M(c)`` and every term
    of order two and more, for every ``q`` of the box.

    Parameters
    ----------
    C : ndarray (B, m, m)
        Float preconditioners (any floats: the result holds for them).
    centre : list of (mid, rad)
        ``D^j M(c)`` for ``j = 0 .. k-1`` (``k >= 2``), shapes ``(m,)*j + (B, m, m)``.
    box : (mid, rad)
        ``D^k M`` over the box, shape ``(m,)*k + (B, m, m)``.
    radii : ndarray (B, m)
        The box's half-widths in ``q``.
    """
    B, m = C.shape[0], C.shape[-1]
    k = len(centre)
    terms = list(centre) + [box]
    v_mid, v_rad = _ball_product(C, *terms[0])
    E_mid = np.eye(m) - v_mid
    E_rad = v_rad
    g_mid, g_rad = _ball_product(C, *terms[1]) if k >= 2 else (None, None)
    for j in range(2 if k >= 2 else 1, k + 1):
        mid, rad = _ball_product(C, *terms[j])
        magnitude = np.abs(mid) + rad  # (m,)*j + (B, m, m)
        contribution = (magnitude * _term_weight(radii, j)).reshape(-1, B, m, m).sum(0) / factorial(j)
        E_rad = E_rad + contribution * (1 + SUM_MARGIN)
    rest = (E_mid, (E_rad + GAMMA * np.abs(E_mid)) * (1 + SUM_MARGIN) + TINY)
    if g_mid is None:  # k = 1: the mean-value form, every term in the rest
        return None, rest
    return (-g_mid, g_rad), rest


def _term_weight(radii, j: int) -> np.ndarray:
    """``r_p r_l ...`` over the ``j`` derivative axes of an order-``j`` term, shape ``(m,)*j + (B, 1, 1)``."""
    B, m = radii.shape
    weight = np.ones((B,) + (1,) * j)
    for axis in range(j):  # each (B, m) placed on its own axis
        shape = [B] + [1] * j
        shape[1 + axis] = m
        weight = weight * radii.reshape(shape)
    return np.moveaxis(weight, 0, -1)[..., None, None]


def residual_ball(linear, rest, radii):
    """The ball ``(mid, rad)`` of ``E`` over the box from :func:`taylor_residual`'s pieces."""
    E_mid, E_rad = rest
    if linear is not None:
        spread = ((np.abs(linear[0]) + linear[1]) * radii.T[:, :, None, None]).sum(0)
        E_rad = (E_rad + spread * (1 + SUM_MARGIN)) * (1 + GAMMA) + TINY
    return E_mid, E_rad


def perron_bound(N, iterations: int = 8):
    """``(alpha, v)``: a positive ``v`` and a float ``alpha`` above ``max_i (N v)_i / v_i`` (outward rounding).

    ``N`` ``(B, m, m)`` nonnegative; ``v`` the eigenvector of ``N``'s largest
    eigenvalue ``rho`` (the Perron vector, kept positive), polished by power
    steps on ``N + rho I`` (same vector, no oscillation on periodic ``N``).
    Any positive ``v`` gives a valid ``alpha``; then ``rho(A) <= alpha`` for
    every ``|A| <= N``.
    """
    B = N.shape[0]
    safe = np.where(np.isfinite(N), N, 0.0)
    with np.errstate(all="ignore"):
        values, vectors = np.linalg.eig(safe)
    top = np.argmax(values.real, axis=-1)
    rho = np.maximum(values.real[np.arange(B), top], 0.0)
    v = np.abs(vectors.real[np.arange(B), :, top])
    v = np.where(np.isfinite(v), v, 1.0)
    v = v / np.maximum(v.max(-1, keepdims=True), 1e-300)
    for _ in range(iterations):
        w = np.einsum("bij,bj->bi", safe, v) + rho[:, None] * v + 1e-9 * (rho[:, None] + TINY)
        v = w / w.max(-1, keepdims=True)
    v = np.maximum(v, 1e-12)
    Nv = upper(np.einsum("bij,bj->bi", N, v), 0.0)
    alpha = upper((Nv / v).max(-1), 0.0)
    return np.where(np.isfinite(alpha), alpha, np.inf), v


def neumann_inverse(C, linear, rest, radii, terms: int = 3):
    """``(mid, rad, alpha)``: the inverses ``(I - E)^-1 C`` for every ``E`` of the box, where ``alpha < 1``.

    ``Y = C + E C + ... + E^(K-1) C + E^K Y`` (``K = terms``).  ``E C`` is
    ``sum_p (linear_p C) d_p + rest C``: ``linear_p C`` is a product of
    thin balls, so the first-order spread keeps its cancellations; the
    further terms are ball products ``E (E^j C)``.  ``|Y|_(:, j) <= beta_j v / (1 - alpha)``
    with ``beta_j = max_l |C|_lj / v_l`` (:func:`perron_bound`), so
    ``|E^K Y|_ij <= (|E|^K v)_i beta_j / (1 - alpha)``.  Where ``alpha >= 1``
    nothing is proved: ``rad = inf``.
    """
    E_mid, E_rad = residual_ball(linear, rest, radii)
    N = upper(np.abs(E_mid), E_rad)
    alpha, v = perron_bound(N)
    E = BallJet(E_mid[None], E_rad[None], 0, 0)
    Cb = BallJet(C[None], np.zeros_like(C)[None], 0, 0)
    first = BallJet(rest[0][None], rest[1][None], 0, 0) @ Cb
    if linear is not None:
        lin = BallJet(linear[0], linear[1], 0, 0).const_form("matmul", C, left=False)  # (m, B, m, m)
        spread = ((np.abs(lin.mid) + lin.rad) * radii.T[:, :, None, None]).sum(0)
        first = BallJet(first.mid, (first.rad + spread[None] * (1 + SUM_MARGIN)) * (1 + GAMMA) + TINY, 0, 0)
    power, total = first, Cb + first
    for _ in range(terms - 2):
        power = E @ power
        total = total + power
    w = v
    for _ in range(terms):
        w = upper(np.einsum("bij,bj->bi", N, w), 0.0)
    beta = upper((np.abs(C) / v[..., None]).max(-2), 0.0)  # (B, j)
    ok = alpha < 1.0
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        gap = np.where(ok, lower(1.0 - alpha, 0.0), 1.0)
        tail = upper(w[..., :, None] * beta[..., None, :] / gap[:, None, None], 0.0)
        rad = (total.rad[0] + tail) * (1 + GAMMA) + TINY
    rad = np.where(ok[:, None, None] & np.isfinite(rad), rad, np.inf)
    return total.mid[0], rad, alpha


def taylor_neumann_inverse(centre, box, radii, terms: int = 3):
    """``(mid, rad, alpha)``: ``M(q)^-1`` enclosed for every ``q`` of each box (``rad = inf`` where not proved).

    ``centre`` and ``box`` as for :func:`taylor_residual`; the preconditioner
    is the float inverse of ``M(c)``'s midpoint.
    """
    M0 = centre[0][0]
    with np.errstate(all="ignore"):
        C = np.linalg.inv(M0)
    C = np.where(np.isfinite(C), C, 0.0)
    linear, rest = taylor_residual(C, centre, box, radii)
    return neumann_inverse(C, linear, rest, radii, terms)


def fixed_point_inverse(Y_centre, dM, radii):
    """``(rad, proved)``: a ball ``Y_c ± rad`` holding ``M(q)^-1`` on every box where ``proved`` (the earlier method).

    ``Y_centre = (mid, rad)`` ``(B, m, m)``: the inverse at the centre;
    ``dM``: ``(mid, rad)`` of ``dM/dq_p`` over the box, ``(m, B, m, m)``.
    The ball ``Yhat`` is grown until ``T(Yhat) = Y_c + sum_p (-Yhat dM/dq_p Yhat) [-r_p, r_p]``
    lies inside it; then ``Y(q)`` stays in ``T(Yhat)`` on every segment from
    the centre (mean-value theorem; ``Y`` cannot leave ``Yhat`` without
    crossing its boundary).
    """
    Yc_mid, Yc_rad = Y_centre
    m = Yc_mid.shape[-1]
    grads = [BallJet(dM[0][p][None], dM[1][p][None], m, 0) for p in range(m)]

    def T(rad_hat):
        Yhat = BallJet(Yc_mid[None], rad_hat[None], m, 0)
        rad = Yc_rad.copy()
        for p in range(m):
            prod = Yhat @ (grads[p] @ Yhat)
            rad = rad + radii[:, p, None, None] * (np.abs(prod.mid[0]) + prod.rad[0])
        return (rad + GAMMA * np.abs(Yc_mid)) * (1.0 + GAMMA) + TINY

    guess = T(Yc_rad)  # the first-order spread, with Y_c's cancellations
    rad = 2.0 * guess + 1e-12 * (np.abs(Yc_mid) + Yc_rad)
    proved = np.zeros(len(radii), bool)
    final = np.full_like(rad, np.inf)
    for _ in range(12):
        new = T(rad)
        inside = np.all(new < rad, axis=(-1, -2)) & np.all(np.isfinite(new), axis=(-1, -2))
        final = np.where((inside & ~proved)[:, None, None], new, final)
        proved |= inside
        if proved.all():
            break
        rad = np.where(proved[:, None, None], rad, 1.5 * np.maximum(new, rad))
    for _ in range(6):  # T maps an enclosure of Y(Q) to one: iterating it (and intersecting) only tightens
        if not proved.any():
            break
        new = T(np.where(proved[:, None, None], final, 0.0))
        final = np.where(proved[:, None, None], np.minimum(final, new), final)
    return np.where(proved[:, None, None], final, np.inf), proved


def _transformed(T, mid, rad):
    """The balls of ``T X T^T`` for the float ``T`` ``(B, m, m)`` and the balls ``X`` ``(..., B, m, m)``."""
    left = _ball_product(T, mid, rad)
    out = BallJet(left[0][None], left[1][None], 0, 0).const_form("matmul", np.swapaxes(T, -1, -2), left=False)
    return out.mid[0], out.rad[0]


def loewner_inverse(centre, box, radii):
    """``(mid, rad, sensitivity)``: ``M(q)^-1`` enclosed by its Loewner bounds, for boxes the Neumann bound cannot prove.

    The model's mass matrix is symmetric positive definite at every ``q``;
    the entrywise bound of :func:`taylor_neumann_inverse` forgets it, and on
    panda's task the sampled ``|I - C M_hat(q)|`` itself has a spectral radius
    above 1 until the box is a quarter of the task wide.  Here, with ``T``
    the float ``M(c)^-1/2``, the Taylor form ``A(d) = T M(c + d) T^T`` splits
    into its affine part's midpoints ``A_0 + sum_p d_p A_p`` and a rest
    (the balls' radii, every term of order two and more, the float
    products' rounding) whose 2-norm is at most ``eta`` (the Perron bound
    of its entrywise bound, symmetrised: :func:`perron_bound`).  The smallest
    eigenvalue of a symmetric matrix is concave in it and the largest
    convex, so over the box they are extreme at the affine part's vertices
    (``2^m`` symmetric eigenproblems, each widened by
    :data:`EIGEN_MARGIN`): ``lam_lo I <= A(d) <= lam_hi I`` with
    ``lam_lo = min_v lambda_min - eta``.  Where ``lam_lo > 0``,
    ``Y = M^-1 = T^T Z T`` with the eigenvalues of ``Z = A^-1`` in
    ``[1/lam_hi, 1/lam_lo]``: ``Y_ij`` lies in ``c (T^T T)_ij +- Delta |t_i| |t_j|``
    (``c`` and ``Delta`` the middle and half width of that interval, ``t_i``
    the columns of ``T``).

    Wider than the Neumann bound where both prove (an entry's radius is
    ``Delta`` times its row's and column's scale), but it proves on boxes
    twice as wide on panda (half its task, with the branch and bound's
    Taylor-model jets: ``tests/test_certified_inverse.py``), and a finite
    enclosure there lets the branch and bound's ranges be finite at its
    work limit.  Why by hand: no library bounds a matrix function's
    spectrum over a box with outward rounding.

    Parameters
    ----------
    centre : list of (mid, rad)
        ``D^j M(c)`` for ``j = 0 .. k-1`` (``k >= 2``), shapes ``(m,)*j + (B, m, m)``.
    box : (mid, rad)
        ``D^k M`` over the box, shape ``(m,)*k + (B, m, m)``.
    radii : ndarray (B, m)
        The box's half-widths in ``q``.

    Returns
    -------
    mid, rad : ndarray (B, m, m)
        ``rad = inf`` where ``lam_lo <= 0`` (nothing proved).
    sensitivity : ndarray (B, m)
        ``r_p max |A_p|``: how much each coordinate moves ``A`` (where to split).
    """
    M0 = centre[0][0]
    B, m = M0.shape[0], M0.shape[-1]
    T = _inverse_root(M0)
    terms = list(centre) + [box]
    A0m, A0r = _transformed(T, *terms[0])
    A1m, A1r = _transformed(T, *terms[1])  # (m, B, m, m)
    # the rest: the affine part's radii, every higher term's magnitude, entrywise
    rest = A0r + (A1r * radii.T[:, :, None, None]).sum(0)
    for j in range(2, len(terms)):
        mid, rad = _transformed(T, *terms[j])
        rest = rest + ((np.abs(mid) + rad) * _term_weight(radii, j)).reshape(-1, B, m, m).sum(0) / factorial(j)
    scaled = A1m * radii.T[:, :, None, None]  # (m, B, m, m): r_p A_p
    magnitude = np.abs(A0m) + np.abs(scaled).sum(0)
    rest = (rest * (1 + SUM_MARGIN) + GAMMA * (m + 2) * magnitude) * (1 + GAMMA) + TINY  # the vertices' sums
    with np.errstate(all="ignore"):
        # ||X||_2 <= rho(N) for |X| <= N symmetric nonnegative (N the rest, symmetrised upwards)
        eta = perron_bound(np.maximum(rest, np.swapaxes(rest, -1, -2)))[0]
        lam_lo, lam_hi = np.full(B, np.inf), np.full(B, -np.inf)
        moving = np.flatnonzero((radii > 0).any(0))
        for k in range(2 ** len(moving)):
            signs = np.zeros(m)
            signs[moving] = np.where((k >> np.arange(len(moving))) & 1, 1.0, -1.0)
            X = A0m + np.einsum("p,pbij->bij", signs, scaled)
            X = 0.5 * (X + np.swapaxes(X, -1, -2))  # A(d) is symmetric: its skew part is in the rest
            values = np.linalg.eigvalsh(np.where(np.isfinite(X), X, 0.0))
            size = EIGEN_MARGIN * np.sqrt((X**2).sum((-1, -2)))
            lam_lo = np.minimum(lam_lo, values[:, 0] - size)
            lam_hi = np.maximum(lam_hi, values[:, -1] + size)
        lam_lo, lam_hi = lower(lam_lo - eta, 0.0), upper(lam_hi + eta, 0.0)
        ok = np.isfinite(rest).all((-1, -2)) & (lam_lo > 0) & np.isfinite(lam_hi)
        lo, hi = np.where(ok, lam_lo, 1.0), np.where(ok, lam_hi, 1.0)
        inv_lo, inv_hi = upper(1.0 / lo, 0.0), lower(1.0 / hi, 0.0)  # 1/lam_lo from above, 1/lam_hi from below
        c = 0.5 * (inv_lo + inv_hi)
        half = upper(0.5 * (inv_lo - inv_hi), 0.0) + GAMMA * c
        Tt = np.swapaxes(T, -1, -2)
        T2 = Tt @ T
        T2_err = GAMMA * (m + 1) * (np.abs(Tt) @ np.abs(T))
        row = upper(np.sqrt((T**2).sum(-2)), 0.0)  # |t_i|, the columns' norms
        mid = c[:, None, None] * T2
        rad = (half[:, None, None] * row[:, :, None] * row[:, None, :] + c[:, None, None] * T2_err
               + GAMMA * np.abs(mid)) * (1 + GAMMA) + TINY  # fmt: skip
    rad = np.where(ok[:, None, None] & np.isfinite(rad), rad, np.inf)
    sensitivity = np.abs(scaled).max((-1, -2)).T  # (B, m)
    return mid, rad, np.where(np.isfinite(sensitivity), sensitivity, 0.0)


def _inverse_root(M0):
    """Float ``M0^-1/2`` per box (symmetrised; the identity where ``M0`` is not positive definite: any float ``T``
    gives a valid bound, a poor one only fails to prove)."""
    with np.errstate(all="ignore"):
        S = 0.5 * (M0 + np.swapaxes(M0, -1, -2))
        good = np.isfinite(S).all((-1, -2))
        w, U = np.linalg.eigh(np.where(good[:, None, None], S, np.eye(S.shape[-1])))
        good &= (w > 0).all(-1)
        root = (U * np.where(good[:, None], w, 1.0)[:, None, :] ** -0.5) @ np.swapaxes(U, -1, -2)
    return np.where(good[:, None, None], root, np.eye(S.shape[-1]))
