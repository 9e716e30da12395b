"""Robust stability and robust performance of a closed loop, as MATLAB's ``robstab``/``robperf``.

Both take the generalized plant ``P`` and a controller ``K``, close
``N = lft(P, K)`` and compute μ over frequency:

- :func:`robstab`: μ of ``N[v, d]`` against the uncertainty blocks.  The
  stability margin is ``1/μ``: the loop stays stable for every ``δ`` scaled by
  less than ``1/μ_upper`` (guaranteed) and is destabilised by the returned
  ``worst_delta`` scaled by ``1/μ_lower``.
- :func:`robperf`: μ of ``N`` against the uncertainty blocks plus the full
  complex performance block; ``μ < 1`` certifies robust performance (the main
  loop theorem).

:func:`sample_stability` adds the checks a μ bound is read against: closed-
loop poles at random parameters and at the corners of the box.

Examples
--------
>>> import numpy as np, polyrob
>>> from polyrob.plant.weights import paper_weights
>>> pldi = polyrob.bound_pldi(polyrob.load_robot("paper_2r"), samples=256, coverage=0, progress=False)
>>> unc = polyrob.uncertain_plant(pldi)
>>> P = polyrob.generalized_plant(unc, *paper_weights())
>>> rs = robstab(P, polyrob.paper_controller(), omega=np.logspace(-2, 3, 40), refine_peak=False)
>>> rs.nominally_stable, rs.mu_upper >= rs.mu_lower
(True, True)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from polyrob.plant.generalized import GeneralizedPlant, closed_loop, lft, nominal_closed_loop

__all__ = ["RobustnessResult", "StabilitySampling", "robstab", "robperf", "sample_stability", "nominal_performance"]


@dataclass(frozen=True, eq=False)
class RobustnessResult:
    """What ``robstab``/``robperf`` report.

    Attributes
    ----------
    kind : {"stability", "performance"}
    mu_upper, mu_lower : float
        Peak μ bounds over frequency.
    margin_lower, margin_upper : float
        ``1/mu_upper`` (guaranteed margin) and ``1/mu_lower``.
    critical_frequency : float
        Where the lower bound peaks (rad/s).
    worst_delta : ndarray
        For the real parameters: the ``δ`` (one per parameter) of the
        destabilising perturbation, scaled to the boundary ``|δ| = 1/mu_lower``.
    worst_perturbation : ndarray
        The whole perturbation matrix at the critical frequency.
    nominally_stable : bool
    mu : MuBoundsResult
    """

    kind: str
    mu_upper: float
    mu_lower: float
    margin_lower: float
    margin_upper: float
    critical_frequency: float
    worst_delta: np.ndarray
    worst_perturbation: np.ndarray
    nominally_stable: bool
    mu: object

    @property
    def robust(self) -> bool:
        """Certified: ``mu_upper < 1``."""
        return bool(self.mu_upper < 1.0)

    def summary(self) -> dict:
        return {
            "kind": self.kind,
            "mu_upper": float(self.mu_upper),
            "mu_lower": float(self.mu_lower),
            "margin_lower": float(self.margin_lower),
            "margin_upper": float(self.margin_upper),
            "critical_frequency": float(self.critical_frequency),
            "nominally_stable": bool(self.nominally_stable),
            "certified_robust": self.robust,
        }


def _analyse(kind, N, blk, P: GeneralizedPlant, K, omega, **mu_options) -> RobustnessResult:
    from polyrob.analysis.mu import mu_bounds

    mu = mu_bounds(N, blk, omega, **mu_options)
    worst = np.asarray(mu.worst_delta)
    diag = np.real(np.diag(worst))[: P.n_delta] if worst.size else np.zeros(P.n_delta)
    # one δ per parameter: merged parameters occupy several channels
    unc = P.uncertain
    delta = np.zeros(unc.n_params)
    for channel, param in enumerate(unc.channel_parameter):
        delta[param] = diag[channel]
    nominal = nominal_closed_loop(unc, K)
    inv = lambda x: float(np.inf) if x == 0 else 1.0 / float(x)  # noqa: E731
    return RobustnessResult(
        kind=kind,
        mu_upper=float(mu.peak_upper),
        mu_lower=float(mu.peak_lower),
        margin_lower=inv(mu.peak_upper),
        margin_upper=inv(mu.peak_lower),
        critical_frequency=float(mu.critical_frequency),
        worst_delta=delta,
        worst_perturbation=worst,
        nominally_stable=bool(nominal.stable),
        mu=mu,
    )


def robstab(P: GeneralizedPlant, K, omega=None, **mu_options) -> RobustnessResult:
    """Robust stability of ``lft(P, K)``: μ of the uncertainty loop ``d -> v``.

    Parameters
    ----------
    P : GeneralizedPlant
    K : controller (``n_u x n_y``)
    omega : array_like, optional
        Frequencies; default: automatic grid refined around the peak.
    **mu_options
        Passed to :func:`polyrob.analysis.mu.mu_bounds` (``method``, ``refine_peak``, ...).
    """
    N = lft(P, K)
    s_v, s_d = P.output_slices["v"], P.input_slices["d"]
    M = N[s_v, s_d]
    return _analyse("stability", M, P.block_structure_rs, P, K, omega, **mu_options)


def robperf(P: GeneralizedPlant, K, omega=None, **mu_options) -> RobustnessResult:
    """Robust performance of ``lft(P, K)``: μ against uncertainty + performance block."""
    N = lft(P, K)
    return _analyse("performance", N, P.block_structure_rp, P, K, omega, **mu_options)


def nominal_performance(P: GeneralizedPlant, K) -> float:
    """H∞ norm from ``w`` to ``z`` of the loop around the nominal plant ``G_n``."""
    import control

    N = lft(P.at(P.uncertain.nominal_delta, strict=False), K, n_u=P.n_u, n_y=P.n_y)
    return float(control.linfnorm(N)[0])


@dataclass(frozen=True, eq=False)
class StabilitySampling:
    """Closed-loop stability at sampled parameters.

    Attributes
    ----------
    random_stable : float
        Fraction of ``random`` uniform ``δ`` with a stable closed loop.
    corners_stable : float or None
        Fraction of the ``2^k`` corners (None when there are too many).
    worst_delta : ndarray
        The sampled ``δ`` with the largest closed-loop spectral abscissa.
    worst_abscissa : float
        Its largest real part of a closed-loop pole (> 0: unstable).
    """

    random: int
    random_stable: float
    corners: int
    corners_stable: float | None
    worst_delta: np.ndarray
    worst_abscissa: float


def sample_stability(unc, K, *, n: int = 1000, max_corners: int = 1024, seed: int = 0) -> StabilitySampling:
    """Monte Carlo and corner check of closed-loop stability over the parameter box."""
    deltas = unc.delta_samples(n, kind="uniform", seed=seed)
    corners = None
    if 2**unc.n_params <= max_corners:
        corners = unc.delta_samples(kind="corners", max_corners=max_corners)
    worst, worst_abs = None, -np.inf

    def stable_fraction(samples):
        nonlocal worst, worst_abs
        ok = 0
        for d in samples:
            cl = closed_loop(unc, K, d)
            a = float(cl.poles.real.max()) if cl.poles.size else -np.inf
            ok += a < 0
            if a > worst_abs:
                worst, worst_abs = d, a
        return ok / len(samples)

    rand_ok = stable_fraction(deltas)
    corner_ok = None if corners is None else stable_fraction(corners)
    return StabilitySampling(
        random=len(deltas),
        random_stable=rand_ok,
        corners=0 if corners is None else len(corners),
        corners_stable=corner_ok,
        worst_delta=np.asarray(worst),
        worst_abscissa=worst_abs,
    )
