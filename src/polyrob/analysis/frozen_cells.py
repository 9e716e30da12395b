"""The frozen robot over a task split into cells: one exact-at-its-centre model per cell, one decision for their union.

An arm's per-link set over its whole task is carried by models whose
blocks must hold every robot at every point of the task; the part of the
factor that moves with the state (``inner-links-moving``'s motion blocks,
:mod:`polyrob.plant.moving_links`) then grows with the task's position
ranges, and on the engineer's set it is what keeps μ above 1 where the
exact model at sampled points stays below (docs/certificates.md, "Which of
the task's ranges the motion's blocks pay for").  A frozen robot sits at
one point, so the task can be cut: the cells' boxes of positions cover the
task's (velocities and accelerations keep their whole ranges), each cell
gets its own ``inner-links-moving`` model (the link scalars exact at the
cell's centre, the motion over the cell only, every block constant), its
coverage measured on fresh true robots at fresh points of the cell, and its
own certificate over every frequency; every frozen robot of the set lies in
some cell, so the union is certified when every cell is
(:func:`~polyrob.analysis.certificate.union_certificate`).

Cells are found by bisection: a cell whose certificate fails is split in
two along the position that moves the factor most over it (its unit
factors' central differences at the cell's centre, weighted as the model
weighs them, times the half-width), until every cell holds or the cell
limit is reached.  This is the gridding a user of LPVTools knows, with the
difference that each cell's model holds every point of its cell, not its
grid point only; what it does not cover is the robot in motion (a moving
robot crosses cells: :mod:`polyrob.analysis.lpv.constant` is that
certificate).

A cell near μ = 1 takes minutes to tens of minutes, so each finished cell
is kept (``cells_dir``): its coverage and certificate, under a hash of
everything it was decided from (the cell's generalized plant and block
structure, the controller, the coverage count and the source of
:mod:`polyrob`), written whole (a temporary file, then a rename).  A run
that finds a cell kept takes it as it is; the bisection visits cells in the
same order, so an interrupted run goes on where it stopped and ends as one
uninterrupted run would.

Examples
--------
>>> import numpy as np
>>> halves = bisect((np.zeros(2), np.ones(2)), 1)
>>> [(lo.tolist(), hi.tolist()) for lo, hi in halves]
[([0.0, 0.0], [1.0, 0.5]), ([0.0, 0.5], [1.0, 1.0])]
"""

from __future__ import annotations

import hashlib
import pickle
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from polyrob.errors import ArgumentError
from polyrob.provenance import source_digest

__all__ = [
    "TaskCell",
    "TaskCellsCertificate",
    "frozen_cells_certificate",
    "cell_domain",
    "cell_plant",
    "bisect",
    "split_position",
    "screen_bound",
    "cell_fingerprint",
]

#: Cells certified at most, by default (each one a model and a μ sweep: about a minute on a 5-6 joint arm).
MAX_CELLS = 32
#: Fresh (true robot, point) pairs per cell for its model's coverage.
COVERAGE_POINTS = 200
#: What each cell's model is, in the scope's words.
CELL_MODEL = "inner-links-moving, every block constant"
#: Central-difference step of the split rule, relative to the cell's half-width (a choice, not a bound).
SPLIT_STEP = 0.5


@dataclass(frozen=True, eq=False)
class TaskCell:
    """One cell: its positions' box, its model's coverage and its certificate."""

    q_lower: np.ndarray
    q_upper: np.ndarray
    coverage: float
    certificate: object
    seconds: float

    def summary(self) -> dict:
        c = self.certificate
        return {
            "q_lower": [round(float(x), 6) for x in self.q_lower],
            "q_upper": [round(float(x), 6) for x in self.q_upper],
            "coverage": self.coverage,
            "status": c.status.value,
            "mu_upper": None if not np.isfinite(c.mu_upper) else float(c.mu_upper),
            "mu_upper_grid": float(c.mu_upper_grid),
            "mu_lower": float(c.mu_lower),
            "seconds": round(self.seconds, 1),
        }


@dataclass(frozen=True, eq=False)
class TaskCellsCertificate:
    """The union's decision (``certificate``), the cells it rests on, the cells visited and those screened out."""

    certificate: object
    cells: tuple
    visited: int
    screened: int
    seconds: float
    max_cells: int
    kept: int = 0

    @property
    def certified(self) -> bool:
        return self.certificate.certified

    @property
    def verdict(self) -> str:
        return f"frozen robot on {_count(len(self.cells))}: {self.certificate.verdict}"

    def words(self) -> str:
        """One line: the cells kept and certified, those visited and screened out, the time."""
        held = sum(c.certificate.certified for c in self.cells)
        earlier = f" ({self.kept} certificates kept by an earlier run)" if self.kept else ""
        return (
            f"task cells: {held} of {len(self.cells)} certified (at most {self.max_cells}); {self.visited} visited, "
            f"{self.screened} split after a screen at one frequency; {self.seconds:.0f} s{earlier}"
        )

    def summary(self) -> dict:
        return {
            "verdict": self.verdict,
            "certificate": self.certificate.summary(),
            "cells": [c.summary() for c in self.cells],
            "visited": self.visited,
            "screened": self.screened,
            "max_cells": self.max_cells,
            "kept": self.kept,
            "seconds": round(self.seconds, 1),
        }


def bisect(box, k: int):
    """The two halves of ``box`` ``(lower, upper)`` along coordinate ``k``."""
    lo, hi = (np.asarray(x, float) for x in box)
    mid = 0.5 * (lo[k] + hi[k])
    left_hi, right_lo = hi.copy(), lo.copy()
    left_hi[k], right_lo[k] = mid, mid
    return (lo, left_hi), (right_lo, hi)


def cell_domain(domain, q_lower, q_upper):
    """``domain`` (a task) with its positions' box replaced by ``[q_lower, q_upper]`` (inside it)."""
    from polyrob.domains.task import TaskDomain

    lo, hi = np.asarray(q_lower, float), np.asarray(q_upper, float)
    if np.any(lo < domain.q_lower - 1e-12) or np.any(hi > domain.q_upper + 1e-12) or np.any(lo > hi):
        raise ArgumentError("a task cell must lie inside the task's positions")
    data = domain.to_dict()
    data["q"] = {name: [float(a), float(b)] for name, a, b in zip(data["joints"], lo, hi)}
    data["name"] = f"{data.get('name', 'task')} [cell]"
    return TaskDomain.from_dict(data, robot=domain.robot)


def split_position(loop, domain) -> int:
    """The position whose range moves the set's factor most over ``domain``: where a failed cell is split.

    ``sum_j ||W (K_j(c + h e_k) - K_j(c - h e_k)) D|| / (2h) * r_k`` per
    position ``k`` (``K_j`` the unit factors of the set's scalars, ``W``,
    ``D`` the model's weighting, ``r_k`` the half-width, ``h =``
    :data:`SPLIT_STEP` ``r_k``), at the cell's centre: a rule for where to
    split, not a bound.
    """
    from polyrob.plant.models import inner_links as links
    from polyrob.plant.moving_links import task_centre

    q, qdot, a = task_centre(domain)
    half = 0.5 * (domain.q_upper - domain.q_lower)
    scalars = links.set_scalars(loop)
    W = links.residual_weighting(loop, domain)
    W_inv = np.linalg.inv(W)
    share = np.zeros(loop.m)
    for k in np.flatnonzero(half > 0):
        h = SPLIT_STEP * half[k]
        step = np.zeros_like(q)
        step[0, k] = h
        change = links.unit_factors(loop, scalars, q + step, qdot, a) - links.unit_factors(
            loop, scalars, q - step, qdot, a
        )
        weighted = links.weighted_factor(change[:, 0], W, W_inv)
        share[k] = np.linalg.norm(weighted, axis=(1, 2)).sum() / (2 * h) * half[k]
    return int(np.argmax(share))


def cell_plant(problem, domain):
    """``(unc, P)``: the ``inner-links-moving`` model of one cell and its generalized plant (the problem's weights)."""
    from polyrob.plant.generalized import generalized_plant
    from polyrob.plant.moving_links import moving_links_plant
    from polyrob.plant.weights import plant_weights

    unc = moving_links_plant(replace(problem.pldi, domain=domain), problem.robot, exact=True, exact_payload=True)
    return unc, generalized_plant(unc, **plant_weights(problem.hyperparameters))


def screen_bound(P, K, frequencies) -> float:
    """The largest of μ's upper bounds of ``K`` on ``P`` (every block constant) at ``frequencies`` (rad/s; 0 when none is given).

    A screen, not a decision: a cell whose bound reaches 1 here is split
    without its certificate, whose sweep would most likely find its peak at
    or above 1 there too (the same descent); it only decides where the work
    goes, and no screened cell enters the union.  The bound is kept in the
    cell's record (how far a screened cell is from a certificate).
    """
    from polyrob.analysis.mu.bounds import mussv
    from polyrob.analysis.mu.frequency import matrix_response
    from polyrob.plant.loops import lft

    w = np.asarray(sorted(set(float(f) for f in frequencies if np.isfinite(f) and f > 0)), float)
    if not len(w):
        return 0.0
    N = lft(P.system, K, n_u=P.n_u, n_y=P.n_u)
    response = matrix_response(*(np.asarray(X, float) for X in (N.A, N.B, N.C, N.D)))(w)
    return max(float(mussv(H, P.block_structure_rp, method="gradient").upper) for H in response)


def _cell_certificate(problem, K, domain, unc, P, coverage_points: int):
    """``(coverage, certificate)`` of ``K`` on one cell's model ``unc``/``P``, every block constant.

    The certificate's scope carries the cell model's coverage on fresh true
    robots at fresh points of the cell, so a cell whose model misses one is
    not certified (the decision's model gap).
    """
    from polyrob.analysis.certificate import certify_loop
    from polyrob.plant.moving_links import motion_coverage

    coverage = motion_coverage(unc, problem.robot, domain, coverage_points) if coverage_points else float("nan")
    checked = np.isfinite(coverage)
    scope = replace(
        problem.scope(),
        model=CELL_MODEL,
        coverage=float(coverage) if checked else None,
        coverage_points=int(coverage_points) if checked else 0,
    )
    return coverage, certify_loop(P, K, scope=scope)


def cell_fingerprint(P, K, coverage_points: int, domain) -> str:
    """A hash of what one cell's certificate is decided from: its plant, the controller, the coverage count, the code.

    ``domain`` is the cell's (its ``to_dict()``: the box, velocities,
    accelerations, the set's words); ``P`` its generalized plant.

    Examples
    --------
    >>> import control
    >>> from types import SimpleNamespace
    >>> P = SimpleNamespace(system=control.ss(-1, 1, 1, 0), block_structure_rp=[[1, 1]], n_u=1)
    >>> cell = SimpleNamespace(to_dict=lambda: {"q": {"j": [0.0, 0.1]}})
    >>> a = cell_fingerprint(P, control.ss(0, 0, 0, 2.0), 200, cell)
    >>> len(a), a == cell_fingerprint(P, control.ss(0, 0, 0, 2.5), 200, cell)
    (24, False)
    """
    import json

    digest = hashlib.sha256(b"polyrob frozen cell 1")
    digest.update(source_digest(Path(__file__).resolve().parents[1]).encode())  # changed code never reuses a cell
    for sys in (P.system, K):
        for X in (sys.A, sys.B, sys.C, sys.D):
            x = np.ascontiguousarray(np.asarray(X, float))
            digest.update(repr(x.shape).encode())
            digest.update(x.tobytes())
    digest.update(repr((P.block_structure_rp, getattr(P, "n_u", None), int(coverage_points))).encode())
    digest.update(json.dumps(domain.to_dict(), sort_keys=True, default=str).encode())
    return digest.hexdigest()[:24]


def _kept_certificate(folder, key, decide):
    """``(coverage, certificate, kept)``: ``decide()``'s (then kept in ``folder``), or the one kept under ``key``."""
    if folder is None:
        return (*decide(), False)
    from polyrob.io.atomic import atomic_write

    path = Path(folder) / f"{key}.pkl"
    if path.exists():
        try:
            with open(path, "rb") as f:
                kept = pickle.load(f)
            if kept.get("key") == key:
                return kept["coverage"], kept["certificate"], True
        except (OSError, pickle.UnpicklingError, EOFError, AttributeError, KeyError, TypeError):
            pass  # unreadable (another version's objects): decided again and written anew
    coverage, cert = decide()
    # the closed loop (a control.StateSpace) does not pickle; the decision does not need it once made
    record = {"key": key, "coverage": coverage, "certificate": replace(cert, closed_loop=None)}
    atomic_write(path, lambda f: pickle.dump(record, f), binary=True)
    return coverage, cert, False


def frozen_cells_certificate(
    problem,
    K,
    *,
    max_cells: int = MAX_CELLS,
    coverage_points: int = COVERAGE_POINTS,
    screen_at=(),
    progress=None,
    on_cell=None,
    cells_dir=None,
) -> TaskCellsCertificate:
    """Robust performance of ``K`` for every frozen robot of ``problem``'s per-link set over its task, cell by cell.

    ``problem``: a per-link set's problem on a task domain (its ``inner-links``
    or ``inner-links-moving`` model; the cells build their own).  A cell is
    first screened at the frequencies ``screen_at`` and at the peaks of the
    cells that failed before it (:func:`screen_bound` reaching 1), then certified; one
    that fails either is bisected (:func:`split_position`) while the count
    of cells stays within ``max_cells`` (at the limit it is kept with its
    certificate, made then).  The union is decided by
    :func:`~polyrob.analysis.certificate.union_certificate`, its scope naming
    the cells, their model and the smallest coverage among them.
    ``progress(done, total)``: after each cell, ``total`` the most cells
    the limit lets the bisection visit; ``on_cell(record)``: after each
    cell too, its box and what became of it (screened out, with μ's bound
    at the screen, ``screen_mu_upper``; or its certificate's status and μ
    bounds), for a log.  ``cells_dir``: where each finished cell's
    certificate is kept and found again (module docstring); ``None`` keeps
    nothing.

    Raises
    ------
    ArgumentError
        Not a task domain, or ``max_cells < 1``.
    """
    from polyrob.analysis.certificate import union_certificate
    from polyrob.domains.task import TaskDomain

    domain = problem.pldi.domain
    if not isinstance(domain, TaskDomain):
        raise ArgumentError("task cells split a task domain's positions: this problem has no task")
    if int(max_cells) < 1:
        raise ArgumentError(f"max_cells must be >= 1, got {max_cells}")
    t0 = time.perf_counter()
    budget = 2 * int(max_cells) - 1  # a bisection tree of max_cells leaves visits this many cells at most
    peaks = [float(w) for w in screen_at]
    open_cells, done, visited, screened, reused = [(domain.q_lower.copy(), domain.q_upper.copy())], [], 0, 0, 0
    while open_cells:
        lo, hi = open_cells.pop(0)
        t1 = time.perf_counter()
        sub = cell_domain(domain, lo, hi)
        unc, P = cell_plant(problem, sub)
        visited += 1
        room = len(done) + len(open_cells) + 2 <= max_cells
        record = {"q_lower": lo.tolist(), "q_upper": hi.tolist()}
        screen = screen_bound(P, K, peaks) if room else 0.0
        if screen >= 1.0:
            screened += 1
            open_cells += list(bisect((lo, hi), split_position(problem.robot, sub)))
            record["screened_out_at"] = list(peaks)
            record["screen_mu_upper"] = round(screen, 4)
        else:
            key = cell_fingerprint(P, K, coverage_points, sub) if cells_dir is not None else None
            coverage, cert, kept = _kept_certificate(
                cells_dir, key, lambda: _cell_certificate(problem, K, sub, unc, P, coverage_points)
            )
            record.update(TaskCell(lo, hi, coverage, cert, time.perf_counter() - t1).summary())
            reused += kept
            if kept:
                record["kept_from"] = str(Path(cells_dir) / f"{key}.pkl")
            if cert.certified or not room:
                done.append(TaskCell(lo, hi, coverage, cert, time.perf_counter() - t1))
            else:
                peaks.append(float(getattr(cert.mu, "peak_upper_frequency", np.nan)) if cert.mu is not None else np.nan)
                open_cells += list(bisect((lo, hi), split_position(problem.robot, sub)))
        if on_cell is not None:
            on_cell(record)
        if progress is not None:
            progress(visited, budget)
    coverages = [c.coverage for c in done if np.isfinite(c.coverage)]
    base = problem.scope()
    scope = replace(
        base,
        model=f"{CELL_MODEL} on each of {_count(len(done))}",
        coverage=min(coverages) if coverages else None,  # each cell's own gap is in its decision already
        coverage_points=int(coverage_points) * len(done) if coverages else 0,
        notes=base.notes + (_cells_words(domain, done),),
    )
    union = union_certificate([c.certificate for c in done], scope)
    seconds = time.perf_counter() - t0
    return TaskCellsCertificate(union, tuple(done), visited, screened, seconds, int(max_cells), reused)


def _count(n: int) -> str:
    return f"{n} task cell" + ("" if n == 1 else "s")


def _cells_words(domain, cells) -> str:
    """How the task was cut, in words: the cells' count and the finest split per position."""
    width = domain.q_upper - domain.q_lower
    finest = [
        int(round(w / min(c.q_upper[k] - c.q_lower[k] for c in cells))) if w > 0 else 1 for k, w in enumerate(width)
    ]
    return (
        f"the task's positions cut into {_count(len(cells))} (finest split per joint: "
        f"{', '.join(f'1/{f}' for f in finest)}), velocities and accelerations whole in each; "
        "each cell's model holds its own cell, so the union covers the frozen robot, not the robot in motion"
    )
