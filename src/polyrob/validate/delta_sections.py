"""Delta-operator second-order sections (Middleton & Goodwin): ``δ = (z - 1)/T``.

In the shift form a slow pole at ``z = 1 - 1e-5`` (a 0.1 Hz mode at 1 kHz)
has ``a1 ≈ -2``, ``a2 ≈ 1``: the pole is the tiny difference ``1 + a1 + a2``,
and rounding the coefficients to float moves it (or loses an integral gain).
In ``δ`` that pole is ``d = -0.01``, a coefficient of ordinary size, so a
rounded coefficient moves it by a relative amount of the rounding itself.

A section row ``[β0, β1, β2, 1, α1, α2]`` means
``(β0 δ² + β1 δ + β2) / (δ² + α1 δ + α2)``; a first-order section is the row
with ``β2 = α2 = 0`` (the common ``δ`` cancels: ``(β0 δ + β1)/(δ + α1)``).
It runs as transposed direct form II with ``δ⁻¹`` as the state update
``s <- s + T w``::

    y = β0 x + s1;  s1 += T (β1 x - α1 y + s2);  s2 += T (β2 x - α2 y)

The coefficients come from the entry's poles and zeros computed in ``δ``
(the eigenvalues and transmission zeros of ``((A - I)/T, B, C/T, D)``), never
from shift coefficients (where ``1 + a1 + a2`` cancels).  An integrator
(``|z - 1| <= at_one``) is ``δ = 0`` exactly, so its ``α2`` (or ``α1``) is an
exact zero in every arithmetic.  ``K(z) = k Π(z - z_i)/Π(z - p_i)
= k T^(nz - np) Π(δ - δz_i)/Π(δ - δp_i)``.

Examples
--------
>>> import control, numpy as np
>>> from polyrob.validate.discretize import discretize
>>> from polyrob.validate.quantize import sos_realization
>>> Kd = discretize(control.tf([1.0, 0.1], [1.0, 0.0]), 1000.0)  # a PI at 1 kHz: 1 + T/20 + 0.1/δ
>>> sos = sos_realization(Kd, form="delta")
>>> sos.form, sos.sections[0][0].tolist()
('delta', [[1.00005, 0.1, 0.0, 1.0, 0.0, 0.0]])
"""

from __future__ import annotations

import control
import numpy as np
import scipy.signal as ss

from polyrob.errors import PolyrobError

__all__ = [
    "clean_pairs",
    "delta_entry_sections",
    "reduced",
    "integrates",
    "delta_entry_gain",
    "delta_cascade_ss",
    "delta_response",
]


def clean_pairs(r):
    """Roots as exact conjugate pairs and exact reals (scipy's pairing needs them)."""
    r = np.asarray(r, complex)
    real = np.abs(r.imag) <= 1e-9 * np.maximum(1.0, np.abs(r))
    out = list(r[real].real.astype(complex))
    upper = r[~real & (r.imag > 0)]
    for z in upper:
        out += [z, np.conj(z)]
    return np.array(out, complex)


def delta_entry_sections(g, dt: float, at_one: float) -> np.ndarray:
    """Delta sections ``(n_sec, 6)`` of one SISO discrete entry ``g`` (a control.StateSpace with ``dt``).

    ``at_one``: a pole or zero with ``|z - 1| <= at_one`` is put at ``δ = 0`` exactly.
    """
    A, B, C, D = (np.asarray(X, float) for X in (g.A, g.B, g.C, g.D))
    n = A.shape[0]
    Ad = (A - np.eye(n)) / dt
    gd = control.ss(Ad, B, C / dt, D)  # K(z) = D + (C/T)(δ I - Ad)^-1 B
    p = clean_pairs(np.linalg.eigvals(Ad))
    z = clean_pairs(np.atleast_1d(gd.zeros()))
    z = z[np.isfinite(z)]
    exact_zero = at_one / dt
    p = np.where(np.abs(p) <= exact_zero, 0.0, p)
    z = np.where(np.abs(z) <= exact_zero, 0.0, z)
    d0 = (0.37 + 0.21j - 1.0) / dt  # the shift form's evaluation point z0, off every pole and zero in practice
    H = complex((D + (C / dt) @ np.linalg.solve(d0 * np.eye(n) - Ad, B))[0, 0])
    k = H * np.prod(d0 - p) / np.prod(d0 - z)
    if abs(k.imag) > 1e-6 * max(abs(k), 1e-300):
        raise PolyrobError(f"internal error: complex gain {k} of a real controller entry")
    rows = np.atleast_2d(ss.zpk2sos(z, p, k.real, analog=True))
    first = rows[:, 3] == 0.0  # scipy's first-order analog rows: [0, β0, β1, 0, 1, α1]
    for r in np.flatnonzero(first):
        rows[r] = [rows[r, 1], rows[r, 2], 0.0, 1.0, rows[r, 5], 0.0]
    return rows


def reduced(row):
    """``(numerator, denominator)`` coefficients in ``δ`` of a row, the common factors ``δ`` cancelled."""
    num, den = np.asarray(row[:3], float), np.asarray(row[3:], float)
    while num.size > 1 and num[-1] == 0.0 and den[-1] == 0.0:
        num, den = num[:-1], den[:-1]
    return num, den


def integrates(row) -> bool:
    """Whether a delta row has a pole at ``δ = 0`` (an integrator, ``z = 1``)."""
    num, den = reduced(row)
    return den.size > 1 and den[-1] == 0.0


def delta_entry_gain(secs, dt: float):
    """``(poles in z, integrators, differentiators, gain)`` of one entry's delta sections.

    ``gain``: ``(1 - z^-1)^(d - i) K(z)`` at ``z = 1`` (the DC gain, or the
    integral gain of an entry that integrates), as the shift form's
    :func:`polyrob.validate.quantize._entry_gain`: ``1 - z^-1 = Tδ/(1 + Tδ)``,
    so each pole at ``δ = 0`` contributes ``T`` and the ratio of the lowest
    non-zero coefficients.
    """
    poles, n_int, n_dif, gain = [], 0, 0, 1.0
    for row in secs:
        num, den = reduced(row)
        poles.extend(1.0 + dt * np.roots(den) if den.size > 1 else [])
        while den.size > 1 and den[-1] == 0.0:
            n_int, den = n_int + 1, den[:-1]
        while num.size > 1 and num[-1] == 0.0 and np.any(num != 0.0):
            n_dif, num = n_dif + 1, num[:-1]
        gain = gain * num[-1] / den[-1] if den[-1] != 0.0 else np.inf
    return np.array(poles, complex), n_int, n_dif, gain * dt ** (n_int - n_dif)


def delta_cascade_ss(secs, dt: float):
    """Shift state space ``(A, B, C, D)`` of a delta cascade: ``A = I + T A_δ`` on the sections' states.

    A first-order section has one state (its ``s2`` never leaves zero).
    """
    n = 2 * secs.shape[0]
    A = np.eye(n)
    B = np.zeros(n)
    cin, din = np.zeros(n), 1.0  # signal into section k = cin . s + din e
    for k, (b0, b1, b2, _, a1, a2) in enumerate(secs):
        cy = b0 * cin
        cy[2 * k] += 1.0
        dy = b0 * din
        w1 = b1 * cin - a1 * cy
        w1[2 * k + 1] += 1.0
        A[2 * k] += dt * w1
        A[2 * k + 1] += dt * (b2 * cin - a2 * cy)
        B[2 * k : 2 * k + 2] = [dt * (b1 * din - a1 * dy), dt * (b2 * din - a2 * dy)]
        cin, din = cy, dy
    # a first-order section's s2 (β2 = α2 = 0) stays zero: drop it, else it is a spurious pole at z = 1
    keep = [k for k in range(n) if k % 2 == 0 or secs[k // 2, 2] != 0.0 or secs[k // 2, 5] != 0.0]
    return A[np.ix_(keep, keep)], B[keep], cin[keep], din


def delta_response(secs, dt: float, omega) -> np.ndarray:
    """Frequency response of a delta cascade at ``omega`` (rad/s), evaluated in ``δ = expm1(jωT)/T`` (no cancellation)."""
    d = np.expm1(1j * np.asarray(omega, float) * dt) / dt
    H = np.ones_like(d)
    for row in secs:
        num, den = reduced(row)
        H = H * np.polyval(num, d) / np.polyval(den, d)
    return H
