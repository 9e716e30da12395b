"""The second-order cell test: the LMI's exact derivative at the cell's centre, its curvature enclosed over the cell.

The bounded-real matrix of the moving robot is a sum of scalar functions of
``rho`` times fixed matrices,

.. math:: L(\\rho) = \\sum_t s_t(\\rho)\\, G_t + \\text{const},

with ``s_t`` in ``f_j`` (``X = sum_j f_j X_j``, against ``He(E X_j Z_c)``),
``f_j Delta P_e`` (the robot's entry ``e`` minus its centre value, against
``He(E X_j Z_e)``), ``r_j = sum_i nu_i df_j/drho_i`` (the rate term, against
``E X_j E^T``) and ``Delta P_e`` (the output blocks).  Taylor's theorem with
the integral remainder, after the congruence by ``W = (-L(rho_c))^(-1/2)``:

.. math:: W L(\\rho) W = W L_c W + \\sum_a \\delta_a D_a + R, \\quad
   \\|R\\| \\le \\tfrac12 \\sum_{ab} h_a h_b K_{ab},

``D_a = sum_t ds_t/drho_a(rho_c) W G_t W`` (one matrix: the plant's and
``X``'s parts keep their cancellation, which bounding them apart loses:
4302 against 5.44 per radian on paper_2r at x4, docs/certificates.md) and
``K_ab >= sup_cell ||sum_t d2s_t/drho_a drho_b W G_t W||``, bounded by the
matrix of the enclosures' midpoints plus their radii term by term.  The
largest eigenvalue of the affine part is convex in ``delta``: it is checked
at the ``2^p`` vertices of the cell.  Every derivative is an outward-rounded
ball (:func:`~polyrob.bounds.certified.analytic.analytic_jacobian_enclosure`
with ``order=3``, :func:`~polyrob.bounds.certified.analytic.function_balls`),
every float product has a rounding allowance.  The interval products are
vectorised numpy written here: ``flint.arb`` balls are scalars, and a cell
needs some ten thousand of them.

Examples
--------
>>> lo, hi = interval_product((np.array([-1.0]), np.array([2.0])), (np.array([3.0]), np.array([4.0])))
>>> float(lo[0]) <= -4.0 and float(hi[0]) >= 8.0
True
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from polyrob.analysis.lpv.cells.loop import derivative_columns, symmetric_norms
from polyrob.analysis.lpv.check import GridData, brl_matrices
from polyrob.bounds.certified.analytic import function_balls

__all__ = ["Expansion", "expansions", "second_order_cell", "interval_product", "interval_sum", "fixed_terms"]

_U = np.finfo(float).eps


def _down(x):
    return np.nextafter(x, -np.inf)


def _up(x):
    return np.nextafter(x, np.inf)


def interval_product(a, b):
    """``[lo, hi]`` holding every product of ``a = (lo, hi)`` and ``b`` (arrays, broadcast), rounded outward."""
    p = np.stack(np.broadcast_arrays(a[0] * b[0], a[0] * b[1], a[1] * b[0], a[1] * b[1]))
    return _down(p.min(axis=0)), _up(p.max(axis=0))


def interval_sum(*terms):
    """``[lo, hi]`` holding the sum of intervals (each addition rounded outward)."""
    lo, hi = terms[0]
    for a, b in terms[1:]:
        lo, hi = _down(lo + a), _up(hi + b)
    return lo, hi


def _sum_axis(x, axis):
    """Sum of intervals along ``axis``, bounded outward (float summation error <= (n-1) u sum |x|)."""
    n = x[0].shape[axis]
    slack = 2 * n * _U
    return (
        _down(np.sum(x[0], axis=axis) - slack * np.sum(np.abs(x[0]), axis=axis)),
        _up(np.sum(x[1], axis=axis) + slack * np.sum(np.abs(x[1]), axis=axis)),
    )


def _he(n, s, XZ):
    """``He(E XZ)`` for a stack ``XZ`` of ``(n, s)`` blocks, ``E = [I; 0]`` (``s x n``)."""
    out = np.zeros(XZ.shape[:-2] + (s, s))
    out[..., :n, :] += XZ
    out[..., :, :n] += np.swapaxes(XZ, -1, -2)
    return out


def fixed_terms(loop, Xs, n: int, m: int, q: int) -> dict:
    """The matrices ``G_t`` that do not change from cell to cell, and their float rounding bounds."""
    s = n + m + q
    GA, GB, GC, GD = (np.array([g[t] for g in loop.G]) for t in range(4))
    Ze = np.zeros((len(GA), n, s))
    Ze[:, :, :n], Ze[:, :, n : n + m] = GA, GB
    XZ = np.einsum("kab,ebc->keac", Xs, Ze)  # (k, E, n, s)
    G_xe = _he(n, s, XZ)
    R = np.zeros((len(Xs), s, s))
    R[:, :n, :n] = Xs
    Q = np.zeros((len(GA), s, s))
    Q[:, n + m :, :n], Q[:, n + m :, n : n + m] = GC, GD
    Q[:, :n, n + m :], Q[:, n : n + m, n + m :] = np.swapaxes(GC, 1, 2), np.swapaxes(GD, 1, 2)
    nX = np.linalg.norm(Xs, axis=(1, 2))
    err_xe = 4 * n * _U * nX[:, None] * np.linalg.norm(Ze, axis=(1, 2))[None, :]  # float X_j Z_e, both blocks
    return {"G_xe": G_xe.reshape(-1, s, s), "R": R, "Q": Q, "nX": nX, "err_xe": err_xe.reshape(-1)}


def _robot_terms(loop, enc, xcol):
    """Entry values ``(2, E)``, gradients ``(2, E, p)`` and (with third order) Hessians ``(2, E, p, p)``, as intervals."""
    src = {"A": (enc.A_lo, enc.A_hi, enc.dA_lo, enc.dA_hi, enc.d2A_lo, enc.d2A_hi),
           "B": (enc.B_lo, enc.B_hi, enc.dB_lo, enc.dB_hi, enc.d2B_lo, enc.d2B_hi)}  # fmt: skip
    P = np.array([[src[kd][t][i, j] for kd, i, j in loop.entries] for t in (0, 1)])
    dP = np.array([[src[kd][t][i, j][xcol] for kd, i, j in loop.entries] for t in (2, 3)])
    if enc.d2A_lo is None:
        return P, dP, None
    d2P = np.array([[src[kd][t][i, j][np.ix_(xcol, xcol)] for kd, i, j in loop.entries] for t in (4, 5)])
    return P, dP, d2P


@dataclass(frozen=True, eq=False)
class Expansion:
    """The LMI at one vertex ``nu`` of a cell's rate box, weighed by ``W``, to second order about the centre.

    For every ``rho`` of the cell, ``W L(rho) W = WLW + sum_a delta_a D[a] + R`` with
    ``||R|| <= allowance + 0.5 h K h`` (``delta = rho - centre``, ``|delta_a| <= h_a``).
    """

    nu: np.ndarray
    W: np.ndarray
    WLW: np.ndarray
    D: np.ndarray
    K: np.ndarray
    allowance: float


def expansions(loop, model, enclose, basis, Xs, rate_plan, fixed, gamma, lo, hi):
    """``(list of Expansion, X's centre data, why)``: one :class:`Expansion` per rate vertex of the cell.

    ``enclose(lo, hi, order)``: the robot's enclosure; ``rate_plan``: ``(exact, box)``, ``exact[i]`` either
    ``None`` (the rate of ``rho_i`` is any value in ``box[i]``) or ``(w, slope)`` (it is ``slope * rho_w``,
    valid while inside ``box[i]``); ``fixed``: :func:`fixed_terms`.  ``why`` is not empty when the cell
    cannot be expanded (then the list is empty).
    """
    ctr, h = 0.5 * (lo + hi), 0.5 * (hi - lo)
    p, k = len(lo), len(basis)
    exact, box = rate_plan
    for i, how in enumerate(exact):  # nu_i = slope rho_w is exact only while the domain's clip is inactive
        if how is not None:
            w, sl = how
            ends = sl * np.array([lo[w], hi[w]])
            if ends.min() < box[i][0] or ends.max() > box[i][1]:
                return [], None, "a position's rate leaves its bound inside the cell (the clip is active)"
    Ap, Bp = model.plant(ctr)
    A, B, C, D = loop.at(Ap, Bp)
    n, m, q = A.shape[0], B.shape[1], C.shape[0]
    s = n + m + q
    xcol = derivative_columns(model)
    Pc, dPc, _ = _robot_terms(loop, enclose(ctr, ctr, 2), xcol)
    Pcell, dPcell, d2Pcell = _robot_terms(loop, enclose(lo, hi, 3), xcol)
    fc, gc, Hc = function_balls(basis, ctr, ctr, order=2)
    fcell, gcell, Hcell, Tcell = function_balls(basis, lo, hi, order=3)
    free = [not np.all(np.isfinite(b)) for b in box]  # a rate without bound: X must not depend on that parameter
    if np.any(gcell[:, :, free]):
        return [], None, "X depends on a parameter whose rate is unbounded"
    E = Pc.shape[1]
    P_fl = np.array([(Ap if kd == "A" else Bp)[i, j] for kd, i, j in loop.entries])  # the float centre L_c uses
    dP_c = (_down(Pc[0] - P_fl), _up(Pc[1] - P_fl))  # P_e(rho_c) - its float value: a rounding error
    dP = (_down(Pcell[0] - P_fl), _up(Pcell[1] - P_fl))  # P_e(rho) - the float centre value, over the cell
    S = np.zeros((p, p))  # d nu_i / d rho_a
    for i, how in enumerate(exact):
        if how is not None:
            S[i, how[0]] = how[1]
    # the scalar functions' gradients at the centre and Hessians over the cell, as intervals; f_j Delta P_e first
    grad_fe = interval_sum(
        interval_product((fc[0][:, None, None], fc[1][:, None, None]), (dPc[0][None], dPc[1][None])),
        interval_product((gc[0][:, None], gc[1][:, None]), (dP_c[0][None, :, None], dP_c[1][None, :, None])),
    )
    hess_fe = interval_sum(
        interval_product((Hcell[0][:, None], Hcell[1][:, None]), (dP[0][None, :, None, None], dP[1][None, :, None, None])),
        interval_product((gcell[0][:, None, :, None], gcell[1][:, None, :, None]),
                         (dPcell[0][None, :, None, :], dPcell[1][None, :, None, :])),
        interval_product((gcell[0][:, None, None, :], gcell[1][:, None, None, :]),
                         (dPcell[0][None, :, :, None], dPcell[1][None, :, :, None])),
        interval_product((fcell[0][:, None, None, None], fcell[1][:, None, None, None]), (d2Pcell[0][None], d2Pcell[1][None])),
    )  # fmt: skip
    val_fe = np.maximum(np.abs(fc).max(axis=0)[:, None] * np.maximum(np.abs(dP_c[0]), np.abs(dP_c[1]))[None], 0.0)
    vertices = [np.array(v) for v in itertools.product(*[[0.0] if how is not None or f else sorted({b[0], b[1]})
                                                         for how, b, f in zip(exact, box, free)])]  # fmt: skip
    Zc = np.zeros((n, s))
    Zc[:, :n], Zc[:, n : n + m] = A, B
    G_x0 = _he(n, s, np.einsum("kab,bc->kac", Xs, Zc))
    G = np.concatenate([G_x0, fixed["G_xe"], fixed["R"], fixed["Q"]])  # (T, s, s)
    nGf = np.linalg.norm(G, axis=(1, 2))
    gerr = np.concatenate([4 * n * _U * fixed["nX"] * np.linalg.norm(Zc), fixed["err_xe"], np.zeros(k + E)])
    dist_c = np.maximum(np.abs(dP_c[0]), np.abs(dP_c[1]))
    # sum_i dnu_i/drho_a d2f_j/drho_i drho_b: the same at every rate vertex
    SH = _sum_axis(interval_product((S[None, :, :, None], S[None, :, :, None]), (Hcell[0][:, :, None, :], Hcell[1][:, :, None, :])), 1)  # fmt: skip
    out = []
    for vert in vertices:
        nu_c = vert + S @ ctr  # the rates at the centre (exact ones from the velocity)
        nu_box = (_down(vert + np.minimum(S @ lo, S @ hi)), _up(vert + np.maximum(S @ lo, S @ hi)))
        # r_j = sum_i nu_i df_j/drho_i: gradient at the centre, Hessian over the cell (third derivatives of f)
        grad_r = interval_sum(_sum_axis(interval_product((gc[0][:, :, None], gc[1][:, :, None]), (S[None], S[None])), 1),
                              _sum_axis(interval_product((Hc[0], Hc[1]), (nu_c[None, :, None], nu_c[None, :, None])), 1))  # fmt: skip
        hess_r = interval_sum(SH, (np.swapaxes(SH[0], 1, 2), np.swapaxes(SH[1], 1, 2)),
                              _sum_axis(interval_product((nu_box[0][None, :, None, None], nu_box[1][None, :, None, None]),
                                                         (Tcell[0], Tcell[1])), 1))  # fmt: skip
        grad = [np.concatenate([gc[t], grad_fe[t].reshape(-1, p), grad_r[t], dPc[t]]) for t in (0, 1)]  # (T, p)
        hess = [np.concatenate([Hcell[t], hess_fe[t].reshape(-1, p, p), hess_r[t], d2Pcell[t]]) for t in (0, 1)]
        r_c = interval_product((gc[0], gc[1]), (nu_c[None], nu_c[None]))
        r_rad = np.max(np.abs(np.stack(r_c) - (0.5 * (gc[0] + gc[1]) * nu_c[None])), axis=0).sum(axis=1) * (1 + 1e-9)
        # the centre's terms are float values: what the exact ones differ by (balls' radii, P_e's rounding)
        val_err = np.concatenate([0.5 * (fc[1] - fc[0]), val_fe.reshape(-1), r_rad, dist_c])
        data = GridData(A[None], B[None], C[None], D[None], (0.5 * (fc[0] + fc[1]))[None],
                        (0.5 * (gc[0] + gc[1]))[None], nu_c[None, None], ctr[None])  # fmt: skip
        M, err, _, _ = brl_matrices(data, Xs, gamma)
        Lc = M[0, 0]
        mu, V = np.linalg.eigh(-Lc)
        if mu[0] <= err[0, 0] + loop.allowance:  # the float loop's LMI against the exact similar loop's
            return [], None, f"LMI not negative at rho = {tuple(round(float(x), 6) for x in ctr)}, a cell's centre"
        W = (V * mu**-0.5) @ V.T
        WGW = W @ G @ W
        nG = symmetric_norms(WGW) * (1 + 1e-9)
        gmid, grad_rad = 0.5 * (grad[0] + grad[1]), _up(0.5 * (grad[1] - grad[0]))
        hmid, hrad = 0.5 * (hess[0] + hess[1]), _up(0.5 * (hess[1] - hess[0]))
        Dw = np.einsum("ta,tij->aij", gmid, WGW)
        # rounding: W G W (2 s u |W|^2 |G|), the sums over t, eigenvalues; |W|^2 = 1 / mu_min
        fl = 4 * (len(G) + 2 * s) * _U / mu[0]
        d_err = grad_rad.T @ nG + fl * (np.abs(gmid).T @ nGf)
        K = symmetric_norms(np.einsum("tab,tij->abij", hmid, WGW).reshape(p * p, s, s)).reshape(p, p) * (1 + 1e-9)
        K = K + np.einsum("tab,t->ab", hrad, nG) + fl * np.einsum("tab,t->ab", np.abs(hmid), nGf)
        # the float G_t against the exact ones, times how far s_t moves over the cell
        ds = np.maximum(np.abs(grad[0]), np.abs(grad[1])) @ h + 0.5 * np.einsum("tab,a,b->t", np.maximum(
            np.abs(hess[0]), np.abs(hess[1])), h, h)  # fmt: skip
        base = (err[0, 0] + 8 * s * _U * np.linalg.norm(Lc) + loop.allowance) / mu[0] + (ds @ gerr) / mu[0] + val_err @ nG
        out.append(Expansion(nu_c, W, W @ Lc @ W, Dw, K, float(base + h @ d_err)))
    return out, (fc, gc, Hcell), ""


def second_order_cell(loop, model, enclose, basis, Xs, rate_plan, fixed, gamma, lo, hi):
    """``(margin, contribution per coordinate, first-order change per unit width, why)`` of one cell.

    ``margin > 0`` proves it; the contribution (first and second order) chooses the coordinate to bisect;
    arguments: :func:`expansions`.
    """
    h, p = 0.5 * (hi - lo), len(lo)
    ex, fcs, why = expansions(loop, model, enclose, basis, Xs, rate_plan, fixed, gamma, lo, hi)
    if why:
        return -np.inf, None, why
    worst, contrib, slope = np.inf, np.zeros(p), np.zeros(p)
    signs = np.array(list(itertools.product((-1.0, 1.0), repeat=p)))  # the cell's vertices, one batch of eigenvalues
    for e in ex:
        T = e.WLW[None] + np.einsum("va,aij->vij", signs * h, e.D)  # lambda_max of the affine part: convex in delta
        top = float(np.max(np.linalg.eigvalsh(T)[:, -1] + 8 * T.shape[1] * _U * np.linalg.norm(T, axis=(1, 2))))
        worst = min(worst, -(top + e.allowance + 0.5 * h @ e.K @ h))
        nD = symmetric_norms(e.D)
        contrib, slope = np.maximum(contrib, h * (nD + e.K @ h)), np.maximum(slope, 0.5 * nD)
    pos = _positive_margin(Xs, fixed["nX"], *fcs, h)
    margin = min(worst, pos)
    if pos == -np.inf:
        where = tuple(round(float(x), 6) for x in 0.5 * (lo + hi))
        return -np.inf, None, f"X(rho) not positive definite at rho = {where}, a cell's centre"
    why = "X(rho) not proved positive definite there" if pos <= 0 else "LMI not proved negative there" if worst <= 0 else ""
    return float(margin), contrib, slope, why


def _positive_margin(Xs, nX, fc, gc, Hcell, h) -> float:
    """``X(rho) > 0`` on the cell to second order: ``> 0`` proves it, ``-inf`` when ``X`` is not definite at the centre.

    ``Wx X(rho) Wx = I + sum_a delta_a Dx_a + R`` with ``Wx = X_c^(-1/2)``; ``lambda_min`` of the affine part is
    concave (checked at the vertices), ``||R|| <= 0.5 h Kx h`` from the basis' Hessians over the cell.
    """
    n, k, p = Xs.shape[1], len(Xs), len(h)
    X = np.einsum("k,kij->ij", 0.5 * (fc[0] + fc[1]), Xs)
    lx, Vx = np.linalg.eigh(X)
    tol = 8.0 * (n + k + 2) * _U * (np.abs(fc).max(axis=0) @ nX) + (0.5 * (fc[1] - fc[0])) @ nX
    if lx[0] <= tol:
        return -np.inf
    Wx = (Vx * lx**-0.5) @ Vx.T
    WXW = Wx @ Xs @ Wx
    nW = symmetric_norms(WXW) * (1 + 1e-9)
    fl = 4 * (k + 2 * n) * _U / lx[0]  # forming Wx X_j Wx and the sums, |Wx|^2 = 1 / lambda_min
    gmid, grad_rad = 0.5 * (gc[0] + gc[1]), _up(0.5 * (gc[1] - gc[0]))
    hmid, hrad = 0.5 * (Hcell[0] + Hcell[1]), _up(0.5 * (Hcell[1] - Hcell[0]))
    Dx = np.einsum("ja,jrs->ars", gmid, WXW)
    Kx = symmetric_norms(np.einsum("jab,jrs->abrs", hmid, WXW).reshape(p * p, n, n)).reshape(p, p) * (1 + 1e-9)
    Kx = Kx + np.einsum("jab,j->ab", hrad, nW) + fl * np.einsum("jab,j->ab", np.abs(hmid), nX)
    allowance = tol / lx[0] + h @ (grad_rad.T @ nW + fl * (np.abs(gmid).T @ nX)) + 0.5 * h @ Kx @ h
    signs = np.array(list(itertools.product((-1.0, 1.0), repeat=p)))
    T = np.eye(n)[None] + np.einsum("va,ars->vrs", signs * h, Dx)
    low = float(np.min(np.linalg.eigvalsh(T)[:, 0] - 8 * n * _U * np.linalg.norm(T, axis=(1, 2))))
    return float(low - allowance)
