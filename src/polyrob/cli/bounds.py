"""``polyrob bounds``: intervals and a polytope of the Jacobians over the domain (a PLDI file)."""

from __future__ import annotations

from pathlib import Path

from polyrob.cli.common import (
    Output,
    add_domain_arguments,
    add_output_flags,
    add_robot_arguments,
    domain_from_args,
    robot_from_args,
)
from polyrob.cli.options import add_proof_dir_argument, fraction, int_at_least, positive_float, proof_options
from polyrob.errors import ArgumentError, CertificationError

__all__ = ["register", "save_pair"]


def save_pair(pldi, output) -> tuple[Path, Path]:
    """Save a PLDI as ``stem.json`` + ``stem.npz``; an interrupted save leaves neither new file."""
    from polyrob.io.paths import pair_paths

    json_path, npz_path = pair_paths(output)
    before = {p: p.exists() for p in (json_path, npz_path)}
    try:
        return pldi.save(json_path)
    except BaseException:
        for p, existed in before.items():
            if not existed:
                p.unlink(missing_ok=True)
        raise


def cmd_bounds(args) -> int:
    from polyrob.bounds.pldi import bound_pldi
    from polyrob.io.paths import check_output_path, pair_paths
    from polyrob.pipeline.reports import model_report, pldi_report

    if args.output:  # before any work: a refused path leaves nothing behind
        for path in (args.output, *pair_paths(args.output)):
            check_output_path(path, "-o")
    certify_options = proof_options(args, ("time_limit", "rel_tol", "max_boxes", "partial"))
    if not args.certify and certify_options:
        raise ArgumentError(
            "--time-limit, --rel-tol, --max-boxes, --complete-proof and --proof-dir set the interval-arithmetic "
            "proof: use them with --certify"
        )
    # one progress line for the whole job (a --certify proof of an arm runs for minutes)
    out = Output(args, stages=2 if args.models else 1, job=["bounds"] + (["uncertainty models"] if args.models else []))
    robot = robot_from_args(args)
    domain = domain_from_args(robot, args)
    out.stage(
        f"bounds: {robot.name} ({robot.m} joints) over domain '{domain.name}'"
        + (", certified by interval arithmetic" if args.certify else "")
    )
    try:
        pldi = bound_pldi(
            robot,
            domain,
            samples=args.samples,
            nominal=args.nominal,
            certify=args.certify,
            certify_options=certify_options or None,
            coverage=args.coverage,
            seed=args.seed,
            progress=out.progress,
        )
    except CertificationError as exc:  # the library names its parameters; the user typed options
        text = str(exc).replace("time_limit", "--time-limit").replace("rel_tol", "--rel-tol")
        text = text.replace("max_boxes", "--max-boxes")
        raise CertificationError(text) from None
    report = pldi_report(pldi, robot.joint_names)
    if args.models:
        out.stage("uncertainty models: size and coverage on fresh samples")
        report["uncertainty_models"] = model_report(pldi, robot)
    if args.output:
        json_path, npz_path = save_pair(pldi, args.output)
        report["files"] = [str(json_path), str(npz_path)]
    out.document(report)
    if out.json:
        return 0
    print(f"robot {robot.name}, domain {domain.name}, {len(pldi.entries)} varying entries")
    print(pldi.table())
    poly = report["polytope"]
    if poly["volume_hits"]:
        volume = f"volume / interval box ~ {poly['volume_ratio']:.3g} ({poly['volume_hits']} of {poly['volume_samples']} box points inside)"
    elif poly["volume_samples"]:
        volume = f"volume / interval box < {poly['volume_ratio_bound']:.2g} (0 of {poly['volume_samples']} box points inside)"
    else:
        volume = "volume ratio not computed"
    print(
        f"polytope: {poly['halfspaces']} half-spaces"
        + (f", {poly['vertices']} vertices" if poly["vertices"] is not None else "")
        + f", reduced dimension {poly['reduced_dim']}, {volume}"
    )
    if "refinement" in report:
        r = report["refinement"]
        print(
            f"local search widened the sampled intervals by at most {r['max_percent']:.3g} % "
            f"({r['entry']}); {r['verification_rounds']} verification round(s)"
        )
    factors = (pldi.info.get("certify") or {}).get("factors")
    if factors:
        proof = pldi.info["certify"]
        kept = proof.get("resumed_boxes") or 0
        earlier = f", {kept} of them by an earlier run, kept in {proof['checkpoint']}" if kept else ""
        print(
            f"proved by interval arithmetic over the task box: the factor ranges of {', '.join(factors)} "
            f"({proof['boxes']} boxes, {proof['seconds']:.1f} s{earlier}); the A, B intervals above are sampled"
        )
        tight = proof["tightness"]
        if proof["done"] < 1.0:
            print(
                f"the proof stopped at its work limit with {100 * proof['done']:.1f} % of its refinement done: "
                f"the ranges proved by then hold, wider than its tolerance (widths up to {tight['max']:.3g}x the "
                f"values attained, median {tight['median']:.3g}); the same command again goes on from there "
                "(--max-boxes N boxes more) and tightens them"
            )
        else:
            print(
                f"within the tolerance: widths up to {tight['max']:.3g}x the values attained "
                f"(median {tight['median']:.3g})"
            )
    if report["coverage"] is not None:
        variants = getattr(robot, "variants", None)
        listed = len(variants()) if callable(variants) else 1
        among = f" of the {listed} true robots the bounds were taken over" if listed > 1 else ""
        print(f"coverage: {report['coverage']:.4f} of {report['coverage_points']} fresh points{among}")
    if report["dropped_positions"]:
        print("positions the dynamics do not depend on: " + ", ".join(report["dropped_positions"]))
    for name, m in report.get("uncertainty_models", {}).items():
        if "error" in m:
            print(f"uncertainty model {name}: not built ({m['error']})")
            continue
        print(
            f"uncertainty model {name}: {m['parameters']} real parameters, Delta {m['delta_shape'][0]}x"
            f"{m['delta_shape'][1]}, coverage {m['coverage']:.4f} of {m['coverage_points']} fresh points, "
            f"volume / polytope ~ {m['volume_over_polytope']:.3g}, "
            f"B = M^-1 not positive definite in {100 * m['input_not_positive_definite']:.3g} % of its members"
        )
    print(f"time: {report['seconds']:.2f} s")
    if args.output:
        print(f"wrote {report['files'][0]} and {report['files'][1]}")
    return 0


def register(sub) -> None:
    p = sub.add_parser("bounds", help="bound the Jacobians over the domain: intervals and a polytope (PLDI)")
    add_robot_arguments(p)
    add_domain_arguments(p)
    p.add_argument(
        "--certify",
        action="store_true",
        help="prove by interval arithmetic: the intervals over a torque box (up to 3 joints), or an arm's "
        "computed-torque factor ranges over its task (up to 7 joints)",
    )
    p.add_argument(
        "--max-boxes",
        type=int_at_least(1),
        default=None,
        help="--certify: boxes the proof evaluates before it stops (a count of work, not seconds); an arm's proof then gives the ranges proved by then, wider than its tolerance, unless --complete-proof; a torque box's gives up",
    )
    p.add_argument(
        "--time-limit",
        type=positive_float,
        default=None,
        help="--certify: a safety net of wall-clock seconds before the proof gives up (default none: the proof "
        "is bounded by its number of boxes, so its answer does not depend on the machine's load)",
    )
    add_proof_dir_argument(p)
    p.add_argument(
        "--complete-proof",
        dest="partial",
        action="store_false",
        default=None,
        help="--certify of an arm: refuse ranges the proof has not closed within its tolerance by the work limit "
        "(default: the ranges proved by then are taken, wider, and the output says how far the proof got)",
    )
    p.add_argument(
        "--rel-tol",
        type=fraction,
        default=None,
        help="--certify: width tolerance relative to each interval (default 1e-5)",
    )
    p.add_argument(
        "--samples", type=int_at_least(1), default=None, help="Sobol' positions (default grows with the dimension)"
    )
    p.add_argument(
        "--nominal", default="equilibrium", choices=["equilibrium", "midpoint"], help="where A0, B0 are taken"
    )
    p.add_argument(
        "--coverage", type=int_at_least(0), default=10_000, help="fresh points for the coverage check (0 skips)"
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the designs")
    p.add_argument(
        "--no-models",
        dest="models",
        action="store_false",
        help="skip the uncertainty models' size and coverage (box and the default tight model)",
    )
    add_output_flags(p)
    p.add_argument(
        "-o",
        "--output",
        default=None,
        help="write the PLDI as STEM.json + STEM.npz (any .json/.npz suffix names the same pair)",
    )
    p.set_defaults(func=cmd_bounds)
