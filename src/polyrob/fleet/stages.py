"""The synthesis, reduction and validation stages of one robot's job (:func:`polyrob.fleet.jobs.run_job`).

Each takes the job's :class:`~polyrob.fleet.jobs.Settings` and records its
time in ``timings`` (and what it skipped in ``details``).
"""

from __future__ import annotations

import time

from polyrob.errors import SynthesisError
from polyrob.fleet.diagnosis import search_skipped

__all__ = [
    "design_stage",
    "moving_stage",
    "moving_tuning_stage",
    "reduce_stage",
    "validate_stage",
    "rate_validation_stage",
    "one_line",
]


def validate_stage(problem, K, settings) -> dict:
    """A small move on the robot's own nonlinear dynamics, from the PLDI's nominal position."""
    import numpy as np

    from polyrob.validate.simulate import simulate, smooth_reference, step_reference

    dom = problem.domain
    lo, hi = np.asarray(dom.q_lower, float), np.asarray(dom.q_upper, float)
    start = np.clip(np.asarray(problem.pldi.nominal_point["q"], float), lo, hi)  # simulate's own q0
    step = settings.validate_step * 0.5 * (hi - lo)
    # step towards the farther end of each joint's range, so the target stays in the domain
    target = np.where(hi - start >= start - lo, start + step, start - step)
    move = smooth_reference(target, settings.validate_move) if settings.validate_move > 0 else step_reference(target)
    # from a settled hold (the robot at rest at the start, its integral action settled): behind an
    # inner layer the model error alone would otherwise accelerate the true robot at t = 0
    sim = simulate(
        problem.robot,
        K,
        problem.pldi,
        move,
        t_final=settings.validate_time,
        time_budget=settings.validate_budget,
        max_evaluations=settings.validate_evaluations,
        u_eq="hold",
    )
    out = sim.summary()
    out.pop("joints", None)
    return out


def rate_validation_stage(problem, K, settings) -> dict:
    """The controller at the rate on ``settings.true_robots`` robots drawn from the set (its summary, without the runs)."""
    from polyrob.validate.at_rate.loop import RealLoopConditions
    from polyrob.validate.at_rate.runs import validate_at_rate

    conditions = RealLoopConditions(**settings.at_rate)
    res = validate_at_rate(problem.robot, K, problem.pldi, conditions=conditions, true_robots=settings.true_robots)
    out = res.summary()
    out.pop("runs", None)
    return out


def moving_stage(problem, K, scalings=None) -> dict:
    """The moving-robot certificate of ``K`` (the masses constant, the state at any rate), its summary.

    ``scalings``: the moving blocks' ``d`` to start from (a tuning's own, :func:`moving_tuning_stage`).
    """
    from polyrob.analysis.lpv.constant import robot_in_motion_certificate

    return robot_in_motion_certificate(problem, K, scalings=scalings).summary()


def moving_tuning_stage(problem, design, settings, timings: dict, details: dict):
    """``settings.tune_moving`` rounds of tuning the design's PID on the moving-robot structure (as ``synth --tune-moving``).

    Returns ``(design, scalings, held)``: the tuned design (its frozen
    certificate made anew), the moving blocks' ``d`` and the problem on its
    model of constants, which the moving-robot stage then checks.  A problem
    with no model of constants, or a tuning that fails, keeps the design as
    it was and says why in ``details["moving_tuning"]``.
    """
    from polyrob.analysis.lpv.constant import moving_problem
    from polyrob.errors import PolyrobError
    from polyrob.pipeline.design import tuned_for_moving

    t0 = time.perf_counter()
    try:
        held = moving_problem(problem)
        if held is None:
            raise SynthesisError(f"no model of constants for the {problem.model!r} model")
        tuned = tuned_for_moving(problem, design, rounds=settings.tune_moving, held=held)
    except PolyrobError as exc:  # recorded: the row keeps the untuned design and says why
        details["moving_tuning"] = f"not tuned: {type(exc).__name__}: {one_line(exc)}"
        return design, None, problem
    finally:
        timings["moving-robot tuning"] = time.perf_counter() - t0
    tuning = details["moving_tuning"] = tuned.record["moving_tuning"]
    return tuned, tuning["scalings"] if tuning.get("kept", True) else None, held


def design_stage(problem, settings, timings: dict, details: dict):
    """One synthesis, or the bandwidth search when asked and the model can certify.

    Returns ``(design, alpha, hyperparameters, omega, skipped)``: ``alpha`` is
    the factor found (``None`` without a search), ``skipped`` why the search
    was skipped (``None`` when it ran or was not asked for).
    """
    import numpy as np

    from polyrob.pipeline import design_controller, design_max_bandwidth, synthesis_options

    options = synthesis_options(progress=False, **settings.synthesis)
    if settings.omega is not None:
        lo, hi, n = settings.omega
        options["omega"] = np.logspace(np.log10(lo), np.log10(hi), int(n))
    t0 = time.perf_counter()
    skipped = search_skipped(problem, details) if settings.search_bandwidth else None
    if settings.search_bandwidth and skipped is None:
        from polyrob.analysis.lpv.constant import applies

        design, res = design_max_bandwidth(
            problem,
            moving=bool(settings.moving) and applies(problem) is None,  # as synth --max-bandwidth --moving
            alphas=settings.alphas,
            search_time_limit=settings.search_time_limit,
            rtol=settings.search_rtol,
            **options,
        )
        if res.stopped_by:
            details["bandwidth_search"] = f"stopped by {res.stopped_by}"
        alpha, hyper = float(res.alpha), res.hyperparameters
    else:
        design = design_controller(problem, **options)
        alpha, hyper = None, problem.hyperparameters
    timings["synthesis"] = time.perf_counter() - t0
    return design, alpha, hyper, options.get("omega"), skipped


def reduce_stage(problem, design, settings, timings: dict, details: dict):
    """A certified full-order controller, reduced while its certificate stays certified (else the design as it is)."""
    from polyrob.pipeline import reduce_design

    full = design.reduced is None and str(design.record.get("structure", "full")) == "full"
    if not (settings.reduce_max_order and full and design.certificate.certified):
        return design
    t0 = time.perf_counter()
    target = min(0.999, 1.05 * design.certificate.bound)
    try:
        reduced = reduce_design(problem, design, settings.reduce_max_order, target=target)
    except SynthesisError as exc:  # e.g. more unstable controller poles than the order allowed
        reduced, why = None, one_line(exc)
    else:
        why = f"no order up to {settings.reduce_max_order} keeps mu < 1"
    timings["reduction"] = time.perf_counter() - t0
    if reduced is not None and reduced.reduced.meets_target and reduced.certificate.certified:
        return reduced
    details["reduction"] = f"kept order {design.result.order}: {why}"
    return design


def one_line(exc: BaseException) -> str:
    """An exception's message on one line (its class name if empty)."""
    return " ".join(str(exc).split()) or type(exc).__name__
