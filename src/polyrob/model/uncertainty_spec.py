"""What a robot engineer states about the robot: per-link parameter errors, a payload body, joint friction.

A :class:`RobotUncertainty` is the uncertainty of issue 38 in one value,
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
non-physical draws (:mod:`polyrob.model.true_robots`).

No command certifies this set yet: the certified models are the common
factor of :mod:`polyrob.model.inner`; ``--robot-uncertainty`` and
``--link-error`` are refused with one line saying so (issue 38).

Examples
--------
>>> from polyrob import load_robot
>>> spec = RobotUncertainty(link_error=0.1).bound(load_robot("ur5"))
>>> spec.words()
'per-link ±10 % (mass, first moment, inertia about the CoM, each link independently); friction: not stated'
>>> RobotUncertainty.from_dict({"links": {"error_percent": -5}})
Traceback (most recent call last):
...
polyrob.errors.ArgumentError: robot uncertainty: links.error_percent: give a percentage in [0, 100), got -5
"""

from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from polyrob.errors import ArgumentError

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

#: The ten standard inertial parameters of a link, in ``pinocchio.Inertia.toDynamicParameters()``'s order
#: (first moment ``m c`` and rotational inertia about the link frame's origin).
PARAMETER_NAMES = ("m", "mcx", "mcy", "mcz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")
#: Tolerance of the physical-consistency test (relative to the largest principal moment).
_PHYSICAL_TOL = 1e-9
#: Viscous friction drifts 17-20 % as the joints warm (Raviola et al. 2021): the range around a URDF's damping.
URDF_VISCOUS_SPREAD = 0.2


@dataclass(frozen=True)
class RatedPayload:
    """A vendor's rated payload (kg) and where the figure comes from; ``kg`` is ``None`` when unknown."""

    kg: float | None
    source: str


#: The rated payload of the arms polyrob ships by name.
RATED_PAYLOAD = {
    "panda": RatedPayload(3.0, "Franka Emika Panda datasheet: 3 kg"),
    "ur5": RatedPayload(5.0, "Universal Robots UR5: 5 kg"),
    "ur10": RatedPayload(10.0, "Universal Robots UR10: 10 kg"),
    "xarm7": RatedPayload(3.5, "UFACTORY xArm 7: 3.5 kg"),
    "z1": RatedPayload(3.0, "Unitree Z1 specification page (dev-z1.cn.unitree.com): payload >= 3 kg"),
    "talos_left_arm": RatedPayload(6.0, "TALOS, Stasse et al., Humanoids 2017: 6 kg per outstretched arm"),
    "kinova": RatedPayload(
        None,
        "unknown: polyrob's kinova is example-robot-data's Jaco2 j2s6s200, not a Gen3 (4 kg); no Jaco2 figure checked",
    ),
    "so101": RatedPayload(None, "unknown: the SO-101's makers state no rated payload"),
}


def _fail(text: str):
    raise ArgumentError(f"robot uncertainty: {text}")


def _finite(value, where: str) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        _fail(f"{where}: {value!r} is not a number")
    if not math.isfinite(x):
        _fail(f"{where}: {x:g} is not a finite number")
    return x


def _pair(value, where: str, *, nonnegative: bool = False) -> tuple[float, float]:
    """``[lo, hi]`` (or one number ``v`` meaning ``[v, v]``) of finite numbers with ``lo <= hi``."""
    items = list(value) if isinstance(value, (list, tuple)) else [value]
    if len(items) not in (1, 2):
        _fail(f"{where}: give [LO, HI], got {value!r}")
    lo, hi = _finite(items[0], where), _finite(items[-1], where)
    if nonnegative and lo < 0:
        _fail(f"{where}: must be >= 0, got {lo:g}")
    if lo > hi:
        _fail(f"{where}: [{lo:g}, {hi:g}] has its lower bound above its upper bound: give LO <= HI")
    return lo, hi


def _vector3(value, where: str) -> tuple[float, float, float]:
    items = list(value) if isinstance(value, (list, tuple)) else None
    if items is None or len(items) != 3:
        _fail(f"{where}: give 3 numbers [x, y, z] (m), got {value!r}")
    return tuple(_finite(v, where) for v in items)


# --------------------------------------------------------------------------- the robot's links


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
            _fail(f"links.{self.link}: give the ten parameters {', '.join(PARAMETER_NAMES)}")
        for k, name in enumerate(PARAMETER_NAMES):
            _pair([lo[k], hi[k]], f"links.{self.link}.{name}", nonnegative=(name == "m"))
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


# --------------------------------------------------------------------------- the payload


@dataclass(frozen=True)
class PayloadBody:
    """A payload as a rigid body at the flange.

    Attributes
    ----------
    mass_lower, mass_upper : float
        kg, ``0 <= lower <= upper``.
    com_lower, com_upper : tuple of 3 floats
        The centre-of-mass box in the flange frame (m), when ``com_radius`` is ``None``.
    com_centre : tuple of 3 floats
        The ball's centre (m, flange frame), when ``com_radius`` is given.
    com_radius : float or None
        The centre of mass lies in the ball ``|c - com_centre| <= com_radius``.
    solid : str
        ``"sphere"`` or ``"box"``: the payload's inertia is that of a uniform solid of ``size``.
    size : tuple
        The sphere's radius (one number) or the box's edges ``(a, b, c)`` along the flange axes (m).
    frame : str
        The flange frame's name, set by :meth:`RobotUncertainty.bound` (``""``: not bound to a robot).
    """

    mass_lower: float
    mass_upper: float
    com_lower: tuple = (0.0, 0.0, 0.0)
    com_upper: tuple = (0.0, 0.0, 0.0)
    com_centre: tuple = (0.0, 0.0, 0.0)
    com_radius: float | None = None
    solid: str = "sphere"
    size: tuple = (0.03,)
    frame: str = ""

    def __post_init__(self):
        lo, hi = _pair([self.mass_lower, self.mass_upper], "payload.mass", nonnegative=True)
        object.__setattr__(self, "mass_lower", lo)
        object.__setattr__(self, "mass_upper", hi)
        lower, upper = _vector3(self.com_lower, "payload.com_box"), _vector3(self.com_upper, "payload.com_box")
        for a, b in zip(lower, upper):
            _pair([a, b], "payload.com_box")
        object.__setattr__(self, "com_lower", lower)
        object.__setattr__(self, "com_upper", upper)
        object.__setattr__(self, "com_centre", _vector3(self.com_centre, "payload.com_ball.centre"))
        if self.com_radius is not None:
            r = _finite(self.com_radius, "payload.com_ball.radius")
            if r < 0:
                _fail(f"payload.com_ball.radius: must be >= 0, got {r:g}")
            object.__setattr__(self, "com_radius", r)
        if self.solid not in ("sphere", "box"):
            _fail(f"payload.inertia: give solid_sphere: R or solid_box: [A, B, C], got {self.solid!r}")
        size = tuple(_finite(v, f"payload.inertia.solid_{self.solid}") for v in np.ravel(self.size))
        if len(size) != (1 if self.solid == "sphere" else 3) or any(v < 0 for v in size):
            _fail(f"payload.inertia.solid_{self.solid}: give {'R' if self.solid == 'sphere' else '[A, B, C]'} >= 0 (m)")
        object.__setattr__(self, "size", size)

    def farthest(self) -> float:
        """The largest distance (m) of a centre of mass of the set from the flange's origin."""
        if self.com_radius is not None:
            return float(np.linalg.norm(self.com_centre)) + self.com_radius
        corners = np.maximum(np.abs(self.com_lower), np.abs(self.com_upper))
        return float(np.linalg.norm(corners))

    def contains(self, com, tol: float = 1e-12) -> bool:
        """Whether ``com`` (flange frame, m) lies in the centre-of-mass set."""
        c = np.asarray(com, float)
        if self.com_radius is not None:
            return bool(np.linalg.norm(c - self.com_centre) <= self.com_radius + tol)
        return bool(np.all(c >= np.array(self.com_lower) - tol) and np.all(c <= np.array(self.com_upper) + tol))

    def rotational_inertia(self, mass: float) -> np.ndarray:
        """The 3x3 inertia (kg m^2) about the centre of mass, flange axes, of the solid with ``mass``."""
        if self.solid == "sphere":
            return 0.4 * mass * self.size[0] ** 2 * np.eye(3)
        a, b, c = self.size
        return mass / 12.0 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])

    def draw(self, rng) -> tuple[float, np.ndarray]:
        """``(mass, com)``: the mass uniform in its range, the centre of mass uniform in its box or ball."""
        mass = float(rng.uniform(self.mass_lower, self.mass_upper))
        if self.com_radius is None:
            return mass, rng.uniform(self.com_lower, self.com_upper)
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction) or 1.0
        radius = self.com_radius * rng.uniform() ** (1.0 / 3.0)  # uniform in the ball's volume
        return mass, np.array(self.com_centre) + radius * direction

    def words(self) -> str:
        where = f" of {self.frame}" if self.frame else " of the flange"
        if self.com_radius is not None:
            centre = "the origin" if not any(self.com_centre) else f"({', '.join(f'{v:g}' for v in self.com_centre)})"
            com = f"centre of mass within {self.com_radius:g} m of {centre}{where}"
        else:
            box = ", ".join(f"{a:g}:{b:g}" for a, b in zip(self.com_lower, self.com_upper))
            com = f"centre of mass in [{box}] m{where}"
        solid = f"solid sphere r {self.size[0]:g} m" if self.solid == "sphere" else f"solid box {self.size} m"
        return f"payload {self.mass_lower:g}-{self.mass_upper:g} kg, {com}, {solid}"

    def to_dict(self) -> dict:
        out = {"mass": [self.mass_lower, self.mass_upper]}
        if self.com_radius is not None:
            out["com_ball"] = {"centre": list(self.com_centre), "radius": self.com_radius}
        else:
            out["com_box"] = {"lower": list(self.com_lower), "upper": list(self.com_upper)}
        out["inertia"] = {f"solid_{self.solid}": self.size[0] if self.solid == "sphere" else list(self.size)}
        return out

    @classmethod
    def from_dict(cls, doc) -> PayloadBody:
        if not isinstance(doc, dict):
            _fail(f"payload: give a mapping with mass, com_box or com_ball, inertia; got {doc!r}")
        unknown = set(doc) - {"mass", "com_box", "com_ball", "inertia"}
        if unknown:
            _fail(f"payload: unknown key(s) {', '.join(sorted(unknown))}: use mass, com_box, com_ball, inertia")
        if "mass" not in doc:
            _fail("payload: give its mass range, mass: [LO, HI] (kg)")
        lo, hi = _pair(doc["mass"], "payload.mass", nonnegative=True)
        kwargs = {}
        if "com_box" in doc and "com_ball" in doc:
            _fail("payload: give com_box or com_ball, not both")
        if "com_box" in doc:
            box = doc["com_box"] or {}
            kwargs.update(com_lower=box.get("lower"), com_upper=box.get("upper"))
        if "com_ball" in doc:
            ball = doc["com_ball"] or {}
            kwargs.update(com_centre=ball.get("centre", [0.0, 0.0, 0.0]), com_radius=ball.get("radius"))
            if kwargs["com_radius"] is None:
                _fail("payload.com_ball: give its radius (m)")
        inertia = doc.get("inertia") or {"solid_sphere": 0.03}
        if not isinstance(inertia, dict) or len(inertia) != 1:
            _fail("payload.inertia: give one of solid_sphere: R or solid_box: [A, B, C] (m)")
        ((key, size),) = inertia.items()
        kwargs.update(solid=str(key).removeprefix("solid_"), size=size)
        return cls(lo, hi, **kwargs)


# --------------------------------------------------------------------------- friction


@dataclass(frozen=True)
class JointFriction:
    """One joint's friction: viscous ``[lo, hi]`` (N m s/rad) and a Coulomb level (N m, ``|tau_c| <= coulomb``)."""

    joint: str
    viscous: tuple = (0.0, 0.0)
    coulomb: float = 0.0
    source: str = "stated"

    def __post_init__(self):
        object.__setattr__(self, "viscous", _pair(self.viscous, f"friction.{self.joint}.viscous", nonnegative=True))
        c = _finite(self.coulomb, f"friction.{self.joint}.coulomb")
        if c < 0:
            _fail(f"friction.{self.joint}.coulomb: a Coulomb level must be >= 0 N m, got {c:g}")
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
            p = _finite(self.link_error, "links.error_percent")
            if not 0.0 <= p < 1.0:
                _fail(f"links.error_percent: give a percentage in [0, 100), got {100 * p:g}")
            object.__setattr__(self, "link_error", p)

    # ------------------------------------------------------------------ reading and writing
    @classmethod
    def from_dict(cls, doc) -> RobotUncertainty:
        """From the mapping of a file (see :meth:`to_dict`); every error is one :class:`ArgumentError` line."""
        if not isinstance(doc, dict):
            _fail(f"give a mapping with links, payload, friction; got {type(doc).__name__}")
        unknown = set(doc) - {"robot", "source", "links", "payload", "friction", "rated_payload"}
        if unknown:
            _fail(f"unknown key(s) {', '.join(sorted(unknown))}: use robot, source, links, payload, friction")
        links_doc = doc.get("links") or {}
        if not isinstance(links_doc, dict):
            _fail("links: give error_percent: P and/or intervals: {LINK: {m: [LO, HI], ...}}")
        bad = set(links_doc) - {"error_percent", "intervals"}
        if bad:
            _fail(f"links: unknown key(s) {', '.join(sorted(bad))}: use error_percent, intervals")
        p = links_doc.get("error_percent")
        link_error = None if p is None else _finite(p, "links.error_percent") / 100.0
        if link_error is not None and not 0.0 <= link_error < 1.0:
            _fail(f"links.error_percent: give a percentage in [0, 100), got {100 * link_error:g}")
        intervals = []
        for name, params in (links_doc.get("intervals") or {}).items():
            if not isinstance(params, dict) or set(params) != set(PARAMETER_NAMES):
                _fail(f"links.intervals.{name}: give all ten of {', '.join(PARAMETER_NAMES)} as [LO, HI]")
            pairs = [_pair(params[k], f"links.{name}.{k}", nonnegative=(k == "m")) for k in PARAMETER_NAMES]
            intervals.append(LinkInterval(str(name), tuple(a for a, _ in pairs), tuple(b for _, b in pairs)))
        friction = []
        for joint, fr in (doc.get("friction") or {}).items():
            if not isinstance(fr, dict) or not set(fr) <= {"viscous", "coulomb", "source"}:
                _fail(f"friction.{joint}: give viscous: [LO, HI] (N m s/rad) and coulomb: C (N m)")
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
            _fail(f"{robot.name}: per-link parameters need a URDF robot (a Pinocchio model), not an analytic one")
        if self.robot and self.robot != robot.name:
            _fail(f"the file is for robot '{self.robot}', not '{robot.name}': give that robot or fix 'robot:'")
        known = link_names(robot)
        notes = list(self.notes)
        for li in self.links:
            if li.link not in known:
                _fail(f"links: unknown link '{li.link}' of {robot.name}: use one of {', '.join(known)}")
            if not physically_consistent(li.centre):
                _fail(f"links.{li.link}: the centre of its box is not a rigid body (m > 0, triangle inequality of I_c)")
            bad = li.vertices_not_physical()
            if bad:
                notes.append(f"{li.link}: {bad} of 1024 box vertices are not a rigid body (drawn robots avoid them)")
        friction = {f.joint: f for f in self.friction}
        for joint in friction:
            if joint not in robot.joint_names:
                _fail(f"friction: unknown joint '{joint}' of {robot.name}: use one of {', '.join(robot.joint_names)}")
        for joint, (damping, coulomb) in urdf_friction(robot).items():
            if joint not in friction and (damping or coulomb):
                spread = URDF_VISCOUS_SPREAD * damping
                friction[joint] = JointFriction(joint, (damping - spread, damping + spread), coulomb, "URDF <dynamics>")
        payload = self.payload
        rated = RATED_PAYLOAD.get(robot.name)
        if payload is not None:
            reach = arm_length(robot)
            if payload.farthest() > reach:
                _fail(
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


def scaled_parameters(theta, mass_factor: float, moment_factor: float, inertia_factor: float) -> np.ndarray:
    """Ten standard parameters with ``m``, ``h = m c`` and ``I_c`` times the three factors (a rigid body stays one)."""
    theta = np.asarray(theta, float)
    m, h = theta[0], theta[1:4]
    ic = _inertia_about_com(theta)
    m2, h2 = mass_factor * m, moment_factor * h
    c2 = h2 / m2 if m2 > 0 else np.zeros(3)
    io = inertia_factor * ic + m2 * (np.dot(c2, c2) * np.eye(3) - np.outer(c2, c2))
    return np.array([m2, *h2, io[0, 0], io[0, 1], io[1, 1], io[0, 2], io[1, 2], io[2, 2]])
