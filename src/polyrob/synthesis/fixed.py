"""Fixed-structure μ-synthesis: a D-G-K iteration over a parametrised controller.

:func:`fixed_structure_musyn` searches a controller of a prescribed structure
(:mod:`polyrob.synthesis.structures`: ``"tfN"``, ``"pid"``, ``"ss:N"``) that
minimises the peak over frequency of the mixed-μ upper bound of the closed
loop ``N(θ) = lft(P, K(θ))``, the paper's fixed-structure ``musyn`` (section 3).

The method (what is implemented, and why)
-----------------------------------------
The μ upper bound at one frequency is ``min over (D, G)`` of
``β_{D,G}(M)``, the smallest ``β`` with
``M^H D² M + j(G M - M^H G) ⪯ β² D²`` (Fan-Tits-Doyle).  For any fixed
admissible scalings ``β_{D,G}(N(jω; θ))`` is an upper bound of μ for every
``θ``; ``β²`` is the largest eigenvalue of the Hermitian matrix
``A = M̃^H M̃ + j(G̃ M̃ - M̃^H G̃)``, ``M̃ = D M D⁻¹``, ``G̃ = D⁻¹ G D⁻¹``, with
an analytic derivative ``dλ = 2 Re(u^H dM̃ v)``, ``u = (M̃ - jG̃) v``
(``v`` the unit eigenvector), ``dN = P₁₂ (I - K P₂₂)⁻¹ dK (I - P₂₂ K)⁻¹ P₂₁``
and ``dK/dθ`` from the structure.

Each iteration (what musyn's fixed-structure mode alternates, tightened):

1. **K-step** — ``min_θ max_ω μ̄(N(jω; θ))`` over the frequencies near the
   peak, in epigraph form ``min t s.t. β_{ω,i}(θ) ≤ t`` solved by SLSQP in a
   trust region (well-scaled parameters), the two largest eigenvalues per
   frequency as separate constraints (a multiple eigenvalue — the rule at
   optimal scalings — is then modelled by its cutting planes, not by one
   arbitrary gradient) and the closed-loop spectral abscissa as a constraint.
   By default (``kstep="live"``) the scalings are re-optimised at every trial
   point by a warm-started batched BFGS on ``(log d, g̃)``, so the K-step
   minimises the μ bound itself (its gradient at optimal scalings is the one
   above, envelope theorem).  With the scalings frozen instead (classic D-K,
   ``kstep="frozen"``) the iteration stalled on the paper's 2R at μ ≈ 1.61
   where the live K-step went on to ≈ 1.45 from the same start.
2. **Acceptance** — backtracking until the loop is internally stable and
   the bound decreased on the working grid *and*, rigorously, on a fine
   screening grid (40/decade, plus the closed-loop pole frequencies, plus
   ``certify_omega``) checked with the nearest grid scalings; so a step
   cannot buy its progress with a resonance between grid points.
3. **D-step** — scalings refreshed where the bound is near the peak (batched
   BFGS warm-started from the previous ones; SLICOT AB13MD via
   :func:`polyrob.analysis.mu.mussv` when progress stalls and for new frequencies);
   the working grid is refined around the peaks.

The grid peak therefore never increases.  Starts: the given ``init`` (e.g.
``"paper"``: ``K*``), or a generic H2 design fitted to the structure, then
random perturbations of it (HIFOO's multi-start); a start that does not
stabilise the loop first goes through a spectral-abscissa minimisation
(HIFOO's stabilisation phase).

The best start is certified by :func:`polyrob.analysis.mu.mu_bounds` of
``lft(P, K)`` (upper and lower bounds, peak-refined): ``peak_mu`` is that
certificate's peak, independent of the optimiser.  If the certificate finds
a peak above the optimised one, it is added to the grid and the iteration
resumes (``certify_rounds``).

Examples
--------
>>> import control, numpy as np
>>> from polyrob.synthesis.fixed import fixed_structure_musyn
>>> # a 1-state plant x' = x + d + u, v = x, y = x, z = 0.5 x; blk: one real δ
>>> # (robust stability) and a 1x1 performance block
>>> P = control.ss([[1.0]], [[1.0, 0.0, 1.0]], [[1.0], [0.5], [1.0]], np.zeros((3, 3)))
>>> w = np.logspace(-2, 2, 41)
>>> r = fixed_structure_musyn(P, [[-1, 0], [1, 1]], "tf0", n_u=1, n_y=1, init=-3.0, starts=1,
...                           max_iter=5, omega=w, certify_omega=w)
>>> r.order, bool(r.peak_mu < 0.5)      # a static gain k < -1 stabilises; large |k| is robust
(0, True)
"""

from __future__ import annotations

import math
import sys
import time
import warnings
from dataclasses import dataclass, field, replace
from typing import Callable, Optional, Union

import control
import numpy as np
from scipy.optimize import minimize

from polyrob._threads import single_blas_thread
from polyrob.analysis.blocks import as_block_structure
from polyrob.errors import PolyrobError, SynthesisError
from polyrob.analysis.mu import mu_bounds
from polyrob.synthesis._fixed_scalings import _Scalings, _diagonal_blocks, _dstep, _majorant, _refine_scalings, _scalings_from
from polyrob.synthesis.result import MusynResult
from polyrob.synthesis.structures import ControllerStructure, controller_structure

__all__ = ["fixed_structure_musyn", "FixedStructureOptions", "closed_loop_response"]


@dataclass(frozen=True)
class FixedStructureOptions:
    """Tuning knobs of :func:`fixed_structure_musyn` (defaults suit small plants).

    Attributes
    ----------
    grid_density : float
        Working-grid points per decade.
    screen_density : float
        Points per decade of the rigorous screening grid.
    kstep_iter : int
        SLSQP iterations per K-step.
    trust_region : float
        Initial K-step trust radius, in units of :meth:`ControllerStructure.scale`.
    tol : float
        Stop when the grid peak improved by less than this (relative) over
        ``patience`` consecutive iterations.
    patience : int
    dstep_ratio : float
        The D-step recomputes the scalings where the majorant is above this
        fraction of the peak (elsewhere stale scalings still give a valid,
        if looser, bound).
    n_eig : int
        Eigenvalues per frequency entered as K-step constraints.
    min_decay : float
        Closed-loop poles must satisfy ``Re λ ≤ -min_decay`` (rad/s).
    spread : float
        Size of the random perturbations of the multi-start.
    certify_rounds : int
        If the final certificate finds a peak above the optimised one, add it
        to the grid and iterate again, at most this many times.
    kstep : {"live", "frozen"}
        ``"live"``: the K-step minimises the μ bound itself, the scalings
        re-optimised (warm-started batched BFGS) at every trial point;
        ``"frozen"``: classic D-K, the scalings held fixed during the K-step
        (cheaper per step, but stalls: on the paper's 2R the frozen majorant
        reaches a local minimum ~0.3 % below the current bound).
    active_ratio : float
        Frequencies whose bound is above this fraction of the peak enter the
        K-step as constraints (the others are checked when the step is accepted).
    live_iter : int
        BFGS iterations of the scaling update per trial point (live K-step).
    exact_ratio : float
        When progress stalls, the scalings of the frequencies above this
        fraction of the peak are recomputed by AB13MD (~40 ms each).
    """

    grid_density: float = 10.0
    screen_density: float = 40.0
    kstep_iter: int = 40
    trust_region: float = 0.5
    tol: float = 1e-3
    patience: int = 3
    dstep_ratio: float = 0.7
    n_eig: int = 2
    min_decay: float = 1e-7
    spread: float = 0.5
    certify_rounds: int = 2
    kstep: str = "live"
    active_ratio: float = 0.8
    live_iter: int = 12
    exact_ratio: float = 0.95


# ============================================================ plant algebra
class _Loop:
    """Frequency responses and closed-loop matrices of ``lft(P, K(θ))`` without python-control objects."""

    def __init__(self, sysP: control.StateSpace, n_u: int, n_y: int, structure: ControllerStructure, st):
        self.A, self.B, self.C, self.D = (np.asarray(X, float) for X in (sysP.A, sysP.B, sysP.C, sysP.D))
        self.n_u, self.n_y = n_u, n_y
        self.nw, self.nz = sysP.ninputs - n_u, sysP.noutputs - n_y
        self.structure, self.st = structure, st
        self.ec, self.er = st._embeddings()  # rows / cols of N inside the padded square problem
        self.npad = st.padded_size
        self._cache = {}
        self._diag = _diagonal_blocks(st)
        # Stability is decided by the loop of the *minimal* u -> y channel: the
        # other modes of P (e.g. the weights' states, unobservable from y)
        # are closed-loop poles whatever K is.  Without them the spectral
        # abscissa is not pinned at the slowest weight pole and its gradient
        # is informative.
        nw, nz = self.nw, self.nz
        A, B2, C2, D22 = self.A, self.B[:, nw:], self.C[nz:], self.D[nz:, nw:]
        try:
            g = control.minreal(control.ss(A, B2, C2, D22), verbose=False) if A.size else None
        except Exception:  # noqa: BLE001 - keep the full channel
            g = None
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
            n = self.A.shape[0]
            s = 1j * omega
            X = np.linalg.solve(s[:, None, None] * np.eye(n) - self.A, np.broadcast_to(self.B, (s.size,) + self.B.shape))
            H = self.C @ X + self.D
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
            R = np.linalg.solve(Iy - P22 @ K, P21)            # (I - P22 K)^-1 P21
            N = P11 + P12 @ (K @ R)
            if not jac:
                return N
            L = np.swapaxes(np.linalg.solve(np.swapaxes(Iu - K @ P22, 1, 2), np.swapaxes(P12, 1, 2)), 1, 2)
        return N, L, R, dK

    # ---------------------------------------------------------------- A_cl
    @staticmethod
    def _close(A, B2, C2, D22, Ak, Bk, Ck, Dk):
        R = np.eye(C2.shape[0]) - D22 @ Dk
        Yx, Yk = np.linalg.solve(R, C2), np.linalg.solve(R, D22 @ Ck)
        return np.block([[A + B2 @ Dk @ Yx, B2 @ (Ck + Dk @ Yk)], [Bk @ Yx, Ak + Bk @ Yk]])

    def closed_loop_matrix(self, theta, *, full=False) -> np.ndarray:
        """``A`` of ``lft(P, K(θ))`` (``full``) or of the loop of the minimal ``u -> y`` channel."""
        K = self.structure.realization(theta)
        if full:
            nw, nz = self.nw, self.nz
            return self._close(self.A, self.B[:, nw:], self.C[nz:], self.D[nz:, nw:], *K)
        return self._close(*self.G22, *K)

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


def closed_loop_response(P, K, omega, *, n_u: Optional[int] = None, n_y: Optional[int] = None) -> np.ndarray:
    """``lft(P, K)(jω)`` as an ``(N, n_out, n_in)`` array, computed from ``P(jω)`` and ``K(jω)``.

    A cross-check of the K-step's algebra against :func:`polyrob.plant.lft`.

    Examples
    --------
    >>> import control, numpy as np
    >>> from polyrob.synthesis.fixed import closed_loop_response
    >>> P = control.ss([[0.0]], [[1.0, 1.0]], [[1.0], [1.0]], np.zeros((2, 2)))
    >>> H = closed_loop_response(P, -2.0, [1.0, 2.0], n_u=1, n_y=1)   # 1/(s + 2)
    >>> np.round(H[:, 0, 0], 6).tolist()
    [(0.4-0.2j), (0.25-0.25j)]
    """
    sysP, n_u, n_y = _plant_parts(P, n_u, n_y)
    omega = np.asarray(omega, float).ravel()
    Hp = np.moveaxis(np.asarray(sysP(1j * omega, squeeze=False)).reshape(sysP.noutputs, sysP.ninputs, -1), -1, 0)
    if isinstance(K, control.LTI):
        Kw = np.moveaxis(np.asarray(K(1j * omega, squeeze=False)).reshape(n_u, n_y, -1), -1, 0)
    else:
        Kw = np.broadcast_to(np.atleast_2d(np.asarray(K, float)), (omega.size, n_u, n_y)).astype(complex)
    nz, nw = sysP.noutputs - n_y, sysP.ninputs - n_u
    P11, P12, P21, P22 = Hp[:, :nz, :nw], Hp[:, :nz, nw:], Hp[:, nz:, :nw], Hp[:, nz:, nw:]
    return P11 + P12 @ Kw @ np.linalg.solve(np.eye(n_y) - P22 @ Kw, P21)


def _plant_parts(P, n_u, n_y):
    from polyrob.plant.generalized import GeneralizedPlant

    if isinstance(P, GeneralizedPlant):
        return P.system, P.n_u, P.n_y
    if isinstance(P, control.StateSpace):
        if n_u is None or n_y is None:
            raise PolyrobError("a bare StateSpace plant needs n_u and n_y")
        if P.dt not in (0, None):
            raise PolyrobError("the plant must be continuous-time")
        return P, int(n_u), int(n_y)
    raise PolyrobError(f"fixed_structure_musyn needs a GeneralizedPlant or a StateSpace, got {type(P).__name__}")


# ============================================================ K-step
def _abscissa_grad(loop: _Loop, theta, S) -> tuple[float, np.ndarray]:
    """Spectral abscissa and a finite-difference gradient in scaled units."""
    a0 = loop.abscissa(theta)
    g = np.zeros(theta.size)
    h = 1e-6
    for p in range(theta.size):
        e = np.zeros(theta.size)
        e[p] = h * S[p]
        g[p] = (loop.abscissa(theta + e) - a0) / h
    return a0, g


def _kstep(loop: _Loop, theta0, sc: _Scalings, opts: FixedStructureOptions, radius: float):
    """SLSQP on the epigraph form of ``min max_ω β_ω(θ)`` in a trust region.

    ``β_ω`` is the μ bound with re-optimised scalings (``opts.kstep == "live"``)
    or with the scalings ``sc`` frozen.  Returns the best stable point
    evaluated (not SLSQP's last iterate), the starting peak and SLSQP's message.
    """
    S = loop.structure.scale(theta0)
    b0 = _majorant(loop, theta0, sc, n_eig=1)[:, 0]
    peak0 = float(np.max(b0))
    if not np.isfinite(peak0) or peak0 <= 0:
        return theta0, peak0, "non-finite majorant"
    n = theta0.size
    k = max(1, int(opts.n_eig))
    # frequencies far below the peak are dropped from the QP (they are checked after)
    active = np.flatnonzero(b0 >= opts.active_ratio * peak0)
    cache = {}
    a_scale = max(abs(loop.abscissa(theta0)), 1e-3)
    live = opts.kstep == "live" and loop._diag is not None
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
                ref = _refine_scalings(loop, th, warm[0], np.arange(active.size), maxiter=opts.live_iter)
                warm[0] = ref
                beta, dbeta = _majorant(loop, th, ref, n_eig=k, jac=True)
            else:
                beta, dbeta = _majorant(loop, th, sc, active, n_eig=k, jac=True)
            a, ga = _abscissa_grad(loop, th, S)
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
            res = minimize(lambda x: x[n], x0, jac=lambda x: np.eye(n + 1)[n], method="SLSQP",
                           bounds=bounds, constraints=[{"type": "ineq", "fun": cons, "jac": cons_jac}],
                           options={"maxiter": int(opts.kstep_iter), "ftol": 1e-8})
            msg = str(res.message)
        except (ValueError, np.linalg.LinAlgError) as exc:
            msg = f"SLSQP failed: {exc}"
    return best[1], peak0, msg


# ============================================================ stabilisation
def _stabilise(loop: _Loop, theta, min_decay: float, max_iter: int = 300, restarts: int = 4, seed: int = 0):
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
        base = best[0] if attempt == 0 else best[0] + 0.1 * loop.structure.scale(best[0]) * rng.standard_normal(theta.size)
        S = loop.structure.scale(base)

        def f(x):
            th = base + S * x
            v = loop.abscissa(th)
            if v < best[1]:
                best[:] = [th, v]
            return v if np.isfinite(v) else 1e6

        def g(x):
            return _abscissa_grad(loop, base + S * x, S)[1]

        def stop(intermediate_result):
            if best[1] <= target:
                raise StopIteration

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                minimize(f, np.zeros(theta.size), jac=g, method="BFGS", callback=stop,
                         options={"maxiter": max_iter, "gtol": 1e-12})
            except (ValueError, np.linalg.LinAlgError):
                pass
        if best[1] <= target:
            break
    return best[0], best[1]


# ============================================================ default start
def _default_controller(sysP, n_u, n_y, eps=1e-2):
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


# ============================================================ main loop
def _check_grid(omega, name):
    if omega is None:
        return None
    w = np.unique(np.asarray(omega, float).ravel())
    if w.size < 3 or np.any(w < 0) or not np.all(np.isfinite(w)) or not np.any(w > 0):
        raise PolyrobError(f"{name} must hold at least 3 finite non-negative frequencies")
    return w


def _grid_span(loop: _Loop, theta, omega) -> tuple[float, float]:
    if omega is not None:
        w = np.asarray(omega, float)
        w = w[w > 0]
        return float(w.min()), float(w.max())
    f = np.concatenate([loop.pole_frequencies(theta), [1.0]])
    f = f[(f > 1e-8) & (f < 1e8)]
    return 10 ** (np.floor(np.log10(f.min())) - 1), 10 ** (np.ceil(np.log10(f.max())) + 1)


def _log_grid(lo, hi, density):
    k = max(int(round(density * math.log10(hi / lo))), 2) + 1
    return np.logspace(math.log10(lo), math.log10(hi), k)


@dataclass
class _Run:
    """Mutable state of one start (private: the loop updates it in place)."""

    theta: np.ndarray
    sc: _Scalings
    peak: float
    history: list = field(default_factory=list)
    gammas: list = field(default_factory=list)
    iterations: int = 0
    notes: list = field(default_factory=list)


def _refine_points(sc: _Scalings, n_peaks=3, min_gap=1e-2) -> np.ndarray:
    """Log-midpoints next to the highest local maxima of the grid bound."""
    mu, lw = sc.mu, np.log10(sc.omega)
    F = mu.size
    peaks = [i for i in range(F) if (i == 0 or mu[i] >= mu[i - 1]) and (i == F - 1 or mu[i] >= mu[i + 1])]
    peaks = sorted(peaks, key=lambda i: -mu[i])[:n_peaks]
    new = []
    for i in peaks:
        for j in (i - 1, i + 1):
            if 0 <= j < F and abs(lw[j] - lw[i]) > min_gap:
                new.append(10 ** (0.5 * (lw[i] + lw[j])))
    return np.unique(np.array(new, float))


def _screen_points(loop: _Loop, theta, screen: np.ndarray) -> np.ndarray:
    """The screening grid plus points around every closed-loop pole and beyond the fastest one.

    Not clipped to the working span: the optimiser moves the controller's
    poles, and a PIDF whose filter pole went to 6e4 rad/s had its μ peak
    there, a decade outside the initial span, where a span-limited screen
    never looked (measured on the paper's 2R: grid μ 1.77, certificate on
    ``mu_bounds``' pole-based grid 3.07).
    """
    pf = loop.pole_frequencies(theta)
    pf = pf[(pf > 1e-9) & (pf < 1e9)]
    around = (pf[:, None] * np.array([0.5, 0.71, 1.0, 1.41, 2.0])[None, :]).ravel()
    hi = [10.0 * pf.max(), 100.0 * pf.max()] if pf.size else []
    w = np.union1d(screen, np.concatenate([around, hi]))
    return w[w > 0]


def _screen(loop: _Loop, run: _Run, screen: np.ndarray, blk, opts) -> int:
    """Rigorously check a fine grid with the nearest scalings; analyse and add the frequencies that fail."""
    w = _screen_points(loop, run.theta, screen)
    w = w[~np.isin(w, run.sc.omega)]
    if w.size == 0:
        return 0
    idx = run.sc.nearest(w)
    near = run.sc.take(idx)
    near = replace(near, omega=w)
    beta = _majorant(loop, run.theta, near, n_eig=1)[:, 0]
    fail = np.flatnonzero(beta > run.peak * (1 + 1e-9))
    if fail.size == 0:
        return 0
    # worst first, a bounded number per call (each costs an AB13MD call)
    fail = fail[np.argsort(-beta[fail])][:12]
    new = _dstep(loop, run.theta, w[fail], blk)
    run.sc = run.sc.merged(new)
    run.peak = float(np.max(run.sc.mu))
    return int(fail.size)


def _bound(loop: _Loop, theta, sc: _Scalings, blk, opts, *, exact: bool = False) -> _Scalings:
    """The grid bound at ``θ``: scalings refreshed where the stale majorant is near its peak.

    Elsewhere the majorant with the old scalings is itself the (valid) bound.
    ``exact`` refreshes with AB13MD (kept only where it improves), otherwise
    with the warm-started batched BFGS of :func:`_refine_scalings`.
    """
    beta = _majorant(loop, theta, sc, n_eig=1)[:, 0]
    sc = replace(sc, mu=beta)
    if not np.any(np.isfinite(beta)):
        return sc
    ratio = opts.exact_ratio if exact else opts.dstep_ratio
    sel = np.flatnonzero(beta >= ratio * float(np.max(beta[np.isfinite(beta)])))
    sel = np.union1d(sel, np.flatnonzero(~np.isfinite(beta)))
    if exact or loop._diag is None:
        fresh = _dstep(loop, theta, sc.omega[sel], blk)
        fresh = fresh.take(np.flatnonzero(fresh.mu < sc.mu[sel]))
    else:
        fresh = _refine_scalings(loop, theta, sc, sel)
    return sc.merged(fresh)


def _screen_check(loop: _Loop, theta, sc: _Scalings, screen: np.ndarray, level: float):
    """Is the bound below ``level`` on the fine screening grid (and at the closed-loop pole frequencies)?

    Every frequency first gets the nearest grid scalings (a rigorous bound
    for free); those above ``level`` get a warm-started scaling update.
    Returns ``(ok, scalings of the frequencies that needed the update)``:
    a step that creates a resonance between grid points is thereby refused
    instead of being discovered one iteration later.
    """
    w = _screen_points(loop, theta, screen)
    w = w[~np.isin(w, sc.omega)]
    if w.size == 0:
        return True, None
    near = replace(sc.take(sc.nearest(w)), omega=w)
    beta = _majorant(loop, theta, near, n_eig=1)[:, 0]
    fail = np.flatnonzero(~(beta < level))
    if fail.size == 0:
        return True, None
    if loop._diag is None:
        return False, None
    fixed = _refine_scalings(loop, theta, near, fail)
    return bool(np.all(fixed.mu < level)), fixed


def _accept(loop: _Loop, theta0, theta1, sc: _Scalings, peak0: float, blk, opts, screen, halvings: int = 4):
    """Backtrack from ``theta1`` towards ``theta0`` until the loop is stable and the bound decreased.

    "Decreased" on the working grid and, rigorously, on the screening grid.
    """
    step = theta1 - theta0
    for _ in range(halvings + 1):
        th = theta0 + step
        if loop.abscissa(th) <= -opts.min_decay and loop.abscissa(th, full=True) < 0:
            new = _bound(loop, th, sc, blk, opts)
            level = peak0 * (1 - 1e-9)
            if float(np.max(new.mu)) < level:
                ok, extra = _screen_check(loop, th, new, screen, level)
                if ok:
                    return th, (new if extra is None else new.merged(extra))
        step = 0.5 * step
    return None, sc


def _optimise(loop: _Loop, run: _Run, blk, opts: FixedStructureOptions, max_iter: int, screen: np.ndarray,
              report: Callable[[dict], None], label: str, target: Optional[float] = None):
    radius = opts.trust_region
    stall = 0
    for _ in range(max_iter):
        if target is not None and run.peak <= target:
            break
        t0 = time.perf_counter()
        old = run.peak
        theta_new, _, msg = _kstep(loop, run.theta, run.sc, opts, radius)
        theta_new, sc = _accept(loop, run.theta, theta_new, run.sc, run.peak, blk, opts, screen)
        run.iterations += 1
        if theta_new is None:
            # no decrease within the trust region: shrink it and refresh the
            # scalings with AB13MD in case the warm-started ones are what stalls
            radius *= 0.3
            run.notes.append(f"iteration {run.iterations}: step rejected ({msg}); trust radius {radius:.3g}")
            sc = _bound(loop, run.theta, run.sc, blk, opts, exact=True)
            stall += 1
        else:
            run.theta = theta_new
            grown = float(np.max(sc.mu)) < 0.97 * old
            radius = min(2.0 * radius, 4.0 * opts.trust_region) if grown else radius
        ref = _refine_points(sc)
        ref = ref[~np.isin(ref, sc.omega)]
        if ref.size:
            sc = sc.merged(_dstep(loop, run.theta, ref, blk))
        run.sc = sc
        run.peak = float(np.max(sc.mu))
        added = _screen(loop, run, screen, blk, opts)
        run.history.append(run.peak)
        run.gammas.append(run.peak)
        report({"start": label, "iteration": run.iterations, "peak_mu": run.peak, "kstep": msg,
                "grid": int(run.sc.omega.size), "screen_added": added, "radius": radius,
                "seconds": time.perf_counter() - t0})
        if theta_new is not None:
            stall = stall + 1 if run.peak > old * (1 - opts.tol) else 0
        if stall >= opts.patience or radius < 1e-4:
            break
    return run


def _reporter(progress) -> Callable[[dict], None]:
    if callable(progress):
        return progress
    if progress:
        def out(d):
            print(f"[fixed {d['start']}] it {d['iteration']:3d}  peak mu {d['peak_mu']:.5f}  grid {d['grid']}"
                  f"  (+{d['screen_added']})  {d['seconds']:.2f}s  r {d['radius']:.3g}  {d['kstep']}", file=sys.stderr, flush=True)
        return out
    return lambda d: None


def fixed_structure_musyn(
    P,
    blk=None,
    structure: Union[str, ControllerStructure] = "tf3",
    *,
    starts: int = 5,
    seed: int = 0,
    max_iter: int = 40,
    omega=None,
    certify_omega=None,
    init=None,
    initial_controller=None,
    progress=None,
    tol: Optional[float] = None,
    target: Optional[float] = None,
    mixed: Optional[bool] = None,
    n_u: Optional[int] = None,
    n_y: Optional[int] = None,
    options: Optional[FixedStructureOptions] = None,
) -> MusynResult:
    """Fixed-structure μ-synthesis (MATLAB ``musyn`` with a tunable controller).

    Parameters
    ----------
    P : GeneralizedPlant or control.StateSpace
        Inputs ``[d; w; u]``, outputs ``[v; z; y]``.  A bare ``StateSpace``
        needs ``n_u`` and ``n_y`` (the last inputs / outputs).
    blk : BlockStructure or array_like, optional
        Structure of ``diag(Δ, Δ_perf)`` for ``lft(P, K)``; default
        ``P.block_structure_rp`` (robust performance).
    structure : str or ControllerStructure
        ``"tfN"`` (each ``K_ij`` of order ``N``), ``"pid"`` or ``"ss:N"``
        (:func:`~polyrob.synthesis.structures.controller_structure`).
    starts : int
        Number of starts: ``init`` (or a generic H2 design fitted to the
        structure), then random perturbations of it.
    seed : int
        Seed of the perturbations: same seed, same result.
    max_iter : int
        D-G-K iterations per start.
    omega : array_like, optional
        Working (D-step) grid, refined around the peaks as the iteration
        goes; its span also sets the rigorous screening grid (40 points per
        decade).  Default: ``grid_density`` points per decade over the
        closed-loop poles of the first start, widened by a decade each side.
    certify_omega : array_like, optional
        Grid of the final certificate (:func:`~polyrob.analysis.mu.mu_bounds`, which
        refines the peak); default ``mu_bounds``' own grid for the final
        closed loop.  Also screened during the iteration.
    init : "paper", LTI system, MusynResult, array, or None
        Starting controller, fitted to the structure; ``"paper"`` is the
        paper's ``K*`` (:func:`~polyrob.plant.paper_controller`), represented
        exactly by ``"tf3"``.  A lower-order result (e.g. a ``"pid"``, which
        is an exact ``"ss:4"``) is a start for a richer structure.
    initial_controller : LTI system, optional
        Alias of ``init`` (the name :func:`polyrob.synthesis.dk.musyn` forwards).
    progress : bool or callable, optional
        ``True`` prints one line per iteration on stderr; a callable gets a
        dict per iteration.
    tol : float, optional
        Overrides ``options.tol`` (relative progress below which an
        iteration counts as stalled).
    target : float, optional
        Stop a start once its grid peak is below ``target``.
    mixed : bool, optional
        ``False`` treats every real block as complex (plain D-K); default:
        real blocks stay real (D-G-K).
    n_u, n_y : int, optional
        Sizes for a bare ``StateSpace`` plant.
    options : FixedStructureOptions, optional

    Returns
    -------
    MusynResult
        ``peak_mu`` is the peak of the certificate :func:`~polyrob.analysis.mu.mu_bounds`
        of ``lft(P, K)``; ``info`` holds ``theta``, the structure's
        coefficients (``"coefficients"``, for ``"tfN"`` the ``num``/``den`` of
        every ``K_ij``), the per-start summary and the grids.

    Raises
    ------
    PolyrobError
        Unknown structure (the message lists the valid ones), bad sizes.
    SynthesisError
        No start could be made to stabilise the closed loop.

    Examples
    --------
    See the module docstring.
    """
    t_start = time.perf_counter()
    opts = options or FixedStructureOptions()
    if tol is not None:
        opts = replace(opts, tol=float(tol))
    sysP, n_u, n_y = _plant_parts(P, n_u, n_y)
    strc = controller_structure(structure, n_u, n_y)
    if blk is None:
        if not hasattr(P, "block_structure_rp"):
            raise PolyrobError("give blk for a bare StateSpace plant")
        blk = P.block_structure_rp
    st = as_block_structure(blk)
    if mixed is False and st.has_real:
        # complex μ: every real block becomes a complex one of the same size
        st = as_block_structure([[b.rows, 0] if b.kind == "real" else list(b.matlab) for b in st.blocks])
    if st.m_shape != (sysP.noutputs - n_y, sysP.ninputs - n_u):
        raise PolyrobError(f"blk {st} needs a {st.m_shape} closed loop; lft(P, K) is "
                           f"{sysP.noutputs - n_y}x{sysP.ninputs - n_u}")
    if int(starts) < 1:
        raise PolyrobError(f"starts must be >= 1, got {starts}")
    omega, certify_omega = _check_grid(omega, "omega"), _check_grid(certify_omega, "certify_omega")
    if init is not None and initial_controller is not None:
        raise PolyrobError("give init or initial_controller, not both")
    init = initial_controller if init is None else init
    report = _reporter(progress)
    loop = _Loop(sysP, n_u, n_y, strc, st)

    with single_blas_thread():
        # ---------------------------------------------------------- starts
        if isinstance(init, str):
            if init != "paper":
                raise PolyrobError(f"init must be 'paper', a controller or None, got {init!r}")
            from polyrob.plant.generalized import paper_controller

            init = paper_controller()
        if isinstance(init, MusynResult):
            init = init.controller
        if init is not None:
            theta0 = strc.from_controller(init)
            origin = "init"
        else:
            try:
                theta0 = strc.from_controller(_default_controller(sysP, n_u, n_y))
                origin = "h2"
            except Exception:  # noqa: BLE001 - e.g. an unstabilisable test plant: go random
                theta0 = strc.initial(int(seed))
                origin = "random"
        rng_seeds = np.random.default_rng(int(seed)).integers(0, 2**31 - 1, size=int(starts))
        candidates = [(origin, theta0)] + [
            (f"perturbed#{k}", strc.initial(int(rng_seeds[k]), around=theta0, spread=opts.spread))
            for k in range(1, int(starts))
        ]

        runs, failures = [], []
        span = None
        for label, th in candidates:
            th, a = _stabilise(loop, th, opts.min_decay)
            if not a <= -opts.min_decay:
                failures.append(f"{label}: spectral abscissa {a:.3g}")
                continue
            a_full = loop.abscissa(th, full=True)
            if not a_full < 0:
                # modes of P that no controller moves (not in the u -> y channel)
                failures.append(f"{label}: P has unstable modes outside the u -> y channel "
                                f"({np.round(loop.fixed_modes[loop.fixed_modes.real >= 0], 4).tolist()})")
                continue
            if span is None:
                span = _grid_span(loop, th, omega)
                work = omega if omega is not None else _log_grid(*span, opts.grid_density)
                screen = _log_grid(*span, opts.screen_density)
                if certify_omega is not None:
                    screen = np.union1d(screen, certify_omega[certify_omega > 0])
            sc = _dstep(loop, th, work, st)
            run = _Run(theta=th, sc=sc, peak=float(np.max(sc.mu)))
            run.history.append(run.peak)
            _screen(loop, run, screen, st, opts)
            run.history[-1] = run.peak
            _optimise(loop, run, st, opts, int(max_iter), screen, report, label, target)
            run.notes.insert(0, label)
            runs.append(run)
        if not runs:
            raise SynthesisError(
                f"no start stabilises the closed loop with a {strc.name} controller "
                f"({'; '.join(failures)}); try another structure, a higher order or an init controller"
            )
        best = min(runs, key=lambda r: r.peak)

        # ---------------------------------------------------------- certify
        cert = None
        for rnd in range(opts.certify_rounds + 1):
            K = strc.controller(best.theta)
            from polyrob.plant.generalized import lft

            N = lft(P, K) if hasattr(P, "block_structure_rp") else lft(sysP, K, n_u=n_u, n_y=n_y)
            cert = mu_bounds(N, st, certify_omega, progress=False)
            if cert.peak_upper <= best.peak * (1 + 1e-3) or rnd == opts.certify_rounds:
                break
            # a peak the grids missed: take its scalings, iterate a little more
            i = int(np.argmax(cert.upper))
            extra = _scalings_from(cert.D[[i]], cert.G[[i]], cert.omega[[i]], cert.upper[[i]])
            best.sc = best.sc.merged(extra)
            best.peak = float(np.max(best.sc.mu))
            best.notes.append(f"certificate round {rnd}: peak {cert.peak_upper:.5g} at {cert.omega[i]:.4g} rad/s "
                              "above the grid peak; added")
            screen = np.union1d(screen, cert.omega[cert.omega > 0])
            _optimise(loop, best, st, opts, max(3, int(max_iter) // 4), screen, report, "certify", target)

    poles = np.linalg.eigvals(np.asarray(N.A)) if N.nstates else np.zeros(0)
    if poles.size and np.max(poles.real) >= 0:  # pragma: no cover - guarded by every accepted step
        raise SynthesisError("the final closed loop is not stable")
    seconds = time.perf_counter() - t_start
    info = {
        "method": f"D-G-K over per-frequency scalings ({opts.kstep} K-step: SLSQP epigraph, trust region, "
                  "closed-loop spectral abscissa constraint; scalings by warm-started batched BFGS and "
                  "AB13MD); adaptive grid with rigorous screening; certificate by mu_bounds",
        "theta": best.theta.tolist(),
        "coefficients": strc.describe(best.theta),
        "start": best.notes[0] if best.notes else "",
        "starts": [{"start": r.notes[0] if r.notes else "", "grid_peak_mu": r.peak, "iterations": r.iterations}
                   for r in runs],
        "failed_starts": failures,
        "notes": best.notes[1:],
        "grid_omega": best.sc.omega.copy(),
        "certify_omega": None if certify_omega is None else certify_omega.copy(),
        "block_structure": st.matlab.tolist(),
        "closed_loop_poles": poles,
    }
    return MusynResult(
        controller=K, structure=strc.name, order=int(K.nstates),
        peak_mu=float(cert.peak_upper), peak_mu_lower=float(cert.peak_lower),
        peak_frequency=float(cert.peak_upper_frequency),
        mu_history=np.array(best.history + [cert.peak_upper], float),
        gamma_history=np.array(best.gammas, float),
        scalings=(best.sc.omega.copy(), best.sc.Dm.copy(), best.sc.G.copy()),
        closed_loop=N, certificate=cert, iterations=int(best.iterations), seconds=seconds, info=info,
    )
