"""An independent check of a frozen-robot certificate: its own dynamics code, true robots drawn from a stated set.

:func:`frozen_check` reads a controller file (as ``polyrob synth -o`` writes
it: the controller, its certificate, its problem), draws ``N`` true robots
from a :class:`~polyrob.uncertainty_set.spec.RobotUncertainty` (each link's
parameters independent, a payload body off the flange's axis; by default
half of them at vertices of the set, each at random corners of the task:
:data:`~polyrob.uncertainty_set.draw.EXTREME_SHARE`), and for each, at
random points of the file's task domain:

1. the frozen Jacobians of the inner and outer loop **computed here**, from
   Pinocchio's ``computeABADerivatives`` on the true model and
   ``computeRNEADerivatives`` (computed torque) or
   ``computeGeneralizedGravityDerivatives`` (gravity) on the inner layer's
   model, chained by hand (no polyrob bounds, plant or model code)::

       qddot = aba_true(q, qdot, tau_inner(q, qdot, v) - D_true qdot)
       A = [[0, I], [d qddot/dq, d qddot/dqdot]],   B = [[0], [M_true^-1 d tau_inner/dv]]

   with ``v`` the input that gives the point's ``qddot`` on this true robot;
2. the closed loop with the controller ``u = K (r - q)``: its largest pole real part;
3. the weighted closed loop ``w = r -> z = [W_S e; W_T y; W_KS u]`` with the
   weights rebuilt here from the file's hyperparameters (the paper's ``W_S``
   and ``W_T``; where the file has limit weights, the effort weight on the
   outer input, ``W_KS = w_n W_u``: the encoder noise ``W_n n`` enters ``e``
   where ``r`` does, so the noise-driven effort is this channel's), and its
   H-infinity norm by SLICOT's ``AB13DD`` (called directly).

A frozen certificate ``mu <= b`` of robust performance implies, for every
robot of its set and every frozen point, a stable loop with ``||N_zw||inf <= b``:
the check counts the loops that break this.  It measures a sample; it
proves nothing (a clean sample is evidence, one failure is a counterexample).
Coulomb friction has no frozen linearisation (the frozen loops of a moving
joint do not see it): the true robots carry their drawn viscous friction only.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio

from polyrob.errors import ArgumentError
from polyrob.uncertainty_set.draw import EXTREME_SHARE, at_vertices

__all__ = [
    "FrozenCheck",
    "weights_from_hyperparameters",
    "effort_weight_from_hyperparameters",
    "frozen_jacobians",
    "weighted_loop",
    "frozen_check",
]

#: The weight hyperparameters this check rebuilds (the paper's W_S and W_T).
PAPER_KEYS = ("omega_b", "M_s", "A_s", "omega_bt", "M_t", "A_t")
#: The limit hyperparameters it rebuilds too: the effort weight ``W_u`` per outer input, the noise ``W_n`` per joint.
LIMIT_KEYS = ("effort", "noise")


def weights_from_hyperparameters(hp: dict, m: int):
    """``(W_S, W_T)`` as state-space matrices of diagonal first-order weights, rebuilt from their formulas.

    ``W_S,i = (s / M_s + w_b) / (s + w_b A_s)``, ``W_T,i = (s + w_bt) / (A_t s + w_bt M_t)``.
    Each is ``(A, B, C, D)`` with ``m`` states.
    """
    unknown = sorted(set(hp) - set(PAPER_KEYS) - set(LIMIT_KEYS))
    if unknown or set(PAPER_KEYS) - set(hp):
        raise ArgumentError(
            f"the controller file's weights hold {sorted(hp)}; this check rebuilds the paper's "
            f"{', '.join(PAPER_KEYS)} and the limit weights' {', '.join(LIMIT_KEYS)} only: check that controller "
            "another way"
        )
    get = {k: np.broadcast_to(np.asarray(hp[k], float), (m,)) for k in PAPER_KEYS}
    wb, ms, As = get["omega_b"], get["M_s"], get["A_s"]
    wbt, mt, At = get["omega_bt"], get["M_t"], get["A_t"]
    # (s/Ms + wb)/(s + wb As) = 1/Ms + (wb - wb As/Ms)/(s + wb As)
    WS = (np.diag(-wb * As), np.eye(m), np.diag(wb - wb * As / ms), np.diag(1.0 / ms))
    # (s + wbt)/(At s + wbt Mt) = 1/At + (wbt - wbt Mt/At)/At / (s + wbt Mt/At)
    p = wbt * mt / At
    WT = (np.diag(-p), np.eye(m), np.diag((wbt - p) / At), np.diag(1.0 / At))
    return WS, WT


def effort_weight_from_hyperparameters(hp: dict, m: int):
    """``W_KS`` on the outer input ``u``: ``diag(W_u) * max(W_n)``, or ``None`` when ``hp`` has no limit keys.

    The noise ``n`` enters the measurement as ``e = r - q - W_n n``, where
    the reference does, so ``n -> u`` is ``-K S W_n``; with the largest noise
    level on every joint (only larger) ``||W_u K S W_n|| <= ||(w_n W_u) K
    S||``, the ``r -> u`` channel this weight puts in the stacked norm.
    """
    if not set(LIMIT_KEYS) & set(hp):
        return None
    if set(LIMIT_KEYS) - set(hp):
        raise ArgumentError(f"the controller file's limit weights need both {list(LIMIT_KEYS)}, it has {sorted(hp)}")
    effort = np.broadcast_to(np.asarray(hp["effort"], float), (m,))
    noise = float(np.max(np.asarray(hp["noise"], float)))
    return np.diag(effort * noise)


def _config(model, q):
    return pinocchio.integrate(model, pinocchio.neutral(model), np.asarray(q, float))


def frozen_jacobians(true_model, true_damping, model_hat, damping_hat, inner: str, q, qdot, qddot):
    """``(A, B, v)`` of the inner+outer loop of one true robot frozen at ``(q, qdot, qddot)`` (see the module)."""
    m = true_model.nv
    data, data_hat = true_model.createData(), model_hat.createData()
    c, c_hat = _config(true_model, q), _config(model_hat, q)
    qdot, qddot = np.asarray(qdot, float), np.asarray(qddot, float)
    D, D_hat = np.diag(true_damping), np.diag(damping_hat)
    tau_needed = pinocchio.rnea(true_model, data, c, qdot, qddot) + D @ qdot
    zero = np.zeros(m)
    if inner == "computed-torque":
        M_hat = pinocchio.crba(model_hat, data_hat, c_hat)
        M_hat = np.triu(M_hat) + np.triu(M_hat, 1).T
        h_hat = pinocchio.rnea(model_hat, data_hat, c_hat, qdot, zero) + D_hat @ qdot
        v = np.linalg.solve(M_hat, tau_needed - h_hat)
        dtau_dq, dtau_dqdot, M_hat = pinocchio.computeRNEADerivatives(model_hat, data_hat, c_hat, qdot, v)
        dtau_dq, dtau_dqdot = np.array(dtau_dq), np.array(dtau_dqdot) + D_hat
        dtau_dv = np.triu(M_hat) + np.triu(M_hat, 1).T
    elif inner == "gravity":
        g_hat = pinocchio.computeGeneralizedGravity(model_hat, data_hat, c_hat)
        v = tau_needed - g_hat
        dtau_dq = np.array(pinocchio.computeGeneralizedGravityDerivatives(model_hat, data_hat, c_hat))
        dtau_dqdot, dtau_dv = np.zeros((m, m)), np.eye(m)
    elif inner == "none":
        v = tau_needed
        dtau_dq, dtau_dqdot, dtau_dv = np.zeros((m, m)), np.zeros((m, m)), np.eye(m)
    else:
        raise ArgumentError(f"unknown inner layer {inner!r}")
    tau_applied = tau_needed - D @ qdot  # what aba sees: the inner law's output with the true damping taken off
    pinocchio.computeABADerivatives(true_model, data, c, qdot, tau_applied)
    Minv = np.triu(data.Minv) + np.triu(data.Minv, 1).T
    A = np.zeros((2 * m, 2 * m))
    A[:m, m:] = np.eye(m)
    A[m:, :m] = np.array(data.ddq_dq) + Minv @ dtau_dq
    A[m:, m:] = np.array(data.ddq_dv) + Minv @ (dtau_dqdot - D)
    B = np.zeros((2 * m, m))
    B[m:] = Minv @ dtau_dv
    return A, B, v


def weighted_loop(A, B, K, WS, WT, W_KS=None):
    """``(closed loop A, weighted loop (A, B, C, D))`` of ``G = (A, B, [I 0], 0)`` under ``u = K (r - y)``.

    ``z = [W_S e; W_T y]``, and ``W_KS u`` below them when the constant ``W_KS`` is given.
    """
    m = B.shape[1]
    n = A.shape[0]
    Ak, Bk, Ck, Dk = K
    nk = Ak.shape[0]
    C = np.hstack([np.eye(m), np.zeros((m, n - m))])
    # states [x; xk]: e = r - C x, u = Ck xk + Dk e
    Acl = np.block([[A - B @ Dk @ C, B @ Ck], [-Bk @ C, Ak]])
    Bcl = np.vstack([B @ Dk, Bk])
    Ccl_e = np.hstack([-C, np.zeros((m, nk))])  # e = Ccl_e xcl + r
    Ccl_y = np.hstack([C, np.zeros((m, nk))])
    (As, Bs, Cs, Ds), (At, Bt, Ct, Dt) = WS, WT
    ns, nt, ncl = As.shape[0], At.shape[0], Acl.shape[0]
    Aw = np.zeros((ncl + ns + nt, ncl + ns + nt))
    Aw[:ncl, :ncl] = Acl
    Aw[ncl : ncl + ns, :ncl] = Bs @ Ccl_e
    Aw[ncl : ncl + ns, ncl : ncl + ns] = As
    Aw[ncl + ns :, :ncl] = Bt @ Ccl_y
    Aw[ncl + ns :, ncl + ns :] = At
    Bw = np.vstack([Bcl, Bs, np.zeros((nt, m))])
    Cw = np.vstack(
        [
            np.hstack([Ds @ Ccl_e, Cs, np.zeros((m, nt))]),
            np.hstack([Dt @ Ccl_y, np.zeros((m, ns)), Ct]),
        ]
    )
    Dw = np.vstack([Ds, np.zeros((m, m))])
    if W_KS is not None:  # u = Ck xk + Dk e = [-Dk C, Ck] xcl + Dk r
        W_KS = np.asarray(W_KS, float)
        Cu = np.hstack([-Dk @ C, Ck, np.zeros((Dk.shape[0], ns + nt))])
        Cw, Dw = np.vstack([Cw, W_KS @ Cu]), np.vstack([Dw, W_KS @ Dk])
    return Acl, (Aw, Bw, Cw, Dw)


def hinf(A, B, C, D, tol: float = 1e-9) -> float:
    """SLICOT AB13DD's H-infinity norm of a stable system (``inf`` when any pole has Re >= 0)."""
    import slycot

    if np.linalg.eigvals(A).real.max(initial=-np.inf) >= 0:
        return float("inf")
    n, mi, p = A.shape[0], B.shape[1], C.shape[0]
    gpeak, _ = slycot.ab13dd("C", "I", "N", "D", n, mi, p, A, np.eye(n), B, C, D, tol)
    return float(gpeak)


@dataclass(frozen=True, eq=False)
class FrozenCheck:
    """What :func:`frozen_check` found: per loop its largest pole real part and weighted norm."""

    controller: str
    robot: str
    inner: str
    uncertainty: str
    bound: float | None
    max_pole_real: np.ndarray
    weighted_norm: np.ndarray
    points_per_robot: int
    info: dict = field(default_factory=dict)

    @property
    def unstable(self) -> int:
        return int(np.sum(self.max_pole_real >= 0))

    @property
    def above_bound(self) -> int:
        stable = self.max_pole_real < 0
        if self.bound is None:
            return 0
        return int(np.sum(self.weighted_norm[stable] > self.bound))

    def summary(self) -> dict:
        stable = self.weighted_norm[self.max_pole_real < 0]
        finite = stable[np.isfinite(stable)]
        return {
            "what": "frozen inner+outer loops of true robots drawn from the set, own Pinocchio derivative code",
            "controller": self.controller,
            "robot": self.robot,
            "inner": self.inner,
            "uncertainty": self.uncertainty,
            "loops": int(self.max_pole_real.size),
            "points_per_robot": self.points_per_robot,
            "unstable": self.unstable,
            "worst_pole_real": float(self.max_pole_real.max()) if self.max_pole_real.size else None,
            "weighted_norm_median": float(np.median(finite)) if finite.size else None,
            "weighted_norm_worst": float(finite.max()) if finite.size else None,
            "bound": self.bound,
            "above_bound": self.above_bound,
            "every_loop_stable_and_below_bound": bool(
                self.unstable == 0 and self.above_bound == 0 and self.bound and "weighted_norm_of" not in self.info
            ),
            **self.info,
        }


def _inner_layer(info: dict) -> str:
    """The controller file's inner layer; words this check cannot read are refused, not taken for "none"."""
    words = str(info.get("inner", "") or "none")
    for layer in ("computed-torque", "gravity", "none"):
        if words.startswith(f"inner layer: {layer}") or words == layer:
            return layer
    raise ArgumentError(f"the controller file's inner layer {words[:60]!r} is not one this check knows")


def _task_box(info: dict, joints):
    dom = info.get("domain") or {}
    if dom.get("kind") != "task":
        raise ArgumentError("the controller file's problem has no task domain (q, qdot, qddot): this check needs one")
    box = {g: np.array([dom[g][j] for j in joints], float) for g in ("q", "qdot", "qddot")}
    return box


def frozen_check(
    controller_path,
    uncertainty=None,
    *,
    n: int = 2000,
    points: int = 1,
    seed: int = 0,
    nominal_only: bool = False,
    at_pose: bool = False,
    controller=None,
    common_factor: float | None = None,
    on_loop=None,
    paper_block: bool = False,
    extremes: float = EXTREME_SHARE,
) -> FrozenCheck:
    """The frozen check of the controller file ``controller_path`` on ``n`` true robots of ``uncertainty``.

    Parameters
    ----------
    controller_path : path
        A controller file with its problem (``info``: robot, inner layer, task domain, weights).
    uncertainty : RobotUncertainty, optional
        Default :func:`polyrob.validate.at_rate.runs.default_uncertainty`.
    n : int
        True robots drawn.
    points : int
        Random task points per robot.
    seed : int
    nominal_only : bool
        One robot: the nominal links, the model's payload (the certificate's nominal plant).
    at_pose : bool
        The points are the task's pose at rest (``qdot = qddot = 0``) instead of random.
    controller : LTI, optional
        Replace the file's controller (e.g. a deliberately broken one).
    common_factor : float, optional
        Draw instead from the set today's certificates cover: every link times one factor
        uniform in ``[1 - p, 1 + p]`` (``p`` this value), the payload of ``uncertainty``
        (point mass, as :func:`polyrob.model.payload.with_payload` puts it), the URDF's damping.
    on_loop : callable, optional
        Called with ``(done, total)`` loops (progress).
    paper_block : bool
        A file whose weights hold limit weights (effort, noise) too: rebuild
        only ``W_S`` and ``W_T`` (by default the effort weight is rebuilt
        too: :func:`effort_weight_from_hyperparameters`).  The norm is then
        that of a sub-block of the certified loop, a lower bound of its norm:
        a value above the bound disproves it, none below proves it (the
        summary says so).
    extremes : float
        The share of the ``n`` robots drawn at vertices of the set (every link factor
        at an end, the payload's mass at an end and its centre of mass on the
        ball's surface), each at random *corners* of the task box (default
        :data:`~polyrob.uncertainty_set.draw.EXTREME_SHARE`); the rest uniformly
        inside the set, at random points of the box.
    """
    import control

    from polyrob.io.controller import load_controller, read_controller_file
    from polyrob.model.robots import load_robot
    from polyrob.uncertainty_set.draw import draw_true_robots, vertex_words
    from polyrob.validate.at_rate.runs import default_uncertainty, model_with_middle_payload

    doc = read_controller_file(controller_path)
    info, cert = doc.get("info") or {}, doc.get("certificate") or {}
    K = control.ss(load_controller(controller_path) if controller is None else controller)
    Kmats = tuple(np.atleast_2d(np.asarray(X, float)) for X in (K.A, K.B, K.C, K.D))
    if K.nstates == 0:
        Kmats = (np.zeros((0, 0)), np.zeros((0, K.ninputs)), np.zeros((K.noutputs, 0)), Kmats[3])
    robot = load_robot(info.get("robot", ""))
    inner = _inner_layer(info)
    m = robot.m
    weights = dict(info.get("weights") or {})
    limit_keys = sorted(set(weights) - set(PAPER_KEYS))
    if paper_block:
        weights = {k: v for k, v in weights.items() if k in PAPER_KEYS}
    WS, WT = weights_from_hyperparameters(weights, m)
    W_KS = effort_weight_from_hyperparameters(weights, m)
    box = _task_box(info, robot.joint_names)
    bound = (cert.get("certificate") or {}).get("bound")
    spec = default_uncertainty(robot) if uncertainty is None else uncertainty
    spec = spec.bound(robot)
    if robot.model.nv != m:
        raise ArgumentError(f"{robot.name}: its Pinocchio model has {robot.model.nv} velocities for {m} joints")
    model_hat = model_with_middle_payload(robot, spec)
    extremes = 0.0 if nominal_only else extremes
    inside = int(n) - at_vertices(n, extremes)
    if nominal_only:
        trues = [(model_hat.model, np.asarray(model_hat.damping, float))]
        words = "the nominal robot (the inner layer's model)"
    elif common_factor is not None:
        from polyrob.model.payload import with_payload

        draw = np.random.default_rng(seed)
        trues = []
        for i in range(int(n)):
            extreme = i >= inside
            mass, com = (0.0, np.zeros(3)) if spec.payload is None else spec.payload.draw(draw, extreme=extreme)
            scale = (
                1 + common_factor * draw.choice([-1.0, 1.0])
                if extreme
                else draw.uniform(1 - common_factor, 1 + common_factor)
            )
            trues.append((with_payload(robot, mass, com, scale=scale).model, np.asarray(robot.damping, float)))
        payload = "no payload" if spec.payload is None else spec.payload.words()
        words = f"one factor on every link within ±{100 * common_factor:g} %, {payload}"
    else:
        drawn = draw_true_robots(robot, spec, int(n), seed=seed, extremes=extremes)
        trues = [(t.model, np.asarray(t.viscous, float)) for t in drawn]
        words = spec.words()
    words += vertex_words(len(trues), extremes) + (" (those at random corners of the task)" if extremes else "")
    rng = np.random.default_rng(seed + 1)
    total = len(trues) * int(points)
    poles, norms = np.empty(total), np.empty(total)
    k = 0
    for i, (true_model, damping) in enumerate(trues):
        for _ in range(int(points)):
            if at_pose:
                q = np.array(info["domain"]["pose"], float)
                qdot = qddot = np.zeros(m)
            elif i >= inside:  # a vertex robot at a corner of the task, where its frozen loop's gain is largest
                q, qdot, qddot = (np.where(rng.integers(0, 2, m) == 1, box[g][:, 1], box[g][:, 0])
                                  for g in ("q", "qdot", "qddot"))  # fmt: skip
            else:
                q, qdot, qddot = (rng.uniform(box[g][:, 0], box[g][:, 1]) for g in ("q", "qdot", "qddot"))
            A, B, _ = frozen_jacobians(
                true_model, damping, model_hat.model, np.asarray(model_hat.damping, float), inner, q, qdot, qddot
            )
            Acl, Wl = weighted_loop(A, B, Kmats, WS, WT, W_KS)
            poles[k] = float(np.linalg.eigvals(Acl).real.max())
            norms[k] = hinf(*Wl) if poles[k] < 0 else float("inf")
            k += 1
            if on_loop is not None:
                on_loop(k, total)
    return FrozenCheck(
        controller=str(controller_path),
        robot=robot.name,
        inner=inner,
        uncertainty=words,
        bound=None if bound is None else float(bound),
        max_pole_real=poles,
        weighted_norm=norms,
        points_per_robot=int(points),
        info={
            "seed": int(seed),
            "certificate": (cert.get("certificate") or {}).get("verdict"),
            "weights_rebuilt": "W_S e, W_T y" + ("" if W_KS is None else ", W_KS u (effort x noise)"),
            **(
                {"weighted_norm_of": f"the W_S/W_T sub-block only ({', '.join(limit_keys)} left out): a lower bound"}
                if paper_block and limit_keys
                else {}
            ),
        },
    )
