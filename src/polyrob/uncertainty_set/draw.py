"""True robots drawn at random inside a :class:`~polyrob.uncertainty_set.spec.RobotUncertainty`.

:func:`draw_true_robot` gives one :class:`TrueRobot`: every link's
parameters drawn independently (the factor form: ``m``, ``h = m c`` and
``I_c`` each times a factor uniform in ``[1 - p, 1 + p]``, always a rigid
body; a ten-parameter box: uniform in the box, redrawn while the draw is
not a rigid body), the payload's mass uniform in its range and its centre
of mass uniform in its box or ball, each joint's viscous friction uniform in
its range (the Coulomb level is carried, not drawn: the frozen loops of a
moving joint do not see it).  Its :attr:`TrueRobot.robot` is a polyrob robot
with the drawn Pinocchio model, usable wherever the nominal one is
(``InnerLoopRobot(true_robot=...)``, the bounds, the validation).

:func:`common_factor_covers` says whether today's certified set (one
factor ``s`` in ``[1 - p, 1 + p]`` on every link, a payload range at the
flange, :func:`polyrob.model.inner.inner_loop`) contains a drawn robot.

Examples
--------
>>> import numpy as np
>>> from polyrob import load_robot
>>> from polyrob.uncertainty_set.spec import RobotUncertainty
>>> ur5 = load_robot("ur5")
>>> spec = RobotUncertainty(link_error=0.1).bound(ur5)
>>> true = draw_true_robot(ur5, spec, np.random.default_rng(0))
>>> common_factor_covers(true, ur5, model_error=0.1).covered
False
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pinocchio

from polyrob.errors import ArgumentError
from polyrob.uncertainty_set.payload_body import SECOND_MOMENT_ENTRIES, payload_middle, second_moment
from polyrob.uncertainty_set.spec import (
    RobotUncertainty,
    link_names,
    physically_consistent,
    scaled_parameters,
)

__all__ = [
    "TrueRobot",
    "Coverage",
    "draw_true_robot",
    "draw_true_robots",
    "vertex_words",
    "at_vertices",
    "EXTREME_SHARE",
    "common_factor_covers",
    "model_of_set",
    "payload_middle",
]

#: Draws of a ten-parameter box tried before the box is declared (nearly) empty of rigid bodies.
MAX_REDRAWS = 1000
#: The share of true robots drawn at vertices of the set (the rest inside it): the checks', the tuning's and
#: the validations' default.  A frozen loop's gain is largest near the vertices, which uniform draws seldom
#: reach (ur5's per-link set: a PID's worst weighted norm 1.02 on 500 uniform draws, 3.04 on 500 at
#: vertices, record ``true_robots``).
EXTREME_SHARE = 0.5


@dataclass(frozen=True, eq=False)
class TrueRobot:
    """One robot drawn from the set.

    Attributes
    ----------
    robot : Robot
        The nominal robot with the drawn links, the payload on its last link and the drawn viscous friction.
    link_parameters : dict
        ``{link: ten standard parameters}`` of the drawn links (without the payload).
    payload_mass : float
    payload_com : ndarray (3,)
        In the flange frame (m).
    viscous, coulomb : ndarray (m,)
        The drawn viscous coefficients (N m s/rad) and the Coulomb levels (N m) per joint.
    extreme : bool
        Drawn at a vertex of the set (``draw_true_robot(extreme=True)``).
    """

    robot: object
    link_parameters: dict
    payload_mass: float
    payload_com: np.ndarray
    viscous: np.ndarray
    coulomb: np.ndarray
    extreme: bool = False

    @property
    def model(self) -> pinocchio.Model:
        return self.robot.model

    def words(self) -> str:
        com = ", ".join(f"{c:.3g}" for c in self.payload_com)
        where = "at a vertex of the set" if self.extreme else "links drawn independently"
        return f"payload {self.payload_mass:.3g} kg at ({com}) m, {where}"


def draw_true_robot(robot, spec: RobotUncertainty, rng, *, extreme: bool = False) -> TrueRobot:
    """One true robot drawn from ``spec`` (bound to ``robot`` when it is not yet).

    ``extreme``: a random vertex of the set instead of a point inside it --
    each link's factors at ``1 ± p``, a ten-parameter box at a vertex that is
    a rigid body (inside the box when :data:`MAX_REDRAWS` vertices are none),
    the payload's mass at an end and its centre of mass on the ball's surface
    or at a box corner, each viscous coefficient at an end.  A frozen loop's
    gain is largest near such points, which uniform draws seldom reach.

    Raises
    ------
    ArgumentError
        A ten-parameter box where :data:`MAX_REDRAWS` draws found no rigid body.
    """
    from polyrob.model.payload import flange_frame

    if spec.robot != robot.name:
        spec = spec.bound(robot)
    model = robot.model.copy()
    explicit = {li.link: li for li in spec.links}
    p = spec.link_error or 0.0
    drawn = {}
    for name, j in link_names(robot).items():
        if name in explicit:
            theta = _draw_box(explicit[name], rng, extreme)
        else:
            nominal = np.asarray(model.inertias[j].toDynamicParameters(), float)
            a, b, d = 1 + p * rng.choice([-1.0, 1.0], size=3) if extreme else rng.uniform(1 - p, 1 + p, size=3)
            theta = scaled_parameters(nominal, a, b, d)
        model.inertias[j] = pinocchio.Inertia.FromDynamicParameters(theta)
        drawn[name] = theta
    mass, com = (0.0, np.zeros(3)) if spec.payload is None else spec.payload.draw(rng, extreme=extreme)
    if mass > 0:
        _, placement = flange_frame(robot)
        body = pinocchio.Inertia(float(mass), np.asarray(com, float), spec.payload.rotational_inertia(mass))
        last = model.njoints - 1
        model.inertias[last] = model.inertias[last] + placement.act(body)
    viscous = np.array(robot.damping, dtype=float)
    coulomb = np.zeros(robot.m)
    for f in spec.friction:
        k = robot.joint_names.index(f.joint)
        viscous[k] = f.viscous[int(rng.integers(2))] if extreme else rng.uniform(*f.viscous)
        coulomb[k] = f.coulomb
    model.damping[:] = viscous
    true = replace(robot, model=model, damping=viscous)
    return TrueRobot(true, drawn, float(mass), np.asarray(com, float), viscous, coulomb, bool(extreme))


def draw_true_robots(robot, spec: RobotUncertainty, n: int, seed: int = 0, *, extremes: float = 0.0) -> list[TrueRobot]:
    """``n`` true robots drawn with ``numpy.random.default_rng(seed)``: the last ``round(extremes n)`` at vertices.

    Raises
    ------
    ArgumentError
        ``extremes`` outside ``[0, 1]``.

    Examples
    --------
    >>> from polyrob import load_robot
    >>> from polyrob.uncertainty_set.spec import RobotUncertainty
    >>> so101 = load_robot("so101")
    >>> drawn = draw_true_robots(so101, RobotUncertainty(link_error=0.1), 4, extremes=0.5)
    >>> [t.extreme for t in drawn]
    [False, False, True, True]
    """
    inside = int(n) - at_vertices(n, extremes)
    spec = spec.bound(robot)
    rng = np.random.default_rng(seed)
    return [draw_true_robot(robot, spec, rng, extreme=k >= inside) for k in range(int(n))]


def at_vertices(n: int, extremes: float) -> int:
    """How many of ``n`` draws a share ``extremes`` puts at vertices (the last ones drawn), ``round(extremes n)``.

    Raises
    ------
    ArgumentError
        ``extremes`` outside ``[0, 1]``.

    >>> at_vertices(20, 0.5), at_vertices(1, 0.5)
    (10, 0)
    """
    if not 0.0 <= float(extremes) <= 1.0:
        raise ArgumentError(f"true robots: the share at vertices must lie in [0, 1], got {extremes!r}")
    return int(round(float(extremes) * int(n)))


def vertex_words(n: int, extremes: float) -> str:
    """How many of ``n`` draws sit at vertices of the set, in words (empty when none do).

    >>> vertex_words(20, 0.5)
    ' (10 of 20 at vertices of the set)'
    """
    k = at_vertices(n, extremes)
    return f" ({k} of {int(n)} at vertices of the set)" if k else ""


def _draw_box(interval, rng, extreme: bool = False) -> np.ndarray:
    lo, hi = np.array(interval.lower), np.array(interval.upper)
    if extreme:  # a vertex that is a rigid body; a box whose vertices are none is drawn inside below
        for _ in range(MAX_REDRAWS):
            theta = np.where(rng.integers(0, 2, size=lo.shape) == 1, hi, lo)
            if physically_consistent(theta):
                return theta
    for _ in range(MAX_REDRAWS):
        theta = rng.uniform(lo, hi)
        if physically_consistent(theta):
            return theta
    raise ArgumentError(
        f"robot uncertainty: links.{interval.link}: {MAX_REDRAWS} draws of its box found no rigid body: check its intervals"
    )


@dataclass(frozen=True)
class Coverage:
    """Whether the common-factor set contains a true robot: ``covered``, the best factor, and why not."""

    covered: bool
    factor: float
    residual: float
    reason: str


def common_factor_covers(true: TrueRobot, robot, *, model_error: float, payload=None, tol: float = 1e-6) -> Coverage:
    """Whether today's certified set contains ``true``.

    That set (:func:`polyrob.model.inner.inner_loop`) holds the robots whose
    every link is the nominal link times one factor ``s`` in
    ``[1 - model_error, 1 + model_error]``, carrying a payload of the
    ``payload`` range (a :class:`~polyrob.model.payload.PayloadRange`: mass
    and centre-of-mass box; the payload's rotational inertia is not compared;
    ``None``: no payload) and the URDF's damping, no Coulomb friction.  ``s`` is fitted
    by least squares to the links' parameters (relative to each parameter's
    size); the robot is covered when the relative residual is below ``tol``.
    """
    nominal = {
        name: np.asarray(robot.model.inertias[j].toDynamicParameters(), float) for name, j in link_names(robot).items()
    }
    scale = {name: np.maximum(np.abs(theta), 1e-6 * max(abs(theta[0]), 1e-12)) for name, theta in nominal.items()}
    x = np.concatenate([nominal[k] / scale[k] for k in nominal])
    y = np.concatenate([true.link_parameters[k] / scale[k] for k in nominal])
    s = float(x @ y / (x @ x))
    residual = float(np.linalg.norm(y - s * x) / np.linalg.norm(y))
    if residual > tol:
        return Coverage(False, s, residual, f"no one factor fits the links (relative residual {residual:.3g})")
    if abs(s - 1.0) > model_error + tol:
        return Coverage(False, s, residual, f"the links' factor {s:.4g} is outside 1 ± {model_error:g}")
    if true.payload_mass > 0:
        if payload is None:
            return Coverage(False, s, residual, "a payload the set does not have")
        inside = payload.mass_lower - tol <= true.payload_mass <= payload.mass_upper + tol and np.all(
            (np.array(payload.com_lower) - tol <= true.payload_com)
            & (true.payload_com <= np.array(payload.com_upper) + tol)
        )
        if not inside:
            return Coverage(False, s, residual, f"the payload is outside {payload.words()}")
    if np.any(true.coulomb > 0) or not np.allclose(true.viscous, robot.damping):
        return Coverage(False, s, residual, "friction the set does not have (Coulomb, or viscous off the URDF's)")
    return Coverage(True, s, residual, "")


def model_of_set(robot, spec: RobotUncertainty):
    """What an inner layer computes with under ``spec``: the nominal links, the middle payload, the middle viscous friction.

    Links given as ten-parameter intervals take their box's centre (an
    identification's estimate); the payload is its middle mass at the centre
    of its centre-of-mass ball or box, with its solid body's inertia.
    """
    from polyrob.model.payload import flange_frame

    if spec.robot != robot.name:
        spec = spec.bound(robot)
    model = robot.model.copy()
    explicit = {li.link: li for li in spec.links}
    for name, j in link_names(robot).items():
        if name in explicit:
            model.inertias[j] = pinocchio.Inertia.FromDynamicParameters(explicit[name].centre)
    body = spec.payload
    if body is not None and body.mass_upper > 0:
        mass, com, second = payload_middle(body)
        if mass > 0:
            _, placement = flange_frame(robot)
            # about its centre of mass: the solid's inertia plus the middle of m S(c)^T S(c), less the model's own shift
            extra = second - second_moment(mass, com)
            about_com = body.rotational_inertia(mass) + _matrix(extra)
            load = pinocchio.Inertia(float(mass), com, about_com)
            last = model.njoints - 1
            model.inertias[last] = model.inertias[last] + placement.act(load)
    viscous = np.array(robot.damping, dtype=float)
    for f in spec.friction:
        viscous[robot.joint_names.index(f.joint)] = 0.5 * (f.viscous[0] + f.viscous[1])
    model.damping[:] = viscous
    return replace(robot, model=model, damping=viscous)


def _matrix(six) -> np.ndarray:
    M = np.zeros((3, 3))
    for value, (i, j) in zip(six, SECOND_MOMENT_ENTRIES):
        M[i, j] = M[j, i] = value
    return M
