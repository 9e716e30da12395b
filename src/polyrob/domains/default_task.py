"""The task an arm gets when the user states none: a region around its reference pose, rates, an inner layer.

A robot of :data:`MIN_JOINTS` joints or more (the spatial arms: so101, ur5,
ur10, z1, talos_left_arm, panda, xarm7, ...) given to ``synth``, ``analyze``,
``run``, ``bounds``, ``info`` or ``batch`` without any domain or inner-layer
option is posed the problem an arm engineer poses:

* a **task domain** (:class:`~polyrob.domains.task.TaskDomain`) around
  the robot's reference pose (its SRDF's first ``group_state`` where
  example-robot-data ships one, else the midpoint of the joint ranges),
  ``|q - q_ref| <= 0.2 rad``, ``|qdot| <= 0.5 rad/s``,
  ``|qddot| <= 2 rad/s^2`` (:data:`DEFAULT_TASK`), torques by inverse
  dynamics;
* a **computed-torque inner layer** ``u = M_hat(q) v + h_hat(q, qdot)``
  computed from a model whose link masses and inertias may be off by
  ``±10 %`` (all links by one factor: the true robot is bounded at both
  ends of that range); reflected rotor inertia from the SRDF when it has
  rotor data, and said when it has none;
* a **payload** at the flange of 0 to 1 % of the arm's link mass
  (:attr:`DefaultTask.payload_fraction`: an instrument, changed between
  tasks; 0.17 kg on panda and ur5, 0.29 kg on ur10, 0.10 kg on xarm7,
  80 g on talos' arm, 47 g on z1, 5 g on so101), its centre of mass at the
  flange; the inner layer's model computes with the middle of the range,
  and the ``inner-gain`` model carries the mass as one more repeated
  scalar (:mod:`polyrob.plant.models.inner_factors`).
  ``DefaultTask(payload_fraction=0)`` poses the task without one.

Robots with fewer joints (the paper's planar arms, ``double_pendulum``,
``TwoDofs``) keep the URDF torque box and no inner layer, as the paper
poses them; any domain or inner-layer option, a ``--pldi`` file or
``--torque-box`` keeps today's behaviour for every robot.

Examples
--------
>>> t = DefaultTask()
>>> t.words()
'task ±0.2 rad around the reference pose, |qdot| <= 0.5 rad/s, |qddot| <= 2 rad/s^2, inner layer computed-torque, link masses/inertias ±10 %, payload 0-1 % of the link mass at the flange'
>>> applies_to(2), applies_to(6)
(False, True)
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace

__all__ = ["DefaultTask", "DEFAULT_TASK", "MIN_JOINTS", "applies_to", "default_task_domain", "default_task_robot"]

#: Robots with at least this many joints get :data:`DEFAULT_TASK` when no domain is given.
MIN_JOINTS = 3


@dataclass(frozen=True)
class DefaultTask:
    """The stated task of an arm: radius around the reference pose, rate bounds, inner layer, model error.

    Attributes
    ----------
    q_radius : float
        rad around the reference pose (clipped to the joint limits).
    qdot_max : float
        rad/s on every joint.
    qddot_max : float
        rad/s^2 on every joint.
    inner : str
        The inner layer (:data:`polyrob.model.inner.INNER_LAYERS`).
    model_error : float
        The true link masses/inertias are the model's times ``1 -+ model_error``.
    payload_fraction : float
        The payload at the flange ranges from 0 to this fraction of the
        arm's total link mass (0: none).

    The weights are the automatic ones of the task
    (:func:`polyrob.fleet.automatic_hyperparameters`), and the synthesis of a
    computed-torque loop starts from a per-joint PID tuned to them
    (:func:`polyrob.pipeline.design.with_default_start`).
    """

    q_radius: float = 0.2
    qdot_max: float = 0.5
    qddot_max: float = 2.0
    inner: str = "computed-torque"
    model_error: float = 0.10
    payload_fraction: float = 0.01

    def payload_range(self, robot):
        """The :class:`~polyrob.model.payload.PayloadRange` of ``robot`` (a URDF robot), or ``None``.

        The mass scales with the arm (an instrument of a few hundred grams on
        a 17 kg arm, tens of grams on a hobby arm); the centre of mass sits
        at the flange, so the payload moves the model by one scalar.
        """
        if not self.payload_fraction:
            return None
        from polyrob.model.payload import PayloadRange

        mass = self.payload_fraction * sum(float(Y.mass) for Y in robot.model.inertias[1:])
        return PayloadRange(0.0, mass).at(robot)

    def with_inner(self, inner: str | None) -> DefaultTask:
        """The same task behind the inner layer ``inner`` (``None``: this task's own).

        Examples
        --------
        >>> DEFAULT_TASK.with_inner("gravity").inner, DEFAULT_TASK.with_inner(None) is DEFAULT_TASK
        ('gravity', True)
        """
        return self if inner is None else replace(self, inner=inner)

    def payload_option(self, robot) -> str | None:
        """:meth:`payload_range` as the ``--payload-mass`` option's ``LO:HI`` (``None``: no payload)."""
        payload = self.payload_range(robot)
        return None if payload is None else f"{payload.mass_lower!r}:{payload.mass_upper!r}"

    def to_dict(self) -> dict:
        return dict(asdict(self), bound_options=self.bound_options)

    @property
    def bound_options(self) -> dict:
        """Search effort of :func:`polyrob.bound_pldi` over this task (a user's options win).

        The task is small (``±q_radius``) and its Jacobians smooth, so one
        local search per direction from the best sampled point, no dense
        screens and one verification round find the extremes; the PLDI's
        coverage is then measured on 2000 fresh points of the domain (and
        the uncertainty model's on its own), so a missed extreme shows as a
        coverage below 1 and no certificate, never as a wider claim.
        """
        return {"screen": 0, "starts_per_direction": 1, "verify_rounds": 1, "coverage": 2000}

    def words(self) -> str:
        """The task in one line (what ``synth`` prints when it poses it)."""
        return (
            f"task ±{self.q_radius:g} rad around the reference pose, |qdot| <= {self.qdot_max:g} rad/s, "
            f"|qddot| <= {self.qddot_max:g} rad/s^2, inner layer {self.inner}"
            + (f", link masses/inertias ±{100 * self.model_error:g} %" if self.model_error else "")
            + (
                f", payload 0-{100 * self.payload_fraction:g} % of the link mass at the flange"
                if self.payload_fraction
                else ""
            )
        )


#: The default task of every arm of :data:`MIN_JOINTS` joints or more.
DEFAULT_TASK = DefaultTask()


def applies_to(m: int) -> bool:
    """Whether a robot of ``m`` joints gets the default task when no domain is given."""
    return int(m) >= MIN_JOINTS


def default_task_robot(robot, task: DefaultTask = DEFAULT_TASK):
    """``robot`` closed by the task's inner layer (with its model error and payload), or ``robot`` itself."""
    payload = task.payload_range(robot)
    if task.inner == "none" and not task.model_error and payload is None:
        return robot
    from polyrob.model.inner import inner_loop

    return inner_loop(robot, task.inner, payload=payload, model_error=task.model_error)


def default_task_domain(robot, task: DefaultTask = DEFAULT_TASK):
    """The task domain of ``task`` around ``robot``'s reference pose (SRDF first pose, else the midpoint)."""
    from polyrob.domains.task import TaskDomain

    return TaskDomain.from_robot(robot, q_radius=task.q_radius, qdot_max=task.qdot_max, qddot_max=task.qddot_max)
