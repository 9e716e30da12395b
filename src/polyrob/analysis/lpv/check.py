"""The a-posteriori check of an LPV norm certificate: float64 eigenvalues with a rounding margin.

The solver's optimum is not a certificate.  A candidate ``X(rho) = sum_j
f_j(rho) X_j`` and a level ``gamma`` are *verified* here, in numpy, at every
grid point ``rho_a`` and every vertex ``nu`` of the rate box:

* ``X(rho_a) > 0``: smallest eigenvalue above a bound of the rounding errors;
* the bounded-real matrix (Wu, Yang, Packard & Becker 1996)

  .. math::

     M(\\rho_a, \\nu) = \\begin{bmatrix} A^T X + X A + \\sum_i \\nu_i \\partial X/\\partial\\rho_i
     & X B & C^T \\\\ B^T X & -\\gamma I & D^T \\\\ C & D & -\\gamma I \\end{bmatrix} < 0

  largest eigenvalue below minus a bound of the rounding errors made in
  forming ``M`` and in computing its eigenvalues.

:func:`proved_gamma` finds the smallest level (to a relative ``1e-7``) at
which a fixed ``X`` passes: the number a result may report as a bound.

Examples
--------
>>> import numpy as np
>>> data = grid_data([np.array([[-1.0]])], [np.array([[1.0]])], [np.array([[1.0]])], [np.array([[0.0]])])
>>> check_solution(data, [np.array([[1.0]])], 1.1).holds     # 1/(s+1): gamma = 1, X = 1 proves 1.1
True
>>> check_solution(data, [np.array([[-1.0]])], 1.1).holds    # X < 0 proves nothing
False
>>> g, _ = proved_gamma(data, [np.array([[1.0]])], 0.5)
>>> round(g, 5)
1.0
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

__all__ = ["GridData", "LpvCheck", "grid_data", "rate_vertices", "check_solution", "proved_gamma"]

_U = np.finfo(float).eps


@dataclass(frozen=True, eq=False)
class GridData:
    """The gridded LPV data the LMIs are written on (arrays over the ``N`` grid points).

    Attributes
    ----------
    A, B, C, D : ndarray
        ``(N, n, n)``, ``(N, n, m)``, ``(N, q, n)``, ``(N, q, m)``.
    F : ndarray
        ``(N, k)``: the basis functions' values at the grid points.
    G : ndarray
        ``(N, k, p)``: their gradients.
    nus : ndarray
        ``(V, p)``: the vertices of the rate box (``[[0, ..., 0]]`` for a constant ``X``),
        or ``(N, V, p)``: a rate box per grid point (:meth:`rates`).
    points : ndarray
        ``(N, p)``: the grid points.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    F: np.ndarray
    G: np.ndarray
    nus: np.ndarray
    points: np.ndarray

    def rates(self) -> np.ndarray:
        """The rate vertices at every grid point, ``(N, V, p)``."""
        nus = np.asarray(self.nus, dtype=float)
        return nus if nus.ndim == 3 else np.broadcast_to(nus, (self.A.shape[0],) + nus.shape)


def grid_data(A, B, C, D, F=None, G=None, nus=None, points=None) -> GridData:
    """Stack per-point matrices into a :class:`GridData` (constant ``X`` when ``F`` is omitted).

    Parameters
    ----------
    A, B, C, D : sequence of ndarray
        The state-space matrices at each grid point.
    F, G : array_like, optional
        Basis values ``(N, k)`` and gradients ``(N, k, p)``; default: one constant function.
    nus : array_like, optional
        Rate-box vertices ``(V, p)``; default: no variation term.
    points : array_like, optional
        The grid points ``(N, p)`` (for reports only).

    Returns
    -------
    GridData
    """
    A, B, C, D = (np.asarray(x, dtype=float) for x in (A, B, C, D))
    N = A.shape[0]
    F = np.ones((N, 1)) if F is None else np.asarray(F, dtype=float)
    G = np.zeros((N, F.shape[1], 1)) if G is None else np.asarray(G, dtype=float)
    nus = np.zeros((1, G.shape[2])) if nus is None else np.asarray(nus, dtype=float)
    points = np.zeros((N, G.shape[2])) if points is None else np.asarray(points, dtype=float)
    return GridData(A, B, C, D, F, G, nus, points)


def rate_vertices(rate_bounds) -> np.ndarray:
    """Vertices of the rate box ``prod_i [lo_i, hi_i]`` (an infinite side counts as 0: see the caller).

    Parameters
    ----------
    rate_bounds : sequence of (lo, hi)

    Returns
    -------
    ndarray
        ``(V, p)``, duplicates removed (``lo == hi`` gives one value).

    Examples
    --------
    >>> rate_vertices([(-1.0, 1.0), (0.0, 0.0)]).tolist()
    [[-1.0, 0.0], [1.0, 0.0]]
    """
    sides = [sorted({float(lo), float(hi)}) if np.isfinite(lo) and np.isfinite(hi) else [0.0] for lo, hi in rate_bounds]
    return np.array(list(itertools.product(*sides)), dtype=float).reshape(-1, len(sides))


@dataclass(frozen=True)
class LpvCheck:
    """The verdict of :func:`check_solution` on one ``(X, gamma)``.

    Attributes
    ----------
    holds : bool
        Every LMI verified strictly, with the rounding margin.
    lmi_margin : float
        ``min -(lambda_max(M) + rounding)`` over all points and rate vertices (``> 0`` when it holds).
    positivity_margin : float
        ``min lambda_min(X(rho_a)) - rounding`` over the grid (``> 0`` when it holds).
    worst_point : tuple of float
        The grid point of the smallest LMI margin.
    worst_rate : tuple of float
        Its rate vertex.
    reason : str
        Why it does not hold (empty when it does).
    """

    holds: bool
    lmi_margin: float
    positivity_margin: float
    worst_point: tuple = ()
    worst_rate: tuple = ()
    reason: str = ""


def _x_values(data: GridData, Xs: np.ndarray):
    """``X(rho_a)`` ``(N, n, n)``, ``dX/drho_i(rho_a)`` ``(N, p, n, n)`` and the scale ``sum_j |f_j| ||X_j||_F``."""
    X = np.einsum("ak,kij->aij", data.F, Xs)
    dX = np.einsum("akp,kij->apij", data.G, Xs)
    nrm = np.linalg.norm(Xs, axis=(1, 2))
    scale = np.abs(data.F) @ nrm
    dscale = np.einsum("akp,k->ap", np.abs(data.G), nrm)
    return X, dX, scale, dscale


def brl_matrices(data: GridData, Xs, gamma: float):
    """The bounded-real matrices ``(N, V, s, s)`` and a bound of their rounding errors ``(N, V)``."""
    Xs = np.asarray(Xs, dtype=float)
    A, B, C, D = data.A, data.B, data.C, data.D
    N, n, m = B.shape
    q = C.shape[1]
    k = Xs.shape[0]
    X, dX, scale, dscale = _x_values(data, Xs)
    nus = data.rates()
    V = nus.shape[1]
    s = n + m + q
    M = np.zeros((N, V, s, s))
    XA = X @ A
    XB = X @ B
    var = np.einsum("avp,apij->avij", nus, dX)
    M[:, :, :n, :n] = (XA + np.transpose(XA, (0, 2, 1)))[:, None] + var
    M[:, :, :n, n : n + m] = XB[:, None]
    M[:, :, n : n + m, :n] = np.transpose(XB, (0, 2, 1))[:, None]
    M[:, :, n + m :, :n] = C[:, None]
    M[:, :, :n, n + m :] = np.transpose(C, (0, 2, 1))[:, None]
    M[:, :, n + m :, n : n + m] = D[:, None]
    M[:, :, n : n + m, n + m :] = np.transpose(D, (0, 2, 1))[:, None]
    d = np.arange(n, s)
    M[:, :, d, d] -= gamma
    nA = np.linalg.norm(A, axis=(1, 2))
    nB = np.linalg.norm(B, axis=(1, 2))
    prods = scale * (2 * nA + 2 * nB)  # |X| |A| and |X| |B| terms (Frobenius bounds |.| products)
    rates = np.einsum("ap,avp->av", dscale, np.abs(nus))  # (N, V)
    err = 8.0 * (s + k + 2) * _U * (prods[:, None] + rates + np.linalg.norm(M, axis=(2, 3)))
    return M, err, X, scale


def check_solution(data: GridData, Xs, gamma: float, slack: float = 0.0) -> LpvCheck:
    """Verify ``X(rho) = sum_j f_j(rho) X_j`` and ``gamma`` at every grid point and rate vertex.

    Parameters
    ----------
    data : GridData
    Xs : sequence of ndarray
        The ``k`` coefficient matrices ``X_j`` (symmetrised here).
    gamma : float
        The level to verify.
    slack : float
        Extra margin the LMIs must clear (the curvature allowance of the
        check between grid points, :mod:`polyrob.analysis.lpv.between`).

    Returns
    -------
    LpvCheck
    """
    Xs = np.asarray(Xs, dtype=float)
    Xs = 0.5 * (Xs + np.transpose(Xs, (0, 2, 1)))
    if not (np.all(np.isfinite(Xs)) and np.isfinite(gamma)):
        return LpvCheck(False, -np.inf, -np.inf, reason="X or gamma not finite")
    M, err, X, scale = brl_matrices(data, Xs, gamma)
    n = X.shape[1]
    pos = np.linalg.eigvalsh(X)[:, 0] - 8.0 * (n + Xs.shape[0] + 2) * _U * scale
    lam = np.linalg.eigvalsh(M)[..., -1] + err  # (N, V)
    a, v = np.unravel_index(int(np.argmax(lam)), lam.shape)
    margin, pmin = float(-lam[a, v]), float(pos.min())
    worst = (tuple(float(x) for x in data.points[a]), tuple(float(x) for x in data.rates()[a, v]))
    if pmin <= 0:
        at = tuple(float(x) for x in data.points[int(np.argmin(pos))])
        return LpvCheck(False, margin, pmin, *worst, reason=f"X(rho) not proved positive definite at rho = {at}")
    if margin <= slack:
        return LpvCheck(
            False, margin, pmin, *worst, reason=f"LMI not proved negative at rho = {worst[0]}, rate {worst[1]}"
        )
    return LpvCheck(True, margin, pmin, *worst)


def proved_gamma(data: GridData, Xs, g0: float, *, slack: float = 0.0, rtol: float = 1e-7, max_growth: float = 1e6):
    """Smallest level (to ``rtol``) at which the fixed ``X_j`` pass :func:`check_solution`.

    Starts at the solver's level ``g0`` and grows it until the check passes
    (``gamma`` enters only the ``-gamma I`` blocks, so passing is monotone in
    it); then bisects.  ``inf`` when no level up to ``g0 * max_growth``
    passes, e.g. because ``X`` is not positive definite or the
    ``A^T X + X A + dX`` block is not negative.

    Parameters
    ----------
    data : GridData
    Xs : sequence of ndarray
    g0 : float
        The solver's level (a starting guess).
    slack : float
        Passed to :func:`check_solution`.
    rtol : float
        Relative width of the final bisection interval.
    max_growth : float
        Give up beyond ``g0 * max_growth``.

    Returns
    -------
    gamma : float
        The proved level, ``inf`` when none.
    check : LpvCheck
        The check at that level (or the last failed one).
    """
    g0 = float(g0) if np.isfinite(g0) and g0 > 0 else 1.0
    hi = g0 * (1 + 10 * rtol)
    chk = check_solution(data, Xs, hi, slack)
    if not chk.holds and chk.positivity_margin <= 0:
        return np.inf, chk
    lo, step = 0.0, 1e-6
    while not chk.holds:
        lo, hi = hi, hi * (1 + step)
        step = min(8 * step, 1.0)
        if hi > g0 * max_growth:
            return np.inf, chk
        chk = check_solution(data, Xs, hi, slack)
    best = chk
    while hi - lo > rtol * hi:
        mid = 0.5 * (lo + hi)
        c = check_solution(data, Xs, mid, slack)
        if c.holds:
            hi, best = mid, c
        else:
            lo = mid
    return float(hi), best
