"""Full-order μ-synthesis by D-K iteration (complex μ) and D-G-K iteration (mixed μ).

:func:`musyn` alternates, like MATLAB's ``musyn``,

* a **D-step**: the μ upper bound of the closed loop ``N = Fl(P, K)`` on a
  frequency grid, with its scalings ``D(ω)`` (and ``G(ω)`` for real
  parameters), computed by SLICOT AB13MD through :func:`polyrob.analysis.mu.bounds.mussv`;
* a **fit**: per-block stable, minimum-phase rational filters of the lowest
  order that reproduces the bound (:mod:`polyrob.synthesis.scalings.dscale`);
* a **K-step**: H∞ synthesis (:func:`polyrob.synthesis.hinf.synthesis.hinfsyn`) for the
  plant scaled by the fitted filters.

The three steps are strategy objects (:class:`MuUpperBound`,
:class:`~polyrob.synthesis.scalings.dscale.LogMagnitudeFit`, :class:`HinfStep`)
passed to :class:`DKIteration`, as in dkpy's ``dk_iteration.py``, so other
bounds, fits or synthesis methods plug in without touching the loop.

Complex vs mixed.  ``mixed=False`` treats every real parameter as a complex
scalar (classical D-K: conservative for real parameters).  ``mixed=True``
(the default when the structure has real blocks) is a D-G-K iteration
(Young 1996): the G scalings of the mixed-μ upper bound are fitted too and
enter the K-step through the J-spectral factorisation of the D-G multiplier
described in :mod:`polyrob.synthesis.scalings.dscale`.  It starts with D-K steps
while they gain more than ``switch_tol`` per iteration (a G step cannot
push the scaled norm below ``max|F|``, so it refines but does not rescue a
poor controller) and continues with D-G-K steps, each guarded: the old
controller must stabilise the G-transformed plant, and a G step that fails
falls back on a D step.  Whatever the iteration, the controller is finally
**certified** with :func:`polyrob.analysis.mu.bounds.mu_bounds` against the structure
``blk`` (real blocks as real) on a peak-refined grid: that number is
:attr:`~polyrob.synthesis.result.MusynResult.peak_mu`.

Safeguards of the loop: the best controller seen is kept (μ can go up);
a K-step whose controller does not stabilise ``P``, or whose scaled H∞ norm
exceeds the old controller's on the same scaled plant by more than 25%, is
rejected (a numerically failed synthesis); the two best controllers are
certified when the first one's certificate exceeds its grid value by 2%.
"""

from __future__ import annotations

import logging
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass

import control
import numpy as np

from polyrob.analysis.mu.blocks import as_block_structure
from polyrob.analysis.mu.frequency import matrix_response
from polyrob.analysis.norms import hinf_norm_estimate
from polyrob.analysis.stability import stability_screen
from polyrob.errors import ArgumentError, SynthesisError
from polyrob.plant.generalized import lower_lft_matrices
from polyrob.progress import report as progress_report
from polyrob.report.numbers import gamma_text
from polyrob.synthesis.dk.frequency import frequency_grid, loop_grid, performance_lower_bound, resonances
from polyrob.synthesis.dk.strategies import HinfStep, MuUpperBound
from polyrob.synthesis.scalings.data import ScalingData, Scalings, complexified, scaling_data
from polyrob.synthesis.scalings.dfit import LogMagnitudeFit
from polyrob.synthesis.scalings.scaled_plant import scaled_plant

log = logging.getLogger(__name__)

__all__ = [
    "DKIteration",
    "IterationRecord",
    "MuUpperBound",
    "HinfStep",
    "frequency_grid",
    "performance_lower_bound",
]


# ================================================================ the loop
@dataclass
class IterationRecord:
    """One D-K iteration: the controller, its grid peak μ, the K-step γ, the fits, the timings."""

    K: control.StateSpace
    mu_peak: float
    gamma: float
    orders: list
    scalings: Scalings | None
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
        A progress bar (tqdm); default: only on a terminal.  One line per
        iteration goes to the ``polyrob`` logger whatever this says.
    deadline : UserTimeLimit, optional
        The time limit the user set (:class:`polyrob.clock.UserTimeLimit`): past it no
        new iteration starts; the best controller so far is kept and
        :attr:`stopped_by` names the limit.
    switch_tol : float
        Mixed problems: D-K steps while the peak improves by more than this
        (relative, per iteration), then D-G-K steps.

    Examples
    --------
    >>> import control
    >>> from polyrob.synthesis.dk.iteration import DKIteration, MuUpperBound, HinfStep
    >>> from polyrob.synthesis.scalings.dscale import LogMagnitudeFit
    >>> it = DKIteration(MuUpperBound(), LogMagnitudeFit(orders=(0, 1, 2)), HinfStep(), max_iter=5)
    >>> it.max_iter
    5
    """

    def __init__(
        self,
        mu_bound=None,
        d_fit=None,
        hinf_step=None,
        *,
        max_iter: int = 20,
        tol: float = 1e-3,
        patience: int = 2,
        target: float | None = None,
        progress: bool | None = None,
        deadline=None,
        switch_tol: float = 0.02,
    ):
        self.mu_bound = mu_bound or MuUpperBound()
        self.d_fit = d_fit or LogMagnitudeFit()
        self.hinf_step = hinf_step or HinfStep()
        self.max_iter, self.tol, self.patience = int(max_iter), float(tol), int(patience)
        self.target, self.progress = target, progress
        #: the time limit the user set (:class:`polyrob.clock.UserTimeLimit`; ``None``: no limit)
        self.deadline = deadline
        #: why the last run stopped early (``None``: it did not)
        self.stopped_by = None
        self.switch_tol = float(switch_tol)
        self.reject_ratio = 1.25
        if self.max_iter < 1:
            raise ArgumentError("max_iter must be >= 1")

    def _k_step(self, Ps, n_u, n_y, A, B, C, D, level_old, it):
        """H∞ step with safeguards: ``None`` if it fails, destabilises ``P`` or is worse than the old K."""
        try:
            hres = self.hinf_step(Ps, n_y, n_u)
        except SynthesisError as exc:
            self.failures.append(f"iteration {it + 1}: {exc}")
            return None
        Ak, Bk, Ck, Dk = (np.asarray(X, float) for X in (hres.K.A, hres.K.B, hres.K.C, hres.K.D))
        try:
            Acl, *_ = lower_lft_matrices(A, B, C, D, Ak, Bk, Ck, Dk, n_u, n_y)
        except np.linalg.LinAlgError:
            Acl = None
        if Acl is None or not stability_screen(Acl):
            self.failures.append(f"iteration {it + 1}: the K-step controller does not stabilise P")
            return None
        if np.isfinite(level_old) and hres.gamma > level_old * self.reject_ratio:
            # the old controller does much better on the same scaled plant:
            # the synthesis went wrong.  (A few percent worse is normal: the
            # K-step solves the regularised problem, and its controller can
            # still lower μ, so it is kept.)
            self.failures.append(
                f"iteration {it + 1}: K-step gamma {hres.gamma:.4g} above the old controller's {level_old:.4g}"
            )
            return None
        return hres

    @staticmethod
    def _start_grid(omega, A, B, C, D, K, n_u, n_y):
        """``omega`` widened down to the start's closed loop (:func:`~polyrob.synthesis.dk.frequency.loop_grid`).

        Only for a given start: widening at every iteration also followed the
        slow poles of intermediate H∞ controllers and moved the main job's
        result (order 11, μ 0.956 instead of 8 and 0.936).
        """
        Ak, Bk, Ck, Dk = (np.asarray(X, float) for X in (K.A, K.B, K.C, K.D))
        try:
            Acl = lower_lft_matrices(A, B, C, D, Ak, Bk, Ck, Dk, n_u, n_y)[0]
        except np.linalg.LinAlgError:  # an ill-posed start is reported by the first iteration
            return omega
        return loop_grid(omega, Acl)

    def run(
        self,
        Psys: control.StateSpace,
        n_u: int,
        n_y: int,
        blk,
        omega,
        *,
        mixed: bool,
        initial_controller=None,
        callback: Callable | None = None,
        start_phase: str | None = None,
    ) -> list[IterationRecord]:
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
        st_c = complexified(st)
        phase = start_phase or "D"
        if phase not in ("D", "DG") or (phase == "DG" and not mixed):
            raise ArgumentError(f"start_phase must be 'D' (or 'DG' for mixed problems), got {start_phase!r}")
        omega = np.asarray(omega, float)
        A, B, C, D = (np.asarray(X, float) for X in (Psys.A, Psys.B, Psys.C, Psys.D))
        hist: list[IterationRecord] = []
        t_run = time.perf_counter()
        self.stopped_by = None
        show = sys.stderr.isatty() if self.progress is None else bool(self.progress)
        bar = tqdm(total=self.max_iter, disable=not show, desc="musyn", leave=False, file=sys.stderr)
        K = initial_controller
        gamma, notes, orders, scal = float("nan"), (), [], None
        t_fit = t_hinf = 0.0
        if K is not None:  # a start's loop (the arms' tuned PID) crosses over where the plant has no pole
            omega = self._start_grid(omega, A, B, C, D, K, n_u, n_y)
        if K is None:
            t0 = time.perf_counter()
            hres = self.hinf_step(Psys, n_y, n_u)
            t_hinf = time.perf_counter() - t0
            K, gamma, notes = hres.K, hres.gamma, hres.regularization
        best = np.inf
        since_best = 0
        prev = np.inf
        self.failures = []
        # the fits' complex D-steps share the D-step's worker (restored after the run)
        fit_sweep = getattr(self.d_fit, "sweep", False)
        if fit_sweep is None:
            self.d_fit.sweep = getattr(self.mu_bound, "sweep", None)
        try:
            for it in range(self.max_iter):
                t0 = time.perf_counter()
                Ak, Bk, Ck, Dk = (np.asarray(X, float) for X in (K.A, K.B, K.C, K.D))
                try:
                    Acl, Bcl, Ccl, Dcl = lower_lft_matrices(A, B, C, D, Ak, Bk, Ck, Dk, n_u, n_y)
                    stable = stability_screen(Acl)
                except np.linalg.LinAlgError:
                    stable = False
                if not stable:
                    rec = IterationRecord(
                        K, np.inf, gamma, orders, scal, {"mu": 0.0, "fit": t_fit, "hinf": t_hinf}, notes, phase
                    )
                    hist.append(rec)
                    log.info(f"musyn iter {it + 1}: closed loop unstable, stopping")
                    break
                w = np.union1d(omega, resonances(Acl, omega.min(), omega.max()))
                H = matrix_response(Acl, Bcl, Ccl, Dcl)(w)
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
                rec = IterationRecord(
                    K, peak, gamma, orders, scal, {"mu": t_mu, "fit": t_fit, "hinf": t_hinf}, notes, phase
                )
                hist.append(rec)
                if callback is not None:
                    callback(rec)
                if peak < best * (1 - self.tol):
                    since_best = 0
                else:
                    since_best += 1
                best = min(best, peak)
                prev = peak
                bar.update(1)
                progress_report(it + 1, self.max_iter)  # the whole job's progress line, when a command shows one
                bar.set_postfix(mu=f"{peak:.4f}", best=f"{best:.4f}", gamma=gamma_text(gamma), nK=K.nstates)
                bound = "mixed " if phase == "DG" else "complex " if st.has_real else ""
                # one line per iteration on the polyrob logger, terminal or not (grid peak: a search figure)
                log.info(
                    f"musyn iter {it + 1:2d}: grid peak mu {peak:.4f} {bound}(best {best:.4f}), "
                    f"gamma {gamma_text(gamma)}, K order {K.nstates}, D/G orders {orders}, "
                    f"{sum(rec.seconds.values()):.1f} s, {time.perf_counter() - t_run:.0f} s in all"
                )
                if it + 1 >= self.max_iter:
                    break
                if self.deadline is not None and self.deadline.passed():
                    self.stopped_by = f"{self.deadline.words}, after {it + 1} iteration(s)"
                    log.info(f"musyn: stopped by {self.stopped_by}")
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
                    self.failures.append(f"iteration {it + 1}: G-scaled K-step failed; D-only K-step tried")
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
            if fit_sweep is None:
                self.d_fit.sweep = None
            close = getattr(self.mu_bound, "close", None)
            if close is not None:
                close()
        return hist


def _scaled_norm(Ps, K, n_u, n_y) -> float:
    """Grid value of the scaled loop's H∞ norm with ``K`` (``inf`` if unstable or ill posed).

    The lower LFT closed, then :func:`~polyrob.analysis.norms.hinf_norm_estimate`
    (which screens stability itself): an estimate from below, used only to
    reject a K-step much worse than the old controller (a heuristic
    safeguard, never a certificate: μ is certified by
    :func:`polyrob.analysis.certificate.certify_loop`).
    """

    A, B, C, D = (np.asarray(X, float) for X in (Ps.A, Ps.B, Ps.C, Ps.D))
    Ak, Bk, Ck, Dk = (np.asarray(X, float) for X in (K.A, K.B, K.C, K.D))
    try:
        Acl, Bcl, Ccl, Dcl = lower_lft_matrices(A, B, C, D, Ak, Bk, Ck, Dk, n_u, n_y)
    except np.linalg.LinAlgError:
        return float("inf")
    return hinf_norm_estimate(Acl, Bcl, Ccl, Dcl)


def _d_route(d_fit, data, H, beta):
    """The D-only fit of mixed data (complex D scalings of ``N/β``)."""
    call = getattr(d_fit, "d_route", None)
    if call is not None:
        return call(data, H, beta)
    return d_fit(data, H, beta, False)
