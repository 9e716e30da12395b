"""Full-order μ-synthesis by D-K iteration (complex μ) and D-G-K iteration (mixed μ).

:func:`musyn` alternates, like MATLAB's ``musyn``,

* a **D-step**: the μ upper bound of the closed loop ``N = Fl(P, K)`` on a
  frequency grid, with its scalings ``D(ω)`` (and ``G(ω)`` for real
  parameters), computed by SLICOT AB13MD through :func:`polyrob.analysis.mu.mussv`;
* a **fit**: per-block stable, minimum-phase rational filters of the lowest
  order that reproduces the bound (:mod:`polyrob.synthesis.dscale`);
* a **K-step**: H∞ synthesis (:func:`polyrob.synthesis.hinf.hinfsyn`) for the
  plant scaled by the fitted filters.

The three steps are strategy objects (:class:`MuUpperBound`,
:class:`~polyrob.synthesis.dscale.LogMagnitudeFit`, :class:`HinfStep`)
passed to :class:`DKIteration`, as in dkpy's ``dk_iteration.py``, so other
bounds, fits or synthesis methods plug in without touching the loop.

Complex vs mixed.  ``mixed=False`` treats every real parameter as a complex
scalar (classical D-K: conservative for real parameters).  ``mixed=True``
(the default when the structure has real blocks) is a D-G-K iteration
(Young 1996): the G scalings of the mixed-μ upper bound are fitted too and
enter the K-step through the J-spectral factorisation of the D-G multiplier
described in :mod:`polyrob.synthesis.dscale`.  It starts with D-K steps
while they gain more than ``switch_tol`` per iteration (a G step cannot
push the scaled norm below ``max|F|``, so it refines but does not rescue a
poor controller) and continues with D-G-K steps, each guarded: the old
controller must stabilise the G-transformed plant, and a G step that fails
falls back on a D step.  Whatever the iteration, the controller is finally
**certified** with :func:`polyrob.analysis.mu.mu_bounds` against the structure
``blk`` (real blocks as real) on a peak-refined grid: that number is
:attr:`~polyrob.synthesis.result.MusynResult.peak_mu`.

Safeguards of the loop: the best controller seen is kept (μ can go up);
a K-step whose controller does not stabilise ``P``, or whose scaled H∞ norm
exceeds the old controller's on the same scaled plant by more than 25%, is
rejected (a numerically failed synthesis); the two best controllers are
certified when the first one's certificate exceeds its grid value by 2%.
"""

from __future__ import annotations

import math
import re
import sys
import time
from dataclasses import dataclass
from typing import Callable, Optional, Sequence

import control
import numpy as np

from polyrob.analysis.blocks import BlockStructure, as_block_structure
from polyrob.errors import PolyrobError, SynthesisError
from polyrob.synthesis.dscale import LogMagnitudeFit, ScalingData, Scalings, scaled_plant, scaling_data
from polyrob._threads import single_blas_thread
from polyrob.synthesis.hinf import HinfResult, _lft_mats, _is_stable, hinfsyn
from polyrob.synthesis.result import MusynResult

__all__ = [
    "musyn",
    "DKIteration",
    "MuUpperBound",
    "HinfStep",
    "certify",
    "frequency_grid",
    "performance_lower_bound",
]


# ================================================================ strategies
class MuUpperBound:
    """D-step strategy: μ upper bound and its scalings at each frequency.

    Parameters
    ----------
    method : {"auto", "ab13md", "lmi"}
        Passed to :func:`polyrob.analysis.mu.mussv` (AB13MD whenever it applies).
    n_jobs : int, optional
        Worker processes for the sweep (see :class:`~polyrob.synthesis.dscale.MuSweep`;
        default serial).

    Calling it with a frequency-response stack ``H`` (``(n, rows, cols)``)
    and a structure returns ``(mu, D, G)`` with ``D``, ``G`` on the padded
    problem (``(n, k, k)``).
    """

    def __init__(self, method: str = "auto", n_jobs: Optional[int] = None):
        from polyrob.synthesis.dscale import MuSweep

        self.method = method
        self.sweep = MuSweep(n_jobs=n_jobs, method=method)

    def __call__(self, H: np.ndarray, blk) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(mu, D, G)`` at every frequency (padded scalings)."""
        st = as_block_structure(blk)
        self.last_complex = None
        if not st.has_real:
            return self.sweep(H, st)
        return self._mixed(H, st)

    def _mixed(self, H, st):
        """Mixed bound by pruning with the (cheaper) complex bound.

        Mixed μ <= complex μ, so only frequencies whose complex bound exceeds
        the largest mixed bound found so far can hold the mixed peak: they
        are visited in decreasing order of the complex bound, and the others
        keep their complex scalings (``G = 0``), which certify a level below
        the peak.  The peak is exact; AB13MD with ten real blocks costs about
        twice the complex call, and typically a third of the grid is visited.
        The complex bound and scalings are kept in :attr:`last_complex` for
        the D-only route of the fit.
        """
        stc = _complexify(st)
        c, Dc, _ = self.sweep(H, stc)
        mu = c.copy()
        D = Dc.copy()
        G = np.zeros_like(Dc)
        order = np.argsort(-c)
        best = 0.0
        todo = []
        for k in order:
            if c[k] <= best:
                break
            todo.append(k)
            if len(todo) >= 4:  # in small batches: best tightens as we go
                m, Dm, Gm = self.sweep(H[todo], st)
                mu[todo], D[todo], G[todo] = m, Dm, Gm
                best = max(best, float(m.max()))
                todo = []
        if todo:
            m, Dm, Gm = self.sweep(H[todo], st)
            mu[todo], D[todo], G[todo] = m, Dm, Gm
        self.last_complex = (c, Dc, stc)
        return mu, D, G

    def close(self):
        """Stop the worker process, if any."""
        self.sweep.close()


class HinfStep:
    """K-step strategy: :func:`~polyrob.synthesis.hinf.hinfsyn` on the scaled plant.

    Parameters
    ----------
    tol : float
        Relative tolerance of the γ bisection.  MATLAB's ``hinfsyn`` uses
        1e-2, but late D-K iterations gain a few tenths of a percent each:
        a 1% suboptimal K-step would hide them.
    method : {"auto", "riccati", "lmi"}
    epsilon : float
        Regularisation ε, see :func:`~polyrob.synthesis.hinf.hinfsyn`.
    """

    def __init__(self, tol: float = 1e-3, method: str = "auto", epsilon: float = 1e-4):
        self.tol, self.method, self.epsilon = tol, method, epsilon

    def __call__(self, P: control.StateSpace, n_y: int, n_u: int) -> HinfResult:
        return hinfsyn(P, n_y, n_u, tol=self.tol, method=self.method, epsilon=self.epsilon)


# ================================================================== helpers
def frequency_grid(sys, per_decade: int = 8) -> np.ndarray:
    """Default D-K grid: the decades spanned by the plant's poles, one more each side.

    Poles at ``s = 0`` and near-integrators (below 1e-4 times the median
    pole magnitude, e.g. a weight's 1e-5 pole) do not widen the grid.

    Examples
    --------
    >>> import control
    >>> from polyrob.synthesis.dk import frequency_grid
    >>> w = frequency_grid(control.ss(control.tf([1], [1, 3, 2])))
    >>> float(w[0]), float(w[-1]), w.size
    (0.1, 100.0, 25)
    """
    A = np.asarray(sys.A, float)
    f = np.abs(np.linalg.eigvals(A)) if A.size else np.zeros(0)
    f = f[np.isfinite(f) & (f > 0)]
    if f.size:
        f = f[f >= 1e-4 * np.median(f)]
    if f.size == 0:
        lo, hi = -2.0, 2.0
    else:
        lo = math.floor(math.log10(f.min()) + 1e-9) - 1
        hi = math.ceil(math.log10(f.max()) - 1e-9) + 1
        if hi - lo < 2:
            lo, hi = lo - 1, hi + 1
    return np.logspace(lo, hi, int(per_decade * (hi - lo)) + 1)


def _resonances(A: np.ndarray, lo: float, hi: float, zeta: float = 0.5) -> np.ndarray:
    """Natural frequencies of lightly damped poles in ``[lo, hi]`` (peaks hide there)."""
    if A.size == 0:
        return np.zeros(0)
    ev = np.linalg.eigvals(A)
    wn = np.abs(ev)
    ok = (wn > 0) & (np.abs(ev.imag) > 0) & (-ev.real < zeta * wn) & (wn >= lo) & (wn <= hi)
    return np.unique(np.round(wn[ok], 12))


def _freqresp(A, B, C, D, omega) -> np.ndarray:
    """``C (jωI - A)^{-1} B + D`` as ``(n, p, m)`` via a Hessenberg-free direct solve."""
    n = A.shape[0]
    out = np.empty((omega.size, C.shape[0], B.shape[1]), complex)
    if n == 0:
        out[:] = D
        return out
    # eigen-decomposition when well conditioned (fast for many frequencies)
    lam, V = np.linalg.eig(A)
    if np.linalg.cond(V) < 1e8:
        Vi_B = np.linalg.solve(V, B)
        CV = C @ V
        for k, w in enumerate(omega):
            out[k] = (CV / (1j * w - lam)[None, :]) @ Vi_B + D
        return out
    I = np.eye(n)
    for k, w in enumerate(omega):
        out[k] = C @ np.linalg.solve(1j * w * I - A, B) + D
    return out


def _complexify(st: BlockStructure) -> BlockStructure:
    """Every real block as a complex (repeated) scalar of the same size."""
    rows = [[b.rows, 0] if b.kind == "real" else list(b.matlab) for b in st.blocks]
    return BlockStructure.from_matlab(rows)


def performance_lower_bound(P) -> tuple[float, float]:
    """A priori lower bound on robust-performance μ from ``W_S`` and ``W_T`` alone.

    ``S + T = I`` forces, for each channel ``k`` of diagonal weights,
    ``|w_S S_kk|^2 + |w_T T_kk|^2 >= |w_S w_T|^2/(|w_S|^2 + |w_T|^2)``, and the
    performance block of :attr:`~polyrob.plant.GeneralizedPlant.block_structure_rp`
    sees (at least) that stacked gain: no controller can do better.

    Returns
    -------
    (bound, frequency) : tuple of float
        ``(0, nan)`` when the plant has no ``W_S`` or no ``W_T``.

    Examples
    --------
    >>> import polyrob, polyrob.plant.weights
    >>> from polyrob.synthesis.dk import performance_lower_bound
    >>> pldi = polyrob.bound_pldi(polyrob.load_robot("paper_2r"), samples=256, coverage=0, progress=False)
    >>> P = polyrob.generalized_plant(polyrob.uncertain_plant(pldi), *polyrob.plant.weights.paper_weights())
    >>> b, w = performance_lower_bound(P)
    >>> bool(b < 1)
    True
    """
    from polyrob.plant.generalized import GeneralizedPlant

    if not isinstance(P, GeneralizedPlant) or P.W_S is None or P.W_T is None:
        return 0.0, float("nan")
    w = np.logspace(-6, 8, 1401)
    HS = _freqresp(*(np.asarray(X, float) for X in (P.W_S.A, P.W_S.B, P.W_S.C, P.W_S.D)), w)
    HT = _freqresp(*(np.asarray(X, float) for X in (P.W_T.A, P.W_T.B, P.W_T.C, P.W_T.D)), w)
    best, where = 0.0, float("nan")
    for k in range(HS.shape[1]):
        if np.any(HS[:, k, np.arange(HS.shape[2]) != k]) or np.any(HT[:, k, np.arange(HT.shape[2]) != k]):
            return 0.0, float("nan")  # not diagonal: no simple bound
        s, t = np.abs(HS[:, k, k]), np.abs(HT[:, k, k])
        b = s * t / np.sqrt(np.maximum(s * s + t * t, 1e-300))
        i = int(np.argmax(b))
        if b[i] > best:
            best, where = float(b[i]), float(w[i])
    return best, where


def certify(P, K, blk, omega=None, *, n_u=None, n_y=None):
    """Certified μ upper bound of ``Fl(P, K)`` on a peak-refined grid.

    Returns ``(peak_mu, peak_lower, peak_frequency, closed_loop, certificate)``;
    an unstable closed loop gives ``peak_mu = inf`` and ``certificate = None``
    (μ certifies nothing without nominal stability).
    """
    from polyrob.analysis.mu import mu_bounds
    from polyrob.plant.generalized import lft

    N = lft(P, K, n_u=n_u, n_y=n_y)
    A = np.asarray(N.A, float)
    if not _is_stable(A):
        return float("inf"), float("nan"), float("nan"), N, None
    if omega is None:
        omega = frequency_grid(P.system if hasattr(P, "system") else P, per_decade=15)
    omega = np.asarray(omega, float)
    w = np.union1d(omega, _resonances(A, omega.min(), omega.max()))
    r = mu_bounds(N, blk, omega=w, refine_peak=True, progress=False)
    return float(r.peak_upper), float(r.peak_lower), float(r.peak_upper_frequency), N, r


# ================================================================ the loop
@dataclass
class _Iter:
    K: control.StateSpace
    mu_peak: float
    gamma: float
    orders: list
    scalings: Optional[Scalings]
    seconds: dict
    notes: tuple
    phase: str = "D"


class DKIteration:
    """D-K / D-G-K iteration with pluggable D-step, fit and K-step.

    Parameters
    ----------
    mu_bound : MuUpperBound, optional
    d_fit : LogMagnitudeFit (or any callable ``(data, H, beta, use_g) -> Scalings``), optional
    hinf_step : HinfStep (or any callable ``(P, n_y, n_u) -> HinfResult``), optional
    max_iter : int
        Maximum number of K-steps.
    tol : float
        Stop when the best peak μ has improved by less than ``tol``
        (relative) over the last ``patience`` iterations.
    patience : int
    target : float, optional
        Stop as soon as the grid peak μ is below ``target``.
    progress : bool, optional
        One line per iteration (tqdm); default: only on a terminal.
    switch_tol : float
        Mixed problems: D-K steps while the peak improves by more than this
        (relative, per iteration), then D-G-K steps.

    Examples
    --------
    >>> import control
    >>> from polyrob.synthesis.dk import DKIteration, MuUpperBound, HinfStep
    >>> from polyrob.synthesis.dscale import LogMagnitudeFit
    >>> it = DKIteration(MuUpperBound(), LogMagnitudeFit(orders=(0, 1, 2)), HinfStep(), max_iter=5)
    >>> it.max_iter
    5
    """

    def __init__(self, mu_bound=None, d_fit=None, hinf_step=None, *, max_iter: int = 20,
                 tol: float = 1e-3, patience: int = 2, target: Optional[float] = None,
                 progress: Optional[bool] = None, switch_tol: float = 0.02):
        self.mu_bound = mu_bound or MuUpperBound()
        self.d_fit = d_fit or LogMagnitudeFit()
        self.hinf_step = hinf_step or HinfStep()
        self.max_iter, self.tol, self.patience = int(max_iter), float(tol), int(patience)
        self.target, self.progress = target, progress
        self.switch_tol = float(switch_tol)
        self.reject_ratio = 1.25
        if self.max_iter < 1:
            raise PolyrobError("max_iter must be >= 1")

    def _k_step(self, Ps, n_u, n_y, A, B, C, D, level_old, it):
        """H∞ step with safeguards: ``None`` if it fails, destabilises ``P`` or is worse than the old K."""
        try:
            hres = self.hinf_step(Ps, n_y, n_u)
        except SynthesisError as exc:
            self.failures.append(f"iteration {it + 1}: {exc}")
            return None
        Ak, Bk, Ck, Dk = (np.asarray(X, float) for X in (hres.K.A, hres.K.B, hres.K.C, hres.K.D))
        try:
            Acl, *_ = _lft_mats(A, B, C, D, Ak, Bk, Ck, Dk, n_u, n_y)
        except np.linalg.LinAlgError:
            Acl = None
        if Acl is None or not _is_stable(Acl):
            self.failures.append(f"iteration {it + 1}: the K-step controller does not stabilise P")
            return None
        if np.isfinite(level_old) and hres.gamma > level_old * self.reject_ratio:
            # the old controller does much better on the same scaled plant:
            # the synthesis went wrong.  (A few percent worse is normal: the
            # K-step solves the regularised problem, and its controller can
            # still lower μ, so it is kept.)
            self.failures.append(
                f"iteration {it + 1}: K-step gamma {hres.gamma:.4g} above the old controller's {level_old:.4g}")
            return None
        return hres

    def run(self, Psys: control.StateSpace, n_u: int, n_y: int, blk, omega, *, mixed: bool,
            initial_controller=None, callback: Optional[Callable] = None,
            start_phase: Optional[str] = None) -> list[_Iter]:
        """Run the iteration; returns the per-iteration records (best is the lowest ``mu_peak``).

        With ``mixed=True`` the iteration runs in two phases: D-K steps
        (complex bound, F = 0) while they still improve the peak by more than
        ``switch_tol`` per iteration, then D-G-K steps (mixed bound, G
        realised).  A D-G-K K-step cannot push the scaled H∞ norm below
        ``max|F|`` (the transformed loop tends to ``D F D^{-1}`` as ``N -> 0``),
        so it refines a controller but makes little progress from a poor one,
        where the homogeneous D-K step gains a factor 5 per iteration.
        """
        from tqdm import tqdm

        st = as_block_structure(blk)
        st_c = _complexify(st)
        phase = start_phase or "D"
        if phase not in ("D", "DG") or (phase == "DG" and not mixed):
            raise PolyrobError(f"start_phase must be 'D' (or 'DG' for mixed problems), got {start_phase!r}")
        omega = np.asarray(omega, float)
        A, B, C, D = (np.asarray(X, float) for X in (Psys.A, Psys.B, Psys.C, Psys.D))
        hist: list[_Iter] = []
        show = (sys.stderr.isatty() if self.progress is None else bool(self.progress))
        bar = tqdm(total=self.max_iter, disable=not show, desc="musyn", leave=False, file=sys.stderr)
        K = initial_controller
        gamma, notes, orders, scal = float("nan"), (), [], None
        t_fit = t_hinf = 0.0
        if K is None:
            t0 = time.perf_counter()
            hres = self.hinf_step(Psys, n_y, n_u)
            t_hinf = time.perf_counter() - t0
            K, gamma, notes = hres.K, hres.gamma, hres.regularization
        best = np.inf
        since_best = 0
        prev = np.inf
        self.failures = []
        from polyrob.synthesis import dscale as _dscale

        # the fits' complex D-steps share the D-step's worker
        _dscale._ACTIVE_SWEEP = getattr(self.mu_bound, "sweep", None)
        try:
            for it in range(self.max_iter):
                t0 = time.perf_counter()
                Ak, Bk, Ck, Dk = (np.asarray(X, float) for X in (K.A, K.B, K.C, K.D))
                try:
                    Acl, Bcl, Ccl, Dcl = _lft_mats(A, B, C, D, Ak, Bk, Ck, Dk, n_u, n_y)
                    stable = _is_stable(Acl)
                except np.linalg.LinAlgError:
                    stable = False
                if not stable:
                    rec = _Iter(K, np.inf, gamma, orders, scal, {"mu": 0.0, "fit": t_fit, "hinf": t_hinf}, notes,
                                phase)
                    hist.append(rec)
                    if show:
                        bar.write(f"musyn iter {it + 1}: closed loop unstable, stopping")
                    break
                w = np.union1d(omega, _resonances(Acl, omega.min(), omega.max()))
                H = _freqresp(Acl, Bcl, Ccl, Dcl, w)
                mu, Dw, Gw = self.mu_bound(H, st_c if phase == "D" else st)
                peak = float(np.max(mu))
                improvement = (prev - peak) / prev if np.isfinite(prev) else 1.0
                if mixed and phase == "D" and it > 0 and improvement < self.switch_tol:
                    # D-K has slowed down: continue with D-G-K from this controller
                    phase = "DG"
                    mu, Dw, Gw = self.mu_bound(H, st)
                    peak = float(np.max(mu))
                    best, since_best = np.inf, 0
                t_mu = time.perf_counter() - t0
                rec = _Iter(K, peak, gamma, orders, scal, {"mu": t_mu, "fit": t_fit, "hinf": t_hinf}, notes, phase)
                hist.append(rec)
                if callback is not None:
                    callback(rec)
                if peak < best * (1 - self.tol):
                    since_best = 0
                else:
                    since_best += 1
                best = min(best, peak)
                prev = peak
                if show:
                    bar.update(1)
                    bar.set_postfix(mu=f"{peak:.4f}", best=f"{best:.4f}", gamma=f"{gamma:.4g}", nK=K.nstates)
                    bound = "mixed" if phase == "DG" else "complex" if st.has_real else ""
                    bar.write(f"musyn iter {it + 1:2d}: peak mu {peak:.4f} {bound}(best {best:.4f}), "
                              f"gamma {gamma:.4g}, K order {K.nstates}, D/G orders {orders}, "
                              f"{sum(rec.seconds.values()):.1f} s")
                if it + 1 >= self.max_iter:
                    break
                if since_best >= self.patience:
                    if mixed and phase == "D":
                        phase = "DG"  # stalled D-K: the next D-step is mixed
                        best, since_best, prev = np.inf, 0, np.inf
                        mu, Dw, Gw = self.mu_bound(H, st)
                        peak = float(np.max(mu))
                        rec.mu_peak, rec.phase = peak, phase
                        best = peak
                    else:
                        break
                if self.target is not None and peak < self.target:
                    break
                # ---- fit
                t0 = time.perf_counter()
                use_g = phase == "DG"
                data = scaling_data(w, mu, Dw, Gw, st if use_g else st_c, M=H if use_g else None, beta=peak)
                if use_g:
                    cplx = getattr(self.mu_bound, "last_complex", None)
                    cmu = cd = None
                    if cplx is not None and cplx[0].shape[0] == w.size:
                        cmu = cplx[0]
                        cd = scaling_data(w, cplx[0], cplx[1], np.zeros_like(cplx[1]), cplx[2]).d
                    data = ScalingData(data.omega, data.mu, data.d, data.g, st, cmu, cd)
                scal = self.d_fit(data, H, peak, use_g)
                Ps = scaled_plant(Psys, scal, n_u, n_y)
                # The G route puts a feedback loop F around N inside the
                # scaled plant: the old controller must still stabilise it,
                # else the K-step has no feasible start and may return worse.
                level_old = _scaled_norm(Ps, K, n_u, n_y)
                if scal.has_g and not np.isfinite(level_old):
                    self.failures.append(f"iteration {it + 1}: G scalings destabilise the old loop; D route used")
                    scal = self.d_fit(data, H, peak, False) if not use_g else _d_route(self.d_fit, data, H, peak)
                    Ps = scaled_plant(Psys, scal, n_u, n_y)
                    level_old = _scaled_norm(Ps, K, n_u, n_y)
                orders = scal.orders[:-1]
                t_fit = time.perf_counter() - t0
                # ---- K step
                t0 = time.perf_counter()
                hres = self._k_step(Ps, n_u, n_y, A, B, C, D, level_old, it)
                if hres is None and scal.has_g:
                    # safeguarded D-G-K: a G step that fails falls back on a D step
                    scal = _d_route(self.d_fit, data, H, peak)
                    Ps = scaled_plant(Psys, scal, n_u, n_y)
                    orders = scal.orders[:-1]
                    hres = self._k_step(Ps, n_u, n_y, A, B, C, D, _scaled_norm(Ps, K, n_u, n_y), it)
                t_hinf = time.perf_counter() - t0
                if hres is None:
                    # no K-step improves on the current controller: stalled
                    if mixed and phase == "D":
                        phase, prev = "DG", np.inf
                        best, since_best = np.inf, 0
                        if show:
                            bar.write(f"musyn iter {it + 1}: D-K stalled; continuing with D-G-K")
                        continue
                    if show:
                        bar.write(f"musyn iter {it + 1}: no K-step improves on the current controller; stopping")
                    break
                K, gamma, notes = hres.K, hres.gamma, hres.regularization
        finally:
            bar.close()
            _dscale._ACTIVE_SWEEP = None
            close = getattr(self.mu_bound, "close", None)
            if close is not None:
                close()
        return hist


def _scaled_norm(Ps, K, n_u, n_y) -> float:
    """H∞ norm (fast estimate) of the scaled loop with ``K`` (``inf`` if unstable or ill posed)."""
    from polyrob.synthesis.hinf import hinf_norm_estimate

    A, B, C, D = (np.asarray(X, float) for X in (Ps.A, Ps.B, Ps.C, Ps.D))
    Ak, Bk, Ck, Dk = (np.asarray(X, float) for X in (K.A, K.B, K.C, K.D))
    try:
        Acl, Bcl, Ccl, Dcl = _lft_mats(A, B, C, D, Ak, Bk, Ck, Dk, n_u, n_y)
    except np.linalg.LinAlgError:
        return float("inf")
    if not _is_stable(Acl, 0.0):
        return float("inf")
    return hinf_norm_estimate(Acl, Bcl, Ccl, Dcl)


def _d_route(d_fit, data, H, beta):
    """The D-only fit of mixed data (complex D scalings of ``N/β``)."""
    call = getattr(d_fit, "d_route", None)
    if call is not None:
        return call(data, H, beta)
    return d_fit(data, H, beta, False)


# ================================================================== musyn
_STRUCT_RE = re.compile(r"^(full|pid|tf\d+|tfN|ss:\d+)$")


def _parse_plant(P, blk, n_u, n_y):
    from polyrob.plant.generalized import GeneralizedPlant

    if isinstance(P, GeneralizedPlant):
        Psys = P.system
        n_u = P.n_u if n_u is None else int(n_u)
        n_y = P.n_y if n_y is None else int(n_y)
        if blk is None:
            blk = P.block_structure_rp
    elif isinstance(P, control.StateSpace):
        Psys = P
        if n_u is None or n_y is None:
            raise PolyrobError("musyn of a bare StateSpace needs n_u and n_y")
        if blk is None:
            raise PolyrobError("musyn of a bare StateSpace needs blk")
    else:
        raise PolyrobError(f"musyn needs a GeneralizedPlant or a StateSpace, got {type(P).__name__}")
    st = as_block_structure(blk)
    nr, nc = st.m_shape
    if (Psys.noutputs - n_y, Psys.ninputs - n_u) != (nr, nc):
        raise PolyrobError(
            f"the plant has {Psys.noutputs - n_y} outputs and {Psys.ninputs - n_u} inputs besides y and u, "
            f"but the block structure {st} needs {nr} and {nc}"
        )
    if Psys.dt not in (0, None):
        raise PolyrobError("musyn: the plant must be continuous-time")
    return Psys, st, int(n_u), int(n_y)


def musyn(
    P,
    blk=None,
    *,
    structure: str = "full",
    mixed: Optional[bool] = None,
    max_iter: int = 20,
    tol: float = 1e-3,
    patience: int = 2,
    d_order: Sequence[int] = (0, 1, 2, 3, 4),
    g_order: Sequence[int] = (0, 1, 2),
    fit_tol: float = 0.01,
    omega=None,
    progress: Optional[bool] = None,
    target: Optional[float] = None,
    initial_controller=None,
    mu_bound=None,
    d_fit=None,
    hinf_step=None,
    certify_omega=None,
    check_weights: bool = True,
    n_u: Optional[int] = None,
    n_y: Optional[int] = None,
    **structure_options,
) -> MusynResult:
    """Robust controller by μ-synthesis (MATLAB's ``musyn``), with its μ certificate.

    Parameters
    ----------
    P : GeneralizedPlant or control.StateSpace
        The generalized plant; a ``StateSpace`` needs ``blk``, ``n_u``, ``n_y``
        (uncertainty/performance channels first, ``u`` and ``y`` last).
    blk : BlockStructure or array_like, optional
        Default: ``P.block_structure_rp`` (uncertainty blocks and the
        performance block).
    structure : str
        ``"full"`` (full-order D-K here) or a fixed structure (``"tf3"``,
        ``"tfN"``, ``"pid"``, ``"ss:N"``) handled by
        :func:`polyrob.synthesis.fixed.fixed_structure_musyn` (imported only
        then), which receives ``structure_options`` and those of ``mixed``,
        ``max_iter``, ``tol``, ``omega``, ``progress``, ``target``,
        ``initial_controller``, ``n_u``, ``n_y``, ``certify_omega`` that are
        set to a non-default value and that it accepts.
    mixed : bool, optional
        D-G-K with real blocks kept real; ``False``: every block complex
        (D-K).  Default: D-G-K when ``blk`` has real blocks.
    max_iter, tol, patience : int, float, int
        Stopping rules, see :class:`DKIteration`.
    d_order, g_order : sequence of int
        Candidate orders of the D and G fits (the lowest that fits is used).
    fit_tol : float
        Relative tolerance of the fitted bound, see
        :class:`~polyrob.synthesis.dscale.LogMagnitudeFit`.
    omega : array_like, optional
        D-step grid (rad/s); default :func:`frequency_grid` (8 points per
        decade); lightly damped closed-loop poles are added each iteration.
    progress : bool, optional
        One line per iteration; default only on a terminal.
    target : float, optional
        Stop once the grid peak μ is below it.
    initial_controller : LTI, optional
        Start with a D-step on this controller instead of the unscaled H∞
        one; for a mixed problem the iteration then goes straight to D-G-K
        steps (warm start, e.g. from a complex D-K result).
    mu_bound, d_fit, hinf_step : strategy objects, optional
        Replace :class:`MuUpperBound`, :class:`~polyrob.synthesis.dscale.LogMagnitudeFit`,
        :class:`HinfStep`.
    certify_omega : array_like, optional
        Grid of the final certificate (default: 12 points per decade over the
        D-step range widened by a decade on each side, plus closed-loop
        resonances, plus peak refinement).
    check_weights : bool
        Raise :class:`SynthesisError` when ``W_S`` and ``W_T`` alone force
        μ > 1 (:func:`performance_lower_bound`).
    n_u, n_y : int, optional
        For a bare ``StateSpace``.

    Returns
    -------
    MusynResult
        ``peak_mu`` is the certified upper bound of ``Fl(P, K)`` against
        ``blk`` with :func:`polyrob.analysis.mu.mu_bounds` (real blocks real), whatever
        the iteration optimised; ``mu_history`` the grid peak of the D-step
        bound after each K-step (complex μ for D-K, mixed μ for D-G-K).
        ``info`` has ``method``, ``orders`` (D/G per iteration), ``gamma``,
        ``timings``, ``regularization``, ``best_iteration``, ``grid_peak_mu``.

    Raises
    ------
    SynthesisError
        Unstabilisable plant, no K-step solvable, weights that make robust
        performance impossible, unknown structure.
    PolyrobError
        Inconsistent sizes.

    Examples
    --------
    A first-order plant with a 50% input-multiplicative complex uncertainty:

    >>> import control, numpy as np
    >>> from polyrob.synthesis import musyn
    >>> G = control.ss(control.tf([1], [1, 1]))
    >>> # inputs [d, w, u], outputs [v, z, y]:  v = 0.5 u, z = 0.5 e, y = e = w - G (u + d)
    >>> A, B, C = G.A, G.B, G.C
    >>> P = control.ss(A, np.hstack([B, 0 * B, B]),
    ...                np.vstack([0 * C, -0.5 * C, -C]),
    ...                [[0, 0, 0.5], [0, 0.5, 0], [0, 1, 0]])
    >>> res = musyn(P, [[1, 1], [1, 1]], n_u=1, n_y=1, max_iter=3, progress=False)
    >>> res.order >= 1, bool(res.peak_mu < 1)
    (True, True)
    """
    t_start = time.perf_counter()
    if not isinstance(structure, str) or not _STRUCT_RE.match(structure):
        raise SynthesisError(
            f"unknown controller structure {structure!r}: use 'full', 'tfN' (e.g. 'tf3'), 'pid' or 'ss:N'"
        )
    if structure != "full":
        try:
            from polyrob.synthesis.fixed import fixed_structure_musyn
        except ImportError as exc:
            raise SynthesisError(
                f"structure {structure!r} needs polyrob.synthesis.fixed, which is not available ({exc})"
            ) from None
        # forward the common options the fixed-structure solver accepts
        import inspect

        common = {"mixed": mixed, "max_iter": max_iter, "tol": tol, "omega": omega, "progress": progress,
                  "target": target, "initial_controller": initial_controller, "n_u": n_u, "n_y": n_y,
                  "certify_omega": certify_omega}
        defaults = {"mixed": None, "max_iter": 20, "tol": 1e-3, "omega": None, "progress": None, "target": None,
                    "initial_controller": None, "n_u": None, "n_y": None, "certify_omega": None}
        try:
            params = inspect.signature(fixed_structure_musyn).parameters
            takes_any = any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values())
        except (TypeError, ValueError):
            params, takes_any = {}, True
        kw = {k: v for k, v in common.items()
              if (takes_any or k in params) and not (v is None and defaults[k] is None) and
              (v is not defaults[k] and not (isinstance(v, (int, float)) and v == defaults[k]))}
        kw.update(structure_options)
        return fixed_structure_musyn(P, blk, structure, **kw)
    if structure_options:
        raise PolyrobError(f"unexpected options for a full-order synthesis: {sorted(structure_options)}")
    Psys, st, n_u, n_y = _parse_plant(P, blk, n_u, n_y)
    if check_weights:
        lb, wlb = performance_lower_bound(P)
        if lb >= 1.0:
            raise SynthesisError(
                f"the weights make robust performance impossible: at {wlb:.3g} rad/s, |W_S W_T|/sqrt(|W_S|^2 + "
                f"|W_T|^2) = {lb:.3g} >= 1, so no controller reaches mu < 1 (S + T = I). Lower the bandwidth "
                "of W_S or raise the crossover of W_T (or pass check_weights=False to get the best mu > 1)"
            )
    if mixed is None:
        mixed = st.has_real
    mixed = bool(mixed) and st.has_real
    if omega is None:
        omega = frequency_grid(Psys)
    omega = np.unique(np.asarray(omega, float).ravel())
    if omega.size < 3 or np.any(omega <= 0) or not np.all(np.isfinite(omega)):
        raise PolyrobError("omega must hold at least three positive finite frequencies")
    from polyrob.synthesis.hinf import check_stabilizable

    B = np.asarray(Psys.B, float)
    C = np.asarray(Psys.C, float)
    check_stabilizable(np.asarray(Psys.A, float), B[:, -n_u:], C[-n_y:], list(Psys.state_labels))
    if d_fit is None:
        d_fit = LogMagnitudeFit(orders=d_order, g_orders=g_order, tol=fit_tol)
    loop = DKIteration(mu_bound, d_fit, hinf_step, max_iter=max_iter, tol=tol, patience=patience,
                       target=target, progress=progress)
    K0 = None
    if initial_controller is not None:
        from polyrob.plant.generalized import _controller

        K0 = _controller(initial_controller, n_u, n_y)
    with single_blas_thread():
        # a warm start of a mixed problem goes straight to D-G-K steps: the
        # controller is presumably already the outcome of D-K steps
        phase0 = "DG" if (mixed and K0 is not None) else "D"
        hist = loop.run(Psys, n_u, n_y, st, omega, mixed=mixed, initial_controller=K0, start_phase=phase0)
        if not hist:
            raise SynthesisError("musyn: no iteration completed")
        # certify the best controllers (by grid peak); a sharp peak between
        # grid points can make the runner-up the better one
        order = sorted(range(len(hist)), key=lambda i: hist[i].mu_peak)
        if not np.isfinite(hist[order[0]].mu_peak):
            raise SynthesisError("musyn: no controller stabilised the plant")
        # the certificate looks a decade beyond the D-step grid on both sides
        cw = certify_omega if certify_omega is not None else np.logspace(
            np.log10(omega.min()) - 1, np.log10(omega.max()) + 1, int(12 * np.log10(omega.max() / omega.min())) + 25)
        Pc = P if not isinstance(P, control.StateSpace) else Psys
        kw = {} if not isinstance(P, control.StateSpace) else {"n_u": n_u, "n_y": n_y}
        best = None
        for i in order[:2]:
            rec = hist[i]
            if not np.isfinite(rec.mu_peak):
                break
            cert = certify(Pc, rec.K, st, cw, **kw)
            if best is None or cert[0] < best[1][0]:
                best = (i, cert)
            if cert[0] <= rec.mu_peak * 1.02:
                break  # the grid saw the peak: no need to look further
    i_best, (peak_mu, peak_lo, peak_w, N, cert) = best
    rec = hist[i_best]
    seconds = time.perf_counter() - t_start
    info = {
        "method": "D-G-K" if mixed else "D-K",
        "mixed": mixed,
        "best_iteration": i_best + 1,
        "grid_peak_mu": float(rec.mu_peak),
        "orders": [h.orders for h in hist],
        "regularization": list(rec.notes),
        "timings": [h.seconds for h in hist],
        "omega": omega,
        "reference": ("P. M. Young, Controller design with real parametric uncertainty, IJC 65(3), 1996; "
                      "G-scalings via J-spectral factorisation (see polyrob.synthesis.dscale)") if mixed else
                     "J. C. Doyle, Structured uncertainty in control system design, CDC 1985 (D-K iteration)",
    }
    return MusynResult(
        controller=rec.K, structure="full", order=int(rec.K.nstates), peak_mu=float(peak_mu),
        peak_mu_lower=float(peak_lo), peak_frequency=float(peak_w),
        mu_history=np.array([h.mu_peak for h in hist]), gamma_history=np.array([h.gamma for h in hist]),
        scalings=(rec.scalings,), closed_loop=N, certificate=cert, iterations=len(hist),
        seconds=float(seconds), info=info,
    )
