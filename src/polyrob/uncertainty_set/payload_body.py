"""A payload as a rigid body at the flange (mass range, centre-of-mass box or ball, inertia), and rated payloads.

The flange is :func:`polyrob.model.payload.flange_frame`: the robot's
``tool0`` / ``flange`` / ``panda_link8`` / ... frame when it is fixed to the
last joint, else the last joint's own frame; the centre of mass is given in
its axes, from its origin.

Examples
--------
>>> body = PayloadBody(0.0, 1.5, com_radius=0.1)
>>> body.farthest(), body.contains([0.0, 0.06, 0.08]), body.contains([0.1, 0.1, 0.0])
(0.1, True, False)
>>> RATED_PAYLOAD["ur5"].kg
5.0
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from polyrob.uncertainty_set.checks import fail, finite, pair, vector3

__all__ = [
    "PayloadBody",
    "RatedPayload",
    "RATED_PAYLOAD",
    "SECOND_MOMENT_ENTRIES",
    "second_moment",
    "payload_sampling_words",
    "payload_points",
    "payload_coordinates",
    "payload_middle",
]

#: The six entries ``(i, j)`` of a symmetric 3 x 3 matrix, in ``toDynamicParameters()``'s inertia order.
SECOND_MOMENT_ENTRIES = ((0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2))


def second_moment(mass: float, com) -> np.ndarray:
    """The six entries of ``m S(c)^T S(c) = m (|c|^2 I - c c^T)``: the parallel-axis part of the inertia about the flange."""
    c = np.asarray(com, float)
    M = mass * (np.dot(c, c) * np.eye(3) - np.outer(c, c))
    return np.array([M[i, j] for i, j in SECOND_MOMENT_ENTRIES])


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
        lo, hi = pair([self.mass_lower, self.mass_upper], "payload.mass", nonnegative=True)
        object.__setattr__(self, "mass_lower", lo)
        object.__setattr__(self, "mass_upper", hi)
        lower, upper = vector3(self.com_lower, "payload.com_box"), vector3(self.com_upper, "payload.com_box")
        for a, b in zip(lower, upper):
            pair([a, b], "payload.com_box")
        object.__setattr__(self, "com_lower", lower)
        object.__setattr__(self, "com_upper", upper)
        object.__setattr__(self, "com_centre", vector3(self.com_centre, "payload.com_ball.centre"))
        if self.com_radius is not None:
            r = finite(self.com_radius, "payload.com_ball.radius")
            if r < 0:
                fail(f"payload.com_ball.radius: must be >= 0, got {r:g}")
            object.__setattr__(self, "com_radius", r)
        if self.solid not in ("sphere", "box"):
            fail(f"payload.inertia: give solid_sphere: R or solid_box: [A, B, C], got {self.solid!r}")
        size = tuple(finite(v, f"payload.inertia.solid_{self.solid}") for v in np.ravel(self.size))
        if len(size) != (1 if self.solid == "sphere" else 3) or any(v < 0 for v in size):
            fail(f"payload.inertia.solid_{self.solid}: give {'R' if self.solid == 'sphere' else '[A, B, C]'} >= 0 (m)")
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

    def com_box(self) -> list[tuple[float, float]]:
        """Per flange axis, the interval of the centre of mass (the ball's bounding box)."""
        if self.com_radius is not None:
            return [(c - self.com_radius, c + self.com_radius) for c in self.com_centre]
        return list(zip(self.com_lower, self.com_upper))

    def moment_range(self) -> tuple[np.ndarray, np.ndarray]:
        """``(lower, upper)`` of the first moment ``m c`` per flange axis over the set (products of the intervals)."""
        lo, hi = zip(*(_product_range((self.mass_lower, self.mass_upper), b) for b in self.com_box()))
        return np.array(lo), np.array(hi)

    def second_moment_range(self) -> tuple[np.ndarray, np.ndarray]:
        """``(lower, upper)`` of the six entries of :func:`second_moment` over the set (an enclosure).

        Diagonal ``m (c_j^2 + c_k^2)``, off-diagonal ``-m c_i c_j``; for a ball
        the distances are capped at ``|centre| + radius`` from the flange's axes.
        """
        box, mass = self.com_box(), (self.mass_lower, self.mass_upper)
        far = float(np.linalg.norm(self.com_centre)) + self.com_radius if self.com_radius is not None else np.inf
        lo, hi = np.zeros(6), np.zeros(6)
        for k, (i, j) in enumerate(SECOND_MOMENT_ENTRIES):
            if i == j:
                a, b = (box[x] for x in range(3) if x != i)
                sq_lo = _square_range(*a)[0] + _square_range(*b)[0]
                sq_hi = min(_square_range(*a)[1] + _square_range(*b)[1], far * far)
                lo[k], hi[k] = _product_range(mass, (sq_lo, sq_hi))
            else:
                p_lo, p_hi = _product_range(box[i], box[j])
                p_lo, p_hi = max(p_lo, -far * far / 2), min(p_hi, far * far / 2)
                lo[k], hi[k] = _product_range(mass, (-p_hi, -p_lo))
        return lo, hi

    def draw(self, rng, *, extreme: bool = False) -> tuple[float, np.ndarray]:
        """``(mass, com)``: the mass uniform in its range, the centre of mass uniform in its box or ball.

        ``extreme``: the mass at one end of its range, the centre of mass at a
        corner of its box or on its ball's surface (where a frozen loop's worst
        cases lie, and uniform draws seldom go).
        """
        if extreme:
            mass = float(self.mass_upper if rng.integers(2) else self.mass_lower)
            if self.com_radius is None:
                return mass, np.where(rng.integers(0, 2, size=3) == 1, self.com_upper, self.com_lower).astype(float)
        else:
            mass = float(rng.uniform(self.mass_lower, self.mass_upper))
            if self.com_radius is None:
                return mass, rng.uniform(self.com_lower, self.com_upper)
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction) or 1.0
        radius = self.com_radius * (1.0 if extreme else rng.uniform() ** (1.0 / 3.0))  # uniform in the ball's volume
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
            fail(f"payload: give a mapping with mass, com_box or com_ball, inertia; got {doc!r}")
        unknown = set(doc) - {"mass", "com_box", "com_ball", "inertia"}
        if unknown:
            fail(f"payload: unknown key(s) {', '.join(sorted(unknown))}: use mass, com_box, com_ball, inertia")
        if "mass" not in doc:
            fail("payload: give its mass range, mass: [LO, HI] (kg)")
        lo, hi = pair(doc["mass"], "payload.mass", nonnegative=True)
        kwargs = {}
        if "com_box" in doc and "com_ball" in doc:
            fail("payload: give com_box or com_ball, not both")
        if "com_box" in doc:
            box = doc["com_box"] or {}
            kwargs.update(com_lower=box.get("lower"), com_upper=box.get("upper"))
        if "com_ball" in doc:
            ball = doc["com_ball"] or {}
            kwargs.update(com_centre=ball.get("centre", [0.0, 0.0, 0.0]), com_radius=ball.get("radius"))
            if kwargs["com_radius"] is None:
                fail("payload.com_ball: give its radius (m)")
        inertia = doc.get("inertia") or {"solid_sphere": 0.03}
        if not isinstance(inertia, dict) or len(inertia) != 1:
            fail("payload.inertia: give one of solid_sphere: R or solid_box: [A, B, C] (m)")
        ((key, size),) = inertia.items()
        kwargs.update(solid=str(key).removeprefix("solid_"), size=size)
        return cls(lo, hi, **kwargs)


def _product_range(*intervals) -> tuple[float, float]:
    corners = np.array(np.meshgrid(*intervals, indexing="ij")).reshape(len(intervals), -1)
    values = np.prod(corners, axis=0)
    return float(values.min()), float(values.max())


def _square_range(lo: float, hi: float) -> tuple[float, float]:
    low = 0.0 if lo <= 0.0 <= hi else min(lo * lo, hi * hi)
    return low, max(lo * lo, hi * hi)


def payload_sampling_words(body, shells: int = 4, per_shell: int = 160) -> str:
    """What :func:`payload_points` samples of the payload's set, in words (the covers line names it)."""
    if body.com_radius is not None:
        return (f"the payload's extremes sampled at its 2 end masses x {1 + shells * per_shell} centres of mass "
                f"(the ball's centre and {shells} spheres of {per_shell} points)")  # fmt: skip
    return (
        "the payload's extremes sampled at its 2 end masses x 343 centres of mass (a 7-point grid per axis of the box)"
    )


def payload_points(body, shells: int = 4, per_shell: int = 160) -> list[tuple[float, np.ndarray]]:
    """``(mass, com)`` points of the payload's set over which its scalars' extremes are taken (sampled).

    Each scalar's effect is linear in the mass at a fixed centre of mass, so
    the masses are the range's two ends; the centres of mass fill the ball
    (its centre and ``shells`` spheres of ``per_shell`` Fibonacci points) or
    the box (a 7-point grid per axis).
    """
    if body.com_radius is not None:
        k = np.arange(per_shell) + 0.5
        polar, azimuth = np.arccos(1 - 2 * k / per_shell), np.pi * (1 + 5**0.5) * k
        sphere = np.column_stack([np.cos(azimuth) * np.sin(polar), np.sin(azimuth) * np.sin(polar), np.cos(polar)])
        radii = body.com_radius * np.arange(1, shells + 1) / shells
        coms = np.vstack([np.zeros((1, 3))] + [r * sphere for r in radii]) + np.array(body.com_centre)
    else:
        axes = [np.linspace(lo, hi, 7) for lo, hi in zip(body.com_lower, body.com_upper)]
        coms = np.array(np.meshgrid(*axes, indexing="ij")).reshape(3, -1).T
    return [(mass, c) for mass in (body.mass_lower, body.mass_upper) for c in coms]


def payload_coordinates(body, mass: float, com) -> dict[str, float]:
    """The payload scalars' values (physical units, about the model's payload) of a payload ``(mass, com)``."""
    m0, c0, second0 = payload_middle(body)
    c = np.asarray(com, float)
    out = {"payload.mass": mass - m0}
    for i, axis in enumerate("xyz"):
        out[f"payload.m{axis}"] = mass * c[i] - m0 * c0[i]
    second = second_moment(mass, c) - second0
    for k, (i, j) in enumerate(SECOND_MOMENT_ENTRIES):
        out[f"payload.second{i}{j}"] = second[k]
    return out


def payload_middle(body) -> tuple[float, np.ndarray, np.ndarray]:
    """``(mass, com, second)``: the payload the inner layer computes with.

    The middle of its mass range at the centre of its centre-of-mass ball or
    box, and ``second`` the middle of the range of the parallel-axis part
    ``m S(c)^T S(c)`` of its inertia about the flange (six entries,
    :func:`~polyrob.uncertainty_set.payload_body.second_moment`): the
    middle of the set in the ten parameters, so that a payload whose centre
    of mass ranges off the last joint's axis is not modelled at the
    lightest end of its inertia about that axis.
    """
    mass = 0.5 * (body.mass_lower + body.mass_upper)
    if body.com_radius is not None:
        com = np.array(body.com_centre, float)
    else:
        com = 0.5 * (np.array(body.com_lower, float) + np.array(body.com_upper, float))
    lo, hi = body.second_moment_range()
    return mass, com, 0.5 * (lo + hi)
