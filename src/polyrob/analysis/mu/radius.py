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


def covering_radius(A, B, C, D, Gt, level: float, w: float) -> float:
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
    return float(eps / (c + eps * r_norm))


def _largest(M, Gt, level) -> float:
    L = M.conj().T @ M + 1j * (Gt @ M - M.conj().T @ Gt) - level**2 * np.eye(M.shape[0])
    return float(np.linalg.eigvalsh((L + L.conj().T) / 2)[-1])
