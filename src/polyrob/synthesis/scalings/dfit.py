"""D-scale fit strategies of the D-K / D-G-K iteration.

:class:`LogMagnitudeFit` (log-magnitude least squares, :func:`fit_magnitude`)
and :class:`SlicotMagnitudeFit` (SLICOT SB10YD) turn the per-frequency
scaling data of a D-step into stable, minimum-phase filters of the lowest
order that reproduces the bound, and realise the G scalings of real blocks
(:func:`~polyrob.synthesis.scalings.gfit.fit_g`).  The method is described in
:mod:`polyrob.synthesis.scalings.dscale`.
"""

from __future__ import annotations

from collections.abc import Sequence

import control
import numpy as np

from polyrob.analysis.mu.blocks import BlockStructure
from polyrob.errors import ArgumentError
from polyrob.synthesis.dk.musweep import MuSweep, complex_dscales
from polyrob.synthesis.scalings.data import BlockScaling, ScalingData, Scalings
from polyrob.synthesis.scalings.gfit import fit_g
from polyrob.synthesis.scalings.magfit import MagnitudeFit, fit_errors, fit_magnitude

__all__ = ["LogMagnitudeFit", "SlicotMagnitudeFit"]


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

    def __init__(
        self,
        orders: Sequence[int] = (0, 1, 2, 3, 4),
        g_orders: Sequence[int] = (0, 1, 2),
        tol: float = 0.02,
        block_tol: float = 0.05,
        peak_power: float = 4.0,
    ):
        self.orders = tuple(int(o) for o in orders)
        self.g_orders = tuple(int(o) for o in g_orders)
        self.tol, self.block_tol, self.peak_power = float(tol), float(block_tol), float(peak_power)
        #: the μ sweep of the fits' complex D-steps (set by DKIteration.run to
        #: share the D-step's worker; ``None``: a serial sweep)
        self.sweep: MuSweep | None = None
        if not self.orders or min(self.orders) < 0:
            raise ArgumentError(f"D-scale orders must be non-negative integers, got {orders!r}")

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
        for F_route in [Fs, {}] if Fs else [{}]:
            if F_route:
                sc0 = Scalings(
                    tuple(BlockScaling(None, F_route.get(i)) for i in range(len(st.blocks))), float(beta), st
                )
                X = sc0.transformed(Nw, omega)
                c, dmat = complex_dscales(X, st, near, data.d, sweep=self.sweep)
            elif data.complex_d is not None:
                c, dmat = data.complex_mu / beta, data.complex_d
            else:
                c, dmat = complex_dscales(Nw / beta, st, sweep=self.sweep)
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
            c, dmat = complex_dscales(Nw / beta, st, sweep=self.sweep)
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
            for i in range(len(st.blocks)):
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
                X = Scalings(
                    tuple(BlockScaling(None, Fs.get(i)) for i in range(len(st.blocks))), float(beta), st
                ).transformed(Nw, omega)
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
        g = np.array(
            [sv[0] * (np.sum(np.abs(u[rows[i]]) ** 2) - np.sum(np.abs(v[cols[i]]) ** 2)) for i in range(nb - 1)]
        )
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


def _sb10yd_fit(omega, dv, order, wt):
    import slycot
    from slycot.exceptions import SlycotArithmeticError, SlycotError

    if order == 0:
        return fit_magnitude(omega, dv, 0, wt)
    try:
        n, A, B, C, D = slycot.sb10yd(0, 1, omega.size, dv, np.zeros_like(dv), omega, order, 1e-8)
    except (SlycotError, SlycotArithmeticError, ValueError):
        return None  # this order is skipped; the caller keeps the best order that fitted
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
    return MagnitudeFit(int(p.size), k, z, p, *fit_errors(e, wt))
