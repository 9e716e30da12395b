"""The robot-uncertainty set a benchmark is run on, from its command line (a file, or a per-link error and an instrument)."""

from __future__ import annotations


def add_set_options(parser, payload_max: float) -> None:
    """``--robot-uncertainty FILE`` or ``--link-error P --payload-max KG --com-radius M``."""
    parser.add_argument(
        "--robot-uncertainty", default=None, help="a robot-uncertainty file (YAML/JSON), or 'default' (the CLI's)"
    )
    parser.add_argument("--link-error", type=float, default=10.0, help="per-link error in percent (default 10)")
    parser.add_argument(
        "--payload-max", type=float, default=payload_max,
        help=f"payload up to this many kg, capped at the rated (default {payload_max:g})",
    )  # fmt: skip
    parser.add_argument("--com-radius", type=float, default=0.1, help="payload centre of mass within this radius (m)")


def set_of(args, name: str):
    """The :class:`~polyrob.uncertainty_set.spec.RobotUncertainty` the options of :func:`add_set_options` state."""
    from polyrob.model.robots import load_robot
    from polyrob.uncertainty_set.spec import RATED_PAYLOAD, PayloadBody, RobotUncertainty

    if args.robot_uncertainty == "default":  # as the CLI's --robot-uncertainty default
        from polyrob.uncertainty_set.default_set import default_set

        return default_set(load_robot(name))
    if args.robot_uncertainty:
        return RobotUncertainty.from_file(args.robot_uncertainty)
    rated = RATED_PAYLOAD.get(load_robot(name).name)
    top = min(args.payload_max, rated.kg) if rated is not None and rated.kg else args.payload_max
    payload = PayloadBody(0.0, top, com_radius=args.com_radius) if top > 0 else None
    return RobotUncertainty(link_error=args.link_error / 100.0, payload=payload, source="benchmark options")


def _file_loop(args, path: str):
    """``(robot, loop, domain, weights)`` of a controller file: its robot, the computed-torque loop of the set of
    :func:`add_set_options`, its task and its weights as the file states them (tuples)."""
    from polyrob.domains.task import TaskDomain
    from polyrob.io.controller import read_controller_file
    from polyrob.model.inner import inner_loop_of_set
    from polyrob.model.robots import load_robot

    info = read_controller_file(path).get("info") or {}
    robot = load_robot(info["robot"])
    loop = inner_loop_of_set(robot, "computed-torque", set_of(args, info["robot"]), draws=2)
    domain = TaskDomain.from_dict(info["domain"], robot=loop)
    return robot, loop, domain, {k: tuple(v) for k, v in info["weights"].items()}


def controller_problem(args, path: str):
    """``(robot, loop, domain, weights, K, pldi)`` of a controller file (as ``polyrob synth -o`` writes it) on the set of :func:`add_set_options`.

    ``loop``: the computed-torque loop of that set; ``pldi``: a stand-in
    with what the models read of a PLDI (its domain, size and nominal at one
    point of the task).
    """
    from polyrob.io.controller import load_controller
    from polyrob.plant.weights import plant_weights

    robot, loop, domain, weights = _file_loop(args, path)
    return robot, loop, domain, plant_weights(weights), load_controller(path), pldi_stand_in(loop, domain)


def controller_file_problem(args, path: str):
    """``(robot, loop, problem, K)``: a controller file's problem bounded as ``polyrob analyze`` bounds it, on the set of :func:`add_set_options`.

    ``loop``: the computed-torque loop of that set; ``problem``: its
    :func:`polyrob.pipeline.problem.build_problem` on the file's task and
    weights; ``K`` the file's controller.
    """
    from polyrob.io.controller import load_controller
    from polyrob.pipeline.problem import build_problem

    robot, loop, domain, weights = _file_loop(args, path)
    problem = build_problem(loop, domain, hyperparameters=weights, progress=False)
    return robot, loop, problem, load_controller(path)


def pldi_stand_in(loop, domain):
    """What the models read of a PLDI (its domain, size and nominal at one point of the task), for ``loop`` on ``domain``."""
    from types import SimpleNamespace

    q, qdot, a = domain.split(domain.sample_box(1, method="uniform", seed=0))
    A0, B0 = loop.jacobians_batch(q, qdot, loop.inverse_dynamics(q, qdot, a))
    return SimpleNamespace(m=loop.m, domain=domain, A0=A0[0], B0=B0[0], enclosure="sampled", robot_name=loop.name)
