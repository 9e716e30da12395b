"""What the ``inner-links`` model's inertia block costs μ at one frequency, against the drawn robots' own inertia errors, as JSON.

    python benchmarks/inertia_block.py CONTROLLER.json [--omega W] [-n 60] [--seed 5] [--extremes 0.5]
        [--com-box] [--ball 0] [--hermitian] [--fixed-positions] [--exact-links K ...]
        [--robot-uncertainty FILE | --link-error 10 --payload-max 1.5 --com-radius 0.1]

The model (:mod:`polyrob.plant.models.inner_links`) carries the relative
inertia error of the computed-torque loop (the acceleration columns of the
factor, ``I - M_hat^-1 M`` in ``M_hat^1/2`` coordinates) as one full complex
block of norm at most one in its shaped coordinates, independent of the
other blocks.  At the frequency ``W`` (default: the peak of the controller
file's certificate) this prints μ of the robust-performance loop with every
block, μ with the inertia block left out, and μ's upper bound of the rest of
the structure with the inertia block *closed* at each of ``n`` true robots'
own inertia error at the task's centre (a real, nearly symmetric matrix,
drawn from the stated set: half at its vertices).  The last is what a model
exact in the inertia could reach at best with the other blocks as they are
(an estimate from the draws, not a bound); the first is what the certificate
pays.  ``--com-box`` draws the payload's centre of mass in the box that holds
the ball (a box-shaped parametrisation's set); ``--ball K`` also searches
``K`` random real symmetric matrices of the block's unit ball (its extreme
points ``Q diag(+-1) Q^T``) and ``K`` rotations of the worst: what a real
symmetric block of the same size would still allow.

``--hermitian`` prints μ's upper bound with the block's members taken as
what they are, real matrices: at the task's centre they are symmetric (the
weighting is ``M_hat^1/2`` there), away from it the fixed weighting leaves a
skew-symmetric part, bounded here over the model's own samples of the task
and the set (the dilation bound of
:func:`~polyrob.plant.models.inner_links_inertia.residual_norm_bounds`,
times the model's margin).  The block is then a Hermitian block of norm 1
plus ``-j`` times a Hermitian block of that size, each with the scalar
G-scaling a Hermitian block admits
(:class:`~polyrob.analysis.mu.gradient.GradientUpper`'s ``hermitian``):
what a model that carried the block so would certify at this frequency (the
model does not yet).  ``--fixed-positions`` rebuilds the model with the
task's positions held at its centre (velocities and accelerations as they
are) and prints its μ: what the inertia's and the stiffness's change over
the positions costs.  ``--exact-links K ...`` rebuilds the model with the
links' inertia exact in their parameters: each link scalar's acceleration
columns at the mean of the model's samples as one real scalar of its own
(repeated as often as their rank), and for each ``K`` the instrument's
acceleration columns at that mean on ``K`` principal directions of its
physical set (real scalars within their reach); what that leaves (the
change over the task, the instrument beyond its directions) stays in the
shaped block.  It prints μ's bounds for each ``K`` and, for the first, with
the block left out and with the links' scalars left out (which of them
carries μ).  These are experiments on the model, not a model polyrob uses.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

from _results import add_results_option, save_run
from _sets import add_set_options, set_of


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("controller", help="a controller file as `polyrob synth -o` writes it (an inner-links problem)")
    ap.add_argument("--omega", type=float, default=None, help="rad/s (default: the certificate's peak frequency)")
    ap.add_argument("-n", type=int, default=60, help="true robots drawn (default 60)")
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--extremes", type=float, default=0.5, help="share drawn at vertices of the set (default 0.5)")
    ap.add_argument("--com-box", action="store_true", help="draw the centre of mass in the box holding the ball")
    ap.add_argument("--ball", type=int, default=0, help="also search this many symmetric matrices of the unit ball")
    ap.add_argument("--hermitian", action="store_true", help="also mu with the block's real members (symmetric + skew)")
    ap.add_argument("--fixed-positions", action="store_true", help="also mu with the task's positions at its centre")
    ap.add_argument(
        "--exact-links", type=int, nargs="+", default=None, metavar="K",
        help="also mu with the links' inertia exact (real scalars) and K directions of the instrument's",
    )  # fmt: skip
    add_set_options(ap, payload_max=1.5)
    add_results_option(ap)
    args = ap.parse_args()

    import dataclasses

    import numpy as np

    from polyrob.analysis.margins import block_words
    from polyrob.analysis.mu.blocks import as_block_structure
    from polyrob.analysis.mu.bounds import mussv
    from polyrob.domains.task import TaskDomain
    from polyrob.io.controller import load_controller, read_controller_file
    from polyrob.model.inner import inner_loop_of_set
    from polyrob.model.robots import load_robot
    from polyrob.plant.generalized import generalized_plant, lft
    from polyrob.plant.models import inner_links as links
    from polyrob.plant.weights import plant_weights
    from polyrob.uncertainty_set.draw import draw_true_robots

    t0 = time.perf_counter()
    doc = read_controller_file(args.controller)
    info, cert = doc.get("info") or {}, doc.get("certificate") or {}
    omega = float(args.omega if args.omega is not None else cert.get("peak_frequency"))
    robot = load_robot(info["robot"])
    spec = set_of(args, info["robot"])
    loop = inner_loop_of_set(robot, "computed-torque", spec, draws=2)
    domain = TaskDomain.from_dict(info["domain"], robot=loop)
    unc = links.light_model(loop, domain, samples=256)
    weights = {k: tuple(v) for k, v in info["weights"].items()}
    P = generalized_plant(unc, **plant_weights(weights))
    M = np.asarray(lft(P, load_controller(args.controller))(1j * omega), complex)
    blocks = list(as_block_structure(P.block_structure_rp).blocks)
    words = block_words(unc, P.block_structure_rp)
    i = next(k for k, w in enumerate(words) if "inertia" in w)
    row0 = np.cumsum([0] + [b.cols for b in blocks])
    col0 = np.cumsum([0] + [b.rows for b in blocks])
    ri, ci = np.arange(row0[i], row0[i + 1]), np.arange(col0[i], col0[i + 1])
    ro, co = np.r_[0 : row0[i], row0[i + 1] : row0[-1]], np.r_[0 : col0[i], col0[i + 1] : col0[-1]]
    rest = [b.matlab for k, b in enumerate(blocks) if k != i]

    def mu_closed(D):  # mu's upper bound of the rest with the inertia block closed at D
        X = M[np.ix_(ro, co)] + M[np.ix_(ro, ci)] @ D @ np.linalg.solve(
            np.eye(len(ci)) - M[np.ix_(ri, ci)] @ D, M[np.ix_(ri, co)]
        )
        return float(mussv(X, rest, lower=False).upper)

    full = mussv(M, P.block_structure_rp)
    # each drawn robot's block value: its acceleration columns less the centre, in the block's shaped coordinates
    W, g = unc.info["residual_weighting"], unc.info["residual_g_norm"]
    values, vectors = np.linalg.eigh(unc.info.get("residual_g_shape", np.eye(robot.m)))
    H_inv = (vectors / np.sqrt(values)) @ vectors.T
    n = 2 * robot.m
    draw_spec = spec
    if args.com_box and spec.payload is not None and spec.payload.com_radius is not None:
        box = spec.payload.com_box()
        body = dataclasses.replace(
            spec.payload, com_radius=None, com_lower=tuple(b[0] for b in box), com_upper=tuple(b[1] for b in box)
        )
        draw_spec = dataclasses.replace(spec, payload=body)
    centre = 0.5 * (np.asarray(domain.lower, float) + np.asarray(domain.upper, float))
    q, qdot, a = domain.split(centre[None])
    trues = draw_true_robots(loop.uncertainty_robot, draw_spec, args.n, seed=args.seed, extremes=args.extremes)
    offset = unc.info["K_offset"][:, n:]
    deltas = [
        H_inv @ W @ (links.factor_of(loop, t.robot, q, qdot, a)[0][:, n:] - offset) @ np.linalg.inv(W) @ H_inv / g
        for t in trues
    ]
    closed = np.array([mu_closed(D) for D in deltas])
    norms = np.array([np.linalg.norm(D, 2) for D in deltas])
    out = {
        "what": "mu at one frequency: the inertia block as the model carries it, left out, and closed at drawn robots' own errors",
        "controller": str(args.controller),
        "robot": robot.name,
        "set": spec.words(),
        "omega": omega,
        "mu": [round(float(full.lower), 4), round(float(full.upper), 4)],
        "mu_without_inertia_block": round(mu_closed(np.zeros((len(ci), len(ri)))), 4),
        "robots": len(trues),
        "com_box": bool(args.com_box),
        "block_norm_of_drawn": {"median": round(float(np.median(norms)), 3), "worst": round(float(norms.max()), 3)},
        "mu_closed_at_drawn": {"median": round(float(np.median(closed)), 4), "worst": round(float(closed.max()), 4)},
    }
    if args.ball:
        from scipy.linalg import expm

        rng = np.random.default_rng(args.seed)
        k = len(ci)
        best, best_D = -1.0, None
        for _ in range(args.ball):
            Q = np.linalg.qr(rng.normal(size=(k, k)))[0]
            D = (Q * rng.choice([-1.0, 1.0], size=k)) @ Q.T
            value = mu_closed(D)
            best, best_D = (value, D) if value > best else (best, best_D)
        for _ in range(args.ball):
            A = 0.1 * rng.normal(size=(k, k))
            Q = expm(A - A.T)
            value = mu_closed(Q @ best_D @ Q.T)
            best, best_D = (value, Q @ best_D @ Q.T) if value > best else (best, best_D)
        out["mu_closed_at_unit_ball_symmetric_worst_found"] = round(best, 4)
    if args.hermitian:
        out.update(_hermitian_split(loop, domain, unc, M, i, blocks))
    if args.fixed_positions:
        fixed = TaskDomain.from_dict(_positions_at_centre(info["domain"]), robot=loop)
        unc_fixed = links.light_model(loop, fixed, samples=256)
        P_fixed = generalized_plant(unc_fixed, **plant_weights(weights))
        at = mussv(
            np.asarray(lft(P_fixed, load_controller(args.controller))(1j * omega), complex), P_fixed.block_structure_rp
        )
        out["mu_positions_at_centre"] = [round(float(at.lower), 4), round(float(at.upper), 4)]
        out["inertia_block_norm_positions_at_centre"] = round(float(unc_fixed.info["residual_g_norm"]), 4)
    if args.exact_links:
        out["exact_links"] = _exact_links(
            args.exact_links, loop, domain, plant_weights(weights), load_controller(args.controller), omega
        )
    out["seconds"] = round(time.perf_counter() - t0, 1)
    figure = (
        f"{robot.name} at {omega:.4g} rad/s: mu {out['mu']} with the inertia block, "
        f"{out['mu_without_inertia_block']} without it, worst {out['mu_closed_at_drawn']['worst']} "
        f"with it closed at {len(trues)} drawn robots' own errors"
    )
    if args.exact_links:
        first = out["exact_links"][f"instrument_directions_{args.exact_links[0]}"]["mu"]
        figure += f"; with the links' inertia exact {first}"
    save_run(args.results, "inertia_block", "The inertia block's cost against drawn robots' errors", figure, out)
    print(json.dumps(out, indent=1))
    print(figure, file=sys.stderr)


def _positions_at_centre(domain: dict) -> dict:
    """A task domain's dictionary with every joint's position range collapsed to its centre."""
    out = dict(domain, q={j: [0.5 * (lo + hi)] * 2 for j, (lo, hi) in domain["q"].items()})
    out["q_radius"] = 0.0
    return out


def _hermitian_split(loop, domain, unc, M, i, blocks) -> dict:
    """μ's upper bound with the inertia block ``i`` as a Hermitian block plus ``-j`` times a Hermitian one (its skew part).

    The block's member is ``S^-1/2 (X - C - g0 S) S^-1/2 / g`` with ``X = W G W^-1``
    (the fixed weighting ``W``); ``C`` and ``S`` are symmetric, so its skew part
    is ``skew(S^-1/2 X S^-1/2) / g``, linear in the set's scalars: bounded at
    each of the model's samples by the dilation bound, over the box and the
    payload's points, times the model's margin.  The model's samples are its
    own (``inner_links.model_samples``): the bound
    is of the set the model holds, sampled over the task as the model is.
    """
    import numpy as np

    from polyrob.analysis.mu.blocks import as_block_structure
    from polyrob.analysis.mu.gradient import GradientUpper
    from polyrob.plant.models import inner_links as links
    from polyrob.plant.models.inner_links_inertia import residual_norm_bounds

    m = loop.m
    q, qdot, a = links.model_samples(domain, int(unc.info["samples"]))
    named = {s.name: s for s in links.set_scalars(loop)}
    scalars = [named[name] for name in unc.info["scalars"]]
    G = links.unit_factors(loop, scalars, q, qdot, a)[..., 2 * m :]  # (N, S, m, m): acceleration columns
    W, g = unc.info["residual_weighting"], unc.info["residual_g_norm"]
    values, vectors = np.linalg.eigh(unc.info.get("residual_g_shape", np.eye(m)))
    T = (vectors / np.sqrt(values)) @ vectors.T @ W  # S^-1/2 W
    X = T @ G @ np.linalg.inv(W) @ (vectors / np.sqrt(values)) @ vectors.T
    skew = 0.5 * (X - np.swapaxes(X, -1, -2))
    on_payload = np.array([s.name.startswith("payload.") for s in scalars])
    pay = links.payload_set_points(loop.uncertainty.payload, scalars) if on_payload.any() else np.zeros((1, 0))
    size = links.G_MARGIN * float(residual_norm_bounds(skew[~on_payload], skew[on_payload], pay).max()) / g
    # the block's output is Delta_sym z + s (-j) H z: its input rows twice, its output columns twice (the second times -j s)
    rows = np.cumsum([0] + [b.cols for b in blocks])
    cols = np.cumsum([0] + [b.rows for b in blocks])
    r, c = np.arange(rows[i], rows[i + 1]), np.arange(cols[i], cols[i + 1])
    split = np.block([[M, -1j * size * M[:, c]], [M[r, :], -1j * size * M[np.ix_(r, c)]]])
    k = len(r)
    st = as_block_structure([b.matlab for b in blocks] + [(k, k)])
    padded = st.pad(split)
    bound = GradientUpper(st, hermitian=[i, len(blocks)])(padded)[0]
    return {
        "inertia_skew_part_norm": round(size, 4),
        "mu_upper_inertia_block_real": round(float(bound), 4),
    }


def _exact_links_model(loop, domain, directions: int):
    """The ``inner-links`` model with the links' inertia scalars exact at the samples' mean (``--exact-links``).

    Returns the model and the indices of its real scalars that carry the links' inertia.
    """
    import numpy as np
    from _sets import pldi_stand_in

    from polyrob.plant.models import inner_links as links
    from polyrob.plant.models.inner_factors import factor_lft_plant
    from polyrob.plant.models.inner_links_inertia import g_norm_bound, shape_of

    pldi = pldi_stand_in(loop, domain)
    f = links.set_factors(pldi, loop, samples=256)
    m, n = loop.m, 2 * loop.m
    on, pay = f.on_payload, f.pay
    ranges = links.RANGE_MARGIN * links.reach_of(f.coeff, on, pay).max(axis=0)
    rest = f.Phi - np.einsum("jsk,kab->jsab", f.coeff, f.centres)
    spread = links.SPREAD_MARGIN * links.entry_bound(rest, on, pay)
    state_norm = links.state_residual_norm_bound(rest[..., :n], on, pay, spread[:, :n])
    G = f.Phi[..., n:].copy()  # (N, S, m, m) in the fixed weighting
    # the links: each scalar's acceleration columns at the mean, exact over the box (|u_j| <= 1); the change over
    # the task stays in the block
    G0 = G[~on].mean(axis=1)
    link_centres = np.zeros((len(G0), m, 3 * m))
    link_centres[..., n:] = G0
    G[~on] -= G0[:, None]
    centres, ranges = np.concatenate([f.centres, link_centres]), np.r_[ranges, np.ones(len(G0))]
    link_scalars = np.arange(len(f.centres), len(centres))
    if directions and on.any():  # the instrument: principal directions of its physical set at the mean
        points = np.einsum("pi,iab->pab", pay, G[on].mean(axis=1)).reshape(len(pay), -1)
        E = np.linalg.svd(points, full_matrices=False)[2][:directions].reshape(-1, m, m)
        coeff = np.einsum("isab,kab->isk", G[on], E)
        reach = np.abs(np.einsum("pi,isk->psk", pay, coeff)).max(axis=(0, 1))
        G[on] -= np.einsum("isk,kab->isab", coeff, E)
        payload_centres = np.zeros((len(E), m, 3 * m))
        payload_centres[..., n:] = E
        centres, ranges = np.concatenate([centres, payload_centres]), np.r_[ranges, reach]
    shape, centre = shape_of(G[~on], G[on], pay)
    g, t = g_norm_bound(G[~on], G[on], pay, np.ones(G.shape[1]), shape=shape, centre=centre)
    model = factor_lft_plant(
        pldi, "inner-links", tuple(f"t{k}" for k in range(len(ranges))), ranges,
        list(links.weighted_factor(centres, np.linalg.inv(f.W), f.W)), spread,
        {"PLDI": pldi.enclosure, "factors": "sampled"}, weighting=f.W, g_norm=links.G_MARGIN * g,
        g_offset=centre + t * shape, g_shape=shape, state_residual_norm=state_norm, low_rank=True,
    )  # fmt: skip
    return model, link_scalars


def _exact_links(directions, loop, domain, weights, K, omega) -> dict:
    """μ's bounds at ``omega`` on :func:`_exact_links_model` for each count of the instrument's directions."""
    import numpy as np

    from polyrob._threads import single_blas_thread
    from polyrob.analysis.mu.blocks import as_block_structure
    from polyrob.analysis.mu.bounds import mussv
    from polyrob.plant.generalized import generalized_plant, lft

    out = {}
    for k in directions:
        model, link_scalars = _exact_links_model(loop, domain, k)
        P = generalized_plant(model, **weights)
        M = np.asarray(lft(P, K)(1j * omega), complex)
        blocks = list(as_block_structure(P.block_structure_rp).blocks)
        rows, cols = np.cumsum([0] + [b.cols for b in blocks]), np.cumsum([0] + [b.rows for b in blocks])
        full = [i for i, b in enumerate(blocks) if b.kind != "real"]
        inertia = full[-2]  # the complex blocks: the state residual, the inertia block, the performance block

        def bounds(left_out=()):
            keep = [i for i in range(len(blocks)) if i not in left_out]
            r = np.concatenate([np.arange(rows[i], rows[i + 1]) for i in keep])
            c = np.concatenate([np.arange(cols[i], cols[i + 1]) for i in keep])
            with single_blas_thread():
                mu = mussv(M[np.ix_(r, c)], [blocks[i].matlab for i in keep])
            return [round(float(mu.lower), 4), round(float(mu.upper), 4)]

        row = {"mu": bounds(), "channels": int(M.shape[1])}
        if k == directions[0]:
            real = [i for i, b in enumerate(blocks) if b.kind == "real"]
            row["mu_without_inertia_block"] = bounds([inertia])
            row["mu_without_link_scalars"] = bounds([real[j] for j in link_scalars])
        out[f"instrument_directions_{k}"] = row
    return out


if __name__ == "__main__":
    main()
