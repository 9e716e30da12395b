"""Closed-loop algebra of the fixed-structure synthesis: ``lft(P, K(θ))`` without python-control objects.

:class:`FixedLoop` evaluates ``N(jω; θ)`` and its derivative factors for a
parametrised controller (:mod:`polyrob.synthesis.fixed.structures`), the
closed-loop matrix and spectral abscissa; :func:`closed_loop_response` is
the same algebra for a given controller, a cross-check against
:func:`polyrob.plant.lft`.  ``P(jω)`` comes from
:func:`~polyrob.analysis.mu.frequency.matrix_response` (a direct solve per ω,
cached per grid), the closed-loop matrix from
:func:`~polyrob.plant.loops.lower_lft_matrices`.
"""

from __future__ import annotations

import math

import control
import numpy as np
from slycot.exceptions import SlycotArithmeticError, SlycotError

from polyrob.analysis.mu.frequency import freqresp, matrix_response
from polyrob.controller import Controller
from polyrob.errors import ArgumentError
from polyrob.plant.loops import lower_lft_matrices
from polyrob.synthesis.fixed.structures import ControllerStructure

__all__ = ["FixedLoop", "closed_loop_response", "plant_parts", "diagonal_blocks"]


# ============================================================ plant algebra
class FixedLoop:
    """Frequency responses and closed-loop matrices of ``lft(P, K(θ))`` without python-control objects."""

    def __init__(self, sysP: control.StateSpace, n_u: int, n_y: int, structure: ControllerStructure, st):
        self.A, self.B, self.C, self.D = (np.asarray(X, float) for X in (sysP.A, sysP.B, sysP.C, sysP.D))
        self.n_u, self.n_y = n_u, n_y
        self.nw, self.nz = sysP.ninputs - n_u, sysP.noutputs - n_y
        self.structure, self.st = structure, st
        # rows / cols of N inside the padded square problem (BlockStructure.pad's placement)
        self.ec = np.array(
            [i for b, sl in zip(st.blocks, st.padded_slices) for i in range(sl.start, sl.start + b.cols)], int
        )
        self.er = np.array(
            [i for b, sl in zip(st.blocks, st.padded_slices) for i in range(sl.start, sl.start + b.rows)], int
        )
        self.npad = st.padded_size
        self._cache = {}
        # direct solves (modal=False): accurate whatever A's eigenvector conditioning
        self._response = matrix_response(self.A, self.B, self.C, self.D, modal=False)
        self.diag = diagonal_blocks(st)
        # Stability is decided by the loop of the *minimal* u -> y channel: the
        # other modes of P (e.g. the weights' states, unobservable from y)
        # are closed-loop poles whatever K is.  Without them the spectral
        # abscissa is not pinned at the slowest weight pole and its gradient
        # is informative.
        nw, nz = self.nw, self.nz
        A, B2, C2, D22 = self.A, self.B[:, nw:], self.C[nz:], self.D[nz:, nw:]
        self.notes: list[str] = []
        try:
            g = control.minreal(control.ss(A, B2, C2, D22), verbose=False) if A.size else None
        except (ValueError, np.linalg.LinAlgError, SlycotError, SlycotArithmeticError) as exc:
            g = None  # keep the full channel: the abscissa is then pinned by the fixed modes, and say so
            self.notes.append(f"minimal u -> y realisation failed ({exc}); stability measured on the full plant")
        if g is None:
            self.G22 = (A, B2, C2, D22)
        else:
            self.G22 = tuple(np.asarray(X, float) for X in (g.A, g.B, g.C, g.D))
        lam_full = np.linalg.eigvals(A) if A.size else np.zeros(0)
        lam_g = np.linalg.eigvals(self.G22[0]) if self.G22[0].size else np.zeros(0)
        # modes no controller moves (to rounding): those of A not in the channel
        rest = list(lam_full)
        for z in lam_g:
            if rest:
                rest.pop(int(np.argmin(np.abs(np.array(rest) - z))))
        self.fixed_modes = np.array(rest, complex)

    # ---------------------------------------------------------------- P(jω)
    def plant(self, omega: np.ndarray):
        key = omega.tobytes()
        if key not in self._cache:
            if len(self._cache) > 8:
                self._cache.clear()
            H = self._response(omega)
            nz, nw = self.nz, self.nw
            self._cache[key] = (H[:, :nz, :nw], H[:, :nz, nw:], H[:, nz:, :nw], H[:, nz:, nw:])
        return self._cache[key]

    def response(self, theta, omega, *, jac=False):
        """``N(jω)``; with ``jac`` also ``L``, ``R`` and ``∂K/∂θ`` (``dN = L dK R``)."""
        P11, P12, P21, P22 = self.plant(omega)
        if jac:
            K, dK = self.structure.freqresp(theta, omega, jac=True)
        else:
            K, dK = self.structure.freqresp(theta, omega), None
        Iy, Iu = np.eye(self.n_y), np.eye(self.n_u)
        with np.errstate(all="ignore"):
            R = np.linalg.solve(Iy - P22 @ K, P21)  # (I - P22 K)^-1 P21
            N = P11 + P12 @ (K @ R)
            if not jac:
                return N
            L = np.swapaxes(np.linalg.solve(np.swapaxes(Iu - K @ P22, 1, 2), np.swapaxes(P12, 1, 2)), 1, 2)
        return N, L, R, dK

    # ---------------------------------------------------------------- A_cl
    def _close(self, A, B2, C2, D22, K):
        """``A`` of the loop ``u = K y`` around ``(A, B2, C2, D22)`` (no other channels)."""
        return lower_lft_matrices(A, B2, C2, D22, *K, self.n_u, self.n_y)[0]

    def closed_loop_matrix(self, theta, *, full=False) -> np.ndarray:
        """``A`` of ``lft(P, K(θ))`` (``full``) or of the loop of the minimal ``u -> y`` channel."""
        K = self.structure.realization(theta)
        if full:
            nw, nz = self.nw, self.nz
            return self._close(self.A, self.B[:, nw:], self.C[nz:], self.D[nz:, nw:], K)
        return self._close(*self.G22, K)

    def abscissa(self, theta, *, full=False) -> float:
        """Largest real part of the closed-loop poles (``inf`` if not computable)."""
        try:
            Acl = self.closed_loop_matrix(theta, full=full)
            if not np.all(np.isfinite(Acl)):
                return math.inf
            return float(np.max(np.linalg.eigvals(Acl).real)) if Acl.size else -math.inf
        except (np.linalg.LinAlgError, ValueError):
            return math.inf

    def pole_frequencies(self, theta) -> np.ndarray:
        try:
            lam = np.linalg.eigvals(self.closed_loop_matrix(theta, full=True))
        except (np.linalg.LinAlgError, ValueError):
            return np.zeros(0)
        w = np.abs(lam)
        return w[np.isfinite(w) & (w > 0)]


def closed_loop_response(P, K, omega, *, n_u: int | None = None, n_y: int | None = None) -> np.ndarray:
    """``lft(P, K)(jω)`` as an ``(N, n_out, n_in)`` array, computed from ``P(jω)`` and ``K(jω)``.

    A cross-check of the K-step's algebra against :func:`polyrob.plant.lft`.

    Examples
    --------
    >>> import control, numpy as np
    >>> from polyrob.synthesis.fixed.synthesis import closed_loop_response
    >>> P = control.ss([[0.0]], [[1.0, 1.0]], [[1.0], [1.0]], np.zeros((2, 2)))
    >>> H = closed_loop_response(P, -2.0, [1.0, 2.0], n_u=1, n_y=1)   # 1/(s + 2)
    >>> np.round(H[:, 0, 0], 6).tolist()
    [(0.4-0.2j), (0.25-0.25j)]
    >>> from polyrob.controller import Controller
    >>> np.allclose(closed_loop_response(P, Controller.of(-2.0), [1.0, 2.0], n_u=1, n_y=1), H)
    True
    """
    sysP, n_u, n_y = plant_parts(P, n_u, n_y)
    omega = np.asarray(omega, float).ravel()
    Hp = freqresp(sysP, omega)
    if isinstance(K, control.LTI):  # a transfer function is evaluated as given, not realised first
        Kw = freqresp(K, omega)
    else:
        K = Controller.of(K, n_u, n_y)  # a gain, a 4-tuple or a Controller (taken as it is)
        Kw = freqresp(K.system, omega) if K.order else np.broadcast_to(K.D, (omega.size, n_u, n_y)).astype(complex)
    nz, nw = sysP.noutputs - n_y, sysP.ninputs - n_u
    P11, P12, P21, P22 = Hp[:, :nz, :nw], Hp[:, :nz, nw:], Hp[:, nz:, :nw], Hp[:, nz:, nw:]
    return P11 + P12 @ Kw @ np.linalg.solve(np.eye(n_y) - P22 @ Kw, P21)


def plant_parts(P, n_u, n_y):
    from polyrob.plant.generalized import GeneralizedPlant

    if isinstance(P, GeneralizedPlant):
        return P.system, P.n_u, P.n_y
    if isinstance(P, control.StateSpace):
        if n_u is None or n_y is None:
            raise ArgumentError("a bare StateSpace plant needs n_u and n_y")
        if P.dt not in (0, None):
            raise ArgumentError("the plant must be continuous-time")
        return P, int(n_u), int(n_y)
    raise ArgumentError(f"fixed_structure_musyn needs a GeneralizedPlant or a StateSpace, got {type(P).__name__}")


def diagonal_blocks(st):
    """Block membership matrix ``E`` (blocks x padded size) and real-block mask, if AB13MD-like.

    The fast D-step handles structures whose optimal scalings are diagonal
    (real scalars and full complex blocks); ``None`` otherwise.
    """
    if st.has_repeated:
        return None
    E = np.zeros((len(st.blocks), st.padded_size))
    for k, sl in enumerate(st.padded_slices):
        E[k, sl] = 1.0
    return E, np.array([b.kind == "real" for b in st.blocks])
