"""Controller parametrisations for fixed-structure μ-synthesis.

A :class:`ControllerStructure` maps a real parameter vector ``θ`` to a
controller ``K(θ)`` (``n_u x n_y``, ``u = K y``) and gives what the
optimiser of :mod:`polyrob.synthesis.fixed` needs from it:

* :meth:`~ControllerStructure.controller` — ``K(θ)`` as a ``control.StateSpace``;
* :meth:`~ControllerStructure.realization` — its ``(A, B, C, D)`` as arrays
  (the closed-loop stability test runs on every trial point: no python-control
  objects there);
* :meth:`~ControllerStructure.freqresp` — ``K(jω; θ)`` and, analytically,
  ``∂K(jω; θ)/∂θ`` (the K-step differentiates the μ majorant through it);
* :meth:`~ControllerStructure.initial` — a starting ``θ``, fitted to a given
  controller or random;
* :meth:`~ControllerStructure.scale` — typical magnitudes of the parameters,
  so the optimiser works in well-conditioned units.

Three kinds, chosen by a string (:func:`controller_structure`):

``"tfN"`` (:class:`TransferFunctionStructure`)
    every ``K_ij`` a proper transfer function of order ``N``: numerator of
    degree ``≤ N`` (``N + 1`` free coefficients), monic denominator written as
    a product of stable factors ``(s + a)`` and ``(s² + b s + c)`` with
    ``a = e^{θ}``, ``b = e^{θ}``, ``c = e^{θ}``.  Every monic Hurwitz
    polynomial has exactly this form (a quadratic factor holds a complex pair
    or two real roots), so the parametrisation covers all stable ``K_ij`` of
    order ``N`` and nothing else.  The paper's ``K*`` is a ``"tf3"``.
``"pid"`` (:class:`PIDStructure`)
    a decentralised PIDF per channel, ``u_i = (Kp + Ki/s + Kd s/(τ s + 1)) e_i``,
    ``τ = e^{θ} > 0``.  ``Ki/s`` puts a controller pole at ``s = 0``: only
    the closed loop has to be stable, which the synthesis checks.
``"ss:N"`` (:class:`StateSpaceStructure`)
    a state-space controller of order ``N`` with free ``A, B, C, D``.

Examples
--------
>>> import numpy as np
>>> from polyrob.synthesis.structures import controller_structure
>>> s = controller_structure("tf3", n_u=2, n_y=2)
>>> s.n_params, s.order
(28, 12)
>>> K = s.controller(s.initial(0))
>>> K.nstates, K.ninputs, K.noutputs
(12, 2, 2)
>>> controller_structure("pid", 2, 2).n_params
8
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import control
import numpy as np
from scipy.optimize import minimize_scalar

from polyrob.errors import PolyrobError

__all__ = [
    "ControllerStructure",
    "TransferFunctionStructure",
    "PIDStructure",
    "StateSpaceStructure",
    "controller_structure",
    "VALID_STRUCTURES",
]

#: The structure strings :func:`controller_structure` understands.
VALID_STRUCTURES = ('"tfN" (e.g. "tf3": each K_ij of order N)', '"pid"', '"ss:N" (e.g. "ss:4")')


def _as_theta(theta, n: int) -> np.ndarray:
    th = np.asarray(theta, dtype=float).ravel()
    if th.size != n:
        raise PolyrobError(f"θ has {th.size} entries; this structure has {n} parameters")
    if not np.all(np.isfinite(th)):
        raise PolyrobError("θ has non-finite entries")
    return th


def _labels(n_u: int, n_y: int) -> dict:
    return {"inputs": [f"e[{j}]" for j in range(n_y)], "outputs": [f"u[{i}]" for i in range(n_u)]}


@dataclass(frozen=True)
class ControllerStructure:
    """Base class of the parametrisations (a strategy object, one per kind).

    Attributes
    ----------
    n_u, n_y : int
        Number of controls (outputs of ``K``) and measurements (its inputs).
    """

    n_u: int
    n_y: int

    # ---------------------------------------------------------------- contract
    @property
    def name(self) -> str:  # pragma: no cover - abstract
        raise NotImplementedError

    @property
    def n_params(self) -> int:  # pragma: no cover - abstract
        raise NotImplementedError

    @property
    def order(self) -> int:  # pragma: no cover - abstract
        """Number of states of :meth:`controller`."""
        raise NotImplementedError

    def realization(self, theta) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover
        """``(A, B, C, D)`` of ``K(θ)`` as plain arrays."""
        raise NotImplementedError

    def freqresp(self, theta, omega, *, jac: bool = False):  # pragma: no cover - abstract
        """``K(jω)`` as ``(N, n_u, n_y)``; with ``jac`` also ``∂K/∂θ`` as ``(N, n_params, n_u, n_y)``."""
        raise NotImplementedError

    def from_controller(self, K) -> np.ndarray:  # pragma: no cover - abstract
        """``θ`` of (an approximation of) a given controller."""
        raise NotImplementedError

    def random(self, rng: np.random.Generator) -> np.ndarray:  # pragma: no cover - abstract
        """A random ``θ`` (no knowledge of the plant: not necessarily stabilising)."""
        raise NotImplementedError

    def scale(self, theta) -> np.ndarray:  # pragma: no cover - abstract
        """Typical magnitude of each parameter around ``θ`` (1 for log-parameters)."""
        raise NotImplementedError

    def describe(self, theta) -> dict:
        """Human-readable parameters (JSON-able)."""
        return {"theta": _as_theta(theta, self.n_params).tolist()}

    # ---------------------------------------------------------------- shared
    def controller(self, theta) -> control.StateSpace:
        """``K(θ)`` as a continuous-time ``control.StateSpace`` (``u = K e``)."""
        A, B, C, D = self.realization(theta)
        return control.ss(A, B, C, D, dt=0, name=f"K[{self.name}]", **_labels(self.n_u, self.n_y))

    def initial(self, source=0, *, around=None, spread: float = 0.5) -> np.ndarray:
        """A starting point.

        Parameters
        ----------
        source : int or LTI system
            A controller to fit (:meth:`from_controller`), or a random seed.
        around : array_like, optional
            With a seed: perturb this ``θ`` by ``spread`` times :meth:`scale`
            (random multi-starts around a known good point, as HIFOO does);
            without it, draw a plant-agnostic :meth:`random` point.
        spread : float
            Relative size of the perturbation.
        """
        if isinstance(source, (control.LTI, np.ndarray)) and not np.isscalar(source):
            return self.from_controller(source)
        if not isinstance(source, (int, np.integer)):
            raise PolyrobError(f"initial() takes a seed or an LTI controller, got {type(source).__name__}")
        rng = np.random.default_rng(int(source))
        if around is None:
            return self.random(rng)
        th = _as_theta(around, self.n_params)
        return th + spread * self.scale(th) * rng.standard_normal(th.size)


# =================================================================== tfN
def _hurwitz_factors(den: np.ndarray) -> tuple[np.ndarray, list[tuple[float, float]]]:
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
class TransferFunctionStructure(ControllerStructure):
    """Each ``K_ij`` a stable proper transfer function of order ``N`` (``"tfN"``).

    Parameters of entry ``(i, j)`` (row-major, ``2N + 1`` each): first the
    denominator, ``log a`` of the first-order factor (``N`` odd) then
    ``(log b, log c)`` of each quadratic factor, then the numerator
    coefficients ``n_0, ..., n_N`` in ascending powers of ``s``::

        K_ij(s) = (n_N s^N + ... + n_0) / ((s + a) (s² + b₁ s + c₁) ...)

    Examples
    --------
    >>> import numpy as np, control
    >>> from polyrob.synthesis.structures import TransferFunctionStructure
    >>> s = TransferFunctionStructure(1, 1, 2)
    >>> th = s.from_controller(control.tf([3.0, 1.0], [1.0, 3.0, 2.0]))
    >>> d = s.describe(th)
    >>> np.round(d["den"][0][0], 6).tolist(), np.round(d["num"][0][0], 6).tolist()
    ([1.0, 3.0, 2.0], [0.0, 3.0, 1.0])
    """

    N: int = 3

    def __post_init__(self):
        if self.N < 0:
            raise PolyrobError(f"tfN needs N >= 0, got {self.N}")

    @property
    def name(self) -> str:
        return f"tf{self.N}"

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
        th = _as_theta(theta, self.n_params).reshape(self.n_u, self.n_y, self.per_entry)
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
        K = _as_lti(K, self.n_u, self.n_y)
        th = np.zeros((self.n_u, self.n_y, self.per_entry))
        for i in range(self.n_u):
            for j in range(self.n_y):
                num, den = _siso_tf(K[i, j], self.N)
                lin, quads = _hurwitz_factors(den)
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
                mag = np.abs(nums[i, j]) * rho ** k
                ref = max(mag.max(), 1e-12)
                sc[i, j, self.N :] = np.maximum(mag, 0.05 * ref) / rho ** k
        return sc.ravel()

    def describe(self, theta) -> dict:
        num, den = self.coefficients(theta)
        out = {
            "theta": _as_theta(theta, self.n_params).tolist(),
            "num": [[v.tolist() for v in row] for row in num],
            "den": [[v.tolist() for v in row] for row in den],
            "poles": [[np.roots(d).tolist() if len(d) > 1 else [] for d in row] for row in den],
        }
        out["K_ij"] = [[_tf_string(n, d) for n, d in zip(rn, rd)] for rn, rd in zip(num, den)]
        # the paper prints K* with the denominator's constant term scaled to 1
        out["num_paper_form"] = [[(n / d[-1]).tolist() for n, d in zip(rn, rd)] for rn, rd in zip(num, den)]
        out["den_paper_form"] = [[(d / d[-1]).tolist() for d in rd] for rd in den]
        return out


def _tf_string(num, den) -> str:
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


def _as_lti(K, n_u, n_y):
    if isinstance(K, np.ndarray) or np.isscalar(K):
        Dk = np.atleast_2d(np.asarray(K, float))
        K = control.ss(np.zeros((0, 0)), np.zeros((0, Dk.shape[1])), np.zeros((Dk.shape[0], 0)), Dk)
    if not isinstance(K, control.LTI):
        raise PolyrobError(f"a controller must be a python-control LTI system, got {type(K).__name__}")
    if (K.noutputs, K.ninputs) != (n_u, n_y):
        raise PolyrobError(f"the controller is {K.noutputs}x{K.ninputs}; the structure needs {n_u}x{n_y}")
    if K.dt not in (0, None):
        raise PolyrobError("the controller must be continuous-time")
    return K


def _siso_tf(Kij, N: int) -> tuple[np.ndarray, np.ndarray]:
    """Monic ``(num, den)`` of a SISO entry with ``deg den == N``.

    Lower orders are padded with a cancelling factor (exact); higher orders
    are reduced by balanced truncation (approximate).
    """
    if isinstance(Kij, control.TransferFunction):
        num = np.trim_zeros(np.asarray(Kij.num[0][0], float), "f")
        den = np.trim_zeros(np.asarray(Kij.den[0][0], float), "f")
        g = control.ss(Kij) if len(den) > 1 else None
    else:
        g = control.ss(Kij)
        g = control.minreal(g, verbose=False) if g.nstates else g
        t = control.tf(g)
        num = np.trim_zeros(np.asarray(t.num[0][0], float), "f")
        den = np.trim_zeros(np.asarray(t.den[0][0], float), "f")
    if num.size == 0:
        num = np.zeros(1)
    if len(den) - 1 > N:
        g = control.ss(control.tf(num, den)) if g is None else g
        try:
            g = control.minreal(g, verbose=False)
            if g.nstates > N:
                g = control.balred(g, N, method="matchdc")
        except Exception as exc:  # noqa: BLE001 - SLICOT reduction failures
            raise PolyrobError(f"cannot reduce a controller entry of order {g.nstates} to order {N}: {exc}") from None
        t = control.tf(g)
        num = np.trim_zeros(np.asarray(t.num[0][0], float), "f")
        den = np.trim_zeros(np.asarray(t.den[0][0], float), "f")
        if num.size == 0:
            num = np.zeros(1)
    num, den = num / den[0], den / den[0]
    if len(num) > len(den):
        raise PolyrobError("an improper controller entry cannot be fitted")
    # pad with a cancelling pole/zero near the existing dynamics (exact)
    roots = np.roots(den) if len(den) > 1 else np.zeros(0)
    p = float(np.exp(np.mean(np.log(np.abs(roots) + 1e-12)))) if roots.size else 1.0
    while len(den) - 1 < N:
        den, num = np.polymul(den, [1.0, p]), np.polymul(num, [1.0, p])
    return np.trim_zeros(num, "f") if np.any(num) else np.zeros(1), den


# =================================================================== pid
@dataclass(frozen=True)
class PIDStructure(ControllerStructure):
    """Decentralised PIDF controller (``"pid"``): ``u_i = (Kp + Ki/s + Kd s/(τ s + 1)) e_i``.

    Parameters per channel: ``Kp, Ki, Kd, log τ``.  The realisation per
    channel has an integrator state ``x₁' = e`` and a filter state
    ``x₂' = (e - x₂)/τ``: ``u = Kp e + Ki x₁ + (Kd/τ)(e - x₂)``.

    Examples
    --------
    >>> import numpy as np
    >>> from polyrob.synthesis.structures import PIDStructure
    >>> s = PIDStructure(1, 1)
    >>> th = np.array([2.0, 0.5, 0.1, np.log(0.01)])
    >>> K = s.freqresp(th, [1.0])[0, 0, 0]
    >>> bool(np.isclose(K, 2.0 + 0.5 / 1j + 0.1j / (0.01j + 1)))
    True
    """

    def __post_init__(self):
        if self.n_u != self.n_y:
            raise PolyrobError(f"a decentralised PID needs as many controls as measurements, got {self.n_u}x{self.n_y}")

    @property
    def name(self) -> str:
        return "pid"

    @property
    def n_params(self) -> int:
        return 4 * self.n_u

    @property
    def order(self) -> int:
        return 2 * self.n_u

    def gains(self, theta) -> np.ndarray:
        """``(n_u, 4)`` array of ``Kp, Ki, Kd, τ`` per channel."""
        g = _as_theta(theta, self.n_params).reshape(self.n_u, 4).copy()
        g[:, 3] = np.exp(g[:, 3])
        return g

    def realization(self, theta):
        g, m = self.gains(theta), self.n_u
        A, B, C, D = np.zeros((2 * m, 2 * m)), np.zeros((2 * m, m)), np.zeros((m, 2 * m)), np.zeros((m, m))
        for i, (kp, ki, kd, tau) in enumerate(g):
            A[2 * i + 1, 2 * i + 1] = -1.0 / tau
            B[2 * i, i], B[2 * i + 1, i] = 1.0, 1.0 / tau
            C[i, 2 * i], C[i, 2 * i + 1] = ki, -kd / tau
            D[i, i] = kp + kd / tau
        return A, B, C, D

    def freqresp(self, theta, omega, *, jac: bool = False):
        s = 1j * np.asarray(omega, dtype=float).ravel()
        g, m = self.gains(theta), self.n_u
        K = np.zeros((s.size, m, m), complex)
        dK = np.zeros((s.size, self.n_params, m, m), complex) if jac else None
        for i, (kp, ki, kd, tau) in enumerate(g):
            f = tau * s + 1.0
            K[:, i, i] = kp + ki / s + kd * s / f
            if jac:
                dK[:, 4 * i, i, i] = 1.0
                dK[:, 4 * i + 1, i, i] = 1.0 / s
                dK[:, 4 * i + 2, i, i] = s / f
                dK[:, 4 * i + 3, i, i] = -kd * s * (tau * s) / f**2
        return (K, dK) if jac else K

    def from_controller(self, K) -> np.ndarray:
        """Least-squares PIDF fit (relative error) of the diagonal of ``K``.

        The fit band lies between ten times the slowest and a third of the
        fastest pole of ``K`` (e.g. 0.05..30 rad/s for the paper's ``K*``):
        outside it a PIDF cannot follow a lag/lead controller anyway, and
        fitting there (flat DC gain, high-frequency roll-off) turned the
        derivative gain negative.
        """
        K = _as_lti(K, self.n_u, self.n_y)
        try:
            p = np.abs(control.ss(K).poles()) if control.ss(K).nstates else np.zeros(0)
        except Exception:  # noqa: BLE001
            p = np.zeros(0)
        p = p[p > 1e-9]
        lo, hi = (10.0 * p.min(), p.max() / 3.0) if p.size else (1e-2, 1e2)
        if not lo < hi / 10.0:
            lo, hi = (1e-2, 1e2) if not p.size else (p.min() / 10.0, 10.0 * p.max())
        w = np.logspace(np.log10(lo), np.log10(hi), 121)
        H = np.moveaxis(np.asarray(K(1j * w, squeeze=False)).reshape(self.n_u, self.n_y, -1), -1, 0)
        th = np.zeros((self.n_u, 4))
        s = 1j * w
        for i in range(self.n_u):
            h = H[:, i, i]
            wt = 1.0 / np.maximum(np.abs(h), 1e-12)  # relative error
            yr = np.concatenate([(h * wt).real, (h * wt).imag])

            def fit(log_tau):
                # Kp, Ki, Kd enter linearly: least squares for a given τ
                X = np.stack([np.ones_like(s), 1.0 / s, s / (math.exp(log_tau) * s + 1.0)], axis=1) * wt[:, None]
                Xr = np.vstack([X.real, X.imag])
                coef, *_ = np.linalg.lstsq(Xr, yr, rcond=None)
                return float(np.linalg.norm(Xr @ coef - yr)), coef

            grid = np.linspace(math.log(0.01 / hi), math.log(100.0 / lo), 61)
            k = int(np.argmin([fit(g)[0] for g in grid]))
            a, b = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
            res = minimize_scalar(lambda g: fit(g)[0], bounds=(a, b), method="bounded", options={"xatol": 1e-10})
            lt = float(res.x) if fit(res.x)[0] <= fit(grid[k])[0] else float(grid[k])
            th[i, :3], th[i, 3] = fit(lt)[1], lt
        return th.ravel()

    def random(self, rng):
        th = np.zeros((self.n_u, 4))
        th[:, :3] = np.abs(rng.standard_normal((self.n_u, 3)))
        th[:, 3] = rng.uniform(math.log(1e-3), math.log(1e-1), self.n_u)
        return th.ravel()

    def scale(self, theta) -> np.ndarray:
        g = _as_theta(theta, self.n_params).reshape(self.n_u, 4)
        sc = np.ones_like(g)
        gains = np.abs(g[:, :3])
        # a zero gain (e.g. Ki of a fitted static controller) still needs a
        # usable scale: floor by the other channels' and the channel's own gains
        own = 0.01 * np.maximum(gains.max(axis=1), 1e-9)
        for c in range(3):
            col = gains[:, c]
            sc[:, c] = np.maximum(np.maximum(col, 0.05 * col.max()), own)
        return sc.ravel()

    def describe(self, theta) -> dict:
        g = self.gains(theta)
        return {
            "theta": _as_theta(theta, self.n_params).tolist(),
            "Kp": g[:, 0].tolist(), "Ki": g[:, 1].tolist(), "Kd": g[:, 2].tolist(), "tau": g[:, 3].tolist(),
        }


# =================================================================== ss:N
@dataclass(frozen=True)
class StateSpaceStructure(ControllerStructure):
    """A state-space controller of order ``N`` with free ``A, B, C, D`` (``"ss:N"``).

    ``θ = [vec(A), vec(B), vec(C), vec(D)]`` (row-major).  Over-parametrised
    (any similarity transformation gives the same ``K``), which gradient
    methods tolerate.

    Examples
    --------
    >>> from polyrob.synthesis.structures import StateSpaceStructure
    >>> s = StateSpaceStructure(2, 2, 4)
    >>> s.n_params
    36
    """

    N: int = 4

    def __post_init__(self):
        if self.N < 0:
            raise PolyrobError(f"ss:N needs N >= 0, got {self.N}")

    @property
    def name(self) -> str:
        return f"ss:{self.N}"

    @property
    def n_params(self) -> int:
        N, m, p = self.N, self.n_u, self.n_y
        return N * N + N * p + m * N + m * p

    @property
    def order(self) -> int:
        return self.N

    def realization(self, theta):
        th = _as_theta(theta, self.n_params)
        N, m, p = self.N, self.n_u, self.n_y
        k = np.cumsum([0, N * N, N * p, m * N, m * p])
        return (th[k[0]:k[1]].reshape(N, N), th[k[1]:k[2]].reshape(N, p),
                th[k[2]:k[3]].reshape(m, N), th[k[3]:k[4]].reshape(m, p))

    def freqresp(self, theta, omega, *, jac: bool = False):
        s = 1j * np.asarray(omega, dtype=float).ravel()
        A, B, C, D = self.realization(theta)
        N, m, p = self.N, self.n_u, self.n_y
        if N == 0:
            K = np.broadcast_to(D, (s.size, m, p)).astype(complex)
            XB = CX = None
        else:
            Z = s[:, None, None] * np.eye(N) - A
            XB = np.linalg.solve(Z, np.broadcast_to(B, (s.size, N, p)))            # (sI-A)^-1 B
            CX = np.swapaxes(np.linalg.solve(np.swapaxes(Z, 1, 2), np.broadcast_to(C.T, (s.size, N, m))), 1, 2)
            K = C @ XB + D
        if not jac:
            return K
        dK = np.zeros((s.size, self.n_params, m, p), complex)
        q = 0
        if N:
            # ∂K/∂A_kl = (C X)[:, k] (X B)[l, :]
            dK[:, q:q + N * N] = (CX[:, :, :, None, None].transpose(0, 2, 3, 1, 4)
                                  * XB[:, None, :, None, :]).reshape(s.size, N * N, m, p)
            q += N * N
            # ∂K/∂B_kl = (C X)[:, k] e_l^T
            dK[:, q:q + N * p] = (CX.transpose(0, 2, 1)[:, :, None, :, None]
                                  * np.eye(p)[None, None, :, None, :]).reshape(s.size, N * p, m, p)
            q += N * p
            # ∂K/∂C_kl = e_k (X B)[l, :]
            dK[:, q:q + m * N] = (np.eye(m)[None, :, None, :, None]
                                  * XB[:, None, :, None, :]).reshape(s.size, m * N, m, p)
            q += m * N
        dK[:, q:] = np.eye(m * p).reshape(m * p, m, p)[None]
        return K, dK

    def from_controller(self, K) -> np.ndarray:
        K = _as_lti(K, self.n_u, self.n_y)
        Ks = control.ss(K)
        if Ks.nstates:
            Ks = control.minreal(Ks, verbose=False)
        if Ks.nstates > self.N:
            try:
                Ks = control.balred(Ks, self.N, method="matchdc")
            except Exception as exc:  # noqa: BLE001
                raise PolyrobError(f"cannot reduce the controller to order {self.N}: {exc}") from None
        A, B, C, D = (np.asarray(X, float) for X in (Ks.A, Ks.B, Ks.C, Ks.D))
        n = A.shape[0]
        if n:
            # diagonal similarity so that each state's input and output gains
            # are of one size: the optimiser's parameter scales then make sense
            bn = np.linalg.norm(B, axis=1)
            cn = np.linalg.norm(C, axis=0)
            t = np.where((bn > 0) & (cn > 0), np.sqrt(np.maximum(bn, 1e-300) / np.maximum(cn, 1e-300)), 1.0)
            A, B, C = A * t[None, :] / t[:, None], B / t[:, None], C * t[None, :]
        if n < self.N:
            # extra fast, weakly coupled states: exact up to ~1e-6 relative, but
            # not exactly decoupled (B = C = 0 would be a stationary point)
            extra = self.N - n
            fast = 10.0 * max(1.0, float(np.max(np.abs(np.linalg.eigvals(A))))) if n else 1.0
            rng = np.random.default_rng(0)
            A = np.block([[A, np.zeros((n, extra))], [np.zeros((extra, n)), -fast * np.eye(extra)]])
            eps = 1e-3 * max(np.max(np.abs(D)), np.max(np.abs(B)) if B.size else 0, np.max(np.abs(C)) if C.size else 0, 1e-6)
            B = np.vstack([B, eps * rng.standard_normal((extra, self.n_y))])
            C = np.hstack([C, eps * rng.standard_normal((self.n_u, extra))])
        return np.concatenate([A.ravel(), B.ravel(), C.ravel(), D.ravel()])

    def random(self, rng):
        N, m, p = self.N, self.n_u, self.n_y
        A = -np.eye(N) + 0.3 * rng.standard_normal((N, N))
        return np.concatenate([A.ravel(), rng.standard_normal(N * p + m * N + m * p)])

    def scale(self, theta) -> np.ndarray:
        A, B, C, D = self.realization(theta)
        out = []
        # A_kl couples states k and l: its natural size is the geometric mean
        # of their own rates (a fast filter state must not set the scale of
        # an integrator's entries)
        rate = np.maximum(np.abs(np.diag(A)), 1e-3 * max(np.max(np.abs(A)) if A.size else 0.0, 1e-9))
        out.append(np.maximum(np.abs(A), 0.1 * np.sqrt(np.outer(rate, rate))).ravel())
        for X in (B, C, D):
            mag = np.abs(X).ravel()
            out.append(np.maximum(mag, 0.1 * max(np.sqrt(np.mean(mag**2)) if mag.size else 0.0, 1e-12)))
        return np.concatenate(out)

    def describe(self, theta) -> dict:
        A, B, C, D = self.realization(theta)
        return {"theta": _as_theta(theta, self.n_params).tolist(), "A": A.tolist(), "B": B.tolist(),
                "C": C.tolist(), "D": D.tolist(), "poles": np.linalg.eigvals(A).tolist() if self.N else []}


# =================================================================== factory
def controller_structure(structure, n_u: int, n_y: int) -> ControllerStructure:
    """The :class:`ControllerStructure` named by a string.

    Parameters
    ----------
    structure : str or ControllerStructure
        ``"tfN"`` (``N`` ≥ 0), ``"pid"`` or ``"ss:N"``; an instance passes through
        (its sizes are checked).
    n_u, n_y : int
        Controls and measurements.

    Raises
    ------
    PolyrobError
        An unknown string (the message lists the valid ones) or sizes that do
        not match.

    Examples
    --------
    >>> from polyrob.synthesis.structures import controller_structure
    >>> controller_structure("ss:2", 1, 1).name
    'ss:2'
    >>> controller_structure("lqg", 1, 1)
    Traceback (most recent call last):
    ...
    polyrob.errors.PolyrobError: unknown controller structure 'lqg'; valid: "tfN" (e.g. "tf3": each K_ij of order N), "pid", "ss:N" (e.g. "ss:4")
    """
    if isinstance(structure, ControllerStructure):
        if (structure.n_u, structure.n_y) != (n_u, n_y):
            raise PolyrobError(f"structure is {structure.n_u}x{structure.n_y}; the plant needs {n_u}x{n_y}")
        return structure
    if isinstance(structure, str):
        s = structure.strip().lower()
        if m := re.fullmatch(r"tf(\d+)", s):
            return TransferFunctionStructure(n_u, n_y, int(m.group(1)))
        if s == "pid":
            return PIDStructure(n_u, n_y)
        if m := re.fullmatch(r"ss:(\d+)", s):
            return StateSpaceStructure(n_u, n_y, int(m.group(1)))
    raise PolyrobError(f"unknown controller structure {structure!r}; valid: {', '.join(VALID_STRUCTURES)}")
