"""Result objects of the μ computations (:func:`polyrob.analysis.mu.bounds.mussv`, :func:`~polyrob.analysis.mu.bounds.mu_bounds`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from polyrob.analysis.mu.blocks import BlockStructure

__all__ = ["MussvResult", "MuBoundsResult"]


@dataclass(frozen=True, eq=False)
class MussvResult:
    """Bounds on :math:`\\mu` of one matrix and their certificates.

    Attributes
    ----------
    upper, lower : float
        :math:`\\ell \\le \\mu_\\Delta(M) \\le` ``upper``.
    delta : ndarray
        Worst perturbation of the lower bound (shape of :math:`\\Delta`):
        :math:`\\det(I - M\\Delta) \\approx 0`, :math:`\\bar\\sigma(\\Delta) = 1/\\ell`.
        The zero matrix when ``lower == 0`` (no destabilising Δ was found;
        for purely real structures μ may truly be 0).
    D, G : ndarray
        Upper-bound scalings on the padded square problem (``D`` in square-root
        form, see module docstring).
    Dl, Dr : ndarray
        ``D`` restricted to M's rows and columns: for complex-only structures
        :math:`\\bar\\sigma(D_l M D_r^{-1}) \\le` ``upper``.
    structure : BlockStructure
    method : str
        Upper-bound method used (``"ab13md"``, ``"lmi"``, ``"gradient"``: descent on the D-G scalings, or
        ``"relaxed"``: AB13MD on a superset structure).
    notes : tuple of str
        LMI solver fallbacks and failed bisection steps (empty when none).
    """

    upper: float
    lower: float
    delta: np.ndarray
    D: np.ndarray
    G: np.ndarray
    Dl: np.ndarray
    Dr: np.ndarray
    structure: BlockStructure
    method: str
    notes: tuple = ()

    def lmi_residual(self, M: np.ndarray) -> float:
        """Largest eigenvalue of the D-G LMI at ``upper``, relative to ``upper**2``.

        ``<= ~1e-8`` means the scalings certify the upper bound.
        """
        Ms = self.structure.pad(self.structure.check_m(M))
        P = self.D @ self.D
        L = Ms.conj().T @ P @ Ms + 1j * (self.G @ Ms - Ms.conj().T @ self.G) - self.upper**2 * P
        L = (L + L.conj().T) / 2
        return float(np.linalg.eigvalsh(L)[-1]) / max(self.upper**2 * np.linalg.norm(P, 2), 1e-300)


@dataclass(frozen=True, eq=False)
class MuBoundsResult:
    """:math:`\\mu` bounds at the points of a frequency grid (see :func:`mu_bounds`).

    Attributes
    ----------
    omega, upper, lower : ndarray
        Sorted frequencies (rad/s, grid + refinement points) and the bounds
        at each of them: ``lower[i] <= mu(M(j omega[i])) <= upper[i]``.
    D, G : ndarray
        Upper-bound scalings per frequency, shape ``(N, n, n)`` (padded).
    peak_upper, peak_upper_frequency : float
        Peak μ upper bound on the grid, :math:`\\max_i` ``upper[i]``, and where
        it is reached.  Not a bound between grid points: an estimate from
        below of :math:`\\sup_\\omega \\mu`.
    peak_lower, critical_frequency : float
        Peak μ lower bound on the grid and where it is reached (a true lower
        bound of :math:`\\sup_\\omega \\mu`: a destabilising Δ exists there).
    worst_delta : ndarray
        Destabilising perturbation at ``critical_frequency`` on the boundary:
        :math:`\\bar\\sigma = 1/` ``peak_lower``, :math:`\\det(I - M(j\\omega_c)\\Delta) = 0`.
    structure : BlockStructure
    method : str
    warm_start_fallbacks : int
        Number of AB13MD warm starts that timed out or failed (then cold).
    notes : tuple of str
        What went wrong on the way and what was done instead (LMI solver
        fallbacks, warm-start timeouts); empty when nothing did.
    between : BetweenGridResult or None
        With ``mu_bounds(..., verify=True)``: the bound between the grid
        points (:func:`polyrob.analysis.mu.between.verify_between`); when it
        holds, ``between.level`` bounds μ at every frequency.
    """

    omega: np.ndarray
    upper: np.ndarray
    lower: np.ndarray
    D: np.ndarray
    G: np.ndarray
    peak_upper: float
    peak_upper_frequency: float
    peak_lower: float
    critical_frequency: float
    worst_delta: np.ndarray
    structure: BlockStructure
    method: str
    warm_start_fallbacks: int = 0
    notes: tuple = ()
    between: object = None

    @property
    def upper_everywhere(self) -> float | None:
        """A bound of μ at every frequency (``between.level``), or ``None`` if not verified."""
        b = self.between
        return float(b.level) if b is not None and b.holds else None

    @property
    def covers(self) -> str:
        """One sentence on what the peak figures cover, printable verbatim."""
        w = self.omega
        grid = f"a grid of {w.size} frequencies in [{w.min():.3g}, {w.max():.3g}] rad/s"
        if self.between is None:
            scope = f"peak mu on {grid} (upper bound at each grid point, not between them)"
        elif self.between.holds:
            scope = f"peak mu on {grid}; {self.between.sentence()}"
        else:
            scope = f"peak mu on {grid} (upper bound at each grid point; {self.between.sentence()})"
        return f"{scope}; structure {self.structure}"
