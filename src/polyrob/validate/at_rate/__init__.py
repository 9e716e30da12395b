"""Validation at the rate: the controller as it runs on the arm, on true robots drawn from the uncertainty set.

* :mod:`~polyrob.validate.at_rate.loop` - one run: the rate, the computation delay, encoder
  quantisation, friction the inner model does not have, the motors' saturation;
* :mod:`~polyrob.validate.at_rate.figures` - its figures: tracking error, settling, the task's
  bounds (q, qdot, qddot), torque chatter against the effort limit;
* :mod:`~polyrob.validate.at_rate.runs` - true robots drawn from the set, the step and the task's
  trajectory on each, the figures aggregated (:func:`validate_at_rate`).
"""

from polyrob.validate.at_rate.loop import RealLoopConditions, simulate_real_loop
from polyrob.validate.at_rate.runs import RateValidation, validate_at_rate

__all__ = ["RealLoopConditions", "simulate_real_loop", "RateValidation", "validate_at_rate"]
