"""One controller value: built once where a controller enters polyrob, taken as it is inside.

A controller reaches polyrob as a python-control system (``StateSpace`` or
``TransferFunction``, from a synthesis or a controller file), a static gain
(a number or a matrix), a 4-tuple ``(A, B, C, D)`` or a synthesis result
(anything with a ``.controller``).  :meth:`Controller.of` turns each into
one :class:`Controller`, a continuous-time state-space realisation
``u = K y`` with its sizes checked; :func:`as_controller_ss` is the same
for code that wants the python-control system.

Examples
--------
>>> import control
>>> from polyrob.controller import Controller
>>> K = Controller.of(control.tf([[[1.0, 2.0]]], [[[1.0, 10.0]]]))
>>> K.order, K.n_u, K.n_y
(1, 1, 1)
>>> Controller.of(2.5).D.tolist(), Controller.of(K) is K
([[2.5]], True)
>>> Controller.of(K, n_u=2, n_y=1)
Traceback (most recent call last):
...
polyrob.errors.ArgumentError: K maps 1 inputs to 1 outputs; expected 1 measurements -> 2 controls
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import control
import numpy as np

from polyrob.errors import ArgumentError
from polyrob.plant.realize import as_state_space, is_static

__all__ = ["Controller", "as_controller_ss"]


@dataclass(frozen=True, eq=False)
class Controller:
    """A continuous-time controller ``u = K y``: ``ẋ_K = A x_K + B y``, ``u = C x_K + D y``.

    Build it with :meth:`Controller.of`.

    Attributes
    ----------
    A, B, C, D : ndarray
        The realisation (``A`` is ``0 x 0`` for a static gain).
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    #: The python-control system it was built from (kept with its signal names), if any.
    given: control.StateSpace | None = field(default=None, repr=False)

    @classmethod
    def of(cls, K, n_u: int | None = None, n_y: int | None = None) -> Controller:
        """``K`` as a :class:`Controller`, ``n_u x n_y`` when the sizes are given.

        Parameters
        ----------
        K : Controller, LTI system, number, matrix, (A, B, C, D) or a synthesis result
            A ``TransferFunction`` is realised entry by entry (exact,
            :func:`~polyrob.plant.realize.as_state_space`); a discrete-time
            system is refused.
        n_u, n_y : int, optional
            Controls (outputs of ``K``) and measurements (its inputs).

        Raises
        ------
        PolyrobError
            Not a controller, discrete-time, or the wrong size.
        """
        if isinstance(K, Controller):
            out = K
        elif isinstance(K, tuple) and len(K) == 4:
            out = cls._of_matrices(*K, n_u=n_u, n_y=n_y)
        elif hasattr(K, "controller") and not isinstance(K, control.LTI):
            out = cls.of(K.controller)  # a synthesis result or a design
        elif is_static(K):
            D = np.atleast_2d(np.asarray(K, float))
            out = cls._of_matrices(np.zeros((0, 0)), np.zeros((0, D.shape[1])), np.zeros((D.shape[0], 0)), D)
        else:
            ss = as_state_space(K, "K")
            out = cls(*(np.asarray(X, float) for X in (ss.A, ss.B, ss.C, ss.D)), given=ss)
        if n_u is not None and n_y is not None and (out.n_u, out.n_y) != (n_u, n_y):
            raise ArgumentError(
                f"K maps {out.n_y} inputs to {out.n_u} outputs; expected {n_y} measurements -> {n_u} controls"
            )
        return out

    @classmethod
    def _of_matrices(cls, A, B, C, D, *, n_u=None, n_y=None) -> Controller:
        """From plain matrices; an empty ``A`` (a static gain) takes its sizes from ``D`` (or ``n_u``, ``n_y``)."""
        D = np.atleast_2d(np.asarray(D, float))
        if n_u is not None and n_y is not None and D.size == n_u * n_y:
            D = D.reshape(n_u, n_y)
        A = np.asarray(A, float)
        nk = A.shape[0] if A.size else 0
        A = A.reshape(nk, nk)
        B = np.asarray(B, float).reshape(nk, D.shape[1])
        C = np.asarray(C, float).reshape(D.shape[0], nk)
        if not all(np.all(np.isfinite(X)) for X in (A, B, C, D)):
            raise ArgumentError("K has non-finite entries")
        return cls(A, B, C, D)

    @property
    def order(self) -> int:
        """Number of states."""
        return int(self.A.shape[0])

    @property
    def n_u(self) -> int:
        """Controls: outputs of ``K``."""
        return int(self.D.shape[0])

    @property
    def n_y(self) -> int:
        """Measurements: inputs of ``K``."""
        return int(self.D.shape[1])

    @property
    def matrices(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(A, B, C, D)``."""
        return self.A, self.B, self.C, self.D

    @cached_property
    def system(self) -> control.StateSpace:
        """The python-control ``StateSpace`` (the one it was built from, when it was built from one)."""
        if self.given is not None:
            return self.given
        return control.ss(self.A, self.B, self.C, self.D, dt=0)


def as_controller_ss(K, n_u: int, n_y: int) -> control.StateSpace:
    """A controller (LTI system, static gain, 4-tuple, :class:`Controller`) as an ``n_u x n_y`` continuous-time ``StateSpace``.

    Raises :class:`~polyrob.errors.ArgumentError` on a size mismatch.
    """
    return Controller.of(K, n_u, n_y).system
