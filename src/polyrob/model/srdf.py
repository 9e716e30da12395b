"""What a robot's SRDF adds to its URDF: named poses and rotor parameters (reflected inertia).

example-robot-data ships an SRDF beside many URDFs (``<pkg>/srdf/<name>.srdf``
next to ``<pkg>/urdf/<name>.urdf``).  Two of its elements matter here:

* ``<group_state name="default">`` entries: named reference poses (panda
  ``default``, z1 ``home``, xarm7 ``home``, talos ``half_sitting``); the
  centre of a task domain (:mod:`polyrob.domains.task`);
* ``<rotor_params>``: per joint a rotor inertia (``mass``) and a gear ratio.
  The motor's rotor turns ``n`` times faster than the joint, so it adds
  ``n^2 J_rotor`` (the reflected inertia) to the joint's diagonal of ``M(q)``;
  Pinocchio adds ``model.armature`` there in ``crba``, ``aba``, ``rnea`` and
  their derivatives.

The file is read here with lxml (the same entries as Pinocchio's
``loadReferenceConfigurations`` and ``loadRotorParameters``, which print a
line for every joint of the SRDF that a reduced model no longer has), and
mapped onto the joints polyrob keeps.

Examples
--------
>>> from polyrob.model.robots import resolve_urdf
>>> srdf = find_srdf(resolve_urdf("panda"))
>>> srdf.name
'panda.srdf'
>>> sorted(read_srdf(srdf).poses)
['default']
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from polyrob.errors import RobotError

__all__ = ["SrdfData", "find_srdf", "read_srdf"]


@dataclass(frozen=True)
class SrdfData:
    """The entries of an SRDF polyrob uses.

    Attributes
    ----------
    path : str
    poses : dict
        ``name -> {joint: value}`` of every ``group_state``, in file order.
    rotors : dict
        ``joint -> (rotor inertia, gear ratio)`` of ``rotor_params``.
    """

    path: str
    poses: dict = field(default_factory=dict)
    rotors: dict = field(default_factory=dict)


def find_srdf(urdf: str | Path) -> Path | None:
    """The SRDF of a URDF: ``../srdf/STEM.srdf``, else the longest SRDF there whose stem starts the URDF's.

    ``ur5_robot.urdf`` finds ``ur5.srdf``, ``talos_left_arm.urdf`` finds
    ``talos.srdf``; a URDF without such a file has none (None).
    """
    urdf = Path(urdf)
    folder = urdf.parent.parent / "srdf"
    if not folder.is_dir():
        return None
    exact = folder / f"{urdf.stem}.srdf"
    if exact.is_file():
        return exact
    candidates = [p for p in folder.glob("*.srdf") if urdf.stem.startswith(p.stem + "_")]
    return max(candidates, key=lambda p: len(p.stem)) if candidates else None


def read_srdf(path: str | Path) -> SrdfData:
    """Named poses and rotor parameters of an SRDF file.

    Raises
    ------
    RobotError
        Malformed XML or a value that is not a number; the message names the file.
    """
    from lxml import etree

    path = Path(path)
    try:
        root = etree.parse(str(path)).getroot()
    except (OSError, etree.XMLSyntaxError) as exc:
        raise RobotError(f"{path}: cannot read the SRDF ({exc})") from None
    poses: dict = {}
    for state in root.iter("group_state"):
        name = state.get("name")
        if not name or name in poses:
            continue
        poses[name] = {j.get("name"): _number(path, j, "value") for j in state.iter("joint") if j.get("name")}
    rotors = {}
    for params in root.iter("rotor_params"):
        for j in params.iter("joint"):
            if j.get("name"):
                rotors[j.get("name")] = (_number(path, j, "mass"), _number(path, j, "gear_ratio"))
    return SrdfData(path=str(path), poses=poses, rotors=rotors)


def _number(path, element, attribute) -> float:
    text = element.get(attribute)
    try:
        return float(str(text).split()[0])
    except (ValueError, IndexError):
        raise RobotError(
            f"{path}: joint '{element.get('name')}' has {attribute}={text!r} in the SRDF: not a number"
        ) from None


def reference_poses(srdf: SrdfData | None, names, default) -> dict:
    """The SRDF's named poses on the joints ``names``: ``name -> tuple`` (joints a pose leaves out keep ``default``)."""
    if srdf is None:
        return {}
    out = {}
    for pose, values in srdf.poses.items():
        if not any(n in values for n in names):  # a pose of other joints (another group)
            continue
        out[pose] = tuple(float(values.get(n, d)) for n, d in zip(names, default))
    return out


def reflected_inertia(srdf: SrdfData | None, names, override=None):
    """The armature (reflected rotor inertia) per joint and where it comes from.

    Parameters
    ----------
    srdf : SrdfData or None
    names : sequence of str
        The joints kept.
    override : float, sequence or mapping joint -> float, optional
        Given values (>= 0, finite): they replace the SRDF's for the joints
        they name (a number or a sequence: every joint).

    Returns
    -------
    armature : list of float
        ``gear_ratio^2 * rotor_inertia`` from the SRDF, or the given values.
    source : str
        ``"from the SRDF (talos.srdf): gear ratio^2 x rotor inertia"``,
        ``"given"``, ``"given, the rest from the SRDF (...)"`` or
        ``"not modelled (no rotor data in the URDF/SRDF)"``.

    Examples
    --------
    >>> reflected_inertia(None, ["j1", "j2"], {"j2": 0.5})
    ([0.0, 0.5], 'given')
    """
    import math

    names = list(names)
    values = [0.0] * len(names)
    rotors = {} if srdf is None else srdf.rotors
    from_srdf = [n in rotors for n in names]
    for k, n in enumerate(names):
        if from_srdf[k]:
            inertia, ratio = rotors[n]
            values[k] = ratio**2 * inertia
    where = "" if srdf is None else Path(srdf.path).name
    source = f"from the SRDF ({where}): gear ratio^2 x rotor inertia" if any(from_srdf) else "not modelled (no rotor data in the URDF/SRDF)"
    if override is None:
        return values, source
    if isinstance(override, dict):
        unknown = [j for j in override if j not in names]
        if unknown:
            raise RobotError(f"armature: unknown joint(s) {', '.join(unknown)} (joints: {', '.join(names)})")
        given = {names.index(j): v for j, v in override.items()}
    elif isinstance(override, (int, float)):
        given = dict.fromkeys(range(len(names)), override)
    else:
        override = list(override)
        if len(override) != len(names):
            raise RobotError(f"armature: give 1 or {len(names)} values (one per joint), got {len(override)}")
        given = dict(enumerate(override))
    for k, v in given.items():
        try:
            v = float(v)
        except (TypeError, ValueError):
            raise RobotError(f"armature of joint '{names[k]}': {v!r} is not a number") from None
        if not (math.isfinite(v) and v >= 0):
            raise RobotError(f"armature of joint '{names[k]}' must be a finite number >= 0, got {v:g}")
        values[k] = v
    rest = [k for k in range(len(names)) if k not in given and from_srdf[k]]
    return values, ("given" if not rest else f"given, the rest from the SRDF ({where})")
