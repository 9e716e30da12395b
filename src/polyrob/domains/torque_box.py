"""The domain: a box over joint positions ``q``, velocities ``qdot`` and torques ``u``.

Defaults come from the robot's limits (URDF position, velocity and effort
limits; a continuous joint turns a full circle ``[-pi, pi]``).  Users override
them per joint or for all joints, scale them, or give the whole domain as a
JSON/YAML file::

    {"q":    {"joint2": [-3.14159, 3.14159]},
     "qdot": {"joint1": 4.0, "joint2": [-10, 10]},
     "u":    0.0}

A single number ``v >= 0`` means ``[-v, v]``; entries left out keep the defaults.
Every number must be finite.

Examples
--------
>>> from polyrob import load_robot, Domain
>>> robot = load_robot("planar_2r")
>>> dom = Domain.from_robot(robot, qdot_max=2.0, u_max={"joint2": 5.0})
>>> dom.qdot_upper, dom.u_upper
(array([2., 2.]), array([100.,   5.]))
>>> dom.dim
6
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from scipy.stats import qmc

from polyrob.domains.joint_box import JointBox
from polyrob.domains.spec import GROUP_TEXT, GROUPS, apply_spec, box_from_dict, read_spec
from polyrob.errors import DomainError

__all__ = ["Domain", "JointBox", "unit_design"]

_GROUP_OPTION = {"q": "--q-range JOINT=LO:HI", "qdot": "--qdot-max JOINT=VALUE", "u": "--u-max JOINT=VALUE"}
#: Largest URDF velocity limit (rad/s or m/s) taken as a default: some URDFs
#: state 1,000-10,000 rad/s (finger_edu, borinot_flying_arm_2), placeholders
#: that make the Jacobians ~1e7 and the bounds meaningless.
MAX_DEFAULT_VELOCITY = 100.0


@dataclass(frozen=True, eq=False)
class Domain(JointBox):
    """A box ``q_lower <= q <= q_upper``, ``qdot_lower <= qdot <= qdot_upper``, ``u_lower <= u <= u_upper``.

    Build it with :meth:`from_robot` (defaults from limits, with overrides),
    :meth:`from_file`, or directly from arrays.
    """

    joint_names: tuple[str, ...]
    q_lower: np.ndarray
    q_upper: np.ndarray
    qdot_lower: np.ndarray
    qdot_upper: np.ndarray
    u_lower: np.ndarray
    u_upper: np.ndarray
    name: str = field(default="custom")

    def __post_init__(self):
        m = len(self.joint_names)
        object.__setattr__(self, "joint_names", tuple(self.joint_names))
        for group in GROUPS:
            for side in ("lower", "upper"):
                attr = f"{group}_{side}"
                arr = np.array(getattr(self, attr), dtype=float).reshape(-1)
                if arr.size == 1:
                    arr = np.full(m, arr[0])
                if arr.shape != (m,):
                    raise DomainError(f"domain: {attr} has {arr.size} values for {m} joints")
                arr.setflags(write=False)
                object.__setattr__(self, attr, arr)
        for group in GROUPS:
            lo, hi = getattr(self, f"{group}_lower"), getattr(self, f"{group}_upper")
            for j, name in enumerate(self.joint_names):
                if not (np.isfinite(lo[j]) and np.isfinite(hi[j])):
                    raise DomainError(
                        f"domain: joint '{name}' has no finite {GROUP_TEXT[group]} limit "
                        f"({lo[j]}, {hi[j]}): give it with {_GROUP_OPTION[group]} or a domain file"
                    )
                if lo[j] > hi[j]:
                    raise DomainError(
                        f"domain: joint '{name}' has an inverted {GROUP_TEXT[group]} range "
                        f"[{lo[j]}, {hi[j]}]: give lower <= upper"
                    )

    def contains(self, q, qdot, u, *, atol: float = 0.0) -> np.ndarray:
        """Whether points (arrays (n, m)) lie in the box."""
        z = np.concatenate([np.atleast_2d(q), np.atleast_2d(qdot), np.atleast_2d(u)], axis=1)
        return np.all((z >= self.lower - atol) & (z <= self.upper + atol), axis=1)

    def clip(self, q, qdot, u):
        """Project points onto the box."""
        lo, hi = self.lower, self.upper
        z = np.clip(np.concatenate([np.atleast_2d(q), np.atleast_2d(qdot), np.atleast_2d(u)], axis=1), lo, hi)
        m = self.m
        return z[:, :m], z[:, m : 2 * m], z[:, 2 * m :]

    def split(self, z):
        """Split stacked points (n, 3m) into ``(q, qdot, u)``."""
        z = np.atleast_2d(z)
        m = self.m
        return z[:, :m], z[:, m : 2 * m], z[:, 2 * m :]

    # ------------------------------------------------------------------ the map to the dynamics
    #: ``"box"``: the third group is the torque itself (a task domain's is the acceleration).
    kind = "box"

    def inputs(self, q, qdot, w) -> np.ndarray:
        """The torques ``u`` at box points ``(q, qdot, w)``: here ``w`` itself.

        The seam the bounds search evaluates the Jacobians through: a
        :class:`~polyrob.domains.task.TaskDomain`'s third group is the
        acceleration, mapped to ``u`` by inverse dynamics.
        """
        return np.atleast_2d(np.asarray(w, dtype=float))

    def points(self, z) -> np.ndarray:
        """Box points ``z`` (n, 3m) as the points ``(q, qdot, u)`` (n, 3m) the Jacobians are taken at."""
        q, qdot, w = self.split(z)
        return np.hstack([q, qdot, self.inputs(q, qdot, w)])

    # ------------------------------------------------------------------ sampling
    def sample_box(self, n: int, *, method: str = "sobol", seed=None, groups=GROUPS) -> np.ndarray:
        """``n`` points of the box, stacked (n, 3m); see :meth:`sample`."""
        lo, hi = self.lower, self.upper
        m = self.m
        vary = np.concatenate([np.full(m, g in groups) for g in GROUPS]) & (hi > lo)
        k = int(vary.sum())
        z = np.tile(0.5 * (lo + hi), (n, 1))
        if k:
            unit = unit_design(n, k, method, seed)
            z[:, vary] = lo[vary] + unit * (hi[vary] - lo[vary])
        return z

    def sample(self, n: int, *, method: str = "sobol", seed=None, groups=GROUPS):
        """``n`` points of the box as ``(q, qdot, u)``, each of shape (n, m).

        Parameters
        ----------
        method : {"sobol", "halton", "lhs", "uniform"}
            A scrambled low-discrepancy design of :mod:`scipy.stats.qmc`, or
            independent uniform draws.
        groups : tuple
            The groups to vary; the others are set to the middle of their range.
        """
        return self.split(self.sample_box(n, method=method, seed=seed, groups=groups))

    # ------------------------------------------------------------------ building
    @classmethod
    def from_robot(
        cls,
        robot,
        domain: str | Path | Mapping | None = None,
        *,
        q_range=None,
        qdot_max=None,
        u_max=None,
        qdot_scale: float = 1.0,
        u_scale: float = 1.0,
    ) -> Domain:
        """The default domain of ``robot``, with overrides.

        Parameters
        ----------
        robot : Manipulator
        domain : str, Path or mapping, optional
            A domain file (JSON/YAML), a mapping of the same form, or the name
            of a domain the robot knows (``"paper"`` for ``paper_2r``).
        q_range : (lo, hi) or mapping joint -> (lo, hi), optional
        qdot_max, u_max : float, (lo, hi) or mapping joint -> either, optional
            A single number ``v`` means ``[-v, v]``.
        qdot_scale, u_scale : float
            Multiply the velocity / torque box (after overrides).
        """
        names = robot.joint_names
        q_lo = np.array(robot.position_lower, float)
        q_hi = np.array(robot.position_upper, float)
        for j, kind in enumerate(robot.joint_kinds):
            if kind == "continuous" and not (np.isfinite(q_lo[j]) and np.isfinite(q_hi[j])):
                q_lo[j], q_hi[j] = -np.pi, np.pi
        v = np.array(robot.velocity_limit, float)
        e = np.array(robot.effort_limit, float)
        bounds = {"q": [q_lo, q_hi], "qdot": [-v, v.copy()], "u": [-e, e.copy()]}
        source = f"{robot.name} limits"
        # Zero limits in a URDF mean "not given" (e.g. double_pendulum): refuse
        # them as defaults, but a user may set a zero-width range on purpose.
        given = {g: np.zeros(len(names), bool) for g in GROUPS}
        named = getattr(robot, "named_domains", {}) or {}
        if domain is None and getattr(robot, "default_domain", None):
            domain = robot.default_domain
        if domain is not None:
            if isinstance(domain, str) and domain in named:
                spec, source = named[domain], domain
            elif isinstance(domain, Mapping):
                spec, source = domain, "custom"
            else:
                spec, source = read_spec(domain, named), str(domain)
            apply_spec(bounds, given, names, spec, source)
        overrides = {"q": q_range, "qdot": qdot_max, "u": u_max}
        for group, value in overrides.items():
            if value is not None:
                apply_spec(bounds, given, names, {group: value}, f"--{group}")
                source = source if source != f"{robot.name} limits" else "custom"
        scales = {"q": 1.0, "qdot": qdot_scale, "u": u_scale}
        for group in ("qdot", "u"):
            scale = scales[group]
            if not (np.isfinite(scale) and scale >= 0):
                raise DomainError(f"domain: {group} scale must be a finite number >= 0, got {scale}")
            bounds[group] = [bounds[group][0] * scale, bounds[group][1] * scale]
        for j, name in enumerate(names):
            # a placeholder limit of the URDF, not a velocity the joint reaches
            top = max(abs(bounds["qdot"][0][j]), abs(bounds["qdot"][1][j]))
            if not given["qdot"][j] and top > MAX_DEFAULT_VELOCITY:
                raise DomainError(
                    f"{robot.source}: joint '{name}' has a default velocity limit of {top:g} (from its URDF), above the "
                    f"{MAX_DEFAULT_VELOCITY:g} polyrob takes as a default (likely a placeholder): give the "
                    f"velocity range with {_GROUP_OPTION['qdot']} (or --qdot-max VALUE for every joint) "
                    "or a domain file (--domain FILE)"
                )
        for group in GROUPS:
            lo, hi = bounds[group]
            for j, name in enumerate(names):
                zero = not given[group][j] and lo[j] == hi[j] and np.isfinite(lo[j])
                if zero and scales[group] == 0:
                    raise DomainError(
                        f"--{group}-scale 0 ({group}_scale=0) makes the {GROUP_TEXT[group]} range of joint "
                        f"'{name}' zero: give a scale > 0 (for a zero range on purpose, --{group}-max 0 instead)"
                    )
                if zero:
                    raise DomainError(
                        f"{robot.source}: joint '{name}' has a zero {GROUP_TEXT[group]} limit: "
                        f"give the domain with {_GROUP_OPTION[group]} or a domain file (--domain FILE)"
                    )
                if not (np.isfinite(lo[j]) and np.isfinite(hi[j])):
                    raise DomainError(
                        f"{robot.source}: joint '{name}' has no {GROUP_TEXT[group]} limit: "
                        f"give it with {_GROUP_OPTION[group]} or a domain file (--domain FILE)"
                    )
        return cls(names, *bounds["q"], *bounds["qdot"], *bounds["u"], name=source)

    @classmethod
    def from_file(cls, robot, path) -> Domain:
        """A domain file (JSON or YAML) for ``robot``; see :meth:`from_robot`."""
        return cls.from_robot(robot, Path(path))

    def with_bounds(self, **arrays) -> Domain:
        """A copy with some of ``q_lower``, ``q_upper``, ... replaced."""
        return replace(self, **arrays)

    # ------------------------------------------------------------------ serialisation
    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "joints": list(self.joint_names),
            **{
                g: {
                    n: [float(lo), float(hi)]
                    for n, lo, hi in zip(self.joint_names, getattr(self, f"{g}_lower"), getattr(self, f"{g}_upper"))
                }
                for g in GROUPS
            },
        }

    @classmethod
    def from_dict(cls, data: Mapping, *, source: str = "domain") -> Domain:
        """The domain :meth:`to_dict` wrote; ``source`` (e.g. the file it was read from) names it in errors."""
        try:
            names = tuple(data["joints"])
            arrays = box_from_dict(data, GROUPS, source)
        except (KeyError, TypeError) as exc:
            raise DomainError(f"{source}: not a domain as to_dict writes it (missing {exc})") from None
        return cls(names, *arrays, name=data.get("name", "custom"))

    def table(self) -> str:
        """A plain-text table of the box, one row per joint."""
        rows = [f"{'joint':<24}{'q':>26}{'qdot':>24}{'u':>24}"]
        for j, n in enumerate(self.joint_names):
            cells = [f"[{getattr(self, g + '_lower')[j]:.4g}, {getattr(self, g + '_upper')[j]:.4g}]" for g in GROUPS]
            rows.append(f"{n:<24}{cells[0]:>26}{cells[1]:>24}{cells[2]:>24}")
        return "\n".join(rows)


def unit_design(n, k, method, seed):
    """``n`` points of the unit cube ``[0, 1]^k`` (:meth:`Domain.sample`'s designs)."""
    if method == "uniform":
        return np.random.default_rng(seed).random((n, k))
    if method == "sobol":
        with warnings.catch_warnings():
            # Sobol' balance is exact for n = 2^k only; other n are still far
            # more even than independent draws, which is all we need here.
            warnings.simplefilter("ignore", UserWarning)
            return qmc.Sobol(k, scramble=True, seed=seed).random(n)
    if method == "halton":
        return qmc.Halton(k, scramble=True, seed=seed).random(n)
    if method == "lhs":
        return qmc.LatinHypercube(k, seed=seed).random(n)
    raise DomainError(f"unknown sampling method '{method}': use sobol, halton, lhs or uniform")
