"""The result of a μ-synthesis: what MATLAB's ``musyn`` returns as ``info``, and more."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import control
import numpy as np

from polyrob.controller import Controller

__all__ = ["MusynResult"]


@dataclass(frozen=True, eq=False)
class MusynResult:
    """A controller with its robustness certificate.

    Attributes
    ----------
    controller : control.StateSpace
        ``K`` (``n_u x n_y``), ``u = K y_meas``.
    structure : str
        ``"full"``, ``"tf3"`` (each K_ij a third-order transfer function),
        ``"pid"``, ``"ss:N"``, or ``"reduced:N"`` for a reduced full-order one.
    order : int
        Number of states of ``controller``.
    peak_mu : float
        Peak of the μ upper bound of the closed loop ``lft(P, K)`` on the
        certificate's peak-refined grid (``certificate.bound`` is the figure
        its status rests on).
    peak_mu_lower : float
        Peak of the μ lower bound on the same grid.
    peak_frequency : float
        Where the upper bound peaks (rad/s).
    mu_history : ndarray
        Peak μ upper bound after each iteration (MATLAB's ``info.MussvBnds``).
    gamma_history : ndarray
        H∞ norm reached by each K-step (or the scaled objective for fixed structure).
    scalings : tuple
        The D (and G) scalings of the last iteration (filters or per-frequency data).
    closed_loop : control.StateSpace
        ``lft(P, K)``: ``[d; w] -> [v; z]``.
    certificate : Certificate
        The decision (:mod:`polyrob.analysis.certificate`) on the synthesis'
        own certificate grid; ``certificate.mu`` is the sweep behind ``peak_mu``.
    iterations : int
    seconds : float
    info : dict
        Regularisation applied, solver notes, per-iteration timings.
    """

    controller: control.StateSpace
    structure: str
    order: int
    peak_mu: float
    peak_mu_lower: float
    peak_frequency: float
    mu_history: np.ndarray
    gamma_history: np.ndarray
    scalings: tuple
    closed_loop: control.StateSpace
    certificate: object
    iterations: int
    seconds: float
    info: dict = field(default_factory=dict)

    @cached_property
    def controller_value(self) -> Controller:
        """``controller`` as a :class:`~polyrob.controller.Controller`, built once (its ``system`` is ``controller``)."""
        return Controller.of(self.controller)

    @classmethod
    def certified(
        cls,
        controller,
        structure: str,
        certificate,
        *,
        seconds: float,
        info: dict,
        mu_history=None,
        gamma_history=None,
        scalings: tuple = (),
        iterations: int = 0,
    ) -> MusynResult:
        """The result of ``controller`` with its ``certificate``, whose figures (peak μ, closed loop) it reads.

        Without an iteration (a tuned PID, a reduced controller) the history
        is the certificate's peak and no H∞ level.
        """
        mu = certificate.mu
        return cls(
            controller=controller,
            structure=structure,
            order=int(controller.nstates),
            peak_mu=float(certificate.mu_upper_grid),
            peak_mu_lower=float(certificate.mu_lower),
            peak_frequency=float(mu.peak_upper_frequency) if mu is not None else float("nan"),
            mu_history=np.asarray([certificate.mu_upper_grid] if mu_history is None else mu_history, float),
            gamma_history=np.asarray([np.nan] if gamma_history is None else gamma_history, float),
            scalings=scalings,
            closed_loop=certificate.closed_loop,
            certificate=certificate,
            iterations=int(iterations),
            seconds=float(seconds),
            info=info,
        )

    @property
    def peak_mu_everywhere(self) -> float | None:
        """A μ bound verified at every frequency (the certificate's check between its grid points), or ``None``."""
        return getattr(getattr(self.certificate, "mu", None), "upper_everywhere", None)

    @property
    def status(self):
        """The certificate's :class:`~polyrob.analysis.certificate.Status`."""
        return self.certificate.status

    def summary(self) -> dict:
        """Plain figures for reports and JSON."""
        return {
            "structure": self.structure,
            "order": int(self.order),
            "peak_mu_upper": float(self.peak_mu),
            "mu_upper_every_frequency": self.peak_mu_everywhere,
            "certificate": self.certificate.summary(),
            "peak_mu_lower": float(self.peak_mu_lower),
            "peak_frequency": float(self.peak_frequency),
            "iterations": int(self.iterations),
            "mu_history": [float(x) for x in np.asarray(self.mu_history)],
            "seconds": round(float(self.seconds), 3),
        }
