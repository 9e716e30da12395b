"""Is a controller file made for the problem it is analysed on?

A controller file records the robot, the domain, the weight
hyperparameters and the uncertainty model it was designed for
(:meth:`Problem.description`).  Analysing it on another problem would
silently certify something else, so :func:`check_controller_problem`
refuses the mismatch and says which options reproduce the file's problem.

Examples
--------
>>> info = {"robot": "paper_2r", "uncertainty": {"model": "box"}}
>>> check_controller_problem(info, {"robot": "paper_2r", "uncertainty": {"model": "box"}}, "K.json")
[]
>>> controller_differences(info, {"robot": "paper_2r", "uncertainty": {"model": "lft"}})
["uncertainty model 'box' (given 'lft'; --uncertainty box)"]
"""

from __future__ import annotations

from polyrob.errors import ControllerFileError
from polyrob.io.controller import same_number

__all__ = ["check_controller_problem", "check_controller_size", "controller_differences"]

_WEIGHT_OPTIONS = {
    "omega_b": "--wb",
    "M_s": "--ms",
    "A_s": "--as",
    "omega_bt": "--wbt",
    "M_t": "--mt",
    "A_t": "--at",
    "effort": "--effort-weight",
}
_GROUP_OPTIONS = {"q": "--q-range", "qdot": "--qdot-max", "u": "--u-max", "qddot": "--qddot-max"}


def _values(x) -> str:
    """Each value's shortest round-trip form: the option it is pasted into must reproduce the file's value
    (six digits made a weight computed from the task's torques differ from itself in the 7th)."""
    out = []
    for v in x:
        text = repr(float(v))
        out.append(text[:-2] if text.endswith(".0") else text)
    return ",".join(out)


def _domain_differences(saved: dict, given: dict) -> list[str]:
    out = []
    joints = saved.get("joints", [])
    if list(joints) != list(given.get("joints", [])):
        return [f"domain joints {joints} (given {given.get('joints')})"]
    for group, option in _GROUP_OPTIONS.items():
        for j in joints:
            a, b = saved.get(group, {}).get(j), given.get(group, {}).get(j)
            if a is None and b is None:  # neither bounds it (a task domain has no torque box)
                continue
            if a is None or b is None or not all(same_number(x, y) for x, y in zip(a, b)):
                lo, hi = (a or [None, None])[:2]
                if lo is None:
                    hint = option
                elif group != "q" and same_number(lo, -hi):  # the bound options take one magnitude per joint
                    hint = f"{option}={j}={hi:.6g}"
                else:
                    hint = f"{option}={j}={lo:.6g}:{hi:.6g}"
                out.append(f"domain {group} of {j} {a} (given {b}; {hint})")
    if out and saved.get("name") not in (None, "custom", given.get("name")):
        out.append(f"(the file's domain is named '{saved['name']}': try --domain {saved['name']})")
    return out


def controller_differences(info: dict, problem) -> list[str]:
    """What differs between a controller file's ``info`` and ``problem`` (empty: same problem).

    ``problem`` is a :class:`~polyrob.pipeline.Problem` or its
    :meth:`~polyrob.pipeline.Problem.description` (or part of it); keys
    missing on either side are not compared.
    """
    given = problem if isinstance(problem, dict) else problem.description()
    diffs = []
    if "robot" in info and "robot" in given and info["robot"] != given["robot"]:
        return [f"robot '{info['robot']}' (given '{given['robot']}'; pass {info['robot']} as the robot)"]
    if "domain" in info and isinstance(info["domain"], dict) and "domain" in given:
        diffs += _domain_differences(info["domain"], given["domain"])
    saved_w, given_w = info.get("weights"), given.get("weights")
    if isinstance(saved_w, dict) and given_w is not None:
        for key, vals in saved_w.items():
            now = given_w.get(key)
            if now is None or len(now) != len(vals) or not all(same_number(a, b) for a, b in zip(vals, now)):
                diffs.append(
                    f"weight {key} = {_values(vals)} (given {_values(now or [])}; "
                    f"{_WEIGHT_OPTIONS.get(key, key)} {_values(vals)})"
                )
    saved_u, given_u = info.get("uncertainty"), given.get("uncertainty")
    if isinstance(saved_u, dict) and given_u is not None:
        if "model" in saved_u and saved_u["model"] != given_u.get("model"):
            diffs.append(
                f"uncertainty model '{saved_u['model']}' (given '{given_u.get('model')}'; "
                f"--uncertainty {saved_u['model']})"
            )
        if "merge_symmetric" in saved_u and bool(saved_u["merge_symmetric"]) != bool(given_u.get("merge_symmetric")):
            diffs.append(
                "merged symmetric parameters"
                + (" (--merge-symmetric)" if saved_u["merge_symmetric"] else " off (drop --merge-symmetric)")
            )
    return diffs


def check_controller_problem(info: dict, problem, source="the controller file") -> list[str]:
    """Refuse a controller made for another problem; returns ``[]`` when it matches.

    Raises
    ------
    ControllerFileError
        Naming each difference and the option that reproduces the file's value.
    """
    diffs = controller_differences(info or {}, problem)
    if diffs:
        raise ControllerFileError(
            f"{source} was made for another problem: {'; '.join(diffs)}. "
            "Analyse it on the problem it was made for (options above)"
        )
    return diffs


def check_controller_size(K, robot, source="the controller file") -> None:
    """Refuse a controller whose size does not fit ``robot`` before anything else is compared.

    A controller maps the ``m`` position measurements to the ``m`` joint
    inputs; a file of another size cannot be meant for this robot, whatever
    its weights say, so its size is the first thing a user is told.

    Raises
    ------
    ControllerFileError

    Examples
    --------
    >>> import control, polyrob
    >>> from polyrob.pipeline.matching import check_controller_size
    >>> check_controller_size(control.ss([], [], [], [[1.0, 0.0], [0.0, 1.0]]), polyrob.load_robot("planar_2r"))
    >>> check_controller_size(control.ss([], [], [], [[1.0]]), polyrob.load_robot("planar_2r"))
    Traceback (most recent call last):
    ...
    polyrob.errors.ControllerFileError: the controller file has 1 input(s) and 1 output(s); planar_2r needs 2 measurement input(s) and 2 joint output(s)
    """
    import control

    Kss = control.ss(K)
    m = int(robot.m)
    if (Kss.ninputs, Kss.noutputs) != (m, m):
        raise ControllerFileError(
            f"{source} has {Kss.ninputs} input(s) and {Kss.noutputs} output(s); {robot.name} needs {m} "
            f"measurement input(s) and {m} joint output(s)"
        )
