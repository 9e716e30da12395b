"""The instrument's part of a computed-torque factor as an exact LFT in its mass and centre of mass.

A payload of mass ``m`` whose centre of mass sits at ``c`` (flange frame) is
the rigid body of ten parameters ``m [1, c, vech(S(c)^T S(c)) + solid]``
(``solid`` the rotational inertia of its solid body per kilogram): linear
in ``m``, quadratic in ``c``.  The computed-torque factor is linear in the
parameters (:mod:`polyrob.plant.models.inner_links`), so its payload part
at one state is, exactly::

    K_pay(m, c) = K_00 + m Phi(c),    Phi(c) = Phi_0 + sum_j d_j Phi_j + sum_{j <= l} d_j d_l Phi_jl

with ``m = m_0 + m_r delta_m`` over the mass range and ``c = c_0 + R d``
over the box that holds the centre-of-mass set (a ball's is its
circumscribed cube: the model covers the cube's corners too, and says so).
That polynomial is an LFT in four real scalars (``delta_m``, ``d_x``,
``d_y``, ``d_z`` within ``±1``), built Horner-wise (:func:`payload_lft`)::

    e_jl = d_l Phi_jl z                     (one per pair j <= l, at the rank of Phi_jl)
    f_j  = d_j (Phi_j z + sum_{l >= j} e_jl)
    g    = delta_m m_r (Phi_0 z + sum_j f_j)
    K_pay z = (K_00 + m_0 Phi_0) z + m_0 sum_j f_j + g

``z = [x; a]``.  Each scalar's channels form one repeated real block, so
μ sees every member as the rigid body it is and nothing else: no box of
the ten parameters, whose corners hold second moments without mass and
indefinite inertias (why ``inner-links`` samples the payload's set
instead, and carries it in norm-bounded blocks).

Why by hand: python-control has no LFT builder for polynomial parameter
dependence (MATLAB's ``ureal`` arithmetic builds this one), and the
factor's coefficients are polyrob's own.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["PayloadLFT", "payload_lft", "PAYLOAD_SCALARS"]

#: The LFT's four scalars (signal names take no dot).
PAYLOAD_SCALARS = ("payload_mass", "payload_com_x", "payload_com_y", "payload_com_z")

#: Singular values kept in a channel's low-rank factors, relative to the largest coefficient's.
RANK_TOL = 1e-10


@dataclass(frozen=True, eq=False)
class PayloadLFT:
    """The payload's part of a factor at one state as an LFT (module text): its coefficients and channels.

    ``offset`` (``m x 3m``) is ``K_pay`` at the scalars' zero; the channels
    ``d = Delta v`` read ``v = C z + D d`` and add ``B d`` to the factor's
    output (``z = [x; a]``); ``parameter`` gives each channel's scalar
    (an index into :data:`PAYLOAD_SCALARS`), channels of one scalar
    contiguous, ``sizes`` each scalar's repeats.
    """

    mass: tuple  # (m_0, m_r)
    com: tuple  # (c_0, R): the centre and half-widths of the box holding the centre-of-mass set
    base: np.ndarray  # K_00
    phi0: np.ndarray
    phi1: np.ndarray  # (3, m, 3m)
    phi2: dict  # (j, l), j <= l -> (m, 3m)
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    parameter: np.ndarray
    covers: str

    @property
    def offset(self) -> np.ndarray:
        """``K_pay`` at the scalars' zero: ``K_00 + m_0 Phi_0``."""
        return self.base + self.mass[0] * self.phi0

    @property
    def sizes(self) -> tuple:
        """Each scalar's repeats (its channels), in :data:`PAYLOAD_SCALARS` order."""
        return tuple(int(np.sum(self.parameter == s)) for s in range(len(PAYLOAD_SCALARS)))

    def units(self, mass, com) -> np.ndarray:
        """The scalars ``(delta_m, d_x, d_y, d_z)`` of a payload ``(mass, com)`` (within ``±1`` on the set)."""
        (m0, mr), (c0, R) = self.mass, self.com
        d = np.divide(np.asarray(com, float) - c0, R, out=np.zeros(3), where=R > 0)
        return np.r_[(mass - m0) / mr if mr > 0 else 0.0, d]

    def value(self, mass, com) -> np.ndarray:
        """``K_pay(mass, com)`` from the polynomial (exact up to rounding)."""
        d = self.units(mass, com)[1:]
        phi = self.phi0 + np.tensordot(d, self.phi1, axes=1)
        for (j, l), P in self.phi2.items():
            phi = phi + d[j] * d[l] * P
        return self.base + mass * phi

    def closed(self, delta) -> np.ndarray:
        """The LFT's ``K`` at scalars ``delta`` (4,): ``offset + B Delta (I - D Delta)^-1 C`` (tests it against :meth:`value`)."""
        Delta = np.diag(np.asarray(delta, float)[self.parameter])
        k = len(self.parameter)
        return self.offset + self.B @ Delta @ np.linalg.solve(np.eye(k) - self.D @ Delta, self.C)


def _factors(P, tol):
    """``(L, R)`` with ``P = L R`` at ``P``'s numerical rank (singular values above ``tol``), balanced."""
    U, s, Vt = np.linalg.svd(P, full_matrices=False)
    r = int(np.sum(s > tol))
    root = np.sqrt(s[:r])
    return U[:, :r] * root, root[:, None] * Vt[:r]


def _basis(M, tol):
    """An orthonormal basis of ``M``'s column space (singular values above ``tol``)."""
    U, s, _ = np.linalg.svd(M, full_matrices=False)
    return U[:, : int(np.sum(s > tol))]


def payload_lft(value, body) -> PayloadLFT:
    """The LFT of ``K_pay`` for a payload set ``body`` (:class:`~polyrob.uncertainty_set.payload_body.PayloadBody`).

    ``value(mass, com)`` returns ``K_pay`` (``m x 3m``) of one payload: it
    is sampled at 1 + 3 + 6 centres of mass and two masses, which determine
    the polynomial exactly (it is quadratic in ``c`` and affine in ``m``).

    Examples
    --------
    >>> import numpy as np
    >>> from polyrob.uncertainty_set.payload_body import PayloadBody, second_moment
    >>> rng = np.random.default_rng(0)
    >>> A, Bm, Cs = rng.normal(size=(2, 6)), rng.normal(size=(3, 2, 6)), rng.normal(size=(6, 2, 6))
    >>> def value(mass, com):
    ...     return mass * (A + np.tensordot(com, Bm, 1) + np.tensordot(second_moment(1.0, com), Cs, 1))
    >>> lft = payload_lft(value, PayloadBody(0.0, 1.5, com_radius=0.1))
    >>> delta = np.array([0.3, -1.0, 0.5, 0.2])
    >>> mass, com = 0.75 + 0.75 * delta[0], 0.1 * delta[1:]
    >>> bool(np.allclose(lft.closed(delta), value(mass, com), atol=1e-12))
    True
    """
    lo, hi = float(body.mass_lower), float(body.mass_upper)
    m0, mr = 0.5 * (lo + hi), 0.5 * (hi - lo)
    box = np.array(body.com_box(), float)
    c0, R = box.mean(axis=1), 0.5 * (box[:, 1] - box[:, 0])
    base = np.asarray(value(0.0, c0), float)

    def phi(d):
        return np.asarray(value(1.0, c0 + R * np.asarray(d, float)), float) - base

    e = np.eye(3)
    phi0 = phi(np.zeros(3))
    plus, minus = [phi(e[j]) for j in range(3)], [phi(-e[j]) for j in range(3)]
    phi1 = np.array([0.5 * (p - q) for p, q in zip(plus, minus)])
    phi2 = {(j, j): 0.5 * (plus[j] + minus[j]) - phi0 for j in range(3)}
    for j in range(3):
        for l in range(j + 1, 3):
            phi2[(j, l)] = phi(e[j] + e[l]) - phi0 - phi1[j] - phi1[l] - phi2[(j, j)] - phi2[(l, l)]
    m, width = phi0.shape
    tol = RANK_TOL * max(float(np.abs(a).max()) for a in [phi0, *phi1, *phi2.values()])
    # channels, grouped by scalar: mass (g), then for each d_j its f_j and the e_lj with l = j's pairs... (below)
    pair_factors = {key: _factors(P, tol) for key, P in phi2.items()}
    # f_j's input space: Phi_j z plus the e_jl it sums; g's: Phi_0 z plus every f_j
    f_basis = [_basis(np.hstack([phi1[j]] + [pair_factors[(j, l)][0] for l in range(j, 3)]), tol) for j in range(3)]
    g_basis = _basis(np.hstack([phi0] + f_basis), tol)
    groups = []  # (scalar, kind, key, size)
    groups.append((0, "g", None, g_basis.shape[1]))
    for s in range(3):  # d_s multiplies f_s and every e_js (j <= s)
        groups.append((1 + s, "f", s, f_basis[s].shape[1]))
        groups += [(1 + s, "e", (j, s), pair_factors[(j, s)][1].shape[0]) for j in range(s + 1)]
    start = np.cumsum([0] + [g[3] for g in groups])
    at = {(kind, key): slice(a, b) for (_, kind, key, _), a, b in zip(groups, start[:-1], start[1:])}
    k = int(start[-1])
    B, C, D = np.zeros((m, k)), np.zeros((k, width)), np.zeros((k, k))
    gs = at[("g", None)]
    C[gs] = mr * g_basis.T @ phi0
    B[:, gs] = g_basis
    for j in range(3):
        fs = at[("f", j)]
        Q = f_basis[j]
        C[fs] = Q.T @ phi1[j]
        B[:, fs] = m0 * Q  # m_0 sum_j f_j
        D[gs, fs] = mr * g_basis.T @ Q  # g reads every f_j
        for l in range(j, 3):
            es = at[("e", (j, l))]
            L, Rf = pair_factors[(j, l)]
            C[es] = Rf
            D[fs, es] = Q.T @ L  # f_j reads e_jl
    parameter = np.concatenate([np.full(g[3], g[0]) for g in groups]).astype(int)
    ball = body.com_radius is not None
    covers = (
        f"payload {lo:g}-{hi:g} kg, its centre of mass in the box "
        + " x ".join(f"[{a:.3g}, {b:.3g}]" for a, b in box)
        + (" m (the cube around its ball)" if ball else " m")
        + ", exact in the mass and centre of mass (a rigid body)"
    )
    return PayloadLFT((m0, mr), (c0, R), base, phi0, phi1, phi2, B, C, D, parameter, covers)
