"""D and G scaling data of a D-step, and the fitted scalings as a whole.

:func:`scaling_data` extracts one scalar ``d_i(ω)`` (and ``g_i(ω)`` for real
scalars) per block from the padded ``D``, ``G`` of the μ upper bound,
normalised so that the last (performance) block has ``d = 1``;
:class:`Scalings` holds the fitted filters of every block and evaluates the
transformed loop ``T = D (N/β + F)(I + F N/β)^{-1} D^{-1}`` of the K-step
(see :mod:`polyrob.synthesis.scalings.dscale` for the method).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from polyrob.analysis.mu.blocks import BlockStructure, as_block_structure
from polyrob.synthesis.scalings.gfit import GFit
from polyrob.synthesis.scalings.magfit import MagnitudeFit

__all__ = ["ScalingData", "scaling_data", "BlockScaling", "Scalings", "complexified"]


def complexified(st: BlockStructure) -> BlockStructure:
    """Every real block as a complex (repeated) scalar of the same size."""
    rows = [[b.rows, 0] if b.kind == "real" else list(b.matlab) for b in st.blocks]
    return BlockStructure.from_matlab(rows)


# ============================================================ scaling data
@dataclass(frozen=True, eq=False)
class ScalingData:
    """Per-block scaling data over frequency, normalised (last block ``d = 1``).

    Attributes
    ----------
    omega : ndarray
        Frequencies in rad/s, ascending.
    mu : ndarray
        Upper bound at each frequency (the level the data certify).
    d : ndarray
        ``(n_freq, n_blocks)`` positive scalars (``D = d I`` on each block).
    g : ndarray
        ``(n_freq, n_blocks)`` real G scalars (zero on complex blocks),
        normalised like ``d**2``.
    structure : BlockStructure
    complex_mu, complex_d : ndarray, optional
        The complex-μ bound (real blocks as complex) and its normalised
        ``d`` at the same frequencies, when the D-step computed them: the
        D-only route of D-G-K then needs no further sweep.
    """

    omega: np.ndarray
    mu: np.ndarray
    d: np.ndarray
    g: np.ndarray
    structure: BlockStructure
    complex_mu: np.ndarray | None = None
    complex_d: np.ndarray | None = None


def scaling_data(omega, mu, D, G, blk, *, M=None, beta=None) -> ScalingData:
    """Extract normalised per-block ``d`` (and ``g``) from padded ``D``, ``G`` stacks.

    With ``M`` (the frequency response, ``(n, rows, cols)``) and ``beta``, the
    G scaling is shrunk to the smallest multiple ``t G`` (``0 <= t <= 1``)
    that still certifies ``μ <= beta`` at each frequency: where the D scaling
    alone suffices, ``G = 0``.  The LMI is linear in ``(D^2, G)``, so the
    shrunk pair stays valid; smaller, smoother G data are easier to realise.
    """
    st = as_block_structure(blk)
    omega = np.asarray(omega, float)
    nb = len(st.blocks)
    sls = st.padded_slices
    P = np.einsum("kij,kjl->kil", D, np.conj(np.swapaxes(D, 1, 2)))  # D^2 (Hermitian)
    d = np.zeros((omega.size, nb))
    g = np.zeros((omega.size, nb))
    for k in range(omega.size):
        Gk = np.array(G[k], dtype=complex)
        if M is not None and beta is not None and st.has_real and np.any(Gk):
            Ms = st.pad(M[k])
            Gk = Gk * _shrink_g(Ms, P[k], Gk, beta)
        for i, (b, sl) in enumerate(zip(st.blocks, sls)):
            Pb = P[k][sl, sl]
            d[k, i] = np.sqrt(max(np.real(np.trace(Pb)) / b.size, 1e-300))
            if b.kind == "real":
                g[k, i] = float(np.real(np.trace(Gk[sl, sl])) / b.size)
    # normalise: last block d = 1 (D and G scale together: the LMI is homogeneous in (D^2, G))
    ref = d[:, -1].copy()
    ref[ref <= 0] = 1.0
    d = d / ref[:, None]
    g = g / (ref**2)[:, None]
    return ScalingData(omega, np.asarray(mu, float), d, g, st)


def _shrink_g(Ms, P, G, beta) -> float:
    """Smallest ``t in [0, 1]`` with ``λmax(M^H P M + j t (G M - M^H G), P) <= beta^2``."""
    P = (P + P.conj().T) / 2
    ev = np.linalg.eigvalsh(P)
    if ev[0] <= 0:
        return 1.0
    A0 = Ms.conj().T @ P @ Ms
    A1 = 1j * (G @ Ms - Ms.conj().T @ G)

    def lev(t):
        A = A0 + t * A1
        A = (A + A.conj().T) / 2
        try:
            return sla.eigh(A, P, eigvals_only=True)[-1]
        except np.linalg.LinAlgError:
            return np.inf

    target = beta**2
    if lev(0.0) <= target:
        return 0.0
    if lev(1.0) > target * (1 + 1e-9):
        return 1.0
    lo, hi = 0.0, 1.0  # convex in t: bisection on the sublevel set's left end
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        if lev(mid) <= target:
            hi = mid
        else:
            lo = mid
    return hi


# ======================================================== fitted scalings
@dataclass(frozen=True, eq=False)
class BlockScaling:
    """Fitted scaling of one block: ``d`` (``None``: the constant one) and ``F`` (real blocks)."""

    d: MagnitudeFit | None
    F: GFit | None = None

    @property
    def d_order(self) -> int:
        return 0 if self.d is None else self.d.order

    @property
    def g_order(self) -> int:
        return 0 if self.F is None else self.F.order

    def d_at(self, s):
        return np.ones(np.shape(s), complex) if self.d is None else self.d(s)

    def F_at(self, s):
        return np.zeros(np.shape(s), complex) if self.F is None else self.F(s)


@dataclass(frozen=True, eq=False)
class Scalings:
    """Fitted D (and G) scalings of all blocks, and the level β they were computed at.

    Attributes
    ----------
    blocks : tuple of BlockScaling
    beta : float
        Level of the D-G-K transformation (``N/β``); irrelevant without G.
    structure : BlockStructure
    """

    blocks: tuple
    beta: float
    structure: BlockStructure

    @property
    def orders(self) -> list[tuple[int, int]]:
        """``(d order, G order)`` per block."""
        return [(b.d_order, b.g_order) for b in self.blocks]

    @property
    def has_g(self) -> bool:
        return any(b.F is not None and b.F.order > 0 for b in self.blocks)

    def transformed(self, Nw: np.ndarray, omega: np.ndarray) -> np.ndarray:
        """``T(jω) = D (N/β + F)(I + F N/β)^{-1} D^{-1}`` at each frequency (``F = 0``: ``D N D^{-1}/β``)."""
        st = self.structure
        s = 1j * np.asarray(omega, float)
        rows, cols = st.col_slices, st.row_slices  # M rows = block cols, M cols = block rows
        out = np.empty_like(Nw, dtype=complex)
        nr, nc = Nw.shape[1:]
        for k in range(s.size):
            dl = np.zeros(nr, complex)
            dr = np.zeros(nc, complex)
            Fr = np.zeros((nr, nc), complex)
            for b, sc, rsl, csl in zip(st.blocks, self.blocks, rows, cols):
                dv = sc.d_at(s[k])
                dl[rsl] = dv
                dr[csl] = dv
                if b.kind == "real" and sc.F is not None:
                    Fr[rsl, csl] = sc.F_at(s[k]) * np.eye(b.rows)
            Nt = Nw[k] / self.beta
            if np.any(Fr):
                Fc = Fr.T
                X = (Nt + Fr) @ np.linalg.inv(np.eye(nc) + Fc @ Nt)
            else:
                X = Nt
            out[k] = dl[:, None] * X / dr[None, :]
        return out
