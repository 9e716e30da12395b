"""The moving-robot certificate as a result: its verdict, its details and its record.

:class:`MovingRobotCertificate` is what both moving-robot routes return --
the robot scheduled on its state with the domain's rates
(:mod:`polyrob.analysis.lpv.moving`, decided from an :func:`polyrob.lpvnorm`
result) and the masses held constant with the state moving at any rate
(:mod:`polyrob.analysis.lpv.constant`, decided by μ: ``decided``).

Examples
--------
>>> c = MovingRobotCertificate.not_computed("asked not to (--no-moving)")
>>> c.verdict
'moving robot: robust performance not computed (asked not to (--no-moving))'
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

__all__ = ["refuses", "MovingRobotCertificate", "rate_words"]


def rate_words(names, rates, source: str) -> str:
    """``dq2/dt = qdot2 (|dq2/dt| <= 9.956), |dqdot1/dt| <= 18.59, ...``: the rate bounds in words."""
    parts = []
    for name, (_lo, hi) in zip(names, rates):
        dot = f"d{name}/dt"
        if name.startswith("q") and not name.startswith("qdot") and f"qdot{name[1:]}" in names and np.isfinite(hi):
            parts.append(f"{dot} = qdot{name[1:]} (|{dot}| <= {hi:.4g})")
        else:
            parts.append(f"|{dot}| <= {hi:.4g}" if np.isfinite(hi) else f"{dot} arbitrary")
    bounded = any(n.startswith("qdot") and np.isfinite(r[1]) for n, r in zip(names, rates))
    return ", ".join(parts) + (f" (accelerations {source})" if bounded else "")


@dataclass(frozen=True, eq=False)
class MovingRobotCertificate:
    """Robust performance of the linearised robot moving within rate bounds.

    Attributes
    ----------
    computed : bool
        False when the moving-robot check did not apply (its reason says why).
    gamma : float
        Proved bound of the ``r -> z`` induced L2 gain on the grid (``inf``: none).
    frozen_gamma : float
        Largest frozen (LTI) H-infinity norm over the grid points (NaN on the μ route).  Not a lower bound
        of the moving robot's gain: at a grid point where a scheduled position's velocity or an acceleration
        is not 0 the robot cannot stay, so that frozen loop is no motion of it (:attr:`lower` is the gain found).
    rates : tuple of (float, float)
    rate_words : str
    grid_words : str
    result : LpvNormResult or None
    scope : Scope or None
    notes : tuple of str
    finer : dict
        The returned ``X`` re-checked on a finer grid
        (:func:`~polyrob.analysis.lpv.basis.finer_recheck`: ``points``,
        ``gamma``, ``holds_at_gamma``); empty when not re-checked.
    cells : dict
        The same ``X`` proved between the grid points
        (:meth:`polyrob.analysis.lpv.cells.CellCheck.summary`); empty when not tried.
    lower : dict
        The largest gain found along admissible trajectories
        (:meth:`polyrob.analysis.time_varying.trajectory_gains.TrajectoryLowerBound.summary`); empty when not computed.
    seconds : float
    decided : Certificate or None
        The certificate when another test decided it (μ, :mod:`polyrob.analysis.lpv.constant`).
    worst_case : WorstCaseGain or None
        On the constant-parameter route, when asked for: the weighted gain
        of the moving robot over the whole set, bounded at every frequency
        on the same merged structure (:func:`polyrob.analysis.worst_case.wcgain`,
        no member claimed: the structure is a sufficient test).
    """

    #: The key of its figures in a run's certificate record (:mod:`polyrob.report.certificates`).
    record_key = "moving"

    computed: bool
    gamma: float = float("inf")
    frozen_gamma: float = float("nan")
    rates: tuple = ()
    rate_words: str = ""
    grid_words: str = ""
    result: object = None
    scope: object = None
    notes: tuple = ()
    finer: dict = field(default_factory=dict)
    cells: dict = field(default_factory=dict)
    lower: dict = field(default_factory=dict)
    seconds: float = 0.0
    decided: object = None
    worst_case: object = None

    @classmethod
    def not_computed(cls, why: str) -> MovingRobotCertificate:
        """A certificate that was not computed, and why."""
        return cls(False, notes=(why,))

    @property
    def certificate(self):
        """The decided :class:`~polyrob.analysis.certificate.Certificate` (``None`` when not computed)."""
        from polyrob.analysis.certificate import Scope, gridded_gain_certificate

        if not self.computed or self.decided is not None:  # decided: a certificate made elsewhere (mu)
            return self.decided
        r = self.result
        proved = bool(r is not None and r.proved and np.isfinite(self.gamma))
        # proved between the grid points: on the whole box by multi-convexity, or on the cells covering it
        between = bool(r is not None and r.whole_box) or bool(self.cells.get("holds"))
        why = "" if proved else (self.notes[-1] if self.notes else (r.reason if r is not None else ""))
        scope = replace(self.scope or Scope(), kind="robust performance", frequencies="")
        return gridded_gain_certificate(scope, gamma=self.gamma, proved=proved, between=between, why=why)

    @property
    def verdict(self) -> str:
        """``moving robot with rates <= ...: robust performance ...``."""
        found = f"; L2 gain {self.lower['words']}" if self.lower else ""
        if self.lower and self.lower["gamma"] >= 1.0:  # no certificate can hold: say so where the user reads
            found += ": at or above 1, robust performance fails for the linearised robot along that motion (simulated)"
        if not self.computed:
            why = self.notes[0] if self.notes else "not asked"
            return f"moving robot: robust performance not computed ({why}){found}"
        return f"moving robot with rates {self.rate_words}: {self.certificate.verdict}{found}"

    def details(self) -> str:
        """What it covers, the frozen peak beside it."""
        if not self.computed:
            return ""
        lines = [f"covers: {self.certificate.scope.sentence()}"]
        if self.decided is not None:
            lines.append(f"mu lower bound {self.decided.mu_lower:.4g}; {self.grid_words}; {self.seconds:.0f} s")
            if self.worst_case is not None:  # the whole set in motion, at a weaker performance level
                lines.append(f"moving robot over the whole set: {moving_gain_words(self.worst_case)}")
            return "\n".join(lines)
        lines.append(
            f"frozen peak over the grid {self.frozen_gamma:.4g} (not a lower bound: the robot cannot rest at most grid points); "
            f"{self.grid_words}; {self.seconds:.0f} s"
        )
        if self.finer.get("points"):
            f = self.finer
            lines.append(
                f"the same X re-checked on a finer grid of {f['points']} points (sampled, not between them): "
                + (f"bound {f['gamma']:.4g}" if np.isfinite(f["gamma"]) else f"no bound ({f.get('reason', '')})")
            )
        if self.cells:
            c = self.cells
            lines.append(
                f"between the grid points: proved at level {c['gamma']:.4g} on {c['cells']} cells ({c['seconds']:.0f} s)"
                if c["holds"]
                else f"between the grid points: not proved ({c['reason']})"
            )
        return "\n".join(lines)

    def summary(self) -> dict:
        """Strict JSON."""
        from polyrob.analysis.scope import finite_or_none

        cert = self.certificate
        return {
            "computed": self.computed,
            "status": None if cert is None else cert.status.value,
            "certified": bool(cert is not None and cert.certified),
            "gamma": finite_or_none(self.gamma),
            "frozen_gamma": finite_or_none(self.frozen_gamma),
            "mu_lower": None if self.decided is None else finite_or_none(self.decided.mu_lower),
            "route": "mu, constant parameters" if self.decided is not None else "lpvnorm, the state's rates",
            "rates": [[finite_or_none(lo), finite_or_none(hi)] for lo, hi in self.rates],
            "rate_words": self.rate_words,
            "grid": self.grid_words,
            "lpvnorm": None if self.result is None else self.result.summary(),
            "scope": None if cert is None else cert.scope.summary(),
            "notes": list(self.notes),
            "finer_grid": {k: finite_or_none(v) if isinstance(v, float) else v for k, v in self.finer.items()},
            "cells": dict(self.cells),
            "lower": dict(self.lower),
            # the number the report's verdict table shows beside the bound (report.certificates.lower_bound_words)
            "lower_bound": finite_or_none(float(self.lower["gamma"])) if self.lower else None,
            "seconds": round(float(self.seconds), 3),
            "verdict": self.verdict,
            "worst_case": None if self.worst_case is None else self.worst_case.summary(),
        }


def moving_gain_words(wc) -> str:
    """The moving robot's worst-case gain in words: an upper bound only (its structure is a sufficient test)."""
    if wc.proved:
        return f"every motion stable, weighted gain <= {wc.upper:.3g} (at every frequency)"
    return f"no gain bound proved ({wc.reason})"


def refuses(summary: dict | None) -> bool:
    """A moving-robot certificate's summary (:meth:`MovingRobotCertificate.summary`) that was computed and whose
    status is not CERTIFIED: where it exists, it decides with μ (``synth --moving``, ``batch --moving``).

    >>> refuses(None), refuses({"computed": False}), refuses({"computed": True, "status": "GRID_ONLY"})
    (False, False, True)
    >>> refuses({"computed": True, "status": "CERTIFIED"})
    False
    """
    from polyrob.analysis.certificate import Status

    if not summary or not summary.get("computed"):
        return False
    status = summary.get("status")
    return status is None or not Status(status).certified
