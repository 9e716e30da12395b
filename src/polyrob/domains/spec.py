"""Domain specifications as users write them: files (JSON/YAML), option values, one joint's range.

A single number ``v >= 0`` means ``[-v, v]``; a pair is ``[lo, hi]``; a
mapping names joints, a nested list has one entry per joint.  Every error
names where the value came from (the file, the option, the joint).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from polyrob.errors import DomainError

__all__ = ["GROUPS", "GROUP_TEXT", "read_spec", "apply_spec", "joint_range", "box_from_dict"]

#: The groups of a torque-box domain, in the order of its box.
GROUPS = ("q", "qdot", "u")
#: Their names in errors (and a task domain's accelerations).
GROUP_TEXT = {"q": "position", "qdot": "velocity", "u": "torque", "qddot": "acceleration"}


def read_spec(path, named) -> Mapping:
    path = Path(path)
    if not path.is_file():
        known = ", ".join(named) if named else "none for this robot"
        raise DomainError(f"{path}: no such domain file (named domains: {known})")
    text = path.read_text()
    try:
        if path.suffix.lower() in (".yaml", ".yml"):
            import yaml

            try:
                spec = yaml.safe_load(text)
            except yaml.YAMLError as exc:
                raise ValueError(exc) from None
        else:
            spec = json.loads(text)
    except ValueError as exc:  # json/yaml syntax errors: a domain error
        raise DomainError(f"{path}: cannot read the domain file ({exc})") from None
    if not isinstance(spec, Mapping):
        raise DomainError(f"{path}: a domain file holds a mapping with keys q, qdot, u")
    return spec


def apply_spec(bounds, given, names, spec: Mapping, source: str):
    """Write the ranges of a domain spec into ``bounds`` (in place)."""
    unknown_groups = set(spec) - set(GROUPS) - {"name", "joints"}
    if unknown_groups:
        raise DomainError(f"{source}: unknown domain keys {sorted(unknown_groups)}: use q, qdot, u")
    for group in GROUPS:
        if group not in spec or spec[group] is None:
            continue
        value = spec[group]
        # an option (--qdot) names one group already; a file or mapping names the entry
        entry = "" if source.startswith("--") else f"'{group}' entry of "
        every = f"{source}: '{group}' entry (every joint)" if entry else f"{source}: every joint"
        if isinstance(value, Mapping) or _is_per_joint_list(value, len(names)):
            pairs = value.items() if isinstance(value, Mapping) else zip(names, value)
            items = ((joint, rng, f"{source}: {entry}joint '{joint}'") for joint, rng in pairs)
        else:
            items = ((joint, value, every) for joint in names)
        for joint, rng, where in items:
            if joint not in names:
                raise DomainError(f"{source}: unknown joint '{joint}' (joints: {', '.join(names)})")
            lo, hi = joint_range(rng, group, where)
            j = names.index(joint)
            bounds[group][0][j], bounds[group][1][j] = lo, hi
            given[group][j] = True


def _is_per_joint_list(value, m) -> bool:
    """A nested list holds one entry per joint; a flat list of two numbers is
    one ``[lo, hi]`` range for every joint; a flat list of ``m != 2`` numbers
    holds one symmetric bound per joint (use a mapping to be explicit)."""
    if isinstance(value, (str, bytes)) or np.ndim(value) == 0:
        return False
    if any(np.ndim(v) > 0 for v in value):
        return True
    return len(value) != 2 and len(value) == m


def joint_range(value, group, where):
    """``(lo, hi)`` of a bound ``V >= 0`` (``[-V, V]``) or a range ``[lo, hi]``; errors name ``where`` (file, group, joint)."""
    text = GROUP_TEXT[group]
    try:
        arr = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise DomainError(f"{where}: {text} range {value!r} is not numeric") from None
    if arr.size not in (1, 2):
        raise DomainError(f"{where}: give a {text} range as a number or [lo, hi]")
    if np.isnan(arr).any():
        raise DomainError(f"{where}: {text} range contains NaN: give finite numbers")
    if not np.isfinite(arr).all():
        shown = f"{arr[0]:g}" if arr.size == 1 else f"[{arr[0]:g}, {arr[1]:g}]"
        raise DomainError(
            f"{where}: {text} range {shown} is not finite: give a finite bound V (it means [-V, V]) "
            "or a range [lo, hi] of finite numbers"
        )
    if arr.size == 1:
        if arr[0] < 0:
            raise DomainError(
                f"{where}: a bound must be >= 0 (it means [-V, V]; give a range [lo, hi] otherwise), got {arr[0]:g}"
            )
        lo, hi = -arr[0], arr[0]
    else:
        lo, hi = arr
    if lo > hi:
        raise DomainError(f"{where}: {text} range [{lo:g}, {hi:g}] is inverted: give lower <= upper")
    return float(lo), float(hi)


def box_from_dict(data, groups, source: str) -> list[np.ndarray]:
    """``[lower, upper]`` arrays of each group of a box as a domain's ``to_dict`` writes it (``data[group][joint]``).

    Raises ``KeyError`` or ``TypeError`` where an entry is missing (the caller
    names what it reads), :class:`DomainError` where one is not a range.
    """
    arrays = []
    for g in groups:
        pairs = [joint_range(data[g][n], g, f"{source}: '{g}' entry of joint '{n}'") for n in data["joints"]]
        arrays += [np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])]
    return arrays
