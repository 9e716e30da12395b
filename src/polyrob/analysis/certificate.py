"""THE certificate: one decision of what a closed loop is proved to do, and what that covers.

Every verdict polyrob prints -- ``synth``, ``analyze``, ``run``, ``reduce``,
``--max-bandwidth``, the fleet, the report, the JSON, the exit status --
reads :attr:`Certificate.status`, decided here and nowhere else:

``CERTIFIED``
    The loop at ``Δ = 0`` is proved stable (extended-precision verdict) and
    the bound is proved below 1: for μ, the upper bound holds **at every
    frequency** (the grid's D-G scalings checked between its points,
    :func:`polyrob.analysis.mu.between.verify_between`); for an L2 gain,
    the LMI solution re-checked a posteriori.
``GRID_ONLY``
    μ < 1 at every point of the frequency grid, but not proved between the
    points (the check gave up, or was not possible): the grid peak is an
    estimate of sup μ from below, not a bound.
``NOT_CERTIFIED``
    Neither proved nor disproved (μ straddles 1, the loop's stability
    undecided, the model misses Jacobians of the robot, ...).
``VIOLATED``
    Disproved: the loop at ``Δ = 0`` (a member of the set) is proved
    unstable, or the μ lower bound is ``>= 1`` (a member of the set breaks it).  The set is the
    uncertainty model's, which holds the robot's set and may hold more: VIOLATED disproves the
    model's robust property, as MATLAB's ``robstab`` lower bound does, not each robot of a wider model.

A certificate also says what it covers (:class:`Scope`): which property, for
which variation of the parameters, on which frequencies, for which model and
how well that model covers the robot, over which domain and how the PLDI was
enclosed (sampled, or proved by interval arithmetic: the weakest input wins).

Examples
--------
>>> import control
>>> P = control.ss([[-1.0]], [[1.0, 1.0]], [[1.0], [1.0]], [[0.0, 0.0], [0.0, 0.0]])
>>> c = certify_loop(P, -1.0, [[1, 1]], n_u=1, n_y=1)     # N = 1/(s + 2), mu = 0.5
>>> c.status.value, round(c.mu_upper, 3)
('CERTIFIED', 0.504)
>>> c.verdict
'robust performance CERTIFIED: mu <= 0.504 at every frequency'
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field, replace

import numpy as np

from polyrob.analysis.loop_sweep import FLAT_RTOL, POINTS_PER_DECADE, RESPONSE_BITS, RESPONSE_TOL, grid_words
from polyrob.analysis.scope import ARBITRARY, FROZEN, Scope, finite_or_none, strict_json, weakest_enclosure
from polyrob.errors import ArgumentError

__all__ = [
    "Status",
    "Scope",
    "Certificate",
    "certify_loop",
    "certificate_of_sweep",
    "rescoped",
    "union_certificate",
    "decide_mu",
    "decide_gain",
    "decide_gridded_gain",
    "gain_certificate",
    "gridded_gain_certificate",
    "nominal_performance_verdict",
    "friction_sentence",
    "weakest_enclosure",
    "FROZEN",
    "ARBITRARY",
    "POINTS_PER_DECADE",
    "FLAT_RTOL",
    "RESPONSE_BITS",
    "RESPONSE_TOL",
]


class Status(str, enum.Enum):
    """The four outcomes of a certificate (module docstring)."""

    CERTIFIED = "CERTIFIED"
    GRID_ONLY = "GRID_ONLY"
    NOT_CERTIFIED = "NOT_CERTIFIED"
    VIOLATED = "VIOLATED"

    def __str__(self) -> str:
        return self.value

    @property
    def certified(self) -> bool:
        """Only CERTIFIED certifies."""
        return self is Status.CERTIFIED


#: The share of a certificate's progress its grid sweep fills; the check between the points fills the rest (its
#: intervals are known only as it splits them, so its share is a guess, and the job's line never goes back).
SWEEP_SHARE = 0.75

#: How the words of a verdict read for each status (GRID_ONLY says exactly what holds).
_WORDS = {
    Status.CERTIFIED: "CERTIFIED",
    Status.GRID_ONLY: "GRID_ONLY (mu < 1 on the frequency grid only, not proved between its points)",
    Status.NOT_CERTIFIED: "NOT certified",
    Status.VIOLATED: "VIOLATED",
}


@dataclass(frozen=True, eq=False)
class Certificate:
    """One decided certificate.

    Attributes
    ----------
    status : Status
        CERTIFIED, GRID_ONLY, NOT_CERTIFIED or VIOLATED, decided in this module only.
    bound : float
        The figure the status rests on: for μ the bound at every frequency
        when it was proved, else the grid peak; for an L2 gain the verified γ.
        :attr:`mu_upper` is the proved μ bound alone.
    mu_upper_grid, mu_lower : float
        Peak μ upper bound on the grid and the peak lower bound (NaN for a gain).
    stable_at_delta0 : StabilityVerdict or None
    scope : Scope
    reasons : tuple of str
        Why the status is not CERTIFIED (empty when it is).
    mu : MuBoundsResult or None
        The sweep (with ``mu.between``, the check between its points).
    closed_loop : control.StateSpace or None
    default_grid : bool
        The sweep ran on the loop's own default grid (``omega=None``): the
        same call as every other caller's, so it can be reused (:func:`rescoped`).
    bound_everywhere : bool
        ``bound`` is a μ bound proved at every frequency (not a grid peak).
    lower_bound_disproves : bool
        A μ lower bound ``>= 1`` disproves (VIOLATED); ``False`` for a
        structure that is only a sufficient test (:func:`certify_loop`).
    """

    status: Status
    bound: float
    mu_upper_grid: float
    mu_lower: float
    stable_at_delta0: object
    scope: Scope
    reasons: tuple = ()
    mu: object = None
    closed_loop: object = field(default=None, repr=False)
    default_grid: bool = False
    bound_everywhere: bool = False
    lower_bound_disproves: bool = True

    @property
    def certified(self) -> bool:
        """``status is CERTIFIED``: the one test every caller uses."""
        return self.status.certified

    @property
    def mu_upper(self) -> float:
        """The μ upper bound proved at every frequency: ``inf`` when none was (the grid peak is :attr:`mu_upper_grid`)."""
        return float(self.bound) if self.bound_everywhere else float("inf")

    @property
    def verdict(self) -> str:
        """The one short verdict line (no scope: :meth:`details` has it)."""
        what = f"{self.scope.kind} {_WORDS[self.status]}"
        if self.status is Status.CERTIFIED:
            return f"{what}: {self.figure}" if self.figure else what
        if self.status is Status.GRID_ONLY and self.mu is None and np.isnan(self.mu_upper_grid):
            return f"{self.scope.kind} GRID_ONLY: L2 gain <= {self.bound:.4g} < 1 at the parameter grid's points only"
        if self.status is Status.GRID_ONLY:
            return f"{what}: peak {self.mu_upper_grid:.4g}"
        return f"{what}: {self.reasons[0]}" if self.reasons else what

    @property
    def figure(self) -> str:
        """What a CERTIFIED status rests on, in words (``mu <= 0.9449 at every frequency``; empty otherwise)."""
        if self.status is not Status.CERTIFIED:
            return ""
        if self.mu is None:
            return f"L2 gain <= {self.bound:.4g} < 1" if "performance" in self.scope.kind else ""
        return f"mu <= {self.bound:.4g} at every frequency"

    def details(self) -> str:
        """The lines below the verdict: what it covers, and why it is not more."""
        lines = [f"covers: {self.scope.sentence()}"]
        lines += [f"why: {r}" for r in self.reasons[1:] if self.status is not Status.CERTIFIED]
        if self.stable_at_delta0 is not None:
            lines.append(f"loop at Delta = 0: {self.stable_at_delta0.verdict}")
        return "\n".join(lines)

    def summary(self) -> dict:
        """JSON: ``certified`` is true only for status CERTIFIED."""
        between = getattr(self.mu, "between", None)
        return {
            "status": self.status.value,
            "certified": self.certified,
            "bound": finite_or_none(self.bound),
            "mu_upper": finite_or_none(self.mu_upper),
            "mu_upper_grid": finite_or_none(self.mu_upper_grid),
            "mu_lower": finite_or_none(self.mu_lower),
            "stable_at_delta0": None if self.stable_at_delta0 is None else self.stable_at_delta0.verdict,
            "between_grid_points": None if between is None else strict_json(between.summary()),
            "reasons": list(self.reasons),
            "scope": self.scope.summary(),
            "verdict": self.verdict,
            "figure": self.figure,
        }

    def with_scope(self, scope: Scope) -> Certificate:
        """The same decision with the caller's scope (the frequency clause kept)."""
        return replace(self, scope=replace(scope, frequencies=self.scope.frequencies))


def decide_mu(
    stability, mu_upper_grid: float, mu_lower: float, between, *, model_gap: str = "", lower_bound_disproves=True
) -> tuple[Status, tuple[str, ...]]:
    """The μ decision: status and reasons from the loop's stability, the grid peaks and the check between points.

    ``model_gap``: why the model does not cover the robot (empty: it does);
    then μ < 1 certifies the model, not the robot.  ``lower_bound_disproves``
    False: the structure is a sufficient test only, so a lower bound ``>= 1``
    disproves nothing (NOT_CERTIFIED, not VIOLATED).

    >>> from types import SimpleNamespace as NS
    >>> stable = NS(stable=True, unstable=False, verdict="stable")
    >>> decide_mu(stable, 0.8, 0.79, NS(holds=True, level=0.81, peak_upper=0.8, failed_at=None, reason=""))[0].value
    'CERTIFIED'
    >>> decide_mu(stable, 0.8, 0.79, NS(holds=False, level=float("nan"), peak_upper=0.8, failed_at=None, reason="gave up"))
    (<Status.GRID_ONLY: 'GRID_ONLY'>, ('not proved between the grid points: gave up',))
    """
    if stability is not None and stability.unstable:
        return Status.VIOLATED, ("the loop at Delta = 0 (a member of the set) is proved unstable",)
    reasons = []
    if stability is None or not stability.stable:
        reasons.append(
            f"the loop at Delta = 0 is not proved stable ({'not checked' if stability is None else stability.verdict})"
        )
    if np.isfinite(mu_lower) and mu_lower >= 1.0 and not reasons:
        if not lower_bound_disproves:
            return Status.NOT_CERTIFIED, (
                f"this test cannot prove it: mu lower bound {mu_lower:.4g} >= 1 of the scaled structure "
                "(a sufficient test; no robot of the set is shown to violate it)",
            )
        return Status.VIOLATED, (
            f"mu lower bound {mu_lower:.4g} >= 1: a member of the uncertainty model's set breaks it "
            "(the model holds the robot's set, maybe more)",
        )
    if not mu_upper_grid < 1.0:
        reasons.append(f"mu in [{mu_lower:.4g}, {mu_upper_grid:.4g}] on the grid: not below 1")
        return Status.NOT_CERTIFIED, tuple(reasons)
    if reasons:
        return Status.NOT_CERTIFIED, tuple(reasons)
    if between is not None and between.holds and between.level < 1.0:
        return (Status.NOT_CERTIFIED, (model_gap,)) if model_gap else (Status.CERTIFIED, ())
    if between is not None and (between.failed_at is not None or between.peak_upper >= 1.0 or between.level >= 1.0):
        reached = max(float(between.peak_upper), float(between.level) if between.holds else 0.0)
        return Status.NOT_CERTIFIED, (
            f"mu < 1 on the grid ({mu_upper_grid:.4g}) but its upper bound reaches {reached:.4g} between the points",
        )
    why = "not checked" if between is None else between.reason
    return Status.GRID_ONLY, (f"not proved between the grid points: {why}",)


def decide_gain(stable: bool, gamma: float, checked: bool, why: str = "") -> tuple[Status, tuple[str, ...]]:
    """The decision for a verified L2-gain (or stability-only) bound: CERTIFIED when a re-checked ``gamma < 1``.

    >>> decide_gain(True, 0.5, True)[0].value, decide_gain(True, 0.5, False, "not re-checked")[0].value
    ('CERTIFIED', 'NOT_CERTIFIED')
    """
    if stable and checked and gamma < 1.0:
        return Status.CERTIFIED, ()
    return Status.NOT_CERTIFIED, (
        why or (f"verified bound {gamma:.4g} is not below 1" if checked else "no verified bound"),
    )


def decide_gridded_gain(proved: bool, gamma: float, between: bool, why: str = "") -> tuple[Status, tuple[str, ...]]:
    """:func:`decide_gain` for a bound proved on a parameter grid: GRID_ONLY unless it holds between the points too.

    >>> decide_gridded_gain(True, 0.5, False)[0].value, decide_gridded_gain(True, 0.5, True)[0].value
    ('GRID_ONLY', 'CERTIFIED')
    """
    status, reasons = decide_gain(proved, gamma, proved, why)
    if status is Status.CERTIFIED and not between:
        return Status.GRID_ONLY, ("proved at the parameter grid's points only, not between them",)
    return status, reasons


def gain_certificate(scope: Scope, *, stable: bool, checked: bool, gamma=None, why: str = "", notes=()) -> Certificate:
    """The certificate of a verified L2 gain (``gamma``) or, with ``gamma=None``, of stability alone.

    ``checked``: the test ran and its solution was re-checked; ``notes`` are
    added to the reasons when it does not certify.

    >>> gain_certificate(Scope(kind="robust stability"), stable=True, checked=True).status.value
    'CERTIFIED'
    """
    status, reasons = decide_gain(stable, 0.0 if gamma is None else float(gamma), checked, why)
    reasons = reasons + tuple(n for n in notes if n not in reasons) if reasons else ()
    bound = float("nan") if gamma is None else float(gamma)
    return Certificate(status, bound, float("nan"), float("nan"), None, scope, reasons)


def gridded_gain_certificate(scope: Scope, *, gamma: float, proved: bool, between: bool, why: str = "") -> Certificate:
    """The certificate of an L2 gain proved on a parameter grid; ``between``: proved between its points too.

    >>> gridded_gain_certificate(Scope(), gamma=0.5, proved=True, between=False).status.value
    'GRID_ONLY'
    """
    status, reasons = decide_gridded_gain(proved, gamma, between, why)
    return Certificate(status, float(gamma), float("nan"), float("nan"), None, scope, reasons)


def nominal_performance_verdict(hinf_norm: float) -> str:
    """``"met"`` when the nominal loop's ``||N_zw||inf < 1`` (a computed norm, no certificate), else ``"not met"``.

    >>> nominal_performance_verdict(0.4), nominal_performance_verdict(float("nan"))
    ('met', 'not met')
    """
    return "met" if hinf_norm < 1.0 else "not met"


def friction_sentence(channel) -> str:
    """The words of a :class:`~polyrob.synthesis.integral.CoulombChannel`: what Coulomb friction does to the error.

    A statement beside the certificate, not a status: the steady state is
    proved for every member the certificate keeps stable only with integral
    action; otherwise, and for the peak, the figures are the nominal loop's.
    """
    levels = sorted(set(channel.levels))
    fc = f"{levels[0]:g} N m" if len(levels) == 1 else f"{levels[0]:g}-{levels[-1]:g} N m"
    head = f"friction: Coulomb |d| <= {fc} per joint ({channel.source}), not in the model, as a torque disturbance: "
    if not channel.stable:
        return head + "no figure (the nominal loop is not stable)"
    if channel.integral:
        steady = (
            "integral action on every joint, so a constant friction torque leaves no steady-state error on every "
            "robot whose loop is stable (every member of the set, when the loop is CERTIFIED)"
        )
    else:
        worst = max(channel.steady_state)
        steady = (
            f"no integral action: a constant friction torque leaves up to {worst:.3g} rad of steady-state error "
            f"({max(channel.steady_state_per_nm):.3g} rad per N m; nominal model, exact DC gain)"
        )
    peak = (
        f"; at any frequency the error stays within {channel.peak:.3g} rad ({channel.peak_per_nm:.3g} rad per N m; "
        "H-inf of the nominal loop, proved from above)"
    )
    rate = getattr(channel, "slowest_rate", float("nan"))
    decay = (
        f"; the nominal loop's slowest pole decays at {rate:.3g} 1/s (time constant {1.0 / rate:.3g} s): "
        "an error friction leaves fades no faster"
        if np.isfinite(rate) and rate > 0
        else ""
    )
    approx = f" ({channel.approximation})" if channel.approximation else ""
    return head + steady + peak + decay + approx


def certify_loop(
    P,
    K,
    blk=None,
    omega=None,
    *,
    kind: str = "performance",
    scope: Scope | None = None,
    n_u: int | None = None,
    n_y: int | None = None,
    sweep_unstable: bool = True,
    lower_bound_disproves: bool = True,
    **mu_options,
) -> Certificate:
    """Close the loop, decide its stability at ``Δ = 0``, sweep μ, check between the grid points, decide.

    Parameters
    ----------
    P : GeneralizedPlant or control.StateSpace
        A bare state space needs ``blk``, ``n_u`` and ``n_y`` (controls and
        measurements are its last inputs and outputs).
    K : controller (``n_u x n_y``)
    blk : block structure, optional
        Default: ``P.block_structure_rp`` (``kind="performance"``) or
        ``P.block_structure_rs`` (``"stability"``).
    omega : array_like, optional
        Frequencies; default the loop's own grid
        (:func:`polyrob.analysis.loop_sweep.sweep_loop`), so that every caller
        certifies one controller on the same grid.  ω = 0 is added for real
        blocks (real μ is discontinuous there).
    n_u, n_y : int, optional
        Controls and measurements of a bare state-space ``P`` (its last
        inputs and outputs); not with a GeneralizedPlant.
    kind : {"performance", "stability"}
        Stability takes μ of ``d -> v`` only.
    scope : Scope, optional
        What the inputs cover (model, coverage, domain, enclosure); the
        frequency clause is set here.
    sweep_unstable : bool
        Sweep μ also when the loop is proved unstable (for the report's
        figures); the status is VIOLATED either way.
    lower_bound_disproves : bool
        False when ``blk`` is only a sufficient test (a scaled structure
        whose μ ``>= 1`` shows no member of the set breaking the property).
    **mu_options
        Passed to :func:`polyrob.analysis.mu.bounds.mu_bounds`.

    Returns
    -------
    Certificate
    """
    from polyrob.analysis.loop_sweep import sweep_loop
    from polyrob.analysis.stability import stability_verdict
    from polyrob.plant.loops import lft
    from polyrob.progress import span

    N = lft(P, K, n_u=n_u, n_y=n_y)
    M = N
    if kind == "stability" and n_u is None:
        M = N[P.output_slices["v"], P.input_slices["d"]]
    if blk is None:
        blk = P.block_structure_rs if kind == "stability" else P.block_structure_rp
    base = replace(scope or Scope(), kind="robust performance" if kind == "performance" else "robust stability")
    stability = stability_verdict(N)
    if stability.unstable and not sweep_unstable:
        status, reasons = decide_mu(stability, np.inf, np.nan, None)
        return Certificate(status, np.inf, np.inf, np.nan, stability, base, reasons, None, N)
    with span(0.0, SWEEP_SHARE):  # the grid's points, then the intervals between them (the job's line)
        mu, response_bits = sweep_loop(M, blk, omega, **mu_options)
    with span(SWEEP_SHARE, 1.0):
        cert = certificate_of_sweep(
            N,
            mu,
            M=M,
            stability=stability,
            scope=base,
            response_bits=response_bits,
            lower_bound_disproves=lower_bound_disproves,
        )
    return replace(cert, default_grid=omega is None)


def union_certificate(parts, scope: Scope, what: str = "cells") -> Certificate:
    """One decision over a set covered by the union of ``parts`` (one certificate each, of its own part).

    Every robot of the set lies in some part, so the union is CERTIFIED when
    every part is, with the largest of their bounds; VIOLATED when a part is
    (a member of that part's model, as for one model); else the worst of the
    others, with the parts that fail counted in its reason.  The returned
    certificate carries the μ sweep of the part with the largest bound.

    >>> ok = Certificate(Status.CERTIFIED, 0.9, 0.89, 0.88, None, Scope(), bound_everywhere=True)
    >>> both = union_certificate([ok, replace(ok, bound=0.95)], Scope())
    >>> both.status.value, both.mu_upper
    ('CERTIFIED', 0.95)
    >>> no = Certificate(Status.NOT_CERTIFIED, 1.1, 1.1, 0.98, None, Scope(), ("mu in [0.98, 1.1] on the grid",))
    >>> union_certificate([ok, no], Scope()).reasons[0]
    '1 of 2 cells not certified; the worst: mu in [0.98, 1.1] on the grid'
    """
    parts = list(parts)
    if not parts:
        raise ArgumentError("union_certificate: no part to decide")
    order = (Status.VIOLATED, Status.NOT_CERTIFIED, Status.GRID_ONLY, Status.CERTIFIED)
    status = min((c.status for c in parts), key=order.index)
    same = [c for c in parts if c.status is status]
    worst = max(same, key=lambda c: (c.bound if np.isfinite(c.bound) else np.inf, c.mu_lower))
    everywhere = status is Status.CERTIFIED and all(c.bound_everywhere for c in parts)
    reasons = ()
    if status is not Status.CERTIFIED:
        failing = sum(not c.certified for c in parts)
        head = f"{failing} of {len(parts)} {what} not certified; the worst: "
        reasons = ((head + (worst.reasons[0] if worst.reasons else str(status))),) + tuple(worst.reasons[1:])
    return Certificate(
        status=status,
        bound=max(float(c.bound) for c in parts) if status is Status.CERTIFIED else float(worst.bound),
        mu_upper_grid=max(float(c.mu_upper_grid) for c in parts),
        mu_lower=max(float(c.mu_lower) for c in parts),
        stable_at_delta0=worst.stable_at_delta0,
        scope=replace(scope, kind=worst.scope.kind, frequencies=worst.scope.frequencies),
        reasons=reasons,
        mu=worst.mu,
        closed_loop=worst.closed_loop,
        bound_everywhere=everywhere,
        lower_bound_disproves=worst.lower_bound_disproves,
    )


def rescoped(cert: Certificate, scope: Scope) -> Certificate:
    """``cert`` decided again with the caller's scope (e.g. the model's coverage), without a new sweep."""
    if cert.mu is None:
        return cert.with_scope(scope)
    kind = "robust performance" if "performance" in cert.scope.kind else "robust stability"
    new = certificate_of_sweep(
        cert.closed_loop,
        cert.mu,
        stability=cert.stable_at_delta0,
        scope=replace(scope, kind=kind),
        lower_bound_disproves=cert.lower_bound_disproves,
    )
    return replace(new, default_grid=cert.default_grid)


def certificate_of_sweep(
    N, mu, *, M=None, stability=None, scope: Scope | None = None, response_bits=None, lower_bound_disproves=True
) -> Certificate:
    """Decide a sweep already made (a synthesis' own certificate grid): stability, the check between points, status.

    ``N`` is the closed loop, ``M`` the system the sweep ``mu`` is of (default
    ``N``).  ``mu.between`` is computed when missing.
    """
    from polyrob.analysis.mu.between import with_between
    from polyrob.analysis.stability import stability_verdict

    M = N if M is None else M
    stability = stability_verdict(N) if stability is None else stability
    if getattr(mu, "between", None) is None:
        mu = with_between(M, mu, response_bits=response_bits)
    between = mu.between
    scope = scope or Scope()
    gap = ""
    if scope.coverage is not None and scope.coverage < 1.0:
        # mu < 1 on a model that misses some of the robot's Jacobians certifies the model, not the robot
        gap = f"the '{scope.model}' model contains only {scope.coverage:.4g} of {scope.coverage_points} fresh Jacobians"
    status, reasons = decide_mu(
        stability,
        float(mu.peak_upper),
        float(mu.peak_lower),
        between,
        model_gap=gap,
        lower_bound_disproves=lower_bound_disproves,
    )
    everywhere = status is Status.CERTIFIED or (between is not None and between.holds and between.level < 1.0)
    frequencies = "every frequency" if everywhere else grid_words(mu.omega)
    bound = float(between.level) if everywhere else float(mu.peak_upper)
    return Certificate(
        status=status,
        bound=bound,
        mu_upper_grid=float(mu.peak_upper),
        mu_lower=float(mu.peak_lower),
        stable_at_delta0=stability,
        scope=replace(scope, frequencies=frequencies),
        reasons=reasons,
        mu=mu,
        closed_loop=N,
        bound_everywhere=everywhere,
        lower_bound_disproves=lower_bound_disproves,
    )
