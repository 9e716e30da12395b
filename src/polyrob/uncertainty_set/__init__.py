"""The robot's uncertainty as an engineer states it, and true robots drawn inside it.

* :mod:`~polyrob.uncertainty_set.spec`: :class:`RobotUncertainty`, the robot-uncertainty file
  (per-link parameter errors, a payload body, joint friction), read, checked and written;
* :mod:`~polyrob.uncertainty_set.links`: a link's ten standard parameters, physical consistency;
* :mod:`~polyrob.uncertainty_set.payload_body`: a payload as a rigid body, vendors' rated payloads;
* :mod:`~polyrob.uncertainty_set.draw`: true robots drawn at random inside a set, and whether
  today's certified common-factor set contains one;
* :mod:`~polyrob.uncertainty_set.checks`: the file's numbers, each refusal one line.

On a computed-torque inner layer the commands carry the set with the ``inner-links`` model
(:mod:`polyrob.plant.models.inner_links`), or refuse it in one line with the measured reason.
"""

from polyrob.uncertainty_set.draw import TrueRobot, common_factor_covers, draw_true_robot, draw_true_robots
from polyrob.uncertainty_set.spec import RobotUncertainty

__all__ = ["RobotUncertainty", "TrueRobot", "draw_true_robot", "draw_true_robots", "common_factor_covers"]
