"""Find and load robots, reduced to their actuated serial joints.

A robot comes from a URDF file, from a robot that ``example-robot-data`` ships
(found through its installed share folder), from a URDF bundled with polyrob
(``urdf/``), or from an analytic model (:mod:`polyrob.model.analytic`, e.g. the
paper's printed ``paper_2r``).  Whatever the source, the result is a
:class:`Manipulator`: ``m`` joints, the joint limits of the URDF, and the
dynamics ``xdot = f(x, u)`` with ``x = (q, qdot)`` and its Jacobians.

Examples
--------
>>> from polyrob import load_robot
>>> robot = load_robot("planar_2r")
>>> robot.m, robot.joint_names
(2, ('joint1', 'joint2'))
>>> robot.mass_matrix([0.0, 0.0]).round(3)
array([[60.625, 19.375],
       [19.375, 13.125]])
"""

from __future__ import annotations

import functools
import importlib.metadata
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np
import pinocchio

from polyrob.model import dynamics
from polyrob.errors import RobotError

__all__ = [
    "Manipulator",
    "Robot",
    "load_robot",
    "available_robots",
    "bundled_urdf_dir",
    "example_robot_data_dir",
    "DEFAULT_LOCK_PATTERN",
]

#: Joints whose name matches this pattern are locked by default: grippers and
#: fingers are not part of the arm's serial dynamics.
DEFAULT_LOCK_PATTERN = re.compile(r"finger|gripper|hand|jaw", re.IGNORECASE)

#: Short names of the serial arms of example-robot-data (relative URDF paths
#: under its ``robots`` folder).  Every other URDF there is reachable by its
#: file stem, e.g. ``ur5_joint_limited_robot``.
EXAMPLE_ROBOT_ALIASES = {
    "panda": "panda_description/urdf/panda.urdf",
    "ur3": "ur_description/urdf/ur3_robot.urdf",
    "ur5": "ur_description/urdf/ur5_robot.urdf",
    "ur10": "ur_description/urdf/ur10_robot.urdf",
    "kinova": "kinova_description/robots/kinova.urdf",
    "z1": "z1_description/urdf/z1.urdf",
    "xarm7": "xarm_description/urdf/xarm7.urdf",
    "so100": "so_arm_description/urdf/so100.urdf",
    "so101": "so_arm_description/urdf/so101.urdf",
    "talos_left_arm": "talos_data/robots/talos_left_arm.urdf",
    "double_pendulum": "double_pendulum_description/urdf/double_pendulum.urdf",
    "finger_edu": "finger_edu_description/robots/finger_edu.urdf",
    "TwoDofs": "asr_twodof_description/urdf/TwoDofs.urdf",
}

JOINT_KINDS = ("revolute", "continuous", "prismatic")


def bundled_urdf_dir() -> Path:
    """The folder of the URDFs bundled with polyrob (the repository's ``urdf/``)."""
    return Path(__file__).resolve().parent.parent / "urdf"


@functools.lru_cache(maxsize=1)
def example_robot_data_dir() -> Path | None:
    """The ``robots`` folder of the installed ``example-robot-data``, or None.

    example-robot-data 6.x ships URDFs only, no Python loader: its files are
    found through the distribution's record of ``package.xml``.
    """
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        return None
    for f in dist.files or ():
        if str(f).endswith("share/example-robot-data/package.xml"):
            return Path(dist.locate_file(f)).parent / "robots"
    return None


class Manipulator:
    """What every robot model offers: joints, limits, ``f(x, u)`` and its Jacobians.

    Subclasses fill the attributes below and implement :meth:`mass_matrix`,
    :meth:`acceleration` and :meth:`jacobians_batch`; the rest is shared.

    Attributes
    ----------
    name : str
    source : str
        Where the model came from (a path, or a description).
    joint_names : tuple of str
    joint_kinds : tuple of str
        ``"revolute"``, ``"continuous"`` (angle is the coordinate) or ``"prismatic"``.
    position_lower, position_upper, velocity_limit, effort_limit : ndarray
        Limits as the model states them, NaN where it gives none.
    damping : ndarray
        Viscous damping per joint (the diagonal of ``D``).
    """

    name: str
    source: str
    joint_names: tuple[str, ...]
    joint_kinds: tuple[str, ...]
    position_lower: np.ndarray
    position_upper: np.ndarray
    velocity_limit: np.ndarray
    effort_limit: np.ndarray
    damping: np.ndarray
    locked: tuple[str, ...] = ()

    @property
    def m(self) -> int:
        """Number of actuated joints (the state has ``2 m`` entries)."""
        return len(self.joint_names)

    @property
    def state_names(self) -> tuple[str, ...]:
        return tuple(f"q_{n}" for n in self.joint_names) + tuple(
            f"qdot_{n}" for n in self.joint_names
        )

    def mass_matrix(self, q) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def acceleration(self, q, qdot, u) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def jacobians_batch(self, q, qdot, u):  # pragma: no cover - abstract
        raise NotImplementedError

    def f(self, x, u) -> np.ndarray:
        """State derivative ``xdot = f(x, u)`` with ``x = (q, qdot)``."""
        x = np.asarray(x, dtype=float)
        m = self.m
        return np.concatenate([x[m:], self.acceleration(x[:m], x[m:], u)])

    def jacobians(self, q, qdot, u) -> tuple[np.ndarray, np.ndarray]:
        """``A = df/dx`` (2m x 2m) and ``B = df/du`` (2m x m) at one point."""
        A, B = self.jacobians_batch(
            np.atleast_2d(q), np.atleast_2d(qdot), np.atleast_2d(u)
        )
        return A[0], B[0]

    def describe(self) -> dict:
        """Joints and limits as plain data (for ``polyrob info --json``)."""
        return {
            "name": self.name,
            "source": self.source,
            "m": self.m,
            "joints": [
                {
                    "name": n,
                    "kind": k,
                    "position": [_none(lo), _none(hi)],
                    "velocity": _none(v),
                    "effort": _none(e),
                    "damping": float(d),
                }
                for n, k, lo, hi, v, e, d in zip(
                    self.joint_names,
                    self.joint_kinds,
                    self.position_lower,
                    self.position_upper,
                    self.velocity_limit,
                    self.effort_limit,
                    self.damping,
                )
            ],
        }


def _none(x):
    return None if not np.isfinite(x) else float(x)


@dataclass(frozen=True, eq=False)
class Robot(Manipulator):
    """A serial robot from URDF: the Pinocchio model reduced to its actuated joints.

    Build it with :func:`load_robot`.  ``model`` has exactly ``m`` one-degree
    of freedom joints in a chain (``model.parents[i] == i - 1``); locked joints
    (grippers, fingers) and fixed joints are folded into the links.
    """

    name: str
    source: str
    model: pinocchio.Model = field(repr=False)
    joint_names: tuple[str, ...]
    joint_kinds: tuple[str, ...]
    position_lower: np.ndarray = field(repr=False)
    position_upper: np.ndarray = field(repr=False)
    velocity_limit: np.ndarray = field(repr=False)
    effort_limit: np.ndarray = field(repr=False)
    damping: np.ndarray = field(repr=False)
    locked: tuple[str, ...] = ()

    @functools.cached_property
    def _data(self) -> pinocchio.Data:
        return self.model.createData()

    def configuration(self, q) -> np.ndarray:
        """Pinocchio configuration(s) for joint coordinates ``q`` (shape (..., m)).

        Continuous joints store ``(cos q, sin q)`` in Pinocchio; the others
        store ``q`` itself.
        """
        return dynamics.to_configuration(self, q)

    def mass_matrix(self, q) -> np.ndarray:
        """The joint-space inertia matrix ``M(q)`` (full, symmetric)."""
        M = pinocchio.crba(self.model, self._data, self.configuration(q)).copy()
        return np.triu(M) + np.triu(M, 1).T

    def acceleration(self, q, qdot, u) -> np.ndarray:
        """``qddot = M(q)^-1 (u - C(q, qdot) qdot - g(q) - D qdot)``."""
        return dynamics.acceleration(self, q, qdot, u)

    def jacobians_batch(self, q, qdot, u):
        """Jacobians at many points: arrays (n, 2m, 2m) and (n, 2m, m).

        See :func:`polyrob.model.dynamics.jacobians_batch`.
        """
        return dynamics.jacobians_batch(self, q, qdot, u)


# --------------------------------------------------------------------------- loading


def load_robot(source: str | Path = "planar_2r", *, lock: Sequence[str] | None = None):
    """Load a robot, reduced to its actuated serial joints.

    Parameters
    ----------
    source : str or Path
        A path to a URDF file, the name of a bundled model (``planar_2r``, the
        analytic ``paper_2r``) or of a robot that ``example-robot-data`` ships
        (``panda``, ``ur5``, ``kinova``, ``z1``, ... or any URDF file stem there).
    lock : sequence of str, optional
        Joints to lock at their neutral position.  By default every joint whose
        name mentions a finger, gripper, hand or jaw; pass ``[]`` to lock none.

    Returns
    -------
    Manipulator
        A :class:`Robot` for URDF sources, an
        :class:`~polyrob.model.analytic.AnalyticRobot` for analytic models.

    Raises
    ------
    RobotError
        Missing or malformed file, floating base, branching tree, unknown
        joint to lock, or no actuated joint; the message names the file.

    Examples
    --------
    >>> load_robot("panda").m      # fingers locked by default
    7
    >>> load_robot("no_such_robot")
    Traceback (most recent call last):
    ...
    polyrob.errors.RobotError: unknown robot 'no_such_robot': give a URDF path or one of the names `polyrob robots` lists
    """
    from polyrob.model import analytic  # analytic models are bundled by name too

    text = str(source)
    if text in analytic.ANALYTIC_ROBOTS:
        return analytic.ANALYTIC_ROBOTS[text]()
    path = resolve_urdf(text)
    return load_urdf(path, name=_robot_name(text, path), lock=lock)


def _robot_name(text: str, path: Path) -> str:
    looks_like_path = text.endswith(".urdf") or "/" in text or "\\" in text
    return path.stem if looks_like_path else text


def resolve_urdf(text: str) -> Path:
    """The URDF file a robot name or path refers to."""
    candidate = Path(text).expanduser()
    if text.endswith(".urdf") or candidate.parent != Path("."):
        if not candidate.is_file():
            raise RobotError(f"{text}: no such URDF file")
        return candidate
    bundled = bundled_urdf_dir() / f"{text}.urdf"
    if bundled.is_file():
        return bundled
    erd = example_robot_data_dir()
    if erd is not None:
        if text in EXAMPLE_ROBOT_ALIASES:
            return erd / EXAMPLE_ROBOT_ALIASES[text]
        for path in sorted(erd.rglob(f"{text}.urdf")):
            return path
    if candidate.is_file():
        return candidate
    raise RobotError(
        f"unknown robot '{text}': give a URDF path or one of the names `polyrob robots` lists"
    )


def load_urdf(path: str | Path, *, name: str | None = None, lock=None) -> Robot:
    """Load a URDF file into a :class:`Robot` (see :func:`load_robot`)."""
    path = Path(path)
    joints = _read_urdf_joints(path)
    model = _build_model(path)
    if lock is None:
        lock_names = [j for j in joints if DEFAULT_LOCK_PATTERN.search(j)]
        if len(lock_names) == len(joints):
            # The robot *is* a finger (finger_edu): nothing to lock.
            lock_names = []
    else:
        lock_names = list(lock)
        unknown = [j for j in lock_names if not model.existJointName(j)]
        if unknown:
            raise RobotError(
                f"{path}: cannot lock {', '.join(unknown)}: no such movable joint "
                f"(movable joints: {', '.join(model.names[1:])})"
            )
    # Mimic joints follow another joint: they are not actuated; lock them too.
    lock_names += [j for j, info in joints.items() if info["mimic"] and j not in lock_names]
    lock_ids = [model.getJointId(j) for j in lock_names if model.existJointName(j)]
    if lock_ids:
        reference = _clipped_neutral(model)
        _rename_locked(model, lock_ids)
        model = pinocchio.buildReducedModel(model, lock_ids, reference)
    if model.njoints <= 1:
        raise RobotError(f"{path}: no actuated joint is left (locked: {', '.join(lock_names) or 'none'})")
    kinds = []
    for i in range(1, model.njoints):
        jname, joint = model.names[i], model.joints[i]
        if model.parents[i] != i - 1:
            raise RobotError(
                f"{path}: joint '{jname}' branches off joint "
                f"'{model.names[model.parents[i]]}': polyrob needs a serial chain "
                "(lock the other branches with lock=[...] / --lock)"
            )
        kinds.append(_joint_kind(path, jname, joint))
    names = tuple(model.names[1:])
    lower = np.full(len(names), np.nan)
    upper = np.full(len(names), np.nan)
    velocity = np.full(len(names), np.nan)
    effort = np.full(len(names), np.nan)
    damping = np.zeros(len(names))
    for k, jname in enumerate(names):
        info = joints[jname]
        lim = info["limit"]
        if kinds[k] != "continuous" and lim is not None:
            lower[k], upper[k] = _num(lim.lower), _num(lim.upper)
        if lim is not None:
            velocity[k], effort[k] = _num(lim.velocity), _num(lim.effort)
        damping[k] = _num(info["damping"], default=0.0)
    model.damping[:] = damping
    return Robot(
        name=name or path.stem,
        source=str(path),
        model=model,
        joint_names=names,
        joint_kinds=tuple(kinds),
        position_lower=lower,
        position_upper=upper,
        velocity_limit=velocity,
        effort_limit=effort,
        damping=damping,
        locked=tuple(lock_names),
    )


def _num(value, default=np.nan) -> float:
    if value is None:
        return default
    try:
        return float(value)
    except (TypeError, ValueError):
        return default


def _read_urdf_joints(path: Path) -> dict:
    """Validate the XML strictly and read the movable joints with yourdfpy."""
    from lxml import etree
    import yourdfpy

    if not path.is_file():
        raise RobotError(f"{path}: no such URDF file")
    try:
        root = etree.parse(str(path)).getroot()
    except etree.XMLSyntaxError as exc:
        raise RobotError(f"{path}: malformed URDF ({exc})") from None
    if root.tag != "robot":
        raise RobotError(f"{path}: not a URDF file (root element <{root.tag}>, expected <robot>)")
    for joint in root.findall("joint"):
        jtype = joint.get("type")
        if jtype in ("floating", "planar"):
            raise RobotError(
                f"{path}: joint '{joint.get('name')}' is {jtype}: polyrob needs a fixed base "
                "and one-degree-of-freedom joints"
            )
        if joint.find("parent") is None or joint.find("child") is None:
            raise RobotError(f"{path}: joint '{joint.get('name')}' lacks a <parent> or <child> link")
    try:
        urdf = yourdfpy.URDF.load(str(path), build_scene_graph=False, load_meshes=False)
    except Exception as exc:  # yourdfpy raises bare Exceptions of many kinds
        raise RobotError(f"{path}: malformed URDF ({exc})") from None
    joints = {}
    for joint in urdf.robot.joints:
        if joint.type in ("fixed",):
            continue
        joints[joint.name] = {
            "type": joint.type,
            "limit": joint.limit,
            "mimic": joint.mimic is not None,
            "damping": joint.dynamics.damping if joint.dynamics is not None else None,
        }
    if not joints:
        raise RobotError(f"{path}: the URDF has no movable joint")
    return joints


def _build_model(path: Path) -> pinocchio.Model:
    try:
        return pinocchio.buildModelFromUrdf(str(path))
    except Exception as exc:  # pinocchio raises ValueError/RuntimeError variants
        raise RobotError(f"{path}: Pinocchio cannot build a model ({exc})") from None


def _rename_locked(model: pinocchio.Model, joint_ids) -> None:
    """Give locked joints (and their joint frames) unique names.

    Pinocchio's ``buildReducedModel`` looks joint frames up by name and fails
    ("Several frames match the filter") when a link has the same name as the
    joint, as so100's ``gripper`` does.
    """
    for jid in joint_ids:
        old = model.names[jid]
        new = f"__locked__{old}"
        for frame in model.frames:
            if frame.name == old and frame.type == pinocchio.FrameType.JOINT:
                frame.name = new
        model.names[jid] = new


def _clipped_neutral(model: pinocchio.Model) -> np.ndarray:
    q = pinocchio.neutral(model)
    lo, hi = model.lowerPositionLimit, model.upperPositionLimit
    ok = np.isfinite(lo) & np.isfinite(hi) & (lo < hi)
    q[ok] = np.clip(q[ok], lo[ok], hi[ok])
    return q


_KIND_BY_SHORTNAME = {
    "JointModelRX": "revolute",
    "JointModelRY": "revolute",
    "JointModelRZ": "revolute",
    "JointModelRevoluteUnaligned": "revolute",
    "JointModelRUBX": "continuous",
    "JointModelRUBY": "continuous",
    "JointModelRUBZ": "continuous",
    "JointModelRevoluteUnboundedUnaligned": "continuous",
    "JointModelPX": "prismatic",
    "JointModelPY": "prismatic",
    "JointModelPZ": "prismatic",
    "JointModelPrismaticUnaligned": "prismatic",
}


def _joint_kind(path: Path, name: str, joint) -> str:
    short = joint.shortname()
    if short == "JointModelFreeFlyer":
        raise RobotError(f"{path}: joint '{name}' is a floating base: polyrob needs a fixed base")
    kind = _KIND_BY_SHORTNAME.get(short)
    if kind is None:
        raise RobotError(
            f"{path}: joint '{name}' ({short}) is not a one-degree-of-freedom "
            "revolute, continuous or prismatic joint"
        )
    return kind


# --------------------------------------------------------------------------- listing


def available_robots() -> list[tuple[str, str]]:
    """Names that :func:`load_robot` accepts, with where they come from.

    Returns ``(name, origin)`` pairs: bundled URDFs and analytic models first,
    then the aliases of example-robot-data's serial arms, then every other
    URDF file there (which may still be refused, e.g. legged robots are trees).
    """
    from polyrob.model import analytic

    names = [(p.stem, "bundled") for p in sorted(bundled_urdf_dir().glob("*.urdf"))]
    names += [(n, "bundled (analytic)") for n in analytic.ANALYTIC_ROBOTS]
    erd = example_robot_data_dir()
    if erd is not None:
        aliased = set()
        for alias, rel in EXAMPLE_ROBOT_ALIASES.items():
            names.append((alias, "example-robot-data"))
            aliased.add(Path(rel).stem)
        for path in sorted(erd.rglob("*.urdf"), key=lambda p: p.stem):
            if path.stem not in aliased and path.stem not in EXAMPLE_ROBOT_ALIASES:
                names.append((path.stem, "example-robot-data"))
    return names
