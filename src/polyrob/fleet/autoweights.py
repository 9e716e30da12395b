"""Default weights for any serial robot: the paper's shape, stretched over the joints, levelled by the domain.

The paper gives W_S / W_T for its two joints only
(:data:`polyrob.plant.weights.PAPER_HYPERPARAMETERS`: joint 1 faster than
joint 2).  For ``m`` joints, :func:`automatic_hyperparameters`

* keeps that shape along the chain: each hyperparameter goes geometrically
  from the paper's joint-1 value at the base to its joint-2 value at the
  last joint (so ``m = 2`` gives the paper's values exactly, and one joint
  gets joint 1's);
* levels the bandwidths ``omega_b`` and ``omega_bt`` by the domain: a
  reference swinging over a joint's half range ``h_q`` at bandwidth ``w``
  needs a velocity of about ``w h_q``, and the paper's weights fit its
  domain's velocity-to-range ratio ``h_qdot / h_q``.  The level factor is
  the geometric mean over the joints of that ratio divided by the same
  mean on the paper's domain (``paper_2r --domain paper``), clipped to
  ``[1/8, 8]``; it is 1 on the paper's domain.

Beside the paper's W_S and W_T, :func:`limit_hyperparameters` gives the
weights of what limits a real loop (:mod:`polyrob.plant.weights`): the
control effort ``W_u`` from the URDF's effort limits and the torque the task
needs, and the encoder noise ``W_n`` from the encoder resolution
(``--encoder-bits``, default 18).  :func:`automatic_hyperparameters` adds
them when given the robot.

The result is a starting point, not a tuned design: the bandwidth search
(:func:`polyrob.pipeline.design_max_bandwidth`) then scales both bandwidths
to the largest factor with certified μ < 1.

Examples
--------
>>> h = automatic_hyperparameters(2)
>>> h["omega_b"], h["M_s"]
((0.5, 0.1), (2.0, 3.0))
>>> [round(w, 3) for w in automatic_hyperparameters(3)["omega_b"]]
[0.5, 0.224, 0.1]
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from polyrob.errors import ArgumentError

__all__ = [
    "automatic_hyperparameters",
    "domain_level",
    "limit_hyperparameters",
    "inverse_inertia_bound",
    "EffortBudget",
    "PAPER_DOMAIN_RATIO",
    "LEVEL_LIMITS",
    "TASK_TORQUE_SAMPLES",
    "TASK_TORQUE_MARGIN",
]

#: Geometric mean over the joints of ``h_qdot / h_q`` on the paper's domain (|qdot| <= 3.9564, 9.9561; q in +-pi).
PAPER_DOMAIN_RATIO = math.sqrt(3.9564 * 9.9561) / math.pi
#: The domain level factor is clipped to this range (a degenerate domain must not ask for absurd bandwidths).
LEVEL_LIMITS = (0.125, 8.0)
#: Domain points the task's torque and the inner layer's mass matrix are sampled at (seeded).
TASK_TORQUE_SAMPLES = 512
#: The sampled task torque is raised by this factor: a sampled maximum is an estimate from below.
TASK_TORQUE_MARGIN = 1.1


def _half_width(interval) -> float:
    lo, hi = (float(v) for v in interval)
    return 0.5 * (hi - lo)


def domain_level(domain) -> float:
    """The bandwidth level factor of ``domain`` (1 on the paper's; see the module text).

    Joints with a zero position or velocity range are left out of the mean;
    without any joint left the factor is 1.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> d = SimpleNamespace(to_dict=lambda: {"q": {"a": [-math.pi, math.pi], "b": [-math.pi, math.pi]},
    ...                                       "qdot": {"a": [-3.9564, 3.9564], "b": [-9.9561, 9.9561]}})
    >>> round(domain_level(d), 12)
    1.0
    """
    d = domain.to_dict()
    logs = []
    for joint, q in d["q"].items():
        hq, hv = _half_width(q), _half_width(d["qdot"][joint])
        if hq > 0 and hv > 0:
            logs.append(math.log(hv / hq))
    if not logs:
        return 1.0
    level = math.exp(sum(logs) / len(logs)) / PAPER_DOMAIN_RATIO
    return min(max(level, LEVEL_LIMITS[0]), LEVEL_LIMITS[1])


@dataclass(frozen=True)
class EffortBudget:
    """What the limit weights of one robot rest on (per joint, in the robot's units).

    Attributes
    ----------
    effort_limit : tuple of float
        ``tau_max`` [N m] (the URDF's effort limits).
    task_torque : tuple of float
        The largest ``|tau|`` the task needs [N m], sampled over the domain
        and the true robots, times :data:`TASK_TORQUE_MARGIN` (not proved).
    inertia_bound : tuple of tuples or None
        ``N_ji = max_q |M_hat(q)_ji|`` [N m s^2/rad] (sampled) when ``u`` is
        the computed-torque input ``v``; ``None`` when ``u`` is the torque.
    encoder_bits : int
    effort : tuple of float
        ``W_u`` [1/N m, or s^2/rad for ``v``], per channel
        (:func:`polyrob.plant.weights.effort_level`).
    noise : tuple of float
        ``W_n = LSB/2`` [rad].
    binds : tuple of str
        Per joint, what sets its torque budget: ``"encoder noise"`` (5 % of
        the limit peak to peak) or ``"effort limit"`` (less is left by the task).
    u_unit : str
    """

    effort_limit: tuple
    task_torque: tuple
    inertia_bound: tuple | None
    encoder_bits: int
    effort: tuple
    noise: tuple
    binds: tuple
    u_unit: str

    def hyperparameters(self) -> dict:
        """``{"effort": ..., "noise": ...}`` for :func:`automatic_hyperparameters`."""
        return {"effort": self.effort, "noise": self.noise}

    def words(self) -> str:
        """The budget in one line (what ``synth`` prints)."""
        from polyrob.plant.weights import CHATTER_FRACTION, encoder_lsb

        lim = ", ".join(f"{t:.3g}" for t in self.effort_limit)
        task = ", ".join(f"{t:.3g}" for t in self.task_torque)
        effort = ", ".join(f"{v:.4g}" for v in self.effort) if len(set(self.effort)) > 1 else f"{self.effort[0]:.4g}"
        through = "" if self.inertia_bound is None else ", shared through M_hat's rows (sampled) per channel"
        return (
            f"limit weights: W_u = {effort} [1/({self.u_unit})] from effort limits ({lim}) N m minus the "
            f"task's torque ({task}) N m (sampled), noise within {100 * CHATTER_FRACTION:g} % of the limit "
            f"peak to peak{through}; "
            f"W_n = {self.noise[0]:.4g} rad (half a count of a {self.encoder_bits}-bit encoder, "
            f"LSB {encoder_lsb(self.encoder_bits):.3g} rad)"
        )


def _task_points(robot, domain, n: int):
    """``(q, qdot, qddot)`` (n, m) each, sampled in the domain (``qddot = 0`` on a torque-box domain)."""
    z = np.asarray(domain.sample_box(n, seed=0), float)
    m = robot.m
    q, qdot = z[:, :m], z[:, m : 2 * m]
    if getattr(domain, "_third", "u") != "qddot":
        return q, qdot, np.zeros_like(q)
    qddot = z[:, 2 * m :]
    # the torque is affine in qddot: each point also with its accelerations pushed to the box's corner
    lo, hi = np.asarray(domain.qddot_lower, float), np.asarray(domain.qddot_upper, float)
    corner = np.where(qddot >= 0.5 * (lo + hi), hi, lo)
    return np.vstack([q, q]), np.vstack([qdot, qdot]), np.vstack([qddot, corner])


def limit_hyperparameters(robot, domain, *, encoder_bits: int | None = None, samples: int = TASK_TORQUE_SAMPLES):
    """The limit weights of ``robot`` over ``domain``: an :class:`EffortBudget`.

    The task's torque is the inverse dynamics of every true robot
    (:meth:`~polyrob.model.inner.InnerLoopRobot.variants`) at ``samples``
    points of the domain's ``(q, qdot, qddot)`` (``qddot = 0`` on a
    torque-box domain, which states no acceleration; each point also with its
    accelerations at the box's corner), raised by
    :data:`TASK_TORQUE_MARGIN`.  On a computed-torque robot ``u`` is ``v``;
    the bound of ``|M_hat(q)|`` is its entries' largest magnitudes at the
    same points, and each ``v`` channel gets its own weight
    (:func:`polyrob.plant.weights.effort_level`).

    Raises
    ------
    ArgumentError
        A joint without a finite effort limit, or a task that needs a
        joint's whole effort limit.
    """
    from polyrob.plant.weights import DEFAULT_ENCODER_BITS, effort_level, encoder_noise_level

    bits = DEFAULT_ENCODER_BITS if encoder_bits is None else encoder_bits
    noise = encoder_noise_level(bits)
    limit = np.asarray(robot.effort_limit, float).ravel()
    if limit.size != robot.m or not np.all(np.isfinite(limit) & (limit > 0)):
        raise ArgumentError(
            f"{robot.name}: the limit weights need a finite effort limit > 0 on every joint "
            f"(the URDF's <limit effort>), got {limit.tolist()}; drop the limit weights (--no-limit-weights)"
        )
    q, qdot, qddot = _task_points(robot, domain, int(samples))
    inner = getattr(robot, "inner", "none")
    variants = robot.variants() if hasattr(robot, "variants") else (robot,)
    truths = [getattr(v, "true_robot", v) for v in variants]
    need = np.max([np.abs(t.inverse_dynamics(q, qdot, qddot)).max(axis=0) for t in truths], axis=0)
    task = TASK_TORQUE_MARGIN * need
    bound = None
    if inner == "computed-torque":
        model = robot.model_robot
        bound = np.max([np.abs(np.asarray(model.mass_matrix(qk), float)) for qk in q], axis=0)
    effort = effort_level(limit, task, bound)
    from polyrob.plant.weights import CHATTER_FRACTION

    binds = tuple(
        "effort limit" if lim - t < 0.5 * CHATTER_FRACTION * lim else "encoder noise" for lim, t in zip(limit, task)
    )
    return EffortBudget(
        effort_limit=tuple(float(v) for v in limit),
        task_torque=tuple(float(v) for v in task),
        inertia_bound=None if bound is None else tuple(tuple(float(v) for v in row) for row in bound),
        encoder_bits=int(bits),
        effort=tuple(float(v) for v in effort),
        noise=(float(noise),) * robot.m,
        binds=binds,
        u_unit="N m" if bound is None else "rad/s^2",
    )


def inverse_inertia_bound(robot, domain, *, samples: int = TASK_TORQUE_SAMPLES):
    """``N_ij >= |M_hat^-1(q)_ij|`` over ``domain`` for a computed-torque robot (``None`` for any other layer).

    The largest ``|M_hat^-1(q)_ij|`` at ``samples`` points of the domain's
    positions (the points of the task torque), times :data:`TASK_TORQUE_MARGIN`:
    sampled, not proved (like the task's torque).  It turns a torque into the
    acceleration the outer loop sees (:func:`polyrob.plant.weights.coulomb_weight`).
    """
    if getattr(robot, "inner", "none") != "computed-torque":
        return None
    q, _, _ = _task_points(robot, domain, int(samples))
    model = robot.model_robot
    inv = np.array([np.abs(np.linalg.inv(np.asarray(model.mass_matrix(qk), float))) for qk in q])
    return TASK_TORQUE_MARGIN * inv.max(axis=0)


def automatic_hyperparameters(
    m: int, domain=None, overrides: dict | None = None, *, robot=None, encoder_bits: int | None = None
) -> dict:
    """W_S / W_T hyperparameters for ``m`` joints over ``domain`` (the paper's shape), and the limit weights.

    Parameters
    ----------
    m : int
        Number of actuated joints (>= 1).
    domain : Domain, optional
        Levels the bandwidths (:func:`domain_level`); default: level 1.
    overrides : dict, optional
        ``key -> sequence`` of 1 or ``m`` values, applied after (as in
        :func:`polyrob.pipeline.default_hyperparameters`; not levelled).
    robot : Manipulator, optional
        With ``domain``: adds the limit weights ``effort`` and ``noise``
        (:func:`limit_hyperparameters`; an override of either wins).
    encoder_bits : int, optional
        The encoder resolution of the noise weight (default 18).

    Returns
    -------
    dict
        ``key -> tuple`` of ``m`` floats, keys of :data:`polyrob.pipeline.WEIGHT_KEYS`
        (and :data:`polyrob.plant.weights.LIMIT_KEYS` with ``robot``).
    """
    from polyrob.pipeline.problem import default_hyperparameters
    from polyrob.plant.weights import PAPER_HYPERPARAMETERS

    if int(m) < 1:
        raise ArgumentError(f"a robot needs at least one joint, got m = {m}")
    m = int(m)
    level = 1.0 if domain is None else domain_level(domain)
    shaped = {}
    for key, paper in PAPER_HYPERPARAMETERS.items():
        first, last = float(paper[0]), float(paper[-1])
        # ends exact (m = 2 is the paper's to the last bit), geometric in between
        vals = [first] + [first * (last / first) ** (j / (m - 1)) for j in range(1, m - 1)] + [last]
        vals = vals[:m]
        if key in ("omega_b", "omega_bt"):
            vals = [v * level for v in vals]
        shaped[key] = vals
    if robot is not None and domain is not None:
        shaped.update(limit_hyperparameters(robot, domain, encoder_bits=encoder_bits).hyperparameters())
    # the user's overrides replace the shaped values as given
    shaped.update({k: list(v) for k, v in (overrides or {}).items()})
    return default_hyperparameters(m, shaped)
