"""Monte Carlo over the uncertain plant: S, T, KS and step responses (the paper's Fig. 4).

:func:`monte_carlo` closes ``u = K (r - y)`` around the nominal plant and
around ``n`` sampled plants of an :class:`~polyrob.plant.uncertainty.UncertainPlant`
(uniform ``δ``, or the corners of the box) and returns their frequency and
step responses together with the weight shapes ``1/|W_S|`` and ``1/|W_T|``
that the certificate promises to stay below.

The samples are *illustrations*: a sampled plant meeting the weights
certifies nothing about the others; the μ bound does (see docs/method.md).

Examples
--------
>>> import polyrob
>>> from polyrob.plant.weights import paper_weights
>>> from polyrob.validate.monte_carlo import monte_carlo
>>> pldi = polyrob.bound_pldi(polyrob.load_robot("paper_2r"), samples=256, coverage=0, progress=False)
>>> unc = polyrob.uncertain_plant(pldi)
>>> mc = monte_carlo(unc, polyrob.paper_controller(), n=3, W_S=paper_weights()[0], seed=1)
>>> mc.S.shape[0], mc.S.shape[2:], mc.all_stable
(3, (2, 2), True)
"""

from __future__ import annotations

from dataclasses import dataclass, field

import control
import numpy as np

from polyrob.analysis.mu.frequency import freqresp as frequency_response  # the one evaluation, kept by this name
from polyrob.controller import Controller
from polyrob.errors import ArgumentError
from polyrob.plant.generalized import loop_functions

__all__ = ["MonteCarloResult", "monte_carlo", "frequency_response", "weight_shape"]


def weight_shape(W, omega, m: int) -> np.ndarray | None:
    """``1/|W_ii(jω)|`` per channel, shape ``(m, N)`` (None when ``W`` is None).

    A SISO weight applies to every channel; an ``m x m`` weight is read on
    its diagonal (the paper's weights are diagonal).
    """
    if W is None:
        return None
    if np.isscalar(W) or (isinstance(W, np.ndarray) and W.ndim <= 2):
        G = np.asarray(W, float)
        d = np.full(m, float(G)) if G.ndim == 0 else np.diag(G)
        return np.repeat(1.0 / np.abs(d)[:, None], len(omega), axis=1)
    H = frequency_response(W, omega)
    if H.shape[1:] == (1, 1):
        return np.repeat(1.0 / np.abs(H[:, 0, 0])[None, :], m, axis=0)
    if H.shape[1:] != (m, m):
        raise ArgumentError(f"a weight is {H.shape[1]}x{H.shape[2]}; expected SISO or {m}x{m}")
    return 1.0 / np.abs(np.diagonal(H, axis1=1, axis2=2)).T


@dataclass(frozen=True, eq=False)
class MonteCarloResult:
    """Loop responses of the nominal and of sampled plants.

    Attributes
    ----------
    kind : {"uniform", "corners"}
    deltas : ndarray (n, n_params)
        The normalised parameters of each sample.
    omega : ndarray (N,)
        Frequencies, rad/s.
    S, T, KS : ndarray (n, N, m, m), complex
        Frequency responses of each sampled loop (``r -> e``, ``r -> y``, ``r -> u``).
    S_nominal, T_nominal, KS_nominal : ndarray (N, m, m), complex
        Those of the nominal plant ``G_n``.
    t : ndarray (n_t,)
        Time of the step responses, s.
    step_y, step_u : ndarray (n, m, m, n_t)
        Output ``y_i`` and control ``u_i`` for a unit step on ``r_j``:
        ``[sample, i, j, time]``; NaN for unstable samples.
    step_y_nominal, step_u_nominal : ndarray (m, m, n_t)
    stable : ndarray (n,) of bool
    nominal_stable : bool
    max_pole_real : ndarray (n,)
        Spectral abscissa of each sampled closed loop.
    inv_W_S, inv_W_T : ndarray (m, N) or None
        ``1/|W_S|``, ``1/|W_T|`` per channel, for comparison with ``S``, ``T``.
    """

    kind: str
    deltas: np.ndarray
    omega: np.ndarray
    S: np.ndarray
    T: np.ndarray
    KS: np.ndarray
    S_nominal: np.ndarray
    T_nominal: np.ndarray
    KS_nominal: np.ndarray
    t: np.ndarray
    step_y: np.ndarray
    step_u: np.ndarray
    step_y_nominal: np.ndarray
    step_u_nominal: np.ndarray
    stable: np.ndarray
    nominal_stable: bool
    max_pole_real: np.ndarray
    inv_W_S: np.ndarray | None = None
    inv_W_T: np.ndarray | None = None
    info: dict = field(default_factory=dict)

    @property
    def n(self) -> int:
        return len(self.deltas)

    @property
    def m(self) -> int:
        return self.S_nominal.shape[1]

    @property
    def all_stable(self) -> bool:
        return bool(self.nominal_stable and np.all(self.stable))

    def weight_violation(self) -> dict:
        """Largest ratio ``|S_ii| / (1/|W_S,ii|)`` (and for T) over samples and frequencies.

        ``<= 1`` means every *sampled* diagonal loop function stays below its
        weight shape (an observation on the samples, not a bound).
        """
        out = {}
        for name, H, inv in (("S", self.S, self.inv_W_S), ("T", self.T, self.inv_W_T)):
            if inv is None or not np.any(self.stable):
                out[name] = None
                continue
            diag = np.abs(np.diagonal(H[self.stable], axis1=2, axis2=3))  # (n, N, m)
            out[name] = float(np.max(diag / inv.T[None]))
        return out

    def summary(self) -> dict:
        """Plain figures for reports and JSON."""
        return {
            "kind": self.kind,
            "samples": int(self.n),
            "stable_fraction": float(np.mean(self.stable)) if self.n else None,
            "nominal_stable": bool(self.nominal_stable),
            "worst_max_pole_real": float(np.max(self.max_pole_real)) if self.n else None,
            "weight_ratio": self.weight_violation(),
        }


def _default_omega(W_S, W_T, cl) -> np.ndarray:
    poles = np.abs(cl.poles[np.abs(cl.poles) > 1e-9]) if cl.poles.size else np.array([1.0])
    lo = np.floor(np.log10(max(poles.min(), 1e-4))) - 1 if poles.size else -2.0
    hi = np.ceil(np.log10(poles.max())) + 1 if poles.size else 2.0
    return np.logspace(lo, hi, int(40 * (hi - lo)) + 1)


def _default_time(cl, omega) -> np.ndarray:
    """About six time constants of the closed-loop bandwidth (where |T| drops below 0.707)."""
    T = np.abs(frequency_response(cl.T, omega)).max(axis=(1, 2))
    below = np.flatnonzero((T < 0.7071) & (omega > omega[np.argmax(T)]))
    w_bw = omega[below[0]] if below.size else omega[-1]
    t_final = float(np.clip(6.0 / max(w_bw, 1e-12) * 2 * np.pi / 2, 1e-3, 1e4))
    return np.linspace(0.0, t_final, 601)


def _steps(cl, t, m):
    if not cl.stable:
        nan = np.full((m, m, len(t)), np.nan)
        return nan, nan.copy()
    resp = control.step_response(cl.system, T=t, squeeze=False)
    Y = np.asarray(resp.outputs)  # (outputs, inputs, time): [e; y; u]
    return Y[m : 2 * m], Y[2 * m : 3 * m]


def monte_carlo(
    unc,
    K,
    n: int | str = 20,
    *,
    seed=0,
    W_S=None,
    W_T=None,
    omega=None,
    t=None,
) -> MonteCarloResult:
    """Nominal and sampled loop functions and step responses of ``u = K (r - y)``.

    Parameters
    ----------
    unc : UncertainPlant or GeneralizedPlant
        For a generalized plant its uncertain plant is sampled and its
        weights ``W_S``, ``W_T`` are used unless given.
    K : LTI system or array
        The controller, ``m x m``, continuous-time.
    n : int or "corners"
        Number of uniform samples of ``δ ∈ [-1, 1]^k``, or ``"corners"`` for
        every corner of the box (raises when there are more than
        :data:`~polyrob.plant.uncertainty.MAX_CORNERS`).
    seed : int
    W_S, W_T : LTI system, array or number, optional
        Weights whose inverse shapes are returned for comparison.
    omega : array_like, optional
        Frequencies (rad/s); default from the nominal closed-loop poles.
    t : array_like, optional
        Times of the step responses; default about six closed-loop time constants.

    Returns
    -------
    MonteCarloResult
    """
    # duck-typed: any uncertain-plant model that samples δ and gives G(δ) (box, oriented, ...)
    if hasattr(unc, "uncertain") and hasattr(unc, "block_structure_rp"):
        W_S = unc.W_S if W_S is None else W_S
        W_T = unc.W_T if W_T is None else W_T
        unc = unc.uncertain
    if not all(hasattr(unc, a) for a in ("delta_samples", "plant_at", "nominal_system")):
        raise ArgumentError(f"monte_carlo needs an UncertainPlant or GeneralizedPlant, got {type(unc).__name__}")
    if isinstance(n, str):
        if n != "corners":
            raise ArgumentError(f"n must be a number of samples or 'corners', got '{n}'")
        deltas, kind = unc.delta_samples(kind="corners"), "corners"
    else:
        if int(n) < 1:
            raise ArgumentError(f"n must be at least 1, got {n}")
        deltas, kind = unc.delta_samples(int(n), kind="uniform", seed=seed), "uniform"
    m = unc.m
    K = Controller.of(K)  # once: every sample's loop_functions takes it as it is
    nominal = loop_functions(unc.nominal_system(), K)
    omega = _default_omega(W_S, W_T, nominal) if omega is None else np.asarray(omega, float)
    t = _default_time(nominal, omega) if t is None else np.asarray(t, float)
    loops = [loop_functions(unc.plant_at(d), K, delta=d) for d in deltas]
    resp = [frequency_response(cl.system, omega) for cl in loops]  # (N, 3m, m)
    steps = [_steps(cl, t, m) for cl in loops]
    nom_resp = frequency_response(nominal.system, omega)
    nom_y, nom_u = _steps(nominal, t, m)
    sl = (slice(0, m), slice(m, 2 * m), slice(2 * m, 3 * m))
    stack = lambda s: np.array([r[:, s, :] for r in resp]).reshape(len(loops), len(omega), m, m)  # noqa: E731
    return MonteCarloResult(
        kind=kind,
        deltas=np.asarray(deltas, float),
        omega=omega,
        S=stack(sl[0]),
        T=stack(sl[1]),
        KS=stack(sl[2]),
        S_nominal=nom_resp[:, sl[0], :],
        T_nominal=nom_resp[:, sl[1], :],
        KS_nominal=nom_resp[:, sl[2], :],
        t=t,
        step_y=np.array([s[0] for s in steps]).reshape(len(loops), m, m, len(t)),
        step_u=np.array([s[1] for s in steps]).reshape(len(loops), m, m, len(t)),
        step_y_nominal=nom_y,
        step_u_nominal=nom_u,
        stable=np.array([cl.stable for cl in loops], dtype=bool),
        nominal_stable=bool(nominal.stable),
        max_pole_real=np.array([cl.poles.real.max() if cl.poles.size else -np.inf for cl in loops]),
        inv_W_S=weight_shape(W_S, omega, m),
        inv_W_T=weight_shape(W_T, omega, m),
        info={"seed": seed},
    )
