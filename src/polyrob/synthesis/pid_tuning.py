"""A per-joint PID tuned to the weights: the start an arm engineer would write down first.

Behind a computed-torque inner layer the outer controller sees, per joint, a
double integrator ``qddot_j = b_j v_j`` up to the model error (``b_j = 1``);
without that layer the nominal input matrix ``M(q_0)^-1`` couples the joints,
and the PID acts through its inverse, the nominal inertia (:func:`_input_gains`).  The textbook
controller for it is a PID with a filtered derivative, critically damped at a
crossover ``ω_c``::

    K_j(s) = (ω_c² + ω_c³/(k_i s) + 2 ω_c s/(s/(n_f ω_c) + 1)) / b_j

:func:`tuned_pid` picks ``(ω_c, k_i, n_f)`` from a small candidate set placed
by the weights (``ω_c`` a fraction of the smallest ``W_T`` bandwidth, which
caps the loop's bandwidth; then, if that is not good enough, one factor per
joint on it) by the robust-performance μ upper bound of each
candidate's closed loop on a coarse frequency grid, computed with AB13MD on a
superset structure (``mussv(method="relaxed")``, or descent on the D-G
scalings when that structure has many real scalars: a true upper bound at
those frequencies, cheap enough to rank candidates).  The figure only ranks
candidates: the controller is certified afterwards like any other
(:func:`polyrob.analysis.certificate.certify_loop`).

Why by hand: no maintained library tunes a PID against a structured singular
value; MATLAB's ``systune`` does it by non-smooth optimisation, which
:mod:`polyrob.synthesis.fixed` does here from this start.

Full-order D-K started from the unscaled H∞ controller stalls on the
computed-torque loops of 5-7 joint arms (panda's default task: μ 5.25 after
D-K, against 0.9643 certified for this PID; docs/fleet.md), because
its first controller is made for ``D = I`` on a structure whose repeated real
block gets one scalar scaling in the fit.  Starting from this PID, the
iteration keeps the best controller it sees, so it can only do better.
"""

from __future__ import annotations

import itertools
import logging
from dataclasses import dataclass, field

import control
import numpy as np

from polyrob.errors import ArgumentError, SynthesisError

__all__ = [
    "TunedPID",
    "tuned_pid",
    "pid_start",
    "start_result",
    "pid_controller",
    "CROSSOVER_FRACTIONS",
    "JOINT_SCALES",
    "MIN_GAIN",
]

log = logging.getLogger("polyrob")

#: ``ω_c`` candidates, as fractions of the smallest ``W_T`` bandwidth ``ω_BT``.
CROSSOVER_FRACTIONS = (0.2, 0.3, 0.4, 0.55, 0.75)
#: Integral ratios ``k_i`` (integral gain ``ω_c³ / k_i``) and derivative filters ``n_f``.
INTEGRAL_RATIOS = (8.0, 16.0, 32.0)
FILTER_RATIOS = (10.0, 20.0)
#: Factors on one joint's crossover tried, joint by joint, when the common crossover ranks in
#: ``refine_window``: the joints of an arm see different model errors (a payload weighs on the wrist's
#: small inertia, the shoulder's is large), so one crossover for all is not always enough (ur10 with a
#: payload is certified only with a crossover per joint, docs/fleet.md).
JOINT_SCALES = (0.5, 0.7, 1.4, 2.0, 2.8)
JOINT_SWEEPS = 2
#: A candidate replaces the best only when its figure is lower by this fraction: the ranking is
#: coarse anyway, and each new best costs a μ bound at every frequency of the grid.
MIN_GAIN = 0.01
#: Off-diagonal input gains up to this fraction of the largest diagonal one are none: no decoupling.
DECOUPLE_TOL = 1e-6


@dataclass(frozen=True)
class TunedPID:
    """The PID :func:`tuned_pid` chose, and how.

    Attributes
    ----------
    controller : control.StateSpace
        Decentralised, order ``2 m``; inputs the errors ``e``, outputs ``u``.
    crossover, integral_ratio, filter_ratio : float
        ``ω_c`` (rad/s), ``k_i``, ``n_f`` of the module text.
    input_gains : ndarray
        ``b_j`` the gains were divided by (the nominal input matrix's diagonal).
    grid_mu : float
        The ranking figure: the largest μ upper bound over the coarse grid
        (a search figure, not a certificate).
    tried : tuple of (crossover, integral_ratio, filter_ratio, grid_mu, joint_scales)
        Every candidate's figure; a candidate dropped once it could no longer
        beat the best by :data:`MIN_GAIN` has the figure of the frequency
        where it was dropped (a lower bound of its own figure, at least
        ``1 - MIN_GAIN`` times the best's at the time).
    joint_scales : tuple of float
        Each joint's crossover is ``crossover`` times its scale (all 1 unless
        the per-joint search improved the figure).
    decoupling : ndarray or None
        ``T``: the controller is ``T diag(K_j)`` (the nominal input matrix's
        inverse when it couples the joints, :func:`tuned_pid`); ``None``: the
        PID alone.
    """

    controller: control.StateSpace = field(repr=False)
    crossover: float
    integral_ratio: float
    filter_ratio: float
    input_gains: np.ndarray = field(repr=False)
    grid_mu: float
    tried: tuple = field(default=(), repr=False)
    joint_scales: tuple = ()
    decoupling: np.ndarray | None = field(default=None, repr=False)

    def crossovers(self) -> np.ndarray:
        """Each joint's crossover ``ω_c`` (rad/s)."""
        scales = np.asarray(self.joint_scales, float) if self.joint_scales else np.ones(self.input_gains.size)
        return self.crossover * scales

    def gains(self) -> np.ndarray:
        """``(m, 4)``: ``Kp, Ki, Kd, τ`` per joint, in :class:`~polyrob.synthesis.fixed.pid.PIDStructure`'s order."""
        return pid_gains(self.crossovers(), self.integral_ratio, self.filter_ratio, self.input_gains)

    def words(self) -> str:
        per_joint = ""
        if self.joint_scales and any(s != 1.0 for s in self.joint_scales):
            per_joint = f" times ({', '.join(f'{s:.3g}' for s in self.joint_scales)}) per joint"
        through = " through the nominal inertia (decoupled at the task's pose)" if self.decoupling is not None else ""
        return (
            f"per-joint PID critically damped at {self.crossover:.3g} rad/s{per_joint}{through} "
            f"(integral omega_c^3/{self.integral_ratio:g}, derivative filter at {self.filter_ratio:g} omega_c)"
        )


def pid_gains(crossover, integral_ratio: float, filter_ratio: float, input_gains) -> np.ndarray:
    """``(m, 4)`` ``Kp, Ki, Kd, τ`` of the PID of the module text, divided by each joint's input gain.

    ``crossover`` is one ``ω_c`` for every joint, or one per joint.
    """
    wc = np.asarray(crossover, float)
    b = np.asarray(input_gains, float)
    g = np.empty((b.size, 4))
    g[:, 0] = wc**2 / b
    g[:, 1] = wc**3 / float(integral_ratio) / b
    g[:, 2] = 2.0 * wc / b
    g[:, 3] = 1.0 / (float(filter_ratio) * wc)
    return g


def pid_controller(gains: np.ndarray) -> control.StateSpace:
    """Decentralised PIDF ``Kp + Ki/s + Kd s/(τ s + 1)`` per joint (``gains`` as :func:`pid_gains`).

    Examples
    --------
    >>> import numpy as np
    >>> K = pid_controller(np.array([[4.0, 1.0, 4.0, 0.05]]))
    >>> K.nstates
    2
    >>> s = 1j
    >>> bool(np.isclose(K(s), 4 + 1 / s + 4 * s / (0.05 * s + 1)))  # a 1x1 system's response is a scalar
    True
    """
    from polyrob.synthesis.fixed.pid import PIDStructure

    g = np.asarray(gains, float)
    m = g.shape[0]
    theta = g.copy()
    theta[:, 3] = np.log(g[:, 3])
    return control.ss(*PIDStructure(m, m).realization(theta.ravel()))


def _input_gains(P, decouple: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
    """``(b, T)``: each joint's input gain ``b_j`` and the static decoupling ``T`` (``None`` if not needed).

    ``B_v``, the nominal input matrix's velocity rows, is the identity behind
    computed torque (``b_j = 1``).  Without that layer (``--inner gravity``,
    ``none``) it is ``M(q_0)^-1``, whose couplings a per-joint PID on its
    diagonal ignores (ur5's shoulder and elbow); with ``decouple`` the PID
    then acts through ``T = B_v^-1`` (the nominal inertia: a PD with inertia
    decoupling at the task's pose, what computed torque does at one pose)
    with every ``b_j = 1``.
    """
    B = getattr(getattr(P, "uncertain", None), "B_nom", None)
    m = int(P.n_u)
    if B is None or np.shape(B) != (2 * m, m):
        return np.ones(m), None
    B_v = np.asarray(B, float)[m:]
    b = np.diag(B_v)
    if np.any(~np.isfinite(B_v)) or np.any(b <= 0):
        raise SynthesisError("a PID start needs a positive nominal input gain on every joint")
    off = B_v - np.diag(b)
    if not decouple or np.abs(off).max(initial=0.0) <= DECOUPLE_TOL * np.abs(b).max():
        return b, None
    return np.ones(m), np.linalg.inv(B_v)


def _decoupled(K: control.StateSpace, T) -> control.StateSpace:
    """``T K``: the PID's outputs through the decoupling (``K`` itself for ``T = None``; python-control's product)."""
    return K if T is None else T * K


def tuned_pid(
    P,
    *,
    omega=None,
    crossovers=None,
    integral_ratios=INTEGRAL_RATIOS,
    filter_ratios=FILTER_RATIOS,
    refine_window: tuple | None = (1.0, 1.5),
    decouple: bool = True,
) -> TunedPID:
    """The per-joint PID of the module text with the smallest coarse-grid μ on ``P``.

    Parameters
    ----------
    P : GeneralizedPlant
        From :func:`polyrob.plant.generalized.generalized_plant` (its weights
        place the crossovers, its uncertain plant gives ``b_j``).
    omega : array_like, optional
        Ranking grid (default 25 points over the weights' decades).
    crossovers : sequence of float, optional
        ``ω_c`` candidates in rad/s (default :data:`CROSSOVER_FRACTIONS` of
        the smallest ``ω_BT`` of the weights).
    refine_window : (float, float), optional
        When the best common crossover's figure lies in ``[lo, hi)`` (not
        good enough, not hopeless), each joint's
        crossover is scaled by :data:`JOINT_SCALES` in turn, keeping what
        lowers the figure, for up to :data:`JOINT_SWEEPS` sweeps while a
        sweep gains 2 % (``None``: never; each candidate costs up to a
        figure on the coarse grid).
    decouple : bool
        When the nominal input matrix couples the joints (no computed-torque
        layer), act through its inverse (:func:`_input_gains`); ``False``:
        divide by its diagonal only, each joint on its own.

    Raises
    ------
    SynthesisError
        No candidate stabilises the nominal loop.
    """
    from polyrob.analysis.mu.blocks import as_block_structure
    from polyrob.analysis.mu.bounds import mussv
    from polyrob.analysis.mu.frequency import matrix_response
    from polyrob.analysis.mu.sweep import relaxed_is_cheap
    from polyrob.plant.loops import lower_lft_matrices

    m = int(P.n_u)
    b, T = _input_gains(P, decouple)
    if crossovers is None:
        wbt = _smallest_bandwidth(P)
        crossovers = [f * wbt for f in CROSSOVER_FRACTIONS]
    crossovers = [float(w) for w in crossovers]
    if omega is None:
        lo, hi = min(crossovers) / 1000.0, max(crossovers) * 100.0
        omega = np.logspace(np.log10(lo), np.log10(hi), 25)
    omega = np.asarray(omega, float)
    st = as_block_structure(P.block_structure_rp)
    # AB13MD on the relaxed structure, unless it has many real scalars (an axes model's dozens):
    # then descent on the D-G scalings, 10-30 times faster there
    method = "relaxed" if relaxed_is_cheap(st) else "gradient"
    A, B, C, D = (np.asarray(X, float) for X in (P.system.A, P.system.B, P.system.C, P.system.D))

    # frequencies in the order of the best candidate's figures, largest first: a candidate is dropped at
    # the first frequency where it is not better than the best by MIN_GAIN (its figure is then that one,
    # a lower bound of its own), so only a candidate that becomes the best is evaluated everywhere
    order = np.arange(omega.size)
    tried: list = []
    bests: list = []  # the rows that became the best, in turn: the last is the best

    def best_figure() -> float:
        return bests[-1][3] if bests else np.inf

    def rank(wc, ki, nf, scales=(1.0,) * m) -> None:
        """Append the candidate's row to ``tried``; make it the best when it ran to the end."""
        figure, complete = np.inf, False
        K = _decoupled(pid_controller(pid_gains(wc * np.asarray(scales, float), ki, nf, b)), T)
        Ak, Bk, Ck, Dk = (np.asarray(X, float) for X in (K.A, K.B, K.C, K.D))
        try:
            Acl, Bcl, Ccl, Dcl = lower_lft_matrices(A, B, C, D, Ak, Bk, Ck, Dk, m, m)
        except np.linalg.LinAlgError:
            Acl = None
        if Acl is not None and np.max(np.linalg.eigvals(Acl).real) < 0:
            H = matrix_response(Acl, Bcl, Ccl, Dcl)(omega)
            bar = best_figure() * (1.0 - MIN_GAIN)
            values = np.full(omega.size, -np.inf)
            for k in order:
                values[k] = mussv(H[k], st, method=method, lower=False).upper
                if values[k] >= bar:
                    break
            else:
                complete = True
            figure = float(values.max())
            if complete:
                order[:] = np.argsort(-values, kind="stable")
        tried.append((wc, ki, nf, figure, tuple(scales)))
        if complete:
            bests.append(tried[-1])

    # crossover first (middle integral and filter), then the other two around the best crossover
    for wc in crossovers:
        rank(wc, 16.0, 20.0)
    if bests:
        wc_best = bests[-1][0]
        for ki, nf in itertools.product(integral_ratios, filter_ratios):
            if (ki, nf) != (16.0, 20.0):
                rank(wc_best, ki, nf)
    mu = best_figure()
    if refine_window is not None and refine_window[0] <= mu < refine_window[1] and m > 1:
        wc, ki, nf = bests[-1][:3]
        for _ in range(JOINT_SWEEPS):
            before = best_figure()
            for j, f in itertools.product(range(m), JOINT_SCALES):
                scales = bests[-1][4]
                rank(wc, ki, nf, tuple(float(x * f) if i == j else x for i, x in enumerate(scales)))
            if best_figure() > 0.98 * before:
                break
        mu = best_figure()
    if not np.isfinite(mu):
        raise SynthesisError(
            f"no per-joint PID of crossover {min(crossovers):.3g}-{max(crossovers):.3g} rad/s stabilises the "
            "nominal loop: give --init FILE or no --init"
        )
    wc, ki, nf, mu, scales = bests[-1]
    return TunedPID(
        controller=_decoupled(pid_controller(pid_gains(wc * np.asarray(scales), ki, nf, b)), T),
        crossover=wc,
        integral_ratio=ki,
        filter_ratio=nf,
        input_gains=b,
        grid_mu=float(mu),
        tried=tuple(tried),
        joint_scales=tuple(scales),
        decoupling=T,
    )


def _smallest_bandwidth(P) -> float:
    """The smallest ``W_T`` bandwidth ``ω_BT`` of the generalized plant (the zeros of ``(s + ω_BT)/(A_T s + ω_BT M_T)``)."""
    W_T = getattr(P, "W_T", None)
    if W_T is not None:
        zeros = np.abs(np.concatenate([np.atleast_1d(control.ss(W_T[i, i]).zeros()) for i in range(W_T.ninputs)]))
        zeros = zeros[np.isfinite(zeros) & (zeros > 0)]
        if zeros.size:
            return float(zeros.min())
    raise SynthesisError("a PID start needs the generalized plant's W_T (its bandwidth places the crossover)")


def pid_start(
    P,
    *,
    target: float | None = None,
    only: bool = False,
    screen: float | None = None,
    certify_omega=None,
    decouple: bool = True,
):
    """``musyn``'s ``initial_controller="pid"``: ``(controller, words, result)``.

    ``result`` is ``None`` (D-K goes on from the tuned PID) unless the PID
    alone answers the call: ``only`` (``max_iter=1``: the start is the whole
    synthesis) or a ``target`` that the PID's certificate already meets
    (MATLAB's ``TargetPerf``: stop once the target is reached; checked on the
    certificate, not on a grid).  Then ``result`` is the
    :class:`~polyrob.synthesis.result.MusynResult` of the PID with that
    certificate and ``info["stopped_by"]`` says why no D-K step ran.
    ``screen`` (a search over weights): a :class:`SynthesisError` instead
    when the ranking's coarse-grid μ is already at least ``screen``.
    ``decouple``: :func:`tuned_pid`'s (``False`` for a fixed structure
    that holds no decoupling, such as ``"pid"``).
    """
    import time

    if isinstance(P, control.StateSpace):
        raise ArgumentError("initial_controller='pid' needs a GeneralizedPlant (its weights place the crossover)")
    t0 = time.perf_counter()
    tuned = tuned_pid(P, decouple=decouple)
    log.info(f"musyn: start from a {tuned.words()}, coarse-grid mu {tuned.grid_mu:.4f}")
    if screen is not None and tuned.grid_mu >= screen:
        # a search's screen (a heuristic: the factor counts as not reached, never as refuted)
        exc = SynthesisError(
            f"the best per-joint PID's coarse-grid mu upper bound {tuned.grid_mu:.4f} >= {screen:g}: "
            "its certificate was not computed (the search's screen)"
        )
        exc.figure = tuned.grid_mu  # the search's stop rule reads it (polyrob.synthesis.bandwidth)
        raise exc
    if (not only and target is None) or (not only and tuned.grid_mu >= target):
        return tuned.controller, tuned.words(), None  # D-K goes on: the ranking already exceeds the target
    from polyrob.analysis.certificate import certify_loop

    cert = certify_loop(P, tuned.controller, None, certify_omega, sweep_unstable=False)
    met = cert.certified and cert.bound < target if target is not None else False
    log.info(f"musyn: certificate of the PID start: {cert.status.value}, bound {cert.bound:.4g}")
    if not (only or met):
        return tuned.controller, tuned.words(), None
    why = f"the PID start's certificate, below the target {target:g}" if met else "max_iter=1: the start only"
    return tuned.controller, tuned.words(), start_result(tuned, cert, time.perf_counter() - t0, why)


def start_result(tuned: TunedPID, certificate, seconds: float, stopped_by: str):
    """The :class:`~polyrob.synthesis.result.MusynResult` of a tuned PID with its certificate (no D-K step)."""
    from polyrob.synthesis.result import MusynResult

    return MusynResult.certified(
        tuned.controller,
        "pid",
        certificate,
        mu_history=[tuned.grid_mu],
        seconds=seconds,
        info={
            "method": "tuned per-joint PID (no D-K step)",
            "start": tuned.words(),
            "stopped_by": stopped_by,
            "pid_gains": tuned.gains().tolist(),
            **({"decoupling": tuned.decoupling.tolist()} if tuned.decoupling is not None else {}),
            "ranking": [list(t) for t in tuned.tried],
        },
    )
