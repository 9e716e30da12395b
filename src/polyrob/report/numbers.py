"""Numbers as a person reads them: round-off printed as 0.

A matrix computed in floating point carries round-off of the size of
``eps`` times its largest entry: an entry that is zero in exact arithmetic
comes out as ``-1.944e-42`` or ``1.9874e-16`` and, printed with five
significant digits, reads like a real coupling.  :func:`zero_round_off`
sets the entries below :data:`RELATIVE_ZERO` of the matrix's scale to 0
before printing; the stored figures (JSON, ``.npz``) keep every digit.

Examples
--------
>>> zero_round_off([[1.0, 1.9874e-16], [-1.944e-42, 2.5]]).tolist()
[[1.0, 0.0], [0.0, 2.5]]
>>> zero_round_off([1e-20, 3e-20]).tolist()  # a matrix of tiny entries keeps them: its scale is its own
[1e-20, 3e-20]
>>> zero_round_off([0.5, 1e-300], scale=1.0).tolist()
[0.5, 0.0]
"""

from __future__ import annotations

import numpy as np

__all__ = ["RELATIVE_ZERO", "NO_HINF_STEP", "gamma_text", "zero_round_off"]

#: Entries below this fraction of the matrix's scale print as 0: far above the
#: round-off of inverses and products of well-posed matrices (1e-16 .. 1e-13),
#: far below the 5 significant digits printed.
RELATIVE_ZERO = 1e-10


def zero_round_off(values, scale: float | None = None) -> np.ndarray:
    """A float copy of ``values`` with every ``|x| <= RELATIVE_ZERO * scale`` set to 0 (and -0.0 to 0).

    Parameters
    ----------
    values : array_like
        A matrix, a vector or a table of figures of one scale.
    scale : float, optional
        The matrix's scale; default its largest finite absolute entry.
    """
    x = np.array(values, dtype=float)
    finite = np.isfinite(x)
    if scale is None:
        scale = float(np.abs(x[finite]).max()) if finite.any() else 0.0
    x[finite & (np.abs(x) <= RELATIVE_ZERO * scale)] = 0.0
    return x + 0.0


#: What an iteration table shows for a controller that no H∞ step made (a given start, a tuned PID, a reduced one).
NO_HINF_STEP = "no H-inf step"


def gamma_text(gamma, digits: int = 4) -> str:
    """The K-step's γ (the scaled plant's H∞ norm) as a table shows it, or :data:`NO_HINF_STEP` when there is none.

    >>> gamma_text(0.98765), gamma_text(float("nan"))
    ('0.9877', 'no H-inf step')
    """
    try:
        g = float(gamma)
    except (TypeError, ValueError):
        return NO_HINF_STEP
    return f"{g:.{digits}g}" if np.isfinite(g) else NO_HINF_STEP
