"""The result of :func:`polyrob.lpvnorm`: a proved bound on the induced L2 gain and what it covers."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from polyrob.analysis.scope import finite_or_none, strict_json

__all__ = ["LpvNormResult", "ARBITRARILY_FAST", "rate_text"]

#: The variation a constant Lyapunov matrix covers.
ARBITRARILY_FAST = "arbitrarily fast (constant Lyapunov matrix X)"


def rate_text(rate_bounds) -> str:
    """The variation a parameter-dependent ``X`` covers, in words.

    Parameters
    ----------
    rate_bounds : sequence of (lo, hi)

    Returns
    -------
    str

    Examples
    --------
    >>> rate_text([(-0.1, 0.1)])
    'rate-bounded: drho_1/dt in [-0.1, 0.1]'
    """
    parts = [f"drho_{i + 1}/dt in [{lo:.4g}, {hi:.4g}]" for i, (lo, hi) in enumerate(rate_bounds)]
    return "rate-bounded: " + ", ".join(parts)


@dataclass(frozen=True, eq=False)
class LpvNormResult:
    """A rate-bounded induced-L2 analysis of a gridded LPV system (:func:`polyrob.lpvnorm`).

    Attributes
    ----------
    gamma : float
        The **proved** upper bound of the induced L2 gain: the smallest level at
        which the returned ``X`` passed the float64 re-check
        (:func:`polyrob.analysis.lpv.check.check_solution`); ``inf`` when
        nothing was proved.  It covers :attr:`variation` on :attr:`coverage`.
    proved : bool
        ``gamma`` is finite and verified.
    gamma_solver : float
        The LMI solver's optimum (not a certificate; ``inf`` when it failed).
    frozen_gamma : float
        Largest LTI H-infinity norm over the grid points (python-control/SLICOT;
        ``inf`` when a frozen system is unstable): a lower bound of the
        LPV gain when constant trajectories are admissible (0 in the rate box).
    variation : str
        Which parameter trajectories the bound covers (arbitrarily fast, or
        the rate box).
    coverage : str
        Which parameter values: "on the grid of N points" (the LMIs hold at
        the grid points only) or "the whole box ... (multi-convexity)".
    whole_box : bool
        The bound is proved between the grid points too (the whole box);
        the fact behind :attr:`coverage`'s words.
    n_points, n_rate_vertices, n_basis, n_states : int
    solver_status : str
    reason : str
        Why nothing was proved (empty when proved).
    lmi_margin : float
        Smallest verified ``-(lambda_max(M) + rounding)`` at :attr:`gamma`.
    X : tuple of ndarray
        The coefficient matrices ``X_j`` of ``X(rho) = sum_j f_j(rho) X_j``,
        in the user's state coordinates and basis (``()`` when none).
    notes : tuple of str
    seconds : float
    """

    gamma: float
    proved: bool
    gamma_solver: float
    frozen_gamma: float
    variation: str
    coverage: str
    n_points: int
    n_rate_vertices: int
    n_basis: int
    n_states: int
    solver_status: str
    reason: str = ""
    lmi_margin: float = float("nan")
    X: tuple = field(default=(), repr=False)
    notes: tuple = ()
    seconds: float = 0.0
    whole_box: bool = False

    @classmethod
    def solver_failed(cls, n_points: int, reason: str) -> LpvNormResult:
        """The result of a search whose solver raised: nothing proved, and why."""
        return cls(float("inf"), False, float("inf"), float("nan"), "", f"on the grid of {n_points} points",
                   n_points, 0, 0, 0, "solver error", reason=reason)  # fmt: skip

    @property
    def status(self) -> str:
        """``"PROVED"`` when :attr:`gamma` is a verified bound, else ``"NOT_PROVED"``."""
        return "PROVED" if self.proved else "NOT_PROVED"

    def X_at(self, f_values) -> np.ndarray:
        """``X(rho) = sum_j f_j(rho) X_j`` from the basis values at one point.

        Parameters
        ----------
        f_values : array_like
            ``(f_1(rho), ..., f_k(rho))`` (``[1.0]`` for a constant ``X``).

        Returns
        -------
        ndarray
        """
        f = np.asarray(f_values, dtype=float).reshape(-1)
        return np.einsum("k,kij->ij", f, np.asarray(self.X))

    @property
    def verdict(self) -> str:
        """One line: the bound and what it covers, or why there is none."""
        if not self.proved:
            return f"induced L2 gain: NOT proved ({self.reason or self.solver_status})"
        return f"induced L2 gain <= {self.gamma:.6g} (PROVED) for {self.variation}, {self.coverage}"

    def summary(self) -> dict:
        """Strict JSON (non-finite numbers as ``null``); ``proved`` is the one flag to read."""
        d = {
            "status": self.status,
            "proved": self.proved,
            "gamma": float(self.gamma),
            "gamma_solver": float(self.gamma_solver),
            "frozen_gamma": float(self.frozen_gamma),
            "variation": self.variation,
            "coverage": self.coverage,
            "whole_box": self.whole_box,
            "n_points": self.n_points,
            "n_rate_vertices": self.n_rate_vertices,
            "n_basis": self.n_basis,
            "n_states": self.n_states,
            "solver_status": self.solver_status,
            "reason": self.reason,
            "lmi_margin": float(self.lmi_margin),
            "notes": list(self.notes),
            "seconds": float(self.seconds),
            "verdict": self.verdict,
        }
        return strict_json(d)

    def __str__(self) -> str:
        frozen = finite_or_none(self.frozen_gamma)
        lines = [
            self.verdict,
            f"  frozen (LTI) peak over the grid: {'inf (a frozen system is unstable)' if frozen is None else f'{frozen:.6g}'}",
            f"  solver optimum: {self.gamma_solver:.6g} ({self.solver_status})",
            f"  LMIs: {self.n_points} grid points x {self.n_rate_vertices} rate vertices, "
            f"{self.n_basis} basis function(s), {self.n_states} states",
        ]
        lines += [f"  note: {n}" for n in self.notes]
        return "\n".join(lines)
