"""``polyrob robots`` and ``polyrob info``: what can be loaded, and one robot's joints, limits, M and B."""

from __future__ import annotations

from polyrob.cli.common import (
    Output,
    add_domain_arguments,
    add_output_flags,
    add_robot_arguments,
    domain_from_args,
    robot_from_args,
)
from polyrob.errors import PolyrobError

__all__ = ["register"]


def cmd_robots(args) -> int:
    from polyrob.model.robots import available_robots, load_robot

    out = Output(args)
    rows = []
    for name, origin in available_robots():
        try:
            robot = load_robot(name)
            row = {"name": name, "origin": origin, "m": robot.m, "locked": list(robot.locked)}
            rows.append({**row, "notes": list(robot.notes)})
        except PolyrobError as exc:
            if args.all:
                rows.append({"name": name, "origin": origin, "m": None, "refused": str(exc).split(": ", 1)[-1]})
    out.document(rows)
    out.line(f"{'robot':<28}{'joints':>7}  {'origin':<20} notes")
    for r in rows:
        joints = "-" if r["m"] is None else str(r["m"])
        notes = r.get("refused") or (f"locked: {', '.join(r['locked'])}" if r["locked"] else "")
        out.line(f"{r['name']:<28}{joints:>7}  {r['origin']:<20} {notes}")
    return 0


def cmd_info(args) -> int:
    from polyrob.pipeline.reports import robot_report

    out = Output(args)
    robot = robot_from_args(args)
    domain = domain_from_args(robot, args)
    info = robot_report(robot, domain)
    out.document(info)
    if out.json:
        return 0
    print(f"robot   {robot.name}  ({robot.m} actuated joints)")
    print(f"source  {robot.source}")
    if robot.locked:
        print(f"locked  {', '.join(robot.locked)}")
    for note in robot.notes:
        print(f"NOTE    {note}")
    print(f"inertia reflected rotor inertia (armature): {robot.reflected_inertia}")
    if any(info["armature"]):
        print("        armature " + ", ".join(f"{a:.4g}" for a in info["armature"]))
    for name, pose in info["poses"].items():
        print(f"pose    {name}: [" + ", ".join(f"{x:.4g}" for x in pose) + "] (SRDF)")
    print()
    print(f"{'joint':<24}{'kind':<12}{'position limits':>22}{'velocity':>10}{'effort':>10}{'damping':>9}")
    for j in info["joints"]:
        lo, hi = j["position"]
        pos = "-" if lo is None else f"[{lo:.4g}, {hi:.4g}]"
        vel = "-" if j["velocity"] is None else f"{j['velocity']:.4g}"
        eff = "-" if j["effort"] is None else f"{j['effort']:.4g}"
        print(f"{j['name']:<24}{j['kind']:<12}{pos:>22}{vel:>10}{eff:>10}{j['damping']:>9.4g}")
    print(f"\ndomain ({domain.name})")
    print(domain.table())
    neutral = info["neutral"]
    q = ", ".join(f"{x:.5g}" for x in neutral["q"])
    print(f"\nat q = [{q}] (q = 0 clipped into the domain), at rest:")
    for line in mass_matrix_lines(robot, neutral):
        print(line)
    return 0


def mass_matrix_lines(robot, neutral: dict) -> list[str]:
    """Which ``M`` and ``B`` ``info`` prints, in words, then the matrices.

    With a computed-torque inner layer the outer controller commands
    accelerations ``v``; the mass matrix of the loop it sees is
    ``M_hat(q)^-1 M(q)``, the identity for the nominal robot.  Printing that
    alone as "M(q)" hides the robot's own, so both are printed, each named.
    """
    from polyrob.pipeline.reports import format_matrix

    inner = getattr(robot, "inner", "none")
    true_robot = getattr(robot, "true_robot", None)
    if inner == "computed-torque" and true_robot is not None:
        which = "the nominal robot" if robot.scenario == "nominal" else robot.scenario
        return [
            f"M(q) of the robot ({robot.name}, {which}; the physical mass matrix) =",
            format_matrix(neutral["M_robot"]),
            "inner layer computed-torque: u = M_hat(q) v + h_hat(q, qdot), so the outer controller sees the "
            "normalised mass matrix M_hat(q)^-1 M(q), the identity I for the nominal robot (the payload range and "
            "the model error are what keeps it from I over the domain):",
            format_matrix(neutral["M"]),
            "B(q) of the loop the controller sees (input v, the commanded acceleration) =",
            format_matrix(neutral["B"]),
        ]
    layer = "" if inner == "none" else f" (inner layer {inner}: the input is v, u = g_hat(q) + v)"
    return [
        f"M(q) of the robot ({robot.name}; the physical mass matrix) =",
        format_matrix(neutral["M"]),
        f"B(q) of the plant{layer} =",
        format_matrix(neutral["B"]),
    ]


def register(sub) -> None:
    p = sub.add_parser("robots", help="list the robots polyrob can load")
    p.add_argument("--all", action="store_true", help="also list refused URDFs with the reason")
    add_output_flags(p, quiet=False)
    p.set_defaults(func=cmd_robots)

    p = sub.add_parser("info", help="joints, limits, default domain, M and B at the neutral configuration")
    add_robot_arguments(p)
    add_domain_arguments(p)
    add_output_flags(p, quiet=False)
    p.set_defaults(func=cmd_info)
