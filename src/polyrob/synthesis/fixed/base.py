"""The contract of a controller parametrisation, and helpers shared by the kinds.

See :mod:`polyrob.synthesis.fixed.structures` for the kinds and the factory.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import control
import numpy as np
from control.exception import ControlArgument, ControlSlycot
from slycot.exceptions import SlycotError

from polyrob.controller import Controller
from polyrob.errors import ArgumentError, SolverError

__all__ = ["ControllerStructure", "OrderedStructure", "as_theta", "io_labels", "as_lti", "siso_tf"]


def as_theta(theta, n: int) -> np.ndarray:
    """``θ`` as a flat float vector of ``n`` finite entries (else :class:`PolyrobError`)."""
    th = np.asarray(theta, dtype=float).ravel()
    if th.size != n:
        raise ArgumentError(f"θ has {th.size} entries; this structure has {n} parameters")
    if not np.all(np.isfinite(th)):
        raise ArgumentError("θ has non-finite entries")
    return th


def io_labels(n_u: int, n_y: int) -> dict:
    """Signal names of a controller ``e -> u``."""
    return {"inputs": [f"e[{j}]" for j in range(n_y)], "outputs": [f"u[{i}]" for i in range(n_u)]}


@dataclass(frozen=True)
class ControllerStructure:
    """Base class of the parametrisations (a strategy object, one per kind).

    Attributes
    ----------
    n_u, n_y : int
        Number of controls (outputs of ``K``) and measurements (its inputs).
    """

    n_u: int
    n_y: int

    # ---------------------------------------------------------------- contract
    @property
    def name(self) -> str:  # pragma: no cover - abstract
        raise NotImplementedError

    @property
    def n_params(self) -> int:  # pragma: no cover - abstract
        raise NotImplementedError

    @property
    def order(self) -> int:  # pragma: no cover - abstract
        """Number of states of :meth:`controller`."""
        raise NotImplementedError

    def realization(self, theta) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover
        """``(A, B, C, D)`` of ``K(θ)`` as plain arrays."""
        raise NotImplementedError

    def freqresp(self, theta, omega, *, jac: bool = False):  # pragma: no cover - abstract
        """``K(jω)`` as ``(N, n_u, n_y)``; with ``jac`` also ``∂K/∂θ`` as ``(N, n_params, n_u, n_y)``."""
        raise NotImplementedError

    def from_controller(self, K) -> np.ndarray:  # pragma: no cover - abstract
        """``θ`` of (an approximation of) a given controller."""
        raise NotImplementedError

    def random(self, rng: np.random.Generator) -> np.ndarray:  # pragma: no cover - abstract
        """A random ``θ`` (no knowledge of the plant: not necessarily stabilising)."""
        raise NotImplementedError

    def scale(self, theta) -> np.ndarray:  # pragma: no cover - abstract
        """Typical magnitude of each parameter around ``θ`` (1 for log-parameters)."""
        raise NotImplementedError

    def describe(self, theta) -> dict:
        """Human-readable parameters (JSON-able)."""
        return {"theta": as_theta(theta, self.n_params).tolist()}

    # ---------------------------------------------------------------- shared
    def controller(self, theta) -> control.StateSpace:
        """``K(θ)`` as a continuous-time ``control.StateSpace`` (``u = K e``)."""
        A, B, C, D = self.realization(theta)
        return control.ss(A, B, C, D, dt=0, name=f"K[{self.name}]", **io_labels(self.n_u, self.n_y))

    def initial(self, source=0, *, around=None, spread: float = 0.5) -> np.ndarray:
        """A starting point.

        Parameters
        ----------
        source : int or LTI system
            A controller to fit (:meth:`from_controller`), or a random seed.
        around : array_like, optional
            With a seed: perturb this ``θ`` by ``spread`` times :meth:`scale`
            (random multi-starts around a known good point, as HIFOO does);
            without it, draw a plant-agnostic :meth:`random` point.
        spread : float
            Relative size of the perturbation.
        """
        if isinstance(source, (control.LTI, np.ndarray)) and not np.isscalar(source):
            return self.from_controller(source)
        if not isinstance(source, (int, np.integer)):
            raise ArgumentError(f"initial() takes a seed or an LTI controller, got {type(source).__name__}")
        rng = np.random.default_rng(int(source))
        if around is None:
            return self.random(rng)
        th = as_theta(around, self.n_params)
        return th + spread * self.scale(th) * rng.standard_normal(th.size)


@dataclass(frozen=True)
class OrderedStructure(ControllerStructure):
    """A kind named by its order ``N`` (``"tfN"``, ``"ss:N"``): the name is :attr:`prefix` then ``N``."""

    #: What the name puts before ``N``.
    prefix: ClassVar[str] = ""
    N: int = 0

    def __post_init__(self):
        if self.N < 0:
            raise ArgumentError(f"{self.prefix}N needs N >= 0, got {self.N}")

    @property
    def name(self) -> str:
        return f"{self.prefix}{self.N}"


# =================================================================== tfN


def as_lti(K, n_u, n_y):
    """A python-control LTI controller, sizes checked; a transfer function stays one (its entries are fitted as given).

    Any other form (a gain, a 4-tuple, a :class:`~polyrob.controller.Controller`)
    goes through :meth:`Controller.of <polyrob.controller.Controller.of>`.
    """
    if not isinstance(K, control.LTI):
        return Controller.of(K, n_u, n_y).system
    if (K.noutputs, K.ninputs) != (n_u, n_y):
        raise ArgumentError(f"the controller is {K.noutputs}x{K.ninputs}; the structure needs {n_u}x{n_y}")
    if K.dt not in (0, None):
        raise ArgumentError("the controller must be continuous-time")
    return K


def siso_tf(Kij, N: int) -> tuple[np.ndarray, np.ndarray]:
    """Monic ``(num, den)`` of a SISO entry with ``deg den == N``.

    Lower orders are padded with a cancelling factor (exact); higher orders
    are reduced by balanced truncation (approximate).
    """
    if isinstance(Kij, control.TransferFunction):
        num = np.trim_zeros(np.asarray(Kij.num[0][0], float), "f")
        den = np.trim_zeros(np.asarray(Kij.den[0][0], float), "f")
        g = control.ss(Kij) if len(den) > 1 else None
    else:
        g = control.ss(Kij)
        g = control.minreal(g, verbose=False) if g.nstates else g
        t = control.tf(g)
        num = np.trim_zeros(np.asarray(t.num[0][0], float), "f")
        den = np.trim_zeros(np.asarray(t.den[0][0], float), "f")
    if num.size == 0:
        num = np.zeros(1)
    if len(den) - 1 > N:
        g = control.ss(control.tf(num, den)) if g is None else g
        try:
            g = control.minreal(g, verbose=False)
            if g.nstates > N:
                g = control.balred(g, N, method="matchdc")
        except (
            ValueError,
            np.linalg.LinAlgError,
            SlycotError,
            ControlArgument,
            ControlSlycot,
        ) as exc:  # SLICOT reduction failures
            raise SolverError(f"cannot reduce a controller entry of order {g.nstates} to order {N}: {exc}") from None
        t = control.tf(g)
        num = np.trim_zeros(np.asarray(t.num[0][0], float), "f")
        den = np.trim_zeros(np.asarray(t.den[0][0], float), "f")
        if num.size == 0:
            num = np.zeros(1)
    num, den = num / den[0], den / den[0]
    if len(num) > len(den):
        raise ArgumentError("an improper controller entry cannot be fitted")
    # pad with a cancelling pole/zero near the existing dynamics (exact)
    roots = np.roots(den) if len(den) > 1 else np.zeros(0)
    p = float(np.exp(np.mean(np.log(np.abs(roots) + 1e-12)))) if roots.size else 1.0
    while len(den) - 1 < N:
        den, num = np.polymul(den, [1.0, p]), np.polymul(num, [1.0, p])
    return np.trim_zeros(num, "f") if np.any(num) else np.zeros(1), den


# =================================================================== pid
