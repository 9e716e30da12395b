"""The inertia block of the ``inner-links`` model: the relative inertia error ``G = I - M_hat^-1 M`` as one norm-bounded block.

Split from :mod:`~polyrob.plant.models.inner_links` (its module text says
how the block is used): the weighted forms of ``G`` over the task's
samples, the bound of their spread over the set, and the inertia ratio the
model reports.
"""

from __future__ import annotations

import numpy as np

__all__ = ["exactly_weighted", "spectrum_bounds", "g_norm_bound", "inertia_range", "inertia_ratio"]


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


def g_norm_bound(box_rest, payload_rest, pay, kappa) -> tuple[float, float]:
    """``(g_norm, g0)``: ``||sum_j u_j R_j - g0 I||_2 <= g_norm`` (acceleration columns) over the set and the samples.

    The symmetric part's spectrum of :func:`spectrum_bounds`, centred: ``g0``
    centres that range (a heavy off-axis payload raises the inertia more
    than a light one lowers it); the skew part adds its norm; ``kappa`` per
    sample is what a fixed weighting costs there.
    """
    bottom, top, skew = spectrum_bounds(box_rest, payload_rest, pay)
    g0 = 0.5 * (float(top.max()) + float(bottom.min()))
    half = np.maximum(top - g0, g0 - bottom).max(axis=0)
    return float((kappa * (half + skew)).max()), g0


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
