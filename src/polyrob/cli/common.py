"""What the commands share: robot/domain/weight options, output paths, and how results are printed."""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import replace

from polyrob.cli.options import (
    add_robot_uncertainty_arguments,
    nonnegative_float,
    number,
    parse_armature,
    parse_bound,
    parse_joint_values,
    parse_list,
    parse_pose,
    positive_float,
    robot_of_set,
    robot_uncertainty_from_args,
    uncertainty_options_clash,
)
from polyrob.errors import ArgumentError, DomainError

__all__ = [
    "DEFAULT_ROBOT",
    "HelpFormatter",
    "Output",
    "add_robot_arguments",
    "add_domain_arguments",
    "add_weight_arguments",
    "add_output_flags",
    "robot_from_args",
    "robot_uncertainty_from_args",
    "domain_from_args",
    "domain_options_given",
    "apply_default_task",
    "hyperparameters_from_args",
    "limit_weights_from_args",
    "to_json",
]

DEFAULT_ROBOT = "planar_2r"
#: the CLI option of each domain group (the library names the group only)
DOMAIN_OPTIONS = {"q": "--q-range", "qdot": "--qdot-max", "u": "--u-max"}
WEIGHT_OPTIONS = (("omega_b", "wb"), ("M_s", "ms"), ("A_s", "as"), ("omega_bt", "wbt"), ("M_t", "mt"), ("A_t", "at"))


# --------------------------------------------------------------------------- printing


class HelpFormatter(argparse.HelpFormatter):
    """Shows an option's default when it has one and its help does not already say it."""

    def _get_help_string(self, action):
        text = action.help or ""
        default = action.default
        flag = isinstance(action, (argparse._StoreTrueAction, argparse._StoreFalseAction))
        if flag or "default" in text or default in (None, False, argparse.SUPPRESS) or not action.option_strings:
            return text
        return f"{text} (default: {default})"


def to_json(doc) -> str:
    # imported here, not at the top: importing the fleet loads numpy, and --help must not
    from polyrob.fleet.outputs import plain

    return json.dumps(plain(doc), indent=2, allow_nan=False)


_LOG_HANDLER = None


def show_library_log(on: bool) -> None:
    """The library's progress lines (``polyrob`` logger, INFO) on stderr, terminal or not; none when ``on`` is False."""
    import logging

    global _LOG_HANDLER
    log = logging.getLogger("polyrob")
    if _LOG_HANDLER is not None:
        log.removeHandler(_LOG_HANDLER)
    _LOG_HANDLER = logging.StreamHandler(sys.stderr)  # the current stderr (tests swap it)
    _LOG_HANDLER.setFormatter(logging.Formatter("%(message)s"))
    log.addHandler(_LOG_HANDLER)
    log.setLevel(logging.INFO if on else logging.WARNING)
    log.propagate = False


class Output:
    """Where a command's lines go.

    Text mode: the report on stdout, each stage's start line first (flushed,
    so a pipe shows it when the stage starts).  ``--json``: one JSON document
    on stdout, stage lines on stderr (none with ``--quiet``).  Progress bars
    only on a terminal and without ``--quiet``.  ``job``: the stages' expected
    titles (their first words weigh them), for one progress line for the
    whole job (:class:`polyrob.progress.JobProgress`: stage k of n, fraction,
    ETA; a bar on a terminal, else a line on stderr at least every 20 s),
    none with ``--quiet``.
    """

    def __init__(self, args, stages: int = 0, *, job=None):
        self.json = bool(getattr(args, "json", False))
        self.quiet = bool(getattr(args, "quiet", False))
        self.stages = stages
        self._stage = 0
        show_library_log(not self.quiet)
        self.job = None
        if job and not self.quiet:
            from polyrob.progress import JobProgress

            self.job = JobProgress(list(job), terminal=sys.stderr.isatty()).start()

    @property
    def progress(self) -> bool:
        return not self.quiet and sys.stderr.isatty()

    def stage(self, text: str) -> None:
        self._stage += 1
        line = f"[{self._stage}/{self.stages}] {text}"
        if not self.json:
            print(line, flush=True)
        elif not self.quiet:
            print(line, file=sys.stderr, flush=True)
        if self.job is not None:
            self.job.begin(self._stage, text)

    def line(self, text: str = "") -> None:
        if not self.json:
            print(text, flush=True)

    def document(self, doc) -> None:
        if self.json:
            print(to_json(doc), flush=True)


def exit_status(certificate, moving: dict | None = None) -> int:
    """The exit status of a command that ends with a certificate: 0 certified, 1 any other status (2 is bad input).

    ``moving``: the summary of a moving-robot certificate the user asked for (``--moving``); when it was
    computed, it must be certified too (a verdict that exists decides), when it was not, μ alone decides.
    """
    from polyrob.analysis.lpv.moving_result import refuses

    return 0 if certificate.certified and not refuses(moving) else 1


def add_output_flags(parser: argparse.ArgumentParser, *, quiet: bool = True) -> None:
    parser.add_argument("--json", action="store_true", help="print one JSON document instead of the text report")
    if quiet:
        parser.add_argument(
            "--quiet", action="store_true", help="no progress bars (and no stage lines on stderr with --json)"
        )


# --------------------------------------------------------------------------- robot and domain


def add_robot_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "robot",
        nargs="?",
        default=DEFAULT_ROBOT,
        help=f"URDF file, bundled or example-robot-data name (default {DEFAULT_ROBOT})",
    )
    parser.add_argument(
        "--lock", default=None, help="comma-separated joints to lock (default: grippers/fingers; '' locks none)"
    )
    parser.add_argument(
        "--armature",
        default=None,
        help="reflected rotor inertia added to M's diagonal: V, V1,V2,... or JOINT=V,... "
        "(replaces the SRDF's gear ratio^2 x rotor inertia; default: the SRDF's, else none)",
    )
    g = parser.add_argument_group(
        "inner layer and payload (the outer controller drives v through an inner loop computed from a model)"
    )
    g.add_argument(
        "--inner",
        default=None,  # not given: an arm's default task (computed torque); --inner none is the paper's single layer
        choices=("none", "gravity", "computed-torque"),
        help="none (the paper: v = u), gravity (u = g_hat(q) + v), computed-torque (u = M_hat(q) v + h_hat(q, qdot)); "
        "default: an arm's default task (computed torque), else none; on an arm, given alone, its default task "
        "with this layer",
    )
    g.add_argument("--payload-mass", default=None, help="payload at the tool flange, kg: LO:HI or M")
    g.add_argument(
        "--payload-com",
        default=None,
        help="payload centre-of-mass offset box in the flange frame, m: X,Y,Z (meaning -|X|:|X|, ...), "
        "R (a cube), or X0:X1,Y0:Y1,Z0:Z1 (default: at the flange)",
    )
    g.add_argument(
        "--model-error",
        default=None,
        help="PCT in [0, 100): the true link masses/inertias are the model's times 1 -+ PCT/100 (default 0)",
    )
    add_robot_uncertainty_arguments(g)


def add_domain_arguments(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("domain")
    g.add_argument(
        "--domain", default=None, help="domain file (JSON/YAML) or a named domain of the robot (e.g. 'paper')"
    )
    g.add_argument(
        "--q-range", default=None, help="position range, e.g. --q-range=-pi:pi or joint2=-1.5:1.5,joint3=0:2"
    )
    g.add_argument("--qdot-max", default=None, help="velocity bound >= 0, e.g. 2 or joint1=4,joint2=10")
    g.add_argument("--u-max", default=None, help="torque bound >= 0, e.g. 50 or joint1=0,joint2=5")
    g.add_argument("--qdot-scale", type=nonnegative_float, default=1.0, help="scale the velocity box")
    g.add_argument("--u-scale", type=nonnegative_float, default=1.0, help="scale the torque box")
    t = parser.add_argument_group(
        "task domain (any of these replaces the torque box: u = inverse dynamics of (q, qdot, qddot))"
    )
    t.add_argument("--pose", default=None, help="reference pose: an SRDF pose name (see `polyrob info`) or q1,q2,...")
    t.add_argument("--q-radius", default=None, help="positions within pose +- RADIUS (and the joint limits)")
    t.add_argument("--qddot-max", default=None, help="acceleration bound >= 0 (rad/s^2), e.g. 2 or 2,2,4")
    t.add_argument(
        "--torque-box",
        action="store_true",
        help="arms of 3+ joints: the URDF torque box without an inner layer instead of their default task "
        "(±0.2 rad around the reference pose, |qdot| <= 0.5, |qddot| <= 2, computed torque, links ±10 %%, payload 0-1 %% of the link mass)",
    )


def robot_from_args(args):
    """The robot of the options: with ``--inner``/``--payload-*``/``--model-error``, its inner loop.

    An arm of :data:`polyrob.domains.default_task.MIN_JOINTS` joints or more
    given without any domain or inner-layer option gets its default task
    (:func:`apply_default_task`): the options are filled in ``args`` and said
    on the ``polyrob`` log (stderr).
    """
    from polyrob.model.robots import load_robot

    lock = None if args.lock is None else [s.strip() for s in args.lock.split(",") if s.strip()]
    robot = load_robot(args.robot, lock=lock, armature=parse_armature(getattr(args, "armature", None)))
    spec = robot_uncertainty_from_args(args, robot)
    if spec is not None:  # the set replaces the payload and model-error options (and the default task's)
        uncertainty_options_clash(args, {k: getattr(args, k.strip("-").replace("-", "_"), None)
                                         for k in ("--payload-mass", "--payload-com", "--model-error")})  # fmt: skip
    args.uncertainty_words = None if spec is None else spec.words()
    # with a set, a refusal (what the model cannot carry) comes before the task's log line
    apply_default_task(robot, args, say=spec is None)
    if spec is not None:
        loop = robot_of_set(robot, spec, args)
        say_default_task(robot, args)
        return loop
    inner, payload = inner_options(args)
    if inner is None:
        return robot
    from polyrob.model.inner import inner_loop

    return inner_loop(robot, inner["inner"], payload=payload, model_error=inner["model_error"])


def apply_default_task(robot, args, *, say: bool = True) -> bool:
    """Fill ``args`` with the robot's default task (:mod:`polyrob.domains.default_task`) when it applies.

    It applies to a robot of ``MIN_JOINTS`` joints or more when no domain
    option, no ``--model-error``, no ``--pldi`` and no ``--torque-box`` is
    given (``--certify`` proves the task's factor ranges: it keeps the
    task).  A payload rides on it; ``--inner LAYER`` alone poses the same
    task with that layer (``none``: the paper's single layer on the task's
    domain and uncertainty; ``--torque-box`` is the URDF torque box).
    Sets ``args.default_task`` to the task's words (``None`` when it does not apply) and returns whether it applied;
    ``say``: log them now (else :func:`say_default_task` does, later).
    """
    from polyrob.domains.default_task import DEFAULT_TASK, applies_to

    args.default_task = None
    args.bound_options = None
    given = (
        domain_options_given(args)
        or getattr(args, "model_error", None) is not None
        or any(getattr(args, k, None) for k in ("pldi", "torque_box"))
    )
    if given or not applies_to(robot.m):
        return False
    t = DEFAULT_TASK.with_inner(getattr(args, "inner", None))
    args.q_radius, args.qdot_max, args.qddot_max = f"{t.q_radius!r}", f"{t.qdot_max!r}", f"{t.qddot_max!r}"
    args.inner, args.model_error = t.inner, f"{100 * t.model_error!r}"
    user_payload = getattr(args, "payload_mass", None)  # a user's payload rides on the default task
    args.payload_mass = user_payload or t.payload_option(robot)
    given_words = f", payload {user_payload} kg at the flange (given)"  # instead of the task's own
    args.default_task = replace(t, payload_fraction=0.0).words() + given_words if user_payload else t.words()
    if getattr(args, "uncertainty_words", None):  # a robot-uncertainty set replaces the task's model error and payload
        args.default_task = replace(t, model_error=0.0, payload_fraction=0.0).words() + "; " + args.uncertainty_words
    args.bound_options = t.bound_options
    if say:
        say_default_task(robot, args)
    return True


def say_default_task(robot, args) -> None:
    """The default task's line on the ``polyrob`` log (stderr), when it applies."""
    import logging

    if getattr(args, "default_task", None):
        logging.getLogger("polyrob").info(
            f"default task of {robot.name} ({robot.m} joints, no domain given): {args.default_task}; "
            "--torque-box for the URDF torque box without an inner layer"
        )


def inner_options(args):
    """``({"inner", "model_error"}, PayloadRange or None)``, or ``(None, None)`` when none of the options is given."""
    layer = getattr(args, "inner", None) or "none"
    mass, com, pct = (getattr(args, k, None) for k in ("payload_mass", "payload_com", "model_error"))
    if layer == "none" and mass is None and com is None and pct is None:
        return None, None
    from polyrob.model.payload import PayloadRange

    if com is not None and mass is None:
        raise ArgumentError("--payload-com: give the payload's mass too (--payload-mass LO:HI)")
    payload = None if mass is None else PayloadRange.parse(mass, com)
    p = 0.0 if pct is None else number(pct, "--model-error")
    if not 0.0 <= p < 100.0:
        raise ArgumentError(f"--model-error: give a percentage in [0, 100), got '{pct}'")
    return {"inner": layer, "model_error": p / 100.0}, payload


def domain_options_given(args) -> bool:
    return (
        any(getattr(args, k, None) is not None for k in ("domain", "q_range", "qdot_max", "u_max"))
        or task_options_given(args)
        or getattr(args, "qdot_scale", 1.0) != 1.0
        or getattr(args, "u_scale", 1.0) != 1.0
    )


def task_options_given(args) -> bool:
    return any(getattr(args, k, None) is not None for k in ("pose", "q_radius", "qddot_max"))


def domain_from_args(robot, args):
    from polyrob.domains.torque_box import Domain

    try:
        if task_options_given(args):
            return task_domain_from_args(robot, args)
        if getattr(robot, "inner", None) == "computed-torque":
            raise ArgumentError(
                "--inner computed-torque: the outer input v is an acceleration: give a task domain "
                "(--qddot-max, with --pose/--q-radius), not a torque box"
            )
        return Domain.from_robot(
            robot,
            args.domain,
            q_range=parse_joint_values(args.q_range, "--q-range", ranges=True),
            qdot_max=parse_joint_values(args.qdot_max, "--qdot-max", ranges=False),
            u_max=parse_joint_values(args.u_max, "--u-max", ranges=False),
            qdot_scale=args.qdot_scale,
            u_scale=args.u_scale,
        )
    except DomainError as exc:
        # the library names a group ("--q: ..."); the user typed the option
        text = str(exc)
        for group, option in DOMAIN_OPTIONS.items():
            if text.startswith(f"--{group}:"):
                raise DomainError(option + text[len(group) + 2 :]) from None
        raise


def task_domain_from_args(robot, args):
    """A :class:`~polyrob.domains.task.TaskDomain` from ``--pose``, ``--q-radius``, ``--qdot-max``, ``--qddot-max``."""
    from polyrob.domains.task import TaskDomain

    for option in ("domain", "q_range", "u_max"):
        if getattr(args, option, None) is not None:
            raise ArgumentError(
                f"--{option.replace('_', '-')} sets a torque-box domain: not with --pose/--q-radius/--qddot-max"
            )
    if getattr(args, "qdot_scale", 1.0) != 1.0 or getattr(args, "u_scale", 1.0) != 1.0:
        raise ArgumentError("--qdot-scale/--u-scale scale a torque-box domain: give --qdot-max for a task domain")
    return TaskDomain.from_robot(
        robot,
        pose=parse_pose(args.pose),
        q_radius=parse_bound(args.q_radius, "--q-radius"),
        qdot_max=parse_joint_values(args.qdot_max, "--qdot-max", ranges=False),
        qddot_max=parse_joint_values(args.qddot_max, "--qddot-max", ranges=False),
    )


# --------------------------------------------------------------------------- weights


def add_weight_arguments(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group(
        "performance weights W_S = (s/M_S + wB)/(s + wB A_S), W_T = (s + wBT)/(A_T s + wBT M_T)",
        "one value > 0 for every joint or one per joint (comma-separated); default: the paper's",
    )
    for key, text in WEIGHT_OPTIONS:
        g.add_argument(f"--{text}", dest=key, default=None, help=f"{key}")
    g.add_argument("--bandwidth-scale", type=positive_float, default=1.0, help="multiply wB and wBT")
    lim = parser.add_argument_group(
        "limit weights W_KS = W_u W_n on u (on by default on an arm's default task; docs/synthesis.md)",
        "the encoder noise W_n n (n on the measured q) may drive at most 5 %% of the effort limit, peak to peak, "
        "within what the task's torque leaves",
    )
    if "--encoder-bits" not in getattr(parser, "_option_string_actions", {}):  # one option, read by both groups
        lim.add_argument(
            "--encoder-bits",
            type=_encoder_bits,
            default=None,
            help="encoder resolution, bits per revolution (default 18): W_n = half a count = pi / 2^B rad",
        )
    lim.add_argument(
        "--effort-weight",
        default=None,
        help="W_u > 0, one or one per joint, in 1/(u's unit): 1/N m, or s^2/rad for the computed-torque input v "
        "(default: from the URDF effort limits minus the task's torque)",
    )
    lim.add_argument("--no-limit-weights", action="store_true", help="the paper's W_S and W_T only")


def hyperparameters_from_args(m: int, args, domain=None) -> dict:
    """The paper's weight hyperparameters with the options' overrides; on an arm's default task, the automatic ones."""
    from polyrob.pipeline.problem import default_hyperparameters

    overrides = {}
    for key, text in WEIGHT_OPTIONS:
        vals = parse_list(getattr(args, key, None), f"--{text}")
        if vals is not None:
            if len(vals) not in (1, m):
                raise ArgumentError(f"--{text}: give 1 or {m} values (one per joint), got {len(vals)}")
            overrides[key] = vals
    if getattr(args, "default_task", None) and domain is not None:
        from polyrob.fleet.autoweights import automatic_hyperparameters

        h = automatic_hyperparameters(m, domain, overrides)
        return default_hyperparameters(m, h, bandwidth_scale=args.bandwidth_scale)
    return default_hyperparameters(m, overrides, bandwidth_scale=args.bandwidth_scale)


def _encoder_bits(text) -> int:
    """``--encoder-bits``: a whole number of bits from 1 to 64 (argparse type)."""
    try:
        value = number(str(text), "--encoder-bits")
    except ArgumentError:
        value = math.nan
    if not (value == int(value) if math.isfinite(value) else False) or not 1 <= value <= 64:
        raise argparse.ArgumentTypeError(f"give a whole number of bits from 1 to 64, got '{text}'")
    return int(value)


def encoder_bits_from_args(args) -> int | None:
    """``--encoder-bits`` as a whole number from 1 to 64, or ``None`` (not stated)."""
    value = getattr(args, "encoder_bits", None)
    return None if value is None else _encoder_bits(value)


def limit_weights_from_args(robot, args, domain, hyperparameters: dict) -> dict:
    """``hyperparameters`` with the limit weights the options ask for (:mod:`polyrob.plant.weights`).

    On by default on an arm's default task; ``--effort-weight`` turns them
    on elsewhere, ``--no-limit-weights`` off; ``--encoder-bits`` sets the noise level.
    """
    bits = encoder_bits_from_args(args)
    effort = parse_list(getattr(args, "effort_weight", None), "--effort-weight")
    if getattr(args, "no_limit_weights", False):
        if effort is not None:
            raise ArgumentError("--no-limit-weights drops the limit weights: drop --effort-weight")
        return hyperparameters
    # --encoder-bits alone does not turn them on: the validation at the rate reads it too, with a default
    if not (getattr(args, "default_task", None) or effort is not None) or domain is None:
        return hyperparameters
    if effort is not None and len(effort) not in (1, robot.m):
        raise ArgumentError(f"--effort-weight: give 1 or {robot.m} values (one per joint), got {len(effort)}")
    h = dict(hyperparameters)
    if effort is None:
        import logging

        from polyrob.fleet.autoweights import limit_hyperparameters

        budget = limit_hyperparameters(robot, domain, encoder_bits=bits)
        logging.getLogger("polyrob").info(budget.words())
        h.update(budget.hyperparameters())
    else:
        from polyrob.plant.weights import DEFAULT_ENCODER_BITS, encoder_noise_level

        noise = encoder_noise_level(DEFAULT_ENCODER_BITS if bits is None else bits)
        h["effort"] = tuple(effort * robot.m if len(effort) == 1 else effort)
        h["noise"] = (noise,) * robot.m
    return h


def scale_names(text: str) -> tuple:
    from polyrob.pipeline.problem import WEIGHT_KEYS

    names = tuple(x.strip() for x in text.split(",") if x.strip())
    unknown = [n for n in names if n not in WEIGHT_KEYS]
    if not names or unknown:
        raise ArgumentError(f"--scale-only: give weight hyperparameters among {', '.join(WEIGHT_KEYS)}, got '{text}'")
    return names


def alphas_from_args(text):
    return parse_list(text, "--alphas")
