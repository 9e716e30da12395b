"""The inertia matrix on its ``L D Lᵀ`` factors: a model of ``M(q)`` that is positive definite in every member.

The robot's ``M(q)`` is symmetric positive definite at every configuration,
and so is its inverse, the input matrix ``B_low``.  A model that moves
``M`` (or ``M⁻¹``) affinely in box parameters loses that: on the URDF arms
the corners of a box around the cloud of ``M(q)`` are indefinite (a box on
the 13 principal directions of ur5's ``vech M(q)``: 73 % of its corners; on
panda's 27: all of them, docs/uncertainty.md).  Written on the factors of
``M = L D Lᵀ`` (``L`` unit lower triangular, ``D`` diagonal)::

    L = I + Σ_{i>j} l_ij e_i e_jᵀ,   l_ij ∈ [l_lo, l_hi]
    D = diag(d_1, ..., d_m),          d_i ∈ [d_lo, d_hi],  d_lo > 0

every member is ``L D Lᵀ`` with ``L`` invertible and ``D > 0``: positive
definite, whatever the parameters, and no vertex check is needed.  The
ranges are the extremes of the factors of the robot's ``M(q)`` over the
domain's positions (sampled, then refined by local search from the best
samples, then checked on fresh samples).

``M(δ)`` is an LFT in the normalised parameters: each ``l_ij`` enters ``L``
and ``Lᵀ`` (a repeated real ``[-2, 0]``), each ``d_i`` once.  Its inverse
``M(δ)⁻¹ = L⁻ᵀ D⁻¹ L⁻¹`` is then an exact LFT of the same parameters
(:func:`inverse_channels`).

Examples
--------
>>> import numpy as np, polyrob
>>> from polyrob.plant.models.inertia_factors import factor_ranges
>>> robot = polyrob.load_robot("planar_2r")
>>> f = factor_ranges(robot, polyrob.Domain.from_robot(robot), samples=256)
>>> f.names
('l21', 'd1', 'd2')
>>> bool(f.d_lower.min() > 0), bool(np.linalg.eigvalsh(f.matrix(-np.ones(3))).min() > 0)
(True, True)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import optimize

from polyrob._threads import single_blas_thread
from polyrob.errors import NotApplicable

__all__ = ["InertiaFactors", "ldl", "factor_ranges", "inverse_channels"]

#: A factor whose range is below this fraction of its size is constant (no parameter).
CONSTANT_RTOL = 1e-9


def ldl(M) -> tuple[np.ndarray, np.ndarray]:
    """``L`` (n, m, m) unit lower triangular and ``D`` (n, m) with ``M = L diag(D) Lᵀ``.

    Raises ``numpy.linalg.LinAlgError`` when a matrix is not positive definite.

    >>> L, D = ldl(np.array([[4.0, 2.0], [2.0, 5.0]]))
    >>> L[0].tolist(), D[0].tolist()
    ([[1.0, 0.0], [0.5, 1.0]], [4.0, 4.0])
    """
    M = np.asarray(M, float)
    if M.ndim == 2:
        M = M[None]
    C = np.linalg.cholesky(0.5 * (M + np.swapaxes(M, 1, 2)))
    d = np.diagonal(C, axis1=1, axis2=2)
    return C / d[:, None, :], d**2


@dataclass(frozen=True)
class InertiaFactors:
    """Ranges of the ``L D Lᵀ`` factors of ``M(q)`` (module docstring).

    Attributes
    ----------
    l_lower, l_upper : ndarray (m, m)
        Ranges of the entries of ``L`` (1 on the diagonal, 0 above it).
    d_lower, d_upper : ndarray (m,)
        Ranges of ``D`` (``d_lower > 0``).
    index : tuple of (int, int)
        The varying factors, in parameter order: ``(i, j)`` with ``i > j`` for
        ``l_ij``, ``(i, i)`` for ``d_i`` (0-based); constant ones have none.
    """

    l_lower: np.ndarray
    l_upper: np.ndarray
    d_lower: np.ndarray
    d_upper: np.ndarray
    index: tuple[tuple[int, int], ...]

    @property
    def m(self) -> int:
        return len(self.d_lower)

    @property
    def names(self) -> tuple[str, ...]:
        """``l21``, ..., ``d1``, ... (1-based), one per parameter."""
        return tuple(f"{'d' if i == j else 'l'}{i + 1}{'' if i == j else j + 1}" for i, j in self.index)

    @property
    def lower(self) -> np.ndarray:
        """Lower end of each parameter's range."""
        return np.array([self.d_lower[i] if i == j else self.l_lower[i, j] for i, j in self.index])

    @property
    def upper(self) -> np.ndarray:
        return np.array([self.d_upper[i] if i == j else self.l_upper[i, j] for i, j in self.index])

    def centre(self) -> tuple[np.ndarray, np.ndarray]:
        """``(L_c, D_c)``: the factors at the middle of every range."""
        return 0.5 * (self.l_lower + self.l_upper), 0.5 * (self.d_lower + self.d_upper)

    def factors(self, delta) -> tuple[np.ndarray, np.ndarray]:
        """``(L, D)`` at normalised parameters ``δ ∈ [-1, 1]`` (one per :attr:`index`)."""
        L, D = self.centre()
        L, D = L.copy(), D.copy()
        half = 0.5 * (self.upper - self.lower)
        for (i, j), d, r in zip(self.index, np.asarray(delta, float), half):
            if i == j:
                D[i] += r * d
            else:
                L[i, j] += r * d
        return L, D

    def matrix(self, delta) -> np.ndarray:
        """``M(δ) = L D Lᵀ``."""
        L, D = self.factors(delta)
        return (L * D) @ L.T

    def scaled(self, factor: float) -> InertiaFactors:
        """The same factors with every range scaled by ``factor`` about its middle (the shrink test)."""
        lc, dc = self.centre()
        return InertiaFactors(
            lc - factor * 0.5 * (self.l_upper - self.l_lower),
            lc + factor * 0.5 * (self.l_upper - self.l_lower),
            dc - factor * 0.5 * (self.d_upper - self.d_lower),
            dc + factor * 0.5 * (self.d_upper - self.d_lower),
            self.index,
        )

    def locate(self, M, *, rtol: float = 1e-9) -> tuple[np.ndarray, np.ndarray]:
        """``(inside, δ)`` of inertia matrices ``M`` (n, m, m): whether each is a member, and its parameters.

        A member is symmetric positive definite, its constant factors equal
        the model's, and its varying factors lie in their ranges (up to
        ``rtol`` of their size).
        """
        M = np.asarray(M, float)
        if M.ndim == 2:
            M = M[None]
        n, m = len(M), self.m
        scale = np.abs(M).max(axis=(1, 2))
        ok = np.abs(M - np.swapaxes(M, 1, 2)).max(axis=(1, 2)) <= 1e-9 * scale
        if n:
            ok &= np.linalg.eigvalsh(0.5 * (M + np.swapaxes(M, 1, 2)))[:, 0] > 0
        L = np.repeat(np.eye(m)[None], n, axis=0)
        D = np.ones((n, m))
        if ok.any():
            L[ok], D[ok] = ldl(M[ok])
        lo = np.concatenate([self.l_lower[None], self.d_lower[None, :, None] * np.eye(m)], axis=0)
        hi = np.concatenate([self.l_upper[None], self.d_upper[None, :, None] * np.eye(m)], axis=0)
        vals = np.concatenate([L[:, None], (D[:, :, None] * np.eye(m))[:, None]], axis=1)  # (n, 2, m, m)
        tol = rtol * (1.0 + np.maximum(np.abs(lo), np.abs(hi)))
        low = np.tril(np.ones((m, m), bool), -1)
        mask = np.stack([low, np.eye(m, dtype=bool)])
        ok &= np.all(((vals >= lo - tol) & (vals <= hi + tol))[:, mask], axis=1)
        mid, rad = 0.5 * (self.lower + self.upper), 0.5 * (self.upper - self.lower)
        picked = np.array([vals[:, 1, i, i] if i == j else vals[:, 0, i, j] for i, j in self.index]).reshape(-1, n).T
        with np.errstate(divide="ignore", invalid="ignore"):
            delta = np.where(rad > 0, (picked - mid) / np.where(rad > 0, rad, 1.0), 0.0)
        return ok, delta


def _entries(M):
    """The factors of ``M`` (n, m, m) as rows ``[l (strict lower, row-major), d]``."""
    L, D = ldl(M)
    m = L.shape[1]
    il = np.tril_indices(m, -1)
    return np.hstack([L[:, il[0], il[1]], D])


def factor_ranges(
    robot, domain, *, samples: int = 2000, starts: int = 2, verify: int = 2000, seed: int = 0
) -> InertiaFactors:
    """The ranges of the ``L D Lᵀ`` factors of ``robot.mass_matrix`` over ``domain``'s positions.

    ``samples`` uniform positions; each factor's minimum and maximum is then
    refined by bounded local search (L-BFGS-B) from the ``starts`` best
    samples; ``verify`` fresh positions (another seed) must not beat the
    refined ranges, else their best is refined too (two rounds).

    Raises
    ------
    NotApplicable
        A sampled ``M(q)`` is not positive definite.
    """
    with single_blas_thread():  # many tiny problems: a threaded BLAS only spin-waits (10x slower)
        return _factor_ranges(robot, domain, samples, starts, verify, seed)


def _factor_ranges(robot, domain, samples, starts, verify, seed) -> InertiaFactors:
    m = robot.m
    lo_q, hi_q = np.asarray(domain.q_lower, float), np.asarray(domain.q_upper, float)
    free = hi_q > lo_q
    rng = np.random.default_rng(seed)

    def at(q):
        return np.array([robot.mass_matrix(x) for x in np.atleast_2d(q)])

    def draw(n):
        return lo_q + rng.random((n, m)) * (hi_q - lo_q)

    def values(q):
        try:
            return _entries(at(q))
        except np.linalg.LinAlgError:
            raise NotApplicable(f"{robot.name}: M(q) is not positive definite at a sampled configuration") from None

    q = draw(int(samples))
    vals = values(q)
    n_f = vals.shape[1]
    best_q = np.zeros((2, n_f, m))
    best = np.vstack([vals.min(axis=0), vals.max(axis=0)])

    def refine(k, sign, q_starts):
        for q0 in q_starts:

            def f(z, k=k, sign=sign, q0=q0):
                x = q0.copy()
                x[free] = z
                try:
                    return sign * _entries(at(x))[0, k]
                except np.linalg.LinAlgError:
                    return np.inf

            res = optimize.minimize(f, q0[free], method="L-BFGS-B", bounds=list(zip(lo_q[free], hi_q[free])))
            side = 0 if sign > 0 else 1
            val = sign * res.fun
            if (side == 0 and val < best[0, k]) or (side == 1 and val > best[1, k]):
                best[side, k] = val
                x = q0.copy()
                x[free] = res.x
                best_q[side, k] = x

    for k in range(n_f):
        order = np.argsort(vals[:, k])
        refine(k, 1.0, q[order[: int(starts)]])
        refine(k, -1.0, q[order[::-1][: int(starts)]])
    for _ in range(2 if verify else 0):
        qv = draw(int(verify))
        vv = values(qv)
        beaten = False
        for k in range(n_f):
            if vv[:, k].min() < best[0, k]:
                refine(k, 1.0, qv[[np.argmin(vv[:, k])]])
                beaten = True
            if vv[:, k].max() > best[1, k]:
                refine(k, -1.0, qv[[np.argmax(vv[:, k])]])
                beaten = True
        if not beaten:
            break
    il = np.tril_indices(m, -1)
    n_l = len(il[0])
    scale = np.maximum(np.abs(best).max(axis=0), 1e-300)
    varying = best[1] - best[0] > CONSTANT_RTOL * scale
    l_lo, l_hi = np.eye(m), np.eye(m)
    l_lo[il], l_hi[il] = best[0, :n_l], best[1, :n_l]
    d_lo, d_hi = best[0, n_l:].copy(), best[1, n_l:].copy()
    if d_lo.min() <= 0:
        raise NotApplicable(f"{robot.name}: a pivot of M(q) = L D L^T reaches {d_lo.min():.3g} <= 0 on the domain")
    index = [(int(i), int(j)) for i, j, v in zip(*il, varying[:n_l]) if v]
    index += [(i, i) for i in range(m) if varying[n_l + i]]
    # a constant factor: its sampled mean, exactly
    for i, j in zip(*il):
        if (i, j) not in index:
            l_lo[i, j] = l_hi[i, j] = vals[:, list(zip(*il)).index((i, j))].mean()
    for i in range(m):
        if (i, i) not in index:
            d_lo[i] = d_hi[i] = vals[:, n_l + i].mean()
    return InertiaFactors(l_lo, l_hi, d_lo, d_hi, tuple(index))


def inverse_channels(factors: InertiaFactors):
    """The LFT of ``M(δ)`` and of its inverse, channels grouped by parameter.

    ``z = M(δ) y`` is ``z = M_c y + B1 d``, ``v = C1 y + D11 d``, ``d = diag(δ) v``
    (each ``l_ij`` on two channels, each ``d_i`` on one, the channels of a
    parameter adjacent).  Its inverse ``y = M(δ)⁻¹ w`` is
    ``y = M_c⁻¹ (w - B1 d)``, ``v = C1 M_c⁻¹ w + (D11 - C1 M_c⁻¹ B1) d``.

    Returns
    -------
    M_c, B1, C1, D11 : ndarray
    channel_parameter : ndarray of int
        Parameter (index into ``factors.index``) of each channel.
    """
    m = factors.m
    L_c, D_c = factors.centre()
    half = 0.5 * (factors.upper - factors.lower)
    ent = [(p, i, j) for p, (i, j) in enumerate(factors.index) if i != j]
    dia = [(p, i) for p, (i, j) in enumerate(factors.index) if i == j]
    K, J = len(ent), len(dia)
    # a = L_cᵀ y + P1 d1 (v1 = Q1 y); b = D_c a + R2 d2 (v2 = a); z = L_c b + P3 d3 (v3 = Q3 b)
    P1, Q1, P3, Q3 = np.zeros((m, K)), np.zeros((K, m)), np.zeros((m, K)), np.zeros((K, m))
    for k, (p, i, j) in enumerate(ent):
        P1[j, k], Q1[k, i] = half[p], 1.0
        P3[i, k], Q3[k, j] = half[p], 1.0
    R2, S2 = np.zeros((m, J)), np.zeros((J, m))
    for k, (p, i) in enumerate(dia):
        R2[i, k], S2[k, i] = half[p], 1.0
    Dm = np.diag(D_c)
    M_c = L_c @ Dm @ L_c.T
    B1 = np.hstack([L_c @ Dm @ P1, L_c @ R2, P3])
    C1 = np.vstack([Q1, S2 @ L_c.T, Q3 @ Dm @ L_c.T])
    D11 = np.zeros((2 * K + J, 2 * K + J))
    D11[K : K + J, :K] = S2 @ P1
    D11[K + J :, :K] = Q3 @ Dm @ P1
    D11[K + J :, K : K + J] = Q3 @ R2
    param = np.r_[[p for p, _, _ in ent], [p for p, _ in dia], [p for p, _, _ in ent]].astype(int)
    order = np.argsort(param, kind="stable")
    B1, C1, D11 = B1[:, order], C1[order], D11[np.ix_(order, order)]
    return M_c, B1, C1, D11, param[order]
