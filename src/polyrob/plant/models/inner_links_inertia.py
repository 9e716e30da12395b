"""The norm-bounded blocks of the ``inner-links`` model: the relative inertia error ``G = I - M_hat^-1 M`` and the state residual.

Split from :mod:`~polyrob.plant.models.inner_links` (its module text says
how the blocks are used): the weighted forms of ``G`` over the task's
samples, the bounds of the blocks' norms over the set, and the inertia
ratio the model reports.

Both blocks are a matrix linear in the set's scalars, ``sum_j u_j R_j``
(``|u_j| <= 1``), plus the payload's part at each point of its physical
set.  Its norm is the largest eigenvalue of its Hermitian dilation
``H(X) = [[0, X], [X^T, 0]]``, linear in ``X``; ``u H(R) <= |H(R)|`` in the
Loewner order, so ``||sum_j u_j R_j + R_p|| <= lambda_max(H(R_p) + sum_j
|H(R_j)|)`` for every ``u`` of the box: at most the triangle inequality's
``sum_j ||R_j|| + ||R_p||``, and less where the ``R_j`` act on different
directions.

Examples
--------
>>> import numpy as np
>>> R = np.array([np.diag([1.0, 0.0]), np.diag([0.0, 1.0])])[:, None]  # two scalars on different axes, one sample
>>> float(residual_norm_bounds(R, np.zeros((0, 1, 2, 2)), np.zeros((1, 0)))[0])  # the triangle inequality says 2
1.0
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "exactly_weighted",
    "spectrum_bounds",
    "g_norm_bound",
    "residual_norm_bounds",
    "inertia_range",
    "inertia_ratio",
]


def exactly_weighted(robot, q, G, W) -> tuple[np.ndarray, np.ndarray]:
    """``W_q G W_q^-1`` with ``W_q = M_hat(q)^{1/2}`` at each sample (symmetric: ``-M_hat^-1/2 dM M_hat^-1/2``), and
    ``kappa = ||W W_q^-1|| ||W_q W^-1||``, what the fixed weighting ``W`` of the block costs at that sample."""
    out, kappa = np.empty_like(G), np.empty(len(q))
    for s, qq in enumerate(q):
        M = robot.model_robot.mass_matrix(qq)
        values, vectors = np.linalg.eigh(0.5 * (M + M.T))
        W_q = (vectors * np.sqrt(values)) @ vectors.T
        W_q_inv = (vectors / np.sqrt(values)) @ vectors.T
        out[:, s] = W_q @ G[:, s] @ W_q_inv
        T = W @ W_q_inv
        kappa[s] = np.linalg.norm(T, 2) * np.linalg.norm(np.linalg.inv(T), 2)
    return out, kappa


def _sym_skew(R):
    sym = 0.5 * (R + np.swapaxes(R, -1, -2))
    return sym, np.linalg.norm(R - sym, 2, axis=(-2, -1))


def spectrum_bounds(box_rest, payload_rest, pay) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(bottom, top, skew)`` per sample: the eigenvalues of the block's symmetric part lie in ``[bottom, top]``.

    Box scalars: ``A = sum_j |sym R_j|`` bounds their symmetric part in the
    Loewner order (``-|S| <= u S <= |S|`` for ``|u| <= 1``), their skew
    parts add their norms (``skew``); the payload at each point ``p`` of its
    sampled physical set (:func:`payload_points`) adds ``S_p``, so the
    symmetric part lies between ``S_p - A`` and ``S_p + A``.  Arrays of the
    samples (one entry when there is no payload).
    """
    sym, skew = _sym_skew(box_rest)
    values, vectors = np.linalg.eigh(sym)
    A = np.einsum("...ab,...b,...cb->...ac", vectors, np.abs(values), vectors).sum(axis=0)  # (S, m, m)
    skew = skew.sum(axis=0)
    if len(payload_rest):
        S_p, skew_p = _sym_skew(np.einsum("pi,isab->psab", pay, payload_rest))
        top = np.linalg.eigvalsh(S_p + A).max(axis=-1)
        bottom = np.linalg.eigvalsh(S_p - A).min(axis=-1)
        skew = skew + skew_p.max(axis=0)
    else:
        top = np.linalg.eigvalsh(A).max(axis=-1)[None]
        bottom = -top
    return bottom, top, skew


def _dilation(X) -> np.ndarray:
    """The Hermitian dilation ``[[0, X], [X^T, 0]]`` of ``X`` (last two axes): linear in ``X``, its largest eigenvalue ``||X||_2``."""
    r, c = X.shape[-2:]
    out = np.zeros(X.shape[:-2] + (r + c, r + c))
    out[..., :r, r:] = X
    out[..., r:, :r] = np.swapaxes(X, -1, -2)
    return out


def g_norm_bound(box_rest, payload_rest, pay, kappa) -> tuple[float, float]:
    """``(g_norm, g0)``: ``||sum_j u_j R_j - g0 I||_2 <= g_norm`` (acceleration columns) over the set and the samples.

    The norm is the largest eigenvalue of the Hermitian dilation ``H``, which
    is linear in the matrix: ``H(sum_j u_j R_j + R_p - g0 I) <= H(R_p - g0 I)
    + sum_j |H(R_j)|`` in the Loewner order for every ``|u_j| <= 1`` (box
    scalars) and every point ``p`` of the payload's sampled physical set.  A
    block that is not symmetric (the fixed weighting away from the task's
    centre) keeps the signs its symmetric and skew parts share; adding the
    skew parts' norms to the symmetric part's spectrum instead refused
    panda's default set and z1's (docs/uncertainty.md).  ``kappa`` per sample is
    what a fixed weighting costs there.

    ``g0``, the block's centre (a heavy off-axis payload raises the inertia
    more than a light one lowers it), minimises ``g_norm / (1 - g0)``, the
    block's size against the room its centre leaves, searched on the
    payload points that attain the largest eigenvalue at some sample.  The
    bound returned holds at every point and sample: each eigenvalue moves
    by at most ``|g0 - g_c|`` from its value at the spectrum's centre
    ``g_c`` (``||H(I)|| = 1``), and every pair that bound does not settle
    is evaluated at ``g0``.
    """
    from scipy.optimize import minimize_scalar

    m = box_rest.shape[-1]
    A = _absolute_sum(box_rest)  # (S, 2m, 2m)
    R = np.einsum("pi,isab->psab", pay, payload_rest) if len(payload_rest) else np.zeros((1,) + box_rest.shape[1:])
    eye = np.eye(m)

    def largest(g, rows, chunk=32):  # (rows, S): the dilation's largest eigenvalue at each payload point and sample
        out = np.empty((len(rows), A.shape[0]))
        for start in range(0, A.shape[0], chunk):  # a payload's 1300 points times 512 samples: a gigabyte at once
            part = slice(start, start + chunk)
            out[:, part] = np.linalg.eigvalsh(_dilation(R[rows, part] - g * eye) + A[part]).max(axis=-1)
        return out

    bottom, top, _ = spectrum_bounds(box_rest, payload_rest, pay[::16])  # a start: any centre gives a bound
    g_c = 0.5 * (float(top.max()) + float(bottom.min()))
    span = max(float(top.max() - bottom.min()), 1e-6)
    at_centre = largest(g_c, np.arange(len(R)))  # (P, S)
    active = np.unique(np.argmax(at_centre, axis=0))
    found = minimize_scalar(
        lambda t: float((kappa * largest(t, active).max(axis=0)).max()) / (1.0 - t),
        bounds=(g_c - 0.5 * span, min(g_c + 0.5 * span, 1.0 - 1e-3)),
        method="bounded",
        options={"xatol": 1e-3},
    )
    g = float(found.x)
    at_g = at_centre + abs(g - g_c)  # every pair's eigenvalue at g, bounded
    at_g[active] = largest(g, active)
    unsettled = np.argwhere(kappa * at_g > (kappa * at_g[active]).max())
    for start in range(0, len(unsettled), 16384):
        p, s = unsettled[start : start + 16384].T
        at_g[p, s] = np.linalg.eigvalsh(_dilation(R[p, s] - g * eye) + A[s]).max(axis=-1)
    bounds = [(float((kappa * at_centre.max(axis=0)).max()), g_c), (float((kappa * at_g.max(axis=0)).max()), g)]
    return min((b for b in bounds if b[1] < 1.0), key=lambda b: b[0] / (1.0 - b[1]))


def _absolute_sum(X) -> np.ndarray:
    """``sum_j |H(X_j)|`` over the first axis of ``X`` ``(J, S, r, c)``: ``(S, r + c, r + c)``."""
    values, vectors = np.linalg.eigh(_dilation(X))
    return np.einsum("...ab,...b,...cb->...ac", vectors, np.abs(values), vectors).sum(axis=0)


def residual_norm_bounds(box_rest, payload_rest, pay, chunk: int = 16) -> np.ndarray:
    """``(S,)``: ``||sum_j u_j R_j + sum_i p_i P_i||_2`` bounded at each sample, over the box ``|u_j| <= 1`` and the points ``p`` of ``pay``.

    ``box_rest`` ``(J, S, r, c)``, ``payload_rest`` ``(I, S, r, c)``, ``pay``
    ``(points, I)``: the module text's dilation bound, the payload's points
    ``chunk`` samples at a time (a payload's set has about 1300 points).
    """
    A = _absolute_sum(box_rest)
    if not len(payload_rest):
        return np.linalg.eigvalsh(A).max(axis=-1)
    out = np.empty(box_rest.shape[1])
    for start in range(0, len(out), chunk):
        part = slice(start, start + chunk)
        sums = np.einsum("pi,isab->psab", pay, payload_rest[:, part])
        out[part] = np.linalg.eigvalsh(_dilation(sums) + A[part]).max(axis=-1).max(axis=0)
    return out


def inertia_range(G_exact_box, G_exact_payload, pay) -> tuple[float, float]:
    """``(lo, hi)``: the true robots' inertia between ``lo`` and ``hi`` times the model's (eigenvalues of
    ``M_hat^-1 M = I - G`` over the set and the task's samples; ``G_exact`` in each sample's ``M_hat^1/2``
    coordinates, where it is symmetric)."""
    bottom, top, _ = spectrum_bounds(G_exact_box, G_exact_payload, pay)
    return 1.0 - float(top.max()), 1.0 - float(bottom.min())


def inertia_ratio(robot, scalars, q, moved_robot) -> float:
    """``rho``: the largest ``|eig(M_hat^-1 dM)|`` over the box's vertices along each scalar, summed (a bound, for reports).

    ``moved_robot(robot, scalar, sign)``: the loop's model robot moved by the scalar's half range.
    """
    dM = []
    model = robot.model_robot
    for s in scalars:
        if s.joint >= 0:
            continue
        moved = moved_robot(
            robot, s, 1.0 if float(model.model.inertias[s.body].mass) + s.half_range * s.params[0] > 0 else -1.0
        )
        dM.append(moved)
    worst = 0.0
    for qq in q[:8]:
        M_hat = model.mass_matrix(qq)
        L = np.linalg.cholesky(M_hat)
        total = 0.0
        for moved in dM:
            D = moved.mass_matrix(qq) - M_hat
            total += float(np.max(np.abs(np.linalg.eigvalsh(np.linalg.solve(L, np.linalg.solve(L, D).T)))))
        worst = max(worst, total)
    return worst
