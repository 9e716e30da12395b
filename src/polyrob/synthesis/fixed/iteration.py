"""The D-G-K iteration of one fixed-structure start: grids, screening, acceptance, the loop.

:func:`optimise_start` alternates the K-step (:func:`~polyrob.synthesis.fixed.kstep.kstep`),
a backtracking acceptance that checks the bound on the working grid *and*
rigorously on a fine screening grid (:func:`accept_step`), and the D-step
refresh of the scalings (:func:`grid_bound`); the working grid is refined
around the peaks (:func:`refine_points`, :func:`screen_grid`).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from polyrob.errors import ArgumentError
from polyrob.progress import span
from polyrob.synthesis.fixed.kstep import kstep
from polyrob.synthesis.fixed.loop import FixedLoop
from polyrob.synthesis.fixed.options import FixedStructureOptions
from polyrob.synthesis.fixed.scalings import PerFrequencyScalings, dstep, majorant, refine_scalings

__all__ = [
    "StartRun",
    "check_grid",
    "grid_span",
    "log_grid",
    "refine_points",
    "screen_points",
    "screen_grid",
    "grid_bound",
    "screen_check",
    "accept_step",
    "optimise_start",
    "reporter",
]


def check_grid(omega, name):
    if omega is None:
        return None
    w = np.unique(np.asarray(omega, float).ravel())
    if w.size < 3 or np.any(w < 0) or not np.all(np.isfinite(w)) or not np.any(w > 0):
        raise ArgumentError(f"{name} must hold at least 3 finite non-negative frequencies")
    return w


def grid_span(loop: FixedLoop, theta, omega) -> tuple[float, float]:
    if omega is not None:
        w = np.asarray(omega, float)
        w = w[w > 0]
        return float(w.min()), float(w.max())
    f = np.concatenate([loop.pole_frequencies(theta), [1.0]])
    f = f[(f > 1e-8) & (f < 1e8)]
    return 10 ** (np.floor(np.log10(f.min())) - 1), 10 ** (np.ceil(np.log10(f.max())) + 1)


def log_grid(lo, hi, density):
    k = max(int(round(density * math.log10(hi / lo))), 2) + 1
    return np.logspace(math.log10(lo), math.log10(hi), k)


log = logging.getLogger(__name__)


@dataclass
class StartRun:
    """Mutable state of one start (the iteration updates it in place)."""

    theta: np.ndarray
    sc: PerFrequencyScalings
    peak: float
    history: list = field(default_factory=list)
    gammas: list = field(default_factory=list)
    iterations: int = 0
    notes: list = field(default_factory=list)


def refine_points(sc: PerFrequencyScalings, n_peaks=3, min_gap=1e-2) -> np.ndarray:
    """Log-midpoints next to the highest local maxima of the grid bound."""
    with np.errstate(divide="ignore"):  # omega = 0 (real blocks): log10 -inf, no log-midpoint next to it
        mu, lw = sc.mu, np.log10(sc.omega)
    F = mu.size
    peaks = [i for i in range(F) if (i == 0 or mu[i] >= mu[i - 1]) and (i == F - 1 or mu[i] >= mu[i + 1])]
    peaks = sorted(peaks, key=lambda i: -mu[i])[:n_peaks]
    new = []
    for i in peaks:
        for j in (i - 1, i + 1):
            if 0 <= j < F and np.isfinite(lw[i]) and np.isfinite(lw[j]) and abs(lw[j] - lw[i]) > min_gap:
                new.append(10 ** (0.5 * (lw[i] + lw[j])))
    return np.unique(np.array(new, float))


def screen_points(loop: FixedLoop, theta, screen: np.ndarray) -> np.ndarray:
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


def screen_grid(loop: FixedLoop, run: StartRun, screen: np.ndarray, blk, opts) -> int:
    """Rigorously check a fine grid with the nearest scalings; analyse and add the frequencies that fail."""
    w = screen_points(loop, run.theta, screen)
    w = w[~np.isin(w, run.sc.omega)]
    if w.size == 0:
        return 0
    idx = run.sc.nearest(w)
    near = run.sc.take(idx)
    near = replace(near, omega=w)
    beta = majorant(loop, run.theta, near, n_eig=1)[:, 0]
    fail = np.flatnonzero(beta > run.peak * (1 + 1e-9))
    if fail.size == 0:
        return 0
    # worst first, a bounded number per call (each costs an AB13MD call)
    fail = fail[np.argsort(-beta[fail])][:12]
    new = dstep(loop, run.theta, w[fail], blk)
    run.sc = run.sc.merged(new)
    run.peak = float(np.max(run.sc.mu))
    return int(fail.size)


def grid_bound(
    loop: FixedLoop, theta, sc: PerFrequencyScalings, blk, opts, *, exact: bool = False
) -> PerFrequencyScalings:
    """The grid bound at ``θ``: scalings refreshed where the stale majorant is near its peak.

    Elsewhere the majorant with the old scalings is itself the (valid) bound.
    ``exact`` refreshes with AB13MD (kept only where it improves), otherwise
    with the warm-started batched BFGS of :func:`refine_scalings`.
    """
    beta = majorant(loop, theta, sc, n_eig=1)[:, 0]
    sc = replace(sc, mu=beta)
    if not np.any(np.isfinite(beta)):
        return sc
    ratio = opts.exact_ratio if exact else opts.dstep_ratio
    sel = np.flatnonzero(beta >= ratio * float(np.max(beta[np.isfinite(beta)])))
    sel = np.union1d(sel, np.flatnonzero(~np.isfinite(beta)))
    if exact or loop.diag is None:
        fresh = dstep(loop, theta, sc.omega[sel], blk)
        fresh = fresh.take(np.flatnonzero(fresh.mu < sc.mu[sel]))
    else:
        fresh = refine_scalings(loop, theta, sc, sel)
    return sc.merged(fresh)


def screen_check(loop: FixedLoop, theta, sc: PerFrequencyScalings, screen: np.ndarray, level: float):
    """Is the bound below ``level`` on the fine screening grid (and at the closed-loop pole frequencies)?

    Every frequency first gets the nearest grid scalings (a rigorous bound
    for free); those above ``level`` get a warm-started scaling update.
    Returns ``(ok, scalings of the frequencies that needed the update)``:
    a step that creates a resonance between grid points is thereby refused
    instead of being discovered one iteration later.
    """
    w = screen_points(loop, theta, screen)
    w = w[~np.isin(w, sc.omega)]
    if w.size == 0:
        return True, None
    near = replace(sc.take(sc.nearest(w)), omega=w)
    beta = majorant(loop, theta, near, n_eig=1)[:, 0]
    fail = np.flatnonzero(~(beta < level))
    if fail.size == 0:
        return True, None
    if loop.diag is None:
        return False, None
    fixed = refine_scalings(loop, theta, near, fail)
    return bool(np.all(fixed.mu < level)), fixed


def accept_step(
    loop: FixedLoop, theta0, theta1, sc: PerFrequencyScalings, peak0: float, blk, opts, screen, halvings: int = 4
):
    """Backtrack from ``theta1`` towards ``theta0`` until the loop is stable and the bound decreased.

    "Decreased" on the working grid and, rigorously, on the screening grid.
    """
    step = theta1 - theta0
    for _ in range(halvings + 1):
        th = theta0 + step
        if loop.abscissa(th) <= -opts.min_decay and loop.abscissa(th, full=True) < 0:
            new = grid_bound(loop, th, sc, blk, opts)
            level = peak0 * (1 - 1e-9)
            if float(np.max(new.mu)) < level:
                ok, extra = screen_check(loop, th, new, screen, level)
                if ok:
                    return th, (new if extra is None else new.merged(extra))
        step = 0.5 * step
    return None, sc


def optimise_start(
    loop: FixedLoop,
    run: StartRun,
    blk,
    opts: FixedStructureOptions,
    max_iter: int,
    screen: np.ndarray,
    report: Callable[[dict], None],
    label: str,
    target: float | None = None,
    deadline=None,
):
    radius = opts.trust_region
    stall = 0
    for i in range(max_iter):
        with span(i / max_iter, (i + 1) / max_iter):  # the job's line: each iteration its part
            if target is not None and run.peak <= target:
                break
            # a start that began makes at least one iteration (a start is not begun after the limit):
            # on a loaded machine its set-up alone can outlast a short limit
            if deadline is not None and run.iterations > 0 and deadline.passed():
                run.notes.append(f"stopped by {deadline.words} after {run.iterations} iteration(s)")
                break
            t0 = time.perf_counter()
            old = run.peak
            theta_new, _, msg = kstep(loop, run.theta, run.sc, opts, radius)
            theta_new, sc = accept_step(loop, run.theta, theta_new, run.sc, run.peak, blk, opts, screen)
            run.iterations += 1
            if theta_new is None:
                # no decrease within the trust region: shrink it and refresh the
                # scalings with AB13MD in case the warm-started ones are what stalls
                radius *= 0.3
                run.notes.append(f"iteration {run.iterations}: step rejected ({msg}); trust radius {radius:.3g}")
                sc = grid_bound(loop, run.theta, run.sc, blk, opts, exact=True)
                stall += 1
            else:
                run.theta = theta_new
                grown = float(np.max(sc.mu)) < 0.97 * old
                radius = min(2.0 * radius, 4.0 * opts.trust_region) if grown else radius
            ref = refine_points(sc)
            ref = ref[~np.isin(ref, sc.omega)]
            if ref.size:
                sc = sc.merged(dstep(loop, run.theta, ref, blk))
            run.sc = sc
            run.peak = float(np.max(sc.mu))
            added = screen_grid(loop, run, screen, blk, opts)
            run.history.append(run.peak)
            run.gammas.append(run.peak)
            report(
                {
                    "start": label,
                    "iteration": run.iterations,
                    "peak_mu": run.peak,
                    "kstep": msg,
                    "grid": int(run.sc.omega.size),
                    "screen_added": added,
                    "radius": radius,
                    "seconds": time.perf_counter() - t0,
                }
            )
            if theta_new is not None:
                stall = stall + 1 if run.peak > old * (1 - opts.tol) else 0
            if stall >= opts.patience or radius < 1e-4:
                break
    return run


def reporter(progress) -> Callable[[dict], None]:
    """A line per iteration on the ``polyrob`` logger (the CLI shows it on stderr, terminal or not)."""
    if callable(progress):
        return progress

    def out(d):
        log.info(
            f"[fixed {d['start']}] it {d['iteration']:3d}  peak mu {d['peak_mu']:.5f}  grid {d['grid']}"
            f"  (+{d['screen_added']})  {d['seconds']:.2f}s  r {d['radius']:.3g}  {d['kstep']}"
        )

    return out
