"""One robot of a batch: what to do (:class:`Job`, :class:`Settings`), doing it (:func:`run_job`), what came out.

:func:`run_job` is the unit of work a batch sends to a worker process or a
Dask worker: a module-level function of two small frozen, picklable objects,
returning a picklable :class:`RobotResult` (the controller travels back as
plain arrays, :func:`controller_data`, since python-control systems hold
lambdas; files are written by the caller, which may be on another machine
than the worker).  It never raises for a robot's own
failure: the error class and its one-line message are recorded instead, so
one robot cannot stop the others.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from pathlib import PurePath

from polyrob.errors import ArgumentError
from polyrob.fleet.diagnosis import why_not_certified
from polyrob.fleet.results import RobotResult, controller_data, controller_system  # noqa: F401 (re-exported)
from polyrob.fleet.stages import (
    design_stage,
    moving_stage,
    moving_tuning_stage,
    one_line,
    rate_validation_stage,
    reduce_stage,
    validate_stage,
)

__all__ = ["Job", "Settings", "RobotResult", "run_job", "as_job"]


@dataclass(frozen=True)
class Job:
    """A robot and its domain / weight options.

    Attributes
    ----------
    robot : str
        A name :func:`polyrob.load_robot` accepts, or a URDF path.
    domain : str, optional
        A named domain of the robot (e.g. ``"paper"``) or a domain file.
    q_range, qdot_max, u_max : optional
        As :meth:`polyrob.Domain.from_robot` takes them (a number or a pair
        applies to every joint; a mapping names joints).
    qdot_scale, u_scale : float
    weights : dict, optional
        Weight hyperparameter overrides (``key -> sequence`` of 1 or ``m``).
    auto_weights : bool
        Weights from :func:`polyrob.fleet.automatic_hyperparameters` (joint
        count and domain); ``False``: the paper's (as ``polyrob run``).
    bandwidth_scale : float
        Multiplies both bandwidths after the weights are chosen.
    uncertainty : str
        Uncertainty model (``"auto"``, ``"box"``, ...).
    lock : tuple of str, optional
        Joints to lock (default: the loader's).
    label : str, optional
        Name of the result (default the robot's); must be unique in a batch.
    pose, q_radius, qddot_max : optional
        A task domain (:meth:`polyrob.domains.task.TaskDomain.from_robot`;
        ``qdot_max`` then bounds its velocities).  Without any domain field an
        arm of 3+ joints gets its default task
        (:mod:`polyrob.domains.default_task`), the other robots the URDF torque box.
    inner : str, optional
        Inner layer (``"none"``, ``"gravity"``, ``"computed-torque"``).
    model_error : float, optional
        Fraction (not percent): the true link masses/inertias are the model's times ``1 -+ model_error``.
    payload_mass, payload_com : str, optional
        Payload range as the ``--payload-mass`` / ``--payload-com`` options take it.
    torque_box : bool
        The URDF torque box without an inner layer even for an arm (no default task).
    robot_uncertainty : dict or "default", optional
        A robot-uncertainty set (the file's mapping,
        :meth:`~polyrob.uncertainty_set.spec.RobotUncertainty.to_dict`, or ``"default"``:
        :func:`~polyrob.uncertainty_set.default_set.default_set` of the job's robot), carried on a
        computed-torque inner layer by the ``inner-links`` model; it replaces the task's model error and payload.
    """

    robot: str
    domain: str | None = None
    q_range: object = None
    qdot_max: object = None
    u_max: object = None
    qdot_scale: float = 1.0
    u_scale: float = 1.0
    weights: dict | None = None
    auto_weights: bool = True
    bandwidth_scale: float = 1.0
    uncertainty: str = "auto"
    lock: tuple | None = None
    label: str | None = None
    pose: object = None
    q_radius: float | None = None
    qddot_max: object = None
    inner: str | None = None
    model_error: float | None = None
    payload_mass: str | None = None
    payload_com: str | None = None
    torque_box: bool = False
    robot_uncertainty: dict | str | None = None

    @property
    def name(self) -> str:
        """The label, else the robot name (a URDF path's file stem)."""
        if self.label:
            return self.label
        text = str(self.robot)
        return PurePath(text).stem if text.lower().endswith(".urdf") else text

    def to_dict(self) -> dict:
        return {k: v for k, v in self.__dict__.items() if v is not None}


def as_job(item) -> Job:
    """A :class:`Job` from a job, a robot name, or a mapping of :class:`Job` fields."""
    if isinstance(item, Job):
        return item
    if isinstance(item, str):
        return Job(robot=item)
    if isinstance(item, dict):
        unknown = sorted(set(item) - set(Job.__dataclass_fields__))
        if unknown or "robot" not in item:
            raise ArgumentError(
                f"a job needs 'robot' and takes only {sorted(Job.__dataclass_fields__)}; got {sorted(item)}"
            )
        item = dict(item)
        if item.get("lock") is not None:
            item["lock"] = tuple(item["lock"])
        return Job(**item)
    raise ArgumentError(f"a job is a robot name, a mapping or a Job, not {type(item).__name__}")


#: Dynamics evaluations a batch's validation simulation may make (a count of work; a stiff loop stops there).
#: About two minutes of an idle 2-core x86_64, far above what a settled move of 20 s needs.
VALIDATE_EVALUATIONS = 5_000_000


@dataclass(frozen=True)
class Settings:
    """What every job of a batch shares (bounding, synthesis, analysis options).

    Attributes
    ----------
    bound_options : dict
        Passed to :func:`polyrob.bound_pldi` (``workers`` defaults to 1 here:
        the batch already runs robots side by side).
    synthesis : dict
        Passed to :func:`polyrob.pipeline.synthesis_options` (``structure``,
        ``max_iter``, ...).
    omega : (lo, hi, n), optional
        Frequency grid of the synthesis and the analysis (default: automatic).
    search_bandwidth : bool
        Find the largest bandwidth factor with certified μ < 1
        (:func:`polyrob.pipeline.design_max_bandwidth`) instead of one synthesis.
    alphas : tuple of float, optional
        The factors the search scans (default its own).
    search_time_limit : float or None
        A safety net the user sets: seconds of one robot's bandwidth search
        after which no new factor starts (its best certified factor so far
        stands, and the row names the limit); ``None`` (default): no limit.
        The search is bounded by its work already (the factors of its scan
        and a bisection to ``search_rtol``), so a robot's factor does not
        depend on the machine's load.
    search_rtol : float
        The search's bisection stops when the first factor that failed is
        within this fraction above the last certified one (0.25: a batch
        wants each robot's factor to within a quarter, not to 5 % as
        ``synth --max-bandwidth`` does; each step is a tuned, certified PID).
    analyze : bool
        μ analysis of the controller (robust stability/performance, sampling).
    mc : int
        Monte Carlo parameter sets of the analysis.
    validate : bool
        Nonlinear closed-loop simulation of a small move
        (:func:`polyrob.validate.simulate.simulate`).
    validate_step : float
        The move, as a fraction of each joint's half position range.
    validate_move : float
        Seconds of the minimum-jerk move to the target (``0``: a step).  A
        step through a controller with a large feedthrough ``D_K`` asks for
        a torque spike of ``D_K`` times the step at ``t = 0+`` (1e5 N m on
        planar_2r's factor-32 controller), which no robot's reference does.
    validate_time : float
        Simulated seconds.
    validate_budget : float or None
        A safety net the user sets: wall-clock seconds the simulation may
        take, named in the row when it fires (``None``, default: no limit).
    validate_evaluations : int or None
        Evaluations of the dynamics the simulation may make; a stiff closed
        loop that has not finished by then is reported as such (a count of
        work, so the row is the same on an idle and on a loaded machine).
    true_robots : int
        True robots drawn from the set for the validation at the rate
        (:func:`polyrob.validate.at_rate.runs.validate_at_rate`; 0, the library's default: skipped;
        ``polyrob batch`` asks for 20, ``--true-robots N``).
    at_rate : dict
        Its conditions, the fields of :class:`~polyrob.validate.at_rate.loop.RealLoopConditions`
        (empty: the defaults, 1 kHz, one sample of delay, 18-bit encoders, viscous 1 and Coulomb 2 N m).
    moving : bool
        Also the moving-robot certificate of each controller (the masses
        constant, the state at any rate:
        :func:`polyrob.analysis.lpv.constant.robot_in_motion_certificate`;
        minutes per arm), in the row's ``moving``; once computed it decides
        the row's ``certified`` with μ, and with the bandwidth search on an
        ``inner-gain`` model a factor counts only when its controller has it
        too (as ``synth --max-bandwidth --moving``).
    tune_moving : int
        Rounds of tuning each controller's PID on the moving-robot structure
        before its certificates (as ``synth --tune-moving N``:
        :func:`polyrob.pipeline.design.tuned_for_moving`; minutes a round on
        an arm); 0: none.  Implies ``moving``.
    reduce_max_order : int or None
        A certified full-order controller is reduced to the smallest order up
        to this one that keeps μ < 1 (:func:`polyrob.pipeline.reduce_design`);
        ``None``: kept as synthesised.
    """

    bound_options: dict = field(default_factory=dict)
    synthesis: dict = field(default_factory=dict)
    omega: tuple | None = None
    search_bandwidth: bool = False
    alphas: tuple | None = None
    search_time_limit: float | None = None
    search_rtol: float = 0.25
    analyze: bool = True
    mc: int = 200
    validate: bool = True
    validate_step: float = 0.02
    validate_move: float = 2.0
    validate_time: float = 20.0
    validate_budget: float | None = None
    validate_evaluations: int | None = VALIDATE_EVALUATIONS
    true_robots: int = 0
    at_rate: dict = field(default_factory=dict)
    reduce_max_order: int | None = 20
    moving: bool = False
    tune_moving: int = 0

    def to_dict(self) -> dict:
        return dict(self.__dict__)


_BOX_FIELDS = ("domain", "q_range", "u_max")
_TASK_FIELDS = ("pose", "q_radius", "qddot_max")


def job_robot_and_domain(job: Job):
    """The robot (its inner loop when the job has one) and the domain of ``job``; the default task when it applies.

    Returns ``(robot, domain, default_task)``: ``default_task`` is the
    :class:`~polyrob.domains.default_task.DefaultTask` used, or ``None``.
    """
    import polyrob
    from polyrob.domains.default_task import DEFAULT_TASK, applies_to
    from polyrob.domains.task import TaskDomain
    from polyrob.domains.torque_box import Domain

    robot = polyrob.load_robot(job.robot, lock=None if job.lock is None else list(job.lock))
    # a payload alone rides on the default task (an instrument on the arm's usual problem), and so does an inner
    # layer alone (the same task with that layer; none: the paper's single layer)
    posed = _BOX_FIELDS + _TASK_FIELDS + ("model_error", "qdot_max")
    given = any(getattr(job, k) is not None for k in posed) or job.qdot_scale != 1.0 or job.u_scale != 1.0
    task = None
    payload = None
    if job.payload_mass is not None:
        from polyrob.model.payload import PayloadRange

        payload = PayloadRange.parse(str(job.payload_mass), job.payload_com)
    if not (given or job.torque_box) and applies_to(robot.m):
        task = DEFAULT_TASK.with_inner(job.inner)
        fields = {"q_radius": task.q_radius, "qdot_max": task.qdot_max, "qddot_max": task.qddot_max}
        inner, error = task.inner, task.model_error
        payload = payload or task.payload_range(robot)
    else:
        fields = {k: getattr(job, k) for k in _TASK_FIELDS}
        inner, error = job.inner or "none", job.model_error or 0.0
    if job.robot_uncertainty is not None:  # the stated set replaces the task's model error and payload
        from polyrob.model.inner import inner_loop_of_set
        from polyrob.uncertainty_set.spec import RobotUncertainty

        if job.model_error is not None or job.payload_mass is not None:
            raise ArgumentError(
                f"job {job.name}: the robot-uncertainty set holds the link errors and the payload: drop "
                + " and ".join(k for k in ("model_error", "payload_mass") if getattr(job, k) is not None)
            )
        if inner != "computed-torque":
            why = (
                f"{robot.name} has {robot.m} joints and no default task (an arm of 3+ joints has one, with that layer)"
                if task is None and not (given or job.torque_box) and job.inner is None
                else f"this job's inner layer is {inner!r}"
            )
            raise ArgumentError(
                f"job {job.name}: a robot-uncertainty set is carried on a computed-torque inner layer only, and {why}: "
                "give inner: computed-torque with a task (pose, q_radius, qddot_max), or drop robot_uncertainty"
            )
        from polyrob.uncertainty_set.default_set import DEFAULT_SET, default_set

        if job.robot_uncertainty == DEFAULT_SET:
            spec = default_set(robot)
        elif isinstance(job.robot_uncertainty, dict):
            spec = RobotUncertainty.from_dict(job.robot_uncertainty)
        else:
            raise ArgumentError(
                f"job {job.name}: robot_uncertainty is a set's mapping (a robot-uncertainty file's) or "
                f"'{DEFAULT_SET}', not {job.robot_uncertainty!r}"
            )
        robot = inner_loop_of_set(robot, inner, spec)
    elif inner != "none" or error or payload is not None:
        from polyrob.model.inner import inner_loop

        robot = inner_loop(robot, inner, payload=payload, model_error=float(error))
    if task is not None or any(getattr(job, k) is not None for k in _TASK_FIELDS):
        if any(getattr(job, k) is not None for k in _BOX_FIELDS):
            raise ArgumentError(
                f"job {job.name}: domain/q_range/u_max set a torque box, not with pose/q_radius/qddot_max"
            )
        if task is None:
            fields["qdot_max"] = job.qdot_max
        return robot, TaskDomain.from_robot(robot, **fields), task
    domain = Domain.from_robot(
        robot,
        job.domain,
        q_range=job.q_range,
        qdot_max=job.qdot_max,
        u_max=job.u_max,
        qdot_scale=job.qdot_scale,
        u_scale=job.u_scale,
    )
    return robot, domain, None


def _problem(job: Job, settings: Settings, timings: dict):
    from polyrob.fleet.autoweights import automatic_hyperparameters
    from polyrob.pipeline import build_problem, default_hyperparameters

    robot, domain, task = job_robot_and_domain(job)
    if job.auto_weights:
        # on a task the automatic weights carry the effort limit and the encoder noise (docs/synthesis.md)
        # the noise weight's encoder is the one the validation quantises with (--encoder-bits)
        bits = settings.at_rate.get("encoder_bits") if settings.at_rate else None
        h = automatic_hyperparameters(
            robot.m, domain, job.weights, robot=robot if task is not None else None, encoder_bits=bits
        )
    else:
        h = default_hyperparameters(robot.m, job.weights)
    if job.bandwidth_scale != 1.0:
        h = default_hyperparameters(robot.m, h, bandwidth_scale=job.bandwidth_scale)
    t0 = time.perf_counter()
    options = {"workers": 1, **(task.bound_options if task is not None else {}), **settings.bound_options}
    problem = build_problem(
        robot, domain, hyperparameters=h, uncertainty=job.uncertainty, progress=False, bound_options=options
    )
    timings["bounds"] = time.perf_counter() - t0
    return problem


def run_job(job: Job, settings: Settings) -> RobotResult:
    """Bounds, weights, synthesis (or bandwidth search), analysis and validation of one robot.

    Never raises for the robot's own failure (an exception of any class
    becomes ``ok=False`` with its class and message); KeyboardInterrupt and
    SystemExit pass.  BLAS is limited to one thread while it runs.
    """
    from polyrob._threads import single_blas_thread

    t0 = time.perf_counter()
    timings: dict = {}
    known: dict = {}  # what the problem says, once it is built: a row that fails later keeps it
    with single_blas_thread():
        try:
            return _run(job, settings, timings, t0, known)
        except Exception as exc:  # noqa: BLE001 - one robot's failure is data (recorded), not the batch's end
            return RobotResult(
                name=job.name,
                ok=False,
                error=type(exc).__name__,
                message=one_line(exc),
                seconds=time.perf_counter() - t0,
                timings=timings,
                **{"robot": str(job.robot), **known},
            )


def _finite(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def _problem_fields(problem) -> dict:
    """The row's fields that the problem alone decides (its robot, domain, model and set)."""
    robot = problem.robot
    return {
        "robot": robot.name,
        "joints": int(robot.m),
        "entries": len(problem.pldi.entries),
        "parameters": int(problem.unc.n_params),
        "model": problem.model,
        "enclosure": problem.scope().enclosure,  # what the certificate rests on: proved factor ranges under --certify
        "domain": problem.domain.name,
        "inner": robot.words() if hasattr(robot, "inner") else "none",
        "inner_layer": getattr(robot, "inner", "none"),
        "uncertainty": robot.set_words() if hasattr(robot, "set_words") else None,
        "reflected_inertia": str(getattr(robot, "reflected_inertia", "unknown")),
    }


def _run(job: Job, settings: Settings, timings: dict, t0: float, known: dict) -> RobotResult:
    from polyrob.pipeline import analyze_controller
    from polyrob.synthesis.bandwidth_stop import loop_crossover

    problem = _problem(job, settings, timings)
    known.update(_problem_fields(problem))
    details = {}
    design, alpha, hyper, omega, skipped = design_stage(problem, settings, timings, details)
    if alpha is not None:
        from polyrob.pipeline.design import scaled_problem

        problem = scaled_problem(problem, hyper)  # where the design was certified: the same PLDI and model
    design = reduce_stage(problem, design, settings, timings, details)
    scalings, held = None, problem
    if settings.tune_moving:  # before the certificate is read and the loop simulated: they are the tuned PID's
        design, scalings, held = moving_tuning_stage(problem, design, settings, timings, details)
    description = problem.description()
    description["job"] = job.to_dict()
    cert = design.certificate
    details["synthesis"] = design.summary()
    if skipped:
        details["bandwidth_search"] = "bandwidth search skipped: " + skipped
    if settings.analyze and skipped:
        # the model cannot certify (its inputs reverse): the sweeps would only restate the synthesis'
        # certificate, at the cost of several minutes on a 6-7 joint arm
        details["analysis"] = "skipped: " + skipped
    elif settings.analyze:
        t1 = time.perf_counter()
        # the design's certificate decided again instead of a second sweep of the same loop, and robust
        # stability read from a certified robust performance (a bound, and said so): one sweep, not three
        a = analyze_controller(
            problem,
            design.controller,
            omega=omega,
            mc=settings.mc,
            progress=False,
            time_varying=False,
            moving=False,  # minutes per arm (docs/certificates.md): `polyrob analyze ... --moving` computes it
            stability="implied",
            certificate=design.certificate,
        )
        timings["analysis"] = time.perf_counter() - t1
        details["analysis"] = a.summary()
        cert = a.certificate  # the same call as the design's certificate, with the analysis' grid option
    validation = None
    if settings.validate:
        t1 = time.perf_counter()
        try:
            sim = validate_stage(problem, design.controller, settings)
            details["validation"] = sim
            settled = "settled" if sim["settled"] else "NOT settled"
            validation = f"{settled}; {sim['verdict']}"
            if sim.get("true_robot"):
                validation += f"; true robot: {sim['true_robot']}"
        except Exception as exc:  # noqa: BLE001 - recorded: a failed simulation is a finding about this robot
            validation = f"simulation failed: {type(exc).__name__}: {one_line(exc)}"
        timings["validation"] = time.perf_counter() - t1
    at_rate = None
    if settings.validate and settings.true_robots:
        t1 = time.perf_counter()
        try:
            details["at_rate"] = rate_validation_stage(problem, design.controller, settings)
            at_rate = {k: details["at_rate"][k] for k in ("by_reference", "meets_bar", "verdict")}
        except Exception as exc:  # noqa: BLE001 - recorded: a failed simulation is a finding about this robot
            at_rate = {"verdict": f"validation at the rate failed: {type(exc).__name__}: {one_line(exc)}"}
        timings["validation at the rate"] = time.perf_counter() - t1
    moving = None
    if settings.moving or settings.tune_moving:
        t1 = time.perf_counter()
        try:
            # on the model of constants the tuning built (a per-link set's is built once), from its scalings
            details["moving"] = moving_stage(held, design.controller, scalings)
        except Exception as exc:  # noqa: BLE001 - recorded: the row keeps its frozen certificate and says why
            details["moving"] = {
                "computed": False, "certified": False, "status": None, "gamma": None,
                "verdict": f"moving robot: not computed: {type(exc).__name__}: {one_line(exc)}",
            }  # fmt: skip
        moving = {k: details["moving"].get(k) for k in ("computed", "certified", "status", "gamma", "verdict")}
        timings["moving robot"] = time.perf_counter() - t1
    from polyrob.pipeline import friction_statement

    friction = friction_statement(problem, design.controller)  # the set's Coulomb levels, as synth and run state them
    if friction is not None:
        details["friction"] = friction
    reason = None if cert.certified else why_not_certified(problem, details, cert)
    if reason and skipped:
        reason = f"{reason} (bandwidth search skipped)"
    K = controller_data(design.controller)
    return RobotResult(
        name=job.name,
        ok=True,
        **_problem_fields(problem),  # the scaled problem's, where the design was certified
        mu_upper=float(cert.mu_upper) if math.isfinite(cert.mu_upper) else None,
        mu_upper_grid=float(cert.mu_upper_grid),
        mu_lower=float(cert.mu_lower),
        status=cert.status.value,
        order=int(design.record.get("order", design.result.order)),
        structure=design.record.get("structure", getattr(design.result, "structure", None)),
        alpha=alpha,
        bandwidth=_finite(loop_crossover(problem.P, design.controller)),  # inf: still above 1 at 1e6 rad/s
        verdict="verdict: " + cert.verdict,
        validation=validation,
        validation_at_rate=at_rate,
        moving=moving,
        reason=reason,
        seconds=time.perf_counter() - t0,
        timings=timings,
        controller=K,
        certificate=dict(design.record, certificate=cert.summary()),
        problem=description,
        details=details,
    )


def with_label(job: Job, label: str) -> Job:
    """``job`` named ``label``."""
    return replace(job, label=label)
