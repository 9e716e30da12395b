"""The figures of one run on the arm: tracking, settling, the task's bounds, torque chatter.

:func:`run_figures` reads a :class:`~polyrob.validate.at_rate.loop.RealLoopTrace`:

* **tracking error** ``|r - q|`` (the true position, not the reading): its
  largest value over the run and joints, and its value at the end;
* **settling**: each joint's band is :data:`SETTLING_BAND` of its move (at
  least a tenth of the largest move's band, and at least two encoder LSB);
  the settling time is when the last joint enters its band for good, and the
  run *settled* when that happens at least :data:`SETTLED_HOLD` s before its end;
* **the task's bounds**: the largest excursion of ``q`` out of the domain's
  box (rad, 0 inside), and the largest ``|qdot|`` and ``|qddot|`` (at any RK4
  substep) as fractions of the domain's bounds (``<= 1``: inside);
* **stuck joints**: a joint outside its band at the end whose error stayed
  within :data:`STUCK_PROGRESS` of itself over the last :data:`SETTLED_HOLD`
  s: held by friction (or a dead band) rather than converging or oscillating;
* **torque chatter**: after settling (or over the last half of the run after
  the reference stopped, when it never settled), the peak-to-peak of the
  applied torque minus its centred moving average over :data:`CHATTER_WINDOW`
  s, per joint, in N m and in percent of the effort limit.

Examples
--------
>>> t = np.arange(0, 1, 0.001)
>>> square = np.where((np.arange(1000) // 5) % 2 == 0, 1.0, -1.0)[None]   # +-1 N m at 100 Hz
>>> chatter_peak_to_peak(t, square, start=0.0).round(6).tolist()
[2.0]
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

__all__ = [
    "SETTLING_BAND",
    "SETTLED_HOLD",
    "CHATTER_WINDOW",
    "RunFigures",
    "chatter_peak_to_peak",
    "settling_time",
    "stuck_joints",
    "run_figures",
]

#: Band of the settling time (fraction of each joint's move).
SETTLING_BAND = 0.02
#: A run settled when it stays in its band for at least this long (s) before its end.
SETTLED_HOLD = 0.5
#: A joint outside its band whose error changed by less than this fraction of itself over the last
#: :data:`SETTLED_HOLD` s is stuck (not converging).
STUCK_PROGRESS = 0.1
#: Window (s) of the moving average the chatter is measured against: far longer than a sample, far shorter than the loop.
CHATTER_WINDOW = 0.05


def chatter_peak_to_peak(t, tau, *, start: float, window: float = CHATTER_WINDOW) -> np.ndarray:
    """Per joint, the peak-to-peak (N m) of ``tau - its centred moving average over window`` for ``t >= start``.

    The average's edges are dropped (``window / 2`` at each end of the segment), so no edge effect counts;
    a segment shorter than two windows gives NaN.
    """
    t, tau = np.asarray(t, float), np.atleast_2d(np.asarray(tau, float))
    h = float(t[1] - t[0]) if len(t) > 1 else 1.0
    n = max(1, int(round(window / h)))
    seg = tau[:, t >= start - 1e-12]
    if seg.shape[1] < 2 * n:
        return np.full(tau.shape[0], np.nan)
    kernel = np.ones(n) / n
    mean = np.array(
        [np.convolve(row, kernel, mode="valid") for row in seg]
    )  # centred on seg[:, n // 2 + i] (half a sample late when n is even)
    detrended = seg[:, n // 2 : n // 2 + mean.shape[1]] - mean
    return detrended.max(axis=1) - detrended.min(axis=1)


def settling_time(t, error, band) -> float:
    """When every joint's ``|error|`` enters its band for good (``t[0]``: always inside; NaN: never)."""
    outside = np.any(np.abs(error) > np.asarray(band, float)[:, None], axis=0)
    idx = np.flatnonzero(outside)
    if not idx.size:
        return float(t[0])
    if idx[-1] == len(t) - 1:
        return float("nan")
    return float(t[idx[-1] + 1])


def stuck_joints(t, error, band, *, hold: float = SETTLED_HOLD, progress: float = STUCK_PROGRESS) -> list:
    """Joints outside their band at the end whose error stayed within ``progress`` of ``|e_end|`` over ``hold`` s.

    >>> t = np.arange(0, 2, 0.001)
    >>> e = np.vstack([np.full(t.size, 0.1), 0.1 * np.exp(-t), np.zeros(t.size), 0.1 * np.cos(4 * np.pi * t)])
    >>> stuck_joints(t, e, [1e-3] * 4)   # held, converging, settled, oscillating (same value 0.5 s apart)
    [0]
    """
    t, error = np.asarray(t, float), np.atleast_2d(np.asarray(error, float))
    if len(t) < 2 or t[-1] - t[0] < hold:
        return []
    k = int(np.searchsorted(t, t[-1] - hold))
    end = np.abs(error[:, -1])
    outside = end > np.asarray(band, float)
    # held: the error stays within progress * |e_end| over the whole window (an oscillation is not held)
    held = np.ptp(error[:, k:], axis=1) < progress * end
    return [int(j) for j in np.flatnonzero(outside & held)]


@dataclass(frozen=True)
class RunFigures:
    """One run's figures (see the module's docstring); lists are per joint."""

    reference: str
    true_robot: str
    success: bool
    max_tracking_error: float
    final_tracking_error: float
    settling_time: float | None
    settled: bool
    stuck: list
    q_excess: float
    qdot_fraction: float | None
    qddot_fraction: float | None
    inside_task: bool
    chatter_peak_to_peak: list
    chatter_percent: list
    chatter_percent_max: float | None
    qddot_peak: list
    saturated_fraction: float
    evaluations: int
    message: str

    def to_dict(self) -> dict:
        """Plain JSON: a figure not measured (NaN: a joint without an effort limit, a run too short) is ``None``."""
        return {k: _plain(v) for k, v in asdict(self).items()}


def _plain(v):
    if isinstance(v, list):
        return [_plain(x) for x in v]
    return None if isinstance(v, float) and not np.isfinite(v) else v


def _fraction(peak, lower, upper) -> float | None:
    if lower is None or upper is None:
        return None
    bound = np.maximum(np.abs(np.asarray(lower, float)), np.abs(np.asarray(upper, float)))
    return float(np.max(peak / bound))


def run_figures(trace, domain, robot, *, reference: str, true_robot: str, move_end: float, lsb: float) -> RunFigures:
    """The figures of ``trace`` against ``domain`` (its q box, qdot and qddot bounds) and ``robot``'s effort limits.

    ``move_end``: when the reference stops moving (0 for a step); ``lsb``: the encoder's resolution (rad).
    """
    t, q = trace.t, trace.q
    err = trace.r - q
    move = np.abs(trace.r[:, -1] - q[:, 0])
    band = np.maximum(SETTLING_BAND * np.maximum(move, 0.1 * move.max(initial=0.0)), 2.0 * lsb)
    band = np.maximum(band, 1e-12)
    ts = settling_time(t, err, band) if len(t) else float("nan")
    t_end = float(t[-1]) if len(t) else 0.0
    settled = bool(trace.success and np.isfinite(ts) and ts <= t_end - SETTLED_HOLD)
    start = max(ts, move_end) if settled else max(move_end, move_end + 0.5 * (t_end - move_end))
    p2p = chatter_peak_to_peak(t, trace.tau_applied, start=start)
    limit = np.asarray(robot.effort_limit, float)
    pct = 100.0 * p2p / np.where(np.isfinite(limit) & (limit > 0), limit, np.nan)
    lo, hi = np.asarray(domain.q_lower, float), np.asarray(domain.q_upper, float)
    excess = float(max(0.0, np.max(lo[:, None] - q), np.max(q - hi[:, None]))) if len(t) else 0.0
    qdot_frac = _fraction(np.abs(trace.qdot).max(axis=1), domain.qdot_lower, domain.qdot_upper)
    qdd_lo, qdd_hi = getattr(domain, "qddot_lower", None), getattr(domain, "qddot_upper", None)
    qddot_frac = _fraction(np.asarray(trace.qddot_peak), qdd_lo, qdd_hi)
    # a run that stopped early (diverged) is not inside: its samples end before the task does
    inside = bool(trace.success and excess <= 1e-9 and (qdot_frac or 0.0) <= 1.0 and (qddot_frac or 0.0) <= 1.0)
    finite_pct = pct[np.isfinite(pct)]
    return RunFigures(
        reference=reference,
        true_robot=true_robot,
        success=bool(trace.success),
        max_tracking_error=float(np.abs(err).max()) if len(t) else float("nan"),
        final_tracking_error=float(np.abs(err[:, -1]).max()) if len(t) else float("nan"),
        settling_time=ts if np.isfinite(ts) else None,
        settled=settled,
        stuck=stuck_joints(t, err, band) if (len(t) and not settled and trace.success) else [],
        q_excess=excess,
        qdot_fraction=qdot_frac,
        qddot_fraction=qddot_frac,
        inside_task=inside,
        chatter_peak_to_peak=[float(v) for v in p2p],
        chatter_percent=[float(v) for v in pct],
        chatter_percent_max=float(finite_pct.max()) if finite_pct.size else None,
        qddot_peak=[float(v) for v in trace.qddot_peak],
        saturated_fraction=float(trace.info.get("saturated_fraction", 0.0)),
        evaluations=int(trace.info.get("evaluations", 0)),
        message=str(trace.info.get("message", "")),
    )
