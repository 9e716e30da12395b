"""``polyrob synth``: μ-synthesis with its certificate; the synthesis options and outputs ``polyrob run`` shares."""

from __future__ import annotations

from polyrob.cli.analyze import (
    add_jerk_argument,
    add_moving_harmonics_argument,
    check_jerk_applies,
    moving_asked,
    moving_options,
)
from polyrob.cli.common import (
    Output,
    add_domain_arguments,
    add_output_flags,
    add_robot_arguments,
    add_weight_arguments,
    alphas_from_args,
    exit_status,
    robot_from_args,
    scale_names,
)
from polyrob.cli.options import (
    add_coulomb_argument,
    add_sampling_arguments,
    add_validation_arguments,
    coulomb_from_args,
    int_at_least,
    positive_float,
    rate_conditions_from_args,
    sampling_from_args,
)
from polyrob.cli.plant import add_plant_arguments, bounds_words, problem_from_args
from polyrob.errors import ArgumentError

__all__ = [
    "register",
    "add_synthesis_arguments",
    "options_from_args",
    "check_output",
    "print_design",
    "print_limit",
    "ruled_out",
    "print_input_check",
    "save_design",
]


def options_from_args(args, out) -> dict:
    """``musyn`` keyword arguments from the synthesis options of ``synth`` and ``run``."""
    from polyrob.pipeline import synthesis_options

    return synthesis_options(
        structure=args.structure,
        complex_blocks=args.complex,
        max_iter=args.max_iter,
        starts=args.starts,
        init=args.init,
        progress=out.progress,
        time_limit=args.time_limit,
        target=args.target,
    )


def check_output(args) -> None:
    if args.output:
        from polyrob.io.paths import check_output_path

        check_output_path(args.output, "-o")


def print_design(design, out) -> None:
    r = design.result
    from polyrob.report.numbers import NO_HINF_STEP, gamma_text

    gam = list(r.gamma_history)
    out.line(f"{'iter':>4}  {'peak mu (upper)':>16}  {'gamma':>14}")
    for i, mu in enumerate(r.mu_history):
        out.line(f"{i + 1:>4}  {mu:>16.5g}  {gamma_text(gam[i]) if i < len(gam) else NO_HINF_STEP:>14}")
    if any(gamma_text(g) == NO_HINF_STEP for g in gam[: len(r.mu_history)]):
        out.line(
            f"({NO_HINF_STEP}: that controller was not made by an H-inf K-step (the start controller, a tuned "
            "PID or a reduced one), so it has no gamma)"
        )
    out.line(
        f"controller: {r.structure}, order {r.order}; peak mu in [{r.peak_mu_lower:.4g}, {r.peak_mu:.4g}] "
        f"(bounds on the frequency grid) at {r.peak_frequency:.4g} rad/s ({r.iterations} iterations, {r.seconds:.1f} s)"
    )
    between = getattr(getattr(getattr(r, "certificate", None), "mu", None), "between", None)
    if between is not None:
        out.line("synthesis grid, between its points: " + between.sentence())
    if design.reduced is not None:
        red = design.reduced
        out.line("order reduction (order: peak mu upper bound):")
        for row in red.table:
            out.line(f"  {row['order']:>4}: {row['peak_mu']:.5g}{'' if row.get('stable', True) else ' (unstable)'}")
        out.line(f"reduced controller: order {red.order}, peak mu in [{red.peak_mu_lower:.4g}, {red.peak_mu:.4g}]")
    for note in design.notes:
        out.line(f"note: {note}")
    stopped = r.info.get("stopped_by") if isinstance(r.info, dict) else None
    if stopped:
        out.line(f"synthesis stopped by {stopped}: the best controller so far is kept")


def print_limit(problem, out) -> dict:
    """Print what no controller can beat at these weights (the robot's unstable poles)."""
    limit = problem.performance_limit()
    out.line(limit.summary())
    return limit.to_dict()


def ruled_out(doc: dict, args, out) -> bool:
    """Whether the performance limit already proves mu >= 1 for every controller (then say so, once)."""
    limit = doc.get("performance_limit") or {}
    if not limit.get("excludes_mu_below_one") or args.anyway:
        return False
    line = (
        f"stopped: the performance limit proves mu >= {limit['bound']:.4g} for every controller at these weights, "
        "so no synthesis can certify this problem; try `polyrob synth --max-bandwidth` (the largest bandwidth "
        "factor that can be certified), a smaller domain, or --anyway for the best controller all the same"
    )
    doc["verdict"] = line
    out.line(line)
    out.document(doc)
    return True


def print_input_check(problem, out) -> dict:
    """Say when the model's input matrices lose the definiteness of the robot's ``M(q)^-1``."""
    from polyrob.plant.coverage import input_definiteness

    check = input_definiteness(problem.unc)
    if check["fraction"] > 0:
        out.line(
            f"model check: {100 * check['fraction']:.0f} % of the {problem.model} model's members "
            f"({check['samples']} uniform samples) have an input matrix B = M(q)^-1 that is not positive "
            f"definite (least eigenvalue {check['least']:.3g}; the robot's never is): a robust controller "
            "must also stabilise inputs that act in reverse, so expect mu >> 1 on this model"
        )
    return check


def save_design(design, problem, args, out, info_extra=None, certificate_extra=None, path=None):
    from polyrob.io.controller import save_controller
    from polyrob.provenance import Provenance

    info = problem.description()
    info.update(info_extra or {})
    cert = dict(design.record, **(certificate_extra or {}))
    from polyrob.cli.interrupt import keep

    made = Provenance.capture(robot=problem.robot, description=info)  # the robot's URDF hashed too
    path = save_controller(design.controller, path or args.output, certificate=cert, info=info, provenance=made)
    keep(path)  # complete on disk (written atomically): an interrupt from now on keeps it
    out.line(f"wrote {path}")
    return str(path)


def max_bandwidth_design(problem, args, out, options: dict):
    """``--max-bandwidth``: the largest certified bandwidth factor, printed; returns ``(design, scaled problem, weights)``."""
    from polyrob.analysis.lpv.constant import applies
    from polyrob.pipeline import design_max_bandwidth
    from polyrob.pipeline.design import scaled_problem

    scale = scale_names(args.scale_only)
    alphas = alphas_from_args(args.alphas)
    moving = bool(args.moving) and applies(problem) is None  # the inner-gain route: one mu test per factor
    what = "the moving-robot certificate (masses constant, the state at any rate)" if moving else "mu < 1"
    out.stage(f"largest bandwidth factor with {what} (scaling {', '.join(scale)}; a synthesis per factor)")
    rate = getattr(args, "rate", None)  # the sampled-data options, when given (docs/synthesis.md)
    design, res = design_max_bandwidth(problem, scale=scale, alphas=alphas, moving=moving, rate=rate, **options)
    out.line(f"{'alpha':>10}  {('moving-robot ' if moving else '') + 'mu at every frequency (inf: not certified)':>18}")
    for alpha, mu in res.history:
        out.line(f"{alpha:>10.4g}  {mu:>18.5g}")
    for alpha, bound in res.excluded:
        out.line(f"{alpha:>10.4g}  {'>= ' + format(bound, '.5g'):>18}  (performance limit: not synthesised)")
    beyond = (
        f"alpha {res.bracket[1]:.4g} does not reach it"
        if res.bracket[1] < float("inf")
        else "the largest factor scanned: larger ones were not tried, see --alphas"
    )
    out.line(
        f"largest certified alpha{' for the moving robot' if moving else ''}: {res.alpha:.4g} "
        f"(mu <= {res.peak_mu:.4g} at every frequency; {beyond}), "
        f"controller order {res.result.order}"
    )
    if res.bound_hit:
        out.line(f"bound hit: {res.bound_hit}")
    if res.crossover == res.crossover:  # not nan
        cap = f" (cap {res.crossover_limit:.4g} rad/s)" if res.crossover_limit == res.crossover_limit else ""
        out.line(f"nominal loop crossover at alpha {res.alpha:.4g}: {res.crossover:.4g} rad/s{cap}")
    out.line("weights: " + ", ".join(f"{k} = {list(v)}" for k, v in res.hyperparameters.items()))
    extra = {"weights": {k: list(v) for k, v in res.hyperparameters.items()}}
    return design, scaled_problem(problem, res.hyperparameters), extra


def cmd_synth(args) -> int:
    from polyrob.pipeline import design_controller, friction_statement

    check_output(args)
    sampling = sampling_from_args(args)
    args.moving = bool(moving_asked(args)) or args.tune_moving > 0
    if args.tune_moving < 0:
        raise ArgumentError(f"--tune-moving takes a number of rounds >= 1, got {args.tune_moving}")
    if args.max_bandwidth:  # option errors before any work
        scale_names(args.scale_only), alphas_from_args(args.alphas)
    at_rate = rate_conditions_from_args(args)
    coulomb = coulomb_from_args(args)
    moving_opts = moving_options(args) if args.moving else None  # its refusals before any work
    stages = ["bounds", "largest bandwidth" if args.max_bandwidth else "synthesis"]
    tuning = f"tuning for the moving robot (up to {args.tune_moving} rounds"  # weighed per round (progress.py)
    stages += [tuning] * (args.tune_moving > 0) + ["moving-robot"] * args.moving
    stages += ["validation"] * (at_rate is not None)
    out = Output(args, stages=len(stages), job=stages)
    options = options_from_args(args, out)
    from polyrob.pipeline.design import TRUE_ROBOT_STARTS, TRUE_ROBOTS_NOT_IN_SEARCH

    if args.init in TRUE_ROBOT_STARTS and args.max_bandwidth:
        raise ArgumentError(TRUE_ROBOTS_NOT_IN_SEARCH)
    if args.init in TRUE_ROBOT_STARTS and getattr(args, "robot_uncertainty", None) is None and args.link_error is None:
        raise ArgumentError(
            "--init true-robots draws true robots from a robot-uncertainty set: give --robot-uncertainty FILE or "
            "--link-error P"
        )
    robot = robot_from_args(args)
    if args.init in TRUE_ROBOT_STARTS:
        true_robots_structure_holds_pid(args.structure, robot.m)
    if coulomb is not None:  # one level or one per joint: refused before any work
        from polyrob.synthesis.integral import coulomb_levels

        coulomb_levels(robot, coulomb)
    if args.qdddot_max is not None and not args.moving:
        raise ArgumentError("--qdddot-max bounds the jerk in the moving-robot certificate: add --moving, or drop it")
    problem = problem_from_args(robot, args, out)
    check_jerk_applies(args, problem)  # a task without an inner layer, before the synthesis
    if args.tune_moving:  # a model of constants to tune on, before the synthesis
        from polyrob.analysis.lpv.constant import MOVING_MODEL, applies

        if applies(problem) and problem.model not in MOVING_MODEL:
            raise ArgumentError(f"--tune-moving needs a model of constants: {applies(problem)}")
    out.line(
        f"robot {robot.name}: {problem.unc.n_params} real parameters ({bounds_words(problem)}, "
        f"{problem.model} model), structure {args.structure}"
    )
    doc = {"robot": robot.name, "problem": problem.description()}
    if args.max_bandwidth:
        design, problem, extra = max_bandwidth_design(problem, args, out, options)
        doc["problem"].update(extra)
        doc["bandwidth_scaling"] = design.record["bandwidth_scaling"]
    else:
        doc["performance_limit"] = print_limit(problem, out)
        doc["input_definiteness"] = print_input_check(problem, out)
        if ruled_out(doc, args, out):
            return 1
        out.stage(f"synthesis ({args.structure}" + (", then order reduction" if args.reduce else "") + ")")
        design = design_controller(problem, reduce=args.reduce, reduce_max_order=args.reduce_max_order, **options)
        print_design(design, out)
        extra = None
    scalings, held = None, problem
    if args.tune_moving:  # before the loop at the rate is checked: that check is of the tuned controller
        design, scalings, held = moving_tuning_stage(problem, design, args.tune_moving, out)
    doc["synthesis"] = design.summary()
    sampled_record = None
    if sampling is not None:  # the loop as it runs: its certificate is the design's verdict
        design, doc["sampled"] = sampled_check(problem, design, sampling, out)
        # export reads the rate, delay and hold the certificate covers (cli/files.py certified_sampling)
        sampled_record = {k: doc["sampled"][k] for k in ("rate_hz", "delay_samples", "hold", "words")}
    # the moving check on the model of constants the tuning built (a per-link set's is built once)
    moving = moving_check(held, design.controller, out, moving_opts, scalings) if args.moving else None
    if moving is not None:
        doc["moving"] = moving
    if args.output:
        doc["output"] = save_design(
            design,
            problem,
            args,
            out,
            info_extra=extra,
            certificate_extra={
                **({} if moving is None else {"moving": moving}),
                **({} if sampled_record is None else {"sampled": sampled_record}),
            }
            or None,
        )
    if at_rate is not None:  # after the controller file: a stop during the simulations keeps it
        doc["validation_at_rate"] = validation_at_rate_stage(problem, design.controller, at_rate, args, out)
    true_robots = true_robot_line(problem, design, out)
    if true_robots is not None:
        doc["true_robots"] = true_robots
    cert = design.certificate
    doc["covers"] = cert.scope.sentence()
    doc["certificate"] = cert.summary()
    doc["verdict"] = "verdict: " + cert.verdict
    out.line(doc["verdict"])
    out.line(cert.details())
    from polyrob.synthesis.true_robots import share_of_mu

    share = None if true_robots is None or cert.certified else share_of_mu(true_robots, cert.mu_lower)
    if share is not None:  # whose the failure is: the controller's or the model's (read, not a status)
        doc["share_of_mu"] = share
        out.line(share)
    friction = friction_statement(problem, design.controller, coulomb)
    if friction is not None:  # beside the covers line: what Coulomb friction does to the error
        doc["friction"] = friction
        out.line(friction["words"])
    from polyrob.analysis.lpv.moving_result import refuses

    if cert.certified and refuses(moving):
        doc["exit"] = (
            "exit status 1: the moving-robot certificate asked for with --moving is not CERTIFIED "
            f"({moving.get('status')}), though mu certifies every frozen robot"
        )
        out.line(doc["exit"])
    out.document(doc)
    return exit_status(cert, moving)


def true_robots_structure_holds_pid(structure: str, m: int) -> None:
    """``--init true-robots --structure ss:N`` starts from the per-joint PID (order ``2 m``): refused below it.

    The state-space structure is started from the PID's realisation; with
    fewer states it cannot hold it and the tuning's warm start stabilises
    none of the true robots (panda: ss:12 against its PID's 14 states,
    measured after minutes of bounds and tuning).
    """
    text = str(structure)
    if text.startswith("ss:"):
        try:
            order = int(text[3:])
        except ValueError:
            return  # the structure's own parser says what is wrong
        if order < 2 * m:
            raise ArgumentError(
                f"--structure {text} --init true-robots: the structure starts from the per-joint PID, "
                f"{2 * m} states on {m} joints; give --structure ss:{2 * m} or more"
            )


def true_robot_line(problem, design, out) -> dict | None:
    """Where true robots can be drawn (:func:`~polyrob.synthesis.true_robots.check_of_problem`): the controller on
    them, beside μ (a sampled lower bound).

    A controller made by ``--init true-robots`` (``max_iter=1``) was checked on
    the same draw when it was tuned: that check is said, not computed again.
    """
    from polyrob.synthesis.true_robots import check_of_problem

    info = design.result.info if isinstance(getattr(design.result, "info", None), dict) else {}
    made = info.get("true_robots")
    if made is not None and design.reduced is None:
        out.line(made["words"])
        return made
    check = check_of_problem(problem, design.controller)
    if check is None:
        return None
    out.line(check.words())
    return check.to_dict()


def sampled_check(problem, design, sampling, out):
    """The design certified again as the sampled loop (:mod:`polyrob.analysis.sampled_data`): ``(design, summary)``."""
    from polyrob.analysis.sampled_data import sampled_certificate, sampling_words

    out.line(f"certificate of the loop {sampling_words(sampling)} (docs/certificates.md)")
    sampled = sampled_certificate(problem.P, design.controller, sampling, scope=problem.scope(), progress=out.progress)
    out.line(sampled.line())
    if not sampled.certificate.certified and design.certificate.certified:
        out.line(sampled.instead_line(design.certificate))
    return design.certified_by(sampled.certificate), sampled.summary()


def add_synthesis_arguments(p) -> None:
    add_robot_arguments(p)
    add_domain_arguments(p)
    add_weight_arguments(p)
    add_plant_arguments(p)
    add_sampling_arguments(p)
    g = p.add_argument_group("synthesis")
    g.add_argument(
        "--structure", default="full", help="full (D-K / D-G-K), tfN (e.g. tf3: each K_ij of order N), pid, ss:N"
    )
    g.add_argument("--complex", action="store_true", help="treat the real parameters as complex (plain D-K)")
    g.add_argument(
        "--max-iter",
        type=int_at_least(1),
        default=None,
        help="D-K iterations (default 20; fixed structure: outer iterations, default 40)",
    )
    g.add_argument("--starts", type=int_at_least(1), default=5, help="fixed structure: optimisation starts")
    g.add_argument(
        "--init",
        default=None,
        metavar="paper|pid|true-robots|true-robots+corners|FILE",
        help="start from the paper's K* ('paper', fixed structures), from a per-joint PID tuned to the weights "
        "('pid'; the default on an arm's default task), from that PID tuned further on the frozen loops of "
        "true robots drawn from a robot-uncertainty set ('true-robots', multi-model H-inf, in the --structure "
        "asked for, a PID for full; with --max-iter 1 it is the answer, certified on the model; "
        "'true-robots+corners': on the uncertainty model's corners too, what its certificate checks) or from a "
        "controller file (K.json, K.mat), "
        "e.g. one designed at a nearby bandwidth",
    )
    g.add_argument("--reduce", action="store_true", help="reduce the full-order controller (balanced truncation)")
    g.add_argument(
        "--target",
        type=positive_float,
        default=None,
        metavar="MU",
        help="full order: stop the D-K iteration once its grid peak mu is below MU (MATLAB's TargetPerf); "
        "the certificate is decided afterwards",
    )
    g.add_argument(
        "--reduce-max-order", type=int_at_least(1), default=20, help="--reduce: largest controller order accepted"
    )
    g.add_argument(
        "--time-limit",
        type=float,
        default=None,
        metavar="SECONDS",
        help="a safety net (default none): no new synthesis iteration (or start) after this many seconds of wall "
        "clock; the best controller so far is certified and the output names the limit. Without it the synthesis "
        "is bounded by its iterations only, so its result does not depend on the machine's load",
    )
    g.add_argument(
        "--anyway",
        action="store_true",
        help="synthesise even when the performance limit proves mu >= 1 for every controller (the best one)",
    )
    add_output_flags(p)
    p.add_argument("-o", "--output", default=None, help="write the controller, its certificate and its problem (JSON)")


def add_bandwidth_arguments(p) -> None:
    """``--max-bandwidth`` and its options (``synth`` and ``run``)."""
    g = p.add_argument_group("bandwidth scan")
    g.add_argument(
        "--max-bandwidth",
        action="store_true",
        help="find the largest scaling of the weights' bandwidths with certified mu < 1",
    )
    g.add_argument(
        "--scale-only",
        default="omega_b,omega_bt",
        help="--max-bandwidth: weight hyperparameters multiplied by the factor",
    )
    g.add_argument(
        "--alphas", default=None, help="--max-bandwidth: comma-separated scan of the factor (default 0.125,0.25,...,32)"
    )


def moving_tuning_stage(problem, design, rounds: int, out):
    """``synth --tune-moving N``: the design's PID tuned on the moving-robot structure; ``(design, scalings, held)``,
    ``held`` the problem on its model of constants."""
    from polyrob.analysis.lpv.constant import moving_problem
    from polyrob.pipeline.design import tuned_for_moving

    out.stage(f"tuning for the moving robot (up to {rounds} rounds: scalings, then the PID on mu)")
    held = moving_problem(problem)
    design = tuned_for_moving(problem, design, rounds=rounds, held=held)
    tuning = design.record["moving_tuning"]
    history = f"tuned for the moving robot: merged-structure mu {', '.join(f'{h:.4g}' for h in tuning['history'])}"
    if not tuning.get("kept", True):  # the tuned PID lost the frozen certificate and won no other: not kept
        out.line(f"{history} ({tuning['seconds']:.0f} s); not kept: its frozen mu {tuning['frozen_mu']:.4g} lost the "
                 f"design's certificate (mu {design.certificate.bound:.4g}), the design stays")  # fmt: skip
        return design, None, held
    out.line(f"{history} ({tuning['seconds']:.0f} s); the frozen robot's mu is now {design.certificate.bound:.4g}")
    return design, tuning["scalings"], held


def moving_check(problem, K, out, options=None, scalings=None) -> dict:
    """``synth --moving``: the moving-robot certificate of the synthesised ``K``, printed; its summary."""
    from polyrob.analysis.lpv.constant import robot_in_motion_certificate

    out.stage("moving-robot certificate of the controller (rate-bounded LPV analysis, docs/certificates.md)")
    mv = robot_in_motion_certificate(problem, K, scalings=scalings, **(options or {}))
    out.line(mv.verdict)
    if mv.computed:
        out.line(mv.details())
    return mv.summary()


def validation_at_rate_stage(problem, K, conditions, args, out) -> dict:
    """``synth --true-robots N``: the controller at the rate on drawn true robots; with ``-o K.json`` the whole
    summary goes to ``K.validation.json`` and the document keeps its figures per reference."""
    import json
    from pathlib import Path

    from polyrob.io.atomic import atomic_write, json_default
    from polyrob.validate.at_rate.runs import validate_at_rate

    out.stage(f"validation at the rate ({args.true_robots} true robots drawn from the set)")
    res = validate_at_rate(problem.robot, K, problem.pldi, conditions=conditions, true_robots=args.true_robots)
    out.line(res.verdict())
    summary = res.summary()
    short = {
        k: summary[k] for k in ("conditions", "uncertainty", "true_robots", "by_reference", "meets_bar", "verdict")
    }
    if args.output:
        path = Path(args.output).with_suffix(".validation.json")
        atomic_write(path, lambda f: f.write(json.dumps(summary, indent=1, default=json_default)))
        out.line(f"wrote {path}")
        short["file"] = str(path)
    return short


def register(sub) -> None:
    p = sub.add_parser("synth", help="mu-synthesis: full order (D-K, D-G-K) or fixed structure")
    add_synthesis_arguments(p)
    add_bandwidth_arguments(p)
    p.add_argument(
        "--moving",
        action="store_true",
        help="also the moving-robot certificate of the synthesised controller, printed and saved with -o "
        "(minutes for a 20-state loop; docs/certificates.md); the exit status is 0 only when mu and, once computed, "
        "the moving-robot certificate are both CERTIFIED. "
        "With --max-bandwidth on an inner-gain model (the arms' default task) a factor counts only when its "
        "controller has the moving-robot certificate too",
    )
    p.add_argument(
        "--tune-moving",
        type=int,
        default=0,
        metavar="ROUNDS",
        help="then tune the per-joint PID on the moving-robot certificate's own structure for up to ROUNDS rounds "
        "(its scalings searched, then mu synthesis of the PID on it; an inner-gain or per-link set's model; minutes a "
        "round on an arm, docs/certificates.md); implies --moving",
    )
    add_moving_harmonics_argument(p)
    add_jerk_argument(p)
    add_validation_arguments(p, true_robots=0)  # synth validates only when asked (minutes on an arm)
    add_coulomb_argument(p)
    p.set_defaults(func=cmd_synth)
