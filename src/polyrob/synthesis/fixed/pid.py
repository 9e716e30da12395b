"""Decentralised PIDF controllers (``"pid"``)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import control
import numpy as np
from scipy.optimize import minimize_scalar

from polyrob.errors import ArgumentError
from polyrob.synthesis.fixed.base import ControllerStructure, as_lti, as_theta

__all__ = ["PIDStructure"]


@dataclass(frozen=True)
class PIDStructure(ControllerStructure):
    """Decentralised PIDF controller (``"pid"``): ``u_i = (Kp + Ki/s + Kd s/(τ s + 1)) e_i``.

    Parameters per channel: ``Kp, Ki, Kd, log τ``.  The realisation per
    channel has an integrator state ``x₁' = e`` and a filter state
    ``x₂' = (e - x₂)/τ``: ``u = Kp e + Ki x₁ + (Kd/τ)(e - x₂)``.

    Examples
    --------
    >>> import numpy as np
    >>> from polyrob.synthesis.fixed.structures import PIDStructure
    >>> s = PIDStructure(1, 1)
    >>> th = np.array([2.0, 0.5, 0.1, np.log(0.01)])
    >>> K = s.freqresp(th, [1.0])[0, 0, 0]
    >>> bool(np.isclose(K, 2.0 + 0.5 / 1j + 0.1j / (0.01j + 1)))
    True
    """

    def __post_init__(self):
        if self.n_u != self.n_y:
            raise ArgumentError(
                f"a decentralised PID needs as many controls as measurements, got {self.n_u}x{self.n_y}"
            )

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
        g = as_theta(theta, self.n_params).reshape(self.n_u, 4).copy()
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
        K = as_lti(K, self.n_u, self.n_y)
        try:
            p = np.abs(control.ss(K).poles()) if control.ss(K).nstates else np.zeros(0)
        except (ValueError, np.linalg.LinAlgError):
            p = np.zeros(0)  # no poles to place the fit band: the default band is used
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
        g = as_theta(theta, self.n_params).reshape(self.n_u, 4)
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
            "theta": as_theta(theta, self.n_params).tolist(),
            "Kp": g[:, 0].tolist(),
            "Ki": g[:, 1].tolist(),
            "Kd": g[:, 2].tolist(),
            "tau": g[:, 3].tolist(),
        }


# =================================================================== ss:N
