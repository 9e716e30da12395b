"""The views every domain shares: a box over the joints' ``(q, qdot, third)``.

:class:`~polyrob.domains.torque_box.Domain` (``third`` = torques ``u``) and
:class:`~polyrob.domains.task.TaskDomain` (``third`` = accelerations
``qddot``) inherit them, so the bounds search sees one interface.
"""

from __future__ import annotations

import numpy as np

__all__ = ["JointBox"]


class JointBox:
    """The views every domain shares: a box over ``(q, qdot, third)``, ``third`` being ``u`` or ``qddot``."""

    _third = "u"  # the group after the velocities (a TaskDomain: "qddot")

    @property
    def m(self) -> int:
        return len(self.joint_names)

    @property
    def dim(self) -> int:
        """Dimension of the box over ``(q, qdot, third)``: ``3 m``."""
        return 3 * self.m

    @property
    def lower(self) -> np.ndarray:
        """Lower corner over ``(q, qdot, third)``."""
        return np.concatenate([self.q_lower, self.qdot_lower, getattr(self, f"{self._third}_lower")])

    @property
    def upper(self) -> np.ndarray:
        """Upper corner over ``(q, qdot, third)``."""
        return np.concatenate([self.q_upper, self.qdot_upper, getattr(self, f"{self._third}_upper")])

    @property
    def midpoint(self) -> np.ndarray:
        return 0.5 * (self.lower + self.upper)
