"""Stable, minimum-phase rational fits of a frequency-dependent magnitude (the D scalings).

:func:`fit_magnitude` fits ``|d(jω)|`` with a biproper filter of bounded order
by weighted least squares on the **log-magnitude**, over a second-order-section
parametrisation whose roots stay in the open left half-plane by construction;
:func:`balanced_realization` realises it in balanced form (canonical forms of
these filters reach entries ~1e10).  SLICOT's SB10YD fits the magnitude
itself and its filters can be non-minimum-phase or badly scaled, hence this
module; :class:`~polyrob.synthesis.scalings.dscale.SlicotMagnitudeFit` keeps SB10YD as
an alternative.

Examples
--------
>>> import numpy as np
>>> from polyrob.synthesis.scalings.magfit import fit_magnitude
>>> w = np.logspace(-2, 2, 50)
>>> fit = fit_magnitude(w, np.abs((1j * w + 1) / (1j * w + 10)), order=1)
>>> fit.order, bool(fit.error < 1e-6)
(1, True)
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from polyrob.errors import ArgumentError
from polyrob.synthesis.balanced import balanced_realization


# ================================================================ realisations
def _sections_ss(k: float, sos_z, sos_p, first_z, first_p):
    """Cascade realisation of ``k * prod(num)/prod(den)`` (biproper sections)."""
    # each section (s^2 + a1 s + a0)/(s^2 + b1 s + b0) = 1 + ((a1-b1) s + (a0-b0))/(s^2 + b1 s + b0)
    blocks = []
    for (a1, a0), (b1, b0) in zip(sos_z, sos_p):
        A = np.array([[0.0, 1.0], [-b0, -b1]])
        B = np.array([[0.0], [1.0]])
        C = np.array([[a0 - b0, a1 - b1]])
        blocks.append((A, B, C, np.array([[1.0]])))
    for az, ap in zip(first_z, first_p):
        blocks.append((np.array([[-ap]]), np.array([[1.0]]), np.array([[az - ap]]), np.array([[1.0]])))
    A = np.zeros((0, 0))
    B = np.zeros((0, 1))
    C = np.zeros((1, 0))
    D = np.array([[k]])
    for a, b, c, d in blocks:  # series: new = blk * current
        n1 = A.shape[0]
        A = np.block([[A, np.zeros((n1, a.shape[0]))], [b @ C, a]])
        B = np.vstack([B, b @ D])
        C = np.hstack([d @ C, c])
        D = d @ D
    return A, B, C, D


# ============================================================ magnitude fit
@dataclass(frozen=True, eq=False)
class MagnitudeFit:
    """A stable, minimum-phase, biproper SISO filter fitted to magnitude data.

    Attributes
    ----------
    order : int
        Number of poles (and of zeros) of the filter.
    gain : float
        High-frequency gain ``k`` (numerator and denominator are monic).
    zeros, poles : ndarray
        In the open left half-plane.
    error : float
        Weighted RMS error of ``log10 |d(jω)|`` against the data (decades,
        ``sqrt(Σ w e^2 / Σ w)``).
    max_error : float
        Largest error of ``log10 |d(jω)|`` where the weight is at least half
        its maximum (decades).
    """

    order: int
    gain: float
    zeros: np.ndarray
    poles: np.ndarray
    error: float
    max_error: float
    params: np.ndarray = field(repr=False, default=None)

    def _sections(self, inverse=False):
        z, p = (self.poles, self.zeros) if inverse else (self.zeros, self.poles)
        k = 1.0 / self.gain if inverse else self.gain
        return k, *_split_sections(z, p)

    def ss(self, inverse: bool = False) -> tuple[np.ndarray, ...]:
        """Balanced ``(A, B, C, D)`` of ``d`` (or of ``1/d``, exactly, from its factors)."""
        return balanced_realization(*_sections_ss(*self._sections(inverse)))

    def __call__(self, s) -> np.ndarray:
        s = np.asarray(s, dtype=complex)
        num = np.ones_like(s)
        den = np.ones_like(s)
        for z in self.zeros:
            num = num * (s - z)
        for p in self.poles:
            den = den * (s - p)
        return self.gain * num / den


def _split_sections(zeros, poles):
    """Pair roots into real second-order sections ``(a1, a0)`` plus first-order ones."""

    def split(r):
        r = np.asarray(r, complex)
        cplx = r[r.imag > 1e-12 * np.maximum(1.0, np.abs(r))]
        real = np.sort(r[np.abs(r.imag) <= 1e-12 * np.maximum(1.0, np.abs(r))].real)
        sos = [(-2 * c.real, abs(c) ** 2) for c in cplx]
        # pair real roots into sections so both sides have the same layout
        firsts = list(-real)
        return sos, firsts

    sz, fz = split(zeros)
    sp, fp = split(poles)
    # make layouts match: turn pairs of first-order terms into sections as needed
    while len(sz) < len(sp) and len(fz) >= 2:
        a, b = fz.pop(), fz.pop()
        sz.append((a + b, a * b))
    while len(sp) < len(sz) and len(fp) >= 2:
        a, b = fp.pop(), fp.pop()
        sp.append((a + b, a * b))
    return sz, sp, fz, fp


def _logmag(params, w, n):
    """log|d(jω)| for the SOS/first-order parametrisation (natural log)."""
    out = np.full(w.shape, params[0])
    w2 = w * w
    i = 1
    for _ in range(n // 2):
        lwz, lzz, lwp, lzp = params[i : i + 4]
        wz, zz, wp, zp = np.exp(lwz), np.exp(lzz), np.exp(lwp), np.exp(lzp)
        out += 0.5 * np.log((wz * wz - w2) ** 2 + (2 * zz * wz * w) ** 2 + 1e-300)
        out -= 0.5 * np.log((wp * wp - w2) ** 2 + (2 * zp * wp * w) ** 2 + 1e-300)
        i += 4
    if n % 2:
        az, ap = np.exp(params[i]), np.exp(params[i + 1])
        out += 0.5 * np.log(az * az + w2) - 0.5 * np.log(ap * ap + w2)
    return out


def _logmag_jac(params, w, n):
    """Jacobian of :func:`_logmag` with respect to the (log) parameters."""
    J = np.zeros((w.size, params.size))
    J[:, 0] = 1.0
    w2 = w * w
    i = 1
    for _ in range(n // 2):
        for off, sign in ((0, 1.0), (2, -1.0)):
            wn, z = np.exp(params[i + off]), np.exp(params[i + off + 1])
            wn2 = wn * wn
            Q = (wn2 - w2) ** 2 + 4 * z * z * wn2 * w2 + 1e-300
            J[:, i + off] = sign * (2 * wn2 * (wn2 - w2) + 4 * z * z * wn2 * w2) / Q
            J[:, i + off + 1] = sign * 4 * z * z * wn2 * w2 / Q
        i += 4
    if n % 2:
        for off, sign in ((0, 1.0), (1, -1.0)):
            a2 = np.exp(2 * params[i + off])
            J[:, i + off] = sign * a2 / (a2 + w2)
    return J


def _root_logs_jac(params, n):
    rows = []
    i = 1
    for _ in range(n // 2):
        for off in (0, 2):
            z = np.exp(params[i + off + 1])
            r1 = np.zeros(params.size)
            r2 = np.zeros(params.size)
            r1[i + off] = r2[i + off] = 1.0
            if z > 1:
                d = z / np.sqrt(max(z * z - 1, 1e-12))
                r1[i + off + 1], r2[i + off + 1] = -d, d
            rows += [r1, r2]
        i += 4
    if n % 2:
        for off in (0, 1):
            r = np.zeros(params.size)
            r[i + off] = 1.0
            rows.append(r)
    return np.array(rows).reshape(-1, params.size)


def _root_logs(params, n):
    """log of the smallest and largest root magnitude of every section (and first-order term)."""
    out = []
    i = 1
    for _ in range(n // 2):
        for lw, lz in ((params[i], params[i + 1]), (params[i + 2], params[i + 3])):
            z = np.exp(lz)
            if z > 1:
                q = z + np.sqrt(z * z - 1)
                out += [lw - np.log(q), lw + np.log(q)]
            else:
                out += [lw, lw]
        i += 4
    if n % 2:
        out += [params[i], params[i + 1]]
    return np.array(out)


def _params_to_roots(params, n):
    zeros, poles = [], []
    i = 1
    for _ in range(n // 2):
        wz, zz, wp, zp = np.exp(params[i : i + 4])
        zeros += list(np.roots([1.0, 2 * zz * wz, wz * wz]))
        poles += list(np.roots([1.0, 2 * zp * wp, wp * wp]))
        i += 4
    if n % 2:
        zeros.append(-np.exp(params[i]))
        poles.append(-np.exp(params[i + 1]))
    return np.array(zeros, complex), np.array(poles, complex)


def fit_magnitude(
    omega,
    mag,
    order: int,
    weight=None,
    *,
    init: MagnitudeFit | None = None,
    zeta_bounds: tuple[float, float] = (0.05, 3.0),
) -> MagnitudeFit:
    """Stable minimum-phase biproper filter with ``|d(jω)| ≈ mag`` (log-magnitude LS).

    Minimises ``Σ w_k (log|d(jω_k)| - log mag_k)^2`` over a gain and second
    (and one first) order sections ``(s^2 + 2ζ_z ω_z s + ω_z^2)/(s^2 + 2ζ_p ω_p s + ω_p^2)``
    whose parameters are optimised in log scale, so every iterate is stable
    and minimum phase.  Natural frequencies are kept within the data range
    and damping ratios within ``zeta_bounds`` (so a real root is at least
    ``ω_min/(2 ζ_max)``): no pole drifts onto the imaginary axis or to
    infinity, which would make the K-step stiff or unstabilisable.

    Parameters
    ----------
    omega, mag : array_like
        Frequencies (rad/s, positive) and magnitudes (positive).
    order : int
        Number of poles (= number of zeros).
    weight : array_like, optional
        Non-negative weight per frequency (default uniform).
    init : MagnitudeFit, optional
        A lower-order fit to start from (the new section is placed where its
        residual is largest).

    Returns
    -------
    MagnitudeFit
    """
    w = np.asarray(omega, float)
    m = np.asarray(mag, float)
    ok = np.isfinite(m) & (m > 0) & (w > 0)
    w, m = w[ok], m[ok]
    if w.size < 2:
        raise ArgumentError("fit_magnitude needs at least two positive frequencies with positive data")
    wt = np.ones_like(w) if weight is None else np.asarray(weight, float)[ok]
    wt = np.maximum(wt, 0.0)
    if wt.sum() <= 0:
        wt = np.ones_like(w)
    y = np.log(m)
    n = int(order)
    if n < 0:
        raise ArgumentError("order must be >= 0")
    k0 = float(np.sum(wt * y) / np.sum(wt))
    if n == 0:
        e = (y - k0) / np.log(10)
        return MagnitudeFit(
            0, float(np.exp(k0)), np.zeros(0, complex), np.zeros(0, complex), *fit_errors(e, wt), np.array([k0])
        )
    lo_w, hi_w = np.log(w.min()), np.log(w.max())
    lz0, lz1 = np.log(zeta_bounds[0]), np.log(zeta_bounds[1])
    lb, ub = [-np.inf], [np.inf]
    for _ in range(n // 2):
        lb += [lo_w, lz0, lo_w, lz0]
        ub += [hi_w, lz1, hi_w, lz1]
    if n % 2:
        lb += [lo_w, lo_w]
        ub += [hi_w, hi_w]
    lb, ub = np.array(lb), np.array(ub)
    sw = np.sqrt(wt)
    lw_min, lw_max = np.log(w.min() / 2), np.log(w.max() * 2)
    pen = 10.0 * np.sqrt(np.sum(wt) / w.size)

    def resid(p):
        r = sw * (_logmag(p, w, n) - y)
        # keep every root (also the small real root of an overdamped
        # section, ω(ζ - sqrt(ζ^2 - 1))) within the data range: a pole far
        # below it behaves like an integrator in the K-step
        lr = _root_logs(p, n)
        return np.concatenate([r, pen * np.maximum(lw_min - lr, 0), pen * np.maximum(lr - lw_max, 0)])

    def jac(p):
        lr = _root_logs(p, n)
        Jr = _root_logs_jac(p, n)
        return np.vstack(
            [
                sw[:, None] * _logmag_jac(p, w, n),
                -pen * (lw_min - lr > 0)[:, None] * Jr,
                pen * (lr - lw_max > 0)[:, None] * Jr,
            ]
        )

    starts = []
    if init is not None and init.params is not None:
        starts.append(_extend_params(init, n, w, y, wt))
    starts.append(_spread_params(n, w, y, wt))
    best = None
    for x0 in starts:
        x0 = np.clip(x0, lb + 1e-9, ub - 1e-9)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                sol = least_squares(
                    resid,
                    x0,
                    jac=jac,
                    bounds=(lb, ub),
                    method="trf",
                    x_scale=1.0,
                    max_nfev=100 * (len(x0) + 1),
                    xtol=1e-8,
                    ftol=1e-8,
                )
            except ValueError:
                continue
        if best is None or sol.cost < best.cost:
            best = sol
    p = best.x
    z, pl = _params_to_roots(p, n)
    e = (_logmag(p, w, n) - y) / np.log(10)
    return MagnitudeFit(n, float(np.exp(p[0])), z, pl, *fit_errors(e, wt), p)


def fit_errors(e, wt):
    """Weighted RMS of the log10 error, and its largest value where the weight is high."""
    wt = np.asarray(wt, float)
    rms = float(np.sqrt(np.sum(wt * e * e) / max(np.sum(wt), 1e-300)))
    big = wt >= 0.5 * wt.max()
    return rms, float(np.max(np.abs(e[big]))) if np.any(big) else 0.0


def _spread_params(n, w, y, wt):
    """Poles/zeros spread over the data range, pole = zero (a flat start)."""
    k0 = float(np.sum(wt * y) / np.sum(wt))
    ls = np.linspace(np.log(w.min()), np.log(w.max()), n + 2)[1:-1]
    # a better start: place each pair where the data changes slope the most
    p = [k0]
    i = 0
    for _ in range(n // 2):
        lw = ls[i]
        p += [lw + 0.3, np.log(0.7), lw - 0.3, np.log(0.7)]
        i += 2 if i + 2 < len(ls) else 0
    if n % 2:
        lw = ls[-1]
        p += [lw + 0.2, lw - 0.2]
    return np.array(p)


def _extend_params(init: MagnitudeFit, n, w, y, wt):
    """Lower-order solution + a neutral section where the residual is largest."""
    n0 = init.order
    p0 = np.asarray(init.params, float)
    res = np.sqrt(wt) * np.abs(_logmag(p0, w, n0) - y)
    lw = np.log(w[int(np.argmax(res))])
    # rebuild parameters in the layout of order n from the roots of the old fit
    secs = list(p0[1 : 1 + 4 * (n0 // 2)].reshape(-1, 4))
    firsts = [p0[1 + 4 * (n0 // 2) :]] if n0 % 2 else []
    if n % 2 == 0 and n0 % 2 == 1:
        # old first-order term + new first-order term -> one section
        az, ap = np.exp(firsts[0])
        a2 = np.exp(lw)
        wz, wp = np.sqrt(az * a2), np.sqrt(ap * a2)
        zz, zp = (az + a2) / (2 * wz), (ap + a2 * 1.05) / (2 * wp)
        secs.append(np.log([wz, zz, wp, zp]))
        firsts = []
    elif n % 2 == 1 and n0 % 2 == 0:
        firsts = [np.array([lw + 0.05, lw - 0.05])]
    else:
        secs.append(np.array([lw + 0.05, np.log(0.7), lw - 0.05, np.log(0.7)]))
    out = [p0[0]] + [v for s in secs for v in s] + [v for f in firsts for v in f]
    return np.array(out, float)
