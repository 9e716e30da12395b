"""Stable filters ``F`` that realise the G scalings of real parameters (D-G-K).

For a real scalar block the D-G multiplier is J-spectrally factorised with a
stable filter ``F``, ``‖F‖∞ < 1``, whose imaginary part carries ``g/β``
(see :mod:`polyrob.synthesis.scalings.dscale` for the derivation); :func:`fit_g`
finds such an ``F`` of given order from the frequency data.  No library fits
a filter to a prescribed imaginary part under a norm bound, hence this module.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla
from scipy.optimize import least_squares

from polyrob.synthesis.balanced import balanced_realization


# =================================================================== G fit
@dataclass(frozen=True, eq=False)
class GFit:
    """Stable filter ``F`` realising a G scaling.

    ``F(s) = c0 + Σ_k c_k a_k/(s + a_k) + Σ_l (α_l ω_l^2 + β_l ω_l s)/(s^2 + 2 ζ_l ω_l s + ω_l^2)``:
    real first-order terms and resonant pairs (narrow G bumps at a μ peak
    need the latter).

    Attributes
    ----------
    order : int
    c0 : float
    residues, poles : ndarray
        ``c_k`` and ``a_k > 0`` of the first-order terms.
    pairs : ndarray
        ``(m, 4)`` rows ``(ω_l, ζ_l, α_l, β_l)``.
    error : float
        Weighted RMS error of ``h = -2 Im F/(1 - |F|^2)`` against the data.
    hinf : float
        ``‖F‖∞`` (kept below one).
    """

    order: int
    c0: float
    residues: np.ndarray
    poles: np.ndarray
    error: float
    hinf: float
    pairs: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))

    def __call__(self, s):
        s = np.asarray(s, dtype=complex)
        out = np.full(s.shape, self.c0, dtype=complex)
        for c, a in zip(self.residues, self.poles):
            out = out + c * a / (s + a)
        for wl, zl, al, bl in self.pairs:
            out = out + (al * wl * wl + bl * wl * s) / (s * s + 2 * zl * wl * s + wl * wl)
        return out

    def scaled(self, f: float) -> GFit:
        p = self.pairs.copy()
        p[:, 2:] *= f
        return GFit(self.order, self.c0 * f, self.residues * f, self.poles, self.error, self.hinf * f, p)

    def ss(self):
        """Block-diagonal realisation ``(A, B, C, D)``, each mode balanced."""
        blocks = []
        for c, a in zip(self.residues, self.poles):
            g = np.sqrt(abs(c * a)) + 1e-300  # balanced first-order mode
            blocks.append((np.array([[-a]]), np.array([[g]]), np.array([[np.sign(c) * g]])))
        for wl, zl, al, bl in self.pairs:
            A2, B2, C2, _ = balanced_realization(
                np.array([[0.0, 1.0], [-wl * wl, -2 * zl * wl]]),
                np.array([[0.0], [1.0]]),
                np.array([[al * wl * wl, bl * wl]]),
                np.zeros((1, 1)),
            )
            blocks.append((A2, B2, C2))
        if not blocks:
            return np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), np.array([[self.c0]])
        A = sla.block_diag(*[b[0] for b in blocks])
        B = np.vstack([b[1] for b in blocks])
        C = np.hstack([b[2] for b in blocks])
        return A, B, C, np.array([[self.c0]])


def _h_of(Fv):
    return -2 * Fv.imag / np.maximum(1 - np.abs(Fv) ** 2, 1e-12)


def _g_basis(w, layout, x):
    """Columns of Im F and Re F for parameters ``x`` (log poles / log (ω, ζ)) of ``layout``."""
    cols_i, cols_r = [np.zeros_like(w)], [np.ones_like(w)]
    i = 0
    for kind in layout:
        if kind == "r":
            a = np.exp(x[i])
            den = a * a + w * w
            cols_i.append(-a * w / den)
            cols_r.append(a * a / den)
            i += 1
        else:
            wl, zl = np.exp(x[i]), np.exp(x[i + 1])
            re_d, im_d = wl * wl - w * w, 2 * zl * wl * w
            m2 = re_d**2 + im_d**2
            # ω_l^2/den and ω_l s/den
            cols_r.append(wl * wl * re_d / m2)
            cols_i.append(-wl * wl * im_d / m2)
            cols_r.append(wl * w * im_d / m2)
            cols_i.append(wl * w * re_d / m2)
            i += 2
    return np.array(cols_i).T, np.array(cols_r).T


def fit_g(
    omega, h, order: int, weight=None, *, max_gain: float = 0.95, re_weight: float = 0.05, ridge: float = 1e-3
) -> GFit:
    """Stable ``F`` with ``-2 Im F(jω)/(1 - |F(jω)|^2) ≈ h(ω)`` and ``‖F‖∞ < 1``.

    ``h = g/(β p)`` is the normalised G scaling of a real scalar block (see
    the module docstring).  ``F`` is a constant plus first-order terms and
    resonant pairs (``order`` poles in all; both layouts, all-real and
    pairs, are tried and the better kept).  For given poles the
    coefficients solve a linear least-squares problem on ``Im F`` (plus a
    small penalty on ``Re F``, which is free, and a ridge against cancelling
    terms), and the poles are optimised on top (variable projection).  The
    target ``Im F`` depends on ``|F|``, so a few fixed-point passes refine it.

    Parameters
    ----------
    omega, h : array_like
        Frequencies (rad/s) and normalised G data.
    order : int
        Number of poles (``0`` gives ``F = 0``: no G scaling).
    weight : array_like, optional
        Weight per frequency.
    max_gain : float
        ``F`` is scaled down if ``‖F‖∞`` exceeds this (the factorisation
        needs ``‖F‖∞ < 1``).
    re_weight : float
        Weight of the ``Re F`` penalty relative to the ``Im F`` fit (it only
        fixes the constant ``c0``, on which ``Im F`` does not depend).
    ridge : float
        Tikhonov weight on the coefficients.

    Examples
    --------
    >>> import numpy as np
    >>> from polyrob.synthesis.scalings.dscale import fit_g
    >>> w = np.logspace(-2, 2, 60)
    >>> F0 = 0.5 * 2.0 / (1j * w + 2.0) - 0.2           # a realisable F
    >>> h = -2 * F0.imag / (1 - np.abs(F0) ** 2)
    >>> fit = fit_g(w, h, order=1)
    >>> bool(fit.error < 0.05), bool(fit.hinf < 1)
    (True, True)
    """
    w = np.asarray(omega, float)
    h = np.clip(np.asarray(h, float), -50.0, 50.0)
    wt = np.ones_like(w) if weight is None else np.maximum(np.asarray(weight, float), 0.0)
    n = int(order)
    if n == 0 or not np.any(np.abs(h) > 1e-9):
        err = float(np.sqrt(np.sum(wt * h**2) / max(np.sum(wt), 1e-300)))
        return GFit(0, 0.0, np.zeros(0), np.zeros(0), err, 0.0)
    sw = np.sqrt(wt)
    lo, hi = np.log(w.min()), np.log(w.max())
    imp = np.abs(h) * wt
    centre = np.log(w[int(np.argmax(imp))]) if np.any(imp > 0) else 0.5 * (lo + hi)
    layouts = [["r"] * n]
    if n >= 2:
        layouts.append(["c"] * (n // 2) + ["r"] * (n % 2))
    best = None
    for layout in layouts:
        fit = _fit_g_layout(w, h, wt, sw, layout, centre, lo, hi, re_weight, ridge)
        if fit is None:
            continue
        # enforce ||F|| < 1 on a dense grid (the fit only saw the data grid)
        wd = np.logspace(np.log10(w.min()) - 2, np.log10(w.max()) + 2, 600)
        peak = float(max(np.max(np.abs(fit(1j * wd))), np.max(np.abs(fit(1j * w))), abs(fit(0.0))))
        if peak > max_gain:
            fit = fit.scaled(max_gain / peak)
            peak = max_gain
        r = sw * (_h_of(fit(1j * w)) - h)
        err = float(np.sqrt(np.sum(r**2) / max(np.sum(wt), 1e-300)))
        fit = GFit(n, fit.c0, fit.residues, fit.poles, err, peak, fit.pairs)
        if best is None or fit.error < best.error:
            best = fit
    return best


def _fit_g_layout(w, h, wt, sw, layout, centre, lo, hi, re_weight, ridge):
    nc = sum(1 if k == "r" else 2 for k in layout)
    x0, lb, ub = [], [], []
    spread = np.linspace(-1.0, 1.0, len(layout)) * (0.0 if len(layout) == 1 else 1.0)
    for kind, sp in zip(layout, spread):
        if kind == "r":
            x0.append(centre + sp)
            lb.append(lo)
            ub.append(hi)
        else:
            x0 += [centre + 0.5 * sp, np.log(0.3)]
            lb += [lo, np.log(0.05)]
            ub += [hi, 0.0]
    x0 = np.clip(np.array(x0), np.array(lb) + 1e-9, np.array(ub) - 1e-9)
    rg = ridge * np.sqrt(np.sum(wt) / w.size) * np.eye(nc + 1)

    def solve_c(x, tau):
        Bi, Br = _g_basis(w, layout, x)
        M = np.vstack([sw[:, None] * Bi, re_weight * sw[:, None] * Br, rg])
        rhs = np.concatenate([sw * tau, np.zeros(w.size), np.zeros(nc + 1)])
        c, *_ = np.linalg.lstsq(M, rhs, rcond=None)
        return c, M @ c - rhs

    def make(x, c):
        res, pol, pairs = [], [], []
        i, j = 0, 1
        for kind in layout:
            if kind == "r":
                pol.append(np.exp(x[i]))
                res.append(c[j])
                i += 1
                j += 1
            else:
                pairs.append([np.exp(x[i]), np.exp(x[i + 1]), c[j], c[j + 1]])
                i += 2
                j += 2
        return GFit(
            len(layout) + sum(k == "c" for k in layout),
            float(c[0]),
            np.array(res, float),
            np.array(pol, float),
            0.0,
            0.0,
            np.array(pairs, float).reshape(-1, 4),
        )

    tau = -h / (1 + np.sqrt(1 + h * h))  # Im F if F were purely imaginary
    x = x0
    for _ in range(4):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                sol = least_squares(
                    lambda v: solve_c(v, tau)[1],
                    x,
                    bounds=(np.array(lb), np.array(ub)),
                    method="trf",
                    max_nfev=60 * (len(x) + 1),
                )
            except ValueError:
                return None
        x = sol.x
        c, _ = solve_c(x, tau)
        Fv = make(x, c)(1j * w)
        cr = np.clip(1 - Fv.real**2, 0.05, 1.0)
        tau = -h * cr / (1 + np.sqrt(1 + h * h * cr))
    c, _ = solve_c(x, tau)
    return make(x, c)
