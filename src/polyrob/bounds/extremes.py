"""Exact extremes of the Jacobian entries over the velocity/torque box, per position.

For a fixed ``q`` every entry of ``A`` and ``B`` is a polynomial in the
velocities and torques of a known shape (``M^-1`` depends on ``q`` only,
``d qddot/d qdot`` is linear in ``qdot``, ``d qddot/d q`` is affine in ``u``
and quadratic in ``qdot``)::

    p(t, u) = c + a . u + b . t + t' Q t,      qdot = centre + half_width * t

so its coefficients follow from ``1 + 3m + m(m-1)/2`` Jacobian evaluations per
``q`` (:func:`polynomial_coefficients`), and so do the coefficients of any
linear functional ``d . p`` of the entries.  The maximum over the box is then
exact: the ``u`` part is separable, and the quadratic part is maximised by
enumerating the faces of the ``t`` box (``3^m`` of them) for ``m <= 4``.
Beyond, sampling uses its ``2^m`` vertices followed by coordinate ascent
from the best few (a lower bound, nearly always the maximum), and the face
enumeration (``exact=True``) is kept for the few positions that end up as
witnesses.  Only ``q`` needs sampling.

Examples
--------
>>> import numpy as np
>>> c, a, b = np.zeros((1, 1)), np.zeros((1, 2, 1)), np.array([[[1.0], [0.0]]])
>>> Q = np.zeros((1, 2, 2, 1)); Q[0, 1, 1, 0] = -1.0     # p = t1 - t2^2
>>> value, t, u = box_maximum(c, a, b, Q, np.ones(2, bool), np.zeros(2, bool))
>>> float(value[0, 0]), t[0, 0].tolist()
(1.0, [1.0, 0.0])
"""

from __future__ import annotations

import itertools

import numpy as np

from polyrob.errors import BoundsError

__all__ = ["polynomial_coefficients", "box_maximum", "box_upper_bound", "evaluate_polynomial"]

#: Up to this many joints the faces of the velocity box are enumerated (3^m).
FACE_ENUMERATION_MAX_JOINTS = 4
#: Elements (positions x polynomials x faces x joints) of one batch of the face enumeration.
FACE_BATCH_ELEMENTS = 2_000_000


def _design(m: int):
    """Points (t, u) in scaled coordinates at which the Jacobians are evaluated."""
    pts_t, pts_u = [np.zeros(m)], [np.zeros(m)]
    for k in range(m):
        e = np.zeros(m)
        e[k] = 1.0
        pts_t += [np.zeros(m)]
        pts_u += [e]
    for k in range(m):
        e = np.zeros(m)
        e[k] = 1.0
        pts_t += [e, -e]
        pts_u += [np.zeros(m), np.zeros(m)]
    for k, l in itertools.combinations(range(m), 2):
        e = np.zeros(m)
        e[k] = e[l] = 1.0
        pts_t += [e]
        pts_u += [np.zeros(m)]
    return np.array(pts_t), np.array(pts_u)


def polynomial_coefficients(entries_at, q, t_centre, t_scale, u_centre, u_scale):
    """Coefficients of every entry as a polynomial in scaled ``(t, u)``, per ``q``.

    Parameters
    ----------
    entries_at : callable
        ``entries_at(q, qdot, u) -> (n, k)`` the entries at ``n`` points.
    q : ndarray (N, m)
    t_centre, t_scale, u_centre, u_scale : ndarray (m,)
        ``qdot = t_centre + t_scale * t`` and ``u = u_centre + u_scale * s``
        with ``t, s`` in ``[-1, 1]`` (a zero scale pins the coordinate).

    Returns
    -------
    c (N, k), a (N, m, k), b (N, m, k), Q (N, m, m, k) with ``Q`` symmetric.
    """
    N, m = q.shape
    T, S = _design(m)
    P = len(T)
    qq = np.repeat(q, P, axis=0)
    qdot = t_centre + t_scale * np.tile(T, (N, 1))
    u = u_centre + u_scale * np.tile(S, (N, 1))
    vals = entries_at(qq, qdot, u)
    k = vals.shape[1]
    vals = vals.reshape(N, P, k)
    c = vals[:, 0]
    a = vals[:, 1 : 1 + m] - c[:, None]
    plus = vals[:, 1 + m : 1 + 3 * m : 2]
    minus = vals[:, 2 + m : 1 + 3 * m : 2]
    b = 0.5 * (plus - minus)
    diag = 0.5 * (plus + minus) - c[:, None]
    Q = np.zeros((N, m, m, k))
    idx = np.arange(m)
    Q[:, idx, idx] = diag
    for n_pair, (i, j) in enumerate(itertools.combinations(range(m), 2)):
        cross = vals[:, 1 + 3 * m + n_pair]
        qij = 0.5 * (cross - c - b[:, i] - b[:, j] - diag[:, i] - diag[:, j])
        Q[:, i, j] = Q[:, j, i] = qij
    return c, a, b, Q


def evaluate_polynomial(c, a, b, Q, t, u):
    """Value of the polynomials at points ``t, u`` of shape (N, m): returns (N, k)."""
    return c + np.einsum("nmk,nm->nk", a, u) + np.einsum("nmk,nm->nk", b, t) + np.einsum("nijk,ni,nj->nk", Q, t, t)


def _patterns(m: int, faces: bool) -> np.ndarray:
    """Face patterns: -1 lower bound, +1 upper bound, 0 free (interior)."""
    levels = (-1, 0, 1) if faces else (-1, 1)
    return np.array(list(itertools.product(levels, repeat=m)), dtype=float)


def _coordinate_ascent(b, Q, t, t_active, sweeps: int = 4):
    """Exact maximisation along one coordinate at a time, from given points ``t`` (N, D, S, m).

    With too many joints to enumerate faces, an interior maximum (negative
    curvature along a velocity) is reached this way; each step maximises the
    one-dimensional quadratic exactly, so the value never decreases.  ``S``
    starts per polynomial share its coefficients (not copied per start).
    Returns the values (N, D, S) and the points.
    """
    t = t.copy()
    diag = np.moveaxis(np.diagonal(Q, axis1=1, axis2=2), 2, 1)  # (N, m, D)
    for _ in range(sweeps):
        for i in np.flatnonzero(t_active):
            # p(t_i) = Q_ii t_i^2 + beta t_i + const, beta = b_i + 2 sum_{j != i} Q_ij t_j
            qii = diag[:, i][..., None]  # (N, D, 1)
            beta = b[:, i][..., None] + 2 * np.einsum("njd,ndsj->nds", Q[:, i], t) - 2 * qii * t[..., i]
            with np.errstate(divide="ignore", invalid="ignore"):
                stat = np.where(qii < 0, -beta / (2 * qii), 0.0)
            cands = np.stack([-np.ones_like(beta), np.ones_like(beta), np.clip(stat, -1, 1)])
            vals = qii * cands**2 + beta * cands
            t[..., i] = np.take_along_axis(cands, np.argmax(vals, axis=0)[None], axis=0)[0]
    value = np.einsum("nmd,ndsm->nds", b, t) + np.einsum("nijd,ndsi,ndsj->nds", Q, t, t, optimize=True)
    return value, t


def _quadratic_maximum(b, Q, t_active, faces: bool, ascents: int):
    """Maximum of ``b.t + t'Qt`` over the box, for polynomials that have a quadratic part."""
    N, m, D = b.shape
    patterns = np.unique(np.where(t_active, _patterns(m, faces), 0.0), axis=0)
    has_free = np.any((patterns == 0) & t_active, axis=1)
    # Every vertex at once, as two matrix products (BLAS).
    V = patterns[~has_free]
    VV = (V[:, :, None] * V[:, None, :]).reshape(len(V), m * m)
    vals = np.matmul(V, b) + np.matmul(VV, Q.reshape(N, m * m, D))  # (N, P, D)
    if faces:
        arg = np.argmax(vals, axis=1)
        best = np.take_along_axis(vals, arg[:, None, :], axis=1)[:, 0]
        best_t = V[arg]
    else:
        # Coordinate ascent from the best few vertices: one start alone stops
        # at a coordinatewise maximum that is not the box's in ~15 % of the
        # panda's (position, entry) pairs; a few starts close most of these gaps.
        n = min(ascents, len(V))
        top = np.argpartition(-vals, n - 1, axis=1)[:, :n] if n < len(V) else np.argsort(-vals, axis=1)  # (N, n, D)
        val, t = _coordinate_ascent(b, Q, np.moveaxis(V[top], 1, 2), t_active)  # starts (N, D, n, m)
        j = np.argmax(val, axis=2)
        best = np.take_along_axis(val, j[..., None], axis=2)[..., 0]
        best_t = np.take_along_axis(t, j[..., None, None], axis=2)[:, :, 0]
        return best, best_t
    # Faces with free coordinates: the stationary point in the free
    # coordinates, if it lies inside the face.  All faces with the same number
    # of free coordinates are solved in one batch (m batches instead of 3^m
    # solves face by face).
    faces_free = patterns[has_free]
    n_free = np.sum((faces_free == 0) & t_active, axis=1)
    for f in np.unique(n_free):
        faces = faces_free[n_free == f]
        step = max(1, int(FACE_BATCH_ELEMENTS // (len(faces) * D * m)))  # bounded memory for many polynomials
        for lo in range(0, N, step):
            sl = slice(lo, lo + step)
            best[sl], best_t[sl] = _free_face_maxima(b[sl], Q[sl], faces, t_active, best[sl], best_t[sl])
    return best, best_t


def _free_face_maxima(b, Q, patterns, t_active, best, best_t):
    """Update ``best`` with the interior stationary points of faces that have the same number of free coordinates."""
    N, m, D = b.shape
    free = (patterns == 0) & t_active  # (S, m), the same count in every row
    F = np.sort(np.argsort(~free, axis=1, kind="stable")[:, : int(free[0].sum())], axis=1)  # (S, f) free columns
    # stationarity in the free coordinates: 2 Q_FF t_F = -(b + 2 Q t_fixed)_F, t_fixed = the pattern
    rhs = -b[:, None] - 2 * np.einsum("nijd,sj->nsid", Q, patterns, optimize=True)  # (N, S, m, D)
    rhs = np.moveaxis(np.take_along_axis(rhs, F[None, :, :, None], axis=2), 3, 2)  # (N, S, D, f)
    QFF = np.moveaxis(Q[:, F[:, :, None], F[:, None, :]], 4, 2)  # (N, S, D, f, f)
    with np.errstate(all="ignore"):
        det_ok = np.abs(np.linalg.det(QFF)) > 1e-300
        sol = np.zeros_like(rhs)
        if det_ok.any():
            sol[det_ok] = np.linalg.solve(2 * QFF[det_ok], rhs[det_ok][..., None])[..., 0]
    inside = det_ok & np.all(np.abs(sol) <= 1.0, axis=-1)  # (N, S, D)
    t = np.broadcast_to(patterns[None, :, None, :], (N, len(patterns), D, m)).copy()
    np.put_along_axis(t, np.broadcast_to(F[None, :, None, :], sol.shape), sol, axis=3)
    val = np.einsum("nmd,nsdm->nsd", b, t) + np.einsum("nijd,nsdi,nsdj->nsd", Q, t, t, optimize=True)
    val = np.where(inside, val, -np.inf)
    s = np.argmax(val, axis=1)  # (N, D)
    top = np.take_along_axis(val, s[:, None], axis=1)[:, 0]
    better = top > best
    best = np.where(better, top, best)
    best_t[better] = np.take_along_axis(t, s[:, None, :, None], axis=1)[:, 0][better]
    return best, best_t


def box_maximum(c, a, b, Q, t_active, u_active, *, exact: bool | None = None, ascents: int = 4):
    """Maximum of ``c + a.u + b.t + t'Qt`` over ``t, u`` in ``[-1, 1]``, and its argmax.

    Parameters
    ----------
    c : (N, D); a, b : (N, m, D); Q : (N, m, m, D)
        ``D`` polynomials per sample.
    t_active, u_active : (m,) bool
        Coordinates that may move (a zero-width range is pinned at 0).
    exact : bool, optional
        Enumerate all ``3^m`` faces of the velocity box (exact; batched by
        the number of free coordinates, in batches of bounded memory).
        Otherwise the ``2^m`` vertices are evaluated
        and coordinate ascent runs from the best ``ascents`` of them (a lower
        bound that is attained).  Default: exact for
        ``m <= FACE_ENUMERATION_MAX_JOINTS``.

    Returns
    -------
    value : (N, D); t : (N, D, m); u : (N, D, m)

    Notes
    -----
    Polynomials whose quadratic coefficients are all below ``1e-12`` of their
    scale (rounding in :func:`polynomial_coefficients` of an entry linear in
    the velocities, or constant) are maximised as linear ones, at a vertex.
    """
    N, m, D = b.shape
    t_active = np.asarray(t_active, bool)
    u_active = np.asarray(u_active, bool)
    if exact is None:
        exact = m <= FACE_ENUMERATION_MAX_JOINTS
    # u part: separable and linear, the sign of each coefficient decides.
    u_arg = np.where(u_active[None, :, None], np.sign(a), 0.0)
    u_val = np.sum(np.abs(a) * u_active[None, :, None], axis=1)
    # Linear part alone (exact where there is no quadratic part).
    t_arg = np.where(t_active[None, :, None], np.where(b >= 0, 1.0, -1.0), 0.0)
    best = np.sum(np.abs(b) * t_active[None, :, None], axis=1)
    best_t = np.moveaxis(t_arg, 2, 1).copy()
    scale = np.abs(c).max(axis=0) + np.abs(b).sum(axis=1).max(axis=0)
    quad = np.flatnonzero(
        np.abs(Q * t_active[:, None, None] * t_active[None, :, None]).max(axis=(0, 1, 2))
        > 1e-12 * np.maximum(scale, 1e-300)
    )
    if quad.size and t_active.any():
        best_q, t_q = _quadratic_maximum(b[..., quad], Q[..., quad], t_active, exact, ascents)
        best[:, quad], best_t[:, quad] = best_q, t_q
    if not np.all(np.isfinite(best)):
        raise BoundsError("internal error: no vertex of the velocity box was evaluated")
    value = c + u_val + best
    return value, best_t, np.moveaxis(u_arg, 2, 1)


def box_upper_bound(c, a, b, Q, t_active, u_active) -> np.ndarray:
    """An upper bound (N, D) of the maximum :func:`box_maximum` finds, each term at its own worst.

    ``c + sum |a_i| + sum |b_i| + sum max(Q_ii, 0) + sum_{i != j} |Q_ij|`` over
    the coordinates that move: a few array operations, where the maximum
    itself costs a face enumeration or an ascent.  Used to skip the
    positions that cannot beat a known value.

    Examples
    --------
    >>> import numpy as np
    >>> c, a, b = np.zeros((1, 1)), np.zeros((1, 2, 1)), np.array([[[1.0], [0.0]]])
    >>> Q = np.zeros((1, 2, 2, 1)); Q[0, 1, 1, 0] = -1.0; Q[0, 0, 1, 0] = Q[0, 1, 0, 0] = 0.25
    >>> float(box_upper_bound(c, a, b, Q, np.ones(2, bool), np.zeros(2, bool))[0, 0])   # max is 1.0625
    1.5
    """
    t = np.asarray(t_active, bool)
    u = np.asarray(u_active, bool)
    bound = c + np.sum(np.abs(a) * u[None, :, None], axis=1) + np.sum(np.abs(b) * t[None, :, None], axis=1)
    Qt = Q * (t[:, None] & t[None, :])[None, :, :, None]
    diag = np.diagonal(Qt, axis1=1, axis2=2)  # (N, D, m)
    return bound + np.maximum(diag, 0.0).sum(axis=-1) + np.abs(Qt).sum(axis=(1, 2)) - np.abs(diag).sum(axis=-1)
