"""URDF robots: the Pinocchio model reduced to the actuated serial joints.

:func:`load_urdf` reads a URDF file strictly (lxml, then yourdfpy for the
joints), builds the Pinocchio model, locks grippers, fingers and mimic joints
at their neutral position, checks that a serial chain of one-degree-of-freedom
joints is left and that the inertial data are physical
(:mod:`polyrob.model.physical`), and returns a :class:`Robot`.  The XML is
checked (:mod:`polyrob.model.urdf_checks`) before Pinocchio's C++ parser
sees it: an unexpanded xacro file or a missing attribute is one line in words.

Mimic joints are not modelled (Pinocchio reads them, but its dynamics
derivatives refuse them).  The follower of a locked joint (a gripper's second
finger) is locked with it; the follower of an actuated joint is refused with
the ``--lock`` option that fixes it, and once locked on purpose
:attr:`Robot.notes` names it (``polyrob info`` and every result print it).

Examples
--------
>>> from polyrob.model.robots import resolve_urdf
>>> robot = load_urdf(resolve_urdf("planar_2r"))
>>> robot.m, robot.locked
(2, ())
"""

from __future__ import annotations

import functools
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio

from polyrob.errors import RobotError
from polyrob.model import dynamics, physical, srdf, urdf_checks
from polyrob.model.base import Manipulator

__all__ = ["Robot", "load_urdf", "DEFAULT_LOCK_PATTERN", "JOINT_KINDS"]

#: Joints whose name matches this pattern are locked by default: grippers and
#: fingers are not part of the arm's serial dynamics.
DEFAULT_LOCK_PATTERN = re.compile(r"finger|gripper|hand|jaw", re.IGNORECASE)

JOINT_KINDS = ("revolute", "continuous", "prismatic")


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
    notes: tuple[str, ...] = ()
    armature: np.ndarray = field(default=None, repr=False)
    reflected_inertia: str = "not modelled (no rotor data in the URDF/SRDF)"
    srdf: str | None = None
    reference_poses: dict = field(default_factory=dict, repr=False)

    def __post_init__(self):
        if self.armature is None:
            object.__setattr__(self, "armature", np.zeros(len(self.joint_names)))

    @functools.cached_property
    def _data(self) -> pinocchio.Data:
        return self.model.createData()

    def __getstate__(self):
        # the cached Pinocchio data are scratch space: a copy (e.g. in a
        # worker process) builds its own
        state = dict(self.__dict__)
        state.pop("_data", None)
        return state

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

    def inverse_dynamics(self, q, qdot, qddot) -> np.ndarray:
        """Torques (n, m) that give ``qddot`` at ``(q, qdot)``; see :func:`polyrob.model.dynamics.inverse_dynamics`."""
        return dynamics.inverse_dynamics(self, q, qdot, qddot)

    def jacobians_batch(self, q, qdot, u):
        """Jacobians at many points: arrays (n, 2m, 2m) and (n, 2m, m).

        See :func:`polyrob.model.dynamics.jacobians_batch`.
        """
        return dynamics.jacobians_batch(self, q, qdot, u)


def load_urdf(path: str | Path, *, name: str | None = None, lock=None, armature=None) -> Robot:
    """Load a URDF file into a :class:`Robot` (see :func:`load_robot`).

    The SRDF beside it (:func:`polyrob.model.srdf.find_srdf`) gives the named
    reference poses and the rotor parameters: ``model.armature`` is set to
    ``gear_ratio^2 * rotor_inertia`` of the kept joints, or to ``armature``
    (a number, one per joint, or ``joint -> value``) where given.
    """
    path = Path(path)
    urdf_checks.refuse_xacro_name(path)  # before any parser prints on stderr
    joints, links = _read_urdf(path)
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
    _refuse_followed_mimics(path, joints, lock_names)
    # Mimic joints of locked joints (a gripper's second finger) follow them: lock them too.
    lock_names += [j for j, info in joints.items() if info["mimic"] and j not in lock_names]
    lock_ids = [model.getJointId(j) for j in lock_names if model.existJointName(j)]
    notes = []
    if lock_ids:
        reference = _clipped_neutral(model)
        notes = _mimic_notes(model, joints, lock_names, reference)
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
    # physical data last: a tree or a floating base is the clearer message
    physical.check_urdf_links(path, links)
    physical.check_mass_matrix(path, model)
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
    srdf_path = srdf.find_srdf(path)
    srdf_data = None if srdf_path is None else srdf.read_srdf(srdf_path)
    reflected, reflected_source = srdf.reflected_inertia(srdf_data, names, armature)
    model.armature[:] = reflected
    for k, jname in enumerate(names):
        if srdf_data is not None and jname in srdf_data.rotors:
            model.rotorInertia[k], model.rotorGearRatio[k] = srdf_data.rotors[jname]
    centre = np.where(np.isfinite(lower) & np.isfinite(upper), np.clip(0.0, lower, upper), 0.0)
    poses = srdf.reference_poses(srdf_data, names, centre)
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
        notes=tuple(notes),
        armature=np.array(reflected, float),
        reflected_inertia=reflected_source,
        srdf=None if srdf_path is None else str(srdf_path),
        reference_poses=poses,
    )


def _refuse_followed_mimics(path: Path, joints: dict, lock_names: list) -> None:
    """Refuse a mimic joint that follows an actuated joint, unless it is locked on purpose (``lock``).

    Pinocchio reads ``<mimic>`` (``buildModelFromUrdf(..., mimic=True)``), but
    its dynamics derivatives, which the bounds need, refuse mimic joints; so
    polyrob cannot model one.  Locking it silently would certify another
    robot: the user chooses, with the option the message gives.
    """
    followed = [
        (j, info["mimic"])
        for j, info in joints.items()
        if info["mimic"] and j not in lock_names and info["mimic"][0] in joints and info["mimic"][0] not in lock_names
    ]
    if not followed:
        return
    jname, (leader, factor, offset) = followed[0]
    mimics = [j for j, _ in followed]
    option = ",".join(dict.fromkeys([*lock_names, *mimics]))
    both = ",".join(dict.fromkeys([*lock_names, *mimics, *(m[0] for _, m in followed)]))
    raise RobotError(
        f"{path}: joint '{jname}' mimics actuated joint '{leader}' (q = {factor:g} * q_{leader} + {offset:g}) and "
        f"polyrob cannot model mimic joints: give --lock {option} to run on the robot with "
        f"{', '.join(repr(j) for j in mimics)} fixed at its neutral position (or --lock {both} to fix both)"
    )


def _mimic_notes(model, joints, lock_names, reference) -> list[str]:
    """One note per mimic joint locked: what it follows and where it is fixed."""
    notes = []
    for jname in lock_names:
        mimic = joints.get(jname, {}).get("mimic")
        if not mimic or not model.existJointName(jname):
            continue
        joint = model.joints[model.getJointId(jname)]
        q = reference[joint.idx_q : joint.idx_q + joint.nq]
        value = float(np.arctan2(q[1], q[0])) if joint.nq == 2 else float(q[0])
        leader, factor, offset = mimic
        if leader in lock_names or leader not in joints:
            why = "locked too" if leader in lock_names else "not a movable joint"
            notes.append(f"mimic joint '{jname}' (follows '{leader}', {why}) is locked at q = {value:.4g}")
            continue
        note = (
            f"mimic joint '{jname}' follows actuated joint '{leader}' (q = {factor:g} * q_{leader} + {offset:g}) "
            f"in the URDF; it is locked as asked (lock/--lock) at q = {value:.4g}, so every result is for the "
            f"robot with '{jname}' fixed while '{leader}' moves"
        )
        notes.append(note)
    return notes


def _num(value, default=np.nan) -> float:
    if value is None:
        return default
    try:
        return float(value)
    except (TypeError, ValueError):
        return default


def _read_urdf(path: Path) -> tuple[dict, list]:
    """Validate the XML strictly; read the movable joints and the links with yourdfpy."""
    import yourdfpy
    from lxml import etree

    if not path.is_file():
        raise RobotError(f"{path}: no such URDF file")
    try:
        root = etree.parse(str(path)).getroot()
    except etree.XMLSyntaxError as exc:
        raise RobotError(f"{path}: malformed URDF ({exc})") from None
    if root.tag != "robot":
        raise RobotError(f"{path}: not a URDF file (root element <{root.tag}>, expected <robot>)")
    urdf_checks.check_structure(path, root)
    for joint in root.findall("joint"):
        jtype = joint.get("type")
        if jtype in ("floating", "planar"):
            raise RobotError(
                f"{path}: joint '{joint.get('name')}' is {jtype}: polyrob needs a fixed base "
                "and one-degree-of-freedom joints"
            )
    try:
        urdf = yourdfpy.URDF.load(str(path), build_scene_graph=False, load_meshes=False)
    except KeyError as exc:  # yourdfpy's way of saying an attribute is missing
        raise RobotError(f"{path}: malformed URDF: {urdf_checks.describe_key_error(exc)}") from None
    except (ValueError, TypeError, AttributeError, IndexError, OSError, etree.LxmlError) as exc:
        # yourdfpy reports missing attributes as KeyError/AttributeError, bad numbers as ValueError
        raise RobotError(f"{path}: malformed URDF ({type(exc).__name__}: {exc})") from None
    joints = {}
    for joint in urdf.robot.joints:
        if joint.type in ("fixed",):
            continue
        joints[joint.name] = {
            "type": joint.type,
            "limit": joint.limit,
            "mimic": None if joint.mimic is None else _mimic_of(joint.mimic),
            "damping": joint.dynamics.damping if joint.dynamics is not None else None,
        }
    if not joints:
        raise RobotError(f"{path}: the URDF has no movable joint")
    return joints, list(urdf.robot.links)


def _mimic_of(mimic) -> tuple[str, float, float]:
    """``(leader, multiplier, offset)`` of a yourdfpy ``<mimic>``."""
    return mimic.joint, _num(mimic.multiplier, default=1.0), _num(mimic.offset, default=0.0)


def _build_model(path: Path) -> pinocchio.Model:
    try:
        return pinocchio.buildModelFromUrdf(str(path))
    except (ValueError, RuntimeError) as exc:  # Pinocchio's parser errors
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
            f"{path}: joint '{name}' ({short}) is not a one-degree-of-freedom revolute, continuous or prismatic joint"
        )
    return kind
