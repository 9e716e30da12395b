"""The factors' branch and bound over a task box, and the checkpoints that keep what it finished.

:func:`prove_factor_ranges` encloses the factors of
:class:`~polyrob.bounds.certified.factors.ranges.FactorProblem` on boxes
(:meth:`~polyrob.bounds.certified.factors.ranges.FactorProblem.enclose`)
and refines them.  An entry's side is closed on a box when its bound is
within ``rel_tol`` of the entry's width of the *inner* value (the largest
attained at a point so far: the sampled search's, this module's pilot,
every box's centre, and the vertices
:func:`~polyrob.bounds.certified.factors.attained.vertex_ascent` visits on
the task and on each box, near its open sides); a box with an open side
is split along the coordinate that carries most of the over-estimation; a side proved
monotone in a coordinate goes to the face where its extreme lies
(:mod:`~polyrob.bounds.certified.factors.monotone`), and the open entries'
Taylor form is bounded on cells of the box
(:func:`~polyrob.bounds.certified.factors.taylor2.taylor2_cells`).  A box's
enclosure is intersected with its parent's (both hold on it: a child, or a
face, is part of its parent).  The result is the union of the leaves'
enclosures: rigorous whatever the inner values are (they only steer), and
the work is counted in boxes (:data:`MAX_BOXES`), never in seconds.  At
any moment every side is enclosed over the whole task (its closed bound,
and the enclosures of the boxes where it is still open): with
``partial=True`` that is what the work limit returns, proved and wider.

Checkpoints (``checkpoint_dir``): the proof's state -- the boxes still open
with their open sides, the bounds of the sides closed, the values attained
and the tolerances -- is kept in ``checkpoint_dir/<fingerprint>.npz``,
written whole (a temporary file, then a rename) every :data:`SAVE_EVERY`
batches and when the call ends, proved, given up or interrupted.  The
fingerprint (:func:`proof_fingerprint`) hashes everything the proof's boxes
depend on: the chain, the model's parameters and the factors' directions,
the task box, the tolerance and the pilot's settings, and the source of
:mod:`polyrob.bounds.certified` (a changed enclosure never goes on from an
old state).  A call that finds its state goes on from it: the same boxes in
the same order, so it ends as one uninterrupted call would (with the same
number of workers: :mod:`~polyrob.bounds.certified.factors.box_batches`);
a finished proof is returned at once, which makes the directory a cache of
proofs per robot, set and task.  Why by hand: the state is the branch and
bound's own (numpy arrays in one ``.npz``); no library keeps it.
"""

from __future__ import annotations

import hashlib
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from polyrob.bounds.certified.factors.attained import attained_range, vertex_ascent
from polyrob.bounds.certified.factors.box_batches import enclose_batch
from polyrob.bounds.certified.factors.monotone import replace_box
from polyrob.bounds.certified.factors.ranges import FactorProblem
from polyrob.bounds.certified.factors.width_ratio import FLOOR, closing_tolerance, width_ratios
from polyrob.bounds.parallel import WorkerPool
from polyrob.errors import CertificationError
from polyrob.provenance import source_digest

__all__ = [
    "FactorEnclosure",
    "prove_factor_ranges",
    "proof_fingerprint",
    "MAX_BOXES",
    "REL_TOL",
    "BATCH",
    "SAVE_EVERY",
]

#: Boxes the branch and bound evaluates before giving up (a count of work, not of seconds): with the
#: Taylor form (1-2 s a box for ur5 and panda on a loaded 2-core machine), five to ten minutes.
MAX_BOXES = 300
#: Default tolerance: a side closes within 4 % of its entry's width of the inner value (both sides: a ratio
#: of at most 1.08 to the attained width, under issue 41's bar of 1.10).
REL_TOL = 0.04
#: Boxes evaluated together (vectorised).
BATCH = 16
#: A checkpoint is written after this many batches (and when the call ends).
SAVE_EVERY = 8


@dataclass(frozen=True, eq=False)
class FactorEnclosure:
    """Proved entrywise ranges ``lower <= K_k(x) <= upper`` of each factor over the box.

    Attributes
    ----------
    names : tuple of str
        The factors (``links``, ``payload``).
    lower, upper : ndarray (F, m, 3m)
        Columns: ``q``, ``qdot``, then ``a`` (the factor's ``G``).
    boxes : int
        Boxes evaluated, by this call and the calls whose checkpoint it went on from.
    seconds : float
        Their time, summed.
    resumed_boxes : int
        Of ``boxes``, those a checkpoint held when this call began (0 without one).
    checkpoint : str or None
        The file that holds the proof's state.
    done : float
        The refinement's fraction of work done: 1 when every side closed within
        the tolerance, less when the ranges are those proved by the work limit
        (``prove_factor_ranges(..., partial=True)``): proved, and wider.
    attained_lower, attained_upper : ndarray (F, m, 3m) or None
        The extremes of the values attained at points (the pilot's, the
        ascent's, every box centre's): inner bounds, which steer the proof
        and measure its tightness (:meth:`tightness`), never bound anything.
    """

    names: tuple
    lower: np.ndarray
    upper: np.ndarray
    boxes: int
    seconds: float
    resumed_boxes: int = 0
    checkpoint: str | None = None
    done: float = 1.0
    attained_lower: np.ndarray | None = None
    attained_upper: np.ndarray | None = None

    def tightness(self) -> dict:
        """:func:`~polyrob.bounds.certified.factors.width_ratio.width_ratios` of the proved ranges to the attained ones.

        Upper bounds of the over-estimation (the attained widths are inner
        bounds): when ``done == 1``, at most ``1 + 2 rel_tol`` on the
        significant entries, up to the tolerance's ``1e-8`` of the factor's
        scale (:func:`~polyrob.bounds.certified.factors.width_ratio.closing_tolerance`).
        """
        if self.attained_lower is None:
            raise CertificationError("no values attained were kept with these ranges")
        return width_ratios(self.lower, self.upper, self.attained_lower, self.attained_upper, FLOOR)

    def contains(self, K) -> np.ndarray:
        """Whether factor values ``K`` (``(n, F, m, 3m)``) lie in the ranges: one bool per point."""
        K = np.asarray(K, float)
        return np.all((K >= self.lower) & (K <= self.upper), axis=(1, 2, 3))


def proof_fingerprint(problem: FactorProblem, domain, **settings) -> str:
    """A hash of what the proof's boxes depend on: ``problem``, the task box, ``settings`` and the enclosures' source.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> import numpy as np
    >>> from polyrob.bounds.certified.jet_rnea import Chain
    >>> chain = Chain(np.eye(3)[:2], np.stack([np.eye(3)] * 2), np.zeros((2, 3)), np.array([0, 0, -9.81]))
    >>> problem = FactorProblem(chain, ("links",), np.ones((2, 2, 14)), np.zeros((2, 2, 14)))
    >>> box = SimpleNamespace(**{f"{v}_{s}": np.zeros(2) for v in ("q", "qdot", "qddot") for s in ("lower", "upper")})
    >>> a, b = proof_fingerprint(problem, box, rel_tol=0.04), proof_fingerprint(problem, box, rel_tol=0.05)
    >>> len(a), a == b, a == proof_fingerprint(problem, box, rel_tol=0.04)
    (24, False, True)
    """
    digest = hashlib.sha256(b"polyrob factor proof 1")
    digest.update(source_digest(Path(__file__).resolve().parents[1]).encode())  # polyrob.bounds.certified
    chain = problem.chain
    arrays = [chain.axes, chain.rotations, chain.translations, chain.gravity, problem.params, problem.params_rad]
    arrays += [getattr(domain, f"{v}_{s}") for v in ("q", "qdot", "qddot") for s in ("lower", "upper")]
    for x in arrays:
        digest.update(np.ascontiguousarray(np.asarray(x, float)).tobytes())
    digest.update(repr((tuple(problem.names), sorted(settings.items()))).encode())
    return digest.hexdigest()[:24]


@dataclass
class _State:
    """The branch and bound between two batches: what a checkpoint holds."""

    stack: list  # boxes: (q_lo, q_hi, qd_lo, qd_hi, open sides (F, m, 3m, 2), volume share, lower, upper)
    out_lo: np.ndarray
    out_hi: np.ndarray
    p_lo: np.ndarray  # the values attained (they steer)
    p_hi: np.ndarray
    tol: np.ndarray
    boxes: int
    seconds: float

    def save(self, path: Path, fingerprint: str) -> None:
        from polyrob.io.atomic import atomic_write

        columns = list(zip(*self.stack)) if self.stack else [()] * 8
        F, m = self.out_lo.shape[:2]
        arrays = {
            "fingerprint": np.array(fingerprint),
            "boxes": np.array(self.boxes),
            "seconds": np.array(self.seconds),
            **{k: getattr(self, k) for k in ("out_lo", "out_hi", "p_lo", "p_hi", "tol")},
        }
        for k, name in enumerate(("q_lo", "q_hi", "qd_lo", "qd_hi")):
            arrays[name] = np.array(columns[k], float).reshape(-1, m)
        arrays["open"] = np.array(columns[4], bool).reshape(-1, F, m, 3 * m, 2)
        arrays["share"] = np.array(columns[5], float)
        arrays["box_lo"] = np.array(columns[6], float).reshape(-1, F, m, 3 * m)
        arrays["box_hi"] = np.array(columns[7], float).reshape(-1, F, m, 3 * m)
        atomic_write(path, lambda f: np.savez_compressed(f, **arrays), binary=True)

    @classmethod
    def load(cls, path: Path, fingerprint: str):
        """The state in ``path`` if it is this proof's (else ``None``: a missing, damaged or other file)."""
        try:
            with np.load(path) as data:
                if str(data["fingerprint"]) != fingerprint:
                    return None
                parts = [data[k] for k in ("q_lo", "q_hi", "qd_lo", "qd_hi", "open", "share", "box_lo", "box_hi")]
                stack = [
                    tuple(x[i] for x in parts[:5]) + (float(parts[5][i]), parts[6][i], parts[7][i])
                    for i in range(len(parts[5]))
                ]
                return cls(
                    stack,
                    *(data[k].copy() for k in ("out_lo", "out_hi", "p_lo", "p_hi", "tol")),
                    int(data["boxes"]),
                    float(data["seconds"]),
                )
        except (OSError, KeyError, ValueError, EOFError):
            return None

    def enclosure(self):
        """``(lower, upper)`` proved now, however far the refinement is: each side's closed bound and the
        enclosures of the boxes where it is still open (``inf`` before the first box).

        Every point of the task lies in a leaf -- a box closed for the side, or one
        still queued -- or in a half dropped for that side because its extreme lies
        on the face kept (:mod:`~polyrob.bounds.certified.factors.monotone`).
        """
        lower, upper = self.out_lo.copy(), self.out_hi.copy()
        for box in self.stack:
            open_ = box[4]
            lower = np.where(open_[..., 0], np.minimum(lower, box[6]), lower)
            upper = np.where(open_[..., 1], np.maximum(upper, box[7]), upper)
        return lower, upper

    def done_share(self, total_sides: int) -> float:
        """The whole job's fraction: the open work left is each queued box's volume share times its open sides."""
        return 1.0 - sum(b[5] * b[4].sum() for b in self.stack) / total_sides


def prove_factor_ranges(
    loops,
    domain,
    *,
    inner=None,
    rel_tol: float = REL_TOL,
    max_boxes: int = MAX_BOXES,
    time_limit: float | None = None,
    progress=None,
    pilot: int = 256,
    seed: int = 0,
    taylor: bool = True,
    ascent_rounds: int = 8,
    box_ascent_rounds: int = 0,
    workers: int = 1,
    checkpoint_dir=None,
    partial: bool = False,
) -> FactorEnclosure:
    """Proved ranges of the factors of ``loops`` over a task ``domain`` (a branch and bound on its ``(q, qdot)`` box).

    Parameters
    ----------
    loops : list of (str, Direction or FactorLoop)
        :func:`~polyrob.bounds.certified.factors.directions.factor_directions` of the inner loop (names first).
    domain : TaskDomain
        ``q_lower`` ... ``qddot_upper``.
    inner : (lower, upper) arrays (F, m, 3m), optional
        Attained values (the sampled search's) that steer the refinement;
        by default a pilot of ``pilot`` points.  They never enter the bounds.
    rel_tol : float
        A side of an entry is closed on a box when its bound is within
        ``rel_tol`` of the entry's (inner) width of the inner value; for an
        entry thinner than :data:`~polyrob.bounds.certified.factors.width_ratio.FLOOR`
        of its factor's scale, within ``rel_tol`` of that floor.
    max_boxes : int
        Give up (:class:`~polyrob.errors.CertificationError`) after this call
        has evaluated this many boxes.
    time_limit : float, optional
        A wall-clock safety net the caller sets (none by default).
    progress : callable, optional
        ``progress(fraction, boxes, eta_seconds)``: the call's fraction of
        its work, the open volume closed (weighted by the entries still open)
        or the share of ``max_boxes`` evaluated, whichever is further: the call
        ends at either (on panda's whole task no side closes for thousands of
        boxes, and the work limit is what ends it).
    ascent_rounds : int
        Rounds of :func:`~polyrob.bounds.certified.factors.attained.vertex_ascent`
        added to the pilot's values (0: the pilot alone).
    box_ascent_rounds : int
        Rounds of the same ascent on each box, on the workers, over the sides
        its enclosure leaves open within
        :data:`~polyrob.bounds.certified.factors.box_batches.NEAR` tolerances
        of the values attained (0, the default: none).  Each box costs
        more, and a small task needs far fewer: measured by hand on
        2026-12-04 (2 workers, 4 rounds), ur5 at a tenth of its task took
        15 boxes and 26 s in place of 121 and 156 s, at a fifth 551 boxes
        and 789 s in place of 712 and 624 s.
    taylor : bool
        Intersect each box's mean-value and slope forms with the
        second-order Taylor form (:mod:`polyrob.bounds.certified.factors.taylor2`):
        about six times the work per box, far fewer boxes.
    workers : int
        Processes each batch of boxes is shared among (:mod:`~polyrob.bounds.certified.factors.box_batches`):
        the same boxes, sooner (a worker's share may get finer cells, :func:`~polyrob.bounds.certified.factors.taylor2.cell_grid`).
    checkpoint_dir : path, optional
        Keep the proof's state there and go on from it (the module text);
        a proof given up says where its state is.
    partial : bool
        At the work limit, return what is proved by then instead of giving
        up: every entry enclosed (the sides not yet within ``rel_tol`` by the
        enclosures of the boxes where they are open), ``done < 1``.

    Examples
    --------
    finger_edu's factors on a small part of its task, proved in a few boxes,
    then taken from the checkpoint without a box more:

    >>> import tempfile
    >>> from polyrob import load_robot
    >>> from polyrob.domains.default_task import default_task_domain, default_task_robot
    >>> from polyrob.plant.models.inner_factors import factor_parameters
    >>> robot = default_task_robot(load_robot("finger_edu"))
    >>> loops = [(name, loop) for name, _, loop in factor_parameters(robot)]
    >>> box = default_task_domain(robot).scaled(0.02)
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     first = prove_factor_ranges(loops, box, checkpoint_dir=folder, pilot=32, ascent_rounds=0)
    ...     again = prove_factor_ranges(loops, box, checkpoint_dir=folder, pilot=32, ascent_rounds=0)
    >>> again.boxes == again.resumed_boxes == first.boxes, bool((again.upper == first.upper).all())
    (True, True)
    """
    t0 = time.perf_counter()
    problem = FactorProblem.from_loops(loops)
    m, F = problem.m, len(problem.names)
    q_lo, q_hi = np.asarray(domain.q_lower, float), np.asarray(domain.q_upper, float)
    v_lo, v_hi = np.asarray(domain.qdot_lower, float), np.asarray(domain.qdot_upper, float)
    a_lo, a_hi = np.asarray(domain.qddot_lower, float), np.asarray(domain.qddot_upper, float)
    path, fingerprint, state = None, None, None
    if checkpoint_dir is not None:
        settings = dict(rel_tol=rel_tol, pilot=pilot, seed=seed, taylor=taylor, ascent=ascent_rounds, batch=BATCH,
                        box_ascent=box_ascent_rounds)  # fmt: skip
        fingerprint = proof_fingerprint(problem, domain, **settings)
        path = Path(checkpoint_dir) / f"factor-proof-{fingerprint}.npz"
        state = _State.load(path, fingerprint)
    if state is None:
        state = _start(problem, q_lo, q_hi, v_lo, v_hi, a_lo, a_hi, rel_tol, pilot, seed, ascent_rounds)
    if inner is not None:  # more values attained only steer
        state.p_lo, state.p_hi = np.minimum(state.p_lo, inner[0]), np.maximum(state.p_hi, inner[1])
    resumed, seconds_before = state.boxes, state.seconds
    total_sides = F * m * 3 * m * 2
    done_before = state.done_share(total_sides)
    root_q, root_v = np.where(q_hi > q_lo, q_hi - q_lo, 1.0), np.where(v_hi > v_lo, v_hi - v_lo, 1.0)

    def keep():
        state.seconds = seconds_before + time.perf_counter() - t0
        if path is None:
            return
        try:
            state.save(path, fingerprint)
        except OSError as exc:
            warnings.warn(f"the proof's state could not be kept in {path.parent} ({exc})", stacklevel=3)

    batches = 0
    try:
        with WorkerPool(problem, workers) as pool:
            while state.stack:
                counted = state.boxes - resumed >= max_boxes  # this call's work
                if counted or (time_limit is not None and time.perf_counter() - t0 > time_limit):
                    if not partial:
                        what = (
                            f"the limit of {max_boxes} boxes reached"
                            if counted
                            else f"stopped by the time limit of {time_limit:g} s you set"
                        )
                        raise CertificationError(_gave_up(state, what, total_sides, path))
                    break
                _one_batch(state, pool, a_lo, a_hi, taylor, root_q, root_v, box_ascent_rounds)
                batches += 1
                if batches % SAVE_EVERY == 0:
                    keep()
                if progress is not None:  # the ETA from this call's pace (a resumed proof began at done_before)
                    done = max(state.done_share(total_sides), min(1.0, (state.boxes - resumed) / max_boxes))
                    pace = (done - done_before) / (time.perf_counter() - t0)
                    progress(done, state.boxes, (1 - done) / pace if pace > 0 else float("nan"))
    finally:
        if batches:  # a state read back and not changed is not written again
            keep()
    if progress is not None and batches == 0:  # a finished proof read back (or no work allowed)
        progress(state.done_share(total_sides), state.boxes, 0.0)
    lower, upper = state.enclosure()
    unbounded = ~(np.isfinite(lower) & np.isfinite(upper))
    if unbounded.any():  # a box's enclosure is infinite where M_hat is not proved invertible on all of it
        kept = f"; its state is kept in {path}: the same call goes on from there" if path is not None else ""
        raise CertificationError(
            f"proved factor ranges: {int(unbounded.sum())} of {unbounded.size} entries not bounded yet after "
            f"{state.boxes} boxes ({100 * state.done_share(total_sides):.1f} % of the work done): M_hat is not "
            f"proved invertible on the boxes where they are still open{kept}; raise the work limit (max_boxes), "
            "or shrink the task; or drop --certify (sampled bounds)"
        )
    return FactorEnclosure(
        problem.names,
        lower,
        upper,
        state.boxes,
        state.seconds,
        resumed,
        None if path is None else str(path),
        state.done_share(total_sides),
        state.p_lo.copy(),
        state.p_hi.copy(),
    )


def _start(problem, q_lo, q_hi, v_lo, v_hi, a_lo, a_hi, rel_tol, pilot, seed, ascent_rounds) -> _State:
    """The state before the first box: the attained values of the pilot and the ascent, the tolerances, the root box."""
    m, F = problem.m, len(problem.names)
    rng = np.random.default_rng(seed)
    p_lo, p_hi = attained_range(problem, q_lo, q_hi, v_lo, v_hi, a_lo, a_hi, pilot, rng)
    if ascent_rounds:  # the extremes at the box's vertices, which no box centre reaches (attained.py)
        x_lo, x_hi = np.concatenate([q_lo, v_lo]), np.concatenate([q_hi, v_hi])
        at_lo, at_hi = vertex_ascent(problem, x_lo, x_hi, a_lo, a_hi, rounds=ascent_rounds)
        p_lo, p_hi = np.minimum(p_lo, at_lo), np.maximum(p_hi, at_hi)
    tol = closing_tolerance(p_lo, p_hi, rel_tol, FLOOR)
    out_lo, out_hi = np.full((F, m, 3 * m), np.inf), np.full((F, m, 3 * m), -np.inf)
    root = (q_lo, q_hi, v_lo, v_hi, np.ones((F, m, 3 * m, 2), bool), 1.0, out_lo.copy(), out_hi.copy())
    root[6][:], root[7][:] = -np.inf, np.inf  # nothing known of the task yet
    return _State([root], out_lo, out_hi, p_lo, p_hi, tol, 0, 0.0)


def _gave_up(state, what: str, total_sides, path) -> str:
    kept = f"; its state is kept in {path}: the same call goes on from there" if path is not None else ""
    return (
        f"proved factor ranges: {what} with {len(state.stack)} boxes still open "
        f"({100 * state.done_share(total_sides):.1f} % of the work done, {state.boxes} "
        f"{'box' if state.boxes == 1 else 'boxes'} in all{kept}); "
        "raise the tolerance (rel_tol) or the work limit (max_boxes), or shrink the task; "
        "or drop --certify (sampled bounds)"
    )


def _next_batch(stack):
    """``(batch, rest)``: the :data:`BATCH` boxes with the most open work (volume share times open sides) first.

    Best first, not last in first out: depth first dives into one corner, and
    a side that needs many small boxes there holds the whole search; the
    largest open work first keeps every side's worst box refined, so the
    ranges proved by the work limit (``partial``) and the fraction done move
    together.  Boxes whose parent has no finite enclosure (``M_hat^-1`` not
    proved on it) come before all others: until each has one, no range at
    the work limit is finite.  Ties keep the stack's order (the later first).
    """
    if len(stack) <= BATCH:
        return stack, []
    unbounded = np.array([not np.isfinite(b[7]).all() for b in stack])
    work = np.array([b[5] * np.count_nonzero(b[4]) for b in stack]) + np.where(unbounded, 2.0 * stack[0][4].size, 0.0)
    order = np.argsort(-work[::-1], kind="stable")[:BATCH]
    chosen = set((len(stack) - 1 - order).tolist())
    return [stack[i] for i in sorted(chosen)], [b for i, b in enumerate(stack) if i not in chosen]


def _one_batch(state: _State, pool, a_lo, a_hi, taylor, root_q, root_v, box_ascent_rounds=0) -> None:
    """Enclose the last :data:`BATCH` boxes of the stack, close what they close, queue their children.

    The state changes only at the end: an interrupted batch leaves it as it
    was before (a checkpoint is always between two batches).
    """
    m = len(root_q)
    batch, rest = _next_batch(state.stack)
    ql, qh, vl, vh = (np.array([b[k] for b in batch]) for k in range(4))
    sides = np.array([b[4] for b in batch])  # (B, F, m, 3m, 2): the open sides
    entries = sides.any(-1)
    # a box whose parent's M_hat^-1 was not proved: its inverse checked first, then its first finite enclosure
    # (ranges.py); the root gets every form at once (on most arms its inverse is proved)
    unproved_parent = np.array([not np.isfinite(b[7]).all() and b[5] < 1.0 for b in batch])
    ascent = (box_ascent_rounds, state.p_lo, state.p_hi, state.tol) if box_ascent_rounds else None
    lo, hi, contribution, seen_lo, seen_hi, sign = enclose_batch(
        pool, (ql, qh, vl, vh, entries, unproved_parent, sides), a_lo, a_hi, taylor=taylor, ascent=ascent
    )
    # the inner values grow with every box's centre: an entry's side closes against the best value attained
    p_lo, p_hi, tol = state.p_lo, state.p_hi, state.tol
    finite = np.isfinite(hi).all((1, 2, 3))
    if finite.any():
        p_lo = np.minimum(p_lo, seen_lo[finite].min(0))
        p_hi = np.maximum(p_hi, seen_hi[finite].max(0))
    out_lo, out_hi, children = state.out_lo, state.out_hi, []
    # a box's enclosure and its parent's both hold on it (a child, or a face, is part of its parent)
    lo = np.maximum(lo, np.array([b[6] for b in batch]))
    hi = np.minimum(hi, np.array([b[7] for b in batch]))
    for b, (bql, bqh, bvl, bvh, open_, share, _, _) in enumerate(batch):
        done_hi = hi[b] <= p_hi + tol
        done_lo = lo[b] >= p_lo - tol
        q_can = (bqh - bql) > 1e-6 * root_q
        v_can = (bvh - bvl) > 1e-3 * root_v
        still = open_ & ~np.stack([done_lo, done_hi], -1)
        if not (q_can.any() or v_can.any()):
            still[:] = False  # cannot refine further: keep this box's enclosure
        closing = open_ & ~still
        out_lo = np.where(closing[..., 0], np.minimum(out_lo, lo[b]), out_lo)
        out_hi = np.where(closing[..., 1], np.maximum(out_hi, hi[b]), out_hi)
        if not still.any():
            continue
        # split where the open entries' over-estimation comes from (relative to their tolerance)
        weight = still.any(-1) / tol
        scores = np.einsum("fie,fiep->p", weight, contribution[b]) * np.concatenate([q_can, v_can])
        p = int(np.argmax(scores))
        if not np.isfinite(scores[p]) or scores[p] <= 0:
            p = int(np.argmax(np.concatenate([(bqh - bql) / root_q * q_can, (bvh - bvl) / root_v * v_can])))
        # a side monotone in a coordinate needs only the face where its extreme lies (monotone.py)
        x_lo, x_hi = np.concatenate([bql, bvl]), np.concatenate([bqh, bvh])
        for c_lo, c_hi, sides, c_share in replace_box(x_lo, x_hi, still, sign[b], p, share):
            children.append((c_lo[:m], c_hi[:m], c_lo[m:], c_hi[m:], sides, c_share, lo[b], hi[b]))
    state.stack, state.out_lo, state.out_hi = rest + children, out_lo, out_hi
    state.p_lo, state.p_hi, state.boxes = p_lo, p_hi, state.boxes + len(batch)
