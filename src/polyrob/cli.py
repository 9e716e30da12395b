"""The ``polyrob`` command: a thin layer over the library's functions.

Every user error (a :class:`~polyrob.errors.PolyrobError`) ends as one line on
stderr and exit status 2; output files are written to a temporary file and
renamed, so a failed run never leaves a half-written file.
"""

from __future__ import annotations

import argparse
import json
import math
import sys

import numpy as np

from polyrob.errors import DomainError, PolyrobError

__all__ = ["main", "build_parser"]

DEFAULT_ROBOT = "planar_2r"


# --------------------------------------------------------------------------- option parsing


def _number(text: str, option: str) -> float:
    t = text.strip().lower()
    sign = -1.0 if t.startswith("-") else 1.0
    t = t.lstrip("+-")
    try:
        if t.endswith("pi"):
            factor = t[:-2].rstrip("*")
            return sign * (float(factor) if factor else 1.0) * math.pi
        return sign * float(t)
    except ValueError:
        raise DomainError(f"{option}: '{text}' is not a number") from None


def parse_joint_values(text: str | None, option: str, *, ranges: bool):
    """Parse ``4``, ``4,10``, ``joint1=4,joint2=10``, ``-pi:pi`` or ``joint2=-1:1``.

    Returns a value :meth:`polyrob.Domain.from_robot` takes: a number or a
    ``[lo, hi]`` pair for every joint, a list per joint, or a mapping.
    """
    if text is None:
        return None
    items = [s for s in text.split(",") if s.strip()]
    if not items:
        raise DomainError(f"{option}: empty value")

    def value(s):
        if ":" in s:
            lo, hi = s.split(":", 1)
            return [_number(lo, option), _number(hi, option)]
        if ranges:
            raise DomainError(f"{option}: give a range as LO:HI (e.g. {option}=-pi:pi), got '{s}'")
        return _number(s, option)

    if all("=" in s for s in items):
        return {k.strip(): value(v) for k, v in (s.split("=", 1) for s in items)}
    if any("=" in s for s in items):
        raise DomainError(f"{option}: mix of JOINT=VALUE and plain values in '{text}'")
    values = [value(s) for s in items]
    if len(values) == 1:
        return values[0]
    return [v if isinstance(v, list) else [-abs(v), abs(v)] for v in values]


def add_robot_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("robot", nargs="?", default=DEFAULT_ROBOT,
                        help=f"URDF file, bundled or example-robot-data name (default {DEFAULT_ROBOT})")
    parser.add_argument("--lock", default=None,
                        help="comma-separated joints to lock (default: grippers/fingers; '' locks none)")


def add_domain_arguments(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("domain")
    g.add_argument("--domain", default=None,
                   help="domain file (JSON/YAML) or a named domain of the robot (e.g. 'paper')")
    g.add_argument("--q-range", default=None,
                   help="position range, e.g. --q-range=-pi:pi or joint2=-1.5:1.5,joint3=0:2")
    g.add_argument("--qdot-max", default=None, help="velocity bound, e.g. 2 or joint1=4,joint2=10")
    g.add_argument("--u-max", default=None, help="torque bound, e.g. 50 or joint1=0,joint2=5")
    g.add_argument("--qdot-scale", type=float, default=1.0, help="scale the velocity box")
    g.add_argument("--u-scale", type=float, default=1.0, help="scale the torque box")


def robot_from_args(args):
    from polyrob.model.robots import load_robot

    lock = None if args.lock is None else [s.strip() for s in args.lock.split(",") if s.strip()]
    return load_robot(args.robot, lock=lock)


def domain_from_args(robot, args):
    from polyrob.bounds.domain import Domain

    return Domain.from_robot(
        robot,
        args.domain,
        q_range=parse_joint_values(args.q_range, "--q-range", ranges=True),
        qdot_max=parse_joint_values(args.qdot_max, "--qdot-max", ranges=False),
        u_max=parse_joint_values(args.u_max, "--u-max", ranges=False),
        qdot_scale=args.qdot_scale,
        u_scale=args.u_scale,
    )


# --------------------------------------------------------------------------- commands


def cmd_robots(args) -> int:
    from polyrob.model.robots import available_robots, load_robot

    rows = []
    for name, origin in available_robots():
        try:
            robot = load_robot(name)
            rows.append({"name": name, "origin": origin, "m": robot.m, "locked": list(robot.locked)})
        except PolyrobError as exc:
            if args.all:
                rows.append({"name": name, "origin": origin, "m": None, "refused": str(exc).split(": ", 1)[-1]})
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    print(f"{'robot':<28}{'joints':>7}  {'origin':<20} notes")
    for r in rows:
        joints = "-" if r["m"] is None else str(r["m"])
        notes = r.get("refused") or (f"locked: {', '.join(r['locked'])}" if r["locked"] else "")
        print(f"{r['name']:<28}{joints:>7}  {r['origin']:<20} {notes}")
    return 0


def cmd_info(args) -> int:
    robot = robot_from_args(args)
    domain = domain_from_args(robot, args)
    q0 = np.clip(np.zeros(robot.m), domain.q_lower, domain.q_upper)
    M = robot.mass_matrix(q0)
    _, B = robot.jacobians(q0, np.zeros(robot.m), np.zeros(robot.m))
    info = robot.describe()
    info["domain"] = domain.to_dict()
    info["neutral"] = {"q": q0.tolist(), "M": M.tolist(), "B": B.tolist()}
    if args.json:
        print(json.dumps(info, indent=2))
        return 0
    print(f"robot   {robot.name}  ({robot.m} actuated joints)")
    print(f"source  {robot.source}")
    if robot.locked:
        print(f"locked  {', '.join(robot.locked)}")
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
    with np.printoptions(precision=5, suppress=True, linewidth=120):
        print(f"\nat q = {q0}:\nM(q) =\n{M}\nB(q) =\n{B}")
    return 0


def cmd_bounds(args) -> int:
    from polyrob.bounds.pldi import bound_pldi

    robot = robot_from_args(args)
    domain = domain_from_args(robot, args)
    pldi = bound_pldi(
        robot,
        domain,
        samples=args.samples,
        nominal=args.nominal,
        certify=args.certify,
        coverage=args.coverage,
        seed=args.seed,
        progress=None if not args.quiet else False,
    )
    print(f"robot {robot.name}, domain {domain.name}, {len(pldi.entries)} varying entries")
    print(pldi.table())
    poly = pldi.polytope
    print(
        f"polytope: {poly.n_halfspaces} half-spaces"
        + (f", {len(poly.vertices)} vertices" if poly.vertices is not None else "")
        + f", reduced dimension {poly.reduced_dim}, volume / interval box "
        + (f"~ {poly.volume_ratio:.3g}" if poly.volume_hits else f"< {poly.volume_ratio_bound:.2g}")
        + f" ({poly.volume_hits} of {poly.volume_samples} box points inside)"
    )
    if len(pldi.entries) and pldi.enclosure == "sampled":
        worst = int(np.argmax(pldi.refinement))
        print(
            f"local search widened the sampled intervals by at most {100 * pldi.refinement[worst]:.3g} % "
            f"({pldi.entries[worst]}); {pldi.info.get('verification_rounds', 0)} verification round(s)"
        )
    if pldi.coverage_points:
        print(f"coverage: {pldi.coverage:.4f} of {pldi.coverage_points} fresh points")
    if pldi.dropped_q:
        print("positions the dynamics do not depend on: " + ", ".join(robot.joint_names[j] for j in pldi.dropped_q))
    print(f"time: {pldi.info['seconds_total']:.2f} s")
    if args.output:
        json_path, npz_path = pldi.save(args.output)
        print(f"wrote {json_path} and {npz_path}")
    return 0


def _register_bounds(sub) -> None:
    p = sub.add_parser("bounds", help="bound the Jacobians over the domain: intervals and a polytope (PLDI)")
    add_robot_arguments(p)
    add_domain_arguments(p)
    p.add_argument("--certify", action="store_true", help="prove the intervals by interval arithmetic (up to 3 joints)")
    p.add_argument("--samples", type=int, default=None, help="Sobol' positions (default grows with the dimension)")
    p.add_argument("--nominal", default="equilibrium", choices=["equilibrium", "midpoint"])
    p.add_argument("--coverage", type=int, default=10_000, help="fresh points for the coverage check (0 skips)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.add_argument("-o", "--output", default=None, help="write the PLDI (JSON + .npz)")
    p.set_defaults(func=cmd_bounds)


def add_weight_arguments(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group(
        "performance weights W_S = (s/M_S + wB)/(s + wB A_S), W_T = (s + wBT)/(A_T s + wBT M_T)",
        "one value for every joint or one per joint (comma-separated); default: the paper's",
    )
    for key, text in (("omega_b", "wb"), ("M_s", "ms"), ("A_s", "as"), ("omega_bt", "wbt"), ("M_t", "mt"), ("A_t", "at")):
        g.add_argument(f"--{text}", dest=key, default=None, help=f"{key}")
    g.add_argument("--bandwidth-scale", type=float, default=1.0, help="multiply wB and wBT")


def hyperparameters_from_args(m: int, args) -> dict:
    """The paper's weight hyperparameters with per-channel overrides, for ``m`` channels."""
    from polyrob.plant.weights import PAPER_HYPERPARAMETERS

    h = {}
    for key, paper in PAPER_HYPERPARAMETERS.items():
        text = getattr(args, key, None)
        if text is None:
            vals = list(paper) if m == len(paper) else [paper[0]] * m
        else:
            vals = [_number(t, f"--{key}") for t in text.split(",")]
            vals = vals * m if len(vals) == 1 else vals
            if len(vals) != m:
                raise DomainError(f"--{key}: give 1 or {m} values, got {len(vals)}")
        if key in ("omega_b", "omega_bt"):
            vals = [v * args.bandwidth_scale for v in vals]
        h[key] = tuple(vals)
    return h


def weights_from_args(m: int, args):
    """``(W_S, W_T)`` from the weight options (default: the paper's)."""
    from polyrob.plant.weights import paper_weights

    return paper_weights(hyperparameters_from_args(m, args))


def pldi_from_args(robot, args):
    from polyrob.bounds.pldi import PLDI, bound_pldi

    if getattr(args, "pldi", None):
        return PLDI.load(args.pldi)
    domain = domain_from_args(robot, args)
    return bound_pldi(robot, domain, coverage=0, progress=None if not args.quiet else False)


def controller_from_args(args):
    from polyrob.io.controller import load_controller
    from polyrob.plant.generalized import paper_controller

    if args.controller == "paper":
        return paper_controller()
    return load_controller(args.controller)


def cmd_analyze(args) -> int:
    from polyrob.plant.generalized import generalized_plant
    from polyrob.analysis.robust import nominal_performance, robperf, robstab, sample_stability
    from polyrob.plant.uncertainty import uncertain_plant

    robot = robot_from_args(args)
    pldi = pldi_from_args(robot, args)
    unc = uncertain_plant(pldi, merge_symmetric=args.merge_symmetric)
    P = generalized_plant(unc, *weights_from_args(robot.m, args))
    K = controller_from_args(args)
    options = {"progress": None if not args.quiet else False}
    omega = parse_frequencies(args.omega)
    rs = robstab(P, K, omega, **options)
    rp = robperf(P, K, omega, **options)
    npf = nominal_performance(P, K)
    sampling = sample_stability(unc, K, n=args.mc, seed=args.seed)
    report = {
        "robot": robot.name,
        "enclosure": pldi.enclosure,
        "parameters": unc.n_params,
        "nominal_stability": rs.nominally_stable,
        "nominal_performance_hinf": npf,
        "robust_stability": rs.summary(),
        "robust_performance": rp.summary(),
        "monte_carlo": {"samples": sampling.random, "stable_fraction": sampling.random_stable},
        "corners": {"count": sampling.corners, "stable_fraction": sampling.corners_stable},
        "worst_sampled": {"delta": sampling.worst_delta.tolist(), "max_pole_real_part": sampling.worst_abscissa},
    }
    if args.json:
        print(json.dumps(report, indent=2))
        return 0
    print(f"robot {robot.name}: {unc.n_params} real parameters ({pldi.enclosure} PLDI), controller order {_order(K)}")
    print(f"nominal stability      {'yes' if rs.nominally_stable else 'NO'}")
    print(f"nominal performance    ||N_zw||inf = {npf:.4g}  ({'met' if npf < 1 else 'not met'})")
    for title, r in (("robust stability", rs), ("robust performance", rp)):
        verdict = "certified" if r.robust else ("violated" if r.mu_lower >= 1 else "not certified")
        print(f"{title:<22} mu in [{r.mu_lower:.4g}, {r.mu_upper:.4g}] at {r.critical_frequency:.4g} rad/s: {verdict}")
    print(f"monte carlo            {sampling.random_stable:.1%} of {sampling.random} random parameter sets stable")
    if sampling.corners_stable is not None:
        print(f"corners                {sampling.corners_stable:.1%} of {sampling.corners} corners stable")
    print(f"worst sampled          max Re(pole) = {sampling.worst_abscissa:.4g}")
    return 0


def parse_frequencies(text):
    """``LO:HI:N`` -> N log-spaced frequencies (rad/s), or None for automatic."""
    if text is None:
        return None
    try:
        lo, hi, n = text.split(":")
        lo, hi, n = float(lo), float(hi), int(n)
    except ValueError:
        raise DomainError(f"--omega: give LO:HI:N, e.g. 0.01:100:60, got '{text}'") from None
    if not (0 < lo < hi and n >= 2):
        raise DomainError(f"--omega: need 0 < LO < HI and N >= 2, got '{text}'")
    return np.logspace(np.log10(lo), np.log10(hi), n)


def _order(K) -> int:
    import control

    return control.ss(K).nstates


def _register_analyze(sub) -> None:
    p = sub.add_parser("analyze", help="nominal/robust stability and performance (mu) of a controller")
    add_robot_arguments(p)
    add_domain_arguments(p)
    add_weight_arguments(p)
    p.add_argument("--controller", required=True, help="controller file (JSON, see polyrob.io.controller) or 'paper' for K*")
    p.add_argument("--pldi", default=None, help="a PLDI file from `polyrob bounds -o` (instead of bounding again)")
    p.add_argument("--merge-symmetric", action="store_true", help="one repeated parameter for b_ij = b_ji")
    p.add_argument("--mc", type=int, default=500, help="Monte Carlo parameter sets")
    p.add_argument("--omega", default=None, help="frequency grid LO:HI:N in rad/s (log spaced; default automatic)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--quiet", action="store_true")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_analyze)


def _print_synthesis(result) -> None:
    hist = list(result.mu_history)
    gam = list(result.gamma_history)
    print(f"{'iter':>4}  {'peak mu (upper)':>16}  {'gamma':>10}")
    for i, mu in enumerate(hist):
        g = f"{gam[i]:.4g}" if i < len(gam) else "-"
        print(f"{i + 1:>4}  {mu:>16.5g}  {g:>10}")
    print(
        f"controller: {result.structure}, order {result.order}; certified peak mu in "
        f"[{result.peak_mu_lower:.4g}, {result.peak_mu:.4g}] at {result.peak_frequency:.4g} rad/s "
        f"({result.iterations} iterations, {result.seconds:.1f} s)"
    )
    for note in result.info.get("notes", []) if isinstance(result.info, dict) else []:
        print(f"note: {note}")


def synthesis_options(args) -> dict:
    """``musyn`` keyword arguments from the synthesis options of the CLI."""
    options = {"structure": args.structure, "progress": None if not args.quiet else False}
    if args.max_iter is not None:
        options["max_iter"] = args.max_iter
    if args.structure == "full":
        options["mixed"] = not args.complex
    else:
        options["starts"] = args.starts
        if args.init:
            options["init"] = args.init
    return options


def synthesize(robot, args):
    """PLDI -> uncertain plant -> generalized plant -> musyn (-> reduction)."""
    from polyrob.plant.generalized import generalized_plant
    from polyrob.synthesis import musyn, reduce_controller
    from polyrob.plant.uncertainty import uncertain_plant

    pldi = pldi_from_args(robot, args)
    unc = uncertain_plant(pldi, merge_symmetric=args.merge_symmetric)
    P = generalized_plant(unc, *weights_from_args(robot.m, args))
    options = synthesis_options(args)
    result = musyn(P, **options)
    reduced = None
    if args.structure == "full" and args.reduce:
        reduced = reduce_controller(P, result, max_order=args.reduce_max_order)
    return pldi, unc, P, result, reduced


def _certificate(result, P) -> dict:
    cert = result.summary()
    cert["block_structure"] = np.asarray(P.block_structure_rp).tolist()
    return cert


def cmd_synth(args) -> int:
    from polyrob.io.controller import save_controller

    robot = robot_from_args(args)
    if args.max_bandwidth:
        return _max_bandwidth(robot, args)
    pldi, unc, P, result, reduced = synthesize(robot, args)
    print(f"robot {robot.name}: {unc.n_params} real parameters ({pldi.enclosure} PLDI), structure {args.structure}")
    _print_synthesis(result)
    K, cert = result.controller, _certificate(result, P)
    if reduced is not None:
        print("order reduction (order: certified peak mu):")
        for row in reduced.table:
            print(f"  {row['order']:>4}: {row['peak_mu']:.5g}{'' if row.get('stable', True) else ' (unstable)'}")
        print(f"reduced controller: order {reduced.order}, certified peak mu {reduced.peak_mu:.5g}")
        K = reduced.controller
        cert.update(structure=f"reduced:{reduced.order}", order=int(reduced.order),
                    peak_mu_upper=float(reduced.peak_mu), peak_mu_lower=float(reduced.peak_mu_lower),
                    full_order=int(result.order), full_peak_mu_upper=float(result.peak_mu))
    if args.output:
        info = {"robot": robot.name, "domain": pldi.domain.to_dict(), "weights": hyperparameters_from_args(robot.m, args)}
        path = save_controller(K, args.output, certificate=cert, info=info)
        print(f"wrote {path}")
    return 0


def _max_bandwidth(robot, args) -> int:
    """``synth --max-bandwidth``: the largest factor on the weights' bandwidths with certified mu < 1."""
    from polyrob.io.controller import save_controller
    from polyrob.plant.generalized import paper_controller
    from polyrob.synthesis import max_bandwidth_scaling
    from polyrob.plant.uncertainty import uncertain_plant

    pldi = pldi_from_args(robot, args)
    unc = uncertain_plant(pldi, merge_symmetric=args.merge_symmetric)
    options = synthesis_options(args)
    if options.get("init") == "paper":
        options.pop("init")  # K* starts the first synthesis only; later ones start from the nearest alpha's
        options["initial_controller"] = paper_controller()
    scale = tuple(x.strip() for x in args.scale_only.split(",") if x.strip())
    alphas = [_number(a, "--alphas") for a in args.alphas.split(",")] if args.alphas else None
    res = max_bandwidth_scaling(unc, hyperparameters_from_args(robot.m, args), scale=scale,
                                **({"alphas": alphas} if alphas else {}), **options)
    print(f"robot {robot.name}: {unc.n_params} real parameters ({pldi.enclosure} PLDI), scaling {', '.join(scale)}")
    print(f"{'alpha':>10}  {'certified peak mu':>18}")
    for alpha, mu in res.history:
        print(f"{alpha:>10.4g}  {mu:>18.5g}")
    print(f"largest alpha with certified mu < 1: {res.alpha:.4g} (mu {res.peak_mu:.4g}; "
          f"alpha {res.bracket[1]:.4g} does not reach it), controller order {res.result.order}")
    print("weights: " + ", ".join(f"{k} = {list(v)}" for k, v in res.hyperparameters.items()))
    if args.output:
        cert = res.result.summary()
        cert.update(bandwidth_scaling=res.summary())
        info = {"robot": robot.name, "domain": pldi.domain.to_dict(),
                "weights": {k: list(v) for k, v in res.hyperparameters.items()}}
        print(f"wrote {save_controller(res.result.controller, args.output, certificate=cert, info=info)}")
    return 0


def cmd_run(args) -> int:
    """bounds -> synthesis -> analysis in one go."""
    from polyrob.analysis.robust import nominal_performance, robperf, robstab, sample_stability

    robot = robot_from_args(args)
    pldi, unc, P, result, reduced = synthesize(robot, args)
    print(f"[1/3] bounds: {len(pldi.entries)} varying entries ({pldi.enclosure}), robot {robot.name}")
    print(pldi.table())
    print(f"[2/3] synthesis ({args.structure}):")
    _print_synthesis(result)
    K = result.controller if reduced is None else reduced.controller
    if reduced is not None:
        print(f"reduced to order {reduced.order}: certified peak mu {reduced.peak_mu:.5g}")
    print("[3/3] analysis:")
    rs, rp = robstab(P, K, progress=False), robperf(P, K, progress=False)
    sampling = sample_stability(unc, K, n=args.mc, seed=0)
    print(f"nominal performance ||N_zw||inf = {nominal_performance(P, K):.4g}")
    print(f"robust stability   mu in [{rs.mu_lower:.4g}, {rs.mu_upper:.4g}]")
    print(f"robust performance mu in [{rp.mu_lower:.4g}, {rp.mu_upper:.4g}] ({'certified' if rp.robust else 'not certified'})")
    print(f"monte carlo: {sampling.random_stable:.1%} of {sampling.random} stable"
          + (f"; corners: {sampling.corners_stable:.1%} of {sampling.corners} stable" if sampling.corners else ""))
    if args.output:
        from polyrob.io.controller import save_controller

        cert = _certificate(result, P)
        cert.update(robust_stability=rs.summary(), robust_performance=rp.summary())
        print(f"wrote {save_controller(K, args.output, certificate=cert, info={'robot': robot.name})}")
    return 0


def _add_synthesis_arguments(p) -> None:
    add_robot_arguments(p)
    add_domain_arguments(p)
    add_weight_arguments(p)
    p.add_argument("--structure", default="full", help="full (D-K / D-G-K), tfN (e.g. tf3: each K_ij of order N), pid, ss:N")
    p.add_argument("--complex", action="store_true", help="treat the real parameters as complex (plain D-K)")
    p.add_argument("--max-iter", type=int, default=None,
                   help="D-K iterations (default 20; fixed structure: outer iterations, default 40)")
    p.add_argument("--starts", type=int, default=5, help="fixed structure: optimisation starts")
    p.add_argument("--init", default=None, help="fixed structure: 'paper' starts from the paper's K*")
    p.add_argument("--reduce", action="store_true", help="reduce the full-order controller (balanced truncation)")
    p.add_argument("--reduce-max-order", type=int, default=20)
    p.add_argument("--pldi", default=None, help="a PLDI file from `polyrob bounds -o` (instead of bounding again)")
    p.add_argument("--merge-symmetric", action="store_true", help="one repeated parameter for b_ij = b_ji")
    p.add_argument("--quiet", action="store_true")
    p.add_argument("-o", "--output", default=None, help="write the controller and its certificate (JSON)")


def _register_synth(sub) -> None:
    p = sub.add_parser("synth", help="mu-synthesis: full order (D-K, D-G-K) or fixed structure")
    _add_synthesis_arguments(p)
    p.add_argument("--max-bandwidth", action="store_true",
                   help="find the largest scaling of the weights' bandwidths with certified mu < 1")
    p.add_argument("--scale-only", default="omega_b,omega_bt",
                   help="--max-bandwidth: weight hyperparameters multiplied by the factor (default both bandwidths)")
    p.add_argument("--alphas", default=None,
                   help="--max-bandwidth: comma-separated scan of the factor (default 0.125,0.25,...,32)")
    p.set_defaults(func=cmd_synth)
    p = sub.add_parser("run", help="bounds -> synthesis -> analysis in one go")
    _add_synthesis_arguments(p)
    p.add_argument("--mc", type=int, default=200, help="Monte Carlo parameter sets in the analysis")
    p.set_defaults(func=cmd_run)


# --------------------------------------------------------------------------- entry point


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="polyrob",
        description="Robust controllers with a mathematical guarantee for serial robots described in URDF.",
    )
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("robots", help="list the robots polyrob can load")
    p.add_argument("--all", action="store_true", help="also list refused URDFs with the reason")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_robots)

    p = sub.add_parser("info", help="joints, limits, default domain, M and B at the neutral configuration")
    add_robot_arguments(p)
    add_domain_arguments(p)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_info)

    for register in _EXTRA_COMMANDS:
        register(sub)
    return parser


#: Later stages register their sub-commands here (bounds, analyze, synth, run).
_EXTRA_COMMANDS: list = [_register_bounds, _register_analyze, _register_synth]


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except PolyrobError as exc:
        print(f"polyrob: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # `polyrob robots | head`: not an error
        sys.stderr.close()
        return 0
    except KeyboardInterrupt:
        print("polyrob: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
