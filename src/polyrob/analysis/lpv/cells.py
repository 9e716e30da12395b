"""Between the grid points of the moving robot: the bounded-real LMIs proved on every cell of the state box.

The moving-robot search (:mod:`polyrob.analysis.lpv.moving`) proves its
``X(rho) = sum_j f_j(rho) X_j`` at grid points only.  Here the same ``X`` is
proved on the whole box of ``rho``, cell by cell.  For a cell with centre
``rho_c``, every vertex ``nu`` of its rate box and ``W = (-M(rho_c, nu))^(-1/2)``
(so that ``W M(rho_c) W = -I``), ``M(rho) < 0`` follows from

.. math:: \\lambda_{max}(W M(\\rho_c) W) + \\|W (M(\\rho) - M(\\rho_c)) W\\| < 0,

and the norm is bounded from guaranteed enclosures over the cell:

* the closed loop is affine in the robot's ``(A, B)`` (its response to a
  unit change of entry ``e`` is ``G_e``; at ``X_c`` the LMI changes by
  ``S_e``), and by the mean-value theorem ``P_e(rho) - P_e(rho_c) = sum_i
  delta_i dP_e/drho_i(xi)`` with ``dP_e/drho_i`` enclosed over the cell
  (:func:`polyrob.bounds.certified.analytic.analytic_jacobian_enclosure`,
  second derivatives of ``qddot``): the first-order part moves all entries
  together, ``sum_e mid(dP_e/drho_i) S_e``, and only the enclosure's radius
  is taken entry by entry;
* ``X(rho) - X_c`` likewise from the basis functions' gradients over the
  cell (:class:`~polyrob.bounds.certified.analytic.Jet` balls), the rate
  term ``sum_i nu_i dX/drho_i`` from their changes (a position's rate is its
  velocity, so it moves with the cell), the cross terms to second order;
* ``X(rho) > 0`` from ``||X_c^(-1/2) (X(rho) - X_c) X_c^(-1/2)|| < 1``.

Weighing every change by ``W`` is what makes this work on a stiff loop: the
LMI matrix has entries of ``1e4`` next to a margin of ``1e-2``, and a plain
norm bound would ask for cells a million times smaller.  A cell that fails is
bisected along the coordinate with the largest first-order term; a point
where the LMIs fail ends the search (the ``X`` does not hold there).  Before
the cells, the robot's accelerations are proved inside the rate bounds the
``X`` was built for (a sampled bound is not one: ``tests/test_cells.py``
shows a box where the sampled peak times 1.05 is below the robot's), so the
bound covers every trajectory of the linearised robot in the box.

Examples
--------
>>> c = CellCheck(True, 0.99, 120, 0.01, (1.0, 2.0), "", 3.0)
>>> c.words()
'proved on 120 cells covering the whole box at level 0.99 (accelerations proved <= 1, 2)'
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from polyrob.analysis.lpv.check import GridData, brl_matrices
from polyrob.bounds.certified.analytic import distance_up, function_balls
from polyrob.bounds.certified.boxes import prove_on_boxes

__all__ = ["CellCheck", "check_cells", "plant_enclosure"]

_U = np.finfo(float).eps


@dataclass(frozen=True)
class CellCheck:
    """The outcome of :func:`check_cells`.

    Attributes
    ----------
    holds : bool
        Every leaf cell passed: the LMIs hold on the whole box at ``gamma``.
    gamma : float
        The level checked.
    n_cells : int
        Leaf cells proved (all of them when ``holds``).
    smallest_margin : float
        Smallest proved margin ``-(lambda_max + bound)`` over the leaves.
    accelerations : tuple of float
        Proved bound of ``|qddot_j|`` over the box (the largest over the leaves).
    reason : str
        Why it does not hold.
    seconds : float
    sensitivity : tuple of float
        Per coordinate, the largest first-order change of the weighed LMI per
        unit of cell width seen (a cell must be narrower than about its inverse).
    """

    holds: bool
    gamma: float
    n_cells: int
    smallest_margin: float
    accelerations: tuple
    reason: str
    seconds: float
    sensitivity: tuple = ()

    def words(self) -> str:
        if not self.holds:
            return f"not proved between the grid points ({self.reason})"
        acc = ", ".join(f"{a:.4g}" for a in self.accelerations)
        return f"proved on {self.n_cells} cells covering the whole box at level {self.gamma:.4g}" + (
            f" (accelerations proved <= {acc})" if acc else ""
        )

    def summary(self) -> dict:
        from polyrob.analysis.scope import finite_or_none

        return {
            "holds": self.holds,
            "gamma": finite_or_none(self.gamma),
            "cells": self.n_cells,
            "smallest_margin": finite_or_none(self.smallest_margin),
            "accelerations": [finite_or_none(a) for a in self.accelerations],
            "reason": self.reason,
            "sensitivity": [finite_or_none(x) for x in self.sensitivity],
            "seconds": round(self.seconds, 1),
        }


def plant_enclosure(model):
    """``(lo, hi) box of rho -> enclosure`` of the robot's ``A, B, qddot`` over it, or ``None`` when unavailable."""
    from polyrob.model.analytic import AnalyticRobot

    if not isinstance(model.robot, AnalyticRobot):
        return None
    from polyrob.bounds.certified.analytic import analytic_jacobian_enclosure

    def enclose(lo, hi):
        (ql, vl), (qh, vh) = model.state(lo), model.state(hi)
        return analytic_jacobian_enclosure(model.robot, ql, qh, vl, vh, model.u)

    return enclose


class _Loop:
    """The time-scaled, balanced closed loop as an affine function of the robot's varying ``(A, B)`` entries.

    ``c`` and the balancing ``sc`` are powers of two: the loop's matrices are exact images of the robot's.
    """

    def __init__(self, of_plant, c, sc, A0, B0):
        self.c, self.sc = c, sc
        base = self._cond(*of_plant(A0, B0))
        m2 = A0.shape[0]
        m = m2 // 2
        self.entries = [("A", i, j) for i in range(m, m2) for j in range(m2)] + [
            ("B", i, j) for i in range(m, m2) for j in range(B0.shape[1])
        ]
        G = []
        for kind, i, j in self.entries:
            A1, B1 = A0.copy(), B0.copy()
            (A1 if kind == "A" else B1)[i, j] += 1.0
            one = self._cond(*of_plant(A1, B1))
            A2, B2 = A0.copy(), B0.copy()
            (A2 if kind == "A" else B2)[i, j] += 2.0
            two = self._cond(*of_plant(A2, B2))
            d1 = [x - y for x, y in zip(one, base)]
            d2 = [x - y for x, y in zip(two, base)]
            if any(np.abs(b - 2 * a).max() > 1e-8 * (1 + np.abs(b).max()) for a, b in zip(d1, d2)):
                raise ValueError("the closed loop is not affine in the robot's Jacobians")
            G.append(d1)
        self.G = G
        self.of_plant = of_plant

    def _cond(self, A, B, C, D):
        A, B, s = A / self.c, B / self.c, self.sc
        return A / s[:, None] * s[None, :], B / s[:, None], C * s[None, :], D

    def at(self, Ap, Bp):
        return self._cond(*self.of_plant(Ap, Bp))


def _norms(stack) -> np.ndarray:
    """Spectral norms of a stack of matrices (float SVD: the caller rounds the sum up)."""
    return np.linalg.norm(stack, 2, axis=(-2, -1)) if len(stack) else np.zeros(0)


def _cell(loop, model, enclose, basis, Xs, rates_at, gamma, lo, hi):
    """``(margin, first-order bound per coordinate, why)`` of one cell: ``margin > 0`` proves it (at most 1)."""
    ctr, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    Ap, Bp = model.plant(ctr)
    enc = enclose(lo, hi)
    A, B, C, D = loop.at(Ap, Bp)
    n, m, q = A.shape[0], B.shape[1], C.shape[0]
    s = n + m + q
    mm = model.robot.m
    xcol = [j if kind == "q" else mm + j for kind, j in zip(model.kinds, model.joints)]  # rho_i is x[xcol[i]]
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
        if mu[0] <= err[0, v]:
            return -np.inf, None, f"LMI not negative at rho = {tuple(round(float(x), 6) for x in ctr)}, a cell's centre"
        W = (V * mu**-0.5) @ V.T
        WE, ZcW = W[:, :n], Zc @ W
        lam = np.linalg.eigvalsh(W @ M[0, v] @ W)[-1] + (err[0, v] + 8 * s * _U * np.linalg.norm(M[0, v])) / mu[0]
        nS, nSi = _norms(W @ S @ W), _norms(W @ Si @ W)
        nZ, nZi = _norms(Z @ W), _norms(Zi @ W)
        b_plant = half @ (nSi + drad @ nS) + eps @ nS
        dZW = half @ (nZi + drad @ nZ) + eps @ nZ  # ||(Z(rho) - Z_c) W||
        WX, WD = WE @ Xs, WE @ Dx  # (k, s, n), (p, s, n)
        heX = _norms(WX @ ZcW + np.transpose(WX @ ZcW, (0, 2, 1)))
        heD = _norms(WD @ ZcW + np.transpose(WD @ ZcW, (0, 2, 1)))
        b_x = half @ (heD + grad.T @ heX) + 2 * (df @ _norms(WX)) * dZW + (1e-15 * (1 + np.abs(f_c))) @ heX
        # the rate term's change: sum_i (nu_i d(df_j/drho_i) + dnu_i df_j/drho_i) X_j
        b_rate = (dg @ np.abs(nu) + (np.abs(g_c) + dg) @ drate) @ _norms(WX @ WE.T)
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
    pos = 1.0 - df @ _norms(Wx @ Xs @ Wx) * (1 + 1e-9) - 8.0 * (n + len(basis) + 2) * _U * scale[0] / lx[0]
    margin = min(worst, pos)
    why = ""
    if pos <= 0:
        why = "X(rho) not proved positive definite there"
    elif worst <= 0:
        why = "LMI not proved negative there"
    return float(margin), contrib, why


def _accelerations(model, enclose, bounds):
    """``box -> (relative margin, |qddot| bound, why)``: the robot's accelerations inside ``bounds`` there."""
    fin = np.isfinite(bounds)

    def evaluate(lo, hi):
        q, qdot = model.state(0.5 * (lo + hi))
        at_centre = np.abs(model.robot.acceleration(q, qdot, model.u))
        if np.any(at_centre[fin] > bounds[fin]):
            return (
                -np.inf,
                at_centre,
                f"the robot's acceleration {at_centre} exceeds the rate bounds at rho = {0.5 * (lo + hi)}",
            )
        enc = enclose(lo, hi)
        qdd = np.maximum(np.abs(enc.qddot_lo), np.abs(enc.qddot_hi))
        margin = float(np.min((bounds[fin] - qdd[fin]) / bounds[fin])) if np.any(fin) else 1.0
        return margin, qdd, "the robot's accelerations may exceed the rate bounds"

    return evaluate


def check_cells(model, system, Xs, basis, rates, gamma, *, similarity=None, c=1.0, cells=None, max_cells=200_000,
                time_limit=900.0, min_width=1e-6, progress=False) -> CellCheck:  # fmt: skip
    """Prove the bounded-real LMIs of ``X(rho) = sum_j f_j(rho) X_j`` at level ``gamma`` on the whole box of ``rho``.

    Parameters
    ----------
    model : MovingRobotModel
    system : callable
        :func:`~polyrob.analysis.lpv.robot.closed_loop_system` (its ``of_plant``).
    Xs : sequence of ndarray
        ``X_j`` in the coordinates of the loop the search ran on, ``x = T x~``
        and time scaled by ``c`` (:func:`~polyrob.analysis.lpv.robot.conditioned`).
    basis : sequence of (f, grad)
        The functions ``f_j``; each must evaluate on :class:`~polyrob.bounds.certified.analytic.Jet` arrays.
    rates : sequence of (float, float)
        The rate bounds in physical time (a position's rate is its velocity).
    gamma : float
    similarity : ndarray, optional
        ``T`` (default: the identity); the check itself runs in the loop's own coordinates.
    c : float
        The time scale.
    cells : sequence of int, optional
        Initial cells per coordinate (default: the model's grid).
    max_cells, time_limit, min_width
        Give up past that many cells, seconds, or a cell narrower than
        ``min_width`` times its coordinate's range.
    progress : bool
        A tqdm bar (cells proved / cells known).

    Returns
    -------
    CellCheck
    """
    from polyrob.analysis.lpv.norm import state_scaling
    from polyrob.analysis.lpv.robot import kinematic_rates

    t0 = time.perf_counter()
    if basis is None:  # a constant X (arbitrarily fast variation)
        basis = [(lambda r: 1.0, lambda r: np.zeros(len(model.names)))]
    enclose = plant_enclosure(model)
    if enclose is None:
        return CellCheck(False, gamma, 0, -np.inf, (), f"no guaranteed enclosure for {model.robot.name}", 0.0)
    lo0 = np.array([a[0] for a in model.axes], float)
    hi0 = np.array([a[-1] for a in model.axes], float)
    sizes = [a.size - 1 for a in model.axes] if cells is None else list(cells)
    if model.mirrored:  # the cells cover the whole box: the proof does not lean on the (sampled) evenness
        lo0[0], sizes[0] = -hi0[0], 2 * sizes[0]
    edges = [np.linspace(lo0[i], hi0[i], max(1, sizes[i]) + 1) for i in range(len(lo0))]
    A0, B0 = model.plant(0.5 * (lo0 + hi0))
    corners = np.array(np.meshgrid(*edges, indexing="ij")).reshape(len(lo0), -1).T
    sc = state_scaling(np.array([system.of_plant(*model.plant(p))[0] for p in corners]))  # as the grid check
    loop = _Loop(system.of_plant, c, sc, A0, B0)
    n = sc.size
    # X back in the loop's own (time-scaled, balanced) coordinates, x = T x~: X = T^-T X~ T^-1.  The float
    # product is a candidate like any other, and it is what the cells check: no inverse is trusted
    Ti = np.eye(n) if similarity is None else np.linalg.inv(np.asarray(similarity, float))
    Xs = np.einsum("ai,kab,bj->kij", Ti, np.asarray(Xs, float), Ti)
    Xs = 0.5 * (Xs + np.transpose(Xs, (0, 2, 1))) * sc[None, :, None] * sc[None, None, :]
    rates_at = kinematic_rates(model, rates, c)
    acc_bounds = np.full(model.robot.m, np.inf)
    for (_lo, hi), kind, j in zip(rates, model.kinds, model.joints):
        if kind == "qdot":
            acc_bounds[j] = hi
    boxes = [
        (np.array([e[k] for e, k in zip(edges, idx)]), np.array([e[k + 1] for e, k in zip(edges, idx)]))
        for idx in np.ndindex(*[len(e) - 1 for e in edges])
    ]
    width0 = np.where(hi0 > lo0, hi0 - lo0, 1.0)
    deadline = t0 + time_limit
    opts = {"min_width": min_width, "max_boxes": max_cells, "deadline": deadline}
    ok, leaves, why = prove_on_boxes([(lo0, hi0)], _accelerations(model, enclose, acc_bounds), width0, **opts)
    acc = tuple(float(a) for a in np.max([v[1] for v in leaves], axis=0)) if leaves else ()
    if not ok:
        return CellCheck(False, gamma, 0, -np.inf, acc, f"accelerations: {why}", time.perf_counter() - t0)

    seen = np.zeros(len(lo0))

    def evaluate(lo, hi):
        out = _cell(loop, model, enclose, basis, Xs, rates_at, gamma, lo, hi)
        if out[1] is not None:
            seen[:] = np.maximum(seen, out[1] / np.where(hi > lo, hi - lo, np.inf))
        return out

    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=len(boxes), desc="cells", unit="cell")
    try:
        ok, leaves, why = prove_on_boxes(boxes, evaluate, width0, bar=bar, by_contribution=True, **opts)
    finally:
        if bar is not None:
            bar.close()
    smallest = min((v[0] for v in leaves), default=-np.inf)
    return CellCheck(
        ok, gamma, len(leaves), smallest, acc, why, time.perf_counter() - t0, tuple(float(x) for x in seen)
    )
