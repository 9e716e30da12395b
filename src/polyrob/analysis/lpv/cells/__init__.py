"""Between the grid points of the moving robot: the bounded-real LMIs proved on every cell of the state box.

The moving-robot search (:mod:`polyrob.analysis.lpv.moving`) proves its
``X(rho) = sum_j f_j(rho) X_j`` at grid points only.  Here the same ``X`` is
proved on the whole box of ``rho``, cell by cell.  For a cell with centre
``rho_c``, every vertex ``nu`` of its rate box and ``W = (-M(rho_c, nu))^(-1/2)``
(so that ``W M(rho_c) W = -I``), ``M(rho) < 0`` on the cell follows from a
bound of ``W (M(rho) - M(rho_c)) W`` built from guaranteed enclosures of the
robot's Jacobians and of the basis functions over the cell:

* ``order=2`` (default, :mod:`~polyrob.analysis.lpv.cells.second_order`):
  the whole matrix's derivative at the centre, the affine part checked at the
  cell's vertices, the curvature enclosed over the cell (the dynamics' third
  derivatives);
* ``order=1`` (:mod:`~polyrob.analysis.lpv.cells.first_order`): the change's
  parts (plant, ``X``, rates) bounded apart by the mean-value theorem; where
  ``X`` follows the loop the parts cancel and this bound cannot see it.

Weighing every change by ``W`` is what makes this work on a stiff loop: the
LMI matrix has entries of ``1e4`` next to a margin of ``1e-2``, and a plain
norm bound would ask for cells a million times smaller.  A cell that fails is
bisected along the coordinate with the largest term; a point where the LMIs
fail ends the search (the ``X`` does not hold there).  Before the cells, the
robot's accelerations are proved inside the rate bounds the ``X`` was built
for (a sampled bound is not one: ``tests/test_cells.py`` shows a box where
the sampled peak times 1.05 is below the robot's), so the bound covers every
trajectory of the linearised robot in the box.  On a task the accelerations
are parameters of the box (each velocity's rate is its acceleration there,
exactly): there is nothing to prove about them.

Examples
--------
>>> c = CellCheck(True, 0.99, 120, 0.01, (1.0, 2.0), "", 3.0)
>>> c.words()
'proved on 120 cells covering the whole box at level 0.99 (accelerations proved <= 1, 2)'
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from polyrob.analysis.lpv.cells.loop import (
    AffineLoop,
    SimilarTransform,
    acceleration_check,
    plant_enclosure,
    similarity_allowance,
)
from polyrob.analysis.lpv.cells.parallel import CELLS_PER_ROUND, CELLS_PER_TASK, CellWork, batches, evaluate_cells
from polyrob.analysis.lpv.cells.second_order import fixed_terms
from polyrob.bounds.certified.boxes import prove_on_boxes
from polyrob.errors import ArgumentError

__all__ = ["CellCheck", "CellSetting", "cell_setting", "check_cells", "plant_enclosure", "volume_reporter"]


@dataclass(frozen=True)
class CellCheck:
    """The outcome of :func:`check_cells`.

    Attributes
    ----------
    holds : bool
        Every leaf cell passed: the LMIs hold on the whole box at ``gamma``.
    gamma : float
        The level checked.
    n_cells : int
        Leaf cells proved (all of them when ``holds``).
    smallest_margin : float
        Smallest proved margin ``-(lambda_max + bound)`` over the leaves.
    accelerations : tuple of float
        Proved bound of ``|qddot_j|`` over the box (the largest over the leaves).
    reason : str
        Why it does not hold.
    seconds : float
    sensitivity : tuple of float
        Per coordinate, the largest first-order change of the weighed LMI per
        unit of cell width seen (a cell must be narrower than about its inverse):
        the whole matrix's derivative at the cells' centres (second-order test),
        or the sum of its parts' bounds over the cells (first-order test).
    workers : int
        Processes the cells ran on (the verdict does not depend on it).
    """

    holds: bool
    gamma: float
    n_cells: int
    smallest_margin: float
    accelerations: tuple
    reason: str
    seconds: float
    sensitivity: tuple = ()
    workers: int = 1

    def words(self) -> str:
        if not self.holds:
            return f"not proved between the grid points ({self.reason})"
        acc = ", ".join(f"{a:.4g}" for a in self.accelerations)
        return f"proved on {self.n_cells} cells covering the whole box at level {self.gamma:.4g}" + (
            f" (accelerations proved <= {acc})" if acc else ""
        )

    def summary(self) -> dict:
        from polyrob.analysis.scope import finite_or_none

        return {
            "holds": self.holds,
            "gamma": finite_or_none(self.gamma),
            "cells": self.n_cells,
            "smallest_margin": finite_or_none(self.smallest_margin),
            "accelerations": [finite_or_none(a) for a in self.accelerations],
            "reason": self.reason,
            "sensitivity": [finite_or_none(x) for x in self.sensitivity],
            "seconds": round(self.seconds, 1),
            "workers": self.workers,
        }


@dataclass(frozen=True, eq=False)
class CellSetting:
    """What every cell of one check shares: the loop, ``X_j`` in its coordinates, the rates, the initial cells."""

    loop: AffineLoop
    Xs: np.ndarray
    basis: list
    rates_at: object
    rate_plan: tuple
    enclose: object
    boxes: list
    lo: np.ndarray
    hi: np.ndarray
    fixed: dict


def cell_setting(model, system, Xs, basis, rates, *, similarity=None, c=1.0, cells=None, gamma=None) -> CellSetting:
    """The :class:`CellSetting` of :func:`check_cells` (same arguments); ``enclose`` is ``None`` without enclosures.

    With a ``similarity`` ``T`` (``x = T x~``, the coordinates ``X`` was
    searched in) the cells can run in either coordinates: the loop's own,
    ``X`` moved there as the float product ``T^-T X T^-1`` (a candidate like
    any other: no inverse is trusted), or the search's, the loop moved there
    through the float inverse of ``T`` with :func:`~polyrob.analysis.lpv.cells.loop.similarity_allowance`
    added to every cell's rounding allowance.  Both are proofs; the one kept
    has the larger ratio of the LMI's margin to its allowances at the box's
    centre (at ``gamma``, default 1): on a stiff loop ``X`` moved back spans
    many decades and its margin sinks below the rounding (the main job's
    loop), while on a milder one the whole-box allowance costs more than it
    saves (paper_2r at four times the bandwidth).
    """
    if basis is None:  # a constant X (arbitrarily fast variation)
        from polyrob.analysis.lpv.basis import constant_function

        basis = [constant_function(len(model.names))]
    if similarity is None:
        return _setting(model, system, Xs, basis, rates, None, c, cells, moved=False)
    own = _setting(model, system, Xs, basis, rates, similarity, c, cells, moved=False)
    searched = _setting(model, system, Xs, basis, rates, similarity, c, cells, moved=True)
    level = 1.0 if gamma is None else float(gamma)
    return max((own, searched), key=lambda st: _centre_ratio(st, model, level))


def _centre_ratio(st: CellSetting, model, gamma: float) -> float:
    """The LMI's smallest margin at the box's centre over its rounding and similarity allowances (all rate vertices)."""
    from polyrob.analysis.lpv.check import GridData, brl_matrices

    ctr = 0.5 * (st.lo + st.hi)
    A, B, C, D = st.loop.at(*model.plant(ctr))
    f = np.array([[float(fn(ctr)) for fn, _ in st.basis]])
    g = np.array([[np.asarray(gr(ctr), float) for _, gr in st.basis]])
    rc = np.array(st.rates_at(ctr), float)
    rc[~np.isfinite(rc).all(axis=1)] = 0.0
    nus = np.array(np.meshgrid(*[np.unique(x) for x in rc], indexing="ij")).reshape(len(ctr), -1).T
    data = GridData(A[None], B[None], C[None], D[None], f, g, nus[None], ctr[None])
    M, err, _, _ = brl_matrices(data, st.Xs, gamma)
    margins = -np.linalg.eigvalsh(M[0])[:, -1]
    ratio = float(np.min(margins / (err[0] + st.loop.allowance)))
    return ratio if np.isfinite(ratio) else -np.inf


def _setting(model, system, Xs, basis, rates, similarity, c, cells, *, moved: bool) -> CellSetting:
    """One :class:`CellSetting`: ``X`` moved to the loop's own coordinates, or (``moved``) the loop to ``X``'s."""
    from polyrob.analysis.lpv.norm import state_scaling
    from polyrob.analysis.lpv.robot import kinematic_rates

    enclose = plant_enclosure(model)
    lo0 = np.array([a[0] for a in model.axes], float)
    hi0 = np.array([a[-1] for a in model.axes], float)
    sizes = [a.size - 1 for a in model.axes] if cells is None else list(cells)
    if model.mirrored:  # the cells cover the whole box: the proof does not lean on the (sampled) evenness
        lo0[0], sizes[0] = -hi0[0], 2 * sizes[0]
    edges = [np.linspace(lo0[i], hi0[i], max(1, sizes[i]) + 1) for i in range(len(lo0))]
    A0, B0 = model.plant(0.5 * (lo0 + hi0))
    of_plant = SimilarTransform(system.of_plant, similarity) if moved else system.of_plant
    corners = np.array(np.meshgrid(*edges, indexing="ij")).reshape(len(lo0), -1).T
    sc = state_scaling(np.array([of_plant(*model.plant(p))[0] for p in corners]))  # as the grid check
    loop = AffineLoop(of_plant, c, sc, A0, B0)
    n = sc.size
    Xs = np.asarray(Xs, float)
    if similarity is not None and not moved:
        # X back in the loop's own (time-scaled, balanced) coordinates, x = T x~: X = T^-T X~ T^-1.  The float
        # product is a candidate like any other, and it is what the cells check: no inverse is trusted
        Ti = np.linalg.inv(np.asarray(similarity, float))
        Xs = np.einsum("ai,kab,bj->kij", Ti, Xs, Ti)
    Xs = 0.5 * (Xs + np.transpose(Xs, (0, 2, 1))) * sc[None, :, None] * sc[None, None, :]
    # a power-of-two diagonal congruence that brings X's diagonal near 1 (exact): the rounding allowances are
    # relative to |X| |A|, and an X with entries from 1e1 to 1e7 left 0.35 of a cell's margin to them (paper_2r x4)
    mid = 0.5 * (lo0 + hi0)
    dX = np.diag(np.einsum("k,kij->ij", np.array([float(f(mid)) for f, _ in basis]), Xs))
    if np.all(dX > 0) and np.all(np.isfinite(dX)):
        d = 2.0 ** np.round(-0.5 * np.log2(dX))
        sc, Xs = sc * d, Xs * d[None, :, None] * d[None, None, :]
        loop = AffineLoop(of_plant, c, sc, A0, B0)
    if moved and enclose is not None:
        from polyrob.bounds.certified.analytic import function_balls

        fb = function_balls(basis, lo0, hi0, order=1)[0]
        loop.allowance = similarity_allowance(of_plant, AffineLoop(system.of_plant, 1.0, np.ones(n), A0, B0), loop,
                                              enclose(lo0, hi0), Xs, np.maximum(np.abs(fb[0]), np.abs(fb[1])))  # fmt: skip
    elif moved:
        loop.allowance = np.inf  # no enclosure to bound the similarity's effect with: this setting proves nothing
    rates_at = kinematic_rates(model, rates, c)
    boxes = [
        (np.array([e[k] for e, k in zip(edges, idx)]), np.array([e[k + 1] for e, k in zip(edges, idx)]))
        for idx in np.ndindex(*[len(e) - 1 for e in edges])
    ]
    plan = (rates_at.exact, np.array(rates, float) / c)
    _, B, C, _ = loop.at(A0, B0)
    fixed = fixed_terms(loop, Xs, n, B.shape[1], C.shape[0])
    return CellSetting(loop, Xs, basis, rates_at, plan, enclose, boxes, lo0, hi0, fixed)


def check_cells(model, system, Xs, basis, rates, gamma, *, similarity=None, c=1.0, cells=None, max_cells=200_000,
                time_limit=None, min_width=1e-6, progress=False, order=2, workers=None) -> CellCheck:  # fmt: skip
    """Prove the bounded-real LMIs of ``X(rho) = sum_j f_j(rho) X_j`` at level ``gamma`` on the whole box of ``rho``.

    Parameters
    ----------
    model : MovingRobotModel
    system : callable
        :func:`~polyrob.analysis.lpv.robot.closed_loop_system` (its ``of_plant``).
    Xs : sequence of ndarray
        ``X_j`` in the coordinates of the loop the search ran on, ``x = T x~``
        and time scaled by ``c`` (:func:`~polyrob.analysis.lpv.robot.conditioned`).
    basis : sequence of (f, grad)
        The functions ``f_j``; each must evaluate on :class:`~polyrob.bounds.certified.analytic.Jet` arrays.
    rates : sequence of (float, float)
        The rate bounds in physical time (a position's rate is its velocity).
    gamma : float
    similarity : ndarray, optional
        ``T`` (default: the identity); the check itself runs in the loop's own coordinates.
    c : float
        The time scale.
    cells : sequence of int, optional
        Initial cells per coordinate (default: the model's grid).
    max_cells, min_width
        Give up past that many cells or at a cell narrower than ``min_width``
        times its coordinate's range (bounds of work: the verdict does not
        depend on the machine's load).
    time_limit : float, optional
        A safety net the caller sets: wall-clock seconds per branch and bound
        before giving up, named in the reason when it fires (default: none).
    progress : bool
        A tqdm bar (cells proved / cells known).
    order : {1, 2}
        The cell test: 2 (default) expands the LMI to second order about each
        cell's centre (:mod:`~polyrob.analysis.lpv.cells.second_order`), 1
        bounds its change by first-order parts (:mod:`~polyrob.analysis.lpv.cells.first_order`).
    workers : int, optional
        Processes the cells run on (default: the available cores; 1: this
        process).  The verdict does not depend on it
        (:mod:`~polyrob.analysis.lpv.cells.parallel`); inside a daemonic
        process (a pool's worker) the cells run in that process.

    Returns
    -------
    CellCheck
    """
    if order not in (1, 2):
        raise ArgumentError(f"check_cells: order must be 1 or 2, not {order!r}")
    t0 = time.perf_counter()
    st = cell_setting(model, system, Xs, basis, rates, similarity=similarity, c=c, cells=cells, gamma=gamma)
    if st.enclose is None:
        return CellCheck(False, gamma, 0, -np.inf, (), f"no guaranteed enclosure for {model.robot.name}", 0.0)
    loop, Xs, basis, rates_at, enclose, boxes, lo0, hi0 = (st.loop, st.Xs, st.basis, st.rates_at, st.enclose,
                                                          st.boxes, st.lo, st.hi)  # fmt: skip
    width0 = np.where(hi0 > lo0, hi0 - lo0, 1.0)
    opts = {"min_width": min_width, "max_boxes": max_cells, "time_limit": time_limit}
    if "qddot" in model.kinds:  # a task: the accelerations are parameters inside their box, nothing to prove
        acc = ()
    else:
        acc_bounds = np.full(model.robot.m, np.inf)
        for (_lo, hi), kind, j in zip(rates, model.kinds, model.joints):
            if kind == "qdot":
                acc_bounds[j] = hi
        ok, leaves, why = prove_on_boxes([(lo0, hi0)], acceleration_check(model, enclose, acc_bounds), width0, **opts)
        acc = tuple(float(a) for a in np.max([v[1] for v in leaves], axis=0)) if leaves else ()
        if not ok:
            return CellCheck(False, gamma, 0, -np.inf, acc, f"accelerations: {why}", time.perf_counter() - t0)

    seen = np.zeros(len(lo0))

    def observe(out):
        if out[1] is not None:  # (margin, contribution, first-order change per unit width, why)
            seen[:] = np.maximum(seen, out[2])
        return out

    work = CellWork(loop, model, enclose, basis, Xs, rates_at, st.rate_plan, st.fixed, gamma, order)
    n_workers = _workers(workers)
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=len(boxes), desc="cells", unit="cell")
    done = volume_reporter(lo0, hi0)  # the whole job's progress line: the part of the box proved
    try:
        if n_workers == 1:
            ok, leaves, why = prove_on_boxes(boxes, lambda lo, hi: observe(work.test(lo, hi)), width0, bar=bar,
                                             by_contribution=True, on_proved=done, **opts)  # fmt: skip
        else:
            n_workers, (ok, leaves, why) = _in_parallel(work, boxes, width0, n_workers, observe, bar, opts, done)
    finally:
        if bar is not None:
            bar.close()
    smallest = min((v[0] for v in leaves), default=-np.inf)
    return CellCheck(ok, gamma, len(leaves), smallest, acc, why, time.perf_counter() - t0,
                     tuple(float(x) for x in seen), n_workers)  # fmt: skip


def _workers(workers) -> int:
    import multiprocessing

    from polyrob.workers import available_cores

    n = available_cores() if workers is None else int(workers)
    if n < 1:
        raise ArgumentError(f"check_cells: workers must be at least 1, not {workers!r}")
    if multiprocessing.current_process().daemon:  # a daemonic process may not start processes
        return 1
    return n


def volume_reporter(lo0, hi0):
    """``on_proved(lo, hi)`` reporting the fraction of the box ``[lo0, hi0]`` proved (:func:`polyrob.progress.report`).

    The volume counts the coordinates that vary (a fixed one has width 0).

    Examples
    --------
    >>> import io, numpy as np
    >>> from polyrob.progress import JobProgress
    >>> job = JobProgress(["moving-robot"], stream=io.StringIO(), clock=lambda: 0.0)
    >>> job.start() is job and job._stop.set() is None
    True
    >>> job.begin(1, "moving-robot")
    >>> done = volume_reporter(np.array([0.0, 1.0, 0.0]), np.array([2.0, 1.0, 1.0]))
    >>> done(np.array([0.0, 1.0, 0.0]), np.array([1.0, 1.0, 0.5]))     # a quarter of the 2 x 1 box
    >>> round(job.share, 3)
    0.25
    >>> job.stop()
    """
    from polyrob.progress import report

    varying = np.asarray(hi0, float) > np.asarray(lo0, float)
    total = float(np.prod((np.asarray(hi0, float) - np.asarray(lo0, float))[varying]))
    proved = [0.0]

    def on_proved(lo, hi):
        proved[0] += float(np.prod((np.asarray(hi, float) - np.asarray(lo, float))[varying]))
        report(proved[0], total)

    return on_proved


def _in_parallel(work, boxes, width0, n_workers, observe, bar, opts, on_proved=None):
    """``(processes used, prove_on_boxes' answer)`` with the cells evaluated on ``n_workers`` spawned workers."""
    import logging

    from polyrob.bounds.certified.boxes import prove_on_boxes_in_batches
    from polyrob.bounds.parallel import WorkerPool

    with WorkerPool(work, workers=n_workers) as pool:

        def evaluate_many(cells):
            return [v for chunk in pool.map(evaluate_cells, batches(cells, CELLS_PER_TASK)) for v in chunk]

        answer = prove_on_boxes_in_batches(boxes, evaluate_many, width0, batch=CELLS_PER_ROUND * n_workers,
                                           observe=observe, bar=bar, min_width=opts["min_width"],
                                           max_boxes=opts["max_boxes"], time_limit=opts["time_limit"],
                                           on_proved=on_proved)  # fmt: skip
        if pool.fallback is not None:
            logging.getLogger("polyrob").warning("cells: %s", pool.fallback)
            return 1, answer
    return n_workers, answer
