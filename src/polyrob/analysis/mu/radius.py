"""How far from a grid point its D-G scalings keep certifying a level: a perturbation bound on ``M(jω)``.

The check between the grid points (:mod:`polyrob.analysis.mu.between`)
covers an interval when the scalings of one end have no crossing inside it,
a Hamiltonian test.  That test needs ``Φ(∞)`` nonsingular, which scalings
found at a low frequency often break (they scale the blocks that do not
matter there down by six or seven decades, and the feedthrough then makes
``Φ(∞)`` singular), so the flat low-frequency end of a loop with many
blocks was split until the check gave up (xarm7 and talos_left_arm with a
payload were GRID_ONLY for this reason, docs/fleet.md).  There ``M(jω)`` hardly moves, and
a bound on how much it moves covers the interval directly.

With ``Z = jω_e I - A``, ``R = Z^-1`` and the scaled ``M~ = D M D^-1``,
for ``δ = ω - ω_e``::

    M~(jω) - M~(jω_e) = -jδ (D C R) (I + jδ R)^-1 (R B D^-1)
    ||M~(jω) - M~(jω_e)|| <= ε(δ) = |δ| ||D C R|| ||R B D^-1|| / (1 - |δ| ||R||)

and ``Φ~(ω) - Φ~(ω_e)`` (``Φ~ = M~* M~ + j(G~ M~ - M~* G~) - β² I``) is at
most ``2 ε (||M~(jω_e)|| + ||G~||) + ε²`` in norm.  So ``Φ~(ω) ≺ 0`` while
that is below the margin ``-λ_max(Φ~(ω_e))``; half the margin is used, the
other half absorbs rounding.  :func:`covering_radius` returns the ``|δ|``
where the bound reaches it.

That bound multiplies two norms that scalings from a low frequency make
large one by one (ur5's per-link PID at bandwidth factor 8: ``||D C R||
||R B D^-1||`` about 6e4 at 1e-3 rad/s, a radius of 5e-6 rad/s, so the
interval below the grid, ``[0, 1e-3]``, took the check's 200 points and
stayed open), while the product itself barely moves.  So the resolvent's
Neumann series is kept to order ``k`` (:data:`TAYLOR_ORDER`) with its exact
coefficients and only the remainder is bounded by norms::

    M~(jω) - M~(jω_e) = sum_{i=1..k} (-jδ)^i X_i + (-jδ)^(k+1) (D C R) R^k (I + jδ R)^-1 (R B D^-1)
    X_i = D C R^(i+1) B D^-1,   ε(δ) = sum_i |δ|^i ||X_i|| + |δ|^(k+1) ||D C R|| ||R||^k ||R B D^-1|| / (1 - |δ| ||R||)

``ε`` grows with ``|δ|``; the radius is where it reaches the margin's
share (and never less than the first-order bound's, ``k = 0``, which is the
formula above).

Why by hand: a textbook resolvent bound, but no library applies it to μ
scalings.

Examples
--------
>>> import numpy as np
>>> A, B, C, D = -np.eye(1), np.ones((1, 1)), np.ones((1, 1)), np.zeros((1, 1))
>>> r = covering_radius(A, B, C, D, np.zeros((1, 1)), 2.0, 0.0)  # |1/(jw + 1)| <= 1 < 2
>>> 0.1 < r < 1.0
True
"""

from __future__ import annotations

import numpy as np

__all__ = ["covering_radius"]

#: Share of the margin ``-λ_max(Φ~(ω_e))`` the perturbation may use (the rest absorbs rounding).
MARGIN_SHARE = 0.5
#: Terms of the resolvent's series kept exactly (the module text); the rest is bounded by norms.
TAYLOR_ORDER = 4


def covering_radius(A, B, C, D, Gt, level: float, w: float, order: int = TAYLOR_ORDER) -> float:
    """``ρ >= 0``: the scaled test ``Φ~ ≺ 0`` at ``level`` holds for every ``ω >= 0`` with ``|ω - w| <= ρ``.

    Parameters
    ----------
    A, B, C, D : ndarray
        The scaled square ``M~(s) = D M(s) D^-1`` (``A`` stable), ``D`` the
        square root of the scalings' ``P``.
    Gt : ndarray
        ``G~ = D^-1 G D^-1`` (Hermitian).
    level : float
        ``β``.
    w : float
        The scalings' frequency (finite, ``>= 0``).
    order : int
        Terms of the resolvent's series kept exactly (0: the first-order bound alone).

    Returns
    -------
    float
        0 when ``Φ~(w)`` itself is not negative definite.
    """
    n = A.shape[0]
    if n == 0:  # a static M does not move with ω
        return np.inf if _largest(D, Gt, level) < 0 else 0.0
    Z = 1j * float(w) * np.eye(n) - A
    RB = np.linalg.solve(Z, B)
    CR = np.linalg.solve(Z.T, C.T).T
    M = CR @ B + D
    lam = _largest(M, Gt, level)
    if not lam < 0:
        return 0.0
    a = np.linalg.norm(M, 2) + np.linalg.norm(Gt, 2)
    margin = -MARGIN_SHARE * lam
    eps = margin / (a + np.sqrt(a * a + margin))  # the root of 2 a e + e^2 = margin, without cancellation
    r_norm = 1.0 / np.linalg.svd(Z, compute_uv=False)[-1]
    c = np.linalg.norm(CR, 2) * np.linalg.norm(RB, 2)
    first_order = float(eps / (c + eps * r_norm))
    return max(first_order, _series_radius(Z, CR, RB, c, r_norm, eps, order)) if order > 0 else first_order


def _series_radius(Z, CR, RB, c: float, r_norm: float, eps: float, order: int = TAYLOR_ORDER) -> float:
    """The ``|δ| < 1 / ||R||`` where the series bound ``ε(δ)`` of the module text reaches ``eps`` (0 if none)."""
    from scipy.optimize import brentq

    x, W = [], RB
    for _ in range(order):  # X_i = (C R) (R^i B): one more solve per term
        W = np.linalg.solve(Z, W)
        x.append(float(np.linalg.norm(CR @ W, 2)))

    def excess(d):
        tail = d ** (order + 1) * c * r_norm**order / (1.0 - d * r_norm)
        return sum(xi * d ** (i + 1) for i, xi in enumerate(x)) + tail - eps

    top = (1.0 - 1e-9) / r_norm
    if not excess(0.0) < 0.0:
        return 0.0
    if excess(top) < 0.0:
        return float(top)
    return float(brentq(excess, 0.0, top, xtol=1e-15, rtol=1e-10)) * (1.0 - 1e-9)


def _largest(M, Gt, level) -> float:
    L = M.conj().T @ M + 1j * (Gt @ M - M.conj().T @ Gt) - level**2 * np.eye(M.shape[0])
    return float(np.linalg.eigvalsh((L + L.conj().T) / 2)[-1])
