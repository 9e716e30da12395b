"""Option values: parsed and validated here, each error naming the option the user typed.

Only the standard library: the numbers are checked with :mod:`math`, the
arrays are built by the library.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import replace

from polyrob.errors import ArgumentError

__all__ = [
    "MODEL_CHOICES",
    "number",
    "parse_joint_values",
    "parse_list",
    "parse_frequencies",
    "int_at_least",
    "positive_float",
    "nonnegative_float",
    "fraction",
    "parse_armature",
    "parse_pose",
    "parse_bound",
    "parse_interval",
    "add_robot_uncertainty_arguments",
    "robot_uncertainty_from_args",
    "add_proof_dir_argument",
    "proof_options",
    "robot_of_set",
    "uncertainty_options_clash",
    "add_validation_arguments",
    "rate_conditions_from_args",
    "rate_conditions_dict",
    "add_coulomb_argument",
    "coulomb_from_args",
    "add_sampling_arguments",
    "sampling_from_args",
]


#: ``--uncertainty``'s choices: :data:`polyrob.pipeline.problem.UNCERTAINTY_MODELS` (kept here so the CLI starts
#: without importing the pipeline; ``tests/test_arm_uncertainty_model.py`` checks that the two agree).
MODEL_CHOICES = ["auto", "box", "axes", "lft", "lft-torque", "inertia", "inner-links-real"]


def number(text: str, option: str, *, finite: bool = True) -> float:
    """``2``, ``-1.5``, ``pi``, ``2pi``, ``0.5*pi`` -> float; NaN is always refused, inf when ``finite``."""
    t = str(text).strip().lower()
    sign = -1.0 if t.startswith("-") else 1.0
    t = t.lstrip("+-")
    try:
        if t.endswith("pi"):
            factor = t[:-2].rstrip("*")
            value = sign * (float(factor) if factor else 1.0) * math.pi
        else:
            value = sign * float(t)
    except ValueError:
        raise ArgumentError(f"{option}: '{text}' is not a number") from None
    if math.isnan(value):
        raise ArgumentError(f"{option}: NaN is not a valid value")
    if finite and math.isinf(value):
        raise ArgumentError(f"{option}: '{text}' is not a finite number")
    return value


def _per_joint(text: str, option: str, value):
    """``JOINT=V,...`` as a mapping, else the list of plain values, each read by ``value`` (a mix refused)."""
    items = [s for s in text.split(",") if s.strip()]
    if not items:
        raise ArgumentError(f"{option}: empty value")
    if all("=" in s for s in items):
        return {k.strip(): value(v) for k, v in (s.split("=", 1) for s in items)}
    if any("=" in s for s in items):
        raise ArgumentError(f"{option}: mix of JOINT=VALUE and plain values in '{text}'")
    return [value(s) for s in items]


def parse_joint_values(text: str | None, option: str, *, ranges: bool):
    """Parse ``4``, ``4,10``, ``joint1=4,joint2=10``, ``-pi:pi`` or ``joint2=-1:1``.

    Returns a value :meth:`polyrob.Domain.from_robot` takes: a number or a
    ``[lo, hi]`` pair for every joint, a list per joint, or a mapping.  Every
    number must be finite; a single bound (``--qdot-max 2``) must be >= 0 and
    a range ``LO:HI`` must have ``LO <= HI``.
    """
    if text is None:
        return None

    def value(s):
        if ":" in s:
            lo, hi = s.split(":", 1)
            pair = [number(lo, option), number(hi, option)]
            if pair[0] > pair[1]:
                raise ArgumentError(f"{option}: inverted range '{s}' (give LO:HI with LO <= HI)")
            return pair
        if ranges:
            raise ArgumentError(f"{option}: give a range as LO:HI (e.g. {option}=-pi:pi), got '{s}'")
        v = number(s, option)
        if v < 0:
            raise ArgumentError(
                f"{option}: a bound must be >= 0 (it means -V:V; give a range LO:HI otherwise), got '{s}'"
            )
        return v

    values = _per_joint(text, option, value)
    if isinstance(values, dict):
        return values
    if len(values) == 1:
        return values[0]
    return [v if isinstance(v, list) else [-abs(v), abs(v)] for v in values]


def parse_armature(text: str | None):
    """``--armature``: ``0.1`` (every joint), ``0.1,0.2,...`` (one per joint) or ``joint1=0.1,joint3=0.2``.

    Every value must be a finite number >= 0 (kg m^2 for a revolute joint).
    """
    if text is None:
        return None

    def value(s):
        v = number(s, "--armature")
        if v < 0:
            raise ArgumentError(f"--armature: a reflected inertia must be >= 0, got '{s}'")
        return v

    values = _per_joint(text, "--armature", value)
    return values[0] if isinstance(values, list) and len(values) == 1 else values


def parse_pose(text: str | None):
    """``--pose``: a name (``default``, ``home``) or positions ``q1,q2,...`` (finite numbers, ``pi`` allowed)."""
    if text is None:
        return None
    t = text.strip()
    if not t:
        raise ArgumentError("--pose: empty value: give a pose name or q1,q2,...")
    if "," not in t:
        try:
            return [number(t, "--pose")]
        except ArgumentError:
            if t.lower() in ("nan", "-nan", "+nan"):
                raise
            return t
    return [number(s, "--pose") for s in t.split(",")]


def parse_bound(text: str | None, option: str) -> float | None:
    """One finite number >= 0 (``--q-radius``, ``--qddot-max``), or None."""
    if text is None:
        return None
    value = number(text, option)
    if value < 0:
        raise ArgumentError(f"{option}: must be >= 0, got '{text}'")
    return value


def parse_interval(text: str | None, option: str) -> list[float] | None:
    """``LO:HI`` or ``HI`` (meaning ``0:HI``) of finite numbers with ``0 <= LO <= HI``, or None."""
    if text is None:
        return None
    parts = text.split(":")
    if len(parts) > 2:
        raise ArgumentError(f"{option}: give LO:HI, got '{text}'")
    vals = [number(s, option) for s in parts]
    lo, hi = (0.0, vals[0]) if len(vals) == 1 else vals
    if not 0 <= lo <= hi:
        raise ArgumentError(f"{option}: need 0 <= LO <= HI, got '{text}'")
    return [lo, hi]


def parse_list(text: str | None, option: str, *, positive: bool = True) -> list[float] | None:
    """Comma-separated finite numbers (``> 0`` when ``positive``), or None."""
    if text is None:
        return None
    items = [s for s in text.split(",") if s.strip()]
    if not items:
        raise ArgumentError(f"{option}: empty value")
    vals = [number(s, option) for s in items]
    if positive and any(v <= 0 for v in vals):
        raise ArgumentError(f"{option}: every value must be > 0, got '{text}'")
    return vals


def parse_frequencies(text: str | None):
    """``LO:HI:N`` -> ``(lo, hi, n)`` with ``0 < LO < HI`` finite and ``N >= 2``, or None."""
    if text is None:
        return None
    try:
        lo, hi, n = text.split(":")
        lo, hi, n = float(lo), float(hi), int(n)
    except ValueError:
        raise ArgumentError(f"--omega: give LO:HI:N, e.g. 0.01:100:60, got '{text}'") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo < hi and n >= 2):
        raise ArgumentError(f"--omega: need finite 0 < LO < HI and N >= 2, got '{text}'")
    return lo, hi, n


# --------------------------------------------------------------------------- the robot-uncertainty set
# A per-link set (--robot-uncertainty FILE, --link-error P) is checked against the robot, then carried
# by the inner-links model (polyrob.plant.models.inner_links) on a computed-torque inner layer; what that
# model cannot carry is refused in one line that echoes the set and says why.


def add_robot_uncertainty_arguments(group) -> None:
    """``--robot-uncertainty FILE`` and ``--link-error P``: the per-link set (validated, not yet certified)."""
    group.add_argument(
        "--robot-uncertainty",
        default=None,
        metavar="FILE",
        help="a robot-uncertainty file (YAML/JSON: per-link parameter errors, a payload body, joint friction; "
        "examples/uncertainty/panda.yaml), or 'default': each link ±10 %% on its own and an instrument of 0-1.5 kg "
        "(capped at the rated payload) with its centre of mass within 0.1 m of the flange; carried on a "
        "computed-torque inner layer (the inner-links model)",
    )
    group.add_argument(
        "--link-error",
        default=None,
        metavar="P",
        help="each link's mass, first moment and inertia about its centre of mass within ±P %% independently "
        "(replaces the file's percentage; --model-error is the common factor on all links instead)",
    )


def robot_uncertainty_from_args(args, robot):
    """The :class:`~polyrob.uncertainty_set.spec.RobotUncertainty` of the options bound to ``robot``, or ``None``.

    ``--link-error P`` sets (or, with a file, replaces) the file's per-link
    percentage.  Every refusal is one :class:`ArgumentError` line.
    """
    path, pct = getattr(args, "robot_uncertainty", None), getattr(args, "link_error", None)
    if path is None and pct is None:
        return None
    from polyrob.uncertainty_set.default_set import DEFAULT_SET, default_set
    from polyrob.uncertainty_set.spec import RobotUncertainty

    if path == DEFAULT_SET:  # the engineer's set of the arm, not a file
        spec = default_set(robot)
    else:
        spec = RobotUncertainty() if path is None else RobotUncertainty.from_file(path)
    if pct is not None:
        p = number(pct, "--link-error")
        if not 0.0 <= p < 100.0:
            raise ArgumentError(f"--link-error: give a percentage in [0, 100), got '{pct}'")
        spec = replace(spec, link_error=p / 100.0)
    try:
        return spec.bound(robot)
    except ArgumentError as exc:
        where = f"--robot-uncertainty {path}" if path is not None else "--link-error"
        raise ArgumentError(f"{where}: {str(exc).removeprefix('robot uncertainty: ')}") from None


def uncertainty_options_clash(args, user_given: dict) -> None:
    """Refuse in one line the options a robot-uncertainty set replaces (``user_given``: as the user gave them)."""
    path = getattr(args, "robot_uncertainty", None)
    where = f"--robot-uncertainty {path}" if path is not None else f"--link-error {args.link_error}"
    for option, value in user_given.items():
        if value is not None:
            raise ArgumentError(
                f"{where}: {option} {value} would state the uncertainty twice: put the payload and the link "
                "errors in the robot-uncertainty file (payload:, links:) and drop " + option
            )


def robot_of_set(robot, spec, args):
    """The inner loop of ``robot`` over the per-link set ``spec``, or one :class:`ArgumentError` line why not.

    The set is carried on a computed-torque inner layer only (the
    :mod:`~polyrob.plant.models.inner_links` model: there the loop's factor
    is exactly linear in the parameters); a torque box has no accelerations
    to hold fixed, so the set needs a task domain.
    """
    path = getattr(args, "robot_uncertainty", None)
    where = f"--robot-uncertainty {path}" if path is not None else f"--link-error {args.link_error}"
    inner = getattr(args, "inner", None) or "none"
    if inner != "computed-torque":
        raise ArgumentError(
            f"{where} ({spec.words()}): carried on a computed-torque inner layer only (--inner computed-torque, "
            f"the default task of an arm), not --inner {inner}: there the loop is not linear in the link parameters"
        )
    if getattr(args, "torque_box", False):
        raise ArgumentError(f"{where}: a per-link set needs a task domain (accelerations), not --torque-box")
    from polyrob.model.inner import inner_loop_of_set

    loop = inner_loop_of_set(robot, inner, spec)
    if getattr(args, "default_task", None):  # measured before the bounds, on the task the pipeline will pose
        from polyrob.domains.default_task import DEFAULT_TASK, default_task_domain
        from polyrob.plant.models.inner_links import carried

        why = carried(loop, default_task_domain(loop, DEFAULT_TASK))
        if why:
            raise ArgumentError(f"{where} ({spec.words()}): not carried on {robot.name}'s default task: {why}")
    return loop


# --------------------------------------------------------------------------- the sample rate and the delay
# ``--rate`` and ``--delay`` land in ``args.rate`` (Hz, or None: not stated) and ``args.delay_samples``
# (None: not stated), the attributes the validation at the rate reads too (rate_conditions_from_args:
# 1 kHz and one sample when not stated).  Not stated, the certificate is the continuous-time one.


def _rate(text):
    """``--rate``: ``continuous`` or ``0`` -> None (the continuous-time certificate), else a rate in Hz > 0."""
    t = str(text).strip().lower()
    if t in ("continuous", "0", "0.0"):
        return None
    try:
        value = number(t, "--rate")
    except ArgumentError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("--rate: ")) from None
    if value <= 0:
        raise argparse.ArgumentTypeError(f"give a sample rate in Hz > 0 or 'continuous', got '{text}'")
    return value


def _delay(text):
    try:
        value = int(str(text).strip())
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"give a whole number of samples >= 0, got '{text}'")
    return value


def add_sampling_arguments(group) -> None:
    """``--rate HZ|continuous`` and ``--delay SAMPLES``: the loop the certificate covers."""
    group.add_argument(
        "--rate",
        type=_rate,
        default=None,
        metavar="HZ",
        help="certify the loop sampled at HZ (zero-order hold, the controller discretised by Tustin as "
        "`export` runs it), at the sampling instants; 'continuous' or 0 (the default): the continuous-time loop",
    )
    group.add_argument(
        "--delay",
        dest="delay_samples",
        type=_delay,
        default=None,
        metavar="SAMPLES",
        help="computation delay of the sampled loop in whole samples (with --rate HZ; default 1)",
    )


def sampling_from_args(args):
    """The :class:`~polyrob.analysis.sampled_data.SamplingSpec` of ``--rate``/``--delay``, or ``None`` (continuous)."""
    rate, delay = getattr(args, "rate", None), getattr(args, "delay_samples", None)
    if rate is None:
        if delay is not None:
            raise ArgumentError("--delay: a delay in samples needs a sample rate: give --rate HZ")
        return None
    from polyrob.analysis.sampled_data import SamplingSpec

    return SamplingSpec(float(rate), 1 if delay is None else int(delay))


# --------------------------------------------------------------------------- argparse types
# argparse reports an ArgumentTypeError as "argument --mc: <message>" on the one line
# PolyrobParser.error prints.


def int_at_least(low: int):
    def parse(text):
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"'{text}' is not an integer") from None
        if value < low:
            raise argparse.ArgumentTypeError(f"must be an integer >= {low}, got {value}")
        return value

    parse.__name__ = f"integer >= {low}"
    return parse


def _float(text) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a number") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text}")
    return value


def positive_float(text) -> float:
    value = _float(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
    return value


def nonnegative_float(text) -> float:
    value = _float(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text}")
    return value


def fraction(text) -> float:
    value = _float(text)
    if not 0 < value < 1:
        raise argparse.ArgumentTypeError(f"must be in (0, 1), got {text}")
    return value


# --------------------------------------------------------------------------- validation at the rate
# ``--encoder-bits`` is read as ``args.encoder_bits`` by the validation and by the weights' sensor-noise
# level alike: whichever group defines it first owns the option, the other reads the same attribute.
# The rate and the delay are the certificate's (``args.rate``, ``args.delay_samples`` when the command
# has them; else 1 kHz and one sample).

#: The loop's rate (Hz) when the command states none.
DEFAULT_RATE = 1000.0
#: Encoder bits per turn when the command states none (``--encoder-bits`` left to a per-robot default elsewhere).
DEFAULT_ENCODER_BITS = 18


def add_validation_arguments(parser, *, true_robots: int = 20) -> None:
    """The group "validation at the rate" of ``parser`` (an option another group defined already is kept).

    ``true_robots``: the default of ``--true-robots`` (0: the validation runs only when asked).
    """
    g = parser.add_argument_group(
        "validation at the rate",
        "run -o DIR: the controller, discretised, closed on true robots drawn from the set (the nonlinear arm, "
        "one sample of delay, quantised encoders, friction the inner model does not have)",
    )
    have = getattr(parser, "_option_string_actions", {})
    if "--encoder-bits" not in have:
        g.add_argument(
            "--encoder-bits",
            dest="encoder_bits",
            type=int_at_least(4),
            default=DEFAULT_ENCODER_BITS,
            help="joint encoder resolution in bits per turn (LSB = 2 pi / 2^B; default %(default)s)",
        )
    g.add_argument(
        "--friction-viscous",
        type=nonnegative_float,
        default=1.0,
        help="viscous friction on every joint, N m s/rad, not in the inner model (default 1)",
    )
    g.add_argument(
        "--friction-coulomb",
        type=nonnegative_float,
        default=2.0,
        help="Coulomb friction on every joint, N m, not in the inner model (default 2; c tanh(qdot / 0.01 rad/s))",
    )
    g.add_argument(
        "--true-robots",
        type=int_at_least(0),
        default=true_robots,
        help="true robots drawn from the set for the validation at the rate, half at its vertices "
        "(default %(default)s; 0: skip it)",
    )


def rate_conditions_from_args(args):
    """The :class:`~polyrob.validate.at_rate.loop.RealLoopConditions` of the options, or ``None`` (0 true robots)."""
    from polyrob.validate.at_rate.loop import RealLoopConditions

    if not getattr(args, "true_robots", 0):
        return None
    rate = getattr(args, "rate", None) or DEFAULT_RATE
    delay = getattr(args, "delay_samples", None)
    return RealLoopConditions(
        rate=float(rate),
        delay_samples=1 if delay is None else int(delay),
        encoder_bits=getattr(args, "encoder_bits", None) or DEFAULT_ENCODER_BITS,
        friction_viscous=float(args.friction_viscous),
        friction_coulomb=float(args.friction_coulomb),
    )


def rate_conditions_dict(args) -> dict:
    """The conditions of the options as plain fields (a batch's settings travel to its workers as data)."""
    c = rate_conditions_from_args(args)
    if c is None:
        return {}
    return {k: getattr(c, k) for k in ("rate", "delay_samples", "encoder_bits", "friction_viscous", "friction_coulomb")}


# --------------------------------------------------------------------------- Coulomb friction in the certificate's words


def add_coulomb_argument(group) -> None:
    """``--coulomb N_M``: the Coulomb level the certificate states the tracking error of (docs/synthesis.md)."""
    group.add_argument(
        "--coulomb",
        default=None,
        metavar="N_M",
        help="Coulomb friction |d| <= N_M per joint (one value, or one per joint, comma-separated), not in the model: "
        "the certificate states the tracking error it causes (default: the robot-uncertainty set's friction)",
    )


def coulomb_from_args(args):
    """The ``--coulomb`` levels (N m, ``>= 0``), or ``None``."""
    text = getattr(args, "coulomb", None)
    if text is None:
        return None
    vals = parse_list(text, "--coulomb", positive=False)
    if any(v < 0 for v in vals):
        raise ArgumentError(f"--coulomb: give levels >= 0 N m, got '{text}'")
    return vals


def add_proof_dir_argument(parser) -> None:
    """``--proof-dir``: where an arm's ``--certify`` proof keeps its state and its finished proofs."""
    parser.add_argument(
        "--proof-dir",
        default=None,
        metavar="DIR",
        help="--certify: where an arm's proof keeps its state (a proof given up goes on from there when run "
        "again) and its finished proofs (reused at once for the same robot, set and task); default "
        "$POLYROB_CACHE_DIR/proofs or ~/.cache/polyrob/proofs; 'none' keeps nothing",
    )


def proof_options(args, names=("time_limit", "rel_tol", "max_boxes")) -> dict:
    """The proof's options the user typed: those of ``names`` given, and ``checkpoint_dir`` (``--proof-dir``)."""
    out = {k: getattr(args, k) for k in names if getattr(args, k, None) is not None}
    folder = getattr(args, "proof_dir", None)
    if folder is not None:
        out["checkpoint_dir"] = None if folder.strip().lower() == "none" else folder
    return out
