"""Frequency tools of μ-synthesis: the D-step grid and the performance floor.

* :func:`frequency_grid` - the default D-K grid from the plant's poles;
* :func:`loop_grid` - that grid widened to the closed loop's poles, at each iteration;
* :func:`resonances` - lightly damped natural frequencies the grid must hold;
* :func:`performance_lower_bound` - what ``W_S`` and ``W_T`` alone force on μ.

Responses are evaluated by :mod:`polyrob.analysis.mu.frequency` (``freqresp``
for systems, ``matrix_response`` for the closed-loop matrices of the loop).

The certificate every synthesis result carries is
:func:`polyrob.analysis.certificate.certify_loop`'s.
"""

from __future__ import annotations

import math

import numpy as np

from polyrob.analysis.mu.frequency import freqresp

__all__ = ["frequency_grid", "loop_grid", "resonances", "performance_lower_bound"]


def frequency_grid(sys, per_decade: int = 8) -> np.ndarray:
    """Default D-K grid: the decades spanned by the plant's poles, one more each side.

    Poles at ``s = 0`` and near-integrators (below 1e-4 times the median
    pole magnitude, e.g. a weight's 1e-5 pole) do not widen the grid.  A
    plant of double integrators (an arm behind computed torque) has no pole
    where its loop will cross over: the iteration adds the closed loop's
    decades of a start's loop (:func:`loop_grid`).

    Examples
    --------
    >>> import control
    >>> from polyrob.synthesis.dk.frequency import frequency_grid
    >>> w = frequency_grid(control.ss(control.tf([1], [1, 3, 2])))
    >>> float(w[0]), float(w[-1]), w.size
    (0.1, 100.0, 25)
    """
    lo, hi = _pole_decades(np.asarray(sys.A, float))
    return np.logspace(lo, hi, int(per_decade * (hi - lo)) + 1)


def loop_grid(omega, A_loop: np.ndarray, per_decade: int = 8) -> np.ndarray:
    """``omega`` widened to the decades of the closed loop's poles (the rule of :func:`frequency_grid`).

    μ peaks near the loop's crossover, which the open plant's poles need not
    reveal: on ur5 behind computed torque the plant's poles are the double
    integrators' zeros and the weights' fast poles, so the plant's grid ran
    from 100 rad/s up while the per-joint PID start's μ peaked at 15-20 rad/s
    (2.75 there, 1.2 on the grid): the D-steps fitted scalings that miss the
    peak and every K-step made μ worse.  The closed loop's poles sit at the
    crossover.  Points are added on the same ``per_decade`` lattice, below
    ``omega``'s lowest point only: a grid that already reaches down to the
    loop is kept.  The iteration widens its grid once, from the loop of the
    controller it starts from (:class:`~polyrob.synthesis.dk.iteration.DKIteration`).

    Examples
    --------
    >>> import numpy as np
    >>> w = loop_grid(np.logspace(2, 5, 25), np.diag([-0.5, -10.0, -1e3]))
    >>> float(w[0]), float(w[-1]), bool(np.all(np.diff(w) > 0))
    (0.01, 100000.0, True)
    >>> loop_grid(np.logspace(2, 5, 25), np.diag([-1e3, -1e7])).size  # faster poles: the grid is kept
    25
    """
    omega = np.asarray(omega, float)
    lo, hi = _pole_decades(A_loop)
    band = np.logspace(lo, hi, int(per_decade * (hi - lo)) + 1)
    return np.union1d(omega, band[band < omega.min() * (1 - 1e-9)])


def _pole_decades(A: np.ndarray) -> tuple[int, int]:
    """``(lo, hi)``: the powers of ten spanning the poles of ``A``, one more each side (integrators left out)."""
    f = np.abs(np.linalg.eigvals(A)) if A.size else np.zeros(0)
    f = f[np.isfinite(f) & (f > 0)]
    if f.size:
        f = f[f >= 1e-4 * np.median(f)]
    if f.size == 0:
        return -2, 2
    lo = math.floor(math.log10(f.min()) + 1e-9) - 1
    hi = math.ceil(math.log10(f.max()) - 1e-9) + 1
    if hi - lo < 2:
        lo, hi = lo - 1, hi + 1
    return lo, hi


def resonances(A: np.ndarray, lo: float, hi: float, zeta: float = 0.5) -> np.ndarray:
    """Natural frequencies of lightly damped poles in ``[lo, hi]`` (peaks hide there)."""
    if A.size == 0:
        return np.zeros(0)
    ev = np.linalg.eigvals(A)
    wn = np.abs(ev)
    ok = (wn > 0) & (np.abs(ev.imag) > 0) & (-ev.real < zeta * wn) & (wn >= lo) & (wn <= hi)
    return np.unique(np.round(wn[ok], 12))


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
    >>> from polyrob.synthesis.dk.frequency import performance_lower_bound
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
    HS = freqresp(P.W_S, w)
    HT = freqresp(P.W_T, w)
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
