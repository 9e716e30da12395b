"""Riccati route of the H∞ synthesis: SLICOT SB10FD inside an own γ bisection.

``control.hinfsyn`` exposes neither its starting γ nor its tolerance, so
the bisection is done here around :func:`sb10fd_controller` (the central
controller at one γ), with an explicit closed-loop eigenvalue check at every
step.  Near the optimal γ the Riccati equations are ill conditioned and
SB10FD can return a stabilising controller that misses γ by orders of
magnitude: :func:`riccati_controller` accepts a controller only when the
Hamiltonian test proves ``‖Fl(P, K)‖∞ < γ (1 + rtol)``
(:func:`verify_controller`), and otherwise backs γ off.
"""

from __future__ import annotations

import warnings

import numpy as np

from polyrob.analysis.norms import hinf_norm_below
from polyrob.analysis.stability import stability_screen
from polyrob.plant.generalized import lower_lft_matrices
from polyrob.synthesis.hinf.problem import SynthesisProblem

__all__ = ["sb10fd_controller", "bisect_gamma", "verify_controller", "riccati_controller", "RANK_FAIL"]


def sb10fd_controller(prob: SynthesisProblem, gamma: float):
    """Central controller at ``γ`` (SLICOT SB10FD) if it stabilises the loop: ``(mats, 0)``, else ``(None, code)``.

    ``code`` is SB10FD's ``info`` (1-5: rank conditions, 6: no admissible γ,
    7/8: Riccati failures) or 9 for an ill-posed loop.
    """
    import slycot
    from slycot.exceptions import SlycotArithmeticError, SlycotError

    A, B, C, D = prob.A, prob.B, prob.C, prob.D
    n, m, p = A.shape[0], B.shape[1], C.shape[0]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            Ak, Bk, Ck, Dk, rcond = slycot.sb10fd(n, m, p, prob.n_u, prob.n_y, gamma, A, B, C, D)
    except (SlycotArithmeticError, SlycotError, ValueError) as exc:
        return None, int(getattr(exc, "info", -1) or -1)
    mats = (np.asarray(Ak), np.asarray(Bk), np.asarray(Ck), np.asarray(Dk))
    if not all(np.all(np.isfinite(X)) for X in mats):
        return None, 7
    try:
        Acl, *_ = lower_lft_matrices(A, B, C, D, *mats, prob.n_u, prob.n_y)
    except np.linalg.LinAlgError:
        return None, 9
    if not stability_screen(Acl):
        return None, 6  # formulas gave a controller but the loop is not stable
    return mats, 0


RANK_FAIL = {1, 2, 3, 4, 5}


def bisect_gamma(prob: SynthesisProblem, gamma_range, tol: float):
    """Smallest feasible γ (to relative ``tol``) and its controller, or ``(None, info)``."""
    calls = 0
    lo, hi, best = 0.0, None, None
    if gamma_range is not None:
        lo = float(gamma_range[0] or 0.0)
        g = float(gamma_range[1])
        mats, info = sb10fd_controller(prob, g)
        calls += 1
        if mats is None:
            return None, {"calls": calls, "last_info": info, "rank_fail": info in RANK_FAIL}
        hi, best = g, mats
    else:
        g = 1.0
        mats, info = sb10fd_controller(prob, g)
        calls += 1
        if info in RANK_FAIL:
            return None, {"calls": calls, "last_info": info, "rank_fail": True}
        # bracket by decades: down while feasible, or up while infeasible
        feasible = mats is not None
        if feasible:
            hi, best = g, mats
        else:
            lo = g
        step = 0.1 if feasible else 10.0
        while 1e-10 < g < 1e14:
            g *= step
            m2, info = sb10fd_controller(prob, g)
            calls += 1
            if m2 is not None:
                hi, best = g, m2
                if not feasible:
                    break
            else:
                if not feasible and info in RANK_FAIL:
                    return None, {"calls": calls, "last_info": info, "rank_fail": True}
                lo = g
                if feasible:
                    break
        if hi is None:
            return None, {"calls": calls, "last_info": info, "rank_fail": False}
    while hi - lo > tol * hi and calls < 200:
        mid = np.sqrt(lo * hi) if lo > 0 else 0.5 * hi
        m2, _ = sb10fd_controller(prob, mid)
        calls += 1
        if m2 is None:
            lo = mid
        else:
            hi, best = mid, m2
    return best, {"calls": calls, "gamma": hi, "gamma_lower": lo}


def verify_controller(prob: SynthesisProblem, mats, gamma: float, rtol: float = 1e-2) -> bool:
    """Is ``‖Fl(P_s, K)‖∞ < γ (1 + rtol)`` on the synthesis plant, proved by the Hamiltonian test?

    SB10FD near the optimal γ solves ill-conditioned Riccati equations; the
    controller it returns can then be stabilising yet miss the bound by
    orders of magnitude.  Every accepted controller is checked, against a
    true bound (a grid value would be an estimate from below and could
    accept a controller whose peak falls between grid points).
    """
    try:
        cl = lower_lft_matrices(prob.A, prob.B, prob.C, prob.D, *mats, prob.n_u, prob.n_y)
    except np.linalg.LinAlgError:
        return False
    return hinf_norm_below(cl, gamma * (1 + rtol))


def riccati_controller(prob: SynthesisProblem, gamma_range, tol):
    """Bisection, then back off from the optimum until the controller verifies."""
    mats, info = bisect_gamma(prob, gamma_range, tol)
    if mats is None:
        return None, info
    g0 = float(info["gamma"])
    if verify_controller(prob, mats, g0):
        return mats, info
    for f in (1.01, 1.03, 1.1, 1.3, 2.0):
        m2, code = sb10fd_controller(prob, g0 * f)
        info["calls"] = info.get("calls", 0) + 1
        if m2 is not None and verify_controller(prob, m2, g0 * f):
            info["gamma"] = g0 * f
            info["backoff"] = f
            prob.notes.append(
                f"SB10FD controller at gamma = {g0:.4g} was numerically inaccurate (closed-loop norm above "
                f"gamma): backed off to gamma = {g0 * f:.4g}"
            )
            return m2, info
    info["last_info"] = 10
    info["rank_fail"] = False
    return None, info
