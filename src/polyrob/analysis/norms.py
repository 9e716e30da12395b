"""The H∞ norm helper of the synthesis stage: true upper bounds only.

* :func:`hinf_norm` - ``‖G‖∞`` of a stable continuous-time system from SLICOT
  AB13DD, raised by its tolerance and confirmed by the Hamiltonian test
  (AB13DD's value is attained at a frequency: a value from below); when AB13DD fails, a bisection on the Hamiltonian test
  :func:`hinf_norm_below` gives a level that the norm is *proved* to stay
  below (never a grid value, which is an estimate from below and can miss a
  sharp resonance).  ``inf`` for an unstable system (python-control's
  ``linfnorm`` is finite for ``1/(s - 1)``: an L∞ norm, not an H∞ one).
* :func:`hinf_norm_below` - the Hamiltonian test ``‖G‖∞ < γ`` (Boyd,
  Balakrishnan & Kabamba 1989): the only check a controller is accepted on.
* :func:`hinf_norm_estimate` - a fast grid value, an estimate *from below*;
  used only to rank candidate controllers, never as γ or a certificate.

Stability is screened by :func:`polyrob.analysis.stability.stability_screen`
and responses evaluated by :func:`polyrob.analysis.mu.frequency.matrix_response`
(both written once, there).

Examples
--------
>>> import control
>>> from polyrob.analysis.norms import hinf_norm, hinf_norm_below
>>> G = control.ss(control.tf([1], [1, 0.2, 1]))
>>> round(hinf_norm(G), 4), hinf_norm_below(G, 5.03), hinf_norm_below(G, 5.02)
(5.0252, True, False)
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
from scipy.optimize import minimize_scalar

from polyrob.analysis.mu.frequency import matrix_response
from polyrob.analysis.stability import stability_screen
from polyrob.errors import SynthesisError

__all__ = ["hinf_norm", "hinf_norm_below", "hinf_norm_upper", "hinf_norm_estimate", "state_matrices"]


def state_matrices(sys) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(A, B, C, D)`` of a state-space object (or a 4-tuple) as float arrays."""
    if isinstance(sys, tuple):
        return tuple(np.asarray(X, float) for X in sys)
    return tuple(np.array(X, dtype=float) for X in (sys.A, sys.B, sys.C, sys.D))


def _norm2(H) -> float:
    """Spectral norm, ``inf`` for a response with a non-finite entry (a pole on the axis)."""
    if not np.all(np.isfinite(H)):
        return np.inf
    return float(np.linalg.norm(H, 2))


def hinf_norm_below(sys, gamma: float, *, rtol: float = 1e-2) -> bool:
    """Is ``‖G‖∞ < γ``?  Hamiltonian test, for a stable ``G`` (``False`` if unstable).

    For ``σ̄(D) < γ`` and stable ``A``, ``‖G‖∞ < γ`` iff the Hamiltonian

    .. math:: H_γ = \\begin{pmatrix} A + B R^{-1} D^T C & B R^{-1} B^T \\\\
              -C^T (I + D R^{-1} D^T) C & -(A + B R^{-1} D^T C)^T \\end{pmatrix},
              \\quad R = γ^2 I - D^T D,

    has no eigenvalue on the imaginary axis (Boyd, Balakrishnan & Kabamba
    1989).  Near a flat or multiple peak the imaginary eigenvalues are
    defective and rounding moves them by ``~sqrt(eps ‖H‖)``, far off the
    axis (measured: ``8e-5 ± 0.018j`` for a crossing near ``0.0115j``).  So
    every eigenvalue within ``rtol |λ|`` (or ``10 sqrt(eps ‖H‖)``) of the
    axis is a *candidate*, and ``σ̄(G(jω))`` is maximised over a decade on
    each side of its frequency: ``γ`` passes only if no candidate reaches it.
    Rounding can then only make the answer ``False`` (the caller raises γ).
    """
    A, B, C, D = state_matrices(sys)
    gamma = float(gamma)
    if not (gamma > 0) or not np.isfinite(gamma):
        return False
    if not stability_screen(A, 0.0):
        return False
    if D.size and np.linalg.norm(D, 2) >= gamma:
        return False
    n = A.shape[0]
    if n == 0:
        return True
    if B.shape[1] and C.shape[0]:
        A, B, C = _balanced(A, B, C)
    m = B.shape[1]
    R = gamma**2 * np.eye(m) - D.T @ D
    try:
        Ri = np.linalg.inv(R)
    except np.linalg.LinAlgError:  # gamma**2 underflows (a level near 0): no proof at that level
        return False
    with np.errstate(all="ignore"):  # a level near 0 overflows: checked just below
        Ah = A + B @ Ri @ D.T @ C
        H = np.block([[Ah, B @ Ri @ B.T], [-C.T @ (np.eye(C.shape[0]) + D @ Ri @ D.T) @ C, -Ah.T]])
    if not np.all(np.isfinite(H)):
        return False
    lam = sla.eigvals(H)
    slack = 10.0 * np.sqrt(np.finfo(float).eps * np.linalg.norm(H, 1))
    cand = lam[(np.abs(lam.real) <= np.maximum(rtol * np.abs(lam), slack)) & (lam.imag >= 0)]
    covered = -1.0  # a check at ω covers [ω/10, 10 ω]; nearby candidates share it
    for w in np.unique(np.round(np.abs(cand), 14)):
        if w <= covered / 3.0:
            continue
        if _local_peak(A, B, C, D, float(w)) >= gamma:
            return False
        covered = 10.0 * w
    return True


def _balanced(A, B, C):
    """TB01ID balancing of ``[A B; C 0]`` (a similarity: same transfer function, smaller ``‖H‖``)."""
    import slycot

    _, As, Bs, Cs, _ = slycot.tb01id(A.shape[0], B.shape[1], C.shape[0], 0.0, A.copy(), B.copy(), C.copy(), job="A")
    return np.asarray(As, float), np.asarray(Bs, float), np.asarray(Cs, float)


def _local_peak(A, B, C, D, w: float) -> float:
    """``max σ̄(G(jω))`` over ``[ω/10, 10 ω]`` (and ``ω = 0``): a grid, then a bounded refinement."""
    sig = _sigma_function(A, B, C, D)
    if w <= 0:
        return sig(0.0)
    grid = w * np.logspace(-1, 1, 41)
    vals = np.array([sig(x) for x in grid])
    k = int(np.argmax(vals))
    a, b = np.log(grid[max(k - 1, 0)]), np.log(grid[min(k + 1, grid.size - 1)])
    r = minimize_scalar(lambda x: -sig(float(np.exp(x))), bounds=(a, b), method="bounded", options={"xatol": 1e-10})
    return float(max(vals[k], -r.fun, sig(0.0)))


def _sigma_function(A, B, C, D):
    """``ω -> σ̄(G(jω))`` (``inf`` at a pole on the axis)."""
    response = matrix_response(A, B, C, D)
    return lambda x: _norm2(response(x)[0])


def hinf_norm_upper(sys, *, rtol: float = 1e-6, lower: float = 0.0) -> float:
    """An upper bound of ``‖G‖∞`` within ``rtol`` of the norm, by bisection on :func:`hinf_norm_below`.

    ``inf`` for an unstable system; raises :class:`SynthesisError` when no
    level passes the Hamiltonian test (numerically degenerate data).
    """
    A, B, C, D = state_matrices(sys)
    if not stability_screen(A, 0.0):
        return float("inf")
    lo = max(float(lower), hinf_norm_estimate(A, B, C, D), float(np.linalg.norm(D, 2)) if D.size else 0.0)
    hi = max(lo, 1e-150) * (1 + rtol)  # 1e-150: gamma**2 stays a normal float
    tries = 0
    while not hinf_norm_below((A, B, C, D), hi):
        lo, hi = hi, 2.0 * hi
        tries += 1
        if tries > 80:
            raise SynthesisError("no H∞ upper bound: the Hamiltonian test fails at every level tried")
    while hi - lo > rtol * hi:
        mid = 0.5 * (lo + hi)
        if hinf_norm_below((A, B, C, D), mid):
            hi = mid
        else:
            lo = mid
    return float(hi)


def hinf_norm(sys, tol: float = 1e-6) -> float:
    """H∞ norm of a stable continuous-time system (SLICOT AB13DD); ``inf`` if unstable.

    The value returned is an upper bound within ``tol`` (relative) of the
    norm: AB13DD's peak raised by ``tol`` and confirmed by the Hamiltonian
    test :func:`hinf_norm_below`; if AB13DD fails or the test refuses, the
    level of a Hamiltonian bisection (:func:`hinf_norm_upper`).  Never a
    sampled value.

    Examples
    --------
    >>> import control
    >>> from polyrob.analysis.norms import hinf_norm
    >>> round(hinf_norm(control.ss(control.tf([1], [1, 0.2, 1]))), 4)
    5.0252
    >>> hinf_norm(control.ss(control.tf([1], [1, -1])))
    inf
    """
    A, B, C, D = state_matrices(sys)
    if A.size and not stability_screen(A, 0.0):
        return float("inf")
    if A.size == 0:
        return float(np.linalg.norm(D, 2)) if D.size else 0.0
    import slycot
    from slycot.exceptions import SlycotArithmeticError, SlycotError

    n, m, p = A.shape[0], B.shape[1], C.shape[0]
    try:
        g, _ = slycot.ab13dd("C", "I", "N", "D", n, m, p, A, np.eye(n), B, C, D, tol)
    except (SlycotError, SlycotArithmeticError, ValueError, np.linalg.LinAlgError):
        # AB13DD failed: a bound that is a bound (Hamiltonian bisection), not a grid value
        return hinf_norm_upper((A, B, C, D), rtol=tol)
    # AB13DD's value is sigma_max at its peak frequency, accurate to ``tol``: a
    # value from below (measured: 1.5e-8 below the norm).  The level quoted is
    # the one the Hamiltonian test proves the norm to stay below.
    g_up = float(g) * (1 + tol)
    if hinf_norm_below((A, B, C, D), g_up):
        return g_up
    return hinf_norm_upper((A, B, C, D), rtol=tol, lower=float(g))


def hinf_norm_estimate(A, B, C, D, n_grid: int = 200) -> float:
    """Fast grid value of the H∞ norm: an estimate from below (``inf`` if unstable).

    A log grid over the poles' decades plus every pole's natural frequency,
    refined around the largest value.  For ranking candidates only (AB13DD
    on 100+ states costs ~1 s); never reported as γ or used as a certificate.
    """
    A, B, C, D = (np.asarray(X, float) for X in (A, B, C, D))
    if A.size == 0:
        return float(np.linalg.norm(D, 2)) if D.size else 0.0
    if not stability_screen(A, 0.0):
        return float("inf")
    wn = np.abs(np.linalg.eig(A)[0])  # the eigenvalues the grid has always used
    wn = wn[wn > 0]
    lo = np.log10(max(wn.min() if wn.size else 1e-3, 1e-8)) - 2
    hi = np.log10(wn.max() if wn.size else 1e3) + 2
    w = np.union1d(np.logspace(lo, hi, n_grid), wn)
    sig = _sigma_function(A, B, C, D)
    vals = np.array([sig(x) for x in w])
    k = int(np.argmax(vals))
    best = float(vals[k])
    a, b = np.log(w[max(k - 1, 0)]), np.log(w[min(k + 1, w.size - 1)])
    r = minimize_scalar(lambda x: -sig(np.exp(x)), bounds=(a, b), method="bounded", options={"xatol": 1e-6})
    return float(max(best, -r.fun, sig(0.0)))
