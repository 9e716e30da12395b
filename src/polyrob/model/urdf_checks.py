"""Checks of a URDF's XML before any parser sees it: one line in words, nothing on stderr.

yourdfpy reports a missing attribute as ``KeyError: 'name'`` and Pinocchio's
C++ parser (urdfdom) prints its complaints on stderr and then says only that
the file "does not contain a valid URDF model".  The structure both rely on
is checked here first, on the lxml tree, so that the error names the element
and what it lacks; an unexpanded xacro file is recognised by its name or by
its ``xacro:`` elements and refused with the command that expands it.

Examples
--------
>>> from lxml import etree
>>> root = etree.fromstring('<robot name="r"><link name="a"/><joint type="fixed"/></robot>')
>>> check_structure("r.urdf", root)
Traceback (most recent call last):
...
polyrob.errors.RobotError: r.urdf: malformed URDF: a <joint> without a name attribute (the 1st <joint>): give every joint a unique name
"""

from __future__ import annotations

from pathlib import Path

from polyrob.errors import RobotError

__all__ = ["refuse_xacro_name", "check_structure", "describe_key_error", "JOINT_TYPES"]

JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")


def _expanded_name(path: Path) -> Path:
    if path.name.endswith(".urdf.xacro"):
        return path.with_name(path.name[: -len(".xacro")])
    if path.suffix == ".xacro":
        return path.with_suffix(".urdf")
    return path.with_name(f"{path.stem}_expanded.urdf")  # never overwrite the input


def xacro_error(path) -> RobotError:
    path = Path(path)
    out = _expanded_name(path)
    return RobotError(f"{path}: a xacro file must be expanded to URDF first: xacro {path} > {out}")


def refuse_xacro_name(path) -> None:
    """Refuse a path ending in ``.xacro`` (before anything parses it)."""
    if Path(path).suffix.lower() == ".xacro":
        raise xacro_error(path)


def _ordinal(k: int) -> str:
    suffix = "th" if 10 <= k % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(k % 10, "th")
    return f"{k}{suffix}"


def check_structure(path, root) -> None:
    """Refuse xacro content and the missing attributes or elements a URDF parser needs.

    ``root`` is the lxml root element (already known to be ``<robot>``).
    Raises :class:`~polyrob.errors.RobotError` naming the element.
    """
    for el in root.iter():
        tag = el.tag if isinstance(el.tag, str) else ""  # comments and processing instructions
        if (tag.startswith("{") and "xacro" in tag) or any("${" in v for v in el.attrib.values()):
            raise xacro_error(path)

    def bad(text):
        return RobotError(f"{path}: malformed URDF: {text}")

    if not root.get("name"):
        raise bad('the <robot> element has no name attribute: give it one (<robot name="...">)')
    links = set()
    for k, link in enumerate(root.findall("link"), 1):
        name = link.get("name")
        if not name:
            raise bad(f"a <link> without a name attribute (the {_ordinal(k)} <link>): give every link a unique name")
        links.add(name)
        mass = link.find("inertial/mass")
        if mass is not None and mass.get("value") is None:
            raise bad(f"link '{name}': <mass> has no value attribute")
        if link.find("inertial") is not None and link.find("inertial/inertia") is None:
            # a parser reads it as a point mass (urdfdom says so on stderr only): the dynamics would be another robot's
            raise RobotError(
                f"{path}: link '{name}' has an <inertial> without <inertia> (it would be read as a point mass): add "
                '<inertia ixx="..." iyy="..." izz="..." ixy="0" ixz="0" iyz="0"/> (kg m^2, about its centre of mass)'
            )
    for k, joint in enumerate(root.findall("joint"), 1):
        name = joint.get("name")
        if not name:
            raise bad(f"a <joint> without a name attribute (the {_ordinal(k)} <joint>): give every joint a unique name")
        jtype = joint.get("type")
        if jtype not in JOINT_TYPES:
            got = "no type attribute" if jtype is None else f"type '{jtype}'"
            raise bad(f"joint '{name}' has {got}: give type=\"{'|'.join(JOINT_TYPES)}\"")
        for end in ("parent", "child"):
            el = joint.find(end)
            if el is None:
                raise RobotError(f"{path}: joint '{name}' lacks a <parent> or <child> link")
            if not el.get("link"):
                raise bad(f"joint '{name}': <{end}> has no link attribute")
            if el.get("link") not in links:
                raise bad(f"joint '{name}': {end} link '{el.get('link')}' is not a <link> of the file")
        limit = joint.find("limit")
        if jtype in ("revolute", "prismatic"):
            if limit is None:
                raise bad(f"joint '{name}' is {jtype} but has no <limit> (effort and velocity are required)")
        if limit is not None:
            for attr in ("effort", "velocity"):
                if limit.get(attr) is None:
                    raise bad(f"joint '{name}': <limit> has no {attr} attribute")
        mimic = joint.find("mimic")
        if mimic is not None and not mimic.get("joint"):
            raise bad(f"joint '{name}': <mimic> has no joint attribute (the joint it follows)")


def describe_key_error(exc: KeyError) -> str:
    """A parser's ``KeyError: 'x'`` in words: an element lacks its ``x`` attribute."""
    key = exc.args[0] if exc.args else "?"
    return f"an element lacks its required '{key}' attribute"
