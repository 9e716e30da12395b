"""What a robot engineer states about the robot: per-link parameter errors, a payload body, joint friction.

A :class:`RobotUncertainty` is that uncertainty in one value,
read from a YAML/JSON file (:meth:`RobotUncertainty.from_file`) or the
``--link-error P`` option, and written back by :meth:`RobotUncertainty.to_dict`:

* **links**: either ``link_error = p`` (each link's mass ``m``, first moment
  ``h = m c`` and rotational inertia about its centre of mass ``I_c`` each
  times its own factor in ``[1 - p, 1 + p]``, independently per link), or,
  per link, intervals of the ten standard parameters
  ``[m, mcx, mcy, mcz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]`` in the order of
  Pinocchio's ``Inertia.toDynamicParameters()`` (inertia about the link
  frame's origin: an identification's confidence intervals);
* **payload** (:class:`PayloadBody`): a rigid body, its mass in a range, its
  centre of mass in a box or a ball in the *flange frame*
  (:func:`polyrob.model.payload.flange_frame`: the robot's ``tool0`` /
  ``flange`` / ``panda_link8`` / ... frame when it is fixed to the last
  joint, else the last joint's frame), its inertia a solid sphere or box of
  stated size or given about its centre of mass;
* **friction** (:class:`JointFriction`): per joint a viscous range (N m s/rad)
  and a Coulomb level (N m: ``|tau_c| <= coulomb``), from the URDF's
  ``<dynamics damping friction>`` where the file states none;
* the vendor's **rated payload** of the arms polyrob ships by name
  (:data:`RATED_PAYLOAD`).

Why the factor form scales ``I_c`` and not the inertia about the joint:
scaling ``m``, ``h`` and ``I_c`` by positive factors keeps every draw a
physical body (positive mass, ``I_c`` with the triangle inequality of its
principal moments), so the sampler never redraws; scaling the inertia about
the joint origin instead can make ``I_c = I_O - S(h)^T S(h) / m`` indefinite
on links whose centre of mass sits far from their joint.  A ten-parameter
box may have non-physical vertices: that is *noted*
(:attr:`RobotUncertainty.notes`), not refused, because an identification's
box routinely has such corners while the robot lies in its physical part;
a box whose *centre* is not physical is refused, and the sampler redraws
non-physical draws (:mod:`polyrob.uncertainty_set.draw`).

On a computed-torque inner layer the commands carry this set with the
``inner-links`` model (:mod:`polyrob.plant.models.inner_links`), or refuse
it in one line with the measured reason when that model cannot hold it.

Examples
--------
>>> from polyrob import load_robot
>>> spec = RobotUncertainty(link_error=0.1).bound(load_robot("ur5"))
>>> spec.words()
'per-link ±10 % (mass, first moment, inertia about the CoM, each link independently); no payload; friction: not stated'
>>> RobotUncertainty.from_dict({"links": {"error_percent": -5}})
Traceback (most recent call last):
...
polyrob.errors.ArgumentError: robot uncertainty: links.error_percent: give a percentage in [0, 100), got -5
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from polyrob.errors import ArgumentError
from polyrob.uncertainty_set.checks import fail, finite, pair
from polyrob.uncertainty_set.links import (
    PARAMETER_NAMES,
    LinkInterval,
    arm_length,
    link_names,
    physically_consistent,
    scaled_parameters,
)
from polyrob.uncertainty_set.payload_body import RATED_PAYLOAD, PayloadBody, RatedPayload

__all__ = [
    "PARAMETER_NAMES",
    "RATED_PAYLOAD",
    "RatedPayload",
    "LinkInterval",
    "PayloadBody",
    "JointFriction",
    "RobotUncertainty",
    "link_names",
    "arm_length",
    "physically_consistent",
    "urdf_friction",
    "scaled_parameters",
]

#: Viscous friction drifts 17-20 % as the joints warm (Raviola et al. 2021): the range around a URDF's damping.
URDF_VISCOUS_SPREAD = 0.2


# --------------------------------------------------------------------------- friction


@dataclass(frozen=True)
class JointFriction:
    """One joint's friction: viscous ``[lo, hi]`` (N m s/rad) and a Coulomb level (N m, ``|tau_c| <= coulomb``)."""

    joint: str
    viscous: tuple = (0.0, 0.0)
    coulomb: float = 0.0
    source: str = "stated"

    def __post_init__(self):
        object.__setattr__(self, "viscous", pair(self.viscous, f"friction.{self.joint}.viscous", nonnegative=True))
        c = finite(self.coulomb, f"friction.{self.joint}.coulomb")
        if c < 0:
            fail(f"friction.{self.joint}.coulomb: a Coulomb level must be >= 0 N m, got {c:g}")
        object.__setattr__(self, "coulomb", c)

    def to_dict(self) -> dict:
        return {"viscous": list(self.viscous), "coulomb": self.coulomb, "source": self.source}


def urdf_friction(robot) -> dict[str, tuple[float, float]]:
    """``{joint: (damping, friction)}`` of the URDF's ``<dynamics>`` tags (only the joints that have one)."""
    try:
        root = ET.parse(str(robot.source)).getroot()
    except (OSError, ET.ParseError):
        return {}
    out = {}
    for joint in root.iter("joint"):
        dyn = joint.find("dynamics")
        if dyn is None or joint.get("name") not in robot.joint_names:
            continue
        try:
            out[joint.get("name")] = (float(dyn.get("damping", 0) or 0), float(dyn.get("friction", 0) or 0))
        except ValueError:
            continue
    return out


# --------------------------------------------------------------------------- the whole set


@dataclass(frozen=True)
class RobotUncertainty:
    """The uncertainty of one robot as an engineer states it (see the module's text).

    Attributes
    ----------
    link_error : float or None
        ``p`` in ``[0, 1)``: every link not in :attr:`links` has its mass, first
        moment and inertia about its centre of mass each times its own factor in
        ``[1 - p, 1 + p]``.  ``None``: those links are exact.
    links : tuple of LinkInterval
        Per-link intervals of the ten standard parameters (absolute values).
    payload : PayloadBody or None
    friction : tuple of JointFriction
        As stated; :meth:`bound` fills the joints the file leaves out from the URDF.
    source : str
        Where the figures come from, in words.
    robot : str
        The robot it is bound to (``""``: not yet).
    notes : tuple of str
        What :meth:`bound` found and did not refuse (non-physical vertices, capped payloads).
    """

    link_error: float | None = None
    links: tuple = ()
    payload: PayloadBody | None = None
    friction: tuple = ()
    source: str = "stated"
    robot: str = ""
    notes: tuple = ()
    _rated: RatedPayload | None = field(default=None, repr=False, compare=False)

    def __post_init__(self):
        if self.link_error is not None:
            p = finite(self.link_error, "links.error_percent")
            if not 0.0 <= p < 1.0:
                fail(f"links.error_percent: give a percentage in [0, 100), got {100 * p:g}")
            object.__setattr__(self, "link_error", p)

    # ------------------------------------------------------------------ reading and writing
    @classmethod
    def from_dict(cls, doc) -> RobotUncertainty:
        """From the mapping of a file (see :meth:`to_dict`); every error is one :class:`ArgumentError` line."""
        if not isinstance(doc, dict):
            fail(f"give a mapping with links, payload, friction; got {type(doc).__name__}")
        unknown = set(doc) - {"robot", "source", "links", "payload", "friction", "rated_payload"}
        if unknown:
            fail(f"unknown key(s) {', '.join(sorted(unknown))}: use robot, source, links, payload, friction")
        links_doc = doc.get("links") or {}
        if not isinstance(links_doc, dict):
            fail("links: give error_percent: P and/or intervals: {LINK: {m: [LO, HI], ...}}")
        bad = set(links_doc) - {"error_percent", "intervals"}
        if bad:
            fail(f"links: unknown key(s) {', '.join(sorted(bad))}: use error_percent, intervals")
        p = links_doc.get("error_percent")
        link_error = None if p is None else finite(p, "links.error_percent") / 100.0
        if link_error is not None and not 0.0 <= link_error < 1.0:
            fail(f"links.error_percent: give a percentage in [0, 100), got {100 * link_error:g}")
        intervals = []
        for name, params in (links_doc.get("intervals") or {}).items():
            if not isinstance(params, dict) or set(params) != set(PARAMETER_NAMES):
                fail(f"links.intervals.{name}: give all ten of {', '.join(PARAMETER_NAMES)} as [LO, HI]")
            pairs = [pair(params[k], f"links.{name}.{k}", nonnegative=(k == "m")) for k in PARAMETER_NAMES]
            intervals.append(LinkInterval(str(name), tuple(a for a, _ in pairs), tuple(b for _, b in pairs)))
        friction = []
        for joint, fr in (doc.get("friction") or {}).items():
            if not isinstance(fr, dict) or not set(fr) <= {"viscous", "coulomb", "source"}:
                fail(f"friction.{joint}: give viscous: [LO, HI] (N m s/rad) and coulomb: C (N m)")
            friction.append(
                JointFriction(
                    str(joint), fr.get("viscous", [0.0, 0.0]), fr.get("coulomb", 0.0), fr.get("source", "stated")
                )
            )
        payload = None if doc.get("payload") is None else PayloadBody.from_dict(doc["payload"])
        return cls(
            link_error=link_error,
            links=tuple(intervals),
            payload=payload,
            friction=tuple(friction),
            source=str(doc.get("source", "stated")),
            robot=str(doc.get("robot", "")),
        )

    @classmethod
    def from_file(cls, path) -> RobotUncertainty:
        """Read a YAML (``.yaml``/``.yml``) or JSON file; a missing or malformed file is one ArgumentError line."""
        path = Path(path)
        try:
            text = path.read_text(encoding="utf-8")
        except OSError as exc:
            raise ArgumentError(f"--robot-uncertainty {path}: cannot read it ({exc.strerror})") from None
        import yaml

        try:
            doc = yaml.safe_load(text) if path.suffix.lower() in (".yaml", ".yml") else json.loads(text)
        except (yaml.YAMLError, ValueError) as exc:
            first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise ArgumentError(f"--robot-uncertainty {path}: not valid YAML/JSON ({first})") from None
        try:
            return cls.from_dict(doc)
        except ArgumentError as exc:
            raise ArgumentError(f"--robot-uncertainty {path}: {str(exc).removeprefix('robot uncertainty: ')}") from None

    def to_dict(self) -> dict:
        """The file's mapping (:meth:`from_dict` reads it back to an equal value)."""
        links = {}
        if self.link_error is not None:
            links["error_percent"] = 100.0 * self.link_error
        if self.links:
            links["intervals"] = {li.link: li.to_dict() for li in self.links}
        out = {"robot": self.robot, "source": self.source, "links": links}
        if self.payload is not None:
            out["payload"] = self.payload.to_dict()
        if self.friction:
            out["friction"] = {f.joint: f.to_dict() for f in self.friction}
        return out

    def write(self, path) -> None:
        """Write :meth:`to_dict` as YAML (``.yaml``/``.yml``) or JSON."""
        path = Path(path)
        if path.suffix.lower() in (".yaml", ".yml"):
            import yaml

            path.write_text(yaml.safe_dump(self.to_dict(), sort_keys=False), encoding="utf-8")
        else:
            path.write_text(json.dumps(self.to_dict(), indent=2), encoding="utf-8")

    # ------------------------------------------------------------------ bound to a robot
    def bound(self, robot) -> RobotUncertainty:
        """This set checked against ``robot`` (a URDF robot), the URDF's friction filled in, its notes said.

        Raises
        ------
        ArgumentError
            The file names another robot, an unknown link or joint, a centre
            of mass farther from the flange than the arm is long, or a link
            box whose centre is not a rigid body.
        """
        from polyrob.model.payload import flange_frame

        if getattr(robot, "model", None) is None:
            fail(f"{robot.name}: per-link parameters need a URDF robot (a Pinocchio model), not an analytic one")
        if self.robot and self.robot != robot.name:
            fail(f"the file is for robot '{self.robot}', not '{robot.name}': give that robot or fix 'robot:'")
        known = link_names(robot)
        notes = list(self.notes)
        for li in self.links:
            if li.link not in known:
                fail(f"links: unknown link '{li.link}' of {robot.name}: use one of {', '.join(known)}")
            if not physically_consistent(li.centre):
                fail(f"links.{li.link}: the centre of its box is not a rigid body (m > 0, triangle inequality of I_c)")
            bad = li.vertices_not_physical()
            if bad:
                notes.append(f"{li.link}: {bad} of 1024 box vertices are not a rigid body (drawn robots avoid them)")
        friction = {f.joint: f for f in self.friction}
        for joint in friction:
            if joint not in robot.joint_names:
                fail(f"friction: unknown joint '{joint}' of {robot.name}: use one of {', '.join(robot.joint_names)}")
        for joint, (damping, coulomb) in urdf_friction(robot).items():
            if joint not in friction and (damping or coulomb):
                spread = URDF_VISCOUS_SPREAD * damping
                friction[joint] = JointFriction(joint, (damping - spread, damping + spread), coulomb, "URDF <dynamics>")
        payload = self.payload
        rated = RATED_PAYLOAD.get(robot.name)
        if payload is not None:
            reach = arm_length(robot)
            if payload.farthest() > reach:
                fail(
                    f"payload: its centre of mass may lie {payload.farthest():.3g} m from the flange, farther than "
                    f"{robot.name}'s arm is long ({reach:.3g} m): shrink com_box/com_ball"
                )
            payload = replace(payload, frame=flange_frame(robot)[0])
            if rated is not None and rated.kg is not None and payload.mass_upper > rated.kg:
                notes.append(
                    f"payload up to {payload.mass_upper:g} kg exceeds the rated {rated.kg:g} kg ({rated.source})"
                )
        ordered = tuple(friction[j] for j in robot.joint_names if j in friction)
        return replace(self, payload=payload, friction=ordered, robot=robot.name, notes=tuple(notes), _rated=rated)

    @property
    def rated_payload(self) -> RatedPayload | None:
        """The vendor's rated payload of the bound robot (``None``: not bound, or not an arm polyrob names)."""
        return self._rated

    def words(self) -> str:
        """The set as one phrase (a certificate's ``covers:`` text will carry it once it is certified)."""
        parts = []
        if self.link_error is not None:
            parts.append(
                f"per-link ±{100 * self.link_error:g} % (mass, first moment, inertia about the CoM, each link independently)"
            )
        if self.links:
            parts.append(f"ten-parameter intervals on {len(self.links)} link(s)")
        if not parts:
            parts.append("links exact")
        if self.payload is not None:
            parts.append(self.payload.words())
        else:
            parts.append("no payload")
        if self.friction:
            coulomb = max(f.coulomb for f in self.friction)
            viscous = max(f.viscous[1] for f in self.friction)
            parts.append(
                f"friction on {len(self.friction)} joint(s) (viscous <= {viscous:g} N m s/rad, Coulomb <= {coulomb:g} N m)"
            )
        else:
            parts.append("friction: not stated")
        return "; ".join(parts)

    # ------------------------------------------------------------------ per-link parameters
    def link_box(self, robot) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Per link, the interval hull ``(lower, upper)`` of its ten standard parameters over the set.

        For the factor form (``m``, ``h`` and ``I_c`` times factors in
        ``[1 - p, 1 + p]``) the inertia about the link origin,
        ``I_O = d I_c + (b^2 / a) S(c)^T S(c) m``, is monotone in ``d`` and in
        ``b^2 / a``, so the hull is taken over their extreme values.
        """
        explicit = {li.link: (np.array(li.lower), np.array(li.upper)) for li in self.links}
        out = {}
        for name, j in link_names(robot).items():
            if name in explicit:
                out[name] = explicit[name]
                continue
            theta = np.asarray(robot.model.inertias[j].toDynamicParameters(), float)
            p = self.link_error or 0.0
            candidates = []
            for a in (1 - p, 1 + p):
                for b in (1 - p, 1 + p):
                    for d in (1 - p, 1 + p):
                        candidates.append(scaled_parameters(theta, a, b, d))
            cand = np.array(candidates)
            out[name] = (cand.min(axis=0), cand.max(axis=0))
        return out
