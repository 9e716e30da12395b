"""Finding the extremes of the Jacobian entries: sampling, exact inner maxima, local search.

Used by :func:`polyrob.pldi.bound_pldi`; see there for the method.
"""

from __future__ import annotations

import os

import numpy as np
from scipy import optimize
from scipy.stats import qmc

from .domain import Domain
from .extremes import box_maximum, polynomial_coefficients


class Problem:
    """The robot, the domain and the entry layout shared by the steps below."""

    def __init__(self, robot, domain: Domain):
        self.robot, self.domain = robot, domain
        m = self.m = robot.m
        rows = np.arange(m, 2 * m)
        # every entry that can vary: rows m..2m-1 of A (all columns) and of B
        self.all_index = np.array(
            [(0, r, c) for r in rows for c in range(2 * m)] + [(1, r, c) for r in rows for c in range(m)]
        )
        self.lo, self.hi = domain.lower, domain.upper
        self.t_centre = 0.5 * (domain.qdot_lower + domain.qdot_upper)
        self.t_scale = 0.5 * (domain.qdot_upper - domain.qdot_lower)
        self.u_centre = 0.5 * (domain.u_lower + domain.u_upper)
        self.u_scale = 0.5 * (domain.u_upper - domain.u_lower)

    def entries_at(self, q, qdot, u, index=None) -> np.ndarray:
        """Entries (n, k) of the Jacobians at ``n`` points."""
        A, B = self.robot.jacobians_batch(q, qdot, u)
        idx = self.all_index if index is None else index
        out = np.empty((len(q), len(idx)))
        isA = idx[:, 0] == 0
        out[:, isA] = A[:, idx[isA, 1], idx[isA, 2]]
        out[:, ~isA] = B[:, idx[~isA, 1], idx[~isA, 2]]
        return out


def dropped_positions(problem: Problem, rng) -> tuple[int, ...]:
    """Position coordinates on which no Jacobian entry depends (numerically)."""
    d = problem.domain
    m = problem.m
    base = np.column_stack(d.sample(6, method="uniform", seed=rng.integers(2**31)))
    dropped = []
    for j in range(m):
        if d.q_upper[j] == d.q_lower[j]:
            dropped.append(j)
            continue
        pts = np.repeat(base, 5, axis=0)
        # random values, not a uniform grid: a grid over [-2 pi, 2 pi] aliases
        # the 2 q terms of a rotating inertia into identical values
        pts[:, j] = rng.uniform(d.q_lower[j], d.q_upper[j], len(pts))
        vals = problem.entries_at(pts[:, :m], pts[:, m : 2 * m], pts[:, 2 * m :]).reshape(len(base), 5, -1)
        spread = np.abs(vals - vals[:, :1]).max()
        if spread <= 1e-10 * max(1.0, np.abs(vals).max()):
            dropped.append(j)
    return tuple(dropped)


def position_design(problem: Problem, n: int, dropped, seed) -> np.ndarray:
    """Sobol' points over the positions that matter, plus the corners of their box."""
    d = problem.domain
    m = problem.m
    active = [j for j in range(m) if j not in dropped]
    q = np.tile(0.5 * (d.q_lower + d.q_upper), (n, 1))
    if not active:
        return q[:1]
    lo, hi = d.q_lower[active], d.q_upper[active]
    unit = qmc.Sobol(len(active), scramble=True, seed=seed).random_base2(int(np.ceil(np.log2(max(n, 2)))))
    q = np.tile(0.5 * (d.q_lower + d.q_upper), (len(unit), 1))
    q[:, active] = lo + unit * (hi - lo)
    if len(active) <= 10:
        corners = np.array(np.meshgrid(*[[0.0, 1.0]] * len(active))).reshape(len(active), -1).T
        qc = np.tile(q[0], (len(corners), 1))
        qc[:, active] = lo + corners * (hi - lo)
        q = np.vstack([qc, q])
    return q


def pilot(problem: Problem, seed, n=4096):
    """Random Jacobians: which entries vary, their scale, the principal directions,
    and the points themselves (extra starts for the local search)."""
    q, qdot, u = problem.domain.sample(n, method="uniform", seed=seed)
    vals = problem.entries_at(q, qdot, u)
    spread = vals.max(axis=0) - vals.min(axis=0)
    scale_all = np.maximum(np.abs(vals).max(axis=0), 1e-300)
    varying = spread > 1e-12 * np.maximum(1.0, scale_all)
    return vals, varying, np.hstack([q, qdot, u])


def support_pass(problem: Problem, q, directions, index, progress, workers):
    """Max over the velocity/torque box of ``d . p`` for each direction, per ``q`` chunk.

    Returns the best value per direction and its witness ``(q, qdot, u)``.
    """
    m = problem.m
    t_active = problem.t_scale > 0
    u_active = problem.u_scale > 0
    chunks = np.array_split(np.arange(len(q)), max(1, int(np.ceil(len(q) / 128))))

    def entries(qq, qd, uu):
        return problem.entries_at(qq, qd, uu, index)

    def run(chunk):
        c, a, b, Q = polynomial_coefficients(
            entries, q[chunk], problem.t_centre, problem.t_scale, problem.u_centre, problem.u_scale
        )
        D = directions.T  # (k, D)
        val, t, u = box_maximum(c @ D, a @ D, b @ D, Q @ D, t_active, u_active)
        n_best = np.argmax(val, axis=0)
        cols = np.arange(val.shape[1])
        return val[n_best, cols], q[chunk][n_best], t[n_best, cols], u[n_best, cols]

    results = parallel_map(run, chunks, workers, progress, "bounding")
    vals = np.array([r[0] for r in results])  # (chunks, D)
    order = np.argsort(-vals, axis=0)[:3]  # the three best chunks per direction
    cols = np.arange(vals.shape[1])

    def witness_of(rank):
        chunk_of = order[min(rank, len(order) - 1)]
        wq = np.array([results[b][1][c] for c, b in enumerate(chunk_of)]).reshape(len(cols), m)
        wt = np.array([results[b][2][c] for c, b in enumerate(chunk_of)]).reshape(len(cols), m)
        wu = np.array([results[b][3][c] for c, b in enumerate(chunk_of)]).reshape(len(cols), m)
        return np.hstack([wq, problem.t_centre + problem.t_scale * wt, problem.u_centre + problem.u_scale * wu])

    value = vals[order[0], cols]
    # best witness first, then the best of two other chunks: extra starts for
    # the local search where the landscape turns out rough
    starts = np.stack([witness_of(r) for r in range(3)], axis=1)
    return value, starts


def refine(problem: Problem, directions, values, starts, index, dropped, progress, workers, maxiter=200):
    """Bounded local search (L-BFGS-B) from each witness; never lowers a support value."""
    m = problem.m
    lo, hi = problem.lo.copy(), problem.hi.copy()
    free = hi > lo
    free[list(dropped)] = False
    nfree = int(free.sum())
    span = np.where(free, hi - lo, 1.0)

    def local_search(k, x0):
        d = directions[k]
        scale = max(abs(values[k]), 1e-12)
        step = 1e-6
        pos = np.flatnonzero(free)

        def fun(y):
            x = x0.copy()
            x[free] = y
            # value and central-difference gradient in one batched evaluation
            pts = np.tile(x, (1 + 2 * nfree, 1))
            h = step * span[pos]
            pts[1 + np.arange(nfree), pos] += h
            pts[1 + nfree + np.arange(nfree), pos] -= h
            pts = np.clip(pts, lo, hi)
            vals = problem.entries_at(pts[:, :m], pts[:, m : 2 * m], pts[:, 2 * m :], index) @ d
            dh = pts[1 + np.arange(nfree), pos] - pts[1 + nfree + np.arange(nfree), pos]
            grad = (vals[1 : 1 + nfree] - vals[1 + nfree :]) / np.where(dh > 0, dh, 1.0)
            return -vals[0] / scale, -grad / scale

        res = optimize.minimize(
            fun, x0[free], jac=True, method="L-BFGS-B", bounds=list(zip(lo[free], hi[free])),
            options={"maxiter": maxiter, "ftol": 1e-14, "gtol": 1e-11},
        )
        x = x0.copy()
        x[free] = np.clip(res.x, lo[free], hi[free])
        return float(problem.entries_at(x[None, :m], x[None, m : 2 * m], x[None, 2 * m :], index)[0] @ d), x

    def refine_one(k):
        best_val, best_x = values[k], starts[k, 0]
        if nfree == 0:
            return best_val, best_x
        val, x = local_search(k, starts[k, 0])
        if val > best_val:
            gain = val - best_val
            best_val, best_x = val, x
            # a large gain says the samples missed a peak: try the other starts
            if gain > 1e-3 * max(abs(best_val), 1e-12):
                for x0 in starts[k, 1:]:
                    val, x = local_search(k, x0)
                    if val > best_val:
                        best_val, best_x = val, x
        return best_val, best_x

    chunks = [[k] for k in range(len(directions))]
    out = parallel_map(lambda ks: [refine_one(k) for k in ks], chunks, workers, progress, "refining")
    new_values = np.array([o[0][0] for o in out])
    new_witness = np.array([o[0][1] for o in out])
    return new_values, new_witness


_FORK_STATE: dict = {}


def _call_in_fork(i):
    return _FORK_STATE["fn"](_FORK_STATE["items"][i])


def parallel_map(fn, items, workers, progress, label):
    """Map over items on ``workers`` forked processes (inheriting the robot), with a bar.

    BLAS runs single-threaded inside: the work is many small problems, and a
    multi-threaded OpenBLAS makes each L-BFGS-B step about 10x slower here.
    """
    from ._threads import single_blas_thread

    with single_blas_thread():
        return _parallel_map_inner(fn, items, workers, progress, label)


def _parallel_map_inner(fn, items, workers, progress, label):
    from tqdm.auto import tqdm

    workers = (os.cpu_count() or 1) if workers is None else workers
    bar = tqdm(total=len(items), desc=label, disable=not progress, leave=False)
    try:
        if workers <= 1 or len(items) < 4:
            out = []
            for it in items:
                out.append(fn(it))
                bar.update()
            return out
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor

        _FORK_STATE.update(fn=fn, items=items)
        try:
            with ProcessPoolExecutor(workers, mp_context=mp.get_context("fork")) as pool:
                out = []
                for r in pool.map(_call_in_fork, range(len(items)), chunksize=max(1, len(items) // (8 * workers))):
                    out.append(r)
                    bar.update()
                return out
        finally:
            _FORK_STATE.clear()
    finally:
        bar.close()
