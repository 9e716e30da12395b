"""Finding the extremes of the Jacobian entries: sampling, exact inner maxima, screens, local search.

Used by :func:`polyrob.bounds.pldi.bound_pldi`; see there for the method.
"""

from __future__ import annotations

import os

import numpy as np
from scipy import optimize
from scipy.stats import qmc

from polyrob.bounds.domain import Domain
from polyrob.bounds.extremes import box_maximum, polynomial_coefficients


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
    if not active:
        return (0.5 * (d.q_lower + d.q_upper))[None]
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
    """Random Jacobians (their values) and which entries vary."""
    q, qdot, u = problem.domain.sample(n, method="uniform", seed=seed)
    vals = problem.entries_at(q, qdot, u)
    spread = vals.max(axis=0) - vals.min(axis=0)
    scale_all = np.maximum(np.abs(vals).max(axis=0), 1e-300)
    varying = spread > 1e-12 * np.maximum(1.0, scale_all)
    return vals, varying


#: Relative size below which a coefficient is rounding (an entry that does not
#: depend on that velocity or torque).
DEPENDENCE_RTOL = 1e-10


def inner_maxima(problem: Problem, q, directions, index, progress, workers):
    """Max over the velocity/torque box of ``d . p`` at every position and direction.

    Returns
    -------
    vals : ndarray (N, D)
        Attained values (vertices and coordinate ascent beyond four joints,
        see :func:`polyrob.bounds.extremes.box_maximum`).
    depends : ndarray (D, 2m) bool
        Which velocities and torques each direction depends on at all.
    """
    t_active = problem.t_scale > 0
    u_active = problem.u_scale > 0
    chunks = np.array_split(np.arange(len(q)), max(1, int(np.ceil(len(q) / 128))))
    Dt = directions.T  # (k, D)

    def entries(qq, qd, uu):
        return problem.entries_at(qq, qd, uu, index)

    def run(chunk):
        c, a, b, Q = polynomial_coefficients(
            entries, q[chunk], problem.t_centre, problem.t_scale, problem.u_centre, problem.u_scale
        )
        c, a, b, Q = c @ Dt, a @ Dt, b @ Dt, Q @ Dt
        val, _, _ = box_maximum(c, a, b, Q, t_active, u_active)
        size = np.abs(c).max(axis=0)
        dep = np.vstack([np.abs(b).max(axis=0) + np.abs(Q).max(axis=(0, 2)), np.abs(a).max(axis=0)])  # (2m, D)
        return val, dep, size

    results = parallel_map(run, chunks, workers, progress, "bounding")
    vals = np.vstack([r[0] for r in results])
    size = np.max([r[2] for r in results], axis=0)
    dep = np.max([r[1] for r in results], axis=0)
    depends = (dep > DEPENDENCE_RTOL * np.maximum(size + dep.max(axis=0), 1e-300)).T
    return vals, depends


def screen(problem: Problem, directions, index, n: int, per_direction: int, seed, workers, around=None):
    """The best positions of ``n`` random points of the domain, per direction.

    One Jacobian per point (no inner maximisation) makes this ~40 times
    cheaper per position than :func:`inner_maxima`: a dense, coarse look for
    narrow peaks (near-singular mass matrices) that the position design
    straddles.  Each batch of 16,384 points gives its best point; the
    ``per_direction`` best batches' points are returned, positions (D, s, m).

    Parameters
    ----------
    around : ndarray (w, 3m), optional
        Draw the points near these (the witnesses found so far) instead of
        uniformly: each point is a random one of them plus a normal step of
        3-30 % of the domain's width (log-uniform), clipped into the domain.
        The peaks of the entries gather where the mass matrix is nearly
        singular, so the witnesses of all directions mark where to look.
    """
    m = problem.m
    batches = max(per_direction, int(np.ceil(n / 16384)))
    # directions along one entry (the intervals) need a column, not a product
    nonzero = directions != 0
    axis = np.flatnonzero(nonzero.sum(axis=1) == 1)
    other = np.setdiff1d(np.arange(len(directions)), axis)
    col = np.argmax(nonzero[axis], axis=1)
    coef = directions[axis, col]

    def run(b):
        if around is None:
            q, qdot, u = problem.domain.sample(16384, method="uniform", seed=[seed, b])
        else:
            rng = np.random.default_rng([seed, b])
            base = around[rng.integers(len(around), size=16384)]
            sigma = np.exp(rng.uniform(np.log(0.03), np.log(0.3), size=(16384, 1)))
            step = rng.standard_normal(base.shape) * sigma * (problem.hi - problem.lo)
            x = np.clip(base + step, problem.lo, problem.hi)
            q, qdot, u = x[:, :m], x[:, m : 2 * m], x[:, 2 * m :]
        e = problem.entries_at(q, qdot, u, index)
        v = np.empty((len(q), len(directions)))
        v[:, axis] = e[:, col] * coef
        v[:, other] = e @ directions[other].T
        arg = np.argmax(v, axis=0)
        return v[arg, np.arange(len(directions))], q[arg]

    out = parallel_map(run, list(range(batches)), workers, False, "screening")
    vals = np.array([o[0] for o in out])  # (batches, D)
    pos = np.array([o[1] for o in out])  # (batches, D, m)
    top = np.argsort(-vals, axis=0)[:per_direction]  # (s, D)
    return np.moveaxis(pos[top, np.arange(len(directions))[None]], 0, 1).reshape(len(directions), -1, m)


def support_pass(problem: Problem, q, directions, index, progress, workers, n_starts: int = 8, extra=None):
    """Max over the velocity/torque box of ``d . p`` for each direction, and starts.

    Parameters
    ----------
    n_starts : int
        Peaks of the sampled landscape kept per direction as starts.
    extra : ndarray (D, s, m), optional
        More start positions per direction (from :func:`screen`).

    Returns
    -------
    value : ndarray (D,)
        The best value per direction.
    starts : ndarray (D, S, 3m)
        Points ``(q, qdot, u)``, best first: the positions are the highest
        peaks of the sampled landscape (:func:`landscape_peaks`) and the extra
        ones, the velocities and torques their exact maximisers.
    depends : ndarray (D, 2m) bool
        Which velocities and torques each direction depends on at all.
    """
    vals, depends = inner_maxima(problem, q, directions, index, progress, workers)
    positions = q[landscape_peaks(problem, q, vals, n_starts)]  # (D, S, m)
    if extra is not None:
        positions = np.concatenate([positions, extra], axis=1)
    starts, start_vals = exact_witnesses(problem, positions, directions, index, workers)
    return np.maximum(vals.max(axis=0), start_vals[:, 0]), starts, depends


def landscape_peaks(problem: Problem, q, vals, n: int, neighbours: int | None = None) -> np.ndarray:
    """The ``n`` highest sampled local maxima per direction: indices (D, n) into ``q``.

    A sample is a peak when no one of its nearest neighbours (in the
    position box scaled to the unit cube) has a higher value (the
    topographical start selection of Toern and Viitanen); starting one local
    search per peak, rather than several from the best samples, which mostly
    lie on the same hill, reaches the separate hills of a many-peaked entry.
    Directions with fewer peaks repeat their best one.
    """
    from scipy.spatial import cKDTree

    N, D = vals.shape
    span = problem.hi[: problem.m] - problem.lo[: problem.m]
    moving = np.ptp(q, axis=0) > 0
    best = np.argmax(vals, axis=0)
    if N < 3 or not moving.any():
        return np.tile(best[:, None], (1, n))
    if neighbours is None:
        neighbours = 2 * int(moving.sum())
    neighbours = min(neighbours, N - 1)
    unit = (q[:, moving] - problem.lo[: problem.m][moving]) / span[moving]
    _, nb = cKDTree(unit).query(unit, neighbours + 1)
    nb = nb[:, 1:]
    score = np.empty_like(vals)
    for block in np.array_split(np.arange(D), max(1, D // 32)):  # (N, neighbours, 32) at a time
        v = vals[:, block]
        peak = v >= v[nb].max(axis=1)
        score[:, block] = np.where(peak, v, -np.inf)
    top = np.argsort(-score, axis=0)[:n].T  # (D, n)
    valid = np.isfinite(np.take_along_axis(score.T, top, axis=1))
    return np.where(valid, top, best[:, None])


def exact_witnesses(problem: Problem, positions, directions, index, workers):
    """The exact maximiser over the velocity/torque box at given positions, per direction.

    Parameters
    ----------
    positions : ndarray (D, S, m)
        ``S`` positions for each of the ``D`` directions.

    Returns
    -------
    points : ndarray (D, S, 3m)
        ``(q, qdot, u)``, per direction sorted best first.
    values : ndarray (D, S)
    """
    m = problem.m
    D, S, _ = positions.shape
    t_active = problem.t_scale > 0
    u_active = problem.u_scale > 0
    pair_dir = np.repeat(np.arange(D), S)
    pair_q = positions.reshape(D * S, m)

    def run(pairs):
        qq = pair_q[pairs]
        c, a, b, Q = polynomial_coefficients(
            lambda x, y, z: problem.entries_at(x, y, z, index),
            qq, problem.t_centre, problem.t_scale, problem.u_centre, problem.u_scale,
        )
        d = directions[pair_dir[pairs]]  # one polynomial per pair
        val, t, u = box_maximum(
            np.einsum("nk,nk->n", c, d)[:, None], np.einsum("nmk,nk->nm", a, d)[..., None],
            np.einsum("nmk,nk->nm", b, d)[..., None], np.einsum("nijk,nk->nij", Q, d)[..., None],
            t_active, u_active, exact=True,
        )
        x = np.hstack([qq, problem.t_centre + problem.t_scale * t[:, 0], problem.u_centre + problem.u_scale * u[:, 0]])
        return val[:, 0], x

    chunks = np.array_split(np.arange(D * S), max(1, int(np.ceil(D * S / 64))))
    out = parallel_map(run, chunks, workers, False, "witnesses")
    vals = np.concatenate([o[0] for o in out]).reshape(D, S)
    points = np.vstack([o[1] for o in out]).reshape(D, S, 3 * m)
    order = np.argsort(-vals, axis=1, kind="stable")
    return np.take_along_axis(points, order[..., None], axis=1), np.take_along_axis(vals, order, axis=1)


def cross_seed(problem: Problem, directions, values, witnesses, index, dropped, depends, progress, workers,
               rounds: int = 3):
    """Search each direction again from the other directions' witnesses where those are higher.

    The entries share their sharp peaks (where the mass matrix is nearly
    singular, ``M^-1`` and everything it multiplies is large), so the position
    where one direction's maximum was found is often a better start for
    another than any of its own.  Repeats while something improves.
    """
    values, witnesses = values.copy(), witnesses.copy()
    m = problem.m
    for _ in range(rounds):
        q = np.unique(witnesses[:, :m], axis=0)
        vals, _ = inner_maxima(problem, q, directions, index, False, workers)  # (W, D)
        best = np.argmax(vals, axis=0)
        better = np.flatnonzero(vals[best, np.arange(len(directions))] > values + 1e-9 * (1.0 + np.abs(values)))
        if not better.size:
            break
        starts, start_vals = exact_witnesses(problem, q[best[better]][:, None], directions[better], index, workers)
        v_ref, w_ref = refine(problem, directions[better], start_vals[:, 0], starts, index, dropped, progress,
                              workers, depends[better])
        up = v_ref > values[better]
        values[better[up]], witnesses[better[up]] = v_ref[up], w_ref[up]
    return values, witnesses


def refine(problem: Problem, directions, values, starts, index, dropped, progress, workers, depends=None,
           maxiter=200):
    """Bounded local search (L-BFGS-B) from every start; never lowers a support value.

    Each search moves the positions that matter and only the velocities and
    torques the direction depends on (``depends`` (D, 2m); all by default).
    The best point found is then checked with the exact maximum over the
    velocity/torque box at its position, and searched from again if that is higher.
    """
    m = problem.m
    lo, hi = problem.lo.copy(), problem.hi.copy()
    q_free = hi > lo
    q_free[list(dropped)] = False
    q_free[m:] = False
    span = np.where(hi > lo, hi - lo, 1.0)
    if depends is None:
        depends = np.ones((len(directions), 2 * m), bool)
    t_active = problem.t_scale > 0
    u_active = problem.u_scale > 0

    def local_search(k, x0, free, coarse=False):
        d = directions[k]
        scale = max(abs(values[k]), 1e-12)
        step = 1e-6
        pos = np.flatnonzero(free)
        nfree = len(pos)

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
            # a coarse search only ranks its start; the best is then polished
            options={"maxiter": maxiter, "ftol": 1e-9, "gtol": 1e-6} if coarse
            else {"maxiter": maxiter, "ftol": 1e-14, "gtol": 1e-11},
        )
        x = x0.copy()
        x[free] = np.clip(res.x, lo[free], hi[free])
        return float(problem.entries_at(x[None, :m], x[None, m : 2 * m], x[None, 2 * m :], index)[0] @ d), x

    def exact_inner(k, x):
        """The exact maximum over the velocity/torque box at the position of ``x``."""
        c, a, b, Q = polynomial_coefficients(
            lambda qq, qd, uu: problem.entries_at(qq, qd, uu, index),
            x[None, :m], problem.t_centre, problem.t_scale, problem.u_centre, problem.u_scale,
        )
        d = directions[k][:, None]
        _, t, u = box_maximum(c @ d, a @ d, b @ d, Q @ d, t_active, u_active, exact=True)
        y = np.concatenate([x[:m], problem.t_centre + problem.t_scale * t[0, 0],
                            problem.u_centre + problem.u_scale * u[0, 0]])
        return float(problem.entries_at(y[None, :m], y[None, m : 2 * m], y[None, 2 * m :], index)[0] @ directions[k]), y

    def refine_one(k):
        best_val, best_x = values[k], starts[k, 0]
        free = q_free.copy()
        free[m:] = depends[k] & np.concatenate([t_active, u_active])
        if not free.any():
            return best_val, best_x
        tried, found = [], []
        for x0 in starts[k]:
            if any(np.array_equal(x0, y) for y in tried):
                continue
            tried.append(x0)
            found.append(local_search(k, x0, free, coarse=len(starts[k]) > 1))
        val, x = max(found, key=lambda f: f[0])
        if len(found) > 1:
            val, x = local_search(k, x, free)
        if val > best_val:
            best_val, best_x = val, x
        # the local search may leave the velocities at a lower face maximum
        val, x = exact_inner(k, best_x)
        if val > best_val + 1e-12 * (1.0 + abs(best_val)):
            val, x = local_search(k, x, free)
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
    from polyrob._threads import single_blas_thread

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
