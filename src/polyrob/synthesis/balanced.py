"""Balanced realisations of the scaling filters.

Canonical forms of the D and G filters of μ-synthesis reach entries ~1e10;
:func:`balanced_realization` returns the balanced form (equal, diagonal
Gramians), whose entries stay moderate.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

__all__ = ["balanced_realization"]


def balanced_realization(A, B, C, D):
    """Balanced realisation of a stable system (square-root method).

    Both Gramians become the same diagonal matrix of Hankel singular values,
    so every state carries comparable energy: entries stay of the order of the
    system's gains, where companion forms of a D-scale reach ~1e10.

    Examples
    --------
    >>> import numpy as np
    >>> from polyrob.synthesis.scalings.dscale import balanced_realization
    >>> A, B, C, D = balanced_realization(np.array([[-1.0, 0], [0, -100.0]]), np.array([[1.0], [1e3]]),
    ...                                   np.array([[1.0, 1e-3]]), np.array([[1.0]]))
    >>> bool(np.abs(B).max() < 10)
    True
    """
    A, B, C, D = (np.atleast_2d(np.asarray(X, float)) for X in (A, B, C, D))
    n = A.shape[0] if A.size else 0
    if n == 0:
        return A.reshape(0, 0), B.reshape(0, D.shape[1]), C.reshape(D.shape[0], 0), D
    try:
        Wc = sla.solve_continuous_lyapunov(A, -B @ B.T)
        Wo = sla.solve_continuous_lyapunov(A.T, -C.T @ C)
        Wc, Wo = (Wc + Wc.T) / 2, (Wo + Wo.T) / 2
        Lc = _psd_factor(Wc)
        Lo = _psd_factor(Wo)
        U, s, Vt = np.linalg.svd(Lo.T @ Lc)
        if s[-1] <= 1e-14 * s[0]:
            return A, B, C, D  # non-minimal: keep the given (already sane) realisation
        S = np.diag(s**-0.5)
        T = S @ U.T @ Lo.T  # x_b = T x
        Ti = Lc @ Vt.T @ S
        return T @ A @ Ti, T @ B, C @ Ti, D
    except (np.linalg.LinAlgError, ValueError):
        return A, B, C, D


def _psd_factor(W):
    """``L`` with ``L L^T = W`` for a (numerically) positive semidefinite ``W``."""
    try:
        return np.linalg.cholesky(W)
    except np.linalg.LinAlgError:
        ev, V = np.linalg.eigh(W)
        return V * np.sqrt(np.maximum(ev, 0.0))[None, :]
