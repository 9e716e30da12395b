"""K-step, stabilisation and default start of the fixed-structure synthesis.

* :func:`kstep` - ``min_θ max_ω β_ω(θ)`` in epigraph form by SLSQP in a trust
  region (see :mod:`polyrob.synthesis.fixed.synthesis` for the method);
* :func:`stabilise` - HIFOO's first phase: minimise the closed-loop spectral
  abscissa until the loop is stable;
* :func:`default_controller` - a generic H2 (LQG) start.
"""

from __future__ import annotations

import math
import warnings

import control
import numpy as np
from scipy.optimize import minimize

from polyrob.synthesis.fixed.loop import FixedLoop
from polyrob.synthesis.fixed.options import FixedStructureOptions
from polyrob.synthesis.fixed.scalings import PerFrequencyScalings, majorant, refine_scalings

__all__ = ["abscissa_grad", "kstep", "stabilise", "default_controller"]


def abscissa_grad(loop: FixedLoop, theta, S) -> tuple[float, np.ndarray]:
    """Spectral abscissa and a finite-difference gradient in scaled units."""
    a0 = loop.abscissa(theta)
    g = np.zeros(theta.size)
    h = 1e-6
    for p in range(theta.size):
        e = np.zeros(theta.size)
        e[p] = h * S[p]
        g[p] = (loop.abscissa(theta + e) - a0) / h
    return a0, g


def kstep(loop: FixedLoop, theta0, sc: PerFrequencyScalings, opts: FixedStructureOptions, radius: float):
    """SLSQP on the epigraph form of ``min max_ω β_ω(θ)`` in a trust region.

    ``β_ω`` is the μ bound with re-optimised scalings (``opts.kstep == "live"``)
    or with the scalings ``sc`` frozen.  Returns the best stable point
    evaluated (not SLSQP's last iterate), the starting peak and SLSQP's message.
    """
    S = loop.structure.scale(theta0)
    b0 = majorant(loop, theta0, sc, n_eig=1)[:, 0]
    peak0 = float(np.max(b0))
    if not np.isfinite(peak0) or peak0 <= 0:
        return theta0, peak0, "non-finite majorant"
    n = theta0.size
    k = max(1, int(opts.n_eig))
    # frequencies far below the peak are dropped from the QP (they are checked after)
    active = np.flatnonzero(b0 >= opts.active_ratio * peak0)
    cache = {}
    a_scale = max(abs(loop.abscissa(theta0)), 1e-3)
    live = opts.kstep == "live" and loop.diag is not None
    best = [math.inf, theta0]
    warm = [sc.take(active)]

    def evaluate(x):
        key = x.tobytes()
        if key not in cache:
            th = theta0 + S * x[:n]
            if live:
                # the μ bound itself: scalings re-optimised at th (warm start: the
                # last evaluated point); by the envelope theorem the gradient
                # with the scalings held at their optimum is the bound's gradient
                ref = refine_scalings(loop, th, warm[0], np.arange(active.size), maxiter=opts.live_iter)
                warm[0] = ref
                beta, dbeta = majorant(loop, th, ref, n_eig=k, jac=True)
            else:
                beta, dbeta = majorant(loop, th, sc, active, n_eig=k, jac=True)
            a, ga = abscissa_grad(loop, th, S)
            if len(cache) > 4:
                cache.clear()
            cache[key] = (beta.ravel() / peak0, (dbeta * S[None, None, :]).reshape(-1, n) / peak0, a, ga)
            # SLSQP's last iterate is not always its best (nonsmooth, slightly
            # noisy bound): keep the best stable point evaluated
            top = float(np.max(beta[:, 0])) if beta.size else math.inf
            if a <= -opts.min_decay and top < best[0]:
                best[:] = [top, th]
        return cache[key]

    def cons(x):
        beta, _, a, _ = evaluate(x)
        c = np.empty(beta.size + 1)
        c[:-1] = x[n] - beta
        c[-1] = (-opts.min_decay - a) / a_scale
        return np.where(np.isfinite(c), c, -1e6)

    def cons_jac(x):
        beta, dbeta, a, ga = evaluate(x)
        J = np.zeros((beta.size + 1, n + 1))
        J[:-1, :n] = -dbeta
        J[:-1, n] = 1.0
        J[-1, :n] = -ga / a_scale
        return np.where(np.isfinite(J), J, 0.0)

    x0 = np.zeros(n + 1)
    x0[n] = 1.0
    bounds = [(-radius, radius)] * n + [(0.0, None)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            res = minimize(
                lambda x: x[n],
                x0,
                jac=lambda x: np.eye(n + 1)[n],
                method="SLSQP",
                bounds=bounds,
                constraints=[{"type": "ineq", "fun": cons, "jac": cons_jac}],
                options={"maxiter": int(opts.kstep_iter), "ftol": 1e-8},
            )
            msg = str(res.message)
        except (ValueError, np.linalg.LinAlgError) as exc:
            msg = f"SLSQP failed: {exc}"
    return best[1], peak0, msg


# ============================================================ stabilisation
def stabilise(loop: FixedLoop, theta, min_decay: float, max_iter: int = 300, restarts: int = 4, seed: int = 0):
    """Minimise the closed-loop spectral abscissa until the loop is stable (HIFOO's first phase).

    BFGS on the (nonsmooth) spectral abscissa, restarted from small random
    perturbations of the best point when it stalls short of stability.
    """
    a = loop.abscissa(theta)
    if a <= -min_decay:
        return theta, a
    target = -max(min_decay, 1e-6)
    best = [theta, a]
    rng = np.random.default_rng(seed)
    for attempt in range(restarts + 1):
        base = (
            best[0] if attempt == 0 else best[0] + 0.1 * loop.structure.scale(best[0]) * rng.standard_normal(theta.size)
        )
        S = loop.structure.scale(base)

        def f(x):
            th = base + S * x
            v = loop.abscissa(th)
            if v < best[1]:
                best[:] = [th, v]
            return v if np.isfinite(v) else 1e6

        def g(x):
            return abscissa_grad(loop, base + S * x, S)[1]

        def stop(intermediate_result):
            if best[1] <= target:
                raise StopIteration

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                minimize(
                    f,
                    np.zeros(theta.size),
                    jac=g,
                    method="BFGS",
                    callback=stop,
                    options={"maxiter": max_iter, "gtol": 1e-12},
                )
            except (ValueError, np.linalg.LinAlgError):
                pass  # the best point seen is kept; a start left unstable is reported by the caller
        if best[1] <= target:
            break
    return best[0], best[1]


# ============================================================ default start
def default_controller(sysP, n_u, n_y, eps=1e-2):
    """A generic stabilising full-order controller: the H2 (LQG) design on ``P``.

    LQR on the performance outputs ``z`` (control penalty ``eps²``) and a
    Kalman filter driven by the exogenous inputs (sensor noise ``eps²``),
    in the positive-feedback convention ``u = K y`` of ``lft``.
    """
    A, B, C, D = (np.asarray(X, float) for X in (sysP.A, sysP.B, sysP.C, sysP.D))
    nw, nz = sysP.ninputs - n_u, sysP.noutputs - n_y
    B1, B2, C1, C2 = B[:, :nw], B[:, nw:], C[:nz], C[nz:]
    n = A.shape[0]
    Q = C1.T @ C1 + 1e-9 * np.eye(n)
    W = B1 @ B1.T + 1e-9 * np.eye(n)
    Fk, *_ = control.lqr(A, B2, Q, eps**2 * np.eye(n_u))
    Lk, *_ = control.lqe(A, np.eye(n), C2, W, eps**2 * np.eye(n_y))
    Ak = A - B2 @ Fk - Lk @ C2 + Lk @ D[nz:, nw:] @ Fk
    return control.ss(Ak, Lk, -Fk, np.zeros((n_u, n_y)))
