"""The paper's fixed-structure robust controller ``K*(s)`` (section 3)."""

from __future__ import annotations

import control

__all__ = ["paper_controller", "PAPER_CONTROLLER"]

#: The paper's fixed-structure controller K*(s) (section 3), numerator and
#: denominator coefficients (descending powers of s) of each entry, transcribed
#: exactly as printed.
PAPER_CONTROLLER = {
    "num": [
        [[1.07e5, 1.392e5, 44157.0], [264150.0, 5.362e05, 15849.0]],
        [[3.421e4, 4.447e4, 14454.0], [1.172e5, 4.728e5, 16406.0]],
    ],
    "den": [
        [[0.02, 4.0, 200.0, 1.0], [0.08333, 13.33, 500.0, 1.0]],
        [[0.01422, 3.556, 222.2, 1.0], [0.02319, 6.494, 454.6, 1.0]],
    ],
}


def paper_controller() -> control.TransferFunction:
    """The paper's fixed-structure robust controller ``K*(s)`` (section 3).

    A 2x2 matrix of third-order transfer functions from ``e = r - q`` to ``u``,
    obtained there by fixed-structure ``musyn`` (μ upper bound 0.9999 against
    the paper's intervals and weights).  Stable, no integral action.

    Examples
    --------
    >>> from polyrob.plant.generalized import paper_controller
    >>> K = paper_controller()
    >>> K.ninputs, K.noutputs, K.den[1][1].tolist()
    (2, 2, [0.02319, 6.494, 454.6, 1.0])
    >>> round(float(K(0)[0, 0].real))
    44157
    """
    return control.tf(
        PAPER_CONTROLLER["num"],
        PAPER_CONTROLLER["den"],
        inputs=["e[0]", "e[1]"],
        outputs=["u[0]", "u[1]"],
        name="K*",
    )
