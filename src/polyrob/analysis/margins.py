"""What a controller does certify when robust performance is not: its robust margin, and what stands in the way.

A μ bound ``β`` of the robust-performance loop proved at **every** frequency
is itself a certificate (the main loop theorem, Packard & Doyle 1993): for
every parameter set whose normalised ranges are scaled by ``1/β`` about
their centre, the loop is stable and the weighted performance channel has
``‖W·F‖∞ ≤ β``.  MATLAB's ``robgain``/``robstab`` report the same figure
("can tolerate up to 72 % of the modeled uncertainty").  Above 1 the grid's
μ peak bounds nothing between the grid points, so the level is proved
with :func:`polyrob.analysis.mu.between.verify_between` before it is quoted.

Examples
--------
>>> import control
>>> from polyrob.analysis.certificate import certify_loop
>>> from polyrob.analysis.margins import robust_margin
>>> P = control.ss([[-1.0]], [[3.0, 1.0]], [[1.0], [1.0]], [[0.0, 0.0], [0.0, 0.0]])
>>> c = certify_loop(P, -1.0, [[1, 1]], n_u=1, n_y=1)    # N = 3/(s + 2): mu = 1.5
>>> c.status.value                                       # the lower bound 1.5 >= 1 too
'VIOLATED'
>>> m = robust_margin(c)
>>> m.proved, round(m.level, 2), round(m.fraction, 2)
(True, 1.51, 0.66)
>>> m.sentence()
'robust performance at level 1.51 for 66 % of the parameter ranges'
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["RobustMargin", "robust_margin", "dominant_weight"]


@dataclass(frozen=True)
class RobustMargin:
    """A μ level proved at every frequency, read as a margin.

    Attributes
    ----------
    level : float
        ``β``: μ ≤ β at every frequency (NaN when not proved).
    proved : bool
    peak_omega : float
        Frequency (rad/s) of the grid's μ peak: where the problem is hardest.
    reason : str
        Why no level was proved (empty when one was).
    """

    level: float
    proved: bool
    peak_omega: float
    reason: str = ""

    @property
    def fraction(self) -> float:
        """``1/β``: the share of the modelled parameter ranges the level holds for (NaN when not proved)."""
        return 1.0 / self.level if self.proved and self.level > 0 else float("nan")

    def sentence(self) -> str:
        """What the margin proves, in the words of MATLAB's ``robgain`` (a figure, not a verdict: the status decides)."""
        if not self.proved:
            return f"no margin proved ({self.reason})"
        return f"robust performance at level {self.level:.3g} for {100 * self.fraction:.0f} % of the parameter ranges"

    def summary(self) -> dict:
        return {
            "level": float(self.level) if self.proved else None,
            "fraction_of_ranges": float(self.fraction) if self.proved else None,
            "peak_omega": float(self.peak_omega),
            "proved": bool(self.proved),
            "reason": self.reason,
        }


def robust_margin(cert) -> RobustMargin:
    """The μ level of a robust-performance certificate proved at every frequency.

    Parameters
    ----------
    cert : Certificate
        From :func:`polyrob.analysis.certificate.certify_loop` (its sweep and closed loop are used).

    Returns
    -------
    RobustMargin
        ``proved`` only when the loop at ``Δ = 0`` is proved stable and the
        level holds between the grid points; a certified certificate's bound is
        its level.
    """
    from polyrob.analysis.certificate import RESPONSE_BITS, RESPONSE_TOL
    from polyrob.analysis.mu.between import verify_between
    from polyrob.analysis.mu.frequency import needs_extended_precision

    mu = cert.mu
    peak_omega = float(mu.peak_upper_frequency) if mu is not None else float("nan")
    if cert.certified:
        return RobustMargin(float(cert.bound), True, peak_omega)
    if mu is None or cert.closed_loop is None:
        return RobustMargin(float("nan"), False, peak_omega, "no mu sweep")
    st = cert.stable_at_delta0
    if st is None or not st.stable:
        return RobustMargin(float("nan"), False, peak_omega, "the loop at Delta = 0 is not proved stable")
    if not np.isfinite(mu.peak_upper):
        return RobustMargin(float("nan"), False, peak_omega, "mu is unbounded on the grid")
    between = getattr(mu, "between", None)
    if between is not None and between.holds:
        return RobustMargin(float(between.level), True, peak_omega)
    M = cert.closed_loop
    if needs_extended_precision(M, mu.omega, RESPONSE_BITS, RESPONSE_TOL):  # the Hamiltonian test runs in double
        return RobustMargin(float("nan"), False, peak_omega, "the loop's realisation needs extended precision")
    res = verify_between(M, mu)
    if not res.holds:
        return RobustMargin(float("nan"), False, peak_omega, f"not proved between the grid points: {res.reason}")
    return RobustMargin(float(res.level), True, peak_omega)


def dominant_weight(P, N, omega: float) -> str | None:
    """The weighted signal (a label of ``P.z_labels``) with the largest nominal gain at ``omega``.

    ``N = lft(P, K)`` is the loop at ``Δ = 0`` (a certificate's ``closed_loop``),
    stable; its ``w -> z`` response says which performance demand (``W_S`` on
    the error, ``W_T`` on the output, ...) is the hard one there.  ``None``
    for a bare state space.
    """
    from polyrob.analysis.mu.frequency import freqresp

    if not getattr(P, "z_labels", None) or not np.isfinite(omega):
        return None
    zs, ws = P.output_slices["z"], P.input_slices["w"]
    H = np.asarray(freqresp(N[zs, ws], np.array([max(float(omega), 0.0)])))[0]  # (z, w) at omega
    gains = {lab: float(np.linalg.norm(H[rows], 2)) for lab, rows in P.z_slices.items()}
    return max(gains, key=gains.get)
