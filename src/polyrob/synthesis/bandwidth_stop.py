"""Where the bandwidth search stops, and why: the sample rate's cap on the crossover, the bound μ rests on.

:func:`crossover_cap` is the rate rule (the hold and the computation delay's
phase lag at the crossover); :func:`loop_crossover` the nominal loop's
crossover; :func:`bound_hit` the words of
:attr:`polyrob.synthesis.bandwidth.BandwidthScalingResult.bound_hit`: the
sample rate, or the weighted channel μ rests on at the first factor that
did not certify (:mod:`polyrob.synthesis.channel_mu`).
:func:`channel_peaks` and :func:`binding_bound` are the cheaper
nominal-peak rule (a hint).
"""

from __future__ import annotations

import math

import numpy as np

from polyrob.errors import ArgumentError
from polyrob.synthesis.channel_mu import CHANNEL_NAMES, channel_mu, channel_words

__all__ = [
    "RATE_PHASE_BUDGET",
    "DEFAULT_RATE",
    "CHANNEL_NAMES",
    "crossover_cap",
    "loop_crossover",
    "channel_peaks",
    "binding_bound",
    "bound_hit",
    "is_plant",
]

#: Phase lag [rad] the hold and the computation delay may add at the loop's crossover (8.6 degrees).
RATE_PHASE_BUDGET = 0.15
#: Sample rate [Hz] and delay [samples] assumed when the options give none.
DEFAULT_RATE = (1000.0, 1.0)
#: Frequencies [rad/s] of the nominal channel peaks and the crossover (a diagnosis on a grid, not a bound).
_GRID = np.logspace(-3, 6, 901)


def crossover_cap(rate: float = DEFAULT_RATE[0], delay_samples: float = DEFAULT_RATE[1]) -> float:
    """The largest crossover [rad/s] a loop sampled at ``rate`` Hz with ``delay_samples`` of delay may have.

    A zero-order hold lags like half a sample, the computation delay like
    ``delay_samples``: at the crossover ``w_c`` they cost the phase
    ``(delay_samples + 1/2) w_c / rate``, which the continuous-time
    certificate does not see.  The rule keeps it within
    :data:`RATE_PHASE_BUDGET` (0.15 rad, 8.6 degrees)::

        w_c <= 0.15 rate / (delay_samples + 1/2)      (100 rad/s at 1 kHz, one sample)

    A design rule, not a sampled-data certificate.

    Examples
    --------
    >>> from polyrob.synthesis.bandwidth_stop import crossover_cap
    >>> round(crossover_cap(), 6), round(crossover_cap(500.0), 6), round(crossover_cap(1000.0, 0.0), 6)
    (100.0, 50.0, 300.0)
    """
    f = float(rate)
    d = float(delay_samples)
    if not (math.isfinite(f) and f > 0):
        raise ArgumentError(f"the sample rate must be a finite number of Hz > 0, got {rate!r}")
    if not (math.isfinite(d) and d >= 0):
        raise ArgumentError(f"the delay must be a finite number of samples >= 0, got {delay_samples!r}")
    return RATE_PHASE_BUDGET * f / (d + 0.5)


def _loop_responses(P, controller, omega):
    """``(G, K)`` frequency responses (N, m, m) of the nominal plant and the controller."""
    from polyrob.analysis.mu.frequency import freqresp
    from polyrob.controller import as_controller_ss

    unc = P.uncertain
    G = freqresp(unc.nominal_system(), omega)
    K = freqresp(as_controller_ss(controller, unc.m, unc.m), omega)
    return G, K


def loop_crossover(P, controller, omega=None) -> float:
    """The largest gain crossover [rad/s] of the nominal loop ``L = G K``: ``max w`` with ``sigma_max(L(jw)) >= 1``.

    Found on a grid (1e-3 to 1e6 rad/s) and refined by bisection between
    its points; ``0`` when the loop gain never reaches 1, ``inf`` when it
    still does at the grid's end.
    """
    w = _GRID if omega is None else np.asarray(omega, float)
    G, K = _loop_responses(P, controller, w)
    gain = np.linalg.norm(G @ K, ord=2, axis=(1, 2))
    above = np.nonzero(gain >= 1.0)[0]
    if above.size == 0:
        return 0.0
    k = int(above[-1])
    if k == w.size - 1:
        return math.inf
    lo, hi = float(w[k]), float(w[k + 1])
    for _ in range(40):
        mid = math.sqrt(lo * hi)
        Gm, Km = _loop_responses(P, controller, np.array([mid]))
        if np.linalg.norm(Gm[0] @ Km[0], 2) >= 1.0:
            lo = mid
        else:
            hi = mid
    return lo


def channel_peaks(P, controller, omega=None) -> dict:
    """``label -> (peak, frequency)`` of each weighted channel of ``P`` on the nominal loop (a grid value).

    ``W_S S``, ``W_T T`` and ``W_KS K S`` of the loop ``u = K (r - y)``
    around the nominal plant, ``sigma_max`` maximised over the grid: which
    channel is nearest its bound, not a certificate.
    """
    from polyrob.analysis.mu.frequency import freqresp

    w = _GRID if omega is None else np.asarray(omega, float)
    G, K = _loop_responses(P, controller, w)
    m = G.shape[1]
    S = np.linalg.inv(np.eye(m)[None] + G @ K)
    loops = {"W_S e": S, "W_T y": G @ K @ S, "W_KS u": K @ S}
    weights = {"W_S e": P.W_S, "W_T y": P.W_T, "W_KS u": P.W_KS}
    out = {}
    for label, H in loops.items():
        if weights[label] is None:
            continue
        sv = np.linalg.norm(freqresp(weights[label], w) @ H, ord=2, axis=(1, 2))
        i = int(np.argmax(sv))
        out[label] = (float(sv[i]), float(w[i]))
    return out


def binding_bound(P, controller, names: dict | None = None) -> str:
    """The weighted channel of ``P`` nearest its bound with ``controller``, in words (:func:`channel_peaks`).

    ``names`` maps the labels of ``P.z_labels`` to words (default :data:`CHANNEL_NAMES`).
    """
    peaks = channel_peaks(P, controller)
    if not peaks:
        return "no weighted channel"
    label = max(peaks, key=lambda k: peaks[k][0])
    peak, where = peaks[label]
    others = ", ".join(f"{lab} {p:.3g}" for lab, (p, _) in peaks.items() if lab != label)
    return (
        f"{(names or CHANNEL_NAMES).get(label, label)}: nominal peak {peak:.3g} at {where:.3g} rad/s "
        f"(grid; {others or 'no other channel'})"
    )


def is_plant(P) -> bool:
    """A generalized plant (stand-ins of the tests are not: no loop to diagnose)."""
    return hasattr(P, "uncertain") and hasattr(P, "W_KS")


def bound_hit(fail, solved, plants, crossovers, cap, ok, names, stopped, excluded) -> str:
    """Which bound stops the search at ``fail`` (the first factor above ``ok`` that did not certify)."""
    if fail is None:
        return "none within the scan: its largest factor certifies (larger ones were not tried)"
    if stopped and fail not in solved:
        return f"not found: {stopped}"
    if any(a == fail for a, _ in excluded):
        return "the performance limit of the robot's unstable poles (no controller certifies there)"
    wc = crossovers.get(fail)
    if cap is not None and wc is not None and wc > cap:
        return (
            f"sample rate: at alpha = {fail:.4g} the certified loop crosses over at {wc:.4g} rad/s, above "
            f"{cap:.4g} rad/s (the hold and delay's phase lag within {RATE_PHASE_BUDGET} rad)"
        )
    res_fail = solved.get(fail, (None,))[0]
    if res_fail is not None and getattr(res_fail, "controller", None) is not None and is_plant(plants.get(fail)):
        return f"at alpha = {fail:.4g}: " + channel_words(channel_mu(plants[fail], res_fail.controller), names)
    res_ok = solved[ok][0]
    if res_ok is not None and getattr(res_ok, "controller", None) is not None and is_plant(plants.get(fail)):
        # no controller at the failing factor: the certified one of alpha = ok on the failing factor's weights
        return (
            f"alpha = {fail:.4g} failed to synthesise; alpha = {ok:.4g}'s controller on its weights: "
            + channel_words(channel_mu(plants[fail], res_ok.controller), names)
        )
    return f"alpha = {fail:.4g} does not certify"
