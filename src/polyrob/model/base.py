"""The robot interface every model offers: joints, limits, ``f(x, u)`` and its Jacobians.

:class:`Manipulator` is the base class of URDF robots
(:class:`polyrob.model.urdf.Robot`) and analytic ones
(:class:`polyrob.model.analytic.AnalyticRobot`); it lives in its own module so
that neither of those imports the other.
"""

from __future__ import annotations

import numpy as np

__all__ = ["Manipulator", "none_if_not_finite"]


class Manipulator:
    """What every robot model offers: joints, limits, ``f(x, u)`` and its Jacobians.

    Subclasses fill the attributes below and implement :meth:`mass_matrix`,
    :meth:`acceleration` and :meth:`jacobians_batch`; the rest is shared.

    Attributes
    ----------
    name : str
    source : str
        Where the model came from (a path, or a description).
    joint_names : tuple of str
    joint_kinds : tuple of str
        ``"revolute"``, ``"continuous"`` (angle is the coordinate) or ``"prismatic"``.
    position_lower, position_upper, velocity_limit, effort_limit : ndarray
        Limits as the model states them, NaN where it gives none.
    damping : ndarray
        Viscous damping per joint (the diagonal of ``D``).
    locked : tuple of str
        Joints of the source locked at their neutral position (not in ``joint_names``).
    notes : tuple of str
        What the model leaves out that a user must know (e.g. a mimic joint locked).
    reflected_inertia : str
        Whether the rotors' reflected inertia (armature) is in ``M(q)``, and from where.
    reference_poses : dict
        Named poses ``name -> tuple of m values`` (from the robot's SRDF).
    """

    name: str
    source: str
    joint_names: tuple[str, ...]
    joint_kinds: tuple[str, ...]
    position_lower: np.ndarray
    position_upper: np.ndarray
    velocity_limit: np.ndarray
    effort_limit: np.ndarray
    damping: np.ndarray
    locked: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()
    reflected_inertia: str = "not modelled: an analytic M(q) is used as given"
    reference_poses: dict = {}  # noqa: RUF012 - read-only default, instances set their own

    @property
    def m(self) -> int:
        """Number of actuated joints (the state has ``2 m`` entries)."""
        return len(self.joint_names)

    @property
    def state_names(self) -> tuple[str, ...]:
        return tuple(f"q_{n}" for n in self.joint_names) + tuple(f"qdot_{n}" for n in self.joint_names)

    def mass_matrix(self, q) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def acceleration(self, q, qdot, u) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def inverse_dynamics(self, q, qdot, qddot):  # pragma: no cover - abstract
        raise NotImplementedError

    def jacobians_batch(self, q, qdot, u):  # pragma: no cover - abstract
        raise NotImplementedError

    def f(self, x, u) -> np.ndarray:
        """State derivative ``xdot = f(x, u)`` with ``x = (q, qdot)``."""
        x = np.asarray(x, dtype=float)
        m = self.m
        return np.concatenate([x[m:], self.acceleration(x[:m], x[m:], u)])

    def jacobians(self, q, qdot, u) -> tuple[np.ndarray, np.ndarray]:
        """``A = df/dx`` (2m x 2m) and ``B = df/du`` (2m x m) at one point."""
        A, B = self.jacobians_batch(np.atleast_2d(q), np.atleast_2d(qdot), np.atleast_2d(u))
        return A[0], B[0]

    def describe(self) -> dict:
        """Joints and limits as plain data (for ``polyrob info --json``)."""
        return {
            "name": self.name,
            "source": self.source,
            "m": self.m,
            "locked": list(self.locked),
            "notes": list(self.notes),
            "reflected_inertia": self.reflected_inertia,
            "armature": [float(a) for a in getattr(self, "armature", np.zeros(self.m))],
            "poses": {k: list(v) for k, v in self.reference_poses.items()},
            "joints": [
                {
                    "name": n,
                    "kind": k,
                    "position": [none_if_not_finite(lo), none_if_not_finite(hi)],
                    "velocity": none_if_not_finite(v),
                    "effort": none_if_not_finite(e),
                    "damping": float(d),
                }
                for n, k, lo, hi, v, e, d in zip(
                    self.joint_names,
                    self.joint_kinds,
                    self.position_lower,
                    self.position_upper,
                    self.velocity_limit,
                    self.effort_limit,
                    self.damping,
                )
            ],
        }


def none_if_not_finite(x):
    """``None`` for NaN/inf (JSON has no NaN), else the float."""
    return None if not np.isfinite(x) else float(x)
