"""The bounded-real LMIs of :func:`polyrob.lpvnorm` as a block-diagonal SDP whose Schur complement is built from ``n x n`` products.

A general conic solver sees each LMI as a dense ``s(s+1)/2 x nv`` matrix
(``s = n + m + q`` its side, ``nv = k n(n+1)/2 + 1`` variables): on the
x4 moving-robot search (324-576 LMIs of side 26 on 81-144 points, 1471 variables)
Clarabel's runs peaked at 5.9-10.2 GB and took 19-39 minutes, most of it
the search (docs/certificates.md).  Every LMI has the same shape,

.. math::

   M(\\rho_a, \\nu) = \\sum_j \\mathrm{He}(\\tilde E^T X_j \\tilde A_{j})
   - \\gamma J + M_0, \\qquad \\tilde E = [I\\;0\\;0],\\;
   \\tilde A_j = f_j(\\rho_a) [A_a\\; B_a\\; 0] + \\tfrac{1}{2} (\\nabla f_j \\cdot \\nu) \\tilde E,

so the Schur complement ``H_uv = sum_l tr(A_lu W_l A_lv W_l)`` of an
interior-point step (Nesterov-Todd scaling ``W_l``) is a sum over LMIs of
Kronecker-like products of three ``n(n+1)/2``-square matrices
``S[K1, K2]_{ee'} = tr(E_e K1 E_e' K2)``, ``K`` among ``P = Ã W Ẽ^T``,
``R = Ã W Ã^T``, ``T = Ẽ W Ẽ^T`` (``n x n``).  :class:`BoundedRealFamily`
computes them in chunks of LMIs with numpy, and holds only the ``A, B, C,
D`` of the grid: no coefficient matrix is ever formed.  No maintained
Python SDP solver takes the Schur complement from the caller (SDPT3's
``schur`` hook is MATLAB), hence this module and
:mod:`polyrob.analysis.lpv.sdp.interior`.

The variables ``y``: ``y[0]`` is ``gamma`` (or the margin ``t`` when a
``level`` fixes ``gamma``), then the ``k`` symmetric ``X_j`` in the
orthonormal basis ``E_e`` of symmetric matrices (:func:`symmetric_basis`).

Examples
--------
>>> import numpy as np
>>> from polyrob.analysis.lpv.check import grid_data
>>> data = grid_data([np.array([[-1.0]])], [np.array([[1.0]])], [np.array([[1.0]])], [np.array([[0.0]])])
>>> fam = BoundedRealFamily(data)
>>> fam.n_variables, [c.shape for c in fam.C]
(2, [(1, 3, 3), (1, 1, 1), (1, 1, 1)])
"""

from __future__ import annotations

import numpy as np

__all__ = ["symmetric_basis", "svec", "smat", "symmetric_kron", "BoundedRealFamily"]

#: LMIs whose ``S`` matrices are formed at once (memory: about 3 x CHUNK x (n(n+1)/2)^2 floats).
CHUNK = 24


def symmetric_basis(n: int):
    """Index pairs and weights of the orthonormal basis ``E_e`` of symmetric ``n x n`` matrices.

    ``E_e = sum_alpha c[alpha, e] e_{p[alpha, e]} e_{q[alpha, e]}^T`` for
    ``alpha = 0, 1``: ``(e_i e_j^T + e_j e_i^T)/sqrt(2)`` for ``i < j``, and
    ``e_i e_i^T`` (two halves) on the diagonal.

    Examples
    --------
    >>> p, q, c = symmetric_basis(2)
    >>> p.tolist(), q.tolist()
    ([[0, 0, 1], [0, 1, 1]], [[0, 1, 1], [0, 0, 1]])
    """
    iu, ju = np.triu_indices(n)
    c = np.where(iu == ju, 0.5, np.sqrt(0.5))
    return np.array([iu, ju]), np.array([ju, iu]), np.array([c, c])


def svec(G: np.ndarray, basis) -> np.ndarray:
    """``<E_e, G>`` for every ``e`` (``G`` symmetric, any leading batch axes)."""
    p, q, c = basis
    return c[0] * G[..., p[0], q[0]] + c[1] * G[..., p[1], q[1]]


def smat(v: np.ndarray, basis, n: int) -> np.ndarray:
    """``sum_e v_e E_e`` (``v``: ``(..., n(n+1)/2)``)."""
    p, q, c = basis
    X = np.zeros(v.shape[:-1] + (n, n))
    X[..., p[0], q[0]] += c[0] * v
    X[..., p[1], q[1]] += c[1] * v
    return X


def symmetric_kron(K1: np.ndarray, K2: np.ndarray, basis) -> np.ndarray:
    """``S[K1, K2]_{ee'} = tr(E_e K1 E_e' K2)`` over a batch (``(L, n, n)`` -> ``(L, ne, ne)``).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> K1, K2 = rng.normal(size=(2, 1, 3, 3))
    >>> b = symmetric_basis(3)
    >>> E = smat(np.eye(6), b, 3)                     # the six E_e
    >>> S = symmetric_kron(K1, K2, b)[0]
    >>> bool(np.isclose(S[1, 4], np.trace(E[1] @ K1[0] @ E[4] @ K2[0])))
    True
    """
    p, q, c = basis
    S = 0.0
    for a in range(2):
        for b in range(2):
            w = np.outer(c[a], c[b])
            S = S + w * K1[:, q[a][:, None], p[b][None, :]] * K2[:, q[b][None, :], p[a][:, None]]
    return S


class BoundedRealFamily:
    """The LMIs of :func:`polyrob.analysis.lpv.assemble.conic_data` in dual form ``Z_l = C_l - A_l^*(y) >= 0``.

    Three groups of blocks: the bounded-real LMIs (``-eps I - M >= 0``, one
    per grid point and rate vertex), then ``X(rho_a) - lo I >= 0`` and
    ``hi I - X(rho_a) >= 0`` per grid point (the first point only when ``X``
    is constant).  ``b`` makes the dual objective ``-gamma`` (or ``t``).

    Parameters
    ----------
    data : GridData
    x_bounds : (float, float)
    eps : float
    level : float, optional
        Fix ``gamma`` there; ``y[0]`` is then the margin ``t`` of ``M + t I <= -eps I``.
    """

    def __init__(self, data, *, x_bounds=(1e-6, 1e6), eps: float = 1e-7, level=None):
        A, B, C, D, F, G = data.A, data.B, data.C, data.D, data.F, data.G
        N, n, m = B.shape
        q, k = C.shape[1], F.shape[1]
        s = n + m + q
        self.n, self.m, self.q, self.k, self.s = n, m, q, k, s
        self.basis = symmetric_basis(n)
        self.ne = n * (n + 1) // 2
        self.n_variables = 1 + k * self.ne
        point, w = [], []
        for a in range(N):
            for nu in data.rates()[a]:
                point.append(a)
                w.append(G[a] @ nu)
        self.point = np.array(point, dtype=int)
        self.w = np.array(w, dtype=float).reshape(len(point), k)
        self.F = np.asarray(F, float)
        self.Fl = self.F[self.point]
        self.A, self.B = np.asarray(A, float), np.asarray(B, float)
        L = self.point.size
        J = np.zeros(s)
        J[n:] = 1.0
        self.first = np.diag(J) * -1.0 if level is None else np.eye(s)  # the coefficient of y[0]
        M0 = np.zeros((L, s, s))
        M0[:, n + m :, :n], M0[:, n + m :, n : n + m] = C[self.point], D[self.point]
        M0 = M0 + np.transpose(M0, (0, 2, 1))
        if level is not None:
            M0 = M0 - float(level) * np.diag(J)
        C_lmi = -eps * np.eye(s) - M0
        constant = k == 1 and not np.any(G)
        self.x_points = np.arange(1 if constant else N)
        nb = self.x_points.size
        lo, hi = x_bounds
        self.C = [C_lmi, np.broadcast_to(-lo * np.eye(n), (nb, n, n)).copy(),
                  np.broadcast_to(hi * np.eye(n), (nb, n, n)).copy()]  # fmt: skip
        self.b = np.zeros(self.n_variables)
        self.b[0] = -1.0 if level is None else 1.0
        self.sizes = [s, n, n]

    # -- the operators -------------------------------------------------------------------------------
    def matrices(self, y: np.ndarray) -> np.ndarray:
        """The ``(k, n, n)`` matrices ``X_j`` of ``y``."""
        return smat(np.asarray(y[1:], float).reshape(self.k, self.ne), self.basis, self.n)

    def adjoint(self, y: np.ndarray) -> list:
        """``A^*(y)`` per group: ``(L, s, s)``, ``(nb, n, n)``, ``(nb, n, n)``."""
        n, m = self.n, self.m
        Xs = self.matrices(y)
        Y = np.einsum("lj,jab->lab", self.Fl, Xs)
        Wd = np.einsum("lj,jab->lab", self.w, Xs)
        out = np.zeros((self.point.size, self.s, self.s))
        YA = Y @ self.A[self.point]
        out[:, :n, :n] = YA + np.transpose(YA, (0, 2, 1)) + Wd
        YB = Y @ self.B[self.point]
        out[:, :n, n : n + m] = YB
        out[:, n : n + m, :n] = np.transpose(YB, (0, 2, 1))
        out += y[0] * self.first
        Xa = np.einsum("aj,jbc->abc", self.F[self.x_points], Xs)
        return [out, -Xa, Xa]

    def forward(self, S: list) -> np.ndarray:
        """``A(S) = (sum_l <A_lu, S_l>)_u`` for symmetric blocks ``S`` (the adjoint of :meth:`adjoint`)."""
        n, m = self.n, self.m
        S_lmi, S_lo, S_hi = S
        v = np.zeros(self.n_variables)
        v[0] = np.einsum("lab,ab->", S_lmi, self.first)
        P = self.A[self.point] @ S_lmi[:, :n, :n] + self.B[self.point] @ S_lmi[:, n : n + m, :n]  # Ã S Ẽ^T
        sv_p = svec(P + np.transpose(P, (0, 2, 1)), self.basis)
        sv_t = svec(S_lmi[:, :n, :n], self.basis)
        G = self.Fl.T @ sv_p + self.w.T @ sv_t
        G += self.F[self.x_points].T @ svec(S_hi - S_lo, self.basis)
        v[1:] = G.ravel()
        return v

    def schur(self, W: list) -> np.ndarray:
        """``H_uv = sum_l tr(A_lu W_l A_lv W_l)`` (the Nesterov-Todd Schur complement), dense ``(nv, nv)``."""
        n, m, k, ne = self.n, self.m, self.k, self.ne
        W_lmi, W_lo, W_hi = W
        H = np.zeros((self.n_variables, self.n_variables))
        HX = np.zeros((k, k, ne, ne))
        for start in range(0, self.point.size, CHUNK):
            sl = slice(start, start + CHUNK)
            Wc, pts = W_lmi[sl], self.point[sl]
            T = Wc[:, :n, :n]
            AB = np.concatenate([self.A[pts], self.B[pts]], axis=2)
            P = AB @ Wc[:, : n + m, :n]
            R = AB @ Wc[:, : n + m, : n + m] @ np.transpose(AB, (0, 2, 1))
            S1 = 2.0 * (symmetric_kron(P, P, self.basis) + symmetric_kron(R, T, self.basis))
            S2 = 2.0 * symmetric_kron(P, T, self.basis)
            S4 = symmetric_kron(T, T, self.basis)
            Fc, wc = self.Fl[sl], self.w[sl]
            HX += np.einsum("lj,lk,lef->jkef", Fc, Fc, S1, optimize=True)
            HX += np.einsum("lj,lk,lef->jkef", Fc, wc, S2, optimize=True)
            HX += np.einsum("lj,lk,lfe->jkef", wc, Fc, S2, optimize=True)
            HX += np.einsum("lj,lk,lef->jkef", wc, wc, S4, optimize=True)
        Fx = self.F[self.x_points]
        for Wb in (W_lo, W_hi):
            for start in range(0, Fx.shape[0], CHUNK):
                sl = slice(start, start + CHUNK)
                HX += np.einsum("lj,lk,lef->jkef", Fx[sl], Fx[sl], symmetric_kron(Wb[sl], Wb[sl], self.basis),
                                optimize=True)  # fmt: skip
        H[1:, 1:] = np.transpose(HX, (0, 2, 1, 3)).reshape(k * ne, k * ne)
        WJW = W_lmi @ self.first @ W_lmi
        col = self.forward([WJW, np.zeros_like(W_lo), np.zeros_like(W_hi)])
        H[0, :] = col
        H[:, 0] = col
        H[0, 0] = np.einsum("lab,ba->", WJW, self.first)
        return H
