"""Domains: where the robot's state (and torque, or acceleration) is assumed to stay.

The input of the bounds stage (:mod:`polyrob.bounds`): the paper's box over
``(q, qdot, u)`` (:mod:`~polyrob.domains.torque_box`), a task around a pose
over ``(q, qdot, qddot)`` (:mod:`~polyrob.domains.task`), the views they
share (:mod:`~polyrob.domains.joint_box`), how users write them
(:mod:`~polyrob.domains.spec`) and the task an arm gets when none is stated
(:mod:`~polyrob.domains.default_task`).
"""
