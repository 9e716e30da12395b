"""A controller for a problem: μ-synthesis (full order or fixed structure), optional reduction.

``polyrob synth`` and ``polyrob run`` call :func:`design_controller`;
``synth --max-bandwidth`` calls :func:`design_max_bandwidth`.  Both return
the controller with the certificate a controller file stores.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from polyrob.errors import ArgumentError

__all__ = [
    "Design",
    "certify_design",
    "scaled_problem",
    "design_controller",
    "design_max_bandwidth",
    "reduce_design",
    "synthesis_options",
    "starts_from_tuned_pid",
    "true_robot_start",
    "TRUE_ROBOTS",
    "TRUE_ROBOTS_AND_CORNERS",
    "TRUE_ROBOT_STARTS",
]


def synthesis_options(
    *,
    structure: str = "full",
    complex_blocks: bool = False,
    max_iter: int | None = None,
    starts: int | None = None,
    init: str | None = None,
    progress: bool | None = None,
    time_limit: float | None = None,
    target: float | None = None,
) -> dict:
    """``musyn`` keyword arguments from the plain synthesis choices.

    ``init`` is ``"paper"`` (a fixed structure starts from the paper's K*),
    ``"pid"`` (the per-joint PID tuned to the weights, any structure) or
    the path of a controller file (``K.json``, ``K.mat``) that starts the
    synthesis, full order or fixed structure.  ``time_limit`` (seconds): no
    new iteration or start after it (``musyn``'s ``time_limit``).  ``target``:
    the iteration stops once its grid peak μ is below it (``musyn``'s ``target``,
    MATLAB's ``TargetPerf``).
    """
    if max_iter is not None and max_iter < 1:
        raise ArgumentError(f"max_iter must be >= 1, got {max_iter}")
    if starts is not None and starts < 1:
        raise ArgumentError(f"starts must be >= 1, got {starts}")
    if time_limit is not None and not time_limit > 0:
        raise ArgumentError(f"time_limit must be > 0 seconds, got {time_limit}")
    options = {"structure": structure, "progress": progress}
    if target is not None and not target > 0:
        raise ArgumentError(f"target must be > 0, got {target}")
    if time_limit is not None:
        options["time_limit"] = float(time_limit)
    if target is not None:
        options["target"] = float(target)
    if max_iter is not None:
        options["max_iter"] = int(max_iter)
    if structure == "full":
        options["mixed"] = not complex_blocks
    elif starts is not None:
        options["starts"] = int(starts)
    if init == "paper":
        if structure == "full":
            raise ArgumentError("--init paper starts a fixed structure (e.g. --structure tf3) from K*")
        options["init"] = "paper"
    elif init == "pid":  # the per-joint PID tuned to the weights (polyrob.synthesis.pid_tuning)
        options["initial_controller"] = "pid"
    elif init in TRUE_ROBOT_STARTS:  # tuned on true robots of the set (resolved by design_controller)
        options["initial_controller"] = init
    elif init:
        # a controller file: a warm start (continuation from a nearby problem, MATLAB's musyn(P, K0))
        from polyrob.io.controller import controller_from_mapping, read_controller_file

        options["initial_controller"] = controller_from_mapping(read_controller_file(init), init)
    return options


#: ``initial_controller`` of :func:`synthesis_options`'s ``init="true-robots"``.
TRUE_ROBOTS = "true-robots"
#: The same tuned on the uncertainty model's corners too (:func:`~polyrob.synthesis.true_robots.tune_on_true_robots`'s ``model``).
TRUE_ROBOTS_AND_CORNERS = "true-robots+corners"
#: The starts tuned on true robots.
TRUE_ROBOT_STARTS = (TRUE_ROBOTS, TRUE_ROBOTS_AND_CORNERS)
#: Why the bandwidth search refuses that start (``synth`` says it before any bounds).
TRUE_ROBOTS_NOT_IN_SEARCH = (
    "--init true-robots tunes one PID on true robots at the given weights; the bandwidth search does not "
    "take it yet: leave out --max-bandwidth (set --bandwidth-scale) or use --init pid"
)


#: The share of the synthesis stage the tuning on true robots takes when it is the answer (``max_iter=1``:
#: the certificate's sweep takes the rest); a quarter of that before a D-K iteration.
TRUE_ROBOTS_SHARE = 0.7


def true_robot_start(problem, options: dict) -> tuple[dict, object]:
    """``options`` with the start ``init="true-robots"`` resolved, and the synthesis when the start is the answer.

    The per-joint PID tuned to the weights on the model
    (:func:`polyrob.synthesis.pid_tuning.tuned_pid`), then tuned on the frozen
    loops of true robots drawn from the set
    (:func:`polyrob.synthesis.true_robots.tune_on_true_robots`) in the
    structure asked for (a per-joint PID for ``"full"``; ``"ss:N"``, ``"tfN"``
    from that PID).  With ``max_iter=1`` it is the answer and its certificate
    is computed on the model like any other controller's; otherwise the
    result is ``None`` and D-K (or the fixed structure's μ optimisation) goes
    on from it.
    """
    import logging
    import time

    from polyrob.analysis.certificate import certify_loop
    from polyrob.progress import span
    from polyrob.synthesis.pid_tuning import tuned_pid
    from polyrob.synthesis.result import MusynResult
    from polyrob.synthesis.true_robots import tune_on_true_robots

    t0 = time.perf_counter()
    # the true robots' tuning fits a per-joint structure to the start: no decoupling to fit
    start = tuned_pid(problem.P, decouple=False)
    structure = "pid" if options.get("structure", "full") == "full" else options["structure"]
    # the PID first, then the structure from it: started from the model's PID, ss:12 on ur5 stalled at 1.94 on its
    # draws with 6 of 500 others unstable; from the PID tuned on true robots it reached 0.926 on the others
    # (docs/uncertainty.md)
    # the tunings' rounds move the job's line (minutes on a six-joint arm); the certificate's sweep comes after
    share = TRUE_ROBOTS_SHARE if options.get("max_iter") == 1 else TRUE_ROBOTS_SHARE / 4
    half = share if structure == "pid" else share / 2
    model = problem.unc if options["initial_controller"] == TRUE_ROBOTS_AND_CORNERS else None
    with span(0.0, half):
        tuning = tune_on_true_robots(
            problem.robot, problem.domain, problem.hyperparameters, start.controller, model=model
        )
    words = f"{start.words()}, then {tuning.words()}"
    if structure != "pid":
        with span(half, share):
            tuning = tune_on_true_robots(
                problem.robot,
                problem.domain,
                problem.hyperparameters,
                tuning.controller,
                structure=structure,
                model=model,
            )
        words += f", then {tuning.words()}"
    logging.getLogger("polyrob").info(f"musyn: start from a {words}")
    options = {**options, "initial_controller": tuning.controller}
    if options.get("max_iter") != 1:
        return options, None
    cert = certify_loop(problem.P, tuning.controller, None, options.get("certify_omega"), sweep_unstable=False)
    result = MusynResult.certified(
        tuning.controller,
        structure,
        cert,
        mu_history=[cert.mu_upper_grid],
        seconds=time.perf_counter() - t0,
        info={
            "method": f"{structure} tuned on true robots drawn from the set"
            + (" and the model's corners" if model is not None else "")
            + " from the tuned PID (no D-K step)",
            "start": words,
            "stopped_by": "max_iter=1: the start only",
            "true_robots": {
                **tuning.check.to_dict(),
                "fitted_draws": tuning.draws,
                "fitted_worst": tuning.fitted_worst,
            },
        },
    )
    return options, result


def _record(result, P) -> dict:
    import numpy as np

    cert = result.summary()
    cert["block_structure"] = np.asarray(P.block_structure_rp).tolist()
    return cert


@dataclass(frozen=True, eq=False)
class Design:
    """A designed controller with its certificate.

    Attributes
    ----------
    controller : LTI
        The controller to use (the reduced one when reduction was asked).
    result : MusynResult
        The synthesis.
    reduced : ReductionResult or None
    record : dict
        What the controller file stores (peak μ bounds, structure, order,
        and the certificate's summary).
    certificate : Certificate or None
        The certificate of :attr:`controller` on the problem, on the loop's
        own grid (:func:`polyrob.analysis.certificate.certify_loop`, the
        same call as ``polyrob analyze``); ``None`` when the caller certifies
        it itself (``run``'s analysis).
    notes : tuple of str
    """

    controller: object
    result: object
    reduced: object
    record: dict
    certificate: object = None
    notes: tuple = ()

    @property
    def peak_mu(self) -> float:
        return float(self.record["peak_mu_upper"])

    @property
    def peak_mu_lower(self) -> float:
        return float(self.record["peak_mu_lower"])

    def certified_by(self, certificate) -> Design:
        """The design with ``certificate`` (of :attr:`controller` on the problem) as its verdict."""
        record = dict(self.record, certificate=certificate.summary(), status=certificate.status.value)
        return replace(self, certificate=certificate, record=record)

    def summary(self) -> dict:
        out = dict(self.record)
        out["gamma_history"] = [float(g) for g in self.result.gamma_history]
        if self.reduced is not None:
            out["reduction"] = self.reduced.summary()
        out["notes"] = list(self.notes)
        return out


def certify_design(problem, design: Design) -> Design:
    """The design with the certificate of its controller on ``problem`` (the analysis' own call).

    A synthesis certificate made by that same call (the loop's own grid, the
    same closed loop and block structure) is decided again with the
    problem's scope instead of sweeping twice.
    """
    from polyrob.analysis.certificate import certify_loop
    from polyrob.pipeline.analysis import reusable_certificate

    P, K = problem.P, design.controller
    own = getattr(design.result, "certificate", None) if design.reduced is None else None
    cert = reusable_certificate(own, P, K, problem.scope())
    return design.certified_by(cert if cert is not None else certify_loop(P, K, scope=problem.scope()))


def tuned_for_moving(problem, design: Design, *, rounds: int = 3, structure: str = "pid", held=None) -> Design:
    """``design`` with its controller tuned on the moving-robot structure (:mod:`polyrob.synthesis.moving`), certified anew.

    The tuning's scalings and history go to ``record["moving_tuning"]`` (the
    moving-robot certificate starts from those scalings); the frozen
    certificate is the new controller's own, on ``problem``.  A tuning whose
    merged μ stayed at or above 1 and whose controller lost the design's
    frozen certificate is not kept (``record["moving_tuning"]["kept"]`` is
    False, its frozen μ beside it): on ur5 with ±10 % per link three rounds
    left the merged μ at 1.967 and took the frozen μ from 0.931 to 1.465.  ``held``: the
    problem on its model of constants
    (:func:`~polyrob.analysis.lpv.constant.moving_problem`) when the caller
    has it already (a per-link set's is built and its coverage measured:
    minutes on an arm).
    """
    from polyrob.analysis.certificate import certify_loop
    from polyrob.synthesis.moving import tune_for_moving

    tuning = tune_for_moving(held or problem, design.controller, structure=structure, rounds=rounds)
    cert = certify_loop(problem.P, tuning.controller, scope=problem.scope())
    history = ", ".join(f"{h:.4g}" for h in tuning.history)
    lost = bool(getattr(design.certificate, "certified", False)) and not cert.certified
    if lost and min(tuning.history, default=math.inf) >= 1.0:
        # neither robot certified by the tuned controller, the frozen one by the design's: the design stays
        summary = {**tuning.summary(), "kept": False, "frozen_mu": float(cert.bound)}
        why = (f"tuned for the moving robot ({structure}): merged-structure mu {history}, not below 1, and the tuned "
               f"controller's frozen mu {cert.bound:.4g} lost the design's certificate: the design kept")  # fmt: skip
        return replace(design, record={**design.record, "moving_tuning": summary}, notes=design.notes + (why,))
    record = {
        **design.record,
        "moving_tuning": {**tuning.summary(), "kept": True},
        "peak_mu_upper": float(cert.mu_upper_grid),
        "peak_mu_lower": float(cert.mu_lower),
    }
    notes = design.notes + (f"tuned for the moving robot ({structure}): merged-structure mu {history}",)
    moved = Design(controller=tuning.controller, result=design.result, reduced=None, record=record, notes=notes)
    return moved.certified_by(cert)


def starts_from_tuned_pid(robot) -> bool:
    """Whether ``robot``'s synthesis starts from the per-joint PID tuned to the weights (:func:`with_default_start`)."""
    return getattr(robot, "inner", None) == "computed-torque"


def with_default_start(problem, options: dict) -> dict:
    """``options`` with the synthesis start of ``problem`` when none is given.

    A computed-torque inner loop (an arm's default task) starts from the
    per-joint PID tuned to the weights (``initial_controller="pid"``,
    :mod:`polyrob.synthesis.pid_tuning`): its outer plant is a double
    integrator per joint, and D-K from the unscaled H∞ controller stalls
    there (docs/fleet.md).  With it comes ``target=1`` unless a target is
    given: a PID whose certificate is already below 1 is the answer (order
    ``2 m``, what an arm engineer deploys) and no D-K step runs; otherwise
    D-K goes on from it.  Every other problem keeps its default start.
    """
    if not starts_from_tuned_pid(problem.robot):
        return options
    if options.get("init") is not None or options.get("initial_controller") is not None:
        return options
    return {"target": 1.0, **options, "initial_controller": "pid"}


def design_controller(
    problem, *, reduce: bool = False, reduce_max_order: int = 20, certify: bool = True, **options
) -> Design:
    """μ-synthesis on ``problem.P`` (``options`` as from :func:`synthesis_options`), then reduction.

    Parameters
    ----------
    problem : Problem
    reduce : bool
        Balanced reduction of a full-order controller (ignored for fixed structures).
    reduce_max_order : int
        Largest order accepted by the reduction (>= 1).
    certify : bool
        Certify the final controller (:func:`certify_design`); ``run`` leaves it
        to its analysis, which makes the same call.
    **options
        Passed to :func:`polyrob.synthesis.mu_synthesis.musyn`.
    """
    from polyrob.synthesis import musyn

    if reduce and reduce_max_order < 1:
        raise ArgumentError(f"reduce_max_order must be >= 1, got {reduce_max_order}")
    options = with_default_start(problem, options)
    result = None
    if options.get("initial_controller") in TRUE_ROBOT_STARTS:
        options, result = true_robot_start(problem, options)
    if result is None:
        result = musyn(problem.P, **options)
    notes = tuple(result.info.get("notes", [])) if isinstance(result.info, dict) else ()
    design = Design(
        controller=result.controller, result=result, reduced=None, record=_record(result, problem.P), notes=notes
    )
    if reduce and result.structure == "full":  # a certified PID start is returned as it is
        design = reduce_design(problem, design, reduce_max_order, certify=False)
    return certify_design(problem, design) if certify else design


def reduce_design(
    problem, design: Design, max_order: int = 20, *, target: float | None = None, certify: bool = True
) -> Design:
    """The design with its full-order controller reduced (balanced truncation, certified per order).

    ``target``: the largest certified μ accepted (default the full order's
    × 1.05, :func:`polyrob.synthesis.reduce_controller`).
    """
    from polyrob.synthesis import reduce_controller

    result = design.result
    reduced = reduce_controller(problem.P, result, max_order=max_order, target=target)
    # the reduced controller's own figures; the full order's only under full_* names
    cert = _record(reduced.result, problem.P)
    cert.update(full_order=int(result.order), full_peak_mu_upper=float(result.peak_mu))
    if "bandwidth_scaling" in design.record:  # how the weights were found stays with the controller
        cert["bandwidth_scaling"] = design.record["bandwidth_scaling"]
    design = Design(controller=reduced.controller, result=result, reduced=reduced, record=cert, notes=design.notes)
    return certify_design(problem, design) if certify else design


#: Scan of the bandwidth factor for the moving robot's search: quarter octaves from 1/8 to 32.
MOVING_ALPHAS = tuple(2.0 ** (k / 4) for k in range(-12, 21))


def design_max_bandwidth(
    problem,
    *,
    scale=("omega_b", "omega_bt"),
    alphas=None,
    limit=True,
    moving=False,
    rate=None,
    delay_samples=1.0,
    **options,
):
    """The largest bandwidth factor with certified μ < 1; returns ``(Design, BandwidthScalingResult)``.

    With ``limit`` (default) a factor at which the robot's performance limit
    already proves μ >= 1 for every controller is not synthesised.  With
    ``moving`` a factor counts only when its controller also has the
    moving-robot certificate of an inner-gain problem
    (:func:`polyrob.analysis.lpv.constant.constant_parameter_certificate`:
    the masses constant, the state at any rate), so the result is the
    largest factor at which the robot in motion is certified.

    With the limit weights (``effort``, ``noise``: an arm's default task) the
    controller will run sampled: ``rate`` [Hz] (default 1 kHz there, none
    on the paper's problem) and ``delay_samples`` cap the crossover
    (:func:`polyrob.synthesis.bandwidth.crossover_cap`), and the result's
    ``bound_hit`` names the bound where the search stops.
    """
    from polyrob.plant.generalized import paper_controller
    from polyrob.synthesis import max_bandwidth_scaling

    options = with_default_start(problem, dict(options))
    if options.get("initial_controller") in TRUE_ROBOT_STARTS:
        raise ArgumentError(TRUE_ROBOTS_NOT_IN_SEARCH)
    per_factor = "musyn"
    if options.get("initial_controller") == "pid" and options.get("max_iter") is None:
        # the PID tuned and certified at each factor, no D-K step: D-K at every factor of the scan
        # costs minutes on a 6-7 joint arm (docs/fleet.md); --max-iter N asks for D-K steps again
        options["max_iter"] = 1
        per_factor = (
            "the per-joint PID tuned to each factor's weights and certified (no D-K step; --max-iter adds them)"
        )
    if options.get("init") == "paper":
        options.pop("init")  # K* starts the first synthesis only; later ones start from the nearest alpha's
        options["initial_controller"] = paper_controller()
    if alphas is not None:
        alphas = [float(a) for a in alphas]
        if not alphas or any(not (a > 0 and a < float("inf")) for a in alphas):
            raise ArgumentError(f"bandwidth factors must be finite and > 0, got {alphas}")
        options["alphas"] = alphas
    if limit:
        # a factor whose performance limit is >= 1 cannot certify: skip its synthesis
        options["floor"] = lambda alpha, h: problem.performance_limit(h).bound
    if moving:
        options["judge"] = moving_judge(problem)
        # the moving robot's test passes in a window of factors (so101: 16 and 32 fail, 22.6 passes,
        # docs/certificates.md): a quarter-octave scan from the top finds it where octaves step over it
        options.setdefault("alphas", MOVING_ALPHAS)
    if "effort" in problem.hyperparameters:
        from polyrob.synthesis.bandwidth import DEFAULT_RATE

        options["rate"] = DEFAULT_RATE[0] if rate is None else rate
        options["delay_samples"] = delay_samples
        options["channel_names"] = limit_channel_names(problem)
    elif rate is not None:
        options["rate"], options["delay_samples"] = rate, delay_samples
    res = max_bandwidth_scaling(problem.unc, problem.hyperparameters, scale=tuple(scale), **options)
    cert = res.result.summary()
    cert.update(bandwidth_scaling={**res.summary(), "per_factor": per_factor})
    notes = tuple(res.result.info.get("notes", [])) if isinstance(res.result.info, dict) else ()
    design = Design(controller=res.result.controller, result=res.result, reduced=None, record=cert, notes=notes)
    return certify_design(scaled_problem(problem, res.hyperparameters), design), res


def limit_channel_names(problem) -> dict:
    """Words for the weighted channels, the limit weight's naming what sets its level on this robot."""
    from polyrob.errors import PolyrobError
    from polyrob.synthesis.bandwidth import CHANNEL_NAMES

    names = dict(CHANNEL_NAMES)
    try:
        from polyrob.fleet.autoweights import limit_hyperparameters
        from polyrob.plant.weights import encoder_noise_level

        noise = float(problem.hyperparameters["noise"][0])
        bits = next((b for b in range(1, 65) if math.isclose(encoder_noise_level(b), noise)), None)
        budget = limit_hyperparameters(problem.robot, problem.domain, encoder_bits=bits)
    except (PolyrobError, AttributeError, KeyError, TypeError, ValueError):
        return names  # a given --effort-weight or a robot without effort limits: the channel's own words
    if tuple(budget.effort) != tuple(problem.hyperparameters["effort"]):
        names["W_KS u"] = "effort weight as given (W_u K S W_n)"
    elif "effort limit" in budget.binds:
        joints = [j for j, b in enumerate(budget.binds) if b == "effort limit"]
        names["W_KS u"] = f"effort limit (the task's torque leaves less than the noise budget on joints {joints})"
    else:
        names["W_KS u"] = (
            f"encoder noise ({budget.encoder_bits}-bit: its torque reaches 5 % of the effort limit peak to peak)"
        )
    return names


def moving_judge(problem):
    """``(P, result) -> Certificate``: the moving-robot certificate of the result's controller on ``P``."""
    from polyrob.analysis.lpv.constant import applies, constant_parameter_certificate

    why = applies(problem)
    if why:
        raise ArgumentError(f"a bandwidth search on the moving-robot certificate needs an inner-gain model: {why}")

    def judge(P, result):
        if not result.certificate.certified:  # the moving robot's test implies the frozen one's
            return result.certificate
        return constant_parameter_certificate(replace(problem, P=P), result.controller).certificate

    return judge


def scaled_problem(problem, hyperparameters: dict):
    """``problem`` with other weight hyperparameters (same PLDI and model): where a bandwidth factor's controller is certified."""
    from polyrob.plant.generalized import generalized_plant
    from polyrob.plant.weights import plant_weights

    h = {k: tuple(v) for k, v in hyperparameters.items()}
    return replace(problem, P=generalized_plant(problem.unc, **plant_weights(h)), hyperparameters=h)
