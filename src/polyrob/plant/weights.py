"""Frequency weights for mixed-sensitivity and :math:`\\mu` synthesis.

* :func:`makeweight` is MATLAB's ``makeweight(dcgain, [freq, mag], hfgain)``
  (python-control has no equivalent), including the ``N``-th order
  Butterworth-pattern variant.
* :func:`sensitivity_weight` / :func:`complementary_weight` are the paper's
  parametrised :math:`W_S`, :math:`W_T`; :func:`paper_weights` gives its 2x2
  diagonal weights from :data:`PAPER_HYPERPARAMETERS`.
* :func:`diagonal_weight` stacks SISO weights into a diagonal MIMO weight.
* What limits a real loop (beside the paper's shape): :func:`encoder_noise_level`
  (the sensor-noise weight ``W_n`` from the encoder resolution),
  :func:`effort_level` (the control-effort weight ``W_u`` from the effort
  limit and the torque the task needs, per channel through the computed-torque
  layer: :func:`channel_budgets`) and :func:`limit_weight` (the
  ``W_KS = W_u W_n`` they make on the ``u`` channel); :func:`plant_weights`
  gives every weight of a hyperparameter dict.

Units: ``e``, ``y`` and the noise ``W_n n`` are joint positions [rad];
``u`` is the plant's input, a torque deviation [N m] (no inner layer,
gravity compensation) or the computed-torque layer's ``v`` [rad/s^2] whose
torque is ``M_hat(q) v``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import control
import numpy as np

from polyrob.errors import ArgumentError

__all__ = [
    "makeweight",
    "sensitivity_weight",
    "complementary_weight",
    "diagonal_weight",
    "paper_weights",
    "PAPER_HYPERPARAMETERS",
    "LIMIT_KEYS",
    "CHATTER_FRACTION",
    "DEFAULT_ENCODER_BITS",
    "encoder_lsb",
    "encoder_noise_level",
    "effort_level",
    "channel_budgets",
    "CHANNEL_FLOOR",
    "limit_weight",
    "plant_weights",
    "coulomb_weight",
]

#: Hyperparameters of the paper's weights, one entry per joint/output channel.
PAPER_HYPERPARAMETERS = {
    "omega_b": (0.5, 0.1),
    "M_s": (2.0, 3.0),
    "A_s": (1e-2, 2e-2),
    "omega_bt": (10.0, 12.0),
    "M_t": (2.1, 3.0),
    "A_t": (1e-2, 1e-2),
}


def _positive(name: str, value: float, allow_zero: bool = False) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError) as exc:
        raise ArgumentError(f"{name} must be a number, got {value!r}") from exc
    if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        kind = "non-negative" if allow_zero else "positive"
        raise ArgumentError(f"{name} must be a finite {kind} number, got {value!r}")
    return v


def makeweight(
    dcgain: float,
    crossover: float | Sequence[float],
    hfgain: float,
    *,
    order: int = 1,
) -> control.TransferFunction:
    """Monotonic weight through a given gain, like MATLAB's ``makeweight``.

    Builds a stable, minimum-phase continuous-time :math:`W(s)` with
    :math:`W(0) = ` ``dcgain``, :math:`W(\\infty) = ` ``hfgain`` and
    :math:`|W(j\\,\\mathrm{freq})| = ` ``mag``.

    Parameters
    ----------
    dcgain : float
        Low-frequency gain (>= 0).
    crossover : float or (freq, mag)
        ``(freq, mag)``, or just ``freq`` meaning ``mag = 1`` (the gain
        crossover frequency), in rad/s.
    hfgain : float
        High-frequency gain (>= 0).
    order : int, optional
        Order ``N``; for ``N > 1`` poles and zeros sit on Butterworth patterns
        (MATLAB's ``makeweight(..., Ts=0, N)``), giving a steeper transition.

    Returns
    -------
    control.TransferFunction

    Raises
    ------
    PolyrobError
        Non-positive inputs, or ``mag`` not strictly between ``dcgain`` and
        ``hfgain``.

    Notes
    -----
    With :math:`p_k` the unit Butterworth poles of order :math:`N`,
    :math:`W(s) = h \\prod_k (s - \\omega_z p_k)/(s - \\omega_p p_k)`, so
    :math:`|W(j\\omega)|^2 = (h^2\\omega_z^{2N} + h^2\\omega^{2N})/(\\omega_p^{2N}
    + \\omega^{2N})`.  The three constraints then give
    :math:`\\omega_p = \\omega_0 ((h^2 - m^2)/(m^2 - d^2))^{1/2N}` and
    :math:`\\omega_z = \\omega_p (d/h)^{1/N}`.  For :math:`N = 1` this is
    :math:`W(s) = (h s + d\\,\\omega_p)/(s + \\omega_p)`.

    Examples
    --------
    The MATLAB Answers example ``makeweight(100, 10, 0.1)``:

    >>> from polyrob.plant.weights import makeweight
    >>> W = makeweight(100, 10, 0.1)
    >>> W.num[0][0].round(4).tolist(), W.den[0][0].round(4).tolist()
    ([0.1, 9.9504], [1.0, 0.0995])
    >>> print(round(float(abs(W(10j))), 12))
    1.0
    """
    if isinstance(crossover, (tuple, list, np.ndarray)):
        if len(crossover) != 2:
            raise ArgumentError(f"crossover must be freq or (freq, mag), got {crossover!r}")
        freq, mag = crossover
    else:
        freq, mag = crossover, 1.0
    dc = _positive("dcgain", dcgain, allow_zero=True)
    hf = _positive("hfgain", hfgain, allow_zero=True)
    freq = _positive("crossover frequency", freq)
    mag = _positive("crossover magnitude", mag)
    if int(order) != order or order < 1:
        raise ArgumentError(f"order must be a positive integer, got {order!r}")
    n = int(order)
    if not (dc < mag < hf or dc > mag > hf):
        raise ArgumentError(
            f"makeweight needs mag strictly between dcgain and hfgain (got dcgain={dc}, mag={mag}, hfgain={hf})"
        )
    wp = freq * ((hf**2 - mag**2) / (mag**2 - dc**2)) ** (1.0 / (2 * n))
    k = np.arange(1, n + 1)
    bw = np.exp(1j * np.pi * (2 * k + n - 1) / (2 * n))  # unit Butterworth poles
    den = np.real(np.poly(wp * bw))
    if hf > 0:
        wz = wp * (dc / hf) ** (1.0 / n)
        num = hf * np.real(np.poly(wz * bw))
    else:  # hfgain = 0: zeros at infinity, W(0) = dc
        num = np.array([dc * wp**n])
    return control.tf(num, den)


def sensitivity_weight(omega_b: float, M_s: float, A_s: float) -> control.TransferFunction:
    """Performance weight :math:`W_S(s) = (s/M_S + \\omega_B)/(s + \\omega_B A_S)`.

    :math:`1/|W_S|` bounds the sensitivity: at most ``A_s`` at low
    frequency, crossing one near ``omega_b``, at most ``M_s`` at high frequency.

    Examples
    --------
    >>> from polyrob.plant.weights import sensitivity_weight
    >>> W = sensitivity_weight(0.5, 2, 1e-2)
    >>> W.num[0][0].tolist(), W.den[0][0].tolist()
    ([0.5, 0.5], [1.0, 0.005])
    """
    wb = _positive("omega_b", omega_b)
    ms = _positive("M_s", M_s)
    a = _positive("A_s", A_s)
    return control.tf([1.0 / ms, wb], [1.0, wb * a])


def complementary_weight(omega_bt: float, M_t: float, A_t: float) -> control.TransferFunction:
    """Robustness weight :math:`W_T(s) = (s + \\omega_{BT})/(A_T s + \\omega_{BT} M_T)`.

    :math:`1/|W_T|` bounds the complementary sensitivity: at most ``M_t`` at
    low frequency, rolling off past ``omega_bt`` down to ``A_t``.

    Examples
    --------
    >>> from polyrob.plant.weights import complementary_weight
    >>> W = complementary_weight(10, 2.1, 1e-2)
    >>> W.num[0][0].tolist(), W.den[0][0].tolist()
    ([1.0, 10.0], [0.01, 21.0])
    """
    wbt = _positive("omega_bt", omega_bt)
    mt = _positive("M_t", M_t)
    a = _positive("A_t", A_t)
    return control.tf([1.0, wbt], [a, wbt * mt])


def diagonal_weight(weights: Sequence) -> control.TransferFunction:
    """Diagonal MIMO weight :math:`\\operatorname{diag}(W_1, \\ldots, W_n)`.

    Parameters
    ----------
    weights : sequence of SISO LTI systems or numbers
        Numbers are static gains.  State-space entries are converted to
        transfer functions.

    Returns
    -------
    control.TransferFunction
        ``n x n``, off-diagonal entries zero; the diagonal coefficients are
        exactly those of the inputs (use ``control.ss`` for a realisation).

    Examples
    --------
    >>> from polyrob.plant.weights import diagonal_weight
    >>> W = diagonal_weight([control.tf([1], [1, 1]), 2.0])
    >>> W.noutputs, W.ninputs, float(W(0)[1, 1].real)
    (2, 2, 2.0)
    """
    if len(weights) == 0:
        raise ArgumentError("diagonal_weight needs at least one weight")
    tfs = []
    for i, w in enumerate(weights):
        if isinstance(w, (int, float, np.floating, np.integer)):
            w = control.tf([float(w)], [1.0])
        elif isinstance(w, control.LTI):
            if (w.noutputs, w.ninputs) != (1, 1):
                raise ArgumentError(f"weight {i} is {w.noutputs}x{w.ninputs}, expected SISO")
            w = control.tf(w)
        else:
            raise ArgumentError(f"weight {i} must be a SISO LTI system or a number, got {type(w).__name__}")
        tfs.append(w)
    n = len(tfs)
    num = [[tfs[i].num[0][0] if i == j else np.array([0.0]) for j in range(n)] for i in range(n)]
    den = [[tfs[i].den[0][0] if i == j else np.array([1.0]) for j in range(n)] for i in range(n)]
    return control.tf(num, den)


def paper_weights(
    hyperparameters: dict | None = None,
) -> tuple[control.TransferFunction, control.TransferFunction]:
    """The paper's diagonal :math:`W_S` and :math:`W_T`.

    Parameters
    ----------
    hyperparameters : dict, optional
        Keys as in :data:`PAPER_HYPERPARAMETERS` (the default), each a tuple
        with one value per channel.

    Returns
    -------
    (W_S, W_T) : tuple of control.TransferFunction

    Examples
    --------
    >>> from polyrob.plant.weights import paper_weights
    >>> WS, WT = paper_weights()
    >>> WS.num[1][1].round(4).tolist(), WT.den[1][1].tolist()
    ([0.3333, 0.1], [0.01, 36.0])
    """
    h = dict(PAPER_HYPERPARAMETERS if hyperparameters is None else hyperparameters)
    keys = ("omega_b", "M_s", "A_s", "omega_bt", "M_t", "A_t")
    missing = [k for k in keys if k not in h]
    if missing:
        raise ArgumentError(f"missing weight hyperparameters: {missing}")
    n = {len(h[k]) for k in keys}
    if len(n) != 1:
        raise ArgumentError(f"weight hyperparameters must all have the same length, got {n}")
    ws = [sensitivity_weight(*p) for p in zip(h["omega_b"], h["M_s"], h["A_s"])]
    wt = [complementary_weight(*p) for p in zip(h["omega_bt"], h["M_t"], h["A_t"])]
    return diagonal_weight(ws), diagonal_weight(wt)


# --------------------------------------------------------------------------- what limits a real loop

#: Hyperparameters of the limit weights (optional): ``effort`` is ``W_u`` per joint [1/(u's unit)],
#: ``noise`` is ``W_n`` per joint [rad]; absent, the plant has the paper's W_S and W_T only.
LIMIT_KEYS = ("effort", "noise")
#: The encoder noise may drive at most this fraction of a joint's effort limit, peak to peak.
CHATTER_FRACTION = 0.05
#: Encoder resolution assumed when none is given (bits per revolution; ``--encoder-bits``).
DEFAULT_ENCODER_BITS = 18


def encoder_lsb(bits: float) -> float:
    """One count of a ``bits``-bit absolute encoder: ``2 pi / 2**bits`` [rad].

    Examples
    --------
    >>> from polyrob.plant.weights import encoder_lsb
    >>> f"{encoder_lsb(18):.4e}"
    '2.3968e-05'
    """
    b = _positive("encoder bits", bits)
    if int(b) != b or not 1 <= b <= 64:
        raise ArgumentError(f"encoder bits must be a whole number from 1 to 64, got {bits!r}")
    return 2.0 * math.pi / 2.0 ** int(b)


def encoder_noise_level(bits: float) -> float:
    """``W_n`` of a ``bits``-bit encoder: the largest quantisation error, half a count [rad].

    Rounding to the nearest count errs by at most ``LSB/2``, so a unit noise
    input ``|n| <= 1`` through ``W_n = LSB/2`` spans every error the encoder
    makes (peak to peak one LSB).

    Examples
    --------
    >>> from polyrob.plant.weights import encoder_noise_level
    >>> f"{encoder_noise_level(18):.4e}"
    '1.1984e-05'
    """
    return 0.5 * encoder_lsb(bits)


def effort_level(effort_limit, task_torque, inertia_bound=None, *, fraction: float = CHATTER_FRACTION) -> np.ndarray:
    """``W_u`` per joint: one over the torque amplitude the noise may drive, through ``u``.

    The noise-driven torque of joint ``j`` may swing by ``fraction`` of its
    effort limit peak to peak, and never past what the task leaves::

        a_j = min(fraction * tau_max_j / 2,  tau_max_j - tau_task_j)    [N m, amplitude]

    Without ``inertia_bound`` ``u`` is the torque deviation and ``W_u = diag(1/a_j)``.

    With it, ``u`` is the computed-torque layer's ``v`` (torque ``= M_hat(q) v``)
    and ``N_ji >= |M_hat(q)_ji|`` over the domain.  ``W_u = diag(1/c_i)``
    bounds ``||diag(1/c) v|| <= 1``, so by Cauchy-Schwarz
    ``|tau_j| <= sum_i N_ji c_i |v_i / c_i| <= ||N_j o c|| <= a_j`` whenever
    every row satisfies ``||N_j o c|| <= a_j`` (for signals too, row by row,
    with ``M_hat`` moving with ``q``).  One ``c`` on every channel gives
    ``c_u = min_j a_j / ||N_j||``: the heavy joints' rows then set the budget
    of a wrist channel whose ``v`` hardly moves them.  So the channels share
    the rows' budgets: ``c`` maximises ``sum_i log c_i`` (the volume of the
    ``v`` box the noise may drive) with every ``c_i >= CHANNEL_FLOOR * c_u``
    (no channel much tighter than the uniform budget), a convex program
    (cvxpy), re-checked in floats and scaled down when a row is over.

    Parameters
    ----------
    effort_limit : sequence of float
        ``tau_max`` per joint [N m] (the URDF's effort limits).
    task_torque : sequence of float
        The largest ``|tau|`` the task needs per joint [N m].
    inertia_bound : (m, m) array_like, optional
        ``N_ji >= |M_hat(q)_ji|`` [N m per rad/s^2] when ``u`` is the computed-torque input ``v``.
    fraction : float
        Peak-to-peak share of the effort limit (default :data:`CHATTER_FRACTION`).

    Returns
    -------
    ndarray
        ``W_u`` per joint, in 1/N m (torque input) or s^2/rad (``v``).

    Raises
    ------
    ArgumentError
        A limit that is not positive and finite, or a task that needs the
        whole effort limit of a joint (no torque is left for feedback).
    SolverError
        The channels' convex program was not solved.

    Examples
    --------
    >>> from polyrob.plant.weights import effort_level
    >>> effort_level([150.0, 28.0], [20.0, 27.5]).round(4).tolist()   # 3.75 N m; 0.5 N m left on joint 2
    [0.2667, 2.0]

    A shoulder and a wrist, ``N = [[3, 0.01], [0.01, 0.1]]``: one weight on
    both channels would be the shoulder's ``3/3.75 = 0.8``; the wrist's ``v``
    moves the shoulder by 0.01 N m per rad/s^2 only, so its channel gets its
    own row's room, ``0.1/0.7``:

    >>> effort_level([150.0, 28.0], [20.0, 5.0], [[3.0, 0.01], [0.01, 0.1]]).round(3).tolist()
    [0.8, 0.143]
    """
    tau_max = np.asarray(effort_limit, float).ravel()
    tau_task = np.abs(np.asarray(task_torque, float).ravel())
    frac = _positive("fraction", fraction)
    if tau_max.shape != tau_task.shape or tau_max.size == 0:
        raise ArgumentError(
            f"effort limits and task torques need one value per joint, got {tau_max.size}, {tau_task.size}"
        )
    if not np.all(np.isfinite(tau_max) & (tau_max > 0)):
        raise ArgumentError(f"effort limits must be finite and > 0 (the URDF's <limit effort>), got {tau_max.tolist()}")
    left = tau_max - tau_task
    if np.any(left <= 0):
        j = int(np.argmin(left))
        raise ArgumentError(
            f"the task needs {tau_task[j]:.4g} N m on joint {j}, its effort limit is {tau_max[j]:.4g} N m: "
            "no torque is left for feedback; give a smaller task (--qddot-max, --qdot-max, --q-range)"
        )
    amplitude = np.minimum(0.5 * frac * tau_max, left)
    if inertia_bound is None:
        return 1.0 / amplitude
    N = np.abs(np.asarray(inertia_bound, float))
    m = tau_max.size
    if N.shape != (m, m) or not np.all(np.isfinite(N)) or np.any(np.diag(N) <= 0):
        raise ArgumentError(
            f"inertia_bound needs an ({m}, {m}) bound of |M_hat| with a positive diagonal, got shape {N.shape}"
        )
    return 1.0 / channel_budgets(amplitude, N)


#: Each ``v`` channel's budget is at least this share of the uniform one (:func:`effort_level`).
CHANNEL_FLOOR = 0.99


def channel_budgets(amplitude, inertia_bound) -> np.ndarray:
    """The ``v`` channels' amplitudes ``c`` with ``||N_j o c|| <= a_j`` on every row (see :func:`effort_level`).

    Re-checked in floats: a row over its budget scales ``c`` down, so the
    result satisfies every row whatever the solver returned.

    Examples
    --------
    >>> from polyrob.plant.weights import channel_budgets
    >>> channel_budgets([1.0, 1.0], [[1.0, 0.0], [0.0, 0.5]]).round(6).tolist()   # uncoupled: a_j / N_jj
    [1.0, 2.0]
    """
    import cvxpy as cp

    from polyrob.errors import SolverError

    a = np.asarray(amplitude, float).ravel()
    N = np.asarray(inertia_bound, float)
    uniform = float(np.min(a / np.linalg.norm(N, axis=1)))
    # cvxpy: maximise the product of the budgets, a small exponential-cone program; the rows' scale is 1
    c = cp.Variable(a.size, pos=True)
    rows = [cp.norm(cp.multiply(N[j] / a[j], c)) <= 1.0 for j in range(a.size)]
    problem = cp.Problem(cp.Maximize(cp.sum(cp.log(c / uniform))), rows + [c >= CHANNEL_FLOOR * uniform])
    try:
        problem.solve(solver="CLARABEL")
    except cp.error.SolverError as exc:
        raise SolverError(f"the effort weights' channel budgets: {exc}") from exc
    if c.value is None or problem.status not in ("optimal", "optimal_inaccurate"):
        raise SolverError(f"the effort weights' channel budgets: the solver ended {problem.status}")
    budget = np.maximum(np.asarray(c.value, float), CHANNEL_FLOOR * uniform)
    over = float(np.max(np.linalg.norm(N * budget, axis=1) / a))
    return budget / max(over, 1.0) if over > 1.0 else budget


def limit_weight(hyperparameters: dict):
    """``W_KS = W_u W_n`` of the limit hyperparameters, or ``None`` without them.

    The noise ``n`` enters the measurement as ``e = r - q - W_n n``, at the same
    point as the reference, so ``n -> u`` is ``-K S W_n`` (``K S`` is the map
    ``r -> u``).  With one noise level ``w_n`` on every joint (``W_n = w_n I``,
    the largest when they differ, which only enlarges the weight)
    ``||W_u K S W_n|| = ||(w_n W_u) K S||``: the weight ``W_KS = w_n W_u`` on
    ``u`` bounds exactly the noise-driven effort, with ``r`` standing in for
    ``n`` (:func:`polyrob.plant.generalized.generalized_plant` also builds
    the separate input ``n``).

    Examples
    --------
    >>> from polyrob.plant.weights import limit_weight
    >>> limit_weight({"effort": (2.0, 4.0), "noise": (1e-5, 2e-5)}).tolist()
    [[4e-05, 0.0], [0.0, 8e-05]]
    >>> limit_weight({"omega_b": (1.0,)}) is None
    True
    """
    if "effort" not in hyperparameters and "noise" not in hyperparameters:
        return None
    missing = [k for k in LIMIT_KEYS if k not in hyperparameters]
    if missing:
        raise ArgumentError(f"the limit weights need both {list(LIMIT_KEYS)}, missing {missing}")
    effort = np.array([_positive("effort weight", v) for v in hyperparameters["effort"]])
    noise = max(_positive("noise weight", v) for v in hyperparameters["noise"])
    return np.diag(effort * noise)


def plant_weights(hyperparameters: dict | None = None) -> dict:
    """Every weight of ``hyperparameters``: ``{"W_S", "W_T", "W_KS"}`` for :func:`generalized_plant`.

    ``W_KS`` is :func:`limit_weight` (``None`` without the limit keys: the paper's problem).

    Examples
    --------
    >>> from polyrob.plant.weights import plant_weights
    >>> w = plant_weights()
    >>> sorted(w), w["W_KS"] is None
    (['W_KS', 'W_S', 'W_T'], True)
    """
    h = dict(PAPER_HYPERPARAMETERS if hyperparameters is None else hyperparameters)
    W_S, W_T = paper_weights(h)
    return {"W_S": W_S, "W_T": W_T, "W_KS": limit_weight(h)}


def coulomb_weight(levels, inverse_inertia=None, *, model_error: float = 0.0) -> np.ndarray:
    """``W_f``: the Coulomb torque ``|d_j| <= F_c,j`` as the diagonal gain of a disturbance ``|f_i| <= 1`` at ``u``.

    Without ``inverse_inertia`` ``u`` is the torque and ``W_f = diag(F_c)``
    [N m]: exact.  Behind the computed-torque layer (``tau = M_hat v + h_hat``)
    the robot ``M qddot + h = tau + d`` moves as ``qddot = v + M^-1 d`` when
    ``M = M_hat`` (the rest, ``(M^-1 M_hat - I) v`` and ``M^-1 (h_hat - h)``,
    is the model error the uncertainty model carries).  So the outer loop
    sees ``a = v + M_hat^-1 d`` to first order, and with ``inverse_inertia``
    the elementwise bound ``N_ij >= |M_hat^-1(q)_ij|`` over the domain
    ``|(M_hat^-1 d)_i| <= sum_j N_ij F_c,j``: ``W_f = diag(N F_c) / (1 - p)``
    [rad/s^2], the factor ``1/(1 - p)`` for a true inertia within a relative
    ``p`` (``model_error``) of the model's (``M^-1 = M_hat^-1 (I + E)^-1``,
    ``||E|| <= p``; an approximation: ``E`` is bounded in norm, not per entry).

    Parameters
    ----------
    levels : sequence of float
        ``F_c`` per joint [N m] (>= 0).
    inverse_inertia : (m, m) array_like, optional
        ``N``, e.g. :func:`polyrob.fleet.autoweights.inverse_inertia_bound`.
    model_error : float
        ``p`` in ``[0, 1)``.

    Returns
    -------
    ndarray
        ``(m, m)`` diagonal.

    Examples
    --------
    >>> from polyrob.plant.weights import coulomb_weight
    >>> coulomb_weight([2.0, 1.0]).tolist()
    [[2.0, 0.0], [0.0, 1.0]]
    >>> coulomb_weight([2.0, 2.0], [[4.0, 1.0], [1.0, 10.0]]).diagonal().tolist()   # 4*2 + 1*2, 1*2 + 10*2
    [10.0, 22.0]
    """
    fc = np.asarray(levels, float).ravel()
    if fc.size == 0 or not np.all(np.isfinite(fc) & (fc >= 0)):
        raise ArgumentError(f"--coulomb: give Coulomb levels >= 0 N m, got {fc.tolist()}")
    p = float(model_error)
    if not 0.0 <= p < 1.0:
        raise ArgumentError(f"the model error must be in [0, 1), got {model_error!r}")
    if inverse_inertia is None:
        return np.diag(fc)
    N = np.abs(np.asarray(inverse_inertia, float))
    if N.shape != (fc.size, fc.size) or not np.all(np.isfinite(N)):
        raise ArgumentError(f"inverse_inertia must be a finite {fc.size}x{fc.size} matrix, got shape {N.shape}")
    return np.diag(N @ fc / (1.0 - p))
