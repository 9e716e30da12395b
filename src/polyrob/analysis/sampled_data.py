"""The sampled-data certificate: μ of the loop as it runs, sampled at a rate with a computation delay.

A controller runs at a sample rate: it reads the tracking error ``e[k]``
every ``T = 1/rate`` seconds, computes for ``delay`` samples and holds its
output (zero-order hold) until the next one.  This module certifies that
loop at the sampling instants:

1. **The plant, exactly discretised.**  The uncertain robot
   ``ẋ = A(Δ) x + B(Δ) u`` (:class:`~polyrob.plant.lftplant.UncertainPlant`,
   ``[A(Δ) B(Δ)] = [A_mid B_mid] + B_d Q [C_v D_vu]``, ``Q = (I - Δ D_vd)⁻¹ Δ``)
   held over a period is ``Φ(Δ) = exp(F(Δ) T)`` with
   ``F(Δ) = [[A(Δ), B(Δ)], [0, 0]] = F0 + E``.  It is not affine in ``Δ``;
   it is, to first order, and the rest is bounded::

       Φ(Δ) = e^{F0 T} + T e^{F0 T/2} B̃ Q C̃ e^{F0 T/2} + R(Δ),   ‖R(Δ)‖ ≤ ρ

   (the first-order term of the exponential by the midpoint rule, an LFT in
   the **same** ``Δ``).  With ``g = ‖F0‖ T`` and ``h = T sup‖E‖``
   (:func:`remainder_bound`): the terms of second and higher order in ``E``
   sum to at most ``e^g (e^h - 1 - h)``, the midpoint rule misses the
   first-order term by at most ``h (g²/6 + 2 (e^g - 1 - g - g²/2))``
   (coefficient by coefficient of the power series), and ``ρ`` is their sum
   bounded from above.  ``R`` enters as one more full complex block
   ``Δ_R`` (``n x (n + m)``, ``‖Δ_R‖ ≤ 1``, scaled by ``ρ``): the discrete
   model contains the exact zero-order-hold discretisation of every member
   of the continuous set (``tests/test_sampled_certificate.py`` checks it on
   random members, and that a smaller ``ρ`` misses some).
2. **The delay** is exact: ``delay`` samples of ``z⁻¹`` on each control.
3. **The controller** is discretised as ``polyrob export`` runs it (Tustin,
   :func:`polyrob.validate.discretize.discretize`).
4. **The performance weights** ``W_S``, ``W_T`` (``W_KS``) act on the sampled
   error, output (and applied torque), mapped by Tustin: the continuous
   weight's whole frequency axis lands on ``[0, Nyquist)``.
5. **Every frequency.**  The bilinear map ``z = (1 + s)/(1 - s)`` takes the
   unit circle exactly onto the imaginary axis (``e^{jθ} ↔ j tan(θ/2)``)
   and the unit disc onto the left half plane, so the discrete loop maps to
   a continuous one with the same frequency responses (state space, exact
   up to rounding), and :func:`~polyrob.analysis.certificate.certify_loop`
   (stability at ``Δ = 0``, the μ sweep, the check between the grid points,
   ``ω = ∞`` i.e. the Nyquist frequency) decides it unchanged.

Sampled-data stability of a zero-order-hold loop is the discrete loop's
stability; what happens between the samples is not in the μ bound, and the
certificate says "at the sampling instants".

Examples
--------
>>> sampling_words(SamplingSpec(1000.0, 1))
'sampled at 1000 Hz with one sample of delay, zero-order hold'
>>> round(remainder_bound(1e-3, 5e-4), 12)   # second order in h, third in g: tiny at 1 kHz
1.26e-07
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import control
import numpy as np
import scipy.linalg

from polyrob.errors import ArgumentError

__all__ = [
    "SamplingSpec",
    "SampledPlant",
    "SampledCertificate",
    "sampling_words",
    "remainder_bound",
    "perturbation_bound",
    "sampled_generalized_plant",
    "bilinear_to_continuous",
    "physical_frequency",
    "sampled_certificate",
    "DEFAULT_RATE",
    "DEFAULT_DELAY",
]

#: Default sample rate (Hz) and computation delay (samples) of the sampled-data certificate.
DEFAULT_RATE = 1000.0
DEFAULT_DELAY = 1

#: Relative margin on every computed bound (floating-point norms and exponentials are a few ulps off).
_OUTWARD = 1e-9


@dataclass(frozen=True)
class SamplingSpec:
    """The loop as it runs: ``rate`` samples per second, ``delay`` samples of computation delay."""

    rate: float = DEFAULT_RATE
    delay: int = DEFAULT_DELAY

    def __post_init__(self):
        rate = float(self.rate)
        if not (math.isfinite(rate) and rate > 0):
            raise ArgumentError(f"the sample rate must be a positive number of Hz, got {self.rate!r}")
        if int(self.delay) != self.delay or self.delay < 0:
            raise ArgumentError(f"the delay must be a whole number of samples >= 0, got {self.delay!r}")
        object.__setattr__(self, "rate", rate)
        object.__setattr__(self, "delay", int(self.delay))

    @property
    def period(self) -> float:
        return 1.0 / self.rate

    @property
    def nyquist(self) -> float:
        """The Nyquist frequency, rad/s (``π rate``)."""
        return math.pi * self.rate

    def summary(self) -> dict:
        return {"rate_hz": self.rate, "delay_samples": self.delay, "hold": "zero-order", "words": sampling_words(self)}


def sampling_words(spec: SamplingSpec) -> str:
    """``sampled at 1000 Hz with one sample of delay, zero-order hold``."""
    delay = {0: "no delay", 1: "one sample of delay"}.get(spec.delay, f"{spec.delay} samples of delay")
    return f"sampled at {spec.rate:g} Hz with {delay}, zero-order hold"


# --------------------------------------------------------------------------- the bounds


def _series_tail(x: float, first: int) -> float:
    """An upper bound of ``Σ_{k >= first} x^k / k!`` for ``x >= 0`` (the geometric bound of the tail's ratios)."""
    if x == 0.0:
        return 0.0
    lead = x**first / math.factorial(first)
    ratio = x / (first + 1)
    if ratio < 0.5:
        return lead / (1.0 - ratio)
    return math.exp(x) - sum(x**k / math.factorial(k) for k in range(first))  # no cancellation at this size


def remainder_bound(g: float, h: float) -> float:
    """``ρ ≥ ‖e^{G+H} - e^G - e^{G/2} H e^{G/2}‖`` for every ``‖G‖ <= g``, ``‖H‖ <= h``.

    Second and higher order in ``H``: ``Σ_k ((g+h)^k - g^k - k g^{k-1} h)/k! =
    e^g (e^h - 1 - h)``.  The first-order term ``∫_0^1 e^{G(1-s)} H e^{Gs} ds``
    has coefficient ``1/k!`` on each ``G^a H G^b`` (``a + b = k - 1``), the
    midpoint ``1/(2^{k-1} a! b!)``: they agree for ``k <= 2``, differ by
    ``1/6`` in all at ``k = 3`` and by at most ``2/(k-1)!`` beyond, so the
    midpoint's error is at most ``h (g²/6 + 2 (e^g - 1 - g - g²/2))``.
    Each series is bounded from above, the sum raised by a relative 1e-9.

    >>> remainder_bound(0.0, 0.0), remainder_bound(0.0, 1e-3) >= (1e-3) ** 2 / 2
    (0.0, True)
    """
    g, h = float(g), float(h)
    if not (g >= 0 and h >= 0 and math.isfinite(g) and math.isfinite(h)):
        raise ArgumentError(f"remainder_bound needs finite norms >= 0, got g = {g}, h = {h}")
    second_order = math.exp(g) * _series_tail(h, 2)
    midpoint = h * (g * g / 6.0 + 2.0 * _series_tail(g, 3))
    return (second_order + midpoint) * (1.0 + _OUTWARD)


def _norm(X) -> float:
    """The spectral norm, raised by a relative 1e-9 (an upper bound up to the SVD's own rounding)."""
    X = np.asarray(X)
    return 0.0 if X.size == 0 else float(np.linalg.norm(X, 2)) * (1.0 + _OUTWARD)


def _channel_groups(unc):
    """Channel index lists of each block of ``Δ``: a full block's channels, then each real parameter's."""
    groups, start = [], 0
    for size in unc.full_blocks:
        groups.append(list(range(start, start + size)))
        start += size
    for p in range(unc.n_params):
        groups.append([int(i) for i in np.flatnonzero(unc.channel_parameter == p)])
    return [g for g in groups if g]


def perturbation_bound(unc) -> float:
    """An upper bound of ``‖E‖ = ‖B_d Q [C_v D_vu]‖`` over the model's set (``|δ| <= 1``, full blocks ``<= 1``).

    Without feedback inside ``Δ`` (``D_vd = 0``, ``Q = Δ``): the smaller of
    ``‖B_d‖ ‖C̃‖`` and the sum over the blocks of ``‖B_b‖ ‖C̃_b‖``.  Otherwise
    a diagonal scaling ``S`` that commutes with ``Δ`` (one scalar per full
    block, one per real channel) with ``‖S D_vd S⁻¹‖ < 1`` gives
    ``‖B_d S⁻¹‖ ‖S C̃‖ / (1 - ‖S D_vd S⁻¹‖)``; without one the model is refused.
    """
    B = np.asarray(unc.B_d, float)
    C = np.hstack([np.asarray(unc.C_v, float), np.asarray(unc.D_vu, float)])
    D = np.asarray(unc.D_vd, float)
    if not np.any(D):
        blockwise = sum(_norm(B[:, g]) * _norm(C[g, :]) for g in _channel_groups(unc))
        return min(_norm(B) * _norm(C), blockwise)
    _, (_, scale) = scipy.linalg.matrix_balance(np.abs(D) + 1e-300, permute=False, separate=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.clip(1.0 / np.asarray(scale, float), 1e-8, 1e8)  # S = diag(s): the balanced |D|'s scaling
    for g in _channel_groups(unc)[: len(unc.full_blocks)]:  # a full block takes one scalar
        s[g] = np.exp(np.mean(np.log(s[g])))
    best = math.inf
    for d in (np.ones(len(s)), s):
        if not np.all(np.isfinite(d)):
            continue
        contraction = _norm(d[:, None] * D / d[None, :])
        if contraction < 1.0:
            best = min(best, _norm(B / d[None, :]) * _norm(d[:, None] * C) / (1.0 - contraction))
    if not math.isfinite(best):
        raise ArgumentError(
            f"the sampled-data certificate cannot bound the '{unc.model}' model's perturbation (its inner "
            "feedback D_vd is not a contraction under diagonal scaling); use --rate continuous"
        )
    return best


# --------------------------------------------------------------------------- the discrete generalized plant


@dataclass(frozen=True, eq=False)
class SampledPlant:
    """The discrete generalized plant of a sampled loop (:func:`sampled_generalized_plant`).

    Attributes
    ----------
    system : control.StateSpace
        Discrete (``dt = T``).  Inputs ``[w_R (n), d (n_delta), r (m), u (m)]``,
        outputs ``[ζ (n + m), v (n_delta), z (n_z), e (m)]``; states
        ``[x (n), weights, delay line (m·delay)]``.  ``u`` is the controller's
        output, applied ``delay`` samples later.
    block_structure : ndarray
        MATLAB ``blk``: ``[n, n + m]`` (the remainder), the model's blocks, ``[m, n_z]``.
    spec : SamplingSpec
    remainder : float
        ``ρ``: the bound of what the first-order model leaves out.
    g, h : float
        ``‖F0‖ T`` and ``T sup ‖E‖`` the bound was computed from.
    n_u, n_y : int
    """

    system: control.StateSpace
    block_structure: np.ndarray
    spec: SamplingSpec
    remainder: float
    g: float
    h: float
    n_u: int
    n_y: int
    zoh: tuple = field(default=(), repr=False)

    def summary(self) -> dict:
        return {
            **self.spec.summary(),
            "remainder_bound": self.remainder,
            "norm_F0_T": self.g,
            "norm_E_T": self.h,
            "block_structure": np.asarray(self.block_structure).tolist(),
        }


def _robot_zoh(unc, T: float):
    """``(Φ0, half, B̃, C̃)``: ``e^{F0 T}``, ``e^{F0 T/2}`` and the perturbation's factors (``E = B̃ Q C̃``)."""
    n, m, nd = unc.n_x, unc.m, unc.n_delta
    F0 = np.zeros((n + m, n + m))
    F0[:n, :n], F0[:n, n:] = unc.A_mid, unc.B_mid
    Bt = np.zeros((n + m, nd))
    Bt[:n] = unc.B_d
    Ct = np.hstack([np.asarray(unc.C_v, float), np.asarray(unc.D_vu, float)])
    return F0, scipy.linalg.expm(F0 * T), scipy.linalg.expm(F0 * T / 2.0), Bt, Ct


def _tustin_weight(W, T: float):
    """A weight's matrices mapped by Tustin (a static weight as it is)."""
    from polyrob.plant.realize import ss_matrices

    if W.nstates == 0:
        return ss_matrices(W)
    return ss_matrices(control.sample_system(W, T, method="bilinear"))


def sampled_generalized_plant(P, spec: SamplingSpec) -> SampledPlant:
    """The discrete generalized plant of ``P`` (a :class:`~polyrob.plant.generalized.GeneralizedPlant`) at ``spec``.

    Its upper LFT with ``diag(Δ_R, Δ)`` holds the zero-order-hold
    discretisation of ``G(Δ)`` for every ``Δ`` of the model (module
    docstring); the weights act on the sampled signals; the controller's
    output reaches the plant ``spec.delay`` samples later.
    """
    unc = P.uncertain
    T = spec.period
    n, m, nd = unc.n_x, unc.m, unc.n_delta
    F0, Phi0, half, Bt, Ct = _robot_zoh(unc, T)
    g = _norm(F0) * T
    h = perturbation_bound(unc) * T
    rho = remainder_bound(g, h)
    Ad, Bd = Phi0[:n, :n], Phi0[:n, n:]
    B1 = math.sqrt(T) * (half @ Bt)[:n]  # d -> x[k+1]
    C1 = math.sqrt(T) * (Ct @ half)  # [x; u_applied] -> v
    root = math.sqrt(rho)

    weights = [(lab, W) for lab, W in (("W_S e", P.W_S), ("W_T y", P.W_T), ("W_KS u", P.W_KS)) if W is not None]
    mats = [_tustin_weight(W, T) for _, W in weights]
    nw = sum(a.shape[0] for a, *_ in mats)
    nq = m * spec.delay
    N = n + nw + nq
    n_z = m * (len(weights) + (P.regularize is not None))
    ins = {"R": n, "d": nd, "r": m, "u": m}
    col = dict(zip(ins, np.cumsum([0] + list(ins.values()))[:-1]))
    n_in = sum(ins.values())
    A = np.zeros((N, N))
    B = np.zeros((N, n_in))
    # the torque applied this sample: the last stage of the delay line, or u itself without delay
    applied_x = np.zeros((m, N))
    applied_in = np.zeros((m, n_in))
    if spec.delay:
        applied_x[:, N - m :] = np.eye(m)
    else:
        applied_in[:, col["u"] : col["u"] + m] = np.eye(m)
    Cq = np.hstack([np.asarray(unc.C, float), np.zeros((m, N - n))])  # q = C x
    # robot
    A[:n, :n] = Ad
    A[:n] += Bd @ applied_x
    B[:n] += Bd @ applied_in
    B[:n, col["R"] : col["R"] + n] = root * np.eye(n)
    B[:n, col["d"] : col["d"] + nd] = B1
    # delay line: stage 1 takes u, stage i + 1 takes stage i
    for i in range(spec.delay):
        rows = slice(n + nw + i * m, n + nw + (i + 1) * m)
        if i == 0:
            B[rows, col["u"] : col["u"] + m] = np.eye(m)
        else:
            A[rows, n + nw + (i - 1) * m : n + nw + i * m] = np.eye(m)
    # weights on the sampled signals
    r_in = np.zeros((m, n_in))
    r_in[:, col["r"] : col["r"] + m] = np.eye(m)
    feeds = {"W_S e": (-Cq, r_in), "W_T y": (Cq, np.zeros((m, n_in))), "W_KS u": (applied_x, applied_in)}
    Cz = np.zeros((n_z, N))
    Dz = np.zeros((n_z, n_in))
    start, row = n, 0
    for (lab, _), (Aw, Bw, Cw, Dw) in zip(weights, mats):
        fx, fin = feeds[lab]
        sl = slice(start, start + Aw.shape[0])
        A[sl, sl] = Aw
        A[sl] += Bw @ fx
        B[sl] += Bw @ fin
        Cz[row : row + m, sl] = Cw
        Cz[row : row + m] += Dw @ fx
        Dz[row : row + m] += Dw @ fin
        start += Aw.shape[0]
        row += m
    if P.regularize is not None:
        Cz[row : row + m] += P.regularize * applied_x
        Dz[row : row + m] += P.regularize * applied_in
    # [x; u_applied] as rows of the state and inputs: what ζ and v read
    xu_x = np.vstack([np.hstack([np.eye(n), np.zeros((n, N - n))]), applied_x])
    xu_in = np.vstack([np.zeros((n, n_in)), applied_in])
    Czeta, Dzeta = root * xu_x, root * xu_in
    Cv, Dv = C1 @ xu_x, C1 @ xu_in
    Dv[:, col["d"] : col["d"] + nd] += np.asarray(unc.D_vd, float)
    Ce, De = -Cq, r_in.copy()
    C = np.vstack([Czeta, Cv, Cz, Ce])
    D = np.vstack([Dzeta, Dv, Dz, De])
    system = control.ss(A, B, C, D, dt=T)
    blk = np.vstack([[[n, n + m]], np.asarray(unc.block_structure, int).reshape(-1, 2), [[m, n_z]]]).astype(int)
    return SampledPlant(system, blk, spec, rho, g, h, m, m, zoh=(Ad, Bd, B1, C1))


# --------------------------------------------------------------------------- the bilinear map


def bilinear_to_continuous(sys: control.StateSpace) -> control.StateSpace:
    """The continuous system ``H_c(s) = H_d((1 + s)/(1 - s))`` of a discrete one (the unit circle onto jω).

    ``A_c = (A + I)⁻¹ (A - I)``, ``B_c = √2 (A + I)⁻¹ B``, ``C_c = √2 C (A + I)⁻¹``,
    ``D_c = D - C (A + I)⁻¹ B``; ``|z| < 1`` exactly when ``Re s < 0``.
    Refused when ``A`` has an eigenvalue at ``-1`` (``A + I`` singular).

    >>> Hd = control.ss([[0.5]], [[1.0]], [[1.0]], [[0.0]], dt=0.1)
    >>> Hc = bilinear_to_continuous(Hd)
    >>> s = 1j * np.tan(0.3 / 2)    # e^{0.3j} on the circle
    >>> bool(np.isclose(Hc(s), Hd(np.exp(0.3j))))
    True
    """
    A, B, C, D = (np.asarray(X, float) for X in (sys.A, sys.B, sys.C, sys.D))
    n = A.shape[0]
    if n == 0:
        return control.ss(A, B, C, D)
    Ap = A + np.eye(n)
    if np.linalg.cond(Ap) > 1e12:
        raise ArgumentError("the discrete loop has a pole at z = -1: the bilinear map is singular there")
    X = np.linalg.solve(Ap, np.hstack([A - np.eye(n), B]))
    Ac, invB = X[:, :n], X[:, n:]
    Cinv = np.linalg.solve(Ap.T, C.T).T
    return control.ss(Ac, math.sqrt(2.0) * invB, math.sqrt(2.0) * Cinv, D - C @ invB)


def physical_frequency(omega, rate: float):
    """The frequency (rad/s) of the loop sampled at ``rate`` Hz where the bilinear variable is ``jω``: ``2 rate atan(ω)``."""
    return 2.0 * float(rate) * np.arctan(np.asarray(omega, float))


# --------------------------------------------------------------------------- the certificate


@dataclass(frozen=True, eq=False)
class SampledCertificate:
    """The sampled-data certificate and what it was computed from.

    ``certificate`` is decided by :func:`polyrob.analysis.certificate.certify_loop`
    on the bilinear image of the discrete loop; its scope names the rate,
    the delay, the hold and "at the sampling instants".
    """

    certificate: object
    plant: SampledPlant
    controller: object
    peak_frequency: float

    @property
    def verdict(self) -> str:
        return self.certificate.verdict

    def line(self) -> str:
        """The analysis' line: the grid's μ bounds, where they peak (rad/s of the sampled loop), the status."""
        c = self.certificate
        head = f"{'sampled-data':<22} "
        if c.mu is None:
            return head + f"{sampling_words(self.plant.spec)}: {c.status}"
        return head + (
            f"mu in [{c.mu_lower:.4g}, {c.mu_upper_grid:.4g}] (peak on the frequency grid) at "
            f"{self.peak_frequency:.4g} rad/s, {sampling_words(self.plant.spec)}: {c.status}"
        )

    def instead_line(self, continuous) -> str:
        """When the sampled loop is not certified but ``continuous`` (the continuous loop's certificate) is."""
        spec = self.plant.spec
        return (
            f"instead: the continuous-time loop is {continuous.verdict.split(' ', 2)[-1]} (--rate continuous); "
            f"in the way: the rate and the delay (mu peaks at {self.peak_frequency:.3g} rad/s, Nyquist "
            f"{spec.nyquist:.4g} rad/s); try a higher --rate, a smaller --delay or a slower controller"
        )

    def summary(self) -> dict:
        return {
            **self.plant.summary(),
            "controller_discretisation": "tustin",
            "peak_frequency_rad_s": float(self.peak_frequency),
            "certificate": self.certificate.summary(),
        }


def sampled_certificate(P, K, spec: SamplingSpec | None = None, *, scope=None, omega=None, **mu_options):
    """Robust performance of ``K`` on ``P`` sampled at ``spec.rate`` with ``spec.delay`` samples of delay.

    Parameters
    ----------
    P : GeneralizedPlant
    K : controller (continuous, ``m x m``); discretised by Tustin as ``polyrob export`` does.
    spec : SamplingSpec, default 1000 Hz, one sample.
    scope : Scope, optional
        What the inputs cover; the sampling clause is added here.
    omega : array_like, optional
        Grid in the bilinear variable (default: the loop's own).

    Returns
    -------
    SampledCertificate
    """
    from polyrob.analysis.certificate import Scope, certify_loop
    from polyrob.analysis.loop_sweep import grid_words
    from polyrob.validate.discretize import discretize

    spec = spec or SamplingSpec()
    plant = sampled_generalized_plant(P, spec)
    Kd = discretize(K, spec.rate, method="tustin").system
    Pc, Kc = bilinear_to_continuous(plant.system), bilinear_to_continuous(Kd)
    base = scope or Scope()
    words = (
        f"{sampling_words(spec)}, at the sampling instants (frequencies of the unit circle, up to the "
        f"Nyquist frequency {spec.nyquist:.4g} rad/s; the plant's discretisation with a remainder block of "
        f"norm {plant.remainder:.3g}; the controller by Tustin, the weights by Tustin on the sampled signals)"
    )
    base = replace(base, sampling=words)
    # a mu lower bound >= 1 may rest on the remainder block (complex, a superset of the true
    # discretisations): it disproves nothing, so it gives NOT_CERTIFIED, never VIOLATED
    cert = certify_loop(
        Pc,
        Kc,
        plant.block_structure,
        omega,
        n_u=plant.n_u,
        n_y=plant.n_y,
        scope=base,
        lower_bound_disproves=False,
        **mu_options,
    )
    if not cert.bound_everywhere and cert.mu is not None:  # the grid in the loop's own frequencies, not the map's
        w = physical_frequency(cert.mu.omega, spec.rate)
        cert = replace(cert, scope=replace(cert.scope, frequencies=grid_words(w)))
    peak = float(physical_frequency(cert.mu.peak_upper_frequency, spec.rate)) if cert.mu is not None else math.nan
    return SampledCertificate(cert, plant, Kd, peak)
