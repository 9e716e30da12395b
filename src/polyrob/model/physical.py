"""Physical consistency of a robot's inertial data, checked when it is loaded.

A URDF can state a negative mass, an inertia tensor that is not positive
semidefinite or whose principal moments violate the triangle inequality
(``I_a + I_b >= I_c``, which every real body satisfies), or leave a joint
moving no inertia at all.  Pinocchio accepts all of them; the dynamics then
hold ``nan`` or a mass matrix with the wrong sign, and every bound computed
from them is meaningless.  These checks refuse such robots with one line
that names the link (or joint) and the offending value.

Massless frames (mass 0 and inertia 0, as the ``tool0`` or ``ee_link`` of
most arms) are accepted: they carry nothing.  Whether every joint still
moves some inertia is checked on the assembled model instead
(:func:`check_mass_matrix`).

Examples
--------
>>> import numpy as np
>>> check_link_inertia("robot.urdf", "l2", 1.0, np.diag([1.0, 1.0, -10.0]))
Traceback (most recent call last):
...
polyrob.errors.RobotError: robot.urdf: link 'l2' has an inertia that is not positive semidefinite (principal moments -10, 1, 1): fix its <inertia>
"""

from __future__ import annotations

import numpy as np
import pinocchio

from polyrob.errors import RobotError

__all__ = ["check_link_inertia", "check_urdf_links", "check_mass_matrix", "TRIANGLE_RTOL"]

#: Relative slack of the triangle inequality and of semidefiniteness: URDFs
#: print moments to a few digits, so a thin rod's ``I_a + I_b = I_c`` may miss
#: by rounding.
TRIANGLE_RTOL = 1e-6
#: ``M(q)`` counts as singular when its smallest eigenvalue is below this
#: fraction of its largest.
MASS_MATRIX_RTOL = 1e-12


def check_link_inertia(path, link: str, mass, inertia) -> None:
    """Refuse a link whose mass or inertia tensor is not physical.

    Parameters
    ----------
    path : str or Path
        The URDF file (named in the message).
    link : str
    mass : float
    inertia : array_like (3, 3)
        The rotational inertia about the centre of mass.

    Raises
    ------
    RobotError
        Negative or non-finite mass; zero mass with a non-zero inertia; an
        inertia that is not symmetric positive semidefinite, or whose
        principal moments violate the triangle inequality.
    """
    mass = float(mass)
    inertia = np.asarray(inertia, dtype=float).reshape(3, 3)
    where = f"{path}: link '{link}'"
    if not np.isfinite(mass) or mass < 0:
        raise RobotError(f"{where} has mass {mass:g}: a mass must be >= 0 (0 only for a massless frame)")
    if not np.all(np.isfinite(inertia)):
        raise RobotError(f"{where} has a non-finite inertia: fix its <inertia>")
    scale = np.abs(inertia).max()
    if mass == 0 and scale > 0:
        raise RobotError(f"{where} has mass 0 but a non-zero inertia (largest entry {scale:g}): give its mass")
    if scale == 0:
        return
    moments = np.linalg.eigvalsh(0.5 * (inertia + inertia.T))
    text = ", ".join(f"{x:.6g}" for x in moments)
    if moments[0] < -TRIANGLE_RTOL * scale:
        raise RobotError(
            f"{where} has an inertia that is not positive semidefinite (principal moments {text}): fix its <inertia>"
        )
    if moments[0] + moments[1] < moments[2] - TRIANGLE_RTOL * scale:
        raise RobotError(
            f"{where} has principal moments of inertia {text} that violate the triangle inequality "
            "(the two smaller must add up to at least the largest): fix its <inertia>"
        )


def check_urdf_links(path, links) -> None:
    """:func:`check_link_inertia` on every link of a parsed URDF (yourdfpy links)."""
    for link in links:
        inertial = link.inertial
        if inertial is None:
            continue
        mass = 0.0 if inertial.mass is None else inertial.mass
        inertia = np.zeros((3, 3)) if inertial.inertia is None else inertial.inertia
        check_link_inertia(path, link.name, mass, inertia)


def check_mass_matrix(path, model: pinocchio.Model, n_configurations: int = 8, seed: int = 0) -> None:
    """Refuse a model whose ``M(q)`` is singular: some joint moves no inertia.

    ``M(q)`` is evaluated at the neutral configuration and at a few random
    ones (within the position limits where they are finite).  With physical
    links (:func:`check_link_inertia`) it is positive semidefinite, and it is
    singular only when the links behind a joint carry no inertia about it.

    Raises
    ------
    RobotError
        Naming the joint whose diagonal entry vanishes and the massless
        links it moves.
    """
    data = model.createData()
    rng = np.random.default_rng(seed)
    for n in range(n_configurations):
        q = pinocchio.neutral(model)
        for i in range(1, model.njoints) if n else ():
            joint = model.joints[i]
            lo, hi = model.lowerPositionLimit[joint.idx_q], model.upperPositionLimit[joint.idx_q]
            if joint.nq == 2:  # continuous: (cos, sin) of an angle
                angle = rng.uniform(-np.pi, np.pi)
                q[joint.idx_q : joint.idx_q + 2] = np.cos(angle), np.sin(angle)
            else:
                finite = np.isfinite(lo) and np.isfinite(hi) and lo < hi
                q[joint.idx_q] = rng.uniform(lo, hi) if finite else rng.uniform(-np.pi, np.pi)
        M = pinocchio.crba(model, data, q)
        M = np.triu(M) + np.triu(M, 1).T
        if not np.all(np.isfinite(M)):
            raise RobotError(f"{path}: the mass matrix has non-finite entries: check the links' <inertial> data")
        eig = np.linalg.eigvalsh(M)
        if eig[0] > MASS_MATRIX_RTOL * max(eig[-1], 1e-300):
            continue
        j = int(np.argmin(np.diag(M)))
        joint_id = j + 1
        moved = [f.name for f in model.frames if f.type == pinocchio.FrameType.BODY and f.parentJoint >= joint_id]
        raise RobotError(
            f"{path}: joint '{model.names[joint_id]}' moves no inertia (M(q) is singular, smallest "
            f"eigenvalue {eig[0]:.3g}): the links it carries ({', '.join(moved) or 'none'}) have zero mass "
            "and inertia; give them their <inertial> data or lock the joint"
        )
