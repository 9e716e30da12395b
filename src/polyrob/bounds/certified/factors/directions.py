"""The scalars in which an arm's true robots differ from its computed-torque layer's model, for the proof.

:func:`factor_directions` builds the link factor and the payload mass of
:func:`polyrob.plant.models.inner_factors.factor_parameters` here, so that
the bounds do not import the plant (``tests/test_certified_arms.py`` checks
that the two agree); :class:`~polyrob.bounds.certified.factors.ranges.FactorProblem`
reads their directions in the inertial parameters.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from polyrob.errors import CertificationError

__all__ = ["Direction", "factor_directions"]


@dataclass(frozen=True, eq=False)
class Direction:
    """One scalar in which a true robot differs from the inner layer's model: ``theta`` and that true robot."""

    inner: str
    model_robot: object
    true_robot: object
    theta: float


def factor_directions(robot) -> list[tuple[str, Direction]]:
    """``[(name, Direction)]`` of a computed-torque inner loop (:class:`~polyrob.model.inner.InnerLoopRobot`).

    The same scalars as :func:`polyrob.plant.models.inner_factors.factor_parameters`
    (the link factor ``theta = p`` at ``s = 1 - p``; the payload mass, half
    its range above the middle), built here so that the bounds do not
    import the plant; ``tests/test_certified_arms.py`` checks that the two agree.

    Raises
    ------
    CertificationError
        A payload whose centre of mass ranges (not affine in one scalar).
    """
    payload = robot.payload
    mass, com = payload.midpoint if payload is not None else (0.0, np.zeros(3))
    if payload is not None and np.any(np.array(payload.com_upper) > np.array(payload.com_lower)):
        raise CertificationError("proved factor ranges: a payload whose centre of mass ranges is not one scalar")
    out = []
    if robot.model_error:
        p = float(robot.model_error)
        out.append(
            ("links", Direction(robot.inner, robot.model_robot, robot.with_true(mass, com, 1.0 - p).true_robot, p))
        )
    if payload is not None and payload.mass_upper > payload.mass_lower:
        r = 0.5 * (payload.mass_upper - payload.mass_lower)
        out.append(
            ("payload", Direction(robot.inner, robot.model_robot, robot.with_true(mass + r, com, 1.0).true_robot, r))
        )
    return out
