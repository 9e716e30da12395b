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

Both certify only when ``N`` is stable at ``Δ = 0`` -- the loop around the
plant the LFT is built on (the interval midpoints), not the equilibrium
plant -- as decided by :func:`polyrob.analysis.stability.stability_verdict`,
and both report μ as the **peak on the frequency grid** (see
:attr:`RobustnessResult.covers` and ``docs/mu.md``).  :func:`loop_mu` does
the same for a bare state-space generalized plant.

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
>>> rs.nominally_stable, rs.mu_upper_grid >= rs.mu_lower
(True, True)
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from polyrob.analysis.certificate import certify_loop
from polyrob.analysis.stability import StabilityVerdict, stability_verdict
from polyrob.controller import Controller
from polyrob.plant.generalized import GeneralizedPlant, closed_loop, lft, nominal_closed_loop

__all__ = [
    "RobustnessResult",
    "StabilitySampling",
    "robstab",
    "robstab_implied",
    "robperf",
    "loop_mu",
    "sample_stability",
    "nominal_performance",
]


@dataclass(frozen=True, eq=False)
class RobustnessResult:
    """What ``robstab``/``robperf`` report.

    Attributes
    ----------
    kind : {"stability", "performance"}
        Which of ``robstab`` / ``robperf`` produced it.
    mu_upper_grid, mu_lower : float
        Peak μ upper and lower bounds **on the frequency grid** (see
        :attr:`covers`): ``mu_upper_grid`` bounds μ at every grid point, not
        between them.
    margin_lower, margin_upper : float
        ``1/mu_upper_grid`` and ``1/mu_lower`` (on the grid, as above).
    critical_frequency : float
        Where the lower bound peaks (rad/s).
    worst_delta : ndarray
        For the real parameters: the ``δ`` (one per parameter) of the
        destabilising perturbation, scaled to the boundary ``|δ| = 1/mu_lower``.
    worst_perturbation : ndarray
        The whole perturbation matrix at the critical frequency.
    nominally_stable : bool
        The loop around the nominal plant ``G_n`` (the PLDI's equilibrium
        linearisation) is proved stable.  μ needs more: :attr:`stability`.
    mu : MuBoundsResult
    stability : StabilityVerdict or None
        Stability of ``lft(P, K)`` at ``Δ = 0``, i.e. around the plant the
        LFT is built on (the interval midpoints), weights included.  μ only
        certifies when this is ``"stable"``.
    nominal_stability : StabilityVerdict or None
        The verdict behind ``nominally_stable``.
    certificate : Certificate
        The decision (:mod:`polyrob.analysis.certificate`): ``robust`` is its
        status CERTIFIED.
    model : str
        Uncertainty model the block structure stands for (``""`` if unknown).
    implied_by : str
        ``""`` for a sweep of its own; else what it was read from
        (:func:`robstab_implied`: the figures are then those of that result).
    """

    kind: str
    mu_upper_grid: float
    mu_lower: float
    margin_lower: float
    margin_upper: float
    critical_frequency: float
    worst_delta: np.ndarray
    worst_perturbation: np.ndarray
    nominally_stable: bool
    mu: object
    stability: StabilityVerdict | None = None
    nominal_stability: StabilityVerdict | None = None
    model: str = ""

    certificate: object = None
    implied_by: str = ""

    @property
    def failed(self) -> tuple[str, ...]:
        """Why the loop is not certified (empty when it is): the certificate's reasons."""
        return tuple(self.certificate.reasons)

    @property
    def everywhere(self) -> float | None:
        """A μ bound verified at every frequency (see :func:`polyrob.analysis.mu.between.verify_between`), or ``None``."""
        return getattr(self.mu, "upper_everywhere", None)

    @property
    def robust(self) -> bool:
        """Reads ``certificate.certified`` (:mod:`polyrob.analysis.certificate` decides)."""
        return self.certificate.certified

    @property
    def covers(self) -> str:
        """What the certificate covers, one sentence."""
        return self.certificate.scope.sentence()

    def __str__(self) -> str:
        return f"{self.kind}: peak mu on the grid in [{self.mu_lower:.4g}, {self.mu_upper_grid:.4g}]; {self.certificate.verdict}"

    def summary(self) -> dict:
        return {
            "kind": self.kind,
            "mu_upper_grid": float(self.mu_upper_grid),
            "mu_lower": float(self.mu_lower),
            "mu_scope": "peak on the frequency grid",
            "mu_upper_every_frequency": self.everywhere,
            "between_grid_points": None if self.mu.between is None else self.mu.between.summary(),
            "margin_lower": float(self.margin_lower),
            "margin_upper": float(self.margin_upper),
            "critical_frequency": float(self.critical_frequency),
            "nominally_stable": bool(self.nominally_stable),
            "stable_at_delta0": None if self.stability is None else self.stability.summary(),
            "certificate": self.certificate.summary(),
            "covers": self.covers,
            "notes": list(getattr(self.mu, "notes", ())),
            "implied_by": self.implied_by or None,
        }


def _inv(x) -> float:
    return float(np.inf) if x == 0 else 1.0 / float(x)


def _analyse(
    kind, P, K, blk, omega, *, unc=None, scope=None, n_u=None, n_y=None, certificate=None, **mu_options
) -> RobustnessResult:
    """The certificate of ``lft(P, K)`` (:func:`~polyrob.analysis.certificate.certify_loop`, or ``certificate``
    when it is that call's already) with the figures of a robustness result."""
    cert = certificate
    if cert is None:
        cert = certify_loop(P, K, blk, omega, kind=kind, scope=scope, n_u=n_u, n_y=n_y, **mu_options)
    mu = cert.mu
    worst = np.asarray(mu.worst_delta)
    nominal = cert.stable_at_delta0
    delta = np.real(np.diag(worst)) if worst.size else np.zeros(0)
    if unc is not None:
        diag = delta[: unc.n_delta] if delta.size else np.zeros(unc.n_delta)
        # one δ per parameter: merged parameters occupy several channels
        delta = np.zeros(unc.n_params)
        for channel, param in enumerate(unc.channel_parameter):
            if param >= 0:  # -1: a channel of a full (residual) block, no parameter
                delta[param] = diag[channel]
        nominal = stability_verdict(nominal_closed_loop(unc, K).system)
    return RobustnessResult(
        kind=kind,
        mu_upper_grid=float(mu.peak_upper),
        mu_lower=float(mu.peak_lower),
        margin_lower=_inv(mu.peak_upper),
        margin_upper=_inv(mu.peak_lower),
        critical_frequency=float(mu.critical_frequency),
        worst_delta=delta,
        worst_perturbation=worst,
        nominally_stable=nominal.stable,
        mu=mu,
        stability=cert.stable_at_delta0,
        nominal_stability=nominal,
        model=_model_name(P) if hasattr(P, "uncertain") else "",
        certificate=cert,
    )


def _model_name(P: GeneralizedPlant) -> str:
    model = getattr(P.uncertain, "model", "")
    if model:
        return str(model)
    info = getattr(P.uncertain, "info", None) or {}
    return str(info.get("model", "") or info.get("uncertainty_model", "") or "")


def robstab(P: GeneralizedPlant, K, omega=None, **mu_options) -> RobustnessResult:
    """Robust stability of ``lft(P, K)``: μ of the uncertainty loop ``d -> v``.

    Certified (``robust``) only when ``lft(P, K)`` is proved stable at
    ``Δ = 0`` (:func:`~polyrob.analysis.stability.stability_verdict`) and the
    peak μ upper bound on the grid is below 1.

    Parameters
    ----------
    P : GeneralizedPlant
    K : controller (``n_u x n_y``)
    omega : array_like, optional
        Frequencies; default: automatic grid refined around the peak.
    **mu_options
        Passed to :func:`polyrob.analysis.mu.bounds.mu_bounds` (``method``, ``refine_peak``, ...).
    """
    return _analyse("stability", P, K, P.block_structure_rs, omega, unc=P.uncertain, **mu_options)


def robstab_implied(rp: RobustnessResult) -> RobustnessResult | None:
    """Robust stability read from a certified robust-performance result, without a sweep.

    The uncertainty block is a sub-block of the robust-performance structure,
    so at every frequency μ of the uncertainty channels alone is at most μ
    with the performance block (Packard & Doyle 1993, the main loop
    theorem's corollary): a robust-performance bound ``β`` proved at every
    frequency bounds robust-stability μ by ``β`` too.  ``None`` unless ``rp``
    is certified (then only a sweep can say more).  The bound is not the
    robust-stability μ itself (:func:`robstab` computes it: on ``paper_2r``
    at four times the paper's bandwidths it costs 240 s against 18 s for
    robust performance, AB13MD being slow on the all-real block structure at
    low frequencies); the result says so in its scope and its ``mu_lower`` is
    the trivial 0.

    Examples
    --------
    >>> import numpy as np, control
    >>> from polyrob.analysis.robust import loop_mu, robstab_implied
    >>> P = control.ss([[-1.0]], [[1.0, 1.0]], [[1.0], [1.0]], [[0.0, 0.0], [0.0, 0.0]])
    >>> rp = loop_mu(P, -1.0, [[1, 1]], np.logspace(-2, 2, 41), n_u=1, n_y=1)
    >>> rs = robstab_implied(rp)
    >>> rs.kind, rs.certificate.status is rp.certificate.status, rs.certificate.bound == rp.certificate.bound
    ('stability', True, True)
    """
    cert = rp.certificate
    if not cert.certified:
        return None
    note = f"implied by the robust-performance certificate (mu <= {cert.bound:.4g} with the performance block)"
    scope = replace(cert.scope, kind="robust stability", notes=tuple(cert.scope.notes) + (note,))
    return replace(
        rp,
        kind="stability",
        mu_lower=0.0,
        margin_upper=float(np.inf),
        certificate=replace(cert, scope=scope, mu_lower=0.0),
        implied_by="robust performance",
    )


def robperf(P: GeneralizedPlant, K, omega=None, *, certificate=None, **mu_options) -> RobustnessResult:
    """Robust performance of ``lft(P, K)``: μ against uncertainty + performance block.

    Certified only when ``lft(P, K)`` is proved stable at ``Δ = 0`` and the
    peak μ upper bound on the grid is below 1 (main loop theorem).
    ``certificate``: this loop's certificate already made by the same call
    (:func:`polyrob.pipeline.analysis.reusable_certificate` checks that), used instead of a sweep.
    """
    return _analyse(
        "performance", P, K, P.block_structure_rp, omega, unc=P.uncertain, certificate=certificate, **mu_options
    )


def loop_mu(P, K, blk, omega=None, *, n_u: int, n_y: int, kind: str = "performance", **mu_options) -> RobustnessResult:
    """μ analysis of ``lft(P, K)`` for a bare state-space generalized plant.

    For published problems given as one ``StateSpace`` (e.g.
    :func:`polyrob.examples.distillation_plant`): the controls are the last
    ``n_u`` inputs, the measurements the last ``n_y`` outputs, and ``blk``
    covers all remaining channels.  ``worst_delta`` is then the diagonal of
    the worst perturbation.

    Examples
    --------
    >>> import numpy as np, control
    >>> from polyrob.analysis.robust import loop_mu
    >>> P = control.ss([[-1.0]], [[1.0, 1.0]], [[1.0], [1.0]], [[0.0, 0.0], [0.0, 0.0]])
    >>> r = loop_mu(P, -1.0, [[1, 1]], np.logspace(-2, 2, 41), n_u=1, n_y=1)
    >>> r.stability.verdict, round(r.mu_upper_grid, 4)          # N = 1/(s + 2)
    ('stable', 0.5)
    """
    return _analyse(kind, P, K, blk, omega, n_u=n_u, n_y=n_y, **mu_options)


def nominal_performance(P: GeneralizedPlant, K) -> float:
    """H∞ norm from ``w`` to ``z`` of the loop around the nominal plant ``G_n``.

    ``inf`` when that loop is proved unstable (an unstable system has no
    finite H∞ norm), ``nan`` when its stability is undecided; else the
    proved upper bound of :func:`polyrob.analysis.norms.hinf_norm`.
    """
    from polyrob.analysis.norms import hinf_norm

    N = lft(P.at(P.uncertain.nominal_delta, strict=False), K, n_u=P.n_u, n_y=P.n_y)
    verdict = stability_verdict(N)
    if verdict.unstable:
        return float("inf")
    if not verdict.stable:
        return float("nan")
    return float(hinf_norm(N))


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
    undecided : int
        Samples whose stability is undecided at double precision (counted
        as not stable in the fractions).
    """

    random: int
    random_stable: float
    corners: int
    corners_stable: float | None
    worst_delta: np.ndarray
    worst_abscissa: float
    undecided: int = 0


def sample_stability(unc, K, *, n: int = 1000, max_corners: int = 1024, seed: int = 0) -> StabilitySampling:
    """Monte Carlo and corner check of closed-loop stability over the parameter box.

    A sampled check, not a certificate.  Samples that double precision finds
    stable (an eigenvalue bound, or the Lyapunov test) count as stable;
    samples it finds unstable or cannot decide are decided again in extended
    precision (:func:`~polyrob.analysis.stability.stability_verdict`).
    """
    K = Controller.of(K)  # once: every sample's closed_loop takes it as it is
    deltas = unc.delta_samples(n, kind="uniform", seed=seed)
    corners = None
    if 2**unc.n_params <= max_corners:
        corners = unc.delta_samples(kind="corners", max_corners=max_corners)
    worst, worst_abs, undecided = None, -np.inf, 0

    def stable_fraction(samples):
        nonlocal worst, worst_abs, undecided
        ok = 0
        for d in samples:
            sys = closed_loop(unc, K, d).system
            # a sampled check, not a certificate: a stable double-precision
            # eigenvalue bound is taken alone (extended precision costs ~0.5 s
            # per sample on a D-K loop); what would be reported as unstable
            # or undecided is re-decided in extended precision
            v = stability_verdict(sys, extended_bits=0)
            if not v.stable:
                v = stability_verdict(sys)
            ok += v.stable
            undecided += not (v.stable or v.unstable)
            if v.abscissa > worst_abs:
                worst, worst_abs = d, v.abscissa
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
        undecided=undecided,
    )
