"""Published reference problems, used by the tests and the benchmarks.

* :func:`distillation_plant` — Skogestad & Postlethwaite's distillation
  column (*Multivariable Feedback Control*, 2nd ed., 2005, Table 8.1, p. 325),
  the generalized plant dkpy ships as ``example_skogestad2006_p325``.
* :func:`distillation_rp_response` — ``N(jω)`` of the same problem closed by
  the book's inverse-based controller (μ_RP ≈ 5.77, section 8.12.3).
"""

from __future__ import annotations

import control
import numpy as np

__all__ = ["DISTILLATION_BLK", "distillation_plant", "distillation_rp_response"]

#: Two complex scalars (input uncertainty) and a full 2x2 performance block.
DISTILLATION_BLK = [[1, 1], [1, 1], [2, 2]]

_G0 = np.array([[87.8, -86.4], [108.2, -109.6]])


def distillation_plant() -> control.StateSpace:
    """The distillation column's generalized plant (6 states, 6 inputs, 6 outputs).

    ``G = diag(1/(75 s + 1)) G0``, input uncertainty ``W_I = (s + 0.2)/(0.5 s + 1)``,
    performance ``W_P = 0.5 (10 s + 1)/(10 s + 1e-5)``.  Inputs
    ``[d (2), w (2), u (2)]``, outputs ``[v = W_I u, z = W_P e, y = -e]`` with
    ``e = w + G (u + d)``; block structure :data:`DISTILLATION_BLK`, ``n_u = n_y = 2``.

    Examples
    --------
    >>> from polyrob.examples import distillation_plant
    >>> P = distillation_plant()
    >>> P.nstates, P.ninputs, P.noutputs
    (6, 6, 6)
    """
    a, c = -1 / 75, 1 / 75  # 1/(75 s + 1)
    ap, cp, dp = -1e-6, 0.05 - 0.5e-6, 0.5  # W_P = 0.5 + (0.05 - 0.5e-6)/(s + 1e-6)
    ai, ci, di = -2.0, -3.6, 2.0  # W_I = 2 - 3.6/(s + 2)
    A, B, C, D = (np.zeros((6, 6)) for _ in range(4))
    for i in range(2):
        j, k = 2 + i, 4 + i
        A[i, i] = a
        B[i, 0:2] = _G0[i]
        B[i, 4:6] = _G0[i]
        A[j, j], A[j, i], B[j, 2 + i] = ap, c, 1.0
        A[k, k], B[k, 4 + i] = ai, 1.0
        C[i, k], D[i, 4 + i] = ci, di
        C[2 + i, j], C[2 + i, i], D[2 + i, 2 + i] = cp, dp * c, dp
        C[4 + i, i], D[4 + i, 2 + i] = -c, -1.0
    return control.ss(A, B, C, D)


def distillation_rp_response(omega) -> control.FrequencyResponseData:
    """``N = [[-W_I T_I, -W_I K S], [W_P S G, W_P S]]`` with the inverse-based controller.

    ``K = 0.7 (75 s + 1)/s G0^{-1}`` (the integrator moved to ``s = -1e-5``).

    Examples
    --------
    >>> import numpy as np
    >>> from polyrob.examples import DISTILLATION_BLK, distillation_rp_response
    >>> from polyrob.analysis.mu.bounds import mu_bounds
    >>> r = mu_bounds(distillation_rp_response(np.logspace(-3, 3, 61)), DISTILLATION_BLK, progress=False)
    >>> round(r.peak_upper, 2)
    5.77
    """
    omega = np.asarray(omega, dtype=float)
    I2 = np.eye(2)
    out = []
    for s in 1j * omega:
        G = _G0 / (75 * s + 1)
        K = 0.7 * (75 * s + 1) / (s + 1e-5) * np.linalg.inv(_G0)
        wi = (s + 0.2) / (0.5 * s + 1)
        wp = 0.5 * (10 * s + 1) / (10 * s + 1e-5)
        S = np.linalg.inv(I2 + G @ K)
        TI = np.linalg.inv(I2 + K @ G) @ K @ G
        out.append(np.block([[-wi * TI, -wi * K @ S], [wp * S @ G, wp * S]]))
    return control.frd(np.moveaxis(np.array(out), 0, -1), omega)
