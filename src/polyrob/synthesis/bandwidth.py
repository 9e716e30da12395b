"""Largest bandwidth of the weights that a robust controller can certify.

When μ < 1 is out of reach under given weights, the question a designer asks
next is how much performance *can* be certified.  :func:`max_bandwidth_scaling`
answers it for the paper's parametrised weights
(:func:`polyrob.plant.weights.sensitivity_weight`,
:func:`~polyrob.plant.weights.complementary_weight`): the bandwidths ``ω_B`` (and by
default ``ω_BT``) are multiplied by a factor α and a controller is
synthesised for each α.

μ(α) is not monotonic in general.  The weights' low- and high-frequency gains
(``1/A_S``, ``1/A_T``) do not depend on α, so a very small α asks
``|W_T T| < 1`` at almost every frequency (no loop bandwidth left to
stabilise an unstable plant) and a very large α asks ``|W_S S| < 1`` up to
high frequency.  The search therefore scans α on a geometric grid first and
then bisects between the largest grid point that certifies ``μ < target``
and the next one, which does not.

Where it stops, :attr:`BandwidthScalingResult.bound_hit` says which bound
binds there: ``"sample rate"`` when the next factor's controller crosses
over above :func:`crossover_cap` (the rate and delay the loop will run
at), else the weighted channel μ rests on at the next factor
(:func:`polyrob.synthesis.channel_mu.channel_mu`: μ on a grid with each
channel left out of the performance block; the channel without which μ
falls below 1 binds): ``"tracking (W_S)"``, ``"uncertainty (W_T)"``, or
the limit weight ``W_KS = W_u W_n`` (``"encoder noise"`` / ``"effort
limit"``, :mod:`polyrob.plant.weights`).  When the next factor has no
controller (its synthesis failed), the certified controller's μ on the
next factor's weights is read.  :func:`binding_bound` is the cheaper
nominal-peak rule (a hint: a channel slack on the nominal loop can be the
one the worst plant breaks).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from polyrob.errors import ArgumentError, SynthesisError
from polyrob.progress import span
from polyrob.synthesis.bandwidth_stop import (
    CHANNEL_NAMES,
    DEFAULT_RATE,
    RATE_PHASE_BUDGET,
    binding_bound,
    bound_hit,
    channel_peaks,
    crossover_cap,
    is_plant,
    loop_crossover,
)
from polyrob.synthesis.result import MusynResult

__all__ = [
    "BandwidthScalingResult",
    "scaled_hyperparameters",
    "max_bandwidth_scaling",
    "certified_on",
    "crossover_cap",
    "loop_crossover",
    "channel_peaks",
    "binding_bound",
    "RATE_PHASE_BUDGET",
    "DEFAULT_RATE",
    "CHANNEL_NAMES",
]

#: Default scan of the bandwidth factor α (geometric, factor 2).
DEFAULT_ALPHAS = tuple(2.0**k for k in range(-3, 6))


log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class BandwidthScalingResult:
    """Largest bandwidth factor α with a certified robust-performance μ < ``target``.

    Attributes
    ----------
    alpha : float
        Largest α found with a certified ``μ < target`` (the named
        hyperparameters of the weights multiplied by α).
    peak_mu : float
        Certified μ of the controller at ``alpha``.
    result : MusynResult
        The synthesis at ``alpha``.
    history : list of (alpha, peak_mu)
        ``peak_mu`` is the certificate's bound when its status is CERTIFIED, else ``inf``.
        Every α tried, in order (``inf`` when the synthesis failed).
    hyperparameters : dict
        The weight hyperparameters at ``alpha``.
    scale : tuple of str
        Which hyperparameters were multiplied by α.
    bracket : (float, float)
        ``alpha`` and the smallest larger α tried that did not reach the
        target (``inf`` if none did not).
    seconds : float
    excluded : list of (alpha, bound)
        Factors not synthesised because ``floor`` proved ``μ >= bound >= target``
        for every controller (see :mod:`polyrob.analysis.limits`).
    stopped_by : str
        Empty, or why the search ended before its bracket was narrowed to ``rtol``.
    bound_hit : str
        Which bound stops the search at ``bracket[1]`` (:func:`binding_bound`).
    crossover : float
        Largest gain crossover [rad/s] of the nominal loop of the controller at ``alpha``.
    crossover_limit : float
        :func:`crossover_cap` of the rate the search was given (``nan``: none).
    """

    alpha: float
    peak_mu: float
    result: MusynResult
    history: list
    hyperparameters: dict
    scale: tuple = ("omega_b", "omega_bt")
    bracket: tuple = (math.nan, math.nan)
    seconds: float = 0.0
    excluded: list = ()
    stopped_by: str = ""
    bound_hit: str = ""
    crossover: float = math.nan
    crossover_limit: float = math.nan

    def summary(self) -> dict:
        """JSON-ready figures (the controller itself is in ``result``)."""
        return {
            "alpha": self.alpha,
            "peak_mu": self.peak_mu,
            "scale": list(self.scale),
            "bracket": list(self.bracket),
            "order": int(self.result.order),
            "hyperparameters": {k: list(v) for k, v in self.hyperparameters.items()},
            "history": [list(h) for h in self.history],
            "seconds": round(self.seconds, 2),
            "excluded_by_performance_limit": [list(e) for e in self.excluded],
            "stopped_by": self.stopped_by or None,
            "bound_hit": self.bound_hit or None,
            "crossover_rad_s": None if math.isnan(self.crossover) else self.crossover,
            "crossover_limit_rad_s": None if math.isnan(self.crossover_limit) else self.crossover_limit,
        }


def scaled_hyperparameters(
    alpha: float, hyperparameters: dict | None = None, scale: Sequence[str] = ("omega_b", "omega_bt")
) -> dict:
    """Weight hyperparameters with the entries named in ``scale`` multiplied by ``alpha``.

    Examples
    --------
    >>> from polyrob.synthesis.bandwidth import scaled_hyperparameters
    >>> scaled_hyperparameters(0.5)["omega_b"]
    (0.25, 0.05)
    >>> scaled_hyperparameters(0.5, scale=("omega_b",))["omega_bt"]
    (10.0, 12.0)
    """
    from polyrob.plant.weights import PAPER_HYPERPARAMETERS

    h = dict(PAPER_HYPERPARAMETERS if hyperparameters is None else hyperparameters)
    for key in scale:
        if key not in h:
            raise ArgumentError(f"unknown weight hyperparameter {key!r}; known: {sorted(h)}")
        h[key] = tuple(float(alpha * x) for x in h[key])
    return h


def certified_on(P, result) -> MusynResult:
    """``result``'s controller with its certificate on ``P`` (:func:`~polyrob.analysis.certificate.certify_loop`)."""
    import control

    from polyrob.analysis.certificate import certify_loop

    t0 = time.perf_counter()
    K = result.controller
    K = control.ss(K) if isinstance(K, control.TransferFunction) else K  # a state space, as a synthesis gives it
    cert = certify_loop(P, K, sweep_unstable=False)
    info = {"method": "carried over from a nearby factor", "stopped_by": "no synthesis: the controller as it was"}
    return MusynResult.certified(K, result.structure, cert, seconds=time.perf_counter() - t0, info=info)


def _default_synthesis(initial_controller=None, **musyn_options) -> Callable:
    """:func:`musyn` warm-started from the nearest solved α (else ``initial_controller``)."""
    from polyrob.synthesis.mu_synthesis import musyn

    def synthesize(P, K0):
        # a PID start is re-tuned at every factor (its crossover follows the weights)
        if initial_controller == "pid" and musyn_options.get("max_iter") == 1:
            from polyrob.synthesis.pid_tuning import pid_start

            # the PID alone at each factor; one whose ranking figure is >= 1 is not certified (screened)
            options = {k: musyn_options[k] for k in ("certify_omega",) if k in musyn_options}
            return pid_start(P, only=True, screen=musyn_options.get("target") or 1.0, **options)[2]
        start = initial_controller if (K0 is None or initial_controller == "pid") else K0
        return musyn(P, initial_controller=start, **musyn_options)

    return synthesize


def max_bandwidth_scaling(
    unc,
    hyperparameters: dict | None = None,
    *,
    alphas: Sequence[float] = DEFAULT_ALPHAS,
    rtol: float = 0.05,
    target: float = 1.0,
    scale: Sequence[str] = ("omega_b", "omega_bt"),
    synthesize: Callable | None = None,
    plant: Callable | None = None,
    floor: Callable | None = None,
    progress: bool | None = None,
    search_time_limit: float | None = None,
    judge: Callable | None = None,
    stop_after_rises: int = 2,
    rate: float | None = None,
    delay_samples: float = DEFAULT_RATE[1],
    channel_names: dict | None = None,
    carry_over: bool | Callable | None = None,
    **musyn_options,
) -> BandwidthScalingResult:
    """The largest factor α on the weights' bandwidths with a certified μ < ``target``.

    Parameters
    ----------
    unc : UncertainPlant
    hyperparameters : dict, optional
        Base hyperparameters (default :data:`polyrob.plant.weights.PAPER_HYPERPARAMETERS`).
    alphas : sequence of float
        Scan grid of α (sorted, positive); default ``2**-3 ... 2**5``.
    rtol : float
        Bisection stops when ``α_fail/α_ok - 1 < rtol``.
    target : float
    scale : sequence of str
        Hyperparameters multiplied by α (default both bandwidths; e.g.
        ``("omega_b",)`` scales the performance bandwidth only).
    synthesize : callable ``(P, initial_controller) -> MusynResult``, optional
        The synthesis run at each α (strategy); default :func:`musyn` with
        ``musyn_options`` (e.g. ``structure="tf3"``, ``initial_controller``
        for the first α).  Each run is warm-started from the controller of
        the nearest α already solved.
    plant : callable ``(alpha, hyperparameters) -> GeneralizedPlant``, optional
        Default: :func:`~polyrob.plant.generalized_plant` of ``unc`` with
        :func:`~polyrob.plant.weights.paper_weights` of the scaled hyperparameters.
    floor : callable ``(alpha, hyperparameters) -> float``, optional
        A lower bound on every controller's μ at α (e.g. the performance limit
        of :meth:`polyrob.pipeline.Problem.performance_limit`); an α whose
        floor is at least ``target`` is not synthesised (it cannot succeed)
        and counts as a failure, listed in ``excluded``.
    progress : bool, optional
        Progress bars of each synthesis (default: only on a terminal); one
        line per α goes to the ``polyrob`` logger whatever this says.
    search_time_limit : float, optional
        A safety net the caller sets (default none: the scan and the bisection
        bound the search's work): seconds of the whole search after which no new factor starts (the
        one running finishes): the largest certified factor so far is the
        result, its ``bracket`` ending at the next factor not tried
        (``stopped_by`` says so); none so far raises :class:`SynthesisError`.
    judge : callable ``(P, result) -> Certificate``, optional
        The certificate a factor is ranked by (default the synthesis
        result's own, robust performance of the frozen robot); e.g. the
        moving-robot certificate of the controller
        (:func:`polyrob.pipeline.design.design_max_bandwidth`).
    stop_after_rises : int
        The scan down stops, none certified yet, once the figures of the
        failed factors (the certificate's bound, or a PID screen's coarse-grid
        μ) grew at this many consecutive steps down: past the minimum of a
        U-shaped μ(α), smaller factors only do worse (a robot whose tuned
        PIDs all fail used to spend the search's whole time limit below it,
        docs/fleet.md).  A heuristic, and the error says it stopped there;
        0 scans the whole grid.
    rate : float, optional
        Sample rate [Hz] the controller will run at: a certified factor
        whose nominal loop crosses over above :func:`crossover_cap` of
        ``rate`` and ``delay_samples`` counts as a failure (``"sample
        rate"``).  ``None`` (default): no rate, the continuous-time problem.
    delay_samples : float
        Computation delay in samples (default one).
    channel_names : dict, optional
        Words for the weighted channels in :attr:`BandwidthScalingResult.bound_hit`
        (default :data:`CHANNEL_NAMES`).
    carry_over : bool or callable ``(P, result) -> MusynResult``, optional
        A factor whose own synthesis does not certify gets the nearest
        certified factor's controller, certified on its plant (its own
        certificate, the same decision): the factor counts when that
        certifies (and stays within the rate's cap).  ``None`` (default): on
        with the default synthesis, off with a given ``synthesize``;
        ``True``: :func:`certify_loop` of the controller; a callable: that.

    Returns
    -------
    BandwidthScalingResult

    Raises
    ------
    SynthesisError
        No α of the scan reaches a certified ``μ < target``; the message
        lists every α tried with its μ (the evidence).

    Examples
    --------
    A stand-in synthesis whose certified μ is U-shaped in α (as on the
    paper's 2R robot):

    >>> from types import SimpleNamespace
    >>> from polyrob.synthesis.bandwidth import max_bandwidth_scaling
    >>> from polyrob.analysis.certificate import Certificate, Scope, decide_gain
    >>> def fake(P, K0):
    ...     mu = P.alpha ** 2 / 8 + 0.5 / P.alpha
    ...     cert = Certificate(decide_gain(True, mu, True)[0], mu, mu, float("nan"), None, Scope())
    ...     return SimpleNamespace(certificate=cert, controller=None)
    >>> r = max_bandwidth_scaling(None, synthesize=fake, plant=lambda a, h: SimpleNamespace(alpha=a), progress=False)
    >>> print(f"alpha = {r.alpha:.3f}, mu = {r.peak_mu:.3f}, first fail {r.bracket[1]:.3f}")
    alpha = 2.484, mu = 0.972, first fail 2.594
    """
    if plant is None:
        from polyrob.plant.generalized import generalized_plant
        from polyrob.plant.weights import plant_weights

        def plant(alpha, h):
            return generalized_plant(unc, **plant_weights(h))

    synthesize_given = synthesize
    synthesize = synthesize or _default_synthesis(progress=progress, **musyn_options)
    grid = np.asarray(sorted(float(a) for a in alphas))
    if grid.size == 0 or not np.all(np.isfinite(grid)) or grid[0] <= 0:
        raise ArgumentError(f"alphas must be positive finite numbers, got {alphas!r}")
    if not (rtol > 0):
        raise ArgumentError(f"rtol must be positive, got {rtol!r}")
    t0 = time.perf_counter()
    history: list = []
    solved: dict = {}
    excluded: list = []
    evidence: list = []

    def run(alpha):
        h = scaled_hyperparameters(alpha, hyperparameters, scale)
        if floor is not None:
            bound = float(floor(alpha, h))
            if bound >= target:  # proved out of reach: no synthesis can certify it
                excluded.append((float(alpha), bound))
                log.info(f"bandwidth alpha = {alpha:.4g}: every controller has mu >= {bound:.4f}")
                return math.inf
        near = min(solved, key=lambda a: abs(math.log(a / alpha)), default=None)
        K0 = solved[near][0].controller if near is not None and solved[near][0] is not None else None
        try:
            P = plant(alpha, h)
            plants[alpha] = P  # kept when the synthesis fails too: the stop's diagnosis reads its weights
            res = synthesize(P, K0)
            # the factor counts only when its certificate's status is CERTIFIED (mu < 1 at every
            # frequency, loop stable), never on a grid peak
            cert = res.certificate if judge is None else judge(P, res)
            mu = float(cert.bound) if cert.certified else math.inf
            status = cert.status
            figure = None if cert.certified else float(cert.bound)
            if cert.certified and cap is not None and is_plant(P):
                wc = loop_crossover(P, res.controller)
                crossovers[alpha] = wc
                if wc > cap:  # certified in continuous time, too fast for the rate it will run at
                    mu, status, figure = math.inf, f"sample rate (crossover {wc:.4g} rad/s > {cap:.4g})", None
            evidence.append(f"{alpha:g}: {status} {float(cert.bound):.3f}")
        except SynthesisError as exc:
            res, mu, status = None, math.inf, f"synthesis failed ({exc})"
            figure = getattr(exc, "figure", None)  # a PID screen's coarse-grid mu, when it has one
            evidence.append(f"{alpha:g}: synthesis failed" + (f" (screen {figure:.3f})" if figure is not None else ""))
        if not math.isfinite(mu) and carry is not None and alpha in plants:
            res, mu, status, figure = carried(alpha, res, mu, status, figure)
        if figure is not None:
            figures.append((float(alpha), float(figure)))
        history.append((float(alpha), mu))
        solved[alpha] = (res, mu, h)
        shown = f", mu <= {mu:.4f} at every frequency" if math.isfinite(mu) else ""
        log.info(f"bandwidth alpha = {alpha:.4g}: {status}{shown} ({time.perf_counter() - t0:.0f} s)")
        return mu

    carry = (certified_on if synthesize_given is None else None) if carry_over is None else carry_over
    carry = certified_on if carry is True else (None if carry is False else carry)

    carry_tried: set = set()

    def carried(alpha, res, mu, status, figure):
        """The nearest certified factor's controller, certified on this factor's plant: a factor's own synthesis
        can miss a controller that exists (a PID re-tuned per factor from a fixed candidate set)."""
        donors = [a for a, (r, m, _) in solved.items() if math.isfinite(m) and r is not None]
        if not donors:
            return res, mu, status, figure
        carry_tried.add(alpha)
        donor = min(donors, key=lambda a: abs(math.log(a / alpha)))
        P = plants[alpha]
        try:
            other = carry(P, solved[donor][0])
            cert = other.certificate if judge is None else judge(P, other)
        except SynthesisError:
            return res, mu, status, figure
        if not cert.certified:
            evidence.append(f"{alpha:g}: alpha = {donor:g}'s controller {cert.status} {float(cert.bound):.3f}")
            return res, mu, status, figure
        if cap is not None and is_plant(P):
            crossovers[alpha] = loop_crossover(P, other.controller)
            if crossovers[alpha] > cap:
                return res, mu, status, figure
        evidence.append(f"{alpha:g}: alpha = {donor:g}'s controller {cert.status} {float(cert.bound):.3f}")
        return other, float(cert.bound), f"{cert.status} with alpha = {donor:.4g}'s controller", None

    def retried(alpha) -> float:
        """A factor tried before any factor certified, tried again with the nearest certified factor's controller."""
        if carry is None or alpha in carry_tried or alpha not in plants:
            return math.inf
        done = len(history)
        with span(done / (done + 1 + bisection_steps), (done + 1) / (done + 1 + bisection_steps)):
            res, mu, status, _ = carried(alpha, None, math.inf, "", None)
        if math.isfinite(mu):
            history.append((float(alpha), mu))
            solved[alpha] = (res, mu, solved[alpha][2])
            log.info(f"bandwidth alpha = {alpha:.4g}: {status}, mu <= {mu:.4f} at every frequency")
        return mu

    cap = None if rate is None else crossover_cap(rate, delay_samples)
    plants: dict = {}
    crossovers: dict = {}
    deadline = None if search_time_limit is None else t0 + float(search_time_limit)
    stopped = ""
    figures: list = []  # (alpha, mu figure) of the factors that failed, in the order tried

    def rising(next_alpha) -> bool:
        """The failed factors' figures grew at each of the last ``stop_after_rises`` steps down the scan."""
        nonlocal stopped
        last = figures[-(stop_after_rises + 1) :]
        if not stop_after_rises or len(last) < stop_after_rises + 1:
            return False
        steps = list(zip(last, last[1:]))
        if not all(a1 < a0 and f1 > f0 for (a0, f0), (a1, f1) in steps):
            return False
        trend = ", ".join(f"{f:.3g} at {a:g}" for a, f in last)
        stopped = (
            f"the scan's stop rule, before alpha = {next_alpha:.4g}: the mu figures grew as the factor fell ({trend})"
        )
        log.info(f"bandwidth search stopped by {stopped}")
        return True

    def out_of_time(next_alpha) -> bool:
        nonlocal stopped
        if deadline is None or time.perf_counter() < deadline:
            return False
        stopped = f"the search's time limit of {search_time_limit:g} s you set, before alpha = {next_alpha:.4g}"
        log.info(f"bandwidth search stopped by {stopped}")
        return True

    # the whole job's progress line: each factor is one step of a plan that shrinks once a factor certifies
    # (the scan's remaining points, or none, then the bisection's steps)
    widest = max((b / a for a, b in zip(grid, grid[1:])), default=2.0)
    bisection_steps = max(1, math.ceil(math.log2(math.log(widest) / math.log1p(rtol))))

    def counted(alpha, remaining: int) -> float:
        done = len(history)
        with span(done / (done + remaining), (done + 1) / (done + remaining)):
            return run(alpha)

    # scan from the largest α down: the first success is the largest on the grid
    ok = fail = None
    for i, alpha in enumerate(grid[::-1]):
        if history and (out_of_time(alpha) or rising(alpha)):
            break
        if counted(alpha, len(grid) - i + bisection_steps) < target:
            ok = alpha
            break
        fail = alpha
    if ok is None:
        tried = list(evidence)
        tried += [f"{a:g}: >= {b:.3f} (performance limit)" for a, b in excluded]
        why = (
            "the performance limit of the robot's unstable poles excludes every factor (no synthesis ran)"
            if excluded and not history
            else f"none certifies before {stopped}"
            if stopped
            else "none certifies"
        )
        raise SynthesisError(
            f"no bandwidth factor alpha in [{grid[0]:g}, {grid[-1]:g}] (scaling {', '.join(scale)}) reaches a "
            f"certified mu < {target:g}: {why}; alpha: mu = {', '.join(tried)}"
        )
    # the factors above tried before any certified (no controller to lend then): again with the nearest one's
    while fail is not None and not out_of_time(fail) and retried(fail) < target:
        ok = fail
        above = grid[grid > ok]
        fail = float(above[0]) if above.size else None
    if fail is not None:
        lo, hi = ok, fail
        while hi / lo - 1 > rtol:
            mid = math.sqrt(lo * hi)
            if out_of_time(mid):
                break
            left = max(1, math.ceil(math.log2(math.log(hi / lo) / math.log1p(rtol))))
            if counted(mid, left) < target:
                lo = mid
            else:
                hi = mid
        ok, fail = lo, hi
    res, mu, h = solved[ok]
    hit = bound_hit(fail, solved, plants, crossovers, cap, ok, channel_names, stopped, excluded)
    wc = crossovers.get(ok)
    if wc is None and is_plant(plants.get(ok)) and res is not None:
        wc = loop_crossover(plants[ok], res.controller)
    return BandwidthScalingResult(
        alpha=float(ok),
        peak_mu=mu,
        result=res,
        history=history,
        hyperparameters=h,
        scale=tuple(scale),
        bracket=(float(ok), math.inf if fail is None else float(fail)),
        seconds=time.perf_counter() - t0,
        excluded=excluded,
        stopped_by=stopped,
        bound_hit=hit,
        crossover=math.nan if wc is None else float(wc),
        crossover_limit=math.nan if cap is None else float(cap),
    )
