"""Find and load robots by name or path: the catalogue of robots polyrob knows.

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
from collections.abc import Sequence
from pathlib import Path

from polyrob.errors import RobotError
from polyrob.model import analytic
from polyrob.model.base import Manipulator
from polyrob.model.urdf import DEFAULT_LOCK_PATTERN, Robot, load_urdf

__all__ = [
    "Manipulator",
    "Robot",
    "load_robot",
    "load_urdf",
    "resolve_urdf",
    "available_robots",
    "bundled_urdf_dir",
    "example_robot_data_dir",
    "DEFAULT_LOCK_PATTERN",
]

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


#: A name ending so is a path (a ``.xacro`` one is refused by load_urdf with the command that expands it).
_FILE_SUFFIXES = (".urdf", ".xacro")


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


# --------------------------------------------------------------------------- loading


def load_robot(source: str | Path = "planar_2r", *, lock: Sequence[str] | None = None, armature=None):
    """Load a robot, reduced to its actuated serial joints.

    Parameters
    ----------
    source : str or Path
        A path to a URDF file, the name of a bundled model (``planar_2r``, the
        analytic ``paper_2r``) or of a robot that ``example-robot-data`` ships
        (``panda``, ``ur5``, ``kinova``, ``z1``, ... or any URDF file stem there;
        a stem two files share names the first, the other by its path in
        example-robot-data without ``.urdf``, as :func:`available_robots` lists).
    lock : sequence of str, optional
        Joints to lock at their neutral position.  By default every joint whose
        name mentions a finger, gripper, hand or jaw; pass ``[]`` to lock none.
    armature : float, sequence or mapping joint -> float, optional
        Reflected rotor inertia added to the diagonal of ``M(q)``; replaces
        the SRDF's rotor parameters (``gear_ratio^2 * rotor_inertia``) for
        the joints given.  ``robot.reflected_inertia`` says what was used.

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
    >>> load_robot("talos_left_arm").reflected_inertia
    'from the SRDF (talos.srdf): gear ratio^2 x rotor inertia'
    >>> load_robot("no_such_robot")
    Traceback (most recent call last):
    ...
    polyrob.errors.RobotError: unknown robot 'no_such_robot': give a URDF path or one of the names `polyrob robots` lists
    """
    text = str(source)
    if text in analytic.ANALYTIC_ROBOTS:
        if armature is not None:
            raise RobotError(f"{text} is an analytic model: its M(q) is given as is, an armature cannot be added")
        return analytic.ANALYTIC_ROBOTS[text]()
    path = resolve_urdf(text)
    return load_urdf(path, name=_robot_name(text, path), lock=lock, armature=armature)


def _robot_name(text: str, path: Path) -> str:
    looks_like_path = text.endswith(_FILE_SUFFIXES) or Path(text).expanduser().is_file()
    return path.stem if looks_like_path else text


def resolve_urdf(text: str) -> Path:
    """The URDF file a robot name or path refers to."""
    candidate = Path(text).expanduser()
    if text.endswith(_FILE_SUFFIXES) or candidate.is_file():
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
        qualified = erd / f"{text}.urdf"
        if "/" in text and qualified.is_file():
            return qualified
        for path in sorted(erd.rglob(f"{text}.urdf")):
            return path
    if candidate.parent != Path("."):
        raise RobotError(f"{text}: no such URDF file")
    raise RobotError(f"unknown robot '{text}': give a URDF path or one of the names `polyrob robots` lists")


# --------------------------------------------------------------------------- listing


def available_robots() -> list[tuple[str, str]]:
    """Names that :func:`load_robot` accepts, with where they come from.

    Returns ``(name, origin)`` pairs, each name once: bundled URDFs and
    analytic models first, then the aliases of example-robot-data's serial
    arms, then every other URDF file there (which may still be refused, e.g.
    legged robots are trees).  A file whose stem is already taken (two
    ``anymal.urdf``) is listed by its path in example-robot-data without
    ``.urdf`` (``anymal_c_simple_description/urdf/anymal``), which
    :func:`load_robot` accepts too.
    """
    names = [(p.stem, "bundled") for p in sorted(bundled_urdf_dir().glob("*.urdf"))]
    names += [(n, "bundled (analytic)") for n in analytic.ANALYTIC_ROBOTS]
    erd = example_robot_data_dir()
    if erd is not None:
        names += [(alias, "example-robot-data") for alias in EXAMPLE_ROBOT_ALIASES]
        aliased = {Path(rel) for rel in EXAMPLE_ROBOT_ALIASES.values()}
        taken = {n for n, _ in names}
        # the same order as resolve_urdf: the first file of a stem owns the stem
        for path in sorted(erd.rglob("*.urdf")):
            rel = path.relative_to(erd)
            if rel in aliased:
                continue
            name = path.stem if path.stem not in taken else rel.with_suffix("").as_posix()
            taken.add(name)
            names.append((name, "example-robot-data"))
    return names
