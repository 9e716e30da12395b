"""Between the grid points: multi-convexity for a system affine in the parameters.

When ``A, B, C, D`` are affine in ``rho`` (the user's declaration, checked
at the grid points) and ``X(rho)`` is affine (a constant ``X``, or an affine
basis), the bounded-real matrix ``M(rho, nu)`` of
:mod:`polyrob.analysis.lpv.check` is quadratic in ``rho`` and affine in
``nu``; its coefficient of ``rho_i^2`` is

.. math:: D_i = \\begin{bmatrix} Y_i A_i + A_i^T Y_i & Y_i B_i & 0 \\\\ B_i^T Y_i & 0 & 0
          \\\\ 0 & 0 & 0 \\end{bmatrix}

(``A_i, B_i, Y_i``: the slopes of ``A, B, X`` along ``rho_i``).  For any
unit vector ``v``, ``v^T M v`` is then a quadratic whose second derivative
along ``rho_i`` is ``2 v^T D_i v >= -2 e_i`` with ``e_i = max(0, -lambda_min(D_i))``,
so on the box ``prod [lo_i, hi_i]`` it exceeds its largest value at the
box's vertices by at most ``sum_i e_i (hi_i - lo_i)^2 / 4`` (Gahinet,
Apkarian & Chilali, "Affine parameter-dependent Lyapunov functions and real
parametric uncertainty", IEEE TAC 41(3), 1996: multi-convexity is
``e_i = 0``).  The box's vertices are grid points, and ``X(rho)``, affine,
is positive on the box when it is at the vertices: so LMIs verified at the
grid points with a margin above that allowance hold on the whole box.

Examples
--------
>>> import numpy as np
>>> from polyrob.analysis.lpv.check import grid_data
>>> pts = np.array([[0.0], [1.0]])
>>> A = [np.array([[-1.0 - r[0]]]) for r in pts]
>>> data = grid_data(A, [np.ones((1, 1))] * 2, [np.ones((1, 1))] * 2, [np.zeros((1, 1))] * 2, points=pts)
>>> aff = affine_terms(data)
>>> aff.system_affine, aff.basis_affine, round(float(aff.A[0, 0, 0]), 12)
(True, True, -1.0)
>>> curvature_slack(aff, data, [np.eye(1)]) < 1e-12     # constant X: M is affine in rho
True
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from polyrob.analysis.lpv.check import GridData

__all__ = ["AffineTerms", "affine_terms", "curvature_slack", "curvature_blocks"]

_U = np.finfo(float).eps
#: Relative residual below which grid values count as affine in rho.
AFFINE_RTOL = 1e-9


@dataclass(frozen=True, eq=False)
class AffineTerms:
    """Slopes of the system and of the basis along each parameter (least squares over the grid).

    Attributes
    ----------
    A, B : ndarray
        ``(p, n, n)`` and ``(p, n, m)``: ``dA/drho_i``, ``dB/drho_i``.
    F : ndarray
        ``(p, k)``: the slopes of the basis functions.
    system_affine, basis_affine : bool
        The grid values fit an affine function (and, for the basis, the
        gradients equal the slopes) to :data:`AFFINE_RTOL`.
    slope_error : ndarray
        ``(p,)``: a bound of the error of the fitted ``A_i, B_i``.
    width : ndarray
        ``(p,)``: ``hi_i - lo_i``.
    """

    A: np.ndarray
    B: np.ndarray
    F: np.ndarray
    system_affine: bool
    basis_affine: bool
    slope_error: np.ndarray
    width: np.ndarray


def _fit(values: np.ndarray, points: np.ndarray):
    """Affine least-squares fit ``values ~ c0 + sum_i rho_i c_i``: slopes ``(p, ...)`` and max residual."""
    N, p = points.shape
    Phi = np.hstack([np.ones((N, 1)), points])
    Y = values.reshape(N, -1)
    coef, *_ = np.linalg.lstsq(Phi, Y, rcond=None)
    res = float(np.max(np.abs(Phi @ coef - Y))) if Y.size else 0.0
    return coef[1:].reshape((p,) + values.shape[1:]), res


def affine_terms(data: GridData) -> AffineTerms:
    """Fit the slopes of ``A, B, C, D`` and of the basis over the grid, and say whether they are affine.

    Parameters
    ----------
    data : GridData

    Returns
    -------
    AffineTerms
    """
    pts = data.points
    width = pts.max(axis=0) - pts.min(axis=0)
    sA, rA = _fit(data.A, pts)
    sB, rB = _fit(data.B, pts)
    _, rC = _fit(data.C, pts)
    _, rD = _fit(data.D, pts)
    scale = max(1.0, *(float(np.max(np.abs(x))) for x in (data.A, data.B, data.C, data.D)))
    system_affine = max(rA, rB, rC, rD) <= AFFINE_RTOL * scale
    sF, rF = _fit(data.F, pts)
    gscale = max(1.0, float(np.max(np.abs(data.F))))
    grads_match = np.allclose(data.G, np.transpose(sF)[None], rtol=AFFINE_RTOL, atol=AFFINE_RTOL * gscale)
    basis_affine = bool(rF <= AFFINE_RTOL * gscale and grads_match)
    # a fitted slope is off by at most ~ 2 * (residual + rounding) / width along that axis
    err = 2.0 * (max(rA, rB) + 64 * _U * scale) / np.where(width > 0, width, 1.0)
    return AffineTerms(sA, sB, np.asarray(sF), bool(system_affine), basis_affine, err, width)


def curvature_blocks(aff: AffineTerms, Xs) -> np.ndarray:
    """The ``(n + m)``-square upper-left part of each ``D_i`` (the rest is zero): ``(p, n + m, n + m)``.

    Parameters
    ----------
    aff : AffineTerms
    Xs : sequence of ndarray
        The coefficient matrices of ``X(rho) = sum_j f_j(rho) X_j``.

    Returns
    -------
    ndarray
    """
    Xs = np.asarray(Xs, dtype=float)
    Y = np.einsum("pk,kij->pij", aff.F, Xs)
    p, n, m = aff.B.shape
    out = np.zeros((p, n + m, n + m))
    YA = Y @ aff.A
    YB = Y @ aff.B
    out[:, :n, :n] = YA + np.transpose(YA, (0, 2, 1))
    out[:, :n, n:] = YB
    out[:, n:, :n] = np.transpose(YB, (0, 2, 1))
    return out


def curvature_slack(aff: AffineTerms, data: GridData, Xs) -> float:
    """``sum_i e_i (hi_i - lo_i)^2 / 4``: how far ``M`` may rise above its vertex values inside the box.

    Includes bounds of the rounding errors and of the fitted slopes' errors.

    Parameters
    ----------
    aff : AffineTerms
    data : GridData
    Xs : sequence of ndarray

    Returns
    -------
    float
        ``inf`` when the system or the basis is not affine.
    """
    if not (aff.system_affine and aff.basis_affine):
        return float("inf")
    Xs = np.asarray(Xs, dtype=float)
    blocks = curvature_blocks(aff, Xs)
    nY = np.linalg.norm(np.einsum("pk,kij->pij", np.abs(aff.F), np.abs(Xs)), axis=(1, 2))
    s = blocks.shape[1]
    total = 0.0
    for i in range(blocks.shape[0]):
        if aff.width[i] == 0 or nY[i] == 0:
            continue
        lam = float(np.linalg.eigvalsh(blocks[i])[0])
        nA = np.linalg.norm(aff.A[i]) + np.linalg.norm(aff.B[i])
        e = max(0.0, -lam) + 8 * (s + 2) * _U * (2 * nY[i] * nA + np.linalg.norm(blocks[i]))
        e += 2 * nY[i] * aff.slope_error[i]
        total += e * aff.width[i] ** 2 / 4.0
    return float(total)
