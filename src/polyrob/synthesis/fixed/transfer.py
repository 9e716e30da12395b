"""Per-entry transfer functions of order N (``"tfN"``), stable for every θ."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from polyrob.synthesis.fixed.base import OrderedStructure, as_lti, as_theta, siso_tf

__all__ = ["TransferFunctionStructure", "hurwitz_factors", "tf_string"]


def hurwitz_factors(den: np.ndarray) -> tuple[np.ndarray, list[tuple[float, float]]]:
    """Split a monic polynomial into ``(s + a)`` and ``(s² + b s + c)`` factors.

    Roots in the closed right half plane are mirrored to the left (the
    parametrisation only represents stable entries); returns the linear-factor
    roots ``a`` and the quadratic pairs ``(b, c)``.
    """
    r = np.roots(den) if len(den) > 1 else np.zeros(0, complex)
    r = np.where(r.real >= 0, -np.abs(r.real) - 1e-9 * (1 + np.abs(r)) + 1j * r.imag, r)
    cplx = sorted([z for z in r if z.imag > 1e-12 * max(1.0, abs(z))], key=lambda z: abs(z))
    real = sorted([z.real for z in r if abs(z.imag) <= 1e-12 * max(1.0, abs(z))], key=abs)
    quads = [(-2.0 * z.real, abs(z) ** 2) for z in cplx]
    lin = []
    if len(real) % 2:  # odd: the slowest real root is the first-order factor
        lin.append(-real.pop(0))
    for p, q in zip(real[0::2], real[1::2]):
        quads.append((-(p + q), p * q))
    return np.array(lin, float), quads


@dataclass(frozen=True)
class TransferFunctionStructure(OrderedStructure):
    """Each ``K_ij`` a stable proper transfer function of order ``N`` (``"tfN"``).

    Parameters of entry ``(i, j)`` (row-major, ``2N + 1`` each): first the
    denominator, ``log a`` of the first-order factor (``N`` odd) then
    ``(log b, log c)`` of each quadratic factor, then the numerator
    coefficients ``n_0, ..., n_N`` in ascending powers of ``s``::

        K_ij(s) = (n_N s^N + ... + n_0) / ((s + a) (s² + b₁ s + c₁) ...)

    Examples
    --------
    >>> import numpy as np, control
    >>> from polyrob.synthesis.fixed.structures import TransferFunctionStructure
    >>> s = TransferFunctionStructure(1, 1, 2)
    >>> th = s.from_controller(control.tf([3.0, 1.0], [1.0, 3.0, 2.0]))
    >>> d = s.describe(th)
    >>> np.round(d["den"][0][0], 6).tolist(), np.round(d["num"][0][0], 6).tolist()
    ([1.0, 3.0, 2.0], [0.0, 3.0, 1.0])
    """

    prefix = "tf"
    N: int = 3

    @property
    def per_entry(self) -> int:
        return 2 * self.N + 1

    @property
    def n_params(self) -> int:
        return self.n_u * self.n_y * self.per_entry

    @property
    def order(self) -> int:
        return self.n_u * self.n_y * self.N

    @property
    def n_linear(self) -> int:
        """Number of first-order factors (1 if ``N`` is odd)."""
        return self.N % 2

    def _entries(self, theta):
        th = as_theta(theta, self.n_params).reshape(self.n_u, self.n_y, self.per_entry)
        return th[..., : self.N], th[..., self.N :]

    def _den_poly(self, dpar: np.ndarray) -> np.ndarray:
        """Monic denominator (descending powers) of one entry."""
        p = np.ones(1)
        k = 0
        if self.n_linear:
            p = np.array([1.0, math.exp(dpar[0])])
            k = 1
        while k < self.N:
            p = np.convolve(p, [1.0, math.exp(dpar[k]), math.exp(dpar[k + 1])])
            k += 2
        return p

    def coefficients(self, theta) -> tuple[list, list]:
        """``(num, den)`` nested lists ``[i][j]`` in descending powers, den monic."""
        dens, nums = self._entries(theta)
        num = [[nums[i, j][::-1].copy() for j in range(self.n_y)] for i in range(self.n_u)]
        den = [[self._den_poly(dens[i, j]) for j in range(self.n_y)] for i in range(self.n_u)]
        return num, den

    def realization(self, theta):
        num, den = self.coefficients(theta)
        n, N = self.order, self.N
        A, B, C = np.zeros((n, n)), np.zeros((n, self.n_y)), np.zeros((self.n_u, n))
        D = np.zeros((self.n_u, self.n_y))
        k = 0
        for i in range(self.n_u):
            for j in range(self.n_y):
                b, a = num[i][j], den[i][j]
                D[i, j] = b[0]
                if N == 0:
                    continue
                r = (b - b[0] * a)[1:]  # strictly proper remainder, descending, length N
                sl = slice(k, k + N)
                # controllable companion form: x' = A x + e_N e_j, u_i += r x
                Ac = np.zeros((N, N))
                Ac[:-1, 1:] = np.eye(N - 1)
                Ac[-1, :] = -a[1:][::-1]
                A[sl, sl] = Ac
                B[k + N - 1, j] = 1.0
                C[i, sl] = r[::-1]
                k += N
        return A, B, C, D

    def freqresp(self, theta, omega, *, jac: bool = False):
        s = 1j * np.asarray(omega, dtype=float).ravel()
        dens, nums = self._entries(theta)
        nw, N, pe = s.size, self.N, self.per_entry
        K = np.zeros((nw, self.n_u, self.n_y), complex)
        dK = np.zeros((nw, self.n_params, self.n_u, self.n_y), complex) if jac else None
        powers = s[:, None] ** np.arange(N + 1)[None, :]  # (nw, N+1)
        for i in range(self.n_u):
            for j in range(self.n_y):
                dpar, npar = dens[i, j], nums[i, j]
                factors, dfac = [], []  # each factor's value and d(value)/d(its log-params)
                k = 0
                if self.n_linear:
                    a = math.exp(dpar[0])
                    factors.append(s + a)
                    dfac.append([a * np.ones_like(s)])
                    k = 1
                while k < N:
                    b, c = math.exp(dpar[k]), math.exp(dpar[k + 1])
                    factors.append(s * s + b * s + c)
                    dfac.append([b * s, c * np.ones_like(s)])
                    k += 2
                den = np.prod(factors, axis=0) if factors else np.ones_like(s)
                num = powers @ npar
                Kij = num / den
                K[:, i, j] = Kij
                if jac:
                    base = (i * self.n_y + j) * pe
                    p = base
                    for f, dl in zip(factors, dfac):
                        for dv in dl:  # ∂K/∂log(coef) = -K (∂f/∂log coef) / f
                            dK[:, p, i, j] = -Kij * dv / f
                            p += 1
                    dK[:, base + N : base + pe, i, j] = powers / den[:, None]
        return (K, dK) if jac else K

    def from_controller(self, K) -> np.ndarray:
        K = as_lti(K, self.n_u, self.n_y)
        th = np.zeros((self.n_u, self.n_y, self.per_entry))
        for i in range(self.n_u):
            for j in range(self.n_y):
                num, den = siso_tf(K[i, j], self.N)
                lin, quads = hurwitz_factors(den)
                dp = [math.log(a) for a in lin] + [math.log(v) for bc in quads for v in bc]
                th[i, j, : self.N] = dp
                th[i, j, self.N :] = np.pad(num[::-1], (0, self.N + 1 - num.size))
        return th.ravel()

    def random(self, rng):
        th = np.zeros((self.n_u, self.n_y, self.per_entry))
        # poles log-uniform over 1e-1 .. 1e2 rad/s, unit-size numerators
        th[..., : self.N] = rng.uniform(math.log(0.1), math.log(100.0), (self.n_u, self.n_y, self.N))
        th[..., self.N :] = rng.standard_normal((self.n_u, self.n_y, self.N + 1))
        return th.ravel()

    def scale(self, theta) -> np.ndarray:
        dens, nums = self._entries(theta)
        sc = np.ones((self.n_u, self.n_y, self.per_entry))
        k = np.arange(self.N + 1)
        for i in range(self.n_u):
            for j in range(self.n_y):
                den = self._den_poly(dens[i, j])
                # rho: geometric mean of the pole magnitudes, so that n_k rho^k
                # compares coefficients of different powers on one footing
                rho = abs(den[-1]) ** (1.0 / self.N) if self.N else 1.0
                rho = min(max(rho, 1e-6), 1e6)
                mag = np.abs(nums[i, j]) * rho**k
                ref = max(mag.max(), 1e-12)
                sc[i, j, self.N :] = np.maximum(mag, 0.05 * ref) / rho**k
        return sc.ravel()

    def describe(self, theta) -> dict:
        num, den = self.coefficients(theta)
        out = {
            "theta": as_theta(theta, self.n_params).tolist(),
            "num": [[v.tolist() for v in row] for row in num],
            "den": [[v.tolist() for v in row] for row in den],
            "poles": [[np.roots(d).tolist() if len(d) > 1 else [] for d in row] for row in den],
        }
        out["K_ij"] = [[tf_string(n, d) for n, d in zip(rn, rd)] for rn, rd in zip(num, den)]
        # the paper prints K* with the denominator's constant term scaled to 1
        out["num_paper_form"] = [[(n / d[-1]).tolist() for n, d in zip(rn, rd)] for rn, rd in zip(num, den)]
        out["den_paper_form"] = [[(d / d[-1]).tolist() for d in rd] for rd in den]
        return out


def tf_string(num, den) -> str:
    def poly(p):
        n = len(p) - 1
        terms = []
        for k, c in enumerate(p):
            if c == 0 and len(p) > 1:
                continue
            e = n - k
            sym = "" if e == 0 else ("s" if e == 1 else f"s^{e}")
            terms.append(f"{c:.6g}" + (f" {sym}" if sym else ""))
        return " + ".join(terms).replace("+ -", "- ") if terms else "0"

    return f"({poly(num)}) / ({poly(den)})"
