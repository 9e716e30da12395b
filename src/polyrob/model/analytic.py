"""Manipulators given analytically: ``M(q)``, ``C(q, qdot)``, ``g(q)`` and ``D``.

The paper's eq. (1) is the generic m-link model
``M(q) qddot + C(q, qdot) qdot + D qdot + g(q) = u``.  Some published models
(the paper's own 2R, whose printed Coriolis matrix is not the physical one)
exist only as formulas, so polyrob accepts them as Python callables and
differentiates them by the complex-step method: ``df/dx_k = Im f(x + i h e_k) / h``
is exact to rounding for real-analytic ``f`` (no subtractive cancellation,
unlike finite differences), and needs nothing of the user but numpy code that
also works on complex arrays.

The callables are vectorised: ``q`` and ``qdot`` have shape (n, m) and
``M``, ``C`` return (n, m, m), ``g`` returns (n, m).

Examples
--------
>>> from polyrob import load_robot
>>> robot = load_robot("paper_2r")
>>> A, B = robot.jacobians([0.0, 1.0], [1.0, 0.0], [0.0, 0.0])
>>> A[2:, 2:].round(4)
array([[ 0.3875,  0.    ],
       [-1.2886,  0.    ]])
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from polyrob.errors import RobotError
from polyrob.model.base import Manipulator

__all__ = ["AnalyticRobot", "paper_2r", "ANALYTIC_ROBOTS", "PAPER_2R_PARAMETERS"]

#: Step of the complex-step derivative: far below rounding of the real part.
_COMPLEX_STEP = 1e-30


@dataclass(frozen=True, eq=False)
class AnalyticRobot(Manipulator):
    """A manipulator given by vectorised callables ``M``, ``C``, ``g`` and damping ``D``.

    Parameters
    ----------
    name : str
    joint_names : tuple of str
    M : callable
        ``M(q) -> (n, m, m)`` inertia matrices for ``q`` of shape (n, m).
    C : callable
        ``C(q, qdot) -> (n, m, m)`` so that ``C(q, qdot) @ qdot`` is the
        Coriolis/centrifugal torque.
    g : callable or None
        ``g(q) -> (n, m)`` gravity torque; None means ``g = 0``.
    damping : array_like
        Diagonal of ``D``.
    position_lower, position_upper, velocity_limit, effort_limit : array_like
        Limits (NaN where the model gives none).
    named_domains : dict
        Domains known by name (``Domain.from_robot(robot, "paper")``); the one
        named by ``default_domain`` is used when no domain is given.
    """

    name: str
    joint_names: tuple[str, ...]
    M: Callable = field(repr=False)
    C: Callable = field(repr=False)
    g: Callable | None = field(default=None, repr=False)
    damping: np.ndarray = field(default=None, repr=False)
    position_lower: np.ndarray = field(default=None, repr=False)
    position_upper: np.ndarray = field(default=None, repr=False)
    velocity_limit: np.ndarray = field(default=None, repr=False)
    effort_limit: np.ndarray = field(default=None, repr=False)
    source: str = "analytic"
    named_domains: dict = field(default_factory=dict, repr=False)
    default_domain: str | None = None

    def __post_init__(self):
        m = len(self.joint_names)

        def vec(value, default):
            arr = np.full(m, default, dtype=float) if value is None else np.asarray(value, float)
            if arr.shape != (m,):
                raise RobotError(f"{self.name}: expected {m} values per joint, got shape {arr.shape}")
            return arr

        object.__setattr__(self, "joint_names", tuple(self.joint_names))
        object.__setattr__(self, "damping", vec(self.damping, 0.0))
        for attr in ("position_lower", "position_upper", "velocity_limit", "effort_limit"):
            object.__setattr__(self, attr, vec(getattr(self, attr), np.nan))

    @property
    def joint_kinds(self) -> tuple[str, ...]:
        return ("revolute",) * self.m

    def mass_matrix(self, q) -> np.ndarray:
        """``M(q)`` at one configuration."""
        return np.asarray(self.M(np.atleast_2d(np.asarray(q, float))))[0]

    def _acceleration(self, q, qdot, u):
        """Vectorised ``qddot``; works on complex arrays for the complex step."""
        n, m = q.shape
        bias = np.einsum("nij,nj->ni", self.C(q, qdot), qdot) + self.damping * qdot
        if self.g is not None:
            bias = bias + self.g(q)
        return np.linalg.solve(self.M(q), (u - bias)[..., None])[..., 0]

    def acceleration(self, q, qdot, u) -> np.ndarray:
        """``qddot = M(q)^-1 (u - C(q, qdot) qdot - g(q) - D qdot)`` at one point."""
        args = [np.atleast_2d(np.asarray(a, float)) for a in (q, qdot, u)]
        return self._acceleration(*args)[0]

    def inverse_dynamics(self, q, qdot, qddot) -> np.ndarray:
        """``u = M(q) qddot + C(q, qdot) qdot + g(q) + D qdot`` at ``n`` points (n, m)."""
        q, qdot, qddot = (np.atleast_2d(np.asarray(a, float)) for a in (q, qdot, qddot))
        u = np.einsum("nij,nj->ni", self.M(q), qddot) + np.einsum("nij,nj->ni", self.C(q, qdot), qdot)
        u = u + self.damping * qdot
        return u + self.g(q) if self.g is not None else u

    def jacobians_batch(self, q, qdot, u):
        """``A`` (n, 2m, 2m) and ``B`` (n, 2m, m) by the complex step, vectorised."""
        q, qdot, u = (np.atleast_2d(np.asarray(a, float)) for a in (q, qdot, u))
        n, m = q.shape
        qdot = np.broadcast_to(qdot, (n, m))
        u = np.broadcast_to(u, (n, m))
        # One complex evaluation per direction of (q, qdot, u), all at once.
        z = np.concatenate([q, qdot, u], axis=1).astype(complex)
        z = np.repeat(z[:, None, :], 3 * m, axis=1)
        z[:, np.arange(3 * m), np.arange(3 * m)] += 1j * _COMPLEX_STEP
        z = z.reshape(n * 3 * m, 3 * m)
        acc = self._acceleration(z[:, :m], z[:, m : 2 * m], z[:, 2 * m :])
        d = (acc.imag / _COMPLEX_STEP).reshape(n, 3 * m, m).transpose(0, 2, 1)
        A = np.zeros((n, 2 * m, 2 * m))
        A[:, :m, m:] = np.eye(m)
        A[:, m:, :] = d[:, :, : 2 * m]
        B = np.zeros((n, 2 * m, m))
        B[:, m:, :] = d[:, :, 2 * m :]
        return A, B


#: The paper's parameters of its 2R arm (section 3).
PAPER_2R_PARAMETERS = {"a1": 48.125, "a2": 13.125, "a3": 6.25}


def paper_2r() -> AnalyticRobot:
    """The paper's 2R arm with its *printed* Coriolis matrix.

    ``C = a3 sin q2 [[-qdot2, qdot1 + qdot2], [qdot1, 0]]`` as printed differs
    from the physical ``C = a3 sin q2 [[-qdot2, -(qdot1 + qdot2)], [qdot1, 0]]``
    (the sign of ``C12``); the paper's A intervals follow the printed one, so
    this model reproduces them (see ``docs/paper_2r.md``).  The physical arm
    is the bundled URDF ``planar_2r``.
    """
    a1, a2, a3 = (PAPER_2R_PARAMETERS[k] for k in ("a1", "a2", "a3"))
    # module-level functions with bound parameters: the robot pickles (worker processes)
    M = functools.partial(_paper_2r_mass, a1, a2, a3)
    C = functools.partial(_paper_2r_coriolis, a3)

    pi = np.pi
    return AnalyticRobot(
        name="paper_2r",
        joint_names=("joint1", "joint2"),
        M=M,
        C=C,
        g=None,
        damping=[0.0, 0.0],
        position_lower=[-pi, -pi],
        position_upper=[pi, pi],
        velocity_limit=[4.0, 10.0],
        effort_limit=[np.nan, np.nan],
        source="Mihaly et al., Continuous-Time Robust Control for Cancer Treatment Robots, sec. 3",
        named_domains={"paper": PAPER_DOMAIN},
        default_domain="paper",
    )


def _paper_2r_mass(a1, a2, a3, q):
    c = np.cos(q[:, 1])
    out = np.empty(q.shape[:1] + (2, 2), dtype=np.result_type(q, float))
    out[:, 0, 0] = a1 + 2 * a3 * c
    out[:, 0, 1] = out[:, 1, 0] = a2 + a3 * c
    out[:, 1, 1] = a2
    return out


def _paper_2r_coriolis(a3, q, qdot):
    """The printed ``C`` (see :func:`paper_2r`)."""
    s = a3 * np.sin(q[:, 1])
    out = np.zeros(q.shape[:1] + (2, 2), dtype=np.result_type(q, qdot, float))
    out[:, 0, 0] = -s * qdot[:, 1]
    out[:, 0, 1] = s * (qdot[:, 0] + qdot[:, 1])
    out[:, 1, 0] = s * qdot[:, 0]
    return out


#: The domain that reproduces the paper's A and B intervals best (see
#: docs/paper_2r.md): the paper prints no velocity or torque box.
PAPER_DOMAIN = {
    "q": [[-np.pi, np.pi], [-np.pi, np.pi]],
    # fitted by scripts/fit_paper_domain.py (output: docs/paper_2r_fit.json)
    "qdot": [[-3.9564, 3.9564], [-9.9561, 9.9561]],
    "u": [[0.0, 0.0], [0.0, 0.0]],
}

ANALYTIC_ROBOTS = {"paper_2r": paper_2r}
