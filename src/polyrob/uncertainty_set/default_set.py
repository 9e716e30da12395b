"""The set an arm engineer states when asked for none: ``--robot-uncertainty default``.

Issue 38 of the project names it, and the at-rate validation draws its true
robots from it by default:

* **each link** off by ``±10 %`` on its own (mass, first moment and inertia
  about the centre of mass, each with its own factor): a CAD model's masses
  are rarely better, and an identification reports intervals per link and
  per parameter, not one factor for the arm (Corke's ``perturb(robot, 0.1)``
  draws the same way);
* **an instrument** of 0 to 1.5 kg, capped at the vendor's rated payload
  (:data:`~polyrob.uncertainty_set.payload_body.RATED_PAYLOAD`), whose centre
  of mass lies anywhere within 0.1 m of the flange: a treatment robot changes
  instruments of 0.5-1.5 kg whose centre of mass sits 5-15 cm beyond the
  flange.  An arm whose rating polyrob does not know gets no instrument, and
  the set's source says so rather than inventing a mass;
* **friction** as the URDF's ``<dynamics>`` states it where it has them
  (:meth:`RobotUncertainty.bound` fills them in), "not stated" otherwise.

The computed-torque inner layer computes with the nominal links and the
middle of the instrument's range (:func:`polyrob.uncertainty_set.draw.model_of_set`).

Examples
--------
>>> from polyrob import load_robot
>>> default_set(load_robot("ur5")).words().split(";")[:2]
['per-link ±10 % (mass, first moment, inertia about the CoM, each link independently)', ' payload 0-1.5 kg, centre of mass within 0.1 m of the origin of tool0, solid sphere r 0.03 m']
>>> default_set(load_robot("so101")).payload is None
True
"""

from __future__ import annotations

__all__ = ["DEFAULT_SET", "DEFAULT_LINK_ERROR", "DEFAULT_PAYLOAD_KG", "DEFAULT_COM_RADIUS", "default_set"]

#: The ``--robot-uncertainty`` value that names this set instead of a file.
DEFAULT_SET = "default"
#: Each link's parameters within ``±`` this fraction, independently.
DEFAULT_LINK_ERROR = 0.10
#: The instrument's largest mass (kg), capped at the rated payload.
DEFAULT_PAYLOAD_KG = 1.5
#: The instrument's centre of mass lies within this distance (m) of the flange.
DEFAULT_COM_RADIUS = 0.1


def default_set(robot, *, link_error: float = DEFAULT_LINK_ERROR):
    """The default set of ``robot`` (a URDF robot), bound to it.

    Parameters
    ----------
    robot : Manipulator
        From :func:`polyrob.load_robot` (the arm itself, not its inner loop).
    link_error : float
        Each link's factors lie in ``[1 - link_error, 1 + link_error]``.

    Returns
    -------
    RobotUncertainty
        Bound to ``robot`` (:meth:`~polyrob.uncertainty_set.spec.RobotUncertainty.bound`).
    """
    from polyrob.uncertainty_set.payload_body import RATED_PAYLOAD, PayloadBody
    from polyrob.uncertainty_set.spec import RobotUncertainty

    rated = RATED_PAYLOAD.get(robot.name)
    payload, words = None, []
    if rated is not None and rated.kg:
        kg = min(DEFAULT_PAYLOAD_KG, rated.kg)
        payload = PayloadBody(0.0, kg, com_radius=DEFAULT_COM_RADIUS)
        words.append(
            f"an instrument of 0-{kg:g} kg (1.5 kg capped at the rated {rated.kg:g} kg: {rated.source}) "
            f"with its centre of mass within {DEFAULT_COM_RADIUS:g} m of the flange"
        )
    else:
        why = rated.source if rated is not None else "not known to polyrob"
        words.append(f"no instrument: {robot.name}'s rated payload is {why}")
    source = f"polyrob's default set (per-link ±{100 * link_error:g} %; {'; '.join(words)})"
    return RobotUncertainty(link_error=link_error, payload=payload, source=source).bound(robot)
