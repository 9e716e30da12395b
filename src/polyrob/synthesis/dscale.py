"""D and G scalings for D-K / D-G-K iteration: frequency data, rational fits, scaled plants.

The D-step of μ-synthesis gives, at each frequency of a grid, the scalings
of the μ upper bound of the closed loop ``N = Fl(P, K)`` (see
:mod:`polyrob.analysis.mu`): ``D(ω) > 0`` commuting with ``Δ`` and, for real blocks,
``G(ω) = G(ω)^H`` with

.. math:: N^H D^2 N + j(G N - N^H G) - \\beta^2 D^2 \\preceq 0 .

The K-step needs them as stable rational filters.  This module

* extracts one scalar ``d_i(ω)`` (and ``g_i(ω)`` for real scalars) per block,
  normalised so that the last block (the performance block) has ``d = 1``
  (:func:`scaling_data`);
* fits ``d_i`` with a stable, minimum-phase, biproper filter of bounded
  order by a weighted least-squares fit of the **log-magnitude** over a
  second-order-section parametrisation (:func:`fit_magnitude`), realised in a
  **balanced** form (canonical forms of these filters reach entries ~1e10);
* for real scalars, fits a stable filter ``F_i`` that realises the G scaling
  (:func:`fit_g`) and builds the transformed plant of the D-G-K K-step
  (:func:`scaled_plant`).

How the G scaling enters the K-step (the method, and why)
---------------------------------------------------------
For a real scalar block with scalings ``p = d^2`` and ``g`` at level ``β``,
the 2x2 multiplier ``Π = [[p, -j g/β], [j g/β, -p]]`` on ``(y_i, x_i)`` (the
block's output/input of ``N/β``) certifies ``μ ≤ β``.  Young's D-G-K
(P. M. Young, "Controller design with real parametric uncertainty", Int. J.
Control 65(3), 1996) writes the test as
``σ̄((D N D^{-1}/β - jG̃)(I + G̃^2)^{-1/2}) ≤ 1``; its term ``jG̃(ω)`` is purely
imaginary at every frequency, and no stable real-rational filter has a
purely imaginary frequency response, so it cannot be fitted as it stands.
We use instead the J-spectral factorisation ``Π = Ψ^* diag(1, -1) Ψ`` with
the real-rational factor

.. math:: Ψ = d \\begin{pmatrix} 1 & F \\\\ F & 1 \\end{pmatrix},\\qquad
          p = |d|^2 (1 - |F|^2),\\quad g/β = -2 |d|^2 \\operatorname{Im} F,

where ``F`` is any stable filter with ``‖F‖∞ < 1``: the freedom in
``Re F`` is what makes ``F`` realisable.  The certificate then reads
``‖T‖ ≤ 1`` for the Möbius-transformed loop

.. math:: T = D\\,(N/β + F)(I + F N/β)^{-1} D^{-1},

a linear-fractional function of ``N`` and hence of ``K``: the K-step is a
standard H∞ problem for a new generalized plant (:func:`scaled_plant`).
This is the multiplier factorisation used for IQC synthesis (J. Veenman,
C. W. Scherer, "IQC-synthesis with general dynamic multipliers", Int. J.
Robust Nonlinear Control 24(17), 2014), specialised to Young's D-G
scalings.  With ``F = 0`` it is the classical D-K step ``D N D^{-1}``.

Examples
--------
>>> import numpy as np
>>> from polyrob.synthesis.dscale import fit_magnitude
>>> w = np.logspace(-2, 2, 50)
>>> mag = np.abs((1j * w + 1) / (1j * w + 10))          # a first-order scaling
>>> fit = fit_magnitude(w, mag, order=1)
>>> fit.order, bool(fit.error < 1e-6)
(1, True)
>>> sorted(np.round(-fit.poles.real, 4).tolist()), sorted(np.round(-fit.zeros.real, 4).tolist())
([10.0], [1.0])
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Sequence

import control
import numpy as np
import scipy.linalg as sla

from polyrob.analysis.blocks import BlockStructure, as_block_structure
from polyrob.errors import PolyrobError
from polyrob.synthesis.gfit import GFit, fit_g
from polyrob.synthesis.magfit import MagnitudeFit, _fit_errors, balanced_realization, fit_magnitude

__all__ = [
    "MagnitudeFit",
    "GFit",
    "BlockScaling",
    "Scalings",
    "ScalingData",
    "scaling_data",
    "fit_magnitude",
    "fit_g",
    "LogMagnitudeFit",
    "SlicotMagnitudeFit",
    "scaled_plant",
    "balanced_realization",
    "MuSweep",
]


# ============================================================ scaling data
@dataclass(frozen=True, eq=False)
class ScalingData:
    """Per-block scaling data over frequency, normalised (last block ``d = 1``).

    Attributes
    ----------
    omega : ndarray
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
    complex_mu: Optional[np.ndarray] = None
    complex_d: Optional[np.ndarray] = None


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

    d: Optional[MagnitudeFit]
    F: Optional[GFit] = None

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


# ============================================================ fit strategies
class LogMagnitudeFit:
    """D-scale fit strategy: per-block log-magnitude least squares, automatic order.

    For each block the lowest order in ``orders`` whose weighted RMS error of
    ``log10 d`` is below ``block_tol`` (or that no longer improves by 10%) is
    taken; then the fitted scalings are checked as a whole: with the old
    closed loop, ``max_ω σ̄(T_fit)`` must stay within ``1 + tol`` of what the
    data certify.  If not, ``block_tol`` is halved and the fit repeated (at
    most three times), so higher orders are only used where they matter.

    Parameters
    ----------
    orders : sequence of int
        Candidate D orders (default ``0..4``).
    g_orders : sequence of int
        Candidate G (``F``) orders for real blocks in D-G-K (default ``0..2``).
    tol : float
        Relative tolerance on the fitted bound.
    block_tol : float
        Initial per-block RMS tolerance on ``log10 d`` (decades).
    peak_power : float
        Frequencies are weighted by ``(μ(ω)/μ_peak)^peak_power``: the fit
        matters where μ is close to its peak.
    """

    def __init__(self, orders: Sequence[int] = (0, 1, 2, 3, 4), g_orders: Sequence[int] = (0, 1, 2),
                 tol: float = 0.02, block_tol: float = 0.05, peak_power: float = 4.0):
        self.orders = tuple(int(o) for o in orders)
        self.g_orders = tuple(int(o) for o in g_orders)
        self.tol, self.block_tol, self.peak_power = float(tol), float(block_tol), float(peak_power)
        if not self.orders or min(self.orders) < 0:
            raise PolyrobError(f"D-scale orders must be non-negative integers, got {orders!r}")

    # -- one block, magnitude
    def _fit_d(self, omega, dv, wt, tol):
        best, prev = None, None
        for o in sorted(self.orders):
            f = fit_magnitude(omega, dv, o, wt, init=prev)
            if best is None or f.error < best.error * 0.999:
                best = f
            prev = f
            if f.error <= tol:
                return f
        return best

    def __call__(self, data: ScalingData, Nw: np.ndarray, beta: float, use_g: bool) -> Scalings:
        """Fitted scalings for the K-step (D-K: ``use_g=False``; D-G-K: ``True``).

        D-G-K route: the G data of each real block are realised first by a
        filter ``F_i`` (:func:`fit_g`); the D scalings are then re-optimised
        *for the realised* ``F`` (a complex-μ D-step on the transformed loop
        ``X = (N/β + F)(I + F N/β)^{-1}``, where every block is complex) and
        fitted.  The D data and the realised ``F`` are thus consistent even
        where ``F`` only approximates the G data.  If that route fits worse
        than ``1 + 5 tol``, the D-only route (``F = 0``: complex D scalings of
        ``N/β``, a D-K step) is fitted too and the better one returned.
        """
        st = data.structure
        omega = data.omega
        mu = np.maximum(data.mu, 1e-300)
        peak = float(np.max(mu))
        self.last_info = {}
        if not (use_g and st.has_real):
            sc, level = self._fit_route(omega, data.d, mu / beta, {}, beta, Nw, st)
            self.last_info = {"route": "D", "level": level * beta}
            return sc
        wt = np.maximum((mu / peak) ** self.peak_power, 1e-3)
        Fs = {}
        if max(self.g_orders) > 0:
            for i, b in enumerate(st.blocks[:-1]):
                if b.kind == "real" and np.any(data.g[:, i]):
                    h = data.g[:, i] / (beta * np.maximum(data.d[:, i] ** 2, 1e-300))
                    F = self._fit_F(omega, h, wt)
                    if F is not None:
                        Fs[i] = F
        best = None
        near = mu >= 0.3 * peak  # frequencies that matter for the fit
        for F_route in ([Fs, {}] if Fs else [{}]):
            if F_route:
                sc0 = Scalings(tuple(BlockScaling(None, F_route.get(i)) for i in range(len(st.blocks))),
                               float(beta), st)
                X = sc0.transformed(Nw, omega)
                c, dmat = _complex_dscales(X, st, near, data.d)
            elif data.complex_d is not None:
                c, dmat = data.complex_mu / beta, data.complex_d
            else:
                c, dmat = _complex_dscales(Nw / beta, st)
            sc, level = self._fit_route(omega, dmat, c, F_route, beta, Nw, st)
            if best is None or level < best[1]:
                best = (sc, level, "DG" if F_route else "D", float(c.max()))
            if F_route and level <= 1 + 5 * self.tol:
                break  # G route fits well: the D-only route cannot start lower
        self.last_info = {"route": best[2], "level": best[1], "pointwise": best[3]}
        return best[0]

    def d_route(self, data: ScalingData, Nw: np.ndarray, beta: float) -> Scalings:
        """D-only scalings of mixed data: complex D-step of ``N/β``, then the fit."""
        st = data.structure
        if data.complex_d is not None:
            c, dmat = data.complex_mu / beta, data.complex_d
        else:
            c, dmat = _complex_dscales(Nw / beta, st)
        return self._fit_route(data.omega, dmat, c, {}, beta, Nw, st)[0]

    def _fit_route(self, omega, dmat, level_data, Fs, beta, Nw, st):
        """Fit every block's ``d``; returns ``(Scalings, max_ω σ̄(T_fit))``.

        ``level_data`` is what the pointwise scalings achieve (``σ̄`` of the
        transformed loop, or ``μ/β``).  Each block takes the lowest order
        whose weighted log error is below ``block_tol``; frequencies are
        weighted by ``(level/max level)^peak_power``.

        Where the fitted scalings exceed ``(1 + tol)`` times the data's peak,
        the data are *moved towards the fit*: near a μ peak the optimal D is
        far from unique and its pointwise values zigzag, so a smooth filter
        through them can lose 10-15% there although nearby, smoother D's
        achieve the same bound.  At each such frequency, starting from the
        fitted values, a descent on ``σ̄(D X D^{-1})`` over ``log d`` (its
        gradient is ``σ̄ (|u_rows|^2 - |v_cols|^2)`` per block, from the
        singular vectors) stops as soon as the level is met; those points
        get full weight and the fit is repeated (at most three times).
        """
        level_data = np.maximum(np.asarray(level_data, float), 1e-300)
        ref = float(level_data.max())
        target = ref * (1 + 0.5 * self.tol)
        wt = np.maximum((level_data / ref) ** self.peak_power, 1e-3)
        dmat = np.array(dmat, float)
        X = None
        best, best_level = None, np.inf
        for attempt in range(4):
            blocks = []
            for i, b in enumerate(st.blocks):
                if i == len(st.blocks) - 1:
                    blocks.append(BlockScaling(None, None))  # normalised: d = 1
                    continue
                blocks.append(BlockScaling(self._fit_d(omega, dmat[:, i], wt, self.block_tol), Fs.get(i)))
            sc = Scalings(tuple(blocks), float(beta), st)
            lev = np.linalg.norm(sc.transformed(Nw, omega), 2, axis=(1, 2))
            level = float(np.max(lev))
            if level < best_level:
                best, best_level = sc, level
            bad = np.where(lev > ref * (1 + self.tol))[0]
            if bad.size == 0 or attempt == 3:
                break
            if X is None:
                X = Scalings(tuple(BlockScaling(None, Fs.get(i)) for i in range(len(st.blocks))),
                             float(beta), st).transformed(Nw, omega)
            s = 1j * omega
            for k in bad:
                lfit = np.array([np.log(np.abs(b.d_at(s[k]))) for b in sc.blocks[:-1]])
                dmat[k, :-1] = np.exp(_descend_level(X[k], lfit, target, st))
                wt[k] = 1.0
        return best, best_level

    def _fit_F(self, omega, h, wt):
        best = None
        base = float(np.sqrt(np.sum(wt * np.clip(h, -50, 50) ** 2) / np.sum(wt)))
        for o in sorted(self.g_orders):
            if o == 0:
                continue
            f = fit_g(omega, h, o, wt)
            if best is None or f.error < best.error * 0.9:
                best = f
            if f.error <= 0.1 * max(base, 1e-9):
                break
        if best is None or best.error >= base * 0.95:
            return None  # the G data are not realisable well enough to help
        return best


class SlicotMagnitudeFit(LogMagnitudeFit):
    """D-scale fit strategy with SLICOT SB10YD (zero-phase magnitude data, stable min-phase).

    Same order selection as :class:`LogMagnitudeFit`; each block is fitted
    with ``slycot.sb10yd`` (MATLAB's ``fitmagfrd`` ancestor) instead of the
    log least squares.  G scalings (D-G-K) still use :func:`fit_g`.
    """

    def _fit_d(self, omega, dv, wt, tol):
        best = None
        for o in sorted(self.orders):
            f = _sb10yd_fit(omega, dv, o, wt)
            if f is None:
                continue
            if best is None or f.error < best.error * 0.999:
                best = f
            if f.error <= tol:
                return f
        return best if best is not None else fit_magnitude(omega, dv, 0, wt)


def _descend_level(X: np.ndarray, l0: np.ndarray, target: float, st: BlockStructure, steps: int = 60):
    """From ``log d = l0``, descend ``σ̄(D X D^{-1})`` until it is below ``target`` (last block fixed)."""
    rows, cols = st.col_slices, st.row_slices
    nb = len(st.blocks)

    def level(l):
        dl = np.ones(X.shape[0])
        dr = np.ones(X.shape[1])
        for i in range(nb - 1):
            dl[rows[i]] = np.exp(l[i])
            dr[cols[i]] = np.exp(l[i])
        Y = dl[:, None] * X / dr[None, :]
        U, sv, Vh = np.linalg.svd(Y)
        u, v = U[:, 0], Vh[0].conj()
        g = np.array([sv[0] * (np.sum(np.abs(u[rows[i]]) ** 2) - np.sum(np.abs(v[cols[i]]) ** 2))
                      for i in range(nb - 1)])
        return sv[0], g

    l = np.array(l0, float)
    f, g = level(l)
    for _ in range(steps):
        if f <= target:
            break
        gg = float(g @ g)
        if gg <= 1e-300:
            break
        step = (f - target) / gg * g  # Newton step on the linearised level
        t = 1.0
        while t > 1e-4:
            f2, g2 = level(l - t * step)
            if f2 < f:
                break
            t *= 0.5
        if t <= 1e-4:
            break
        l, f, g = l - t * step, f2, g2
    return l


class MuSweep:
    """μ upper bound and scalings of a stack of matrices, on one or two cores.

    Each matrix costs one SLICOT AB13MD call (20-45 ms for the 2R robust
    performance problem, ~100 per D-step).  With ``n_jobs = k`` the
    frequencies are dealt to ``k`` worker processes running ``slycot.ab13md``
    (a fresh interpreter through :class:`polyrob.analysis.mu.TimeLimitedCall`, never
    a fork, and no re-import of the user's script); this process only
    coordinates.  A worker that fails or times out is replaced by a local
    call.

    Parameters
    ----------
    n_jobs : int, optional
        Worker processes; default ``1`` (serial, in this process).  Workers
        pay off on an otherwise idle multi-core machine only: on a loaded
        2-core machine, measured, two workers gave no speed-up.
    method : str
        :func:`polyrob.analysis.mu.mussv` method; repeated scalar blocks (LMI) are
        always computed serially.
    """

    def __init__(self, n_jobs: Optional[int] = None, method: str = "auto", timeout: float = 120.0):
        self.n_jobs, self.method, self.timeout = n_jobs, method, timeout
        self._worker = None
        self._dead = False

    def _jobs(self, H, st) -> int:
        if st.has_repeated or self.method == "lmi":
            return 1
        return max(1, int(self.n_jobs or 1))

    def __call__(self, H: np.ndarray, st: BlockStructure):
        from polyrob.analysis.mu import _upper_ab13md, mussv

        st = as_block_structure(st)
        n = st.padded_size
        N = H.shape[0]
        mu = np.zeros(N)
        D = np.zeros((N, n, n), complex)
        G = np.zeros((N, n, n), complex)

        def local(k):
            if not np.all(np.isfinite(H[k])):
                mu[k], D[k], G[k] = np.inf, np.eye(n), 0.0
                return
            r = mussv(H[k], st, method=self.method, lower=False)
            mu[k], D[k], G[k] = r.upper, r.D, r.G

        jobs = self._jobs(H, st)
        if jobs <= 1 or self._dead or st.has_repeated:
            for k in range(N):
                local(k)
            return mu, D, G
        import threading

        from polyrob.analysis.mu import TimeLimitedCall

        # All AB13MD calls run in worker processes; this process only waits
        # (an AB13MD call here would hold the GIL and starve the threads that
        # talk to the workers).
        if self._worker is None:
            import os

            import slycot

            # one BLAS thread per worker: k workers with multi-threaded
            # OpenBLAS on k cores spin-wait against each other (no speed-up)
            keys = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
            saved = {k: os.environ.get(k) for k in keys}
            try:
                for k in keys:
                    os.environ[k] = "1"
                self._worker = [TimeLimitedCall(slycot.ab13md, timeout=self.timeout) for _ in range(jobs)]
                for wk in self._worker:
                    wk._start()
            finally:
                for k, v in saved.items():
                    if v is None:
                        os.environ.pop(k, None)
                    else:
                        os.environ[k] = v
        nblock, itype = st.ab13md_args
        todo = [k for k in range(N) if np.all(np.isfinite(H[k])) and np.any(H[k])]
        failed = []

        def run_remote(worker, ks):
            for k in ks:
                Ms = np.asfortranarray(st.pad(H[k]))
                ok, val = worker(Ms, nblock, itype)
                if not ok:
                    failed.append(k)
                    continue
                up, Dk, Gk, _ = _upper_ab13md(Ms, st, val)
                mu[k], D[k], G[k] = up, Dk, Gk

        threads = [threading.Thread(target=run_remote, args=(wk, todo[j::len(self._worker)]), daemon=True)
                   for j, wk in enumerate(self._worker)]
        for th in threads:
            th.start()
        for th in threads:
            th.join()
        for k in set(range(N)) - set(todo):
            local(k)
        for k in failed:
            local(k)
        if todo and len(failed) == len(todo):
            self._dead = True  # the workers do not work here: stay serial
        return mu, D, G

    def close(self):
        """Stop the worker processes."""
        if self._worker is not None:
            for wk in self._worker:
                wk.close()
            self._worker = None


#: the sweep used by the fits during a D-K run (set by DKIteration.run)
_ACTIVE_SWEEP: Optional[MuSweep] = None


def _sweep(H, st):
    sw = _ACTIVE_SWEEP if _ACTIVE_SWEEP is not None else MuSweep(n_jobs=1)
    return sw(H, st)


def _complex_dscales(X: np.ndarray, st: BlockStructure, mask=None, fallback=None) -> tuple[np.ndarray, np.ndarray]:
    """Complex-μ upper bound of each ``X[k]`` (real blocks as complex) and its normalised ``d``.

    With ``mask``, only the masked frequencies are swept; elsewhere ``d`` is
    ``fallback`` (per-block data, e.g. the D-step's) and the level is
    ``σ̄(D X D^{-1})`` for it.  Frequencies far below the peak carry little
    weight in the fit, and the fit check repairs them if needed.
    """
    rows = [[b.rows, 0] if b.kind == "real" else list(b.matlab) for b in st.blocks]
    stc = BlockStructure.from_matlab(rows)
    N = X.shape[0]
    idx = np.arange(N) if mask is None else np.where(mask)[0]
    c = np.zeros(N)
    d = np.ones((N, len(st.blocks)))
    if idx.size:
        ci, Di, _ = _sweep(X[idx], stc)
        sd = scaling_data(np.arange(idx.size, dtype=float) + 1.0, ci, Di, np.zeros_like(Di), stc)
        c[idx], d[idx] = ci, sd.d
    rest = np.setdiff1d(np.arange(N), idx)
    if rest.size:
        d[rest] = fallback[rest] if fallback is not None else 1.0
        rsl, csl = st.col_slices, st.row_slices
        for k in rest:
            dl = np.ones(X.shape[1])
            dr = np.ones(X.shape[2])
            for i in range(len(st.blocks)):
                dl[rsl[i]] = d[k, i]
                dr[csl[i]] = d[k, i]
            c[k] = np.linalg.norm(dl[:, None] * X[k] / dr[None, :], 2)
    return c, d


def _sb10yd_fit(omega, dv, order, wt):
    import slycot

    if order == 0:
        return fit_magnitude(omega, dv, 0, wt)
    try:
        n, A, B, C, D = slycot.sb10yd(0, 1, omega.size, dv, np.zeros_like(dv), omega, order, 1e-8)
    except Exception:  # noqa: BLE001
        return None
    A, B, C, D = (np.atleast_2d(X) for X in (A, B, C, D))
    if A.size == 0 or abs(D[0, 0]) < 1e-12:
        return None
    sys = control.ss(A, B, C, D)
    z = np.asarray(sys.zeros(), complex)
    p = np.asarray(sys.poles(), complex)
    if z.size != p.size or np.any(z.real >= 0) or np.any(p.real >= 0):
        return None
    k = float(D[0, 0])
    if k < 0:
        k = -k
    fit = MagnitudeFit(int(p.size), k, z, p, 0.0, 0.0)
    e = np.log10(np.abs(fit(1j * omega))) - np.log10(dv)
    return MagnitudeFit(int(p.size), k, z, p, *_fit_errors(e, wt))


# ============================================================ scaled plant
def _diag_ss(items, n_ch):
    """Block-diagonal MIMO system from a list of per-channel SISO ``(A, B, C, D)``."""
    As, Bs, Cs, Ds = [], [], [], []
    for (A, B, C, D) in items:
        As.append(A)
        Bs.append(B)
        Cs.append(C)
        Ds.append(D)
    A = sla.block_diag(*As) if any(a.size for a in As) else np.zeros((0, 0))
    n = A.shape[0]
    B = np.zeros((n, n_ch))
    C = np.zeros((n_ch, n))
    D = np.zeros((n_ch, n_ch))
    r = 0
    for ch, (a, b, c, d) in enumerate(items):
        k = a.shape[0]
        B[r:r + k, ch] = b[:, 0]
        C[ch, r:r + k] = c[0, :]
        D[ch, ch] = d[0, 0]
        r += k
    return A, B, C, D


def _connect(systems, Q, R, H, E):
    """Interconnect ``systems`` (list of (A,B,C,D)): ``U = Q Y + R e``, ``out = H Y + E e``."""
    A = sla.block_diag(*[s[0] for s in systems if s[0].size]) if any(s[0].size for s in systems) else np.zeros((0, 0))
    Bs = sla.block_diag(*[s[1] if s[1].size else np.zeros((s[0].shape[0], s[3].shape[1])) for s in systems])
    Cs = sla.block_diag(*[s[2] if s[2].size else np.zeros((s[3].shape[0], s[0].shape[0])) for s in systems])
    Ds = sla.block_diag(*[s[3] for s in systems])
    Bs = Bs.reshape(A.shape[0], Ds.shape[1])
    Cs = Cs.reshape(Ds.shape[0], A.shape[0])
    L = np.eye(Q.shape[0]) - Q @ Ds
    Li = np.linalg.solve(L, np.hstack([Q @ Cs, R]))
    LQ, LR = Li[:, :A.shape[0]], Li[:, A.shape[0]:]
    Acl = A + Bs @ LQ
    Bcl = Bs @ LR
    Ccl = H @ (Cs + Ds @ LQ)
    Dcl = H @ Ds @ LR + E
    return Acl, Bcl, Ccl, Dcl


def scaled_plant(P: control.StateSpace, scalings: Scalings, n_u: int, n_y: int) -> control.StateSpace:
    """Generalized plant of the K-step: ``Fl(P_s, K) = T`` of :meth:`Scalings.transformed`.

    ``P`` has inputs ``[x (M columns); u]`` and outputs ``[y (M rows); y_meas]``.
    The result has inputs ``[x̃; u]`` and outputs ``[ỹ; y_meas]`` with
    ``x = D^{-1} x̃ - F y``, ``ỹ = D (y + F x)`` and ``y = (P's M rows)/β``.
    With no G scaling this is ``diag(D, I) P diag(D^{-1}, I)/β`` on the M channels.
    Each scalar filter is realised in balanced form; ``D^{-1}`` is realised
    from the inverted factors, not by inverting a realisation.
    """
    st = scalings.structure
    A, B, C, D = (np.array(X, float) for X in (P.A, P.B, P.C, P.D))
    nr, nc = st.m_shape
    if (C.shape[0] - n_y, B.shape[1] - n_u) != (nr, nc):
        raise PolyrobError(
            f"plant has {C.shape[0] - n_y}x{B.shape[1] - n_u} M channels but the structure needs {nr}x{nc}"
        )
    beta = float(scalings.beta)
    C = C.copy()
    D = D.copy()
    C[:nr] /= beta
    D[:nr] /= beta
    one = (np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), np.array([[1.0]]))
    dl, dri = [one] * nr, [one] * nc
    real_rows, real_cols, Fs = [], [], []
    for b, sc, rsl, csl in zip(st.blocks, scalings.blocks, st.col_slices, st.row_slices):
        if sc.d is not None and (sc.d.order > 0 or abs(sc.d.gain - 1.0) > 0):
            fwd, inv = sc.d.ss(), sc.d.ss(inverse=True)
            for r in range(rsl.start, rsl.stop):
                dl[r] = fwd
            for c in range(csl.start, csl.stop):
                dri[c] = inv
        if b.kind == "real" and sc.F is not None and sc.F.order > 0:
            for j in range(b.rows):
                real_rows.append(rsl.start + j)
                real_cols.append(csl.start + j)
                Fs.append(sc.F.ss())
    Sdl = _diag_ss(dl, nr)
    Sdr = _diag_ss(dri, nc)
    nu_all = B.shape[1]
    ny_all = C.shape[0]
    if not Fs:
        # x = D^-1 x̃ ; ỹ = D y
        systems = [Sdr, (A, B, C, D), Sdl]
        # stacked inputs: [Sdr in (nc); P in (nc + n_u); Sdl in (nr)]
        # stacked outputs: [Sdr out (nc); P out (nr + n_y); Sdl out (nr)]
        nU = nc + nu_all + nr
        nY = nc + ny_all + nr
        Q = np.zeros((nU, nY))
        R = np.zeros((nU, nc + n_u))
        Q[nc:nc + nc, :nc] = np.eye(nc)  # P's x <- Sdr out
        Q[nc + nu_all:, nc:nc + nr] = np.eye(nr)  # Sdl in <- P's y
        R[:nc, :nc] = np.eye(nc)  # Sdr in <- x̃
        R[nc + nc:nc + nu_all, nc:] = np.eye(n_u)  # P's u <- u
        Hm = np.zeros((nr + n_y, nY))
        Hm[:nr, nc + ny_all:] = np.eye(nr)  # ỹ <- Sdl out
        Hm[nr:, nc + nr:nc + ny_all] = np.eye(n_y)  # y_meas
        E = np.zeros((nr + n_y, nc + n_u))
    else:
        nf = len(Fs)
        Er = np.zeros((nf, nr))
        Ec = np.zeros((nf, nc))
        Er[np.arange(nf), real_rows] = 1.0
        Ec[np.arange(nf), real_cols] = 1.0
        SF1 = _diag_ss(Fs, nf)  # f1 = F y_real   (feeds x = x' - Ec^T f1)
        SF2 = _diag_ss(Fs, nf)  # f2 = F x_real   (ỹ = D (y + Er^T f2))
        systems = [Sdr, (A, B, C, D), SF1, SF2, Sdl]
        # inputs: Sdr(nc) | P(nc+n_u) | SF1(nf) | SF2(nf) | Sdl(nr)
        iS, iP, i1, i2, iL = 0, nc, nc + nu_all, nc + nu_all + nf, nc + nu_all + 2 * nf
        nU = iL + nr
        # outputs: Sdr(nc) | P(nr+n_y) | SF1(nf) | SF2(nf) | Sdl(nr)
        oS, oP, o1, o2, oL = 0, nc, nc + ny_all, nc + ny_all + nf, nc + ny_all + 2 * nf
        nY = oL + nr
        Q = np.zeros((nU, nY))
        R = np.zeros((nU, nc + n_u))
        R[iS:iS + nc, :nc] = np.eye(nc)
        # P's x = x' - Ec^T f1
        Q[iP:iP + nc, oS:oS + nc] = np.eye(nc)
        Q[iP:iP + nc, o1:o1 + nf] = -Ec.T
        R[iP + nc:iP + nu_all, nc:] = np.eye(n_u)
        # SF1 in = y_real = Er y
        Q[i1:i1 + nf, oP:oP + nr] = Er
        # SF2 in = x_real = Ec x = Ec (x' - Ec^T f1)
        Q[i2:i2 + nf, oS:oS + nc] = Ec
        Q[i2:i2 + nf, o1:o1 + nf] = -Ec @ Ec.T
        # Sdl in = y + Er^T f2
        Q[iL:iL + nr, oP:oP + nr] = np.eye(nr)
        Q[iL:iL + nr, o2:o2 + nf] = Er.T
        Hm = np.zeros((nr + n_y, nY))
        Hm[:nr, oL:oL + nr] = np.eye(nr)
        Hm[nr:, oP + nr:oP + ny_all] = np.eye(n_y)
        E = np.zeros((nr + n_y, nc + n_u))
    As, Bs, Cs, Ds = _connect(systems, Q, R, Hm, E)
    return control.ss(As, Bs, Cs, Ds, dt=0)
