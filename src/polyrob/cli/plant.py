"""Options shared by ``analyze``, ``synth`` and ``run``: the PLDI, the uncertainty model, the problem."""

from __future__ import annotations

from polyrob.cli.common import (
    domain_from_args,
    domain_options_given,
    hyperparameters_from_args,
    limit_weights_from_args,
)
from polyrob.cli.options import MODEL_CHOICES, add_proof_dir_argument, int_at_least, proof_options
from polyrob.errors import ArgumentError, CertificationError

__all__ = ["add_plant_arguments", "pldi_path", "problem_from_args", "describe_source"]


def add_plant_arguments(p) -> None:
    p.add_argument(
        "--pldi",
        default=None,
        help="a PLDI file from `polyrob bounds -o` (STEM, STEM.json or STEM.npz) instead of bounding again",
    )
    p.add_argument(
        "--uncertainty",
        default="auto",
        choices=MODEL_CHOICES,
        help="uncertainty model of the PLDI (box: one independent real parameter per entry, the paper's; "
        "inertia: M(q) on its L D L^T factors, positive definite in every member, any arm; inner-links-real: "
        "a per-link set's model (auto's inner-links) with its stiffness residual as one real scalar per entry "
        "instead of a complex block: tighter, slower)",
    )
    p.add_argument("--merge-symmetric", action="store_true", help="one repeated parameter for b_ij = b_ji")
    p.add_argument(
        "--certify",
        action="store_true",
        help="prove the bounds the model rests on by interval arithmetic (as `polyrob bounds --certify`): an arm's "
        "computed-torque factor ranges over its task (the inner-gain model then rests on them alone, and the "
        "certificate says proved), or the intervals over a torque box (up to 3 joints)",
    )
    p.add_argument(
        "--max-boxes",
        type=int_at_least(1),
        default=None,
        help="--certify: boxes the proof evaluates before it stops (a count of work, not seconds); an arm's proof then gives the ranges proved by then, wider than its tolerance; a torque box's gives up",
    )
    add_proof_dir_argument(p)


def pldi_path(args):
    """The JSON half of the ``--pldi`` pair, whatever suffix was given."""
    from polyrob.io.paths import pair_paths

    return pair_paths(args.pldi)[0] if args.pldi else None


def describe_source(robot, args) -> str:
    return f"reading the PLDI {pldi_path(args)}" if args.pldi else f"bounds: {robot.name} ({robot.m} joints)"


def bounds_words(problem) -> str:
    """What the uncertainty model's ranges come from, for a command's summary line.

    The PLDI and its enclosure, or, for a model that rests on an arm's proved
    factor ranges alone (``inner-gain`` under ``--certify``), those: its
    sampled A, B intervals are not what the certificate rests on.
    """
    from polyrob.plant.models.registry import enclosure_inputs

    inputs = enclosure_inputs(problem.unc)
    if "PLDI" not in inputs and inputs.get("factors") == "certified":
        return "proved factor ranges"
    return f"{problem.pldi.enclosure} PLDI"


def problem_from_args(robot, args, out, *, hyperparameters=None, check=None):
    """Domain (or ``--pldi``), weights and uncertainty model -> :class:`polyrob.pipeline.Problem`.

    ``check(partial_description)`` runs before the (slow) bounding step, on
    what is known then (robot, domain, weights), so a mismatched controller
    file is refused at once.
    """
    from polyrob.pipeline import build_problem

    if args.merge_symmetric and args.uncertainty != "box":
        raise ArgumentError("--merge-symmetric applies to the box model: add --uncertainty box")
    pldi = domain = None
    bound_options = getattr(args, "bound_options", None)  # the default task's search effort (cli.common)
    proof = proof_options(args, ("max_boxes",))  # synth's --time-limit is the synthesis's
    if proof and not getattr(args, "certify", False):
        raise ArgumentError("--max-boxes and --proof-dir set the interval-arithmetic proof: use them with --certify")
    if getattr(args, "certify", False):
        if args.pldi:
            raise ArgumentError("--pldi holds its bounds already: drop --certify, or prove them with `polyrob bounds "
                                "--certify -o STEM` and pass that file")  # fmt: skip
        bound_options = {**(bound_options or {}), "certify": True, "certify_options": proof}
    if args.pldi:
        from polyrob.bounds.pldi import PLDI

        if domain_options_given(args):
            raise ArgumentError("--pldi holds its own domain: drop --domain/--q-range/--qdot-max/--u-max/--*-scale")
        pldi = PLDI.load(pldi_path(args))
        known_domain = pldi.domain
    else:
        domain = domain_from_args(robot, args)
        known_domain = domain
    # an arm's default task brings its automatic weights (cli.common.hyperparameters_from_args)
    if hyperparameters is None:
        h = hyperparameters_from_args(robot.m, args, known_domain)
        h = limit_weights_from_args(robot, args, known_domain, h)  # effort and encoder noise (docs/synthesis.md)
    else:
        h = hyperparameters
    if check is not None:
        check(
            {
                "robot": robot.name,
                "m": robot.m,
                "domain": known_domain.to_dict(),
                "weights": {k: list(v) for k, v in h.items()},
            }
        )
    out.stage(f"{describe_source(robot, args)} over domain '{known_domain.name}', uncertainty model {args.uncertainty}")
    try:
        return build_problem(
            robot,
            domain,
            hyperparameters=h,
            uncertainty=args.uncertainty,
            pldi=pldi,
            merge_symmetric=args.merge_symmetric,
            progress=out.progress,
            bound_options=bound_options,
        )
    except CertificationError as exc:  # the library names its parameters; the user typed options
        text = str(exc).replace("raise the tolerance (rel_tol) or the work limit", "raise the work limit")
        text = text.replace("max_boxes", "--max-boxes")
        if "--rel-tol" in text or "--time-limit" in text:  # a torque box's proof: those options are bounds'
            text += " (--rel-tol and --time-limit are options of `polyrob bounds --certify -o STEM`; then --pldi STEM)"
        raise CertificationError(text) from None
