"""Tuning knobs of the fixed-structure μ-synthesis (:func:`~polyrob.synthesis.fixed.synthesis.fixed_structure_musyn`)."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["FixedStructureOptions"]


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
