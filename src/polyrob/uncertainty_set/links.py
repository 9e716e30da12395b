"""A link's ten standard inertial parameters: which links a robot has, physical consistency, intervals, scaling.

The parameters are ``[m, mcx, mcy, mcz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]`` in the
order of Pinocchio's ``Inertia.toDynamicParameters()`` (first moment
``h = m c``; rotational inertia about the link frame's origin).  A set of
them is a rigid body when ``m > 0`` and the inertia about the centre of mass
has the triangle inequality of its principal moments
(:func:`physically_consistent`); :func:`scaled_parameters` scales ``m``,
``h`` and the inertia about the centre of mass, which keeps a rigid body one.

Examples
--------
>>> import numpy as np
>>> rod = np.array([1.0, 0.5, 0, 0, 0.0, 0, 1 / 3, 0, 0, 1 / 3])  # 1 kg, 1 m thin rod along x from the origin
>>> physically_consistent(rod), physically_consistent(scaled_parameters(rod, 1.1, 0.9, 1.1))
(True, True)
>>> physically_consistent(rod * [1, 1, 1, 1, 1, 1, 0.5, 1, 1, 1])  # Iyy below m c^2 about the origin
False
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from polyrob.uncertainty_set.checks import fail, pair

__all__ = [
    "PARAMETER_NAMES",
    "LinkInterval",
    "link_names",
    "arm_length",
    "physically_consistent",
    "scaled_parameters",
]

#: The ten standard inertial parameters of a link, in ``pinocchio.Inertia.toDynamicParameters()``'s order
#: (first moment ``m c`` and rotational inertia about the link frame's origin).
PARAMETER_NAMES = ("m", "mcx", "mcy", "mcz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")
#: Tolerance of the physical-consistency test (relative to the largest principal moment).
_PHYSICAL_TOL = 1e-9


def link_names(robot) -> dict[str, int]:
    """The links whose parameters the file may bound: ``{URDF link name: Pinocchio joint index}``.

    Pinocchio merges the links fixed to a joint into that joint's body, so a
    link is the first body frame of each actuated joint (``panda_link7``,
    not ``panda_link8`` or the hand, which ride on it).
    """
    import pinocchio

    out = {}
    for frame in robot.model.frames:
        if frame.type == pinocchio.FrameType.BODY and frame.parentJoint > 0 and frame.parentJoint not in out.values():
            out[frame.name] = int(frame.parentJoint)
    return out


def arm_length(robot) -> float:
    """The distance (m) along the chain from the first joint to the flange: nothing on the arm is farther."""
    from polyrob.model.payload import flange_frame

    model = robot.model
    hops = sum(float(np.linalg.norm(model.jointPlacements[i].translation)) for i in range(2, model.njoints))
    return hops + float(np.linalg.norm(flange_frame(robot)[1].translation))


def physically_consistent(params) -> bool:
    """Whether ten standard parameters are a rigid body: ``m > 0`` and ``I_c`` with the triangle inequality.

    ``I_c = I_O - S(h)^T S(h) / m`` is the inertia about the centre of mass;
    its principal moments ``l1 <= l2 <= l3`` must satisfy ``l1 >= 0`` and
    ``l1 + l2 >= l3`` (equivalently, the pseudo-inertia matrix is positive
    semidefinite).
    """
    p = np.asarray(params, dtype=float)
    m = p[0]
    if not (np.all(np.isfinite(p)) and m > 0):
        return False
    moments = np.linalg.eigvalsh(_inertia_about_com(p))
    tol = _PHYSICAL_TOL * max(1.0, abs(moments[-1]))
    return bool(moments[0] >= -tol and moments[0] + moments[1] >= moments[2] - tol)


def _inertia_about_com(p) -> np.ndarray:
    m, h = p[0], np.asarray(p[1:4])
    ixx, ixy, iyy, ixz, iyz, izz = p[4:10]
    inertia_origin = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    c = h / m
    return inertia_origin - m * (np.dot(c, c) * np.eye(3) - np.outer(c, c))


@dataclass(frozen=True)
class LinkInterval:
    """Intervals of one link's ten standard parameters (``lower``, ``upper``: 10 floats, :data:`PARAMETER_NAMES`)."""

    link: str
    lower: tuple
    upper: tuple

    def __post_init__(self):
        lo, hi = np.asarray(self.lower, float), np.asarray(self.upper, float)
        if lo.shape != (10,) or hi.shape != (10,):
            fail(f"links.{self.link}: give the ten parameters {', '.join(PARAMETER_NAMES)}")
        for k, name in enumerate(PARAMETER_NAMES):
            pair([lo[k], hi[k]], f"links.{self.link}.{name}", nonnegative=(name == "m"))
        object.__setattr__(self, "lower", tuple(float(v) for v in lo))
        object.__setattr__(self, "upper", tuple(float(v) for v in hi))

    @property
    def centre(self) -> np.ndarray:
        return 0.5 * (np.array(self.lower) + np.array(self.upper))

    def vertices_not_physical(self) -> int:
        """How many of the box's 1024 vertices are not a rigid body (:func:`physically_consistent`)."""
        lo, hi = np.array(self.lower), np.array(self.upper)
        bits = (np.arange(1024)[:, None] >> np.arange(10)[None, :]) & 1
        return int(sum(not physically_consistent(np.where(b, hi, lo)) for b in bits))

    def to_dict(self) -> dict:
        return {name: [a, b] for name, a, b in zip(PARAMETER_NAMES, self.lower, self.upper)}


def scaled_parameters(theta, mass_factor: float, moment_factor: float, inertia_factor: float) -> np.ndarray:
    """Ten standard parameters with ``m``, ``h = m c`` and ``I_c`` times the three factors (a rigid body stays one)."""
    theta = np.asarray(theta, float)
    m, h = theta[0], theta[1:4]
    ic = _inertia_about_com(theta)
    m2, h2 = mass_factor * m, moment_factor * h
    c2 = h2 / m2 if m2 > 0 else np.zeros(3)
    io = inertia_factor * ic + m2 * (np.dot(c2, c2) * np.eye(3) - np.outer(c2, c2))
    return np.array([m2, *h2, io[0, 0], io[0, 1], io[1, 1], io[0, 2], io[1, 2], io[2, 2]])
