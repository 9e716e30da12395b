"""The moving robot on a model of physical constants: the masses fixed, the state moving at any rate.

The ``inner-gain`` models (:mod:`polyrob.plant.models.inner_gain`,
:mod:`polyrob.plant.models.inner_factors`) write the Jacobians of a
computed-torque loop as an LFT in *physical constants* -- the link-mass
factor, a payload mass: real parameters that do not move while the robot
does -- and carry every dependence on the robot's state ``(q, qdot, qddot)``
in full complex residual blocks.  Scheduling on the state itself
(:mod:`polyrob.analysis.lpv.robot`) is out of reach for an arm (14 state
variables, and the torque varies in a task domain); the model's own
parameters are not:

* each real parameter stays a real block of μ, constant in time: μ's
  frequency-dependent D-G scalings are valid for it;
* each residual block is scaled by a constant ``d_i`` and merged with the
  performance channels into *one* full block (a constant scalar commutes
  with every time-varying block of norm at most one, so the small-gain
  theorem holds for arbitrarily fast variation of the state dependence,
  Shamma, IEEE TAC 39(4), 1994; a frequency-dependent scaling would not);
  ``d`` comes from the constant-D small gain
  (:func:`~polyrob.analysis.time_varying.smallgain.scaled_small_gain`) at
  ``delta = 0`` -- any ``d`` gives a valid bound, a few multiples are tried;
* μ of that structure below one at every frequency
  (:func:`polyrob.analysis.certificate.certify_loop`, the frozen
  certificate's machinery: upper bounds proved between the grid points) is,
  by the main loop theorem, ``||D N(delta) D^-1||_inf < 1`` for every
  constant ``delta``, hence robust performance for every constant value of
  the parameters and every motion of the state inside the domain, at any
  rate.

A per-link set (the ``inner-links`` model, whose direction scalars move
with the state) is analysed on its ``inner-links-moving`` model
(:func:`moving_problem`, :mod:`polyrob.plant.moving_links`): each true
robot's factor split at the task's centre into constants (the directions'
values and the rest of the factor there: real blocks and constant full
blocks, frequency-dependent scalings) and the motion (full blocks marked
``moving``), and only the motion is merged with the performance channels.

This sits between the frozen robot (μ: constant parameters, constant
state) and the time-varying certificate (every parameter arbitrarily fast,
the masses too), and covers the robot in motion as the time-varying test
does: as far as the model covers its Jacobians, while the state and the
accelerations stay inside the domain the PLDI was bounded on.

Examples
--------
>>> from types import SimpleNamespace
>>> applies(SimpleNamespace(P=SimpleNamespace(uncertain=SimpleNamespace(model="lft"))))
"the 'lft' model's parameters move with the robot's state (only the inner-gain models' are physical constants)"
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from polyrob.errors import ArgumentError, PolyrobError

__all__ = [
    "applies",
    "moving_problem",
    "residual_scalings",
    "scaled_plant",
    "without_motion",
    "constant_parameter_certificate",
    "moving_worst_case",
    "robot_in_motion_certificate",
    "check_jerk",
    "TASK_OPTIONS",
]

#: Largest closed loop (states) analysed.
MAX_STATES = 60
#: Largest LFT loop computed by default (``analyze`` and ``run`` without ``--moving``).
AUTO_STATES = 48
#: Models whose real parameters are physical constants of the robot.
CONSTANT_MODELS = ("inner-gain", "inner-links-moving")
#: Frozen models whose moving robot is analysed on another model of the same set, whose scalars are constants.
MOVING_MODEL = {"inner-links": "inner-links-moving"}


def applies(problem) -> str | None:
    """Why the constant-parameter route does not apply to ``problem`` (``None`` when it does)."""
    model = _model(problem)
    if model not in CONSTANT_MODELS:
        return (
            f"the {model!r} model's parameters move with the robot's state "
            "(only the inner-gain models' are physical constants)"
        )
    return None


def _model(problem) -> str:
    return getattr(getattr(getattr(problem, "P", None), "uncertain", None), "model", "")


def moving_problem(problem):
    """``problem`` on the model whose real scalars are the robot's constants (itself when it is one).

    An ``inner-links`` problem's direction scalars ``t_k(u, x)`` and blocks
    move with the state; the ``inner-links-moving`` model of the same set
    and PLDI (:mod:`polyrob.plant.moving_links`) splits each true robot's
    factor at the task's centre into constants (the scalars and blocks
    there) and the motion (blocks marked ``moving``).  It is built here, its
    coverage measured on fresh true robots with their factors at the centre
    (:func:`~polyrob.plant.moving_links.motion_coverage`), the problem's
    weights kept.  ``None`` when no such model exists.
    """
    model = _model(problem)
    if model in CONSTANT_MODELS:
        return problem
    if model not in MOVING_MODEL or not hasattr(problem, "pldi"):
        return None
    from polyrob.plant.generalized import generalized_plant
    from polyrob.plant.moving_links import motion_coverage
    from polyrob.plant.uncertainty import uncertain_plant
    from polyrob.plant.weights import plant_weights

    unc = uncertain_plant(problem.pldi, model=MOVING_MODEL[model], coverage=0, volume_samples=0)
    points = int(getattr(problem.unc, "coverage_points", 0) or 2000)
    unc = unc.with_figures(
        coverage=motion_coverage(unc, problem.robot, problem.pldi.domain, points), coverage_points=points
    )
    P = generalized_plant(unc, **plant_weights(problem.hyperparameters))
    return replace(problem, unc=unc, P=P, model=unc.model)


def _channels(blk, moving=None):
    """``(real, full)``: per block, its ``d`` (input) and ``v`` (output) channel indices.

    ``moving`` (one flag per full block, in order): ``full`` holds only the
    flagged ones and ``real`` the rest too (the blocks that stay constant).
    """
    from polyrob.analysis.mu.blocks import as_block_structure

    real, full, a, b, k = [], [], 0, 0, 0
    for block in as_block_structure(blk).blocks:
        ins, outs = np.arange(a, a + block.rows), np.arange(b, b + block.cols)
        if block.kind == "real":
            real.append((ins, outs, block))
        else:
            (full if moving is None or moving[k] else real).append((ins, outs, block))
            k += 1
        a, b = a + block.rows, b + block.cols
    return real, full


def _block_scales(full, d, n_in: int, n_out: int, first_in: int, first_out: int):
    """``(s_in, s_out)``: ``1/d_i`` on the inputs and ``d_i`` on the outputs of the full blocks ``full`` (from
    :func:`_channels`), laid out from ``first_in``/``first_out`` in a system of ``n_in`` inputs and ``n_out`` outputs."""
    s_in, s_out = np.ones(n_in), np.ones(n_out)
    a, b = first_in, first_out
    for (i, o, _), dk in zip(full, np.asarray(d, float)):
        s_in[a : a + len(i)], s_out[b : b + len(o)] = 1.0 / dk, dk
        a, b = a + len(i), b + len(o)
    return s_in, s_out


def _moving_flags(P) -> list[bool] | None:
    """Which full blocks move with the state (``None``: all of them, as on ``inner-gain``)."""
    blocks = (getattr(getattr(P, "uncertain", None), "info", None) or {}).get("residual_blocks") or []
    return [bool(b["moving"]) for b in blocks] if blocks and "moving" in blocks[0] else None


def residual_scalings(P, K):
    """``(d, source)``: constant scalings ``d_i`` of the full blocks, the constant-D small gain of the loop at ``delta = 0``."""
    from polyrob.analysis.time_varying.smallgain import scaled_small_gain
    from polyrob.plant.generalized import lft

    _real, full = _channels(P.block_structure_rs, _moving_flags(P))
    if not full:
        return np.ones(0), "no residual block"
    N = lft(P, K)
    n_d = P.n_delta
    ins = np.concatenate([i for i, _, _ in full] + [np.arange(n_d, n_d + P.n_w)])
    outs = np.concatenate([o for _, o, _ in full] + [np.arange(n_d, n_d + P.n_z)])
    blk = [[len(i), len(o)] for i, o, _ in full] + [[P.n_w, P.n_z]]
    res = scaled_small_gain(N[outs.tolist(), ins.tolist()], blk)
    if res.X_r is None:
        return np.ones(len(full)), "the constant-D small gain at delta = 0 found no scaling: d = 1"
    x, start, per = np.diag(res.X_r), 0, []
    for i, *_ in full + [(np.arange(P.n_w), None)]:
        per.append(float(np.mean(x[start : start + len(i)])))
        start += len(i)
    d = np.sqrt(np.maximum(np.array(per[:-1]), 1e-300) / max(per[-1], 1e-300))
    return d, f"the constant-D small gain at delta = 0 ({res.gamma:.4g})"


def without_motion(P) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(outputs, inputs, blk)``: the robust-performance loop of ``P`` with its moving blocks closed at zero.

    The rows (``v`` and ``z``) and columns (``d`` and ``w``) of the loop
    ``lft(P, K)`` that stay, and their structure (MATLAB ``blk``: the
    constant blocks in order, then the performance block).  On an
    ``inner-links-moving`` model the motion ``E_m(u, x) = K(u, x) - K(u,
    x_c)`` is zero at the task's centre, so this is the frozen robot there:
    each true robot's factor exact in its scalars, no motion
    (:mod:`polyrob.plant.moving_links`).  On a model whose blocks carry no
    ``moving`` flag (``inner-gain``) every full block moves, as the
    moving-robot certificate takes them.
    """
    real, full = _channels(P.block_structure_rs, _moving_flags(P))
    kept = sorted(real, key=lambda block: block[0][0])  # the constant blocks in the structure's own order
    n_d, n_v = (sum(len(c[k]) for c in real + full) for k in (0, 1))  # the d inputs, then the v outputs
    ins = np.concatenate([i for i, _, _ in kept] + [np.arange(n_d, n_d + P.n_w)]).astype(int)
    outs = np.concatenate([o for _, o, _ in kept] + [np.arange(n_v, n_v + P.n_z)]).astype(int)
    blk = np.array([list(block.matlab) for _, _, block in kept] + [[P.n_w, P.n_z]])
    return outs, ins, blk


def scaled_plant(P, d):
    """``(plant, blk)``: ``P`` with the residual blocks scaled by ``d`` and merged with the performance block.

    Inputs ``[d_real, d_full / d, w, u]``, outputs ``[v_real, d v_full, z, y]``;
    ``blk``: the real blocks as they are, then one full block for the scaled
    residual channels and the performance channels together -- one block, so
    that no frequency-dependent scaling between them is searched (the
    residual varies in time: only the constant ``d`` is valid for it).  On a
    model whose full blocks say whether they move (``inner-links-moving``),
    only the moving ones are merged; the constant ones stay blocks of their
    own beside the real ones.
    """
    import control

    real, full = _channels(P.block_structure_rs, _moving_flags(P))
    sl_in, sl_out = P.input_slices, P.output_slices
    rng = lambda sl: np.arange(sl.start, sl.stop)  # noqa: E731
    ins = np.concatenate([i for i, _, _ in real] + [i for i, _, _ in full] + [rng(sl_in["w"]), rng(sl_in["u"])])
    outs = np.concatenate([o for _, o, _ in real] + [o for _, o, _ in full] + [rng(sl_out["z"]), rng(sl_out["y"])])
    n_ri, n_ro = sum(len(i) for i, _, _ in real), sum(len(o) for _, o, _ in real)
    s_in, s_out = _block_scales(full, d, ins.size, outs.size, n_ri, n_ro)
    sys = P.system
    B = np.asarray(sys.B, float)[:, ins] * s_in[None, :]
    C = np.asarray(sys.C, float)[outs] * s_out[:, None]
    D = np.asarray(sys.D, float)[np.ix_(outs, ins)] * s_out[:, None] * s_in[None, :]
    blk = [list(block.matlab) for _, _, block in real]
    blk.append([sum(len(i) for i, _, _ in full) + P.n_w, sum(len(o) for _, o, _ in full) + P.n_z])
    return control.ss(np.asarray(sys.A, float), B, C, D), np.array(blk)


#: Log-spaced frequencies (rad/s) on which :func:`search_scalings` compares scalings, and its evaluations.
SEARCH_GRID = (1e-3, 1e4, 36)
SEARCH_EVALUATIONS = 40
SEARCH_ROUNDS = 3


def search_scalings(P, K, d0) -> np.ndarray:
    """Constant scalings ``d`` of the moving blocks that lower the merged structure's μ peak, from ``d0``.

    Any ``d > 0`` gives a valid certificate (:func:`scaled_plant`), so ``d``
    is searched (a grid of starts around ``d0``, then Nelder-Mead on
    ``log d``, :data:`SEARCH_EVALUATIONS` evaluations) on the μ upper bound at the frequencies of
    :data:`SEARCH_GRID` where ``d0``'s is within 30 % of its peak, and
    again with those where the found one's is when its peak moved (up to
    :data:`SEARCH_ROUNDS` rounds); the scalings with the lowest peak on the
    whole grid are returned (``d0`` when none is lower), and the
    certificate then proves them at every frequency.  The loop's
    response is computed once: the scalings act on its outside channels.
    """
    from scipy.optimize import minimize

    from polyrob.analysis.mu.bounds import mussv
    from polyrob.analysis.mu.frequency import matrix_response
    from polyrob.plant.loops import lft
    from polyrob.progress import report

    d0 = np.asarray(d0, float)
    if d0.size == 0:
        return d0
    plant, blk = scaled_plant(P, np.ones_like(d0))
    m = P.n_u
    N = lft(plant, K, n_u=m, n_y=m)
    H = matrix_response(*(np.asarray(X, float) for X in (N.A, N.B, N.C, N.D)))(
        np.logspace(*map(np.log10, SEARCH_GRID[:2]), SEARCH_GRID[2])
    )
    constant, full = _channels(P.block_structure_rs, _moving_flags(P))
    n_c, m_c = sum(len(i) for i, _, _ in constant), sum(len(o) for _, o, _ in constant)

    steps = np.linspace(-1.5, 1.5, 5) if d0.size <= 2 else np.linspace(-1.0, 1.0, 3)  # a grid of starts first
    starts = np.array(np.meshgrid(*[steps] * d0.size, indexing="ij")).reshape(d0.size, -1).T[:SEARCH_EVALUATIONS]
    calls, most = [0], 1 + SEARCH_ROUNDS * (len(starts) + SEARCH_EVALUATIONS + 1)

    def scaled(log_d, at):
        calls[0] += 1  # the job's line: at most `most` evaluations in all
        report(calls[0], most)
        s_in, s_out = _block_scales(full, np.exp(log_d), H.shape[2], H.shape[1], n_c, m_c)
        return np.array([mussv(s_out[:, None] * H[f] * s_in[None, :], blk, lower=False).upper for f in at])

    # the search sees the frequencies near the peak; where the peak moves elsewhere, those join it (a few rounds)
    best_x, best = np.log(d0), scaled(np.log(d0), range(len(H)))
    near = set(np.flatnonzero(best >= 0.7 * best.max()).tolist())
    for _ in range(SEARCH_ROUNDS):
        at = sorted(near)
        start = min((best_x + g for g in starts), key=lambda x: scaled(x, at).max())
        found = minimize(lambda x: scaled(x, at).max(), start, method="Nelder-Mead",
                         options={"maxfev": SEARCH_EVALUATIONS})  # fmt: skip
        whole = scaled(found.x, range(len(H)))
        if whole.max() < best.max():
            best_x, best = found.x, whole
        moved = set(np.flatnonzero(whole >= 0.7 * whole.max()).tolist())
        if moved <= near:
            break
        near |= moved
    return np.exp(best_x)


#: Level (times the nominal loop's gain) at which the scalings are searched for stability alone.
STABILITY_LEVEL = 1e3


def moving_worst_case(P, K, d0, *, scope=None, **mu_options):
    """``(WorstCaseGain, d)``: the moving robot's weighted gain over the whole set on the merged structure.

    :func:`polyrob.analysis.worst_case.wcgain` on :func:`scaled_plant` with
    the performance inputs scaled inside the merged block (no member
    claimed: the structure is a sufficient test).  The scalings ``d0``
    (robust performance's) are tried first; then ``d`` is searched
    (:func:`search_scalings`) on the loop with its performance inputs
    divided by the level the first try reached, or by
    :data:`STABILITY_LEVEL` times the nominal gain where it proved no level
    (stability alone), and tried again.  Any ``d`` gives a valid bound: the
    smaller proved one is kept.
    """
    from polyrob.analysis.robust import nominal_performance
    from polyrob.analysis.worst_case import performance_scaled, wcgain

    def at(d):
        plant, blk = scaled_plant(P, d)
        return wcgain(plant, K, blk, n_u=P.n_u, n_y=P.n_y, n_w=P.n_w, n_z=P.n_z, members=False, scope=scope,
                      **mu_options)  # fmt: skip

    d0 = np.asarray(d0, float)
    best = (at(d0), d0)
    if d0.size == 0:
        return best
    level = best[0].grid_level
    if not np.isfinite(level):
        level = STABILITY_LEVEL * max(float(nominal_performance(P, K)), 1e-12)
    d1 = search_scalings(replace(P, system=performance_scaled(P.system, level, P.n_w, P.n_u)), K, d0)
    if not np.allclose(d1, d0):
        second = at(d1)
        if second.proved and (not best[0].proved or second.upper < best[0].upper):
            best = (second, d1)
    return best


def constant_parameter_certificate(
    problem,
    K,
    *,
    auto: bool = False,
    tries=(1.0, 1.05, 0.95),
    scalings=None,
    search: bool = False,
    worst_case: bool = False,
    **mu_options,
):
    """The moving-robot certificate of ``K`` on an ``inner-gain`` problem: constants fixed, the state at any rate.

    Parameters
    ----------
    problem : Problem
        Its generalized plant's uncertainty model must be an inner-gain one (:func:`applies`), or
        ``inner-links``, analysed on its ``inner-links-moving`` model (:func:`moving_problem`).
    K : LTI
    auto : bool
        Compute it only for a loop of at most :data:`AUTO_STATES` states.
    tries : sequence of float
        Multiples of the small-gain scaling ``d`` tried in turn until one certifies.
    scalings : array_like, optional
        The moving blocks' ``d`` to start from instead of the small gain's
        (a synthesis' own, :mod:`polyrob.synthesis.moving`).
    search : bool
        Search ``d`` first (:func:`search_scalings`), then certify that one.
    worst_case : bool
        Also bound the moving robot's weighted gain over the whole set on
        the same structure (:func:`polyrob.analysis.worst_case.wcgain` with
        the performance inputs scaled inside the merged block: the small
        gain with the constant ``d`` then bounds the gain by the level).
    **mu_options
        Passed to :func:`polyrob.analysis.certificate.certify_loop`.

    Returns
    -------
    MovingRobotCertificate
        ``computed=False`` (and why) when the route does not apply.
    """
    import control

    from polyrob.analysis.certificate import Scope, certify_loop
    from polyrob.analysis.lpv.moving_result import MovingRobotCertificate

    t0 = time.perf_counter()
    why = applies(problem)
    if why and _model(problem) not in MOVING_MODEL:
        return MovingRobotCertificate.not_computed(why)
    n = problem.P.n_x + int(control.ss(K).nstates)  # the same plant on the model of constants
    if n > MAX_STATES or (auto and n > AUTO_STATES):
        return MovingRobotCertificate.not_computed(
            f"the loop has {n} states (computed up to {AUTO_STATES if auto else MAX_STATES})"
        )
    try:
        problem = moving_problem(problem)
    except PolyrobError as exc:
        return MovingRobotCertificate.not_computed(f"the model of constants ({MOVING_MODEL[_model(problem)]}): {exc}")
    P, m = problem.P, problem.P.n_u
    constant, full = _channels(P.block_structure_rs, _moving_flags(P))
    real = [r for r in constant if r[2].kind == "real"]
    if not real:
        return MovingRobotCertificate.not_computed("the model has no constant real parameter")
    base = problem.scope() if hasattr(problem, "scope") else Scope()
    names = ", ".join(P.uncertain.parameter_names[: len(real)])
    held = len(constant) - len(real)  # full blocks that stay constant (inner-links-moving: the rest at the centre)
    exact = (P.uncertain.info or {}).get("exact_scalars")
    what = f"its {len(real)} link and joint parameters, exact there" if exact else f"the directions' values {names}"
    if exact and (P.uncertain.info or {}).get("payload_lft") is not None:  # the instrument's scalars come last
        from polyrob.plant.payload_lft import PAYLOAD_SCALARS

        links = len(real) - sum(name in PAYLOAD_SCALARS for name in P.uncertain.parameter_names)
        what = f"its {links} link and joint parameters and the instrument's mass and centre of mass, exact there"
    if held or exact:
        blocks = f" and {held} full block{'s' * (held > 1)}" if held else ""
        names = f"the set's parameters ({what}{blocks} at the task's centre)"
    words = f"{names} constant (rate 0), the state (q, qdot, qddot) moving at any rate"
    try:
        d0, source = residual_scalings(P, K)
        if scalings is not None and len(scalings) == len(d0):
            d0, source = np.asarray(scalings, float), "given"
        if search:
            d0, source, tries = search_scalings(P, K, d0), f"searched from {source}", (1.0,)
        best = None
        for factor in tries:
            plant, blk = scaled_plant(P, d0 * factor)
            # mu >= 1 of the scaled structure breaks this sufficient test, not the robot: the merged block
            # is complex and its scaling fixed, so no robot of the set is shown to miss the performance
            cert = certify_loop(plant, K, blk, n_u=m, n_y=m, scope=base, lower_bound_disproves=False, **mu_options)
            if best is None or cert.bound < best[0].bound:
                best = (cert, factor)
            if cert.certified or not full:
                break
    except PolyrobError as exc:
        return MovingRobotCertificate.not_computed(str(exc))
    cert, factor = best
    notes = (
        f"the moving residual blocks scaled by the constants d = {', '.join(f'{v:.4g}' for v in d0 * factor)} "
        f"({source}, times {factor:.3g}), one full block with the performance "
        "channels: a constant scaling commutes with a time-varying residual",
        f"the constants {names} as blocks of mu of their own (constant in time: frequency-dependent D-G scalings)",
    )
    scope = replace(
        cert.scope,
        variation=f"the robot {base.robot} in motion inside the domain: {words}",
        notes=notes + tuple(cert.scope.notes),
    )
    cert = replace(cert, scope=scope)
    wc = moving_worst_case(P, K, d0 * factor, scope=scope, **mu_options)[0] if worst_case else None
    return MovingRobotCertificate(
        computed=True,
        gamma=float(cert.bound),
        rates=tuple((0.0, 0.0) for _ in real),
        rate_words=words,
        grid_words=f"mu with {len(real)} constant real block(s), {held} constant full block(s) and one full block "
        "that moves",
        scope=scope,
        decided=cert,
        seconds=time.perf_counter() - t0,
        worst_case=wc,
    )


#: The options :func:`~polyrob.analysis.lpv.task.task_motion_certificate` takes from the moving search's options.
TASK_OPTIONS = (
    "points",
    "velocities",
    "harmonics",
    "level",
    "cells",
    "cell_level",
    "cell_time_limit",
    "cell_workers",
    "progress",
    "solver",
)


def check_jerk(problem, jerk) -> None:
    """Refuse a jerk bound (``--qdddot-max``) where no certificate reads it: off a task, or with an inner layer.

    Raises
    ------
    ArgumentError
    """
    if jerk is None:
        return
    from polyrob.model.inner import InnerLoopRobot

    inner = isinstance(getattr(problem, "robot", None), InnerLoopRobot)
    if getattr(getattr(problem, "domain", None), "kind", "") != "task" or applies(problem) is None or inner:
        raise ArgumentError(
            "--qdddot-max bounds the jerk of a task domain's moving robot: give a task (--pose, --q-radius, "
            "--qdot-max, --qddot-max) without an inner layer, or drop it"
        )


def robot_in_motion_certificate(
    problem, K, *, auto: bool = False, time_varying=None, jerk=None, scalings=None, worst_case=False, **options
):
    """The moving-robot certificate that fits ``problem``'s model and domain.

    An inner-gain model (physical constants and state-dependent residual
    blocks): :func:`constant_parameter_certificate`, its scalings searched
    unless ``auto`` (``scalings``: a synthesis' own to start from; ``worst_case``:
    its gain over the whole set too).  A task domain (the
    torques by inverse dynamics): the robot scheduled on its positions,
    velocities and accelerations,
    :func:`polyrob.analysis.lpv.task.task_motion_certificate` (with the
    arbitrarily fast certificate ``time_varying``, which decides when it
    holds, and the jerk bound ``jerk``).  Any other model: the robot
    scheduled on its state with the domain's rates,
    :func:`polyrob.analysis.lpv.moving.moving_robot_certificate`.
    ``options`` go to the one chosen.

    Raises
    ------
    ArgumentError
        ``jerk`` off a task domain, or an option the chosen certificate does
        not take (``symmetric="auto"`` is dropped on a task: its grid is not
        halved).
    """
    from polyrob.analysis.lpv.moving import moving_robot_certificate

    check_jerk(problem, jerk)
    why = applies(problem)
    if why is None or _model(problem) in MOVING_MODEL:
        # asked for (not auto): the moving blocks' scalings searched, worth its minutes on an arm
        return constant_parameter_certificate(
            problem, K, auto=auto, scalings=scalings, search=not auto, worst_case=worst_case
        )
    from polyrob.model.inner import InnerLoopRobot

    if isinstance(getattr(problem, "robot", None), InnerLoopRobot):
        # an inner loop on another model (inner-links: its direction scalars are the set's constants times
        # coefficients of the state): no constant parameter to hold, and the task's grid is for a bare robot
        from polyrob.analysis.lpv.moving import MovingRobotCertificate

        return MovingRobotCertificate.not_computed(
            f"{why}; only the time-varying verdict (every parameter at any rate) covers the moving robot"
        )
    if getattr(getattr(problem, "domain", None), "kind", "") != "task":
        return moving_robot_certificate(problem, K, auto=auto, **options)
    from polyrob.analysis.lpv.task import task_motion_certificate

    if options.get("symmetric") == "auto":
        options.pop("symmetric")
    unknown = sorted(set(options) - set(TASK_OPTIONS))
    if unknown:
        raise ArgumentError(f"the task's moving-robot certificate takes no {', '.join(unknown)}: drop it")
    return task_motion_certificate(problem, K, auto=auto, jerk=jerk, time_varying=time_varying, **options)
