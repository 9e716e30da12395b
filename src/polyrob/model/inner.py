"""Inner control layers: the robot seen by the outer (robust) controller through an inner loop.

The paper's controller drives the torques itself (``inner = "none"``).  Two
inner layers, computed from a *model* of the robot, can sit between it and
the motors; the outer controller's input is then ``v``:

* ``"gravity"``: ``u = g_hat(q) + v`` (gravity compensation);
* ``"computed-torque"``: ``u = M_hat(q) v + h_hat(q, qdot)`` with
  ``h_hat = C_hat qdot + g_hat + D qdot`` (so ``u = rnea_hat(q, qdot, v) + D qdot``).

The model differs from the true robot by a payload (a :class:`PayloadRange`:
the model carries the middle of the range) and a model error ``p``: the
true robot's link inertias are the model's times ``s`` in ``[1 - p, 1 + p]``.
:class:`InnerLoopRobot` is the closed inner loop ``xdot = f(x, u(x, v))`` of
one true robot, with the interface of every robot
(:class:`~polyrob.model.base.Manipulator`), so the bounds, the plant and
the validation run on it unchanged.  Its Jacobians are exact (chain rule on
Pinocchio's analytic derivatives)::

    A = df/dx + df/du [du/dq, du/dqdot],      B = df/du du/dv = M^-1 (1, 1 or M_hat)

:meth:`InnerLoopRobot.variants` are the true robots the bounds are taken
over (the ranges are *sampled*: the lightest payload at the centre of the
offset box, the heaviest at every corner of it, times ``s = 1 - p, 1 + p``,
all links scaled together, plus the nominal one).

Examples
--------
>>> import numpy as np
>>> from polyrob import load_robot
>>> arm = inner_loop(load_robot("double_pendulum"), "gravity")
>>> q = np.array([[0.3, -0.2]]); z = np.zeros((1, 2))
>>> A, B = arm.jacobians_batch(q, z, z)            # at rest with v = 0: gravity is cancelled
>>> bool(np.allclose(A[0, 2:, :2], 0.0, atol=1e-9)), bool(np.allclose(arm.acceleration(q[0], z[0], z[0]), 0.0))
(True, True)
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import pinocchio

from polyrob.errors import ArgumentError, RobotError
from polyrob.model import dynamics
from polyrob.model.base import Manipulator
from polyrob.model.payload import PayloadRange, with_payload

__all__ = ["INNER_LAYERS", "InnerLoopRobot", "SetLoopRobot", "inner_loop", "inner_loop_of_set", "runtime_needs"]

#: The inner layers: the paper's none, gravity compensation, computed torque.
INNER_LAYERS = ("none", "gravity", "computed-torque")

_COPIED = (
    "name",
    "source",
    "joint_names",
    "joint_kinds",
    "position_lower",
    "position_upper",
    "velocity_limit",
    "effort_limit",
    "damping",
    "locked",
    "notes",
    "reflected_inertia",
    "reference_poses",
)


def runtime_needs(inner: str) -> str:
    """What the inner layer computes at run time, every sample (for exports and messages)."""
    return {
        "none": "nothing: the controller's output is the joint torque u",
        "gravity": "u = g_hat(q) + v: the model's gravity torque g_hat(q) at the measured q, every sample",
        "computed-torque": (
            "u = M_hat(q) v + h_hat(q, qdot): the model's mass matrix M_hat(q) and "
            "h_hat(q, qdot) = C_hat(q, qdot) qdot + g_hat(q) + D qdot at the measured q, qdot, every sample"
        ),
    }[inner]


@dataclass(frozen=True, eq=False)
class InnerLoopRobot(Manipulator):
    """The inner closed loop of one true robot, input ``v``; build it with :func:`inner_loop`.

    Attributes
    ----------
    inner : str
        One of :data:`INNER_LAYERS`.
    model_robot : Robot
        What the inner layer computes with (the robot with the middle payload).
    true_robot : Robot
        The robot the loop is closed on (a payload and a model error).
    payload : PayloadRange or None
    model_error : float
        ``p``: the true link inertias are the model's times a factor in ``[1 - p, 1 + p]``.
    scenario : str
        This true robot's payload and inertia factor, in words.
    """

    inner: str
    model_robot: object = field(repr=False)
    true_robot: object = field(repr=False)
    payload: PayloadRange | None = None
    model_error: float = 0.0
    scenario: str = "nominal"
    _scenarios: tuple = field(default=(), repr=False)

    def __post_init__(self):
        for attr in _COPIED:
            object.__setattr__(self, attr, getattr(self.true_robot, attr))

    # ------------------------------------------------------------------ the inner law
    def torque(self, q, qdot, v) -> np.ndarray:
        """The motor torques ``u`` (n, m) the inner layer gives for outer inputs ``v``."""
        q, qdot, v = _rows(q, qdot, v)
        if self.inner == "none":
            return v.copy()
        if self.inner == "gravity":
            return self.model_robot.inverse_dynamics(q, np.zeros_like(q), np.zeros_like(q)) + v
        return self.model_robot.inverse_dynamics(q, qdot, v)

    def acceleration(self, q, qdot, v) -> np.ndarray:
        """``qddot`` of the true robot under ``u = torque(q, qdot, v)``."""
        u = self.torque(q, qdot, v)[0]
        return self.true_robot.acceleration(q, qdot, u)

    def inverse_dynamics(self, q, qdot, qddot) -> np.ndarray:
        """The outer inputs ``v`` (n, m) that give ``qddot`` on the true robot (the inner law inverted)."""
        q, qdot, qddot = _rows(q, qdot, qddot)
        u = self.true_robot.inverse_dynamics(q, qdot, qddot)
        if self.inner == "none":
            return u
        zero = np.zeros_like(q)
        if self.inner == "gravity":
            return u - self.model_robot.inverse_dynamics(q, zero, zero)
        h = self.model_robot.inverse_dynamics(q, qdot, zero)
        model, data = self.model_robot.model, self.model_robot._data
        Mhat = np.empty((len(q), self.m, self.m))
        for k, c in enumerate(dynamics.to_configuration(self.model_robot, q)):
            Mhat[k] = pinocchio.crba(model, data, c)
        Mhat = np.triu(Mhat) + np.swapaxes(np.triu(Mhat, 1), 1, 2)
        return np.linalg.solve(Mhat, (u - h)[:, :, None])[:, :, 0]

    def mass_matrix(self, q) -> np.ndarray:
        """``(df/dv)^-1`` on the velocity rows: ``M(q)``, or ``M_hat^-1 M`` for computed torque."""
        M = self.true_robot.mass_matrix(q)
        if self.inner == "computed-torque":
            return np.linalg.solve(self.model_robot.mass_matrix(q), M)
        return M

    def jacobians_batch(self, q, qdot, v):
        """``A = df/dx + df/du du/dx`` (n, 2m, 2m) and ``B = df/du du/dv`` (n, 2m, m) of the inner loop."""
        q, qdot, v = _rows(q, qdot, v)
        m = self.m
        if self.inner == "none":
            return self.true_robot.jacobians_batch(q, qdot, v)
        model_robot = self.model_robot
        model, data = model_robot.model, model_robot._data
        config = dynamics.to_configuration(model_robot, q)
        n = len(q)
        if self.inner == "gravity":
            u = self.torque(q, qdot, v)
            A, B = self.true_robot.jacobians_batch(q, qdot, u)
            dg = np.empty((n, m, m))
            for k in range(n):
                dg[k] = pinocchio.computeGeneralizedGravityDerivatives(model, data, config[k])
            A[:, m:, :m] += B[:, m:, :] @ dg
            return A, B
        # computed torque: one RNEA-derivatives call per point gives du/dq, du/dqdot, M_hat and u itself
        qdot_c, v_c = np.ascontiguousarray(qdot), np.ascontiguousarray(v)
        du_dq, du_dv, Mhat, u = np.empty((n, m, m)), np.empty((n, m, m)), np.empty((n, m, m)), np.empty((n, m))
        for k in range(n):
            du_dq[k], du_dv[k], Mhat[k] = pinocchio.computeRNEADerivatives(model, data, config[k], qdot_c[k], v_c[k])
            u[k] = data.tau
        Mhat = np.triu(Mhat) + np.swapaxes(np.triu(Mhat, 1), 1, 2)
        u += qdot * model_robot.damping
        du_dv += np.diag(model_robot.damping)
        A, B = self.true_robot.jacobians_batch(q, qdot, u)
        minv = B[:, m:, :].copy()
        A[:, m:, :m] += minv @ du_dq
        A[:, m:, m:] += minv @ du_dv
        B[:, m:, :] = minv @ Mhat
        return A, B

    # ------------------------------------------------------------------ the ranges
    def variants(self) -> tuple[InnerLoopRobot, ...]:
        """The true robots the bounds are taken over: this one first, then the sampled corners."""
        return (self, *self._scenarios)

    def with_true(self, mass: float | None = None, com=None, scale: float = 1.0) -> InnerLoopRobot:
        """The same inner layer and model on a true robot with this payload and inertia factor."""
        if mass is None:
            mass, com = self.payload.midpoint if self.payload is not None else (0.0, np.zeros(3))
        true = with_payload(self._base, mass, com, scale=scale)
        words = f"payload {mass:.4g} kg at ({', '.join(f'{c:.3g}' for c in np.ravel(com))}), links x {scale:.4g}"
        return replace(self, true_robot=true, scenario=words, _scenarios=())

    def drawn(self, rng, *, extreme: bool = False) -> InnerLoopRobot:
        """A true robot with a payload and an inertia factor drawn uniformly from their ranges (``extreme``: at their ends)."""
        mass, com = self.payload.draw(rng, extreme=extreme) if self.payload is not None else (0.0, np.zeros(3))
        if extreme:
            scale = 1 + self.model_error * rng.choice([-1.0, 1.0])
        else:
            scale = rng.uniform(1 - self.model_error, 1 + self.model_error)
        return self.with_true(mass, com, float(scale))

    @property
    def _base(self):
        return self.model_robot.__dict__.get("_polyrob_base", self.model_robot)

    def words(self, *, bounds_used: bool = True) -> str:
        """The inner layer and the ranges in one line (a certificate's scope note).

        ``bounds_used=False``: the uncertainty model does not rest on the
        PLDI's sampled A, B intervals (``inner-gain`` on proved factor
        ranges), and the note says so.
        """
        parts = [f"inner layer: {self.inner}" + ("" if self.inner == "none" else f" ({runtime_needs(self.inner)})")]
        if self.payload is not None:
            parts.append(self.payload.words() + " (model: the middle)")
        if self.model_error:
            parts.append(f"link masses/inertias ±{100 * self.model_error:g} % (all links by one factor)")
        if len(self._scenarios):
            parts.append(_bounds_words(len(self._scenarios) + 1, "range corners", bounds_used))
        return "; ".join(parts)

    def set_words(self) -> str:
        """The set of true robots in one phrase (a batch row's uncertainty): the link factor and the payload."""
        parts = [f"links ±{100 * self.model_error:g} % (all by one factor)"] if self.model_error else ["links nominal"]
        parts.append(self.payload.words() if self.payload is not None else "no payload")
        return "; ".join(parts)

    def describe(self) -> dict:
        out = super().describe()
        out["inner"] = {"layer": self.inner, "model_error": self.model_error}
        if self.payload is not None:
            out["inner"]["payload"] = self.payload.to_dict()
        return out


def _rows(*arrays):
    return tuple(np.atleast_2d(np.asarray(a, dtype=float)) for a in arrays)


def inner_loop(robot, inner: str = "gravity", *, payload: PayloadRange | None = None, model_error: float = 0.0):
    """The inner closed loop of ``robot`` (a :class:`InnerLoopRobot`) over a payload range and a model error.

    Parameters
    ----------
    robot : Robot
        A URDF robot from :func:`polyrob.load_robot` (without payload).
    inner : {"none", "gravity", "computed-torque"}
    payload : PayloadRange, optional
        The model carries its middle; the true robots range over it.
    model_error : float
        ``p`` in ``[0, 1)``: the true link inertias are the model's times ``1 - p`` ... ``1 + p``.

    Raises
    ------
    ArgumentError
        An unknown layer, or ``p`` not in ``[0, 1)``.
    RobotError
        An analytic robot (no Pinocchio model for the inner layer).
    """
    if inner not in INNER_LAYERS:
        raise ArgumentError(f"--inner: unknown inner layer {inner!r}: use one of {', '.join(INNER_LAYERS)}")
    try:
        p = float(model_error)
    except (TypeError, ValueError):
        raise ArgumentError(f"--model-error: {model_error!r} is not a number") from None
    if not (np.isfinite(p) and 0.0 <= p < 1.0):
        raise ArgumentError(f"--model-error: give a percentage in [0, 100), got {100 * p:g}")
    if getattr(robot, "model", None) is None:
        raise RobotError(f"{robot.name}: an inner layer needs a URDF robot (a Pinocchio model), not an analytic one")
    if payload is not None:
        payload = payload.at(robot)
    mass, com = payload.midpoint if payload is not None else (0.0, np.zeros(3))
    model_robot = with_payload(robot, mass, com)
    model_robot.__dict__["_polyrob_base"] = robot
    nominal = InnerLoopRobot(inner, model_robot, model_robot, payload, p)
    corners = payload.corners() if payload is not None else [(0.0, np.zeros(3))]
    scales = (1.0 - p, 1.0 + p) if p > 0 else (1.0,)
    scenarios = tuple(nominal.with_true(mm, cc, s) for mm, cc in corners for s in scales)
    if payload is None and p == 0:
        scenarios = ()
    return replace(nominal, _scenarios=scenarios)


#: True robots drawn at random inside a robot-uncertainty set that the bounds are taken over (besides the model).
SET_DRAWS = 6


@dataclass(frozen=True, eq=False)
class SetLoopRobot(InnerLoopRobot):
    """The inner loop of one true robot of a :class:`~polyrob.uncertainty_set.spec.RobotUncertainty` set.

    The inner layer computes with :func:`~polyrob.uncertainty_set.draw.model_of_set`
    (nominal links, the middle payload, the middle viscous friction); the
    true robots are drawn at random inside the set
    (:func:`~polyrob.uncertainty_set.draw.draw_true_robot`): each link's
    parameters independently, the payload's mass and off-flange centre of
    mass, each joint's viscous friction.  Build it with :func:`inner_loop_of_set`.
    """

    uncertainty: object = field(default=None, repr=False)

    def drawn(self, rng, *, extreme: bool = False) -> SetLoopRobot:
        """A true robot drawn at random inside the set (``extreme``: at a random vertex of it)."""
        from polyrob.uncertainty_set.draw import draw_true_robot

        true = draw_true_robot(self.uncertainty_robot, self.uncertainty, rng, extreme=extreme)
        return replace(self, true_robot=true.robot, scenario=true.words(), _scenarios=())

    @property
    def uncertainty_robot(self):
        """The nominal URDF robot the set is stated for."""
        return self.model_robot.__dict__["_polyrob_base"]

    def with_true(self, mass=None, com=None, scale: float = 1.0):
        raise ArgumentError("a robot-uncertainty set's true robots are drawn (drawn(rng)), not given by one factor")

    def words(self, *, bounds_used: bool = True) -> str:
        parts = [f"inner layer: {self.inner}" + ("" if self.inner == "none" else f" ({runtime_needs(self.inner)})")]
        parts.append(self.uncertainty.words() + " (model: nominal links, the middle payload and viscous friction)")
        body = self.uncertainty.payload
        if body is not None and body.mass_upper > 0:
            from polyrob.uncertainty_set.payload_body import payload_sampling_words

            parts.append(payload_sampling_words(body).replace("extremes", "inertia and torque extremes", 1))
        if any(f.coulomb > 0 for f in self.uncertainty.friction):
            parts.append("Coulomb friction as stated, no term of the frozen loop's Jacobians: not covered")
        if len(self._scenarios):
            parts.append(_bounds_words(len(self._scenarios) + 1, "the model and random draws", bounds_used))
        return "; ".join(parts)

    def set_words(self) -> str:
        return self.uncertainty.words()

    def describe(self) -> dict:
        out = super().describe()
        out["inner"]["uncertainty"] = self.uncertainty.to_dict()
        return out


def inner_loop_of_set(robot, inner: str, uncertainty, *, draws: int = SET_DRAWS, seed: int = 0) -> SetLoopRobot:
    """The inner loop of ``robot`` over a robot-uncertainty set: the model, then ``draws`` true robots drawn inside it.

    Raises
    ------
    ArgumentError
        An unknown layer, or a set that does not fit ``robot`` (see
        :meth:`~polyrob.uncertainty_set.spec.RobotUncertainty.bound`).
    """
    from polyrob.uncertainty_set.draw import draw_true_robots, model_of_set

    if inner not in INNER_LAYERS:
        raise ArgumentError(f"--inner: unknown inner layer {inner!r}: use one of {', '.join(INNER_LAYERS)}")
    if getattr(robot, "model", None) is None:
        raise RobotError(f"{robot.name}: an inner layer needs a URDF robot (a Pinocchio model), not an analytic one")
    spec = uncertainty.bound(robot)
    model_robot = model_of_set(robot, spec)
    model_robot.__dict__["_polyrob_base"] = robot
    nominal = SetLoopRobot(inner, model_robot, model_robot, uncertainty=spec, scenario="the model")
    trues = draw_true_robots(robot, spec, draws, seed=seed)
    scenarios = tuple(replace(nominal, true_robot=t.robot, scenario=t.words()) for t in trues)
    return replace(nominal, _scenarios=scenarios)


def _bounds_words(robots: int, which: str, used: bool) -> str:
    """How the PLDI's bounds were sampled, and whether the certificate rests on them."""
    if used:
        return f"bounds sampled at {robots} true robots ({which})"
    return f"the PLDI's A, B intervals, sampled at {robots} true robots ({which}), are not what the model rests on"
