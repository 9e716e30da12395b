"""Proved ranges of the factors of a computed-torque inner loop over an arm's task box (5-7 joints).

:mod:`~polyrob.bounds.certified.factors.ranges` (the factors, one box's
enclosure) and :mod:`~polyrob.bounds.certified.factors.proof` (the branch
and bound over the task, its checkpoints), with the forms it intersects on a box
(:mod:`~polyrob.bounds.certified.factors.slope_form`,
:mod:`~polyrob.bounds.certified.factors.taylor2`) and how tightness is
measured (:mod:`~polyrob.bounds.certified.factors.width_ratio`); the values
attained that steer it (:mod:`~polyrob.bounds.certified.factors.attained`),
the faces a monotone side needs (:mod:`~polyrob.bounds.certified.factors.monotone`)
and the scalars proved (:mod:`~polyrob.bounds.certified.factors.directions`).
"""

from polyrob.bounds.certified.factors.attained import attained_range, vertex_ascent
from polyrob.bounds.certified.factors.directions import Direction, factor_directions
from polyrob.bounds.certified.factors.proof import (
    BATCH,
    MAX_BOXES,
    REL_TOL,
    FactorEnclosure,
    prove_factor_ranges,
)
from polyrob.bounds.certified.factors.ranges import FactorProblem

__all__ = [
    "FactorProblem",
    "FactorEnclosure",
    "Direction",
    "prove_factor_ranges",
    "attained_range",
    "vertex_ascent",
    "factor_directions",
    "MAX_BOXES",
    "REL_TOL",
    "BATCH",
]
