"""Discretisation of the controller and μ of the discretised loop.

:func:`discretize` maps a continuous controller to discrete time at a sample
rate: Tustin (bilinear) with optional pre-warping at a frequency ``ω_p``
(the discrete response then equals the continuous one exactly at ``ω_p``),
or zero-order hold; both through ``control.sample_system``.

:func:`sampled_data_mu` closes the discretised controller around the
generalized plant discretised by zero-order hold (the plant sees a held
``u``; ``d`` and ``w`` are held too, which is the approximation of this
check) and computes closed-loop stability (poles inside the unit circle)
and μ bounds over the unit circle (:func:`polyrob.analysis.mu.bounds.mu_bounds`
with ``z = e^{jωh}``, ``ω`` up to the Nyquist frequency).  This is a design
check of the sample rate, not a certificate of the sampled-data system:
inter-sample behaviour is not covered (see docs/method.md).

:func:`min_sample_rate` bisects (in log rate) for the lowest rate whose
discretised-loop μ stays below the continuous value times ``1 + tolerance``.

Examples
--------
>>> import control
>>> from polyrob.validate.discretize import discretize
>>> Kd = discretize(control.tf([10.0], [1.0, 10.0]), 100.0, method="tustin", prewarp=10.0)
>>> Kd.dt, Kd.method
(0.01, 'tustin')
>>> round(abs(complex(Kd.system(complex(__import__("numpy").exp(1j * 10.0 * 0.01))))), 12)  # |K(j10)| kept
0.707106781187
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import control
import numpy as np

from polyrob.analysis.mu.frequency import freqresp
from polyrob.controller import Controller, as_controller_ss
from polyrob.errors import ArgumentError
from polyrob.plant.loops import lft, lower_lft

__all__ = [
    "DiscreteController",
    "SampledDataResult",
    "MinRateResult",
    "discretize",
    "discrete_lft",
    "sampled_data_mu",
    "min_sample_rate",
    "crossover_frequency",
]

METHODS = ("tustin", "zoh")


@dataclass(frozen=True, eq=False)
class DiscreteController:
    """A discrete-time controller ``x[k+1] = A x[k] + B e[k]``, ``u[k] = C x[k] + D e[k]``.

    Attributes
    ----------
    system : control.StateSpace
        Discrete-time, ``dt = 1/rate``.
    rate : float
        Sample rate, Hz.
    method : {"tustin", "zoh"}
    prewarp : float or None
        Pre-warping frequency (rad/s) of the Tustin map.
    continuous : control.StateSpace
        The controller it was made from.
    """

    system: control.StateSpace
    rate: float
    method: str
    prewarp: float | None
    continuous: control.StateSpace

    @property
    def dt(self) -> float:
        return 1.0 / self.rate

    def step_response(self, n: int) -> np.ndarray:
        """Outputs for a unit step on each input: ``(n_out, n_in, n)`` (``[i, j, k]``)."""
        A, B, C, D = (np.asarray(X, float) for X in (self.system.A, self.system.B, self.system.C, self.system.D))
        out = np.zeros((C.shape[0], B.shape[1], n))
        for j in range(B.shape[1]):
            x = np.zeros(A.shape[0])
            for k in range(n):
                out[:, j, k] = C @ x + D[:, j]
                x = A @ x + B[:, j]
        return out

    def to_dict(self) -> dict:
        return {
            "format": "polyrob.discrete_controller/1",
            "rate_hz": self.rate,
            "method": self.method,
            "prewarp_rad_s": self.prewarp,
            **{k: np.asarray(getattr(self.system, k), float).tolist() for k in "ABCD"},
        }


def discretize(K, rate: float, *, method: str = "tustin", prewarp: float | None = None) -> DiscreteController:
    """The controller at ``rate`` Hz: Tustin (pre-warped at ``prewarp`` rad/s) or ZOH.

    Parameters
    ----------
    K : LTI system or array
        Continuous-time, ``n_u x n_y``.
    rate : float
        Sample rate, Hz (> 0).
    method : {"tustin", "zoh"}
    prewarp : float, optional
        Tustin pre-warping frequency in rad/s, below the Nyquist frequency
        ``π rate``; ``None`` for the plain bilinear map.
    """
    if method not in METHODS:
        raise ArgumentError(f"unknown discretisation '{method}': use one of {', '.join(METHODS)}")
    rate = float(rate)
    if not (math.isfinite(rate) and rate > 0):
        raise ArgumentError(f"the sample rate must be a positive number of Hz, got {rate}")
    if isinstance(K, control.LTI) and getattr(K, "dt", 0) not in (0, None):
        raise ArgumentError("the controller is already discrete-time")
    Ks = Controller.of(K).system
    h = 1.0 / rate
    if prewarp is not None:
        prewarp = float(prewarp)
        if method != "tustin":
            raise ArgumentError("pre-warping applies to the Tustin method only")
        if not (0 < prewarp < math.pi * rate):
            raise ArgumentError(f"the pre-warping frequency must lie in (0, π·rate) = (0, {math.pi * rate:.4g}) rad/s")
    if Ks.nstates == 0:
        Kd = control.ss(np.zeros((0, 0)), np.zeros((0, Ks.ninputs)), np.zeros((Ks.noutputs, 0)), Ks.D, dt=h)
    elif method == "tustin":
        Kd = control.sample_system(Ks, h, method="bilinear", prewarp_frequency=prewarp)
    else:
        Kd = control.sample_system(Ks, h, method="zoh")
    return DiscreteController(system=Kd, rate=rate, method=method, prewarp=prewarp, continuous=Ks)


def discrete_lft(Pd: control.StateSpace, Kd: control.StateSpace, n_u: int, n_y: int) -> control.StateSpace:
    """Lower LFT of a discrete plant and controller of the same ``dt`` (:func:`~polyrob.plant.loops.lower_lft`)."""
    if not np.isclose(float(Pd.dt), float(Kd.dt)):
        raise ArgumentError(f"plant dt = {Pd.dt} and controller dt = {Kd.dt} differ")
    return lower_lft(Pd, Kd, n_u, n_y)


def crossover_frequency(G, K, omega=None) -> float:
    """Where ``σ_max(G K)`` of the loop first falls below 1 (rad/s)."""
    omega = np.logspace(-4, 5, 900) if omega is None else np.asarray(omega, float)
    L = freqresp(G, omega) @ freqresp(as_controller_ss(K, G.ninputs, G.noutputs), omega)
    sv = np.linalg.svd(L, compute_uv=False)[:, 0]
    below = np.flatnonzero((sv < 1.0) & (np.r_[True, sv[:-1] >= 1.0]))
    return float(omega[below[-1]] if below.size else omega[np.argmin(np.abs(np.log(sv)))])


@dataclass(frozen=True, eq=False)
class SampledDataResult:
    """Stability and μ of the discretised loop at one sample rate.

    ``mu_upper_grid``/``mu_lower`` are the peaks on the grid ``omega`` (below
    Nyquist); ``stable`` is whether every closed-loop pole lies strictly
    inside the unit circle (``spectral_radius < 1``).
    """

    rate: float
    method: str
    prewarp: float | None
    stable: bool
    spectral_radius: float
    mu_upper_grid: float
    mu_lower: float
    peak_frequency: float
    omega: np.ndarray
    upper: np.ndarray
    lower: np.ndarray
    controller: DiscreteController
    info: dict = field(default_factory=dict)

    def summary(self) -> dict:
        return {
            "rate_hz": self.rate,
            "method": self.method,
            "prewarp_rad_s": self.prewarp,
            "stable": self.stable,
            "spectral_radius": self.spectral_radius,
            "mu_upper_grid": self.mu_upper_grid,
            "mu_lower": self.mu_lower,
            "peak_frequency": self.peak_frequency,
        }


def _mu_curve(sys, blk, w, upper_only, mu_options):
    """μ bounds on the grid: both (mu_bounds) or the upper bound alone (mussv per point, no lower-bound search)."""
    from polyrob.analysis.mu.bounds import mu_bounds, mussv

    if not upper_only:
        mu = mu_bounds(sys, blk, w, **{"refine_peak": False, "progress": False, **mu_options})
        return mu.omega, mu.upper, mu.lower
    H = freqresp(sys, w)
    up = np.array([mussv(H[k], blk, lower=False).upper if np.all(np.isfinite(H[k])) else np.inf for k in range(len(w))])
    return np.asarray(w, float), up, np.full(len(w), np.nan)


def sampled_data_mu(
    P,
    K,
    rate: float,
    *,
    method: str = "tustin",
    prewarp: float | str | None = "crossover",
    omega=None,
    performance: bool = True,
    controller: DiscreteController | control.StateSpace | None = None,
    upper_only: bool = False,
    **mu_options,
) -> SampledDataResult:
    """Stability and μ of ``K`` discretised at ``rate`` Hz around ``P`` discretised by ZOH.

    Parameters
    ----------
    P : GeneralizedPlant
    K : LTI system
        The continuous controller.
    rate : float
        Sample rate, Hz.
    method : {"tustin", "zoh"}
    prewarp : float, "crossover" or None
        Tustin pre-warping frequency; ``"crossover"`` uses the nominal loop's
        gain crossover (capped at half the Nyquist frequency); ignored for ZOH.
    omega : array_like, optional
        Frequencies (rad/s); those at or above Nyquist are dropped.  Default:
        60 points log-spaced from 1e-3 rad/s to Nyquist.
    performance : bool
        μ against uncertainty + performance block (robust performance, the
        certificate's figure); ``False``: robust stability only.
    controller : DiscreteController or discrete StateSpace, optional
        Use this discrete controller (e.g. a quantised one) instead of
        discretising ``K``.
    upper_only : bool
        Only the upper bound (``mussv`` per frequency, no lower-bound
        search; ``lower`` is NaN): what the rate and word-length searches need.
    **mu_options
        Passed to :func:`~polyrob.analysis.mu.bounds.mu_bounds` (default ``refine_peak=False``).
    """
    if not (hasattr(P, "system") and hasattr(P, "block_structure_rp")):
        raise ArgumentError(f"sampled_data_mu needs a GeneralizedPlant, got {type(P).__name__}")
    h = 1.0 / float(rate)
    if controller is None:
        if method != "tustin":
            prewarp = None
        elif prewarp == "crossover":
            wc = crossover_frequency(P.uncertain.nominal_system(), K)
            prewarp = float(min(wc, 0.5 * math.pi * rate))
        dc = discretize(K, rate, method=method, prewarp=prewarp)
    elif isinstance(controller, DiscreteController):
        dc = controller
    else:
        Ksys = control.ss(controller)
        dc = DiscreteController(Ksys, 1.0 / float(Ksys.dt), "given", None, Ksys)
    Kd = dc.system
    if not np.isclose(float(Kd.dt), h):
        raise ArgumentError(f"the discrete controller runs at {1 / float(Kd.dt):.6g} Hz, not {rate:.6g} Hz")
    Pd = control.sample_system(P.system, h, method="zoh")
    N = discrete_lft(Pd, Kd, P.n_u, P.n_y)
    rho = float(np.abs(np.linalg.eigvals(np.asarray(N.A))).max()) if N.nstates else 0.0  # discrete time: |z| < 1
    nyq = math.pi * rate
    w = np.logspace(-3, math.log10(nyq), 60) if omega is None else np.asarray(omega, float)
    w = w[(w > 0) & (w < 0.999 * nyq)]
    w = w if w.size else np.array([0.5 * nyq])
    if performance:
        sys, blk = N, P.block_structure_rp
    else:
        sys, blk = N[P.output_slices["v"], P.input_slices["d"]], P.block_structure_rs
    stable = rho < 1.0
    if stable:
        ww, uu, ll = _mu_curve(sys, blk, w, upper_only, mu_options)
        k = int(np.argmax(uu))
        up, lo, pk = float(uu[k]), float(np.nanmax(ll)) if not upper_only else float("nan"), float(ww[k])
    else:  # an unstable loop has no finite μ certificate
        up, lo, pk, ww, uu, ll = np.inf, np.inf, float("nan"), w, np.full(w.size, np.inf), np.full(w.size, np.inf)
    return SampledDataResult(
        rate=float(rate),
        method=dc.method,
        prewarp=dc.prewarp,
        stable=bool(stable),
        spectral_radius=rho,
        mu_upper_grid=float(up),
        mu_lower=float(lo),
        peak_frequency=float(pk),
        omega=ww,
        upper=uu,
        lower=ll,
        controller=dc,
        info={"performance": performance, "plant_discretisation": "zoh"},
    )


@dataclass(frozen=True, eq=False)
class MinRateResult:
    """The lowest sample rate found with discretised μ <= ``threshold``.

    ``rate`` is the lowest passing rate tried (``None`` if even
    ``rate_bounds[1]`` fails); ``history`` lists every rate tried with its
    μ and stability.  The search assumes μ decreases with the rate
    (bisection in log rate between a failing and a passing rate).
    """

    rate: float | None
    mu: float | None
    threshold: float
    mu_continuous: float
    history: tuple
    method: str

    def summary(self) -> dict:
        return {
            "min_rate_hz": self.rate,
            "mu_at_min_rate": self.mu,
            "threshold": self.threshold,
            "mu_continuous": self.mu_continuous,
            "method": self.method,
            "history": [list(h) for h in self.history],
        }


def continuous_mu(P, K, omega=None, *, performance: bool = True, upper_only: bool = True, **mu_options) -> float:
    """Peak μ upper bound of the continuous loop on ``omega`` (same options as the discrete check)."""
    N = lft(P, K)
    w = np.logspace(-3, 4, 60) if omega is None else np.asarray(omega, float)
    if performance:
        sys, blk = N, P.block_structure_rp
    else:
        sys, blk = N[P.output_slices["v"], P.input_slices["d"]], P.block_structure_rs
    return float(np.max(_mu_curve(sys, blk, w, upper_only, mu_options)[1]))


def min_sample_rate(
    P,
    K,
    *,
    mu_continuous: float | None = None,
    tolerance: float = 0.05,
    rate_bounds: tuple[float, float] = (1.0, 1e5),
    method: str = "tustin",
    omega=None,
    rel_tol: float = 0.05,
    **options,
) -> MinRateResult:
    """Lowest sample rate (Hz) whose discretised loop is stable with μ <= μ_c (1 + ``tolerance``).

    Parameters
    ----------
    P, K
        Generalized plant and continuous controller.
    mu_continuous : float, optional
        The continuous loop's peak μ; computed on the same grid when omitted.
    tolerance : float
        Allowed relative increase of μ (the brief's 5 %).
    rate_bounds : (float, float)
        Search interval in Hz.
    rel_tol : float
        Stop when the bracket's ratio is below ``1 + rel_tol``.
    **options
        Passed to :func:`sampled_data_mu`.
    """
    if mu_continuous is None:
        mu_continuous = continuous_mu(P, K, omega, performance=options.get("performance", True))
    threshold = float(mu_continuous) * (1.0 + tolerance)
    history = []

    def passes(rate):
        res = sampled_data_mu(P, K, rate, method=method, omega=omega, **{"upper_only": True, **options})
        ok = res.stable and res.mu_upper_grid <= threshold
        history.append((float(rate), float(res.mu_upper_grid), bool(res.stable), bool(ok)))
        return ok, res.mu_upper_grid

    lo, hi = map(float, rate_bounds)
    ok_hi, mu_hi = passes(hi)
    if not ok_hi:
        return MinRateResult(None, None, threshold, float(mu_continuous), tuple(history), method)
    ok_lo, mu_lo = passes(lo)
    if ok_lo:
        return MinRateResult(lo, float(mu_lo), threshold, float(mu_continuous), tuple(history), method)
    best_mu = mu_hi
    while hi / lo > 1.0 + rel_tol:
        mid = math.sqrt(lo * hi)
        ok, mu = passes(mid)
        if ok:
            hi, best_mu = mid, mu
        else:
            lo = mid
    return MinRateResult(hi, float(best_mu), threshold, float(mu_continuous), tuple(history), method)
