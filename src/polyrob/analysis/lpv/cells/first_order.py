"""The first-order cell test: the change of the LMI over a cell bounded part by part (plant, ``X``, rates).

Kept beside the second-order test (:mod:`polyrob.analysis.lpv.cells.second_order`) because it needs only
first derivatives of the robot's Jacobians; on a loop whose ``X(rho)`` follows the plant its parts cancel,
which this bound cannot see (docs/certificates.md).
"""

from __future__ import annotations

import numpy as np

from polyrob.analysis.lpv.cells.loop import derivative_columns, spectral_norms
from polyrob.analysis.lpv.check import GridData, brl_matrices
from polyrob.bounds.certified.analytic import distance_up, function_balls

__all__ = ["first_order_cell"]

_U = np.finfo(float).eps


def first_order_cell(loop, model, enclose, basis, Xs, rates_at, gamma, lo, hi):
    """``(margin, first-order bound per coordinate, the same per unit width, why)`` of one cell.

    ``margin > 0`` proves it (at most 1).
    """
    ctr, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    Ap, Bp = model.plant(ctr)
    enc = enclose(lo, hi)
    A, B, C, D = loop.at(Ap, Bp)
    n, m, q = A.shape[0], B.shape[1], C.shape[0]
    s = n + m + q
    xcol = derivative_columns(model)  # rho_i is x[xcol[i]] (z on a task)
    # mean value form: P_e(rho) - P_e(rho_c) = sum_i delta_i dP_e/drho_i(xi), |delta_i| <= half_i
    P = {"A": (Ap, enc.dA_lo, enc.dA_hi), "B": (Bp, enc.dB_lo, enc.dB_hi)}
    dlo = np.array([[P[kd][1][i, j, x] for kd, i, j in loop.entries] for x in xcol])  # (p, E)
    dhi = np.array([[P[kd][2][i, j, x] for kd, i, j in loop.entries] for x in xcol])
    dmid, drad = 0.5 * (dlo + dhi), 0.5 * (dhi - dlo) * (1 + 4 * _U)
    eps = 1e-13 * (1 + np.abs([P[kd][0][i, j] for kd, i, j in loop.entries]))  # the centre's own rounding
    f_c = np.array([float(fn(ctr)) for fn, _ in basis])
    g_c = np.array([np.asarray(gr(ctr), float) for _, gr in basis])
    fb, gb = function_balls(basis, lo, hi)
    df = distance_up(fb[0], fb[1], f_c)  # |f_j(rho) - f_j(rho_c)|
    dg = distance_up(gb[0], gb[1], g_c)  # |df_j/drho_i (rho) - df_j/drho_i (rho_c)|, (k, p)
    gmid, grad = 0.5 * (gb[0] + gb[1]), 0.5 * (gb[1] - gb[0]) * (1 + 4 * _U)  # df_j/drho_i over the cell
    X = np.einsum("k,kij->ij", f_c, Xs)
    Dx = np.einsum("kp,kij->pij", gmid, Xs)  # X(rho) - X_c = sum_i delta_i (Dx_i + sum_j grad_ji theta X_j)
    # the change of M for a unit change of entry e at X_c (S_e), and of Z = [A B 0] (Z_e): M is affine in them
    GA, GB, GC, GD = (np.array([g[t] for g in loop.G]) for t in range(4))
    XA, XB = X @ GA, X @ GB
    S, Z = np.zeros((len(GA), s, s)), np.zeros((len(GA), n, s))
    S[:, :n, :n] = XA + np.transpose(XA, (0, 2, 1))
    S[:, :n, n : n + m], S[:, n + m :, :n], S[:, n + m :, n : n + m] = XB, GC, GD
    S[:, n : n + m, :n] = np.transpose(XB, (0, 2, 1))
    S[:, :n, n + m :], S[:, n : n + m, n + m :] = np.transpose(GC, (0, 2, 1)), np.transpose(GD, (0, 2, 1))
    Z[:, :, :n], Z[:, :, n : n + m] = GA, GB
    Si, Zi = np.einsum("pe,eij->pij", dmid, S), np.einsum("pe,eij->pij", dmid, Z)  # along each rho_i
    Zc = np.zeros((n, s))
    Zc[:, :n], Zc[:, n : n + m] = A, B
    rc = np.array(rates_at(ctr), float)  # (p, 2)
    free = ~np.isfinite(rc).all(axis=1)  # a coordinate moving arbitrarily fast: X must not depend on it
    if np.any(gb[:, :, free]):
        return -np.inf, None, "X depends on a parameter whose rate is unbounded"
    rc[free] = 0.0
    rl, rh = np.array(rates_at(lo), float), np.array(rates_at(hi), float)
    rl[free], rh[free] = 0.0, 0.0
    fixed = rc[:, 0] == rc[:, 1]  # a position's rate is its velocity: it moves over the cell
    drate = np.where(fixed, np.maximum(np.abs(rl[:, 0] - rc[:, 0]), np.abs(rh[:, 0] - rc[:, 0])), 0.0)
    nus = np.array(np.meshgrid(*[np.unique(x) for x in rc], indexing="ij")).reshape(len(lo), -1).T
    data = GridData(A[None], B[None], C[None], D[None], f_c[None], g_c[None], nus[None], ctr[None])
    M, err, _, scale = brl_matrices(data, Xs, gamma)
    worst, contrib = np.inf, np.zeros(len(lo))
    for v, nu in enumerate(nus):
        # congruence by W = (-M_c)^(-1/2): M < 0 iff W M W < 0, and W M_c W = -I; each change is weighed by W,
        # so directions where M_c is very negative absorb large changes (a plain norm bound would not); one W per
        # vertex (one W at the rate box's centre left margins of 1e-4 at the vertices of paper_2r's loop)
        mu, V = np.linalg.eigh(-M[0, v])
        if mu[0] <= err[0, v] + loop.allowance:  # the float loop's LMI against the exact similar loop's
            return -np.inf, None, f"LMI not negative at rho = {tuple(round(float(x), 6) for x in ctr)}, a cell's centre"
        W = (V * mu**-0.5) @ V.T
        WE, ZcW = W[:, :n], Zc @ W
        lam = np.linalg.eigvalsh(W @ M[0, v] @ W)[-1] + (err[0, v] + 8 * s * _U * np.linalg.norm(M[0, v])
                                                          + loop.allowance) / mu[0]  # fmt: skip
        nS, nSi = spectral_norms(W @ S @ W), spectral_norms(W @ Si @ W)
        nZ, nZi = spectral_norms(Z @ W), spectral_norms(Zi @ W)
        b_plant = half @ (nSi + drad @ nS) + eps @ nS
        dZW = half @ (nZi + drad @ nZ) + eps @ nZ  # ||(Z(rho) - Z_c) W||
        WX, WD = WE @ Xs, WE @ Dx  # (k, s, n), (p, s, n)
        heX = spectral_norms(WX @ ZcW + np.transpose(WX @ ZcW, (0, 2, 1)))
        heD = spectral_norms(WD @ ZcW + np.transpose(WD @ ZcW, (0, 2, 1)))
        b_x = half @ (heD + grad.T @ heX) + 2 * (df @ spectral_norms(WX)) * dZW + (1e-15 * (1 + np.abs(f_c))) @ heX
        # the rate term's change: sum_i (nu_i d(df_j/drho_i) + dnu_i df_j/drho_i) X_j
        b_rate = (dg @ np.abs(nu) + (np.abs(g_c) + dg) @ drate) @ spectral_norms(WX @ WE.T)
        worst = min(worst, -(lam + (b_plant + b_x + b_rate) * (1 + 1e-9)))  # float norms: a little up
        contrib = np.maximum(contrib, half * (nSi + drad @ nS + heD + grad.T @ heX))  # first order, per coordinate
    lx, Vx = np.linalg.eigh(X)
    if lx[0] <= 8.0 * (n + len(basis) + 2) * _U * scale[0]:
        return (
            -np.inf,
            None,
            f"X(rho) not positive definite at rho = {tuple(round(float(x), 6) for x in ctr)}, a cell's centre",
        )
    Wx = (Vx * lx**-0.5) @ Vx.T  # X(rho) > 0 iff I + Wx (X(rho) - X_c) Wx > 0
    pos = 1.0 - df @ spectral_norms(Wx @ Xs @ Wx) * (1 + 1e-9) - 8.0 * (n + len(basis) + 2) * _U * scale[0] / lx[0]
    margin = min(worst, pos)
    why = ""
    if pos <= 0:
        why = "X(rho) not proved positive definite there"
    elif worst <= 0:
        why = "LMI not proved negative there"
    return float(margin), contrib, contrib / np.where(hi > lo, hi - lo, np.inf), why
