"""A payload range at the tool flange, and link inertias off by a percentage.

A medical robot changes instruments: the mass at its flange, and where that
mass sits, vary between tasks.  :class:`PayloadRange` states the range (mass
``[lo, hi]`` kg, centre-of-mass offset box in the flange frame, metres);
:func:`with_payload` gives a copy of a URDF robot carrying one payload, with
every link's inertia (mass, first and second moments) scaled by one factor
(the model error of :mod:`polyrob.model.inner`).  The payload is a solid
sphere of radius :data:`PAYLOAD_RADIUS` (a small rotational inertia).

The flange is the robot's ``tool0``/``flange``/``panda_link8`` frame when
it has one, else the frame of its last joint.

Examples
--------
>>> import numpy as np
>>> from polyrob import load_robot
>>> robot = load_robot("planar_2r")
>>> rng = PayloadRange(0.0, 2.0, com_lower=(0.0, 0.0, 0.0), com_upper=(0.05, 0.0, 0.0)).at(robot)
>>> rng.words()
'payload 0-2 kg, COM offset [0:0.05, 0:0, 0:0] m at joint2'
>>> heavy = with_payload(robot, 2.0, (0.05, 0.0, 0.0))
>>> bool(heavy.mass_matrix([0.0, 0.0])[1, 1] > robot.mass_matrix([0.0, 0.0])[1, 1])
True
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, replace

import numpy as np
import pinocchio

from polyrob.errors import DomainError

__all__ = ["PayloadRange", "with_payload", "flange_frame", "PAYLOAD_RADIUS", "FLANGE_FRAMES"]

#: Radius (m) of the solid sphere a payload is modelled as.
PAYLOAD_RADIUS = 0.03
#: Frames taken as the tool flange, first found first.
FLANGE_FRAMES = ("tool0", "flange", "panda_link8", "link_flange", "link6_flange")


def flange_frame(robot) -> tuple[str, pinocchio.SE3]:
    """The flange frame's name and placement in the last joint's frame."""
    model = robot.model
    last = model.njoints - 1
    for name in FLANGE_FRAMES:
        if model.existFrame(name):
            frame = model.frames[model.getFrameId(name)]
            if frame.parentJoint == last:
                return name, frame.placement
    return model.names[last], pinocchio.SE3.Identity()


def _check_number(value, what) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise DomainError(f"{what}: {value!r} is not a number") from None
    if not np.isfinite(x):
        raise DomainError(f"{what}: {x:g} is not finite: give a finite number")
    return x


@dataclass(frozen=True)
class PayloadRange:
    """Mass ``[mass_lower, mass_upper]`` (kg) and COM offset box (m, flange frame).

    Attributes
    ----------
    mass_lower, mass_upper : float
    com_lower, com_upper : tuple of 3 floats
    frame : str
        Where the offset is measured (set by :meth:`at`; ``""``: not yet bound to a robot).
    """

    mass_lower: float
    mass_upper: float
    com_lower: tuple = (0.0, 0.0, 0.0)
    com_upper: tuple = (0.0, 0.0, 0.0)
    frame: str = ""

    def __post_init__(self):
        lo = _check_number(self.mass_lower, "--payload-mass")
        hi = _check_number(self.mass_upper, "--payload-mass")
        if lo < 0:
            raise DomainError(f"--payload-mass: a mass must be >= 0 kg, got {lo:g}")
        if lo > hi:
            raise DomainError(f"--payload-mass: range {lo:g}:{hi:g} is inverted: give LO <= HI")
        object.__setattr__(self, "mass_lower", lo)
        object.__setattr__(self, "mass_upper", hi)
        for attr in ("com_lower", "com_upper"):
            vals = tuple(_check_number(v, "--payload-com") for v in np.ravel(getattr(self, attr)))
            if len(vals) != 3:
                raise DomainError(f"--payload-com: give 3 numbers X,Y,Z (metres), got {len(vals)}")
            object.__setattr__(self, attr, vals)
        if any(a > b for a, b in zip(self.com_lower, self.com_upper)):
            raise DomainError("--payload-com: the offset box is inverted: give lower <= upper per axis")

    @classmethod
    def parse(cls, mass: str, com: str | None = None) -> PayloadRange:
        """From the CLI's ``--payload-mass LO:HI`` (or ``M``) and ``--payload-com X,Y,Z`` (or ``R``).

        ``X,Y,Z`` is the box ``[-|X|, |X|] x ...``; one number ``R`` is the cube ``[-R, R]^3``;
        ``X0:X1,Y0:Y1,Z0:Z1`` gives each axis' range.

        Examples
        --------
        >>> PayloadRange.parse("0.2:1.5", "0,0,0.02").com_upper
        (0.0, 0.0, 0.02)
        >>> PayloadRange.parse("2:1")
        Traceback (most recent call last):
        ...
        polyrob.errors.DomainError: --payload-mass: range 2:1 is inverted: give LO <= HI
        """
        parts = str(mass).split(":")
        if len(parts) not in (1, 2) or not all(p.strip() for p in parts):
            raise DomainError(f"--payload-mass: give LO:HI (kg) or one mass, got {mass!r}")
        lo, hi = (parts[0], parts[-1])
        lo, hi = _check_number(lo, "--payload-mass"), _check_number(hi, "--payload-mass")
        if com is None or not str(com).strip():
            return cls(lo, hi)
        axes = [a.strip() for a in str(com).split(",")]
        if len(axes) == 1:
            axes = axes * 3
        if len(axes) != 3:
            raise DomainError(f"--payload-com: give X,Y,Z or one radius R (metres), got {com!r}")
        lower, upper = [], []
        for a in axes:
            ends = a.split(":")
            if len(ends) == 2:
                lower.append(_check_number(ends[0], "--payload-com"))
                upper.append(_check_number(ends[1], "--payload-com"))
            elif len(ends) == 1:
                r = abs(_check_number(ends[0], "--payload-com"))
                lower.append(-r)
                upper.append(r)
            else:
                raise DomainError(f"--payload-com: {a!r} is not a number or LO:HI")
        return cls(lo, hi, tuple(lower), tuple(upper))

    def at(self, robot) -> PayloadRange:
        """This range bound to ``robot``'s flange frame (its name in :attr:`frame`)."""
        return replace(self, frame=flange_frame(robot)[0])

    @property
    def midpoint(self) -> tuple[float, np.ndarray]:
        """``(mass, com)`` in the middle of the range: the model's payload."""
        return 0.5 * (self.mass_lower + self.mass_upper), 0.5 * (np.array(self.com_lower) + np.array(self.com_upper))

    def corners(self) -> list[tuple[float, np.ndarray]]:
        """The payloads the bounds are sampled at: the lightest at the centre, the heaviest at every corner."""
        mid = self.midpoint[1]
        out = [(self.mass_lower, mid)]
        moving = [j for j in range(3) if self.com_upper[j] > self.com_lower[j]]
        for bits in itertools.product((0, 1), repeat=len(moving)):
            c = mid.copy()
            for j, b in zip(moving, bits):
                c[j] = (self.com_lower, self.com_upper)[b][j]
            out.append((self.mass_upper, c))
        return [p for k, p in enumerate(out) if self.mass_upper > self.mass_lower or k > 0]

    def draw(self, rng, *, extreme: bool = False) -> tuple[float, np.ndarray]:
        """A payload drawn uniformly from the range (``extreme``: the mass at an end, the COM at a corner)."""
        if extreme:
            corner = np.where(rng.integers(0, 2, size=3) == 1, self.com_upper, self.com_lower)
            return float(self.mass_upper if rng.integers(2) else self.mass_lower), np.asarray(corner, float)
        mass = rng.uniform(self.mass_lower, self.mass_upper)
        return float(mass), rng.uniform(self.com_lower, self.com_upper)

    def words(self) -> str:
        """The range in one line."""
        box = ", ".join(f"{a:.3g}:{b:.3g}" for a, b in zip(self.com_lower, self.com_upper))
        where = f" at {self.frame}" if self.frame else ""
        return f"payload {self.mass_lower:g}-{self.mass_upper:g} kg, COM offset [{box}] m{where}"

    def to_dict(self) -> dict:
        return {
            "mass": [self.mass_lower, self.mass_upper],
            "com_lower": list(self.com_lower),
            "com_upper": list(self.com_upper),
            "frame": self.frame,
        }


def with_payload(robot, mass: float = 0.0, com=(0.0, 0.0, 0.0), *, scale: float = 1.0):
    """A copy of URDF ``robot`` with every link inertia times ``scale`` and a payload at its flange.

    Parameters
    ----------
    robot : Robot
    mass : float
        Payload mass (kg); 0: none.
    com : 3 floats
        The payload's centre of mass in the flange frame (m).
    scale : float
        Factor on every link's mass and inertia (the reflected rotor inertia is kept).
    """
    model = robot.model.copy()
    for i in range(1, model.njoints):
        Y = model.inertias[i]
        model.inertias[i] = pinocchio.Inertia(scale * Y.mass, Y.lever.copy(), scale * Y.inertia.copy())
    if mass > 0:
        _, placement = flange_frame(robot)
        sphere = 0.4 * mass * PAYLOAD_RADIUS**2 * np.eye(3)
        load = placement.act(pinocchio.Inertia(float(mass), np.asarray(com, float).reshape(3), sphere))
        last = model.njoints - 1
        model.inertias[last] = model.inertias[last] + load
    return replace(robot, model=model)
