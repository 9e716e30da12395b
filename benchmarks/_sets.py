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
