"""State-space controllers of order N with free ``A, B, C, D`` (``"ss:N"``)."""

from __future__ import annotations

from dataclasses import dataclass

import control
import numpy as np
from control.exception import ControlArgument, ControlSlycot
from slycot.exceptions import SlycotError

from polyrob.errors import SolverError
from polyrob.synthesis.fixed.base import OrderedStructure, as_lti, as_theta

__all__ = ["StateSpaceStructure"]


@dataclass(frozen=True)
class StateSpaceStructure(OrderedStructure):
    """A state-space controller of order ``N`` with free ``A, B, C, D`` (``"ss:N"``).

    ``θ = [vec(A), vec(B), vec(C), vec(D)]`` (row-major).  Over-parametrised
    (any similarity transformation gives the same ``K``), which gradient
    methods tolerate.

    Examples
    --------
    >>> from polyrob.synthesis.fixed.structures import StateSpaceStructure
    >>> s = StateSpaceStructure(2, 2, 4)
    >>> s.n_params
    36
    """

    prefix = "ss:"
    N: int = 4

    @property
    def n_params(self) -> int:
        N, m, p = self.N, self.n_u, self.n_y
        return N * N + N * p + m * N + m * p

    @property
    def order(self) -> int:
        return self.N

    def realization(self, theta):
        th = as_theta(theta, self.n_params)
        N, m, p = self.N, self.n_u, self.n_y
        k = np.cumsum([0, N * N, N * p, m * N, m * p])
        return (
            th[k[0] : k[1]].reshape(N, N),
            th[k[1] : k[2]].reshape(N, p),
            th[k[2] : k[3]].reshape(m, N),
            th[k[3] : k[4]].reshape(m, p),
        )

    def freqresp(self, theta, omega, *, jac: bool = False):
        s = 1j * np.asarray(omega, dtype=float).ravel()
        A, B, C, D = self.realization(theta)
        N, m, p = self.N, self.n_u, self.n_y
        if N == 0:
            K = np.broadcast_to(D, (s.size, m, p)).astype(complex)
            XB = CX = None
        else:
            Z = s[:, None, None] * np.eye(N) - A
            XB = np.linalg.solve(Z, np.broadcast_to(B, (s.size, N, p)))  # (sI-A)^-1 B
            CX = np.swapaxes(np.linalg.solve(np.swapaxes(Z, 1, 2), np.broadcast_to(C.T, (s.size, N, m))), 1, 2)
            K = C @ XB + D
        if not jac:
            return K
        dK = np.zeros((s.size, self.n_params, m, p), complex)
        q = 0
        if N:
            # ∂K/∂A_kl = (C X)[:, k] (X B)[l, :]
            dK[:, q : q + N * N] = (CX[:, :, :, None, None].transpose(0, 2, 3, 1, 4) * XB[:, None, :, None, :]).reshape(
                s.size, N * N, m, p
            )
            q += N * N
            # ∂K/∂B_kl = (C X)[:, k] e_l^T
            dK[:, q : q + N * p] = (
                CX.transpose(0, 2, 1)[:, :, None, :, None] * np.eye(p)[None, None, :, None, :]
            ).reshape(s.size, N * p, m, p)
            q += N * p
            # ∂K/∂C_kl = e_k (X B)[l, :]
            dK[:, q : q + m * N] = (np.eye(m)[None, :, None, :, None] * XB[:, None, :, None, :]).reshape(
                s.size, m * N, m, p
            )
            q += m * N
        dK[:, q:] = np.eye(m * p).reshape(m * p, m, p)[None]
        return K, dK

    def from_controller(self, K) -> np.ndarray:
        K = as_lti(K, self.n_u, self.n_y)
        Ks = control.ss(K)
        if Ks.nstates:
            Ks = control.minreal(Ks, verbose=False)
        if Ks.nstates > self.N:
            try:
                Ks = control.balred(Ks, self.N, method="matchdc")
            except (ValueError, np.linalg.LinAlgError, SlycotError, ControlArgument, ControlSlycot) as exc:
                raise SolverError(f"cannot reduce the controller to order {self.N}: {exc}") from None
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
            eps = 1e-3 * max(
                np.max(np.abs(D)), np.max(np.abs(B)) if B.size else 0, np.max(np.abs(C)) if C.size else 0, 1e-6
            )
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
        return {
            "theta": as_theta(theta, self.n_params).tolist(),
            "A": A.tolist(),
            "B": B.tolist(),
            "C": C.tolist(),
            "D": D.tolist(),
            "poles": np.linalg.eigvals(A).tolist() if self.N else [],
        }
