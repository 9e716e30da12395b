"""A controller tuned on the moving-robot certificate's own structure.

The moving-robot certificate of an ``inner-gain`` or ``inner-links``
problem (:func:`polyrob.analysis.lpv.constant.constant_parameter_certificate`)
is μ of a scaled plant: the blocks that move with the state, scaled by
constants ``d``, merged with the performance channels into one full block
(:func:`~polyrob.analysis.lpv.constant.scaled_plant`), the constants kept
as blocks of their own.  For fixed ``d`` that is a plain μ problem, so the
fixed-structure μ synthesis (:func:`polyrob.synthesis.musyn`: a PID per
joint tuned on μ's D-G scalings) applies to it unchanged; ``d`` is then
searched again for the new controller
(:func:`~polyrob.analysis.lpv.constant.search_scalings`), and the two steps
alternate.  The merged block's scaling stays one constant, which is all
that time variation allows: a controller that a frozen design certifies
can lose the moving robot's certificate (ur5's default PID: frozen μ 0.878,
moving 1.28), and this tuning is how it is won back (docs/certificates.md).

Examples
--------
>>> from polyrob.synthesis.moving import MovingTuning
>>> MovingTuning.__dataclass_fields__.keys() >= {"controller", "scalings", "history"}
True
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from polyrob.errors import ArgumentError

__all__ = ["MovingTuning", "tune_for_moving"]


@dataclass(frozen=True, eq=False)
class MovingTuning:
    """The result of :func:`tune_for_moving`.

    Attributes
    ----------
    controller : LTI
        The controller of the round with the lowest merged peak (the first
        round's is kept whatever its peak; a later round counts only when
        it lowers it).
    scalings : ndarray
        Its moving blocks' ``d``.
    history : tuple of float
        The merged structure's μ upper bound after each round (the
        synthesis' certified figure on its grid).
    structure : str
    seconds : float
    """

    controller: object
    scalings: np.ndarray
    history: tuple
    structure: str
    seconds: float

    def summary(self) -> dict:
        return {
            "structure": self.structure,
            "scalings": [float(x) for x in self.scalings],
            "history": [round(float(x), 6) for x in self.history],
            "seconds": round(self.seconds, 1),
        }


def tune_for_moving(problem, K, *, structure: str = "pid", rounds: int = 3, max_iter: int = 3) -> MovingTuning:
    """Tune ``K`` on the moving-robot structure of ``problem`` for ``rounds`` rounds (module text).

    Each round searches the scalings ``d`` for the current controller, then
    runs ``max_iter`` steps of the fixed-structure μ synthesis of
    ``structure`` on the scaled plant from it; a round that does not lower
    the peak ends the tuning.

    Raises
    ------
    ArgumentError
        A problem with no model of constants (not ``inner-gain`` or
        ``inner-links``), or ``rounds < 1``.
    """
    from polyrob.analysis.lpv.constant import applies, moving_problem, residual_scalings, scaled_plant, search_scalings
    from polyrob.progress import span
    from polyrob.synthesis import musyn
    from polyrob.synthesis.options import MusynOptions

    if int(rounds) < 1:
        raise ArgumentError(f"the moving-robot tuning needs at least one round, got {rounds}")
    held = moving_problem(problem)
    if held is None:
        raise ArgumentError(f"tuning for the moving robot needs a model of constants: {applies(problem)}")
    t0 = time.perf_counter()
    P, m = held.P, held.P.n_u
    d, _ = residual_scalings(P, K)
    history, best = [], (np.inf, K, d)
    for k in range(int(rounds)):  # each round its part of the job's line: the scalings a fifth, mu synthesis the rest
        with span(k / rounds, (k + 0.2) / rounds):
            d = search_scalings(P, best[1], best[2])
        plant, blk = scaled_plant(P, d)
        options = MusynOptions.build(structure=structure, initial_controller=best[1], max_iter=max_iter, starts=1)
        with span((k + 0.2) / rounds, (k + 1) / rounds):
            res = musyn(plant, blk, n_u=m, n_y=m, options=options)
        history.append(float(res.peak_mu))
        if not res.peak_mu < best[0]:
            break
        best = (float(res.peak_mu), res.controller, d)
    return MovingTuning(best[1], np.asarray(best[2], float), tuple(history), structure, time.perf_counter() - t0)
