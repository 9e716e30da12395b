"""Controller parametrisations for fixed-structure μ-synthesis.

A :class:`ControllerStructure` maps a real parameter vector ``θ`` to a
controller ``K(θ)`` (``n_u x n_y``, ``u = K y``) and gives what the
optimiser of :mod:`polyrob.synthesis.fixed.synthesis` needs from it:

* :meth:`~ControllerStructure.controller` — ``K(θ)`` as a ``control.StateSpace``;
* :meth:`~ControllerStructure.realization` — its ``(A, B, C, D)`` as arrays
  (the closed-loop stability test runs on every trial point: no python-control
  objects there);
* :meth:`~ControllerStructure.freqresp` — ``K(jω; θ)`` and, analytically,
  ``∂K(jω; θ)/∂θ`` (the K-step differentiates the μ majorant through it);
* :meth:`~ControllerStructure.initial` — a starting ``θ``, fitted to a given
  controller or random;
* :meth:`~ControllerStructure.scale` — typical magnitudes of the parameters,
  so the optimiser works in well-conditioned units.

Three kinds, chosen by a string (:func:`controller_structure`):

``"tfN"`` (:class:`TransferFunctionStructure`)
    every ``K_ij`` a proper transfer function of order ``N``: numerator of
    degree ``≤ N`` (``N + 1`` free coefficients), monic denominator written as
    a product of stable factors ``(s + a)`` and ``(s² + b s + c)`` with
    ``a = e^{θ}``, ``b = e^{θ}``, ``c = e^{θ}``.  Every monic Hurwitz
    polynomial has exactly this form (a quadratic factor holds a complex pair
    or two real roots), so the parametrisation covers all stable ``K_ij`` of
    order ``N`` and nothing else.  The paper's ``K*`` is a ``"tf3"``.
``"pid"`` (:class:`PIDStructure`)
    a decentralised PIDF per channel, ``u_i = (Kp + Ki/s + Kd s/(τ s + 1)) e_i``,
    ``τ = e^{θ} > 0``.  ``Ki/s`` puts a controller pole at ``s = 0``: only
    the closed loop has to be stable, which the synthesis checks.
``"ss:N"`` (:class:`StateSpaceStructure`)
    a state-space controller of order ``N`` with free ``A, B, C, D``.

Examples
--------
>>> import numpy as np
>>> from polyrob.synthesis.fixed.structures import controller_structure
>>> s = controller_structure("tf3", n_u=2, n_y=2)
>>> s.n_params, s.order
(28, 12)
>>> K = s.controller(s.initial(0))
>>> K.nstates, K.ninputs, K.noutputs
(12, 2, 2)
>>> controller_structure("pid", 2, 2).n_params
8
"""

from __future__ import annotations

import re

from polyrob.errors import ArgumentError
from polyrob.synthesis.fixed.base import ControllerStructure
from polyrob.synthesis.fixed.pid import PIDStructure
from polyrob.synthesis.fixed.state_space import StateSpaceStructure
from polyrob.synthesis.fixed.transfer import TransferFunctionStructure

__all__ = [
    "ControllerStructure",
    "TransferFunctionStructure",
    "PIDStructure",
    "StateSpaceStructure",
    "controller_structure",
    "VALID_STRUCTURES",
]

#: The structure strings :func:`controller_structure` understands.
VALID_STRUCTURES = ('"tfN" (e.g. "tf3": each K_ij of order N)', '"pid"', '"ss:N" (e.g. "ss:4")')


# =================================================================== factory
def controller_structure(structure, n_u: int, n_y: int) -> ControllerStructure:
    """The :class:`ControllerStructure` named by a string.

    Parameters
    ----------
    structure : str or ControllerStructure
        ``"tfN"`` (``N`` ≥ 0), ``"pid"`` or ``"ss:N"``; an instance passes through
        (its sizes are checked).
    n_u, n_y : int
        Controls and measurements.

    Raises
    ------
    ArgumentError
        An unknown string (the message lists the valid ones) or sizes that do
        not match.

    Examples
    --------
    >>> from polyrob.synthesis.fixed.structures import controller_structure
    >>> controller_structure("ss:2", 1, 1).name
    'ss:2'
    >>> controller_structure("lqg", 1, 1)
    Traceback (most recent call last):
    ...
    polyrob.errors.ArgumentError: unknown controller structure 'lqg'; valid: "tfN" (e.g. "tf3": each K_ij of order N), "pid", "ss:N" (e.g. "ss:4")
    """
    if isinstance(structure, ControllerStructure):
        if (structure.n_u, structure.n_y) != (n_u, n_y):
            raise ArgumentError(f"structure is {structure.n_u}x{structure.n_y}; the plant needs {n_u}x{n_y}")
        return structure
    if isinstance(structure, str):
        s = structure.strip().lower()
        if m := re.fullmatch(r"tf(\d+)", s):
            return TransferFunctionStructure(n_u, n_y, int(m.group(1)))
        if s == "pid":
            return PIDStructure(n_u, n_y)
        if m := re.fullmatch(r"ss:(\d+)", s):
            return StateSpaceStructure(n_u, n_y, int(m.group(1)))
    raise ArgumentError(f"unknown controller structure {structure!r}; valid: {', '.join(VALID_STRUCTURES)}")
