"""Guaranteed (interval-arithmetic) bounds on the Jacobians of robot dynamics.

For a fixed-base serial robot with dynamics ``M(q) qdd + h(q, qd) + D qd = u``
and ``f(x, u) = (qd, M^-1 (u - h - D qd))``, :func:`certified_jacobian_bounds`
returns entrywise intervals ``[A_lo, A_hi]``, ``[B_lo, B_hi]`` that provably
contain ``A = df/dx`` and ``B = df/du`` for *every* ``(q, qd, u)`` in a box.

Method (see :mod:`polyrob.bounds.certified.interval_rbd` for the dynamics themselves):

* On a q-box every entry is a polynomial in ``(qd, u)`` of degree <= 2 whose
  coefficients ``c(q)`` are enclosed by order-2 *Taylor models* in
  ``d = q - qc``: thin value, gradient and Hessian at the box centre plus a
  rigorous third-order remainder.  Plain interval (or mean-value) forms
  over-estimate badly here, because ``M^-1`` of an ill-conditioned ``M``
  multiplies the widths of everything it touches.
* The Taylor model's linear part is maximised exactly (at a vertex of the
  q-box, jointly with ``qd`` below); only its quadratic part and remainder are
  enclosed, so the over-estimation is second order with the true curvature
  as constant and the branch and bound needs few boxes.
* ``u`` enters affinely (and ``d qdd/d qd`` is affine in ``qd``), so the
  extremes are at vertices of the u-box (qd-box): they are enumerated, not
  split.  The quadratic dependence of ``d qdd/d q`` on ``qd`` is maximised
  exactly over a qd-box (enumeration of its faces, in ``arb``); the qd-box is
  bisected only when the enclosed Taylor terms depend mostly on its extent.
* Branch and bound on outer bounds: for each entry we keep the best inner
  value (attained at evaluated points, by Pinocchio) and refine a box only
  while its enclosure sticks out beyond it by more than ``rel_tol`` x the
  current width.  Inner values only steer the search; the result is the union
  of the enclosures of all leaves, so it is rigorous whatever they are.
* Coordinates the dynamics do not depend on (structurally, from the exact
  polynomials, and numerically, by Pinocchio) are never bisected, and an
  entry independent of a bisected coordinate follows one half only.

Floats: every ``arb`` result is converted outward (``arb_upper``/``arb_lower``:
``float()`` rounds to nearest, so the result is moved one ulp outward when an
exact comparison shows it fell inside).
"""

from __future__ import annotations

import heapq
import itertools
import time
from dataclasses import dataclass

import numpy as np

from polyrob.bounds.certified.balls import sq
from polyrob.bounds.certified.branch import BoxProblem, process_box
from polyrob.bounds.certified.interval_rbd import SymbolicDynamics, box_coefficients, entry_depends, entry_terms
from polyrob.bounds.polytope import box_corners
from polyrob.bounds.reference import reference_jacobians
from polyrob.errors import CertificationError, DomainError

__all__ = ["CertifiedEnclosure", "certified_jacobian_bounds", "reference_jacobians", "MAX_BOXES"]

#: Boxes the branch and bound processes before giving up: a count of work, never seconds, so that the
#: same robot and domain are proved or refused on an idle and on a loaded machine alike.
MAX_BOXES = 200_000


@dataclass(frozen=True, eq=False)
class CertifiedEnclosure:
    """Guaranteed entrywise bounds ``A_lo <= A <= A_hi``, ``B_lo <= B <= B_hi``.

    Attributes
    ----------
    A_lo, A_hi : numpy.ndarray, shape (2m, 2m)
    B_lo, B_hi : numpy.ndarray, shape (2m, m)
    n_boxes : int
        Number of q-boxes evaluated by the branch and bound.
    seconds : float
        Wall time.
    max_depth : int
        Deepest bisection level reached.
    """

    A_lo: np.ndarray
    A_hi: np.ndarray
    B_lo: np.ndarray
    B_hi: np.ndarray
    n_boxes: int
    seconds: float
    max_depth: int


def _relevant_dims(model, damping, lo, hi, vlo, vhi, ulo, uhi, sd, rng):
    """Joints whose coordinate changes A or B (numerically, via Pinocchio).

    Only decides which coordinates get bisected: enclosures always use the
    full range of every coordinate, so a wrong answer costs time, not rigour.
    """
    m = len(lo)
    rel = np.array(sd.depends) & (np.asarray(hi) > np.asarray(lo))
    data = model.createData()
    varies = np.zeros(m, dtype=bool)
    for _ in range(6):
        q, v, u = rng.uniform(lo, hi), rng.uniform(vlo, vhi), rng.uniform(ulo, uhi)
        A0, B0 = reference_jacobians(model, damping, q, v, u, data)
        scale = np.abs(A0).max() + np.abs(B0).max()
        for p in np.flatnonzero(rel & ~varies):
            q2 = q.copy()
            q2[p] = rng.uniform(lo[p], hi[p])
            A1, B1 = reference_jacobians(model, damping, q2, v, u, data)
            if max(np.abs(A1 - A0).max(), np.abs(B1 - B0).max()) > 1e-9 * scale:
                varies[p] = True
    return rel & varies


def _as_vec(name, x, m):
    a = np.asarray(x, dtype=float).reshape(-1)
    if a.shape != (m,) or not np.all(np.isfinite(a)):
        raise DomainError(f"{name} must be {m} finite numbers, got {x!r}")
    return a


def certified_jacobian_bounds(
    model,
    damping,
    q_lo,
    q_hi,
    qdot_lo,
    qdot_hi,
    u_lo,
    u_hi,
    *,
    max_joints=3,
    rel_tol=1e-3,
    max_boxes=MAX_BOXES,
    time_limit=None,
    progress=False,
):
    """Guaranteed entrywise bounds of ``A = df/dx`` and ``B = df/du`` over a box.

    For every ``q in [q_lo, q_hi]``, ``qdot in [qdot_lo, qdot_hi]`` and
    ``u in [u_lo, u_hi]``: ``A_lo <= A(q, qdot, u) <= A_hi`` and
    ``B_lo <= B(q) <= B_hi``, proved with outward-rounded interval arithmetic
    (``arb``) and converted to floats outward.  The bounds are tight up to
    ``rel_tol`` times each entry's width (branch and bound over ``q``, and
    over ``qdot`` where it pays off).

    Parameters
    ----------
    model : pinocchio.Model
        Fixed-base serial chain of revolute, continuous or prismatic joints.
    damping : array_like, shape (m,)
        Viscous joint damping ``D = diag(damping)``.
    q_lo, q_hi, qdot_lo, qdot_hi, u_lo, u_hi : array_like, shape (m,)
        The box (angle for continuous joints).  ``lo == hi`` is allowed.
    max_joints : int, default 3
        Robots with more joints are refused at once.
    rel_tol : float, default 1e-3
        Stop refining a box when it cannot widen an entry's bound by more than
        ``rel_tol`` times the entry's current width.
    max_boxes : int, default :data:`MAX_BOXES`
        Boxes processed before giving up (:class:`~polyrob.errors.CertificationError`):
        a count of work, so whether the bounds are proved does not depend on
        the machine's load.
    time_limit : float, optional
        A safety net the caller sets: wall-clock seconds before giving up;
        the error then names it ("stopped by the time limit of N s you set").
        ``None`` (default): no wall-clock limit.
    progress : bool, default False
        Show a tqdm bar (boxes processed / processed + queued).

    Returns
    -------
    CertifiedEnclosure

    Raises
    ------
    CertificationError
        Too many joints, unsupported joint, ``M`` not provably invertible,
        ``max_boxes`` or the time limit reached.
    DomainError
        Malformed box.

    Examples
    --------
    >>> import numpy as np, pinocchio as pin
    >>> model = pin.buildModelFromUrdf("urdf/planar_2r.urdf")
    >>> q = [0.0, np.pi]                       # a single point: a tight enclosure
    >>> enc = certified_jacobian_bounds(model, [0, 0], q, q, [1, 2], [1, 2], [0, 0], [0, 0])
    >>> bool(np.all(enc.B_hi - enc.B_lo < 1e-12))
    True
    >>> float(np.round(enc.B_hi[2, 0], 4))    # 13.125 / det M(pi)
    0.0312
    """
    t0 = time.perf_counter()
    m = model.nv
    name = getattr(model, "name", "") or "the robot"
    if m > max_joints:
        raise CertificationError(
            f"certified bounds support robots of up to {max_joints} joints; {name} has {m}: "
            "use sampled bounds (drop --certify)"
        )
    d = _as_vec("damping", damping, m)
    box = [
        _as_vec(n, x, m)
        for n, x in (
            ("q_lo", q_lo),
            ("q_hi", q_hi),
            ("qdot_lo", qdot_lo),
            ("qdot_hi", qdot_hi),
            ("u_lo", u_lo),
            ("u_hi", u_hi),
        )
    ]
    qlo, qhi, vlo, vhi, ulo, uhi = box
    for n, (lo, hi) in zip(("q", "qdot", "u"), ((qlo, qhi), (vlo, vhi), (ulo, uhi))):
        if np.any(lo > hi):
            raise DomainError(f"{n}: lower bound above upper bound ({lo} > {hi})")
    sd = SymbolicDynamics(model)
    split = _relevant_dims(model, d, qlo, qhi, vlo, vhi, ulo, uhi, sd, np.random.default_rng(0))
    prob = BoxProblem(sd, d, vlo, vhi, rel_tol, model, ulo, uhi)
    deps = entry_depends(sd)
    root_w = np.where(qhi > qlo, qhi - qlo, 1.0)

    # sub-problem: [entry, u-vertex, qdot-box lo, qdot-box hi, hi side open, lo side open]
    # Each entry is affine in u, and affine in qdot unless it has qdot_j qdot_l
    # terms: so the u-box (qdot-box) extremes are at its vertices; only the
    # vertices of the variables an entry actually has (structurally) are used.
    items = []
    vc = tuple(0.5 * (vlo + vhi))
    for e, terms in enumerate(entry_terms(sd, d)):
        Us = [tuple(c) for c in box_corners(ulo, uhi)] if terms & set(range(1, 1 + m)) else [(0.0,) * m]
        if terms & set(range(1 + 2 * m, 1 + 2 * m + len(sd.pairs))):
            Ss = [(tuple(vlo), tuple(vhi))]
        elif terms & set(range(1 + m, 1 + 2 * m)):
            Ss = [(v, v) for v in map(tuple, box_corners(vlo, vhi))]
        else:
            Ss = [(vc, vc)]
        items += [[e, U, S0, S1, True, True] for U in Us for S0, S1 in Ss]

    try:
        from tqdm import tqdm

        bar = tqdm(total=1, disable=not progress, desc="certify", unit="box")
    except ImportError:  # pragma: no cover
        bar = None
    heap = [(0.0, 0, 0, tuple(qlo), tuple(qhi), items)]
    counter, n_boxes, max_depth = itertools.count(1), 0, 0
    while heap:
        out_of_boxes = n_boxes >= max_boxes
        if out_of_boxes or (time_limit is not None and time.perf_counter() - t0 > time_limit):
            open_items = sum(len(h[5]) for h in heap)
            if bar is not None:
                bar.close()
            what = (
                f"the limit of {max_boxes} boxes reached"
                if out_of_boxes
                else f"stopped by the time limit of {time_limit:g} s you set"
            )
            raise CertificationError(
                f"certified bounds: {what} after {n_boxes} boxes (depth {max_depth}) with {open_items} "
                f"sub-problems still open in {len(heap)} boxes; raise the tolerance (--rel-tol) or shrink the domain"
                + (", or raise the time limit (--time-limit)" if not out_of_boxes else "")
            )
        _, _, depth, lo, hi, items = heapq.heappop(heap)
        n_boxes += 1
        max_depth = max(max_depth, depth)
        c0, c1, c2, R, delta = box_coefficients(sd, d, lo, hi)
        if c0 is None:
            raise CertificationError(f"mass matrix not provably invertible at q = {np.add(lo, hi) / 2}")
        delta2 = {(p, q): sq(delta[p]) if p == q else delta[p] * delta[q] for p, q in c2}
        tm = (c0, c1, c2, R, delta, delta2)
        prob.qlo, prob.qhi = lo, hi
        prob.qc = [min(max(0.5 * (a + b), a), b) for a, b in zip(lo, hi)]
        alive = process_box(prob, items, tm)
        cand = [p for p in range(m) if split[p] and hi[p] - lo[p] > 1e-9 * root_w[p]]
        if alive and not cand:  # cannot refine further: keep these enclosures
            for it, _, _, _ in alive:
                h, l, _, _ = prob.evaluate(it, tm, exact=True)
                prob.finalize(it, h if it[4] else None, l if it[5] else None)
            alive = []
        if alive:
            if R is None:
                p = max(cand, key=lambda p: (hi[p] - lo[p]) / root_w[p])
            else:  # the coordinate carrying most of the non-linear Taylor terms
                score = {p: 0.0 for p in cand}
                for it, _, _, terms in alive:
                    t = prob.tol(it[0])
                    for k, x in terms.items():
                        for p in (set(k) if k != "R" else set(cand)) & score.keys():
                            score[p] += float(x.abs_upper()) / t
                p = max(cand, key=lambda p: (score[p], hi[p] - lo[p]))
            prio = -max(prob.excess(it, h, l) for it, h, l, _ in alive)
            mid = 0.5 * (lo[p] + hi[p])
            its = [it for it, _, _, _ in alive]
            for half, (a, b) in enumerate(((lo[p], mid), (mid, hi[p]))):
                clo, chi = list(lo), list(hi)
                clo[p], chi[p] = a, b
                # an entry independent of q_p has the same range on both halves
                sub = [list(it) for it in its if half == 0 or p in deps[it[0]]]
                if sub:
                    heapq.heappush(heap, (prio, next(counter), depth + 1, tuple(clo), tuple(chi), sub))
        if bar is not None:
            bar.total = n_boxes + len(heap)
            bar.update(1)
    if bar is not None:
        bar.close()
    return _assemble(prob, m, n_boxes, time.perf_counter() - t0, max_depth)


def _assemble(prob, m, n_boxes, seconds, max_depth):
    if not (np.all(np.isfinite(prob.out_hi)) and np.all(np.isfinite(prob.out_lo))):
        raise CertificationError("certified bounds: some entry could not be bounded (M not provably invertible)")
    A_lo, A_hi = np.zeros((2 * m, 2 * m)), np.zeros((2 * m, 2 * m))
    A_lo[:m, m:] = A_hi[:m, m:] = np.eye(m)
    B_lo, B_hi = np.zeros((2 * m, m)), np.zeros((2 * m, m))
    for e, (blk, i, j) in enumerate(prob.entries):
        lo, hi = prob.out_lo[e], prob.out_hi[e]
        if blk == "B":
            B_lo[m + i, j] = B_lo[m + j, i] = lo  # M^-1 is symmetric
            B_hi[m + i, j] = B_hi[m + j, i] = hi
        elif blk == "Av":
            A_lo[m + i, m + j], A_hi[m + i, m + j] = lo, hi
        else:
            A_lo[m + i, j], A_hi[m + i, j] = lo, hi
    return CertifiedEnclosure(A_lo, A_hi, B_lo, B_hi, n_boxes, seconds, max_depth)
