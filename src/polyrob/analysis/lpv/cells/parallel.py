"""The cells of the moving robot on spawned worker processes, with the verdict of the one-process search.

:func:`~polyrob.analysis.lpv.cells.check_cells` hands its cells to a
:class:`~polyrob.bounds.parallel.WorkerPool` (spawned processes: no fork,
Ctrl-C ends them all, a dead worker is an error).  Each worker receives the
:class:`CellWork` once, pickled: the loop, ``X_j``, the basis, the robot's
enclosure, the rates, all module-level classes and functions, no closures.
The branch and bound itself stays in the calling process
(:func:`~polyrob.bounds.certified.boxes.prove_on_boxes_in_batches`): it sends
the cells in the order the one-process search takes them and reads their
values back in that order, so the cells proved, the reason of a failure and
the count at which the limit of cells gives up are those of ``workers=1``.

Examples
--------
>>> batches([1, 2, 3, 4, 5], 2)
[[1, 2], [3, 4], [5]]
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from polyrob.analysis.lpv.cells.first_order import first_order_cell
from polyrob.analysis.lpv.cells.second_order import second_order_cell
from polyrob.bounds.certified.boxes import box_words
from polyrob.errors import BoundsError

__all__ = ["CellWork", "evaluate_cells", "batches", "CELLS_PER_TASK", "CELLS_PER_ROUND"]

#: Cells a worker evaluates per message (a cell takes some 50 ms on paper_2r at x 4: a message costs far less).
CELLS_PER_TASK = 2
#: Cells per worker sent out before the values are read (a round ends when its slowest task does; past a failed
#: cell, at most a round's other cells are evaluated for nothing).
CELLS_PER_ROUND = 128


@dataclass(frozen=True, eq=False)
class CellWork:
    """What every cell test of one check needs, picklable: sent once to each worker."""

    loop: object
    model: object
    enclose: object
    basis: list
    Xs: np.ndarray
    rates_at: object
    rate_plan: tuple
    fixed: dict
    gamma: float
    order: int

    def test(self, lo, hi):
        """``(margin, contribution, first-order change per unit width, why)`` of the cell ``[lo, hi]``."""
        if self.order == 2:
            return second_order_cell(self.loop, self.model, self.enclose, self.basis, self.Xs, self.rate_plan,
                                     self.fixed, self.gamma, lo, hi)  # fmt: skip
        return first_order_cell(self.loop, self.model, self.enclose, self.basis, self.Xs, self.rates_at, self.gamma,
                                lo, hi)  # fmt: skip


def evaluate_cells(work: CellWork, cells) -> list:
    """A worker's task: the values of ``cells`` (a list of ``(lo, hi)``), in order.

    An exception of a cell test comes back as a :class:`~polyrob.errors.BoundsError` naming the cell and the
    original error (its traceback stays in the worker: ``workers=1`` shows it).
    """
    out = []
    for lo, hi in cells:
        try:
            out.append(work.test(lo, hi))
        except Exception as exc:  # noqa: BLE001 - re-raised with the cell it happened on
            raise BoundsError(
                f"the cell test failed in a worker process at rho in {box_words(lo, hi)}: {type(exc).__name__}: "
                f"{exc} (run the cells with workers=1 to see the traceback)"
            ) from exc
    return out


def batches(items, size: int) -> list:
    """``items`` cut into consecutive lists of at most ``size``."""
    items = list(items)
    return [items[i : i + size] for i in range(0, len(items), size)]
