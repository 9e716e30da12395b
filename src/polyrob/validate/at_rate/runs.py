"""Validation at the rate: a controller on true robots drawn from the uncertainty set, as the loop runs on the arm.

:func:`validate_at_rate` draws ``N`` true robots (:func:`polyrob.uncertainty_set.draw_true_robots`:
each link's mass, first moment and inertia by its own factor, a payload body
whose centre of mass lies off the flange; by default half of them at
vertices of the set, :data:`~polyrob.uncertainty_set.draw.EXTREME_SHARE`:
every link factor at ``1 ± p``, the payload's mass at an end of its range
and its centre of mass on the ball's surface), puts each behind the problem's
inner layer (which keeps computing with the *nominal* links and the middle
payload: :class:`~polyrob.model.inner.InnerLoopRobot`), and runs two
references on each with :func:`polyrob.validate.at_rate.loop.simulate_real_loop`
(the rate, the delay, the encoders, friction the inner model does not have):

* a **step** of :data:`STEP_FRACTION` of each joint's task range (alternating
  signs; a step asks for unbounded acceleration, so its acceleration figure
  says how hard the controller kicks);
* the **task's trajectory**: a minimum-jerk move of half the way to the
  task's bound on each joint, its duration chosen so that its peak velocity
  and acceleration are half the task's bounds.

Each run starts from a settled hold (the robot at rest at the task's pose,
the controller's offset the input that holds this true robot there, as a
settled integral action leaves it) and is reported with
:class:`~polyrob.validate.at_rate.figures.RunFigures`; the summary aggregates
them per reference.  This is a simulation of drawn robots: it measures, it
certifies nothing (no status of :mod:`polyrob.analysis.certificate` rests on it).

The work is counted: ``4 n_sub`` dynamics evaluations per sample, the same on
an idle and a loaded machine; the whole job's progress is reported per sample
(:func:`polyrob.progress.report`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from polyrob.errors import ArgumentError
from polyrob.uncertainty_set.draw import EXTREME_SHARE, at_vertices, vertex_words
from polyrob.validate.at_rate.figures import run_figures
from polyrob.validate.at_rate.loop import RealLoopConditions, simulate_real_loop
from polyrob.validate.reference import smooth_reference, step_reference

__all__ = [
    "STEP_FRACTION",
    "CHATTER_LIMIT_PERCENT",
    "RateValidation",
    "default_uncertainty",
    "task_references",
    "true_plants",
    "model_with_middle_payload",
    "validate_at_rate",
    "friction_budget",
]

#: The step's size as a fraction of each joint's task range.
STEP_FRACTION = 0.002
#: Torque chatter the issue's bar allows, peak to peak, in percent of the effort limit.
CHATTER_LIMIT_PERCENT = 5.0


def default_uncertainty(robot):
    """The set the validation draws from when none is given: :func:`~polyrob.uncertainty_set.default_set.default_set`.

    Per-link ``±p`` with ``p`` the inner layer's model error (10 % without
    one); for an arm whose rated payload polyrob knows, an instrument of 0 to
    1.5 kg (capped at the rating) with its centre of mass within 0.1 m of the flange.
    """
    from polyrob.uncertainty_set.default_set import DEFAULT_LINK_ERROR, default_set

    p = float(getattr(robot, "model_error", 0.0) or DEFAULT_LINK_ERROR)
    return default_set(_base(robot), link_error=p)


def _base(robot):
    """The URDF robot under an inner layer (the robot itself otherwise)."""
    return robot._base if hasattr(robot, "_base") else robot


def model_with_middle_payload(robot, spec):
    """What the inner layer computes with: the nominal links and the middle of the set's payload.

    ``robot``: a URDF robot or an :class:`~polyrob.model.inner.InnerLoopRobot` (a set without a
    payload keeps its model: the nominal links with the middle of its own payload range).
    """
    from polyrob.model.payload import with_payload

    if spec.payload is None:
        return getattr(robot, "model_robot", robot)
    pl = spec.payload
    mass = 0.5 * (pl.mass_lower + pl.mass_upper)
    com = (
        np.array(pl.com_centre)
        if pl.com_radius is not None
        else 0.5 * (np.array(pl.com_lower) + np.array(pl.com_upper))
    )
    model = with_payload(_base(robot), mass, com)
    model.__dict__["_polyrob_base"] = _base(robot)
    return model


def true_plants(robot, spec, n: int, seed: int = 0, *, extremes: float = 0.0) -> list:
    """``[(plant, words)]``: ``n`` true robots of ``spec`` behind ``robot``'s inner layer (the robot itself when it
    has no Pinocchio model: an analytic robot has no per-link parameters to draw); the last
    ``round(extremes n)`` at vertices of the set (:func:`~polyrob.uncertainty_set.draw.draw_true_robots`)."""
    from polyrob.uncertainty_set.draw import draw_true_robots

    base = _base(robot)
    if getattr(base, "model", None) is None:
        return [(robot, "the model itself (an analytic robot: no links to draw)")]
    drawn = draw_true_robots(base, spec, n, seed=seed, extremes=extremes)
    if not hasattr(robot, "true_robot"):
        return [(t.robot, t.words()) for t in drawn]
    model = model_with_middle_payload(robot, spec)
    return [
        (replace(robot, model_robot=model, true_robot=t.robot, scenario=t.words(), _scenarios=()), t.words())
        for t in drawn
    ]


def task_references(domain, q0, *, settle_time: float = 3.0) -> list:
    """``[(name, Reference, t_final, move_end)]``: the step and the task's trajectory from ``q0`` (see the module)."""
    lo, hi = np.asarray(domain.q_lower, float), np.asarray(domain.q_upper, float)
    q0 = np.asarray(q0, float)
    sign = np.where(np.arange(len(q0)) % 2 == 0, 1.0, -1.0)
    step = np.clip(q0 + STEP_FRACTION * (hi - lo) * sign, lo, hi)
    toward = np.where(hi - q0 >= q0 - lo, 1.0, -1.0)  # the farther bound: the move stays inside
    distance = 0.5 * np.where(toward > 0, hi - q0, q0 - lo)
    target = q0 + toward * distance
    d = float(distance.max(initial=0.0))
    vmax = float(np.min(np.maximum(np.abs(domain.qdot_lower), np.abs(domain.qdot_upper))))
    duration = 1.875 * d / (0.5 * vmax) if vmax > 0 else 1.0  # minimum jerk: peak velocity 1.875 D / T
    if getattr(domain, "qddot_lower", None) is not None:
        amax = float(np.min(np.maximum(np.abs(domain.qddot_lower), np.abs(domain.qddot_upper))))
        duration = max(duration, np.sqrt(5.7735 * d / (0.5 * amax)))  # peak acceleration 5.7735 D / T^2
    duration = max(float(duration), 0.1)
    return [
        ("step", step_reference(step), settle_time, 0.0),
        ("trajectory", smooth_reference(target, duration), duration + settle_time, duration),
    ]


def friction_budget(robot, q0, conditions, domain) -> dict:
    """What the validation's friction asks of each joint, from the model's inertia at the start.

    ``coulomb_acceleration``: the Coulomb level over the joint's own inertia ``c / M_jj`` (rad/s^2), the
    acceleration a friction torque the controller has not yet matched gives (a joint whose friction
    changes by ``c`` faster than the loop follows leaves its acceleration bound by about this much);
    ``rest_damping``: the smoothed Coulomb term's slope at rest, ``c / v_s`` (N m s/rad), against which a
    joint creeps at ``K_torque / (c / v_s)`` per second (``K_torque``: the controller's torque per rad).
    Computed from the model (the inner layer's, else the robot's) at ``q0``; the true robots differ by the set.
    """
    model = getattr(robot, "model_robot", None) or _base(robot)
    M = np.asarray(model.mass_matrix(np.asarray(q0, float)), float)
    inertia = np.diag(M)
    c = float(conditions.friction_coulomb)
    bound = getattr(domain, "qddot_upper", None)
    return {
        "inertia": [float(v) for v in inertia],
        "coulomb": c,
        "coulomb_acceleration": [float(c / v) for v in inertia],
        "qddot_bound": None if bound is None else [float(abs(v)) for v in bound],
        "rest_damping": c / float(conditions.coulomb_velocity),
    }


def _budget_words(budget) -> str:
    acc = np.asarray(budget["coulomb_acceleration"], float)
    j = int(np.argmax(acc))
    bound = budget["qddot_bound"]
    task = f" (the task's bound: {bound[j]:.3g})" if bound else ""
    return (
        f"Coulomb {budget['coulomb']:g} N m is up to {acc[j]:.3g} rad/s^2 on joint {j}'s inertia "
        f"{budget['inertia'][j]:.3g} kg m^2{task}; near rest it acts as a damper of {budget['rest_damping']:.3g} N m s/rad"
    )


def _aggregate(figs) -> dict:
    def worst(key, pick=max):
        vals = [getattr(f, key) for f in figs if getattr(f, key) is not None and np.isfinite(getattr(f, key))]
        return pick(vals) if vals else None

    return {
        "runs": len(figs),
        "settled": sum(f.settled for f in figs),
        "stuck": sum(bool(f.stuck) for f in figs),
        "stuck_joints": sorted({j for f in figs for j in f.stuck}),
        "inside_task": sum(f.inside_task for f in figs),
        "chatter_within_limit": sum(
            f.chatter_percent_max is not None and f.chatter_percent_max <= CHATTER_LIMIT_PERCENT for f in figs
        ),
        "max_tracking_error_worst": worst("max_tracking_error"),
        "final_tracking_error_worst": worst("final_tracking_error"),
        "settling_time_worst": worst("settling_time"),
        "q_excess_worst": worst("q_excess"),
        "qdot_fraction_worst": worst("qdot_fraction"),
        "qddot_fraction_worst": worst("qddot_fraction"),
        "chatter_percent_worst": worst("chatter_percent_max"),
        "chatter_percent_median": (
            float(np.median([f.chatter_percent_max for f in figs if f.chatter_percent_max is not None]))
            if any(f.chatter_percent_max is not None for f in figs)
            else None
        ),
        "saturated_fraction_worst": worst("saturated_fraction"),
    }


@dataclass(frozen=True, eq=False)
class RateValidation:
    """The runs of :func:`validate_at_rate`: ``figures`` (one :class:`RunFigures` per run), their conditions."""

    conditions: RealLoopConditions
    uncertainty: str
    true_robots: int
    seed: int
    figures: tuple
    evaluations: int
    extremes: float = 0.0
    info: dict = field(default_factory=dict)

    def by_reference(self) -> dict:
        names = dict.fromkeys(f.reference for f in self.figures)
        return {name: _aggregate([f for f in self.figures if f.reference == name]) for name in names}

    @property
    def meets_bar(self) -> bool:
        """Every run settled, stayed inside the task (q, qdot, qddot) and chattered by at most 5 % of the effort limit."""
        return bool(
            self.figures
            and all(
                f.settled
                and f.inside_task
                and f.chatter_percent_max is not None
                and f.chatter_percent_max <= CHATTER_LIMIT_PERCENT
                for f in self.figures
            )
        )

    def verdict(self) -> str:
        """One line: what was simulated, on what, and what it measured (a measurement, not a certificate)."""
        parts = []
        for name, a in self.by_reference().items():
            chatter = "n/a" if a["chatter_percent_worst"] is None else f"{a['chatter_percent_worst']:.3g} %"
            qdd = "n/a" if a["qddot_fraction_worst"] is None else f"{a['qddot_fraction_worst']:.3g}"
            stuck = (
                f" ({a['stuck']} stuck: joint(s) {', '.join(str(j) for j in a['stuck_joints'])} outside their "
                "band, their error changing by under 10 % in the last 0.5 s: held, or fading over seconds)"
                if a["stuck"]
                else ""
            )
            parts.append(
                f"{name}: {a['settled']}/{a['runs']} settled{stuck}, {a['inside_task']}/{a['runs']} inside the task "
                f"(worst qddot {qdd} of its bound), chatter <= {chatter} of the effort limit"
            )
        bar = "meets" if self.meets_bar else "does not meet"
        budget = self.info.get("friction_budget")
        if budget and not self.meets_bar and budget["coulomb"] > 0:
            parts.append(_budget_words(budget))
        return (
            f"simulated on {self.true_robots} true robot(s) drawn from {self.uncertainty}"
            f"{vertex_words(self.true_robots, self.extremes)}, at "
            f"{self.conditions.words()}: " + "; ".join(parts) + f" ({bar} settle / inside / chatter <= "
            f"{CHATTER_LIMIT_PERCENT:g} %; a simulation, not a certificate)"
        )

    def summary(self) -> dict:
        return {
            "what": "the controller discretised and closed on the nonlinear true robots at the rate (a simulation)",
            "conditions": self.conditions.to_dict(),
            "uncertainty": self.uncertainty,
            "true_robots": self.true_robots,
            "at_vertices": at_vertices(self.true_robots, self.extremes),
            "seed": self.seed,
            "evaluations": self.evaluations,
            "by_reference": self.by_reference(),
            "meets_bar": self.meets_bar,
            "chatter_limit_percent": CHATTER_LIMIT_PERCENT,
            "verdict": self.verdict(),
            "runs": [f.to_dict() for f in self.figures],
            **self.info,
        }


def set_words(spec, conditions) -> str:
    """The drawn set's words, with the friction the loop applies where the set states none.

    The set's own words say "friction: not stated" when it has no friction;
    the validation still applies its conditions' friction to every run.
    """
    words = spec.words()
    return words.replace(
        "friction: not stated",
        f"friction: none in the set; every run applies the validation's own (viscous "
        f"{conditions.friction_viscous:g} N m s/rad + Coulomb {conditions.friction_coulomb:g} N m per joint, "
        "not in the inner model)",
    )


def validate_at_rate(
    robot,
    K,
    domain,
    *,
    conditions: RealLoopConditions | None = None,
    uncertainty=None,
    true_robots: int = 20,
    extremes: float = EXTREME_SHARE,
    seed: int = 0,
    q0=None,
    settle_time: float = 3.0,
    references=None,
) -> RateValidation:
    """Close ``K`` at the rate on ``true_robots`` robots drawn from ``uncertainty`` and run the task's references.

    Parameters
    ----------
    robot : Robot or InnerLoopRobot
        The problem's robot (its inner layer, if any, computes with the nominal model and the middle payload).
    K : LTI system, array or DiscreteController
        The continuous controller (discretised here at ``conditions.rate``), or a discrete one at that rate.
    domain : Domain, TaskDomain or PLDI
        The task whose bounds the runs are measured against (a PLDI gives its domain and nominal position).
    conditions : RealLoopConditions, optional
        Default: 1 kHz, one sample of delay, 18-bit encoders, viscous 1 and Coulomb 2 N m per joint.
    uncertainty : RobotUncertainty, optional
        Default :func:`default_uncertainty`.
    true_robots : int
    extremes : float
        The share of them drawn at vertices of the set (default :data:`~polyrob.uncertainty_set.draw.EXTREME_SHARE`:
        a loop's gain is largest near them); the rest uniformly inside.
    seed : int
    q0 : array_like, optional
        Start (default the PLDI's nominal position, else the domain's centre).
    settle_time : float
        Seconds each run goes on after its reference stops.
    references : list, optional
        ``[(name, Reference, t_final, move_end)]`` (default :func:`task_references`).
    """
    from polyrob.progress import report
    from polyrob.validate.discretize import DiscreteController, discretize

    conditions = RealLoopConditions() if conditions is None else conditions
    if int(true_robots) < 1:
        raise ArgumentError(f"--true-robots: give at least 1, got {true_robots}")
    dom = getattr(domain, "domain", domain)
    point = getattr(domain, "nominal_point", None)
    if q0 is None:
        q0 = np.asarray(point["q"], float) if point else 0.5 * (np.asarray(dom.q_lower) + np.asarray(dom.q_upper))
    q0 = np.clip(np.asarray(q0, float), dom.q_lower, dom.q_upper)
    if isinstance(K, DiscreteController):
        Kd = K.system
    else:
        Kd = discretize(K, conditions.rate, method=conditions.method).system
    spec = default_uncertainty(robot) if uncertainty is None else uncertainty
    base = _base(robot)
    if getattr(base, "model", None) is not None:
        spec = spec.bound(base)
    plants = true_plants(robot, spec, int(true_robots), seed=seed, extremes=extremes)
    analytic = getattr(base, "model", None) is None  # no links to draw: no vertices either
    extremes = 0.0 if analytic else float(extremes)
    refs = task_references(dom, q0, settle_time=settle_time) if references is None else references
    h = 1.0 / conditions.rate
    per_plant = sum(int(np.ceil(t_final / h - 1e-9)) for _, _, t_final, _ in refs)
    total, done = per_plant * len(plants), [0]
    figures, evaluations = [], 0
    zero = np.zeros((1, len(q0)))
    for plant, words in plants:
        v_eq = np.asarray(plant.inverse_dynamics(q0[None], zero, zero), float)[0]  # the settled hold
        for name, ref, t_final, move_end in refs:
            offset = done[0]

            def tick(k, offset=offset):
                done[0] = offset + k
                report(done[0], total)

            trace = simulate_real_loop(
                plant, Kd, ref.bind(q0), q0=q0, t_final=t_final, v_eq=v_eq, conditions=conditions, on_sample=tick
            )
            done[0] = offset + int(np.ceil(t_final / h - 1e-9))
            evaluations += int(trace.info["evaluations"])
            figures.append(
                run_figures(trace, dom, plant, reference=name, true_robot=words, move_end=move_end, lsb=conditions.lsb)
            )
    return RateValidation(
        conditions=conditions,
        uncertainty=set_words(spec, conditions)
        if getattr(base, "model", None) is not None
        else "the model itself (an analytic robot: no links to draw)",
        true_robots=len(plants),
        seed=int(seed),
        figures=tuple(figures),
        evaluations=evaluations,
        extremes=extremes,
        info={
            "inner": getattr(robot, "inner", "none"),
            "start_q": q0.tolist(),
            "friction_budget": friction_budget(robot, q0, conditions, dom),
        },
    )
