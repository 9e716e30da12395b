"""The synthesis plant of :func:`polyrob.synthesis.hinf.synthesis.hinfsyn`: scaled, regularised, shifted.

:class:`SynthesisProblem` holds a copy of the user's generalized plant and
records, in words, every change made to it (:attr:`SynthesisProblem.notes`):
a diagonal state scaling and unit-norm control/measurement channels (which
do not change the problem), a control penalty when ``D12`` lacks full column
rank, measurement noise when ``D21`` lacks full row rank, and a shift of
the imaginary axis when SLICOT reports a rank loss on it.
"""

from __future__ import annotations

import numpy as np

from polyrob.synthesis.hinf.checks import balance_state, format_complex

__all__ = ["SynthesisProblem"]


class SynthesisProblem:
    """The synthesis plant: scaled, regularised copy of the user's plant."""

    def __init__(self, A, B, C, D, n_u, n_y):
        self.n_u, self.n_y = n_u, n_y
        self.A, self.B, self.C, self.D = A, B, C, D
        self.notes: list[str] = []
        self.info: dict = {}
        n = A.shape[0]
        self.T = np.ones(n)  # x_s = T x
        self.su = np.ones(n_u)  # u = su * u_s
        self.sy = np.ones(n_y)  # y_s = sy * y
        self.axis_shift = 0.0

    # ------------------------------------------------------------ scaling
    def balance(self):
        """Diagonal state scaling equalising row/column norms of ``[A B; C 0]``."""
        if self.A.shape[0] == 0:
            return
        self.A, t, _ = balance_state(self.A, self.B, self.C)
        self.T = t
        self.B = t[:, None] * self.B
        self.C = self.C / t[None, :]

    def scale_io(self):
        """Unit-norm control columns ``[B2; D12]`` and measurement rows ``[C2 D21]``."""
        nu, ny = self.n_u, self.n_y
        nw, nz = self.B.shape[1] - nu, self.C.shape[0] - ny
        colu = np.linalg.norm(np.vstack([self.B[:, nw:], self.D[:, nw:]]), axis=0)
        rowy = np.linalg.norm(np.hstack([self.C[nz:], self.D[nz:]]), axis=1)
        su = np.where(colu > 0, 1.0 / np.where(colu > 0, colu, 1.0), 1.0)
        sy = np.where(rowy > 0, 1.0 / np.where(rowy > 0, rowy, 1.0), 1.0)
        su = 2.0 ** np.round(np.log2(su))
        sy = 2.0 ** np.round(np.log2(sy))
        self.B = self.B.copy()
        self.D = self.D.copy()
        self.C = self.C.copy()
        self.B[:, nw:] *= su[None, :]
        self.D[:, nw:] *= su[None, :]
        self.C[nz:] *= sy[:, None]
        self.D[nz:] *= sy[:, None]
        self.su, self.sy = su, sy

    # ------------------------------------------------------- regularisation
    def parts(self):
        nu, ny = self.n_u, self.n_y
        nw, nz = self.B.shape[1] - nu, self.C.shape[0] - ny
        return nw, nz

    def regularize_d12(self, eps: float, rtol: float):
        nw, nz = self.parts()
        D12 = self.D[:nz, nw:]
        s = np.linalg.svd(D12, compute_uv=False) if D12.size else np.zeros(0)
        ref = max(1.0, np.linalg.norm(np.hstack([self.C[:nz], D12]), 2) if nz else 1.0)
        smin = s[-1] if s.size == self.n_u else 0.0
        if smin > rtol * ref:
            return
        nu = self.n_u
        n = self.A.shape[0]
        rows_C = np.zeros((nu, n))
        rows_D = np.zeros((nu, self.D.shape[1]))
        rows_D[:, nw:] = eps * np.eye(nu)
        self.C = np.vstack([self.C[:nz], rows_C, self.C[nz:]])
        self.D = np.vstack([self.D[:nz], rows_D, self.D[nz:]])
        self.info["n_z_reg"] = nu
        per = ", ".join(f"{eps / su:.3g}" for su in self.su)
        self.notes.append(
            f"D12 lacks full column rank (sigma_min = {smin:.2g}): added a control penalty "
            f"z_reg = eps*u with eps = {eps:.3g} in scaled units (per control channel: {per})"
        )

    def regularize_d21(self, eps: float, rtol: float):
        nw, nz = self.parts()
        D21 = self.D[nz:, :nw]
        s = np.linalg.svd(D21, compute_uv=False) if D21.size else np.zeros(0)
        ref = max(1.0, np.linalg.norm(np.vstack([self.B[:, :nw], D21]), 2) if nw else 1.0)
        smin = s[-1] if s.size == self.n_y else 0.0
        if smin > rtol * ref:
            return
        ny = self.n_y
        n = self.A.shape[0]
        self.B = np.hstack([self.B[:, :nw], np.zeros((n, ny)), self.B[:, nw:]])
        cols = np.zeros((self.D.shape[0], ny))
        cols[-ny:, :] = eps * np.eye(ny)
        self.D = np.hstack([self.D[:, :nw], cols, self.D[:, nw:]])
        self.info["n_w_reg"] = ny
        per = ", ".join(f"{eps / sy:.3g}" for sy in self.sy)
        self.notes.append(
            f"D21 lacks full row rank (sigma_min = {smin:.2g}): added measurement noise "
            f"eps*w_n with eps = {eps:.3g} in scaled units (per measurement: {per})"
        )

    def shift_axis(self, eps: float) -> None:
        """Synthesise for ``P(s - eps)`` (``A -> A + eps I``); see :meth:`controller_to_user`.

        Shifting the *axis* rather than the offending poles is what makes
        the regularisation safe: with ``K(s) = K_eps(s + eps)``,
        ``Fl(P, K)(s) = Fl(P_eps, K_eps)(s + eps)``, so the true closed loop
        has its poles left of ``-eps`` and, by the maximum modulus principle,
        ``||Fl(P, K)||_inf <= ||Fl(P_eps, K_eps)||_inf <= gamma``.  Moving
        only the axis poles to ``-eps`` (``A - eps I`` on them) gives no such
        guarantee: the central controller then cancels the shifted poles and
        the loop with the true double integrator can be much worse.
        """
        n = self.A.shape[0]
        lam = np.linalg.eigvals(self.A) if n else np.zeros(0)
        axis = lam[np.abs(lam.real) <= 1e-7 * np.maximum(1.0, np.abs(lam))]
        self.A = self.A + eps * np.eye(n)
        self.axis_shift = eps
        self.info["axis_shift"] = eps
        self.notes.append(
            f"imaginary-axis rank conditions fail (modes at {', '.join(format_complex(x) for x in axis) or 'none'}): "
            f"solved for P(s - {eps:.3g}) and used K(s) = K_eps(s + {eps:.3g}), which guarantees "
            f"closed-loop poles left of -{eps:.3g} and ||Fl(P,K)|| <= gamma"
        )

    # -------------------------------------------------------------- mapping
    def controller_to_user(self, Ak, Bk, Ck, Dk):
        """Undo the input/output scaling: ``u = su u_s``, ``y_s = sy y``."""
        su, sy = self.su, self.sy
        Ak = Ak - self.axis_shift * np.eye(Ak.shape[0])  # K(s) = K_eps(s + eps)
        return Ak, Bk * sy[None, :], su[:, None] * Ck, su[:, None] * Dk * sy[None, :]
