"""A task domain: a region around a reference pose, velocity and acceleration bounds, torques by inverse dynamics.

The torque box of :class:`~polyrob.domains.torque_box.Domain` holds every torque
the motors can give, at every position and velocity: far more than a task
asks of the robot.  A task domain bounds what the trajectories do instead::

    |q - q_ref| <= q_radius (within the joint limits),  |qdot| <= qdot_max,  |qddot| <= qddot_max

and the torque is the one that makes the robot move so, ``u = rnea(q, qdot,
qddot) + D qdot`` (inverse dynamics).  The Jacobians ``A = df/dx``,
``B = df/du`` are still those of the forward dynamics, taken at
``(q, qdot, u)``; their set over the task domain is exactly the set the
robot reaches on trajectories that respect the bounds.

For a fixed ``q`` every entry is a polynomial in ``(qdot, qddot)`` of the
same shape as in ``(qdot, u)`` (``u`` is affine in ``qddot`` and quadratic
in ``qdot``), so the bounds search (:mod:`polyrob.bounds.search`) runs
unchanged on the box ``(q, qdot, qddot)``: it evaluates the Jacobians
through :meth:`TaskDomain.inputs`.  :meth:`TaskDomain.sample` gives the
points ``(q, qdot, u)`` as :meth:`Domain.sample` does, so coverage checks
and every other user of the domain's points stay right.

The reference pose is one of the robot's SRDF poses (``default``, ``home``,
``half_sitting``; :attr:`~polyrob.model.base.Manipulator.reference_poses`),
given positions, or, with neither, the midpoint of the joint ranges.  A
task domain's bounds are sampled (``enclosure = "sampled"``): no
interval-arithmetic proof covers the inverse dynamics.

Examples
--------
>>> from polyrob import load_robot
>>> robot = load_robot("planar_2r")
>>> dom = TaskDomain.from_robot(robot, pose=[0.5, 1.0], q_radius=0.2, qdot_max=0.5, qddot_max=2.0)
>>> dom.q_lower.round(3).tolist(), dom.qddot_upper.tolist()
([0.3, 0.8], [2.0, 2.0])
>>> q, qdot, u = dom.sample(4, seed=0)
>>> bool(abs(robot.acceleration(q[0], qdot[0], u[0])).max() <= 2.0 + 1e-9)
True
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace

import numpy as np

from polyrob.domains.joint_box import JointBox
from polyrob.domains.spec import box_from_dict, joint_range
from polyrob.domains.torque_box import Domain, unit_design
from polyrob.errors import DomainError

__all__ = ["TaskDomain", "domain_from_dict"]

_BOX = ("q", "qdot", "qddot")


@dataclass(frozen=True, eq=False)
class TaskDomain(JointBox):
    """The box ``(q, qdot, qddot)`` around a reference pose; torques ``u = rnea(q, qdot, qddot) + D qdot``.

    Build it with :meth:`from_robot`.

    Attributes
    ----------
    joint_names : tuple of str
    pose : ndarray (m,)
        The reference pose.
    pose_source : str
        Where the pose comes from (``"SRDF pose 'default'"``, ``"given"``,
        ``"midpoint of the joint ranges"``).
    q_radius : float or None
        ``None``: the whole joint range.
    q_lower, q_upper, qdot_lower, qdot_upper, qddot_lower, qddot_upper : ndarray (m,)
    robot : Manipulator
        Whose inverse dynamics map accelerations to torques (not written by
        :meth:`to_dict`; :func:`domain_from_dict` loads it again).
    """

    joint_names: tuple[str, ...]
    pose: np.ndarray
    pose_source: str
    q_radius: float | None
    q_lower: np.ndarray
    q_upper: np.ndarray
    qdot_lower: np.ndarray
    qdot_upper: np.ndarray
    qddot_lower: np.ndarray
    qddot_upper: np.ndarray
    robot: object = field(default=None, repr=False)
    name: str = "task"
    _torques: list = field(default_factory=list, init=False, repr=False)

    kind = "task"
    _third = "qddot"  # JointBox views over (q, qdot, qddot)

    def __post_init__(self):
        object.__setattr__(self, "joint_names", tuple(self.joint_names))
        m = len(self.joint_names)
        for attr in ("pose", *(f"{g}_{s}" for g in _BOX for s in ("lower", "upper"))):
            arr = np.array(getattr(self, attr), dtype=float).reshape(-1)
            if arr.shape != (m,) or not np.all(np.isfinite(arr)):
                raise DomainError(f"task domain: {attr} must be {m} finite numbers, got {arr.tolist()}")
            arr.setflags(write=False)
            object.__setattr__(self, attr, arr)
        for g in _BOX:
            lo, hi = getattr(self, f"{g}_lower"), getattr(self, f"{g}_upper")
            if np.any(lo > hi):
                j = int(np.argmax(lo > hi))
                raise DomainError(f"task domain: joint '{self.joint_names[j]}' has an empty {g} range")

    # ------------------------------------------------------------------ views: JointBox's, over (q, qdot, qddot)

    split = Domain.split

    def contains(self, q, qdot, qddot, *, atol: float = 0.0) -> np.ndarray:
        """Whether points ``(q, qdot, qddot)`` (arrays (n, m)) lie in the box."""
        z = np.concatenate([np.atleast_2d(q), np.atleast_2d(qdot), np.atleast_2d(qddot)], axis=1)
        return np.all((z >= self.lower - atol) & (z <= self.upper + atol), axis=1)

    def scaled(self, factor: float) -> TaskDomain:
        """The task with every range (``q``, ``qdot``, ``qddot``) scaled by ``factor`` about its midpoint.

        Examples
        --------
        >>> from polyrob import load_robot
        >>> task = TaskDomain.from_robot(load_robot("ur5"), q_radius=0.2, qdot_max=0.5, qddot_max=2.0)
        >>> small = task.scaled(0.1)
        >>> float(small.qdot_upper[0]), round(float(small.q_upper[1] - small.q_lower[1]), 6)
        (0.05, 0.04)
        """
        out = {}
        for g in _BOX:
            lo, hi = getattr(self, f"{g}_lower"), getattr(self, f"{g}_upper")
            mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
            out[f"{g}_lower"], out[f"{g}_upper"] = mid - factor * half, mid + factor * half
        radius = None if self.q_radius is None else factor * self.q_radius
        return replace(self, q_radius=radius, **out)

    # ------------------------------------------------------------------ the map to the dynamics
    def inputs(self, q, qdot, qddot) -> np.ndarray:
        """The torques ``u = rnea(q, qdot, qddot) + D qdot`` (n, m) that give these accelerations."""
        if self.robot is None:
            raise DomainError("task domain: no robot to map accelerations to torques (build it with from_robot)")
        return self.robot.inverse_dynamics(q, qdot, qddot)

    points = Domain.points

    def sample_box(self, n: int, *, method: str = "sobol", seed=None, groups=_BOX) -> np.ndarray:
        """``n`` points of the box ``(q, qdot, qddot)``, stacked (n, 3m)."""
        lo, hi = self.lower, self.upper
        vary = np.concatenate([np.full(self.m, g in groups) for g in _BOX]) & (hi > lo)
        z = np.tile(0.5 * (lo + hi), (n, 1))
        if vary.any():
            z[:, vary] = lo[vary] + unit_design(n, int(vary.sum()), method, seed) * (hi[vary] - lo[vary])
        return z

    def sample(self, n: int, *, method: str = "sobol", seed=None, groups=_BOX):
        """``n`` points ``(q, qdot, u)`` (each (n, m)) with ``u`` the inverse dynamics of a box point."""
        q, qdot, w = self.split(self.sample_box(n, method=method, seed=seed, groups=groups))
        return q, qdot, self.inputs(q, qdot, w)

    @property
    def u_lower(self) -> np.ndarray:
        """Smallest torque per joint over 4096 sampled points of the box (what the task asks of the motors)."""
        return self._torque_range()[0]

    @property
    def u_upper(self) -> np.ndarray:
        """Largest torque per joint over 4096 sampled points of the box."""
        return self._torque_range()[1]

    def _torque_range(self):
        if not self._torques:
            u = self.sample(4096, seed=0)[2]
            self._torques.extend([u.min(axis=0), u.max(axis=0)])
        return self._torques

    # ------------------------------------------------------------------ building
    @classmethod
    def from_robot(cls, robot, *, pose=None, q_radius=None, qdot_max=None, qddot_max=None) -> TaskDomain:
        """The task domain of ``robot`` around a pose.

        Parameters
        ----------
        robot : Manipulator
        pose : str or sequence of m floats, optional
            A name of ``robot.reference_poses`` (from its SRDF) or positions.
            Default: the SRDF's first pose, else the midpoint of the joint ranges.
        q_radius : float, optional
            Half-width of the position region around the pose (intersected
            with the joint limits); default: the whole joint range.
        qdot_max : float, (lo, hi) or mapping joint -> either, optional
            As :meth:`Domain.from_robot` takes it; default: the velocity limits.
        qddot_max : float, sequence of m floats or mapping joint -> float
            Acceleration bound (required: a URDF states none).

        Raises
        ------
        DomainError
            An unknown pose name (the message lists the robot's), a pose of
            the wrong length or outside the joint limits, a negative or
            non-finite radius or bound, or no acceleration bound.
        """
        box = Domain.from_robot(robot, qdot_max=qdot_max, u_max=0.0)
        names = robot.joint_names
        poses = dict(getattr(robot, "reference_poses", {}) or {})
        mid = 0.5 * (box.q_lower + box.q_upper)
        if pose is None:
            first = next(iter(poses), None)
            pose, source = (mid, "midpoint of the joint ranges") if first is None else (poses[first], first)
            source = source if first is None else f"SRDF pose '{first}'"
        elif isinstance(pose, str):
            if pose not in poses:
                known = ", ".join(poses) or "none (no SRDF pose for this robot; give q1,q2,...)"
                raise DomainError(f"--pose: unknown pose '{pose}' of {robot.name} (poses: {known})")
            pose, source = poses[pose], f"SRDF pose '{pose}'"
        else:
            source = None  # named by its values once checked
        pose = np.asarray(pose, dtype=float).reshape(-1)
        if pose.shape != (len(names),) or not np.all(np.isfinite(pose)):
            raise DomainError(f"--pose: give {len(names)} finite positions (one per joint), got {pose.tolist()}")
        if source is None:
            source = "q = (" + ", ".join(f"{x:.4g}" for x in pose) + ")"
        # an SRDF pose may name a revolute angle a whole turn away (kinova: -pi/2 for a joint ranging over
        # [0.33, 5.95]): the same configuration; a pose given by the user must be inside as given
        srdf = source.startswith("SRDF pose")
        kinds = getattr(robot, "joint_kinds", ()) if srdf else ()
        pose, wrapped = _wrapped_into_range(pose, box.q_lower, box.q_upper, kinds)
        if wrapped:
            source += " (" + ", ".join(f"{names[j]} + {k:+d} x 2 pi" for j, k in wrapped) + ")"
        outside = (pose < box.q_lower - 1e-9) | (pose > box.q_upper + 1e-9)
        if outside.any():
            j = int(np.argmax(outside))
            raise DomainError(
                f"--pose: joint '{names[j]}' at {pose[j]:.4g} is outside its range "
                f"[{box.q_lower[j]:.4g}, {box.q_upper[j]:.4g}]"
            )
        pose = np.clip(pose, box.q_lower, box.q_upper)
        if q_radius is not None:
            q_radius = float(q_radius)
            if not (np.isfinite(q_radius) and q_radius >= 0):
                raise DomainError(f"--q-radius: must be a finite number >= 0, got {q_radius:g}")
            q_lo, q_hi = np.maximum(box.q_lower, pose - q_radius), np.minimum(box.q_upper, pose + q_radius)
        else:
            q_lo, q_hi = box.q_lower, box.q_upper
        if qddot_max is None:
            raise DomainError("task domain: give the acceleration bound (--qddot-max, rad/s^2): a URDF states none")
        a_lo, a_hi = _per_joint(qddot_max, names, "--qddot-max")
        radius = f"q ±{q_radius:g}" if q_radius is not None else "q joint range"
        name = (
            f"task around {source}: {radius}, qdot {_words(box.qdot_lower, box.qdot_upper)}, qddot {_words(a_lo, a_hi)}"
        )
        return cls(names, pose, source, q_radius, q_lo, q_hi, box.qdot_lower, box.qdot_upper, a_lo, a_hi, robot, name)

    # ------------------------------------------------------------------ serialisation
    def to_dict(self) -> dict:
        box = {
            g: {
                n: [float(lo), float(hi)]
                for n, lo, hi in zip(self.joint_names, getattr(self, f"{g}_lower"), getattr(self, f"{g}_upper"))
            }
            for g in _BOX
        }
        return {
            "kind": "task",
            "name": self.name,
            "joints": list(self.joint_names),
            "pose": [float(x) for x in self.pose],
            "pose_source": self.pose_source,
            "q_radius": self.q_radius,
            **box,
        }

    @classmethod
    def from_dict(cls, data: Mapping, *, robot=None, source: str = "domain") -> TaskDomain:
        """The task domain :meth:`to_dict` wrote; ``robot`` maps its accelerations to torques."""
        try:
            names = tuple(data["joints"])
            arrays = box_from_dict(data, _BOX, source)
            pose = data["pose"]
        except (KeyError, TypeError) as exc:
            raise DomainError(f"{source}: not a task domain as to_dict writes it (missing {exc})") from None
        radius = data.get("q_radius")
        return cls(names, pose, data.get("pose_source", "given"), radius, *arrays, robot, data.get("name", "task"))

    def table(self) -> str:
        """A plain-text table of the box, one row per joint, and the pose."""
        rows = [f"{'joint':<24}{'pose':>9}{'q':>22}{'qdot':>20}{'qddot':>20}"]
        for j, n in enumerate(self.joint_names):
            cells = [f"[{getattr(self, g + '_lower')[j]:.4g}, {getattr(self, g + '_upper')[j]:.4g}]" for g in _BOX]
            rows.append(f"{n:<24}{self.pose[j]:>9.4g}{cells[0]:>22}{cells[1]:>20}{cells[2]:>20}")
        rows.append(f"pose: {self.pose_source}; torques u = rnea(q, qdot, qddot) + D qdot (inverse dynamics)")
        return "\n".join(rows)

    def words(self) -> str:
        """The domain in one line (a certificate's scope)."""
        radius = "the joint ranges" if self.q_radius is None else f"±{self.q_radius:g} rad"
        return (
            f"task domain around {self.pose_source} ({radius}), qdot {_words(self.qdot_lower, self.qdot_upper)}, "
            f"qddot {_words(self.qddot_lower, self.qddot_upper)}, u = inverse dynamics"
        )


def _per_joint(value, names, option):
    """``(lo, hi)`` arrays of a bound for every joint: a number, one entry per joint, or joint -> entry."""
    if isinstance(value, Mapping):
        unknown = [j for j in value if j not in names]
        missing = [j for j in names if j not in value]
        if unknown or missing:
            what = f"unknown joint(s) {', '.join(unknown)}" if unknown else f"no bound for {', '.join(missing)}"
            raise DomainError(f"{option}: {what} (give every joint of {', '.join(names)})")
        value = [value[n] for n in names]
    elif isinstance(value, str) or np.ndim(value) == 0:
        value = [value] * len(names)
    value = list(value)
    if len(value) != len(names):
        raise DomainError(f"{option}: give one bound or {len(names)} (one per joint), got {len(value)}")
    pairs = [joint_range(v, "qddot", f"{option}: joint '{n}'") for n, v in zip(names, value)]
    return np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])


def _words(lo, hi) -> str:
    if np.allclose(lo, -hi) and np.allclose(hi, hi[0]):
        return f"±{hi[0]:.3g}"
    if np.allclose(lo, -hi):
        return "±(" + ", ".join(f"{h:.3g}" for h in hi) + ")"
    return "[" + ", ".join(f"{a:.3g}:{b:.3g}" for a, b in zip(lo, hi)) + "]"


def domain_from_dict(data: Mapping, *, robot=None, source: str = "domain"):
    """A :class:`Domain` or, for ``"kind": "task"``, a :class:`TaskDomain` as ``to_dict`` wrote it."""
    if isinstance(data, Mapping) and data.get("kind") == "task":
        return TaskDomain.from_dict(data, robot=robot, source=source)
    return Domain.from_dict(data, source=source)


def _wrapped_into_range(pose, lower, upper, kinds):
    """``pose`` with each angle outside its range moved by whole turns into it (revolute joints only).

    Returns ``(pose, [(joint index, turns), ...])``; an angle that no whole
    turn brings inside is left as it is (the caller refuses it).
    """
    pose = np.array(pose, dtype=float)
    wrapped = []
    for j, kind in enumerate(kinds or ()):
        if kind not in ("revolute", "continuous") or lower[j] - 1e-9 <= pose[j] <= upper[j] + 1e-9:
            continue
        k = int(np.ceil((lower[j] - 1e-9 - pose[j]) / (2 * np.pi)))  # the fewest turns up to the lower limit
        if pose[j] + 2 * np.pi * k <= upper[j] + 1e-9:
            pose[j] += 2 * np.pi * k
            wrapped.append((j, k))
    return pose, wrapped
