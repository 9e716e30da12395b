"""Frozen plants of true robots drawn from a robot-uncertainty set: a multi-model tuning and a sampled lower bound.

A μ certificate is only as tight as the uncertainty model it is computed
on, and on a per-link set (:mod:`polyrob.plant.models.inner_links`) the
model holds the robot's set and more.  Two things are read from the
robot's own set instead, as MATLAB users do with ``usample`` and
``systune``:

* :func:`true_robot_check`: the frozen loop of ``n`` true robots drawn
  from the set (each at a random point of the task), closed with a
  controller, and the largest weighted gain among them.  Half are drawn
  inside the set at random points of the task; half at random *vertices*
  of the set (every factor at an end, the payload's centre of mass on its
  ball's surface) at random *corners* of the task: a frozen loop's worst
  cases lie there, and uniform draws seldom go (``python
  benchmarks/true_robots.py`` prints both kinds' worst for each controller;
  ``tests/test_true_robots.py`` checks that the vertices find more).  Each true robot is
  a member of the set, so this worst case is a **lower bound** of the
  set's worst case (sampled, and on a frequency grid: a lower bound of each
  loop's H∞ norm too), never a certificate; printed beside μ, it says how
  much of μ is the model's and how much the robot's.
* :func:`tune_on_true_robots`: a fixed-structure controller (a per-joint
  PID by default) tuned on those frozen plants by the multi-model H∞
  optimiser of :func:`~polyrob.synthesis.fixed.vertex.vertex_synthesis`
  (``systune`` with several models), from a warm start, then checked on
  a second, independent draw.  The result is a candidate; its certificate
  is μ's, computed afterwards on the model like any other controller's.

The plants are polyrob's own loop (:meth:`~polyrob.model.inner.SetLoopRobot.drawn`,
its inverse dynamics and Jacobians); ``benchmarks/independent_check.py``
checks the same controllers with code of its own.

Examples
--------
>>> from polyrob.synthesis.true_robots import TrueRobotCheck
>>> TrueRobotCheck(draws=500, unstable=0, worst=0.93, median=0.61, seed=1).words()[:73]
'true robots: worst weighted gain 0.93 (median 0.61) over 500 frozen loops'
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from polyrob.errors import ArgumentError
from polyrob.uncertainty_set.draw import EXTREME_SHARE, at_vertices  # the share at vertices, how many that is

__all__ = [
    "CHECK_DRAWS",
    "TUNING_DRAWS",
    "MODEL_CORNERS",
    "EXTREME_SHARE",
    "TrueRobotCheck",
    "TrueRobotTuning",
    "true_robot_plants",
    "true_robot_check",
    "tune_on_true_robots",
    "check_omega",
    "has_set",
    "check_of_problem",
    "share_of_mu",
]

#: True robots of the held-out check (each at one random point of the task).
CHECK_DRAWS = 500
#: True robots the multi-model tuning is fitted to (ur5's per-link set: a PID fitted to 150 reached 0.825 on
#: them and 1.02 on 500 others, docs/uncertainty.md: the held-out check is what to read).
TUNING_DRAWS = 150
#: Corners of the uncertainty model tuned on with ``model=`` (all of them up to this many, as many random ones
#: beyond): ur5's ``inner-links`` model has six real direction scalars, 64 corners.
MODEL_CORNERS = 64
#: Seeds of the tuning's and the check's draws: the check never sees a plant the tuning fitted.
TUNING_SEED, CHECK_SEED = 0, 99


def has_set(loop) -> bool:
    """Whether true robots can be drawn behind ``loop``: a robot-uncertainty set, or an inner layer's own ranges.

    A :class:`~polyrob.model.inner.SetLoopRobot` draws each link on its own
    (the engineer's set); any other inner loop with a model error or a
    payload range draws from the set its certificate states (one factor on
    all links, the payload range), so an arm's default task says the figure
    too.  A loop whose model is exact has nothing to draw.
    """
    from polyrob.model.inner import InnerLoopRobot, SetLoopRobot

    if isinstance(loop, SetLoopRobot):
        return loop.uncertainty is not None
    return isinstance(loop, InnerLoopRobot) and bool(loop.model_error or loop.payload is not None)


def check_of_problem(problem, K) -> TrueRobotCheck | None:
    """:func:`true_robot_check` of ``K`` on ``problem``'s set and task (what ``analyze`` and ``synth`` print).

    ``None`` without a set to draw from, or off a task domain (a torque
    box fixes the outer input, not the acceleration a true robot is drawn at).
    """
    if not has_set(problem.robot) or getattr(problem.domain, "kind", "") != "task":
        return None
    return true_robot_check(problem.robot, problem.domain, K, problem.hyperparameters)


def _needs_set(loop) -> None:
    if not has_set(loop):
        raise ArgumentError(
            "true robots are drawn from a robot-uncertainty set (--robot-uncertainty FILE or --link-error P) "
            "or an inner layer's model error or payload range (--model-error, --payload-mass)"
        )


def true_robot_plants(
    loop, domain, n: int, *, seed: int = 0, extremes: float = EXTREME_SHARE
) -> list[tuple[np.ndarray, np.ndarray]]:
    """``(A, B)`` of ``n`` frozen loops: each a true robot drawn from ``loop``'s set, at a point of ``domain``.

    The first ``n - round(extremes n)`` are drawn inside the set, each at a
    random point of ``domain``; the rest at a random vertex of the set
    (``loop.drawn(rng, extreme=True)``) and a random corner of ``domain``.

    Parameters
    ----------
    loop : InnerLoopRobot
        The inner loop over a robot-uncertainty set (:func:`polyrob.model.inner.inner_loop_of_set`), or
        one with a model error or a payload range (:func:`polyrob.model.inner.inner_loop`).
    domain : TaskDomain
        Positions, velocities and accelerations; the outer input at a point
        is the one that gives its acceleration on that true robot.
    n : int
    seed : int

    Raises
    ------
    ArgumentError
        ``loop`` has no set, or ``n < 1``.
    """
    _needs_set(loop)
    if int(n) < 1:
        raise ArgumentError(f"true robots: need at least one draw, got {n}")
    rng = np.random.default_rng(seed)
    points = domain.sample_box(int(n), method="uniform", seed=int(rng.integers(2**31)))
    inside = int(n) - at_vertices(n, extremes)
    lower, upper = np.asarray(domain.lower, float), np.asarray(domain.upper, float)
    corners = rng.integers(0, 2, size=(int(n) - inside, len(lower))) == 1
    points[inside:] = np.where(corners, upper, lower)
    q, qdot, a = domain.split(points)
    out = []
    for k in range(int(n)):
        true = loop.drawn(rng, extreme=k >= inside)
        v = true.inverse_dynamics(q[k : k + 1], qdot[k : k + 1], a[k : k + 1])
        A, B = true.jacobians_batch(q[k : k + 1], qdot[k : k + 1], v)
        out.append((np.asarray(A[0], float), np.asarray(B[0], float)))
    return out


def check_omega(weights: dict) -> np.ndarray:
    """The frequency grid of the check and the tuning: 20 points per decade over the weights' corners and beyond."""
    corners = []
    for key in ("omega_b", "omega_bt"):
        corners += [float(v) for v in np.atleast_1d(weights.get(key, ())) if float(v) > 0]
    lo = min(corners, default=1.0) * 1e-3
    hi = max(corners, default=1.0) * 1e3
    return np.logspace(np.log10(lo), np.log10(hi), int(20 * np.log10(hi / lo)) + 1)


@dataclass(frozen=True)
class TrueRobotCheck:
    """The largest weighted gain of a controller's frozen loops on true robots drawn from the set.

    Attributes
    ----------
    draws : int
        Frozen loops (true robots, each at one random task point).
    extremes : int
        Of them, drawn at a vertex of the set and a corner of the task.
    unstable : int
        Loops with a closed-loop pole at ``Re >= 0``.
    worst, median : float
        Over the stable loops, the peak of ``σ_max`` of the weighted loop
        (``[W_S S; W_T T; W_KS K S]``) on the grid: a lower bound of the
        set's worst case (``inf`` when a loop is unstable).
    seed : int
    worst_channels : dict
        The worst loop's peak for each weight alone (``W_S S``, ``W_T T``,
        ``W_KS K S``: the ones the problem has), on the same grid: which
        weight it misses (empty when a loop is unstable).
    """

    draws: int
    unstable: int
    worst: float
    median: float
    seed: int
    extremes: int = 0
    worst_channels: dict = field(default_factory=dict)

    def words(self) -> str:
        none = "none unstable" if self.unstable == 0 else f"{self.unstable} UNSTABLE"
        where = f" ({self.extremes} at its vertices and the task's corners)" if self.extremes else ""
        channels = ""
        if self.worst_channels and self.worst >= 1.0:
            channels = "; the worst loop by weight: " + ", ".join(
                f"{name} {value:.3g}" for name, value in self.worst_channels.items()
            )
        return (
            f"true robots: worst weighted gain {self.worst:.3g} (median {self.median:.3g}) over {self.draws} "
            f"frozen loops drawn from the set{where}, {none}{channels} (sampled on a frequency grid: a lower bound "
            "of the set's worst case, not a certificate)"
        )

    def to_dict(self) -> dict:
        return {
            "draws": self.draws,
            "unstable": self.unstable,
            "worst": self.worst,
            "median": self.median,
            "seed": self.seed,
            "extremes": self.extremes,
            "worst_channels": dict(self.worst_channels),
            "words": self.words(),
        }


def share_of_mu(check: dict, mu_lower: float | None) -> str | None:
    """Whose a μ above 1 is, read from the true robots' figure (``check``: :meth:`TrueRobotCheck.to_dict`).

    ``None`` when there is nothing to say (μ's lower bound unknown or below 1
    and the true robots meet the weights).  Every true robot is a member of
    the set, so a figure of 1 or more (or an unstable loop) is a robot of the
    set that the controller fails: the controller's share, which no tighter
    model removes.  A μ lower bound above every true robot's figure is a
    member of the *model* that no drawn robot is: the model's share (the
    draws are a sample, so this says "none drawn", not "none exists").

    Examples
    --------
    >>> share_of_mu({"worst": 1.4, "unstable": 0, "draws": 500}, 2.7)[:46]
    'the controller fails true robots of the set to'
    >>> share_of_mu({"worst": 0.93, "unstable": 0, "draws": 500}, 3.8)[:39]
    "mu's lower bound 3.8 is above every one"
    """
    worst, unstable, draws = float(check["worst"]), int(check["unstable"]), int(check["draws"])
    above = mu_lower is not None and np.isfinite(mu_lower) and mu_lower >= 1.0 and mu_lower > worst
    model = (
        f"mu's lower bound {mu_lower:.3g} is above every one of the {draws} true robots ({worst:.3g}): it is a "
        "member of the uncertainty model that no drawn robot is"
        if above
        else ""
    )
    if unstable or worst >= 1.0:
        what = f"{unstable} of {draws} unstable" if unstable else f"worst weighted gain {worst:.3g}"
        words = (
            f"the controller fails true robots of the set too ({what}): a better controller is needed before "
            "any model can certify it"
        )
        return words + (f"; beyond that, {model}" if model else "")
    if model:
        return model + ", so a tighter model is what stands between this controller and a certificate"
    return None


def _loop_figures(plants, K, W_S, W_T, W_KS, omega) -> tuple[np.ndarray, np.ndarray]:
    """Per plant: the closed loop's spectral abscissa and its weighted grid peak."""
    from polyrob.analysis.time_varying.vertices import closed_loop_vertices, vertex_set
    from polyrob.synthesis.fixed.vertex import vertex_peaks

    vs = vertex_set(plants, max_vertices=len(plants))
    abscissa = np.array([np.linalg.eigvals(A).real.max() for A in closed_loop_vertices(vs, K)])
    return abscissa, vertex_peaks(vs, K, W_S, W_T, W_KS, omega=omega)


def true_robot_check(
    loop, domain, K, weights: dict, *, n: int = CHECK_DRAWS, seed: int = CHECK_SEED, extremes: float = EXTREME_SHARE
) -> TrueRobotCheck:
    """:class:`TrueRobotCheck` of ``K`` on ``n`` true robots of ``loop``'s set over ``domain``.

    ``extremes``: the share drawn at vertices of the set and corners of the
    task (:func:`true_robot_plants`).

    ``weights``: the problem's hyperparameters (:func:`polyrob.plant.weights.plant_weights`
    builds ``W_S``, ``W_T`` and, with the limit keys, ``W_KS``).
    """
    from polyrob.plant.weights import plant_weights

    W = plant_weights(weights)
    plants = true_robot_plants(loop, domain, n, seed=seed, extremes=extremes)
    omega = check_omega(weights)
    abscissa, peaks = _loop_figures(plants, K, W["W_S"], W["W_T"], W["W_KS"], omega)
    stable = abscissa < 0
    worst = float(peaks[stable].max()) if stable.all() else float("inf")
    median = float(np.median(peaks[stable])) if stable.any() else float("inf")
    channels = _channels(plants[int(np.argmax(peaks))], K, W, omega) if stable.all() else {}
    return TrueRobotCheck(int(n), int((~stable).sum()), worst, median, int(seed), at_vertices(n, extremes), channels)


def _channels(plant, K, W, omega) -> dict:
    """One loop's peak for each weight alone: ``{"W_S S": ..., "W_T T": ..., "W_KS K S": ...}`` (those given)."""
    from polyrob.analysis.time_varying.vertices import vertex_set
    from polyrob.synthesis.fixed.vertex import vertex_peaks

    vs = vertex_set([plant], max_vertices=1)
    names = {"W_S": "W_S S", "W_T": "W_T T", "W_KS": "W_KS K S"}
    return {name: float(vertex_peaks(vs, K, **{key: W[key]}, omega=omega)[0])
            for key, name in names.items() if W.get(key) is not None}  # fmt: skip


@dataclass(frozen=True, eq=False)
class TrueRobotTuning:
    """What :func:`tune_on_true_robots` made.

    Attributes
    ----------
    controller : control.StateSpace
    structure : str
    draws : int
        True robots the tuning was fitted to.
    start_worst, fitted_worst : float
        The worst weighted grid peak over those robots, of the warm start and of the result.
    check : TrueRobotCheck
        The result on an independent draw.
    seconds : float
    corners : int
        Corners of the uncertainty model tuned on too (``model``; their figures are in the worst ones).
    """

    controller: object
    structure: str
    draws: int
    start_worst: float
    fitted_worst: float
    check: TrueRobotCheck
    seconds: float
    corners: int = 0

    def words(self) -> str:
        model = f" and {self.corners} corners of the uncertainty model" if self.corners else ""
        return (
            f"{self.structure} tuned on {self.draws} true robots drawn from the set{model} (multi-model H-inf on a "
            f"grid): worst {self.start_worst:.3g} -> {self.fitted_worst:.3g} on them; on {self.check.draws} others: "
            f"worst {self.check.worst:.3g}, {self.check.unstable} unstable"
        )


def tune_on_true_robots(
    loop,
    domain,
    weights: dict,
    start,
    *,
    structure: str = "pid",
    n: int = TUNING_DRAWS,
    check_draws: int = CHECK_DRAWS,
    max_iter: int = 300,
    progress=None,
    model=None,
) -> TrueRobotTuning:
    """A ``structure`` controller tuned from ``start`` on ``n`` frozen loops of true robots (see the module text).

    ``model`` (an :class:`~polyrob.plant.lftplant.UncertainPlant`): the
    plants at corners of its real parameters (the norm-bounded blocks at 0;
    all corners up to :data:`MODEL_CORNERS`, as many random ones beyond) are
    tuned on too.  μ certifies the model, which holds members no true robot
    is (a stiffness box wider than any link's): tuned on those as well, the
    controller is robust to what its certificate checks, as MATLAB's
    ``systune`` tunes an uncertain model on its scenarios.

    Raises
    ------
    ArgumentError
        ``loop`` has no true robots to draw (:func:`has_set`).
    SynthesisError
        No gain of ``start`` stabilises every frozen loop of the draw.
    """
    from polyrob.plant.weights import plant_weights
    from polyrob.synthesis.fixed.vertex import vertex_peak, vertex_synthesis

    t0 = time.perf_counter()
    W = plant_weights(weights)
    omega = check_omega(weights)
    plants = true_robot_plants(loop, domain, n, seed=TUNING_SEED)
    corners = 0
    if model is not None:
        k = model.n_params
        deltas = (model.delta_samples(kind="corners") if 2**k <= MODEL_CORNERS
                  else model.delta_samples(MODEL_CORNERS, kind="corners", seed=TUNING_SEED))  # fmt: skip
        plants = plants + [model.matrices_at(d) for d in deltas]
        corners = len(deltas)
    start_worst = vertex_peak(plants, start, W["W_S"], W["W_T"], W["W_KS"], omega=omega)
    result = vertex_synthesis(
        plants, W["W_S"], W["W_T"], W["W_KS"], structure=structure, initial=start, omega=omega,
        max_vertices=len(plants), max_iter=max_iter, rounds=5, certify=False, progress=progress,
    )  # fmt: skip
    fitted = vertex_peak(plants, result.controller, W["W_S"], W["W_T"], W["W_KS"], omega=omega)
    if fitted > start_worst:  # the optimiser's smoothed figure fell, its peak did not: keep the start
        controller, fitted = start, start_worst
    else:
        controller = result.controller
    check = true_robot_check(loop, domain, controller, weights, n=check_draws)
    return TrueRobotTuning(controller, structure, int(n), float(start_worst), float(fitted), check,
                           time.perf_counter() - t0, corners)  # fmt: skip
