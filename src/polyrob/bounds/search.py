"""Finding the extremes of the Jacobian entries: sampling, exact inner maxima, start positions.

Used by :func:`polyrob.bounds.pldi.bound_pldi` (see there for the method);
the local search from the starts found here is :mod:`polyrob.bounds.local_search`.
The parallel steps run their tasks on a :class:`~polyrob.bounds.parallel.WorkerPool`
whose shared state is the :class:`Problem`: each task is a module-level
function ``fn(problem, item)``.
"""

from __future__ import annotations

import numpy as np
from scipy.stats import qmc

from polyrob.bounds.extremes import box_maximum, box_upper_bound, polynomial_coefficients
from polyrob.bounds.witnesses import exact_witnesses
from polyrob.domains.torque_box import Domain
from polyrob.errors import BoundsError

__all__ = [
    "Problem",
    "dropped_positions",
    "position_design",
    "pilot",
    "check_mass_matrices",
    "inner_maxima",
    "support_pass",
    "landscape_peaks",
    "exact_witnesses",
    "DEPENDENCE_RTOL",
]


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
        # the box the search moves in: (q, qdot, w) with w the torque u of a
        # Domain, or the acceleration of a TaskDomain (u by inverse dynamics)
        self.lo, self.hi = domain.lower, domain.upper
        self.t_centre = 0.5 * (domain.qdot_lower + domain.qdot_upper)
        self.t_scale = 0.5 * (domain.qdot_upper - domain.qdot_lower)
        self.u_centre = 0.5 * (self.lo[2 * m :] + self.hi[2 * m :])
        self.u_scale = 0.5 * (self.hi[2 * m :] - self.lo[2 * m :])

        # the true robots the bounds hold for (an inner loop's payload and model error
        # ranges, sampled: see polyrob.model.inner); one, the robot itself, otherwise
        variants = getattr(robot, "variants", None)
        self.variants = tuple(variants()) if callable(variants) else (robot,)
        self.domains = tuple(_domain_of(domain, r) for r in self.variants)

    def entries_at(self, q, qdot, w, index=None, variant: int = 0) -> np.ndarray:
        """Entries (n, k) of the Jacobians at ``n`` box points ``(q, qdot, w)`` (``u = domain.inputs(q, qdot, w)``)."""
        robot, domain = self.variants[variant], self.domains[variant]
        A, B = robot.jacobians_batch(q, qdot, domain.inputs(q, qdot, w))
        return self.entries_from(A, B, index)

    def along(self, q, qdot, w, index, d, variant: int | None = None) -> np.ndarray:
        """``max`` over the variants (or of one ``variant``) of the entries times ``d`` (k,) or (k, D): (n,) or (n, D)."""
        if variant is not None:
            return self.entries_at(q, qdot, w, index, variant) @ d
        return np.max([self.entries_at(q, qdot, w, index, i) @ d for i in range(len(self.variants))], axis=0)

    def best_variant(self, x, index, d) -> tuple[float, int]:
        """The largest ``d . p`` over the variants at one point ``x = (q, qdot, w)``, and the variant attaining it."""
        m = self.m
        vals = [float(self.along(x[None, :m], x[None, m : 2 * m], x[None, 2 * m :], index, d, i)[0])
                for i in range(len(self.variants))]  # fmt: skip
        i = int(np.argmax(vals))
        return vals[i], i

    def entries_from(self, A, B, index=None) -> np.ndarray:
        """Entries (n, k) of given Jacobians ``A`` (n, 2m, 2m), ``B`` (n, 2m, m)."""
        idx = self.all_index if index is None else index
        out = np.empty((len(A), len(idx)))
        isA = idx[:, 0] == 0
        out[:, isA] = A[:, idx[isA, 1], idx[isA, 2]]
        out[:, ~isA] = B[:, idx[~isA, 1], idx[~isA, 2]]
        return out


def _domain_of(domain, robot):
    """The domain whose inputs map through ``robot`` (a task domain's inverse dynamics are the robot's)."""
    if getattr(domain, "robot", None) is None or domain.robot is robot:
        return domain
    from dataclasses import replace

    return replace(domain, robot=robot)


def dropped_positions(problem: Problem, rng) -> tuple[int, ...]:
    """Position coordinates on which no Jacobian entry depends (numerically)."""
    d = problem.domain
    m = problem.m
    base = d.sample_box(6, method="uniform", seed=rng.integers(2**31))
    dropped = []
    for j in range(m):
        if d.q_upper[j] == d.q_lower[j]:
            dropped.append(j)
            continue
        pts = np.repeat(base, 5, axis=0)
        # random values, not a uniform grid: a grid over [-2 pi, 2 pi] aliases
        # the 2 q terms of a rotating inertia into identical values
        pts[:, j] = rng.uniform(d.q_lower[j], d.q_upper[j], len(pts))
        vals = np.concatenate(
            [
                problem.entries_at(pts[:, :m], pts[:, m : 2 * m], pts[:, 2 * m :], None, i)
                for i in range(len(problem.variants))
            ]
        ).reshape(-1, 5, len(problem.all_index))
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
    """Random Jacobians (their values) and which entries vary.

    The same samples check that ``M(q)`` is positive definite
    (:func:`check_mass_matrices`).
    """
    vals = []
    for robot, domain in zip(problem.variants, problem.domains):
        q, qdot, u = domain.sample(n // len(problem.variants) or 1, method="uniform", seed=seed)
        try:
            A, B = robot.jacobians_batch(q, qdot, u)
        except np.linalg.LinAlgError:  # an analytic M(q) that is singular somewhere
            A = B = None
        if getattr(robot, "jacobians_are_factors", False):
            pass  # a computed-torque factor's B is no inverse inertia; its robot's M was checked with its own loop's PLDI
        elif getattr(robot, "inner", "none") == "computed-torque":
            # B = M^-1 M_hat is no inverse inertia (not symmetric once a payload differs): check the true M itself
            _check_true_mass_matrices(robot.true_robot, q)
        else:
            check_mass_matrices(robot, q, None if B is None else B[:, problem.m :, :])
        vals.append(problem.entries_from(A, B))
    vals = np.vstack(vals)
    spread = vals.max(axis=0) - vals.min(axis=0)
    # roundoff is relative to the matrix an entry is computed in, not to the entry: behind
    # computed torque B = M_hat^-1 M = s I, whose off-diagonal entries spread by ~1e-12 of its
    # diagonal (ur10), so an entry varies when its spread exceeds 1e-10 of its matrix's scale
    scale = np.abs(vals).max(axis=0)
    isA = problem.all_index[:, 0] == 0
    block = np.where(isA, scale[isA].max(initial=0.0), scale[~isA].max(initial=0.0))
    varying = spread > 1e-10 * np.maximum(1.0, block)
    return vals, varying


def _check_true_mass_matrices(robot, q) -> None:
    """:func:`check_mass_matrices` of ``robot`` (a URDF robot) at ``q``, from its own ``M(q)``."""
    M = np.array([robot.mass_matrix(qi) for qi in q])
    try:
        minv = np.linalg.inv(M) if np.all(np.isfinite(M)) else None
    except np.linalg.LinAlgError:
        minv = None
    check_mass_matrices(robot, q, minv)


def check_mass_matrices(robot, q, minv=None) -> None:
    """Refuse a robot whose ``M(q)`` is not positive definite at sampled positions.

    Parameters
    ----------
    robot : Manipulator
    q : ndarray (n, m)
    minv : ndarray (n, m, m), optional
        ``M(q)^-1`` at ``q`` (the ``B`` block), when already computed.

    Raises
    ------
    BoundsError
        Naming the first configuration where ``M`` is singular, indefinite
        or not finite.
    """
    if minv is not None:
        finite = np.all(np.isfinite(minv), axis=(1, 2))
        ok = finite.copy()
        if finite.any():
            sym = 0.5 * (minv[finite] + np.swapaxes(minv[finite], 1, 2))
            ok[finite] = np.linalg.eigvalsh(sym)[:, 0] > 0
        if ok.all():
            return
        bad = int(np.flatnonzero(~ok)[0])
    else:
        bad = None
        for i, qi in enumerate(q):
            M = robot.mass_matrix(qi)
            if not np.all(np.isfinite(M)) or np.linalg.eigvalsh(0.5 * (M + M.T))[0] <= 0:
                bad = i
                break
        if bad is None:
            raise BoundsError(
                f"{robot.name}: M(q)^-1 cannot be computed, though M(q) is positive definite at every sampled position"
            )
    M = robot.mass_matrix(q[bad])
    eig = np.linalg.eigvalsh(0.5 * (M + M.T)) if np.all(np.isfinite(M)) else np.array([np.nan])
    config = ", ".join(f"{n}={x:.4g}" for n, x in zip(robot.joint_names, q[bad]))
    raise BoundsError(
        f"{robot.name}: the mass matrix M(q) is not positive definite at q = ({config}) "
        f"(smallest eigenvalue {eig[0]:.3g}): the robot's inertial data are not physical"
    )


#: Relative size below which a coefficient is rounding (an entry that does not
#: depend on that velocity or torque).
DEPENDENCE_RTOL = 1e-10


def _inner_task(problem: Problem, item):
    q, directions, index, floor, variants, top_only = item
    out = []
    for i in range(variants):
        c, a, b, Q = polynomial_coefficients(
            lambda qq, qd, uu, i=i: problem.entries_at(qq, qd, uu, index, i),
            q,
            problem.t_centre,
            problem.t_scale,
            problem.u_centre,
            problem.u_scale,
        )
        Dt = directions.T  # (k, D)
        c, a, b, Q = c @ Dt, a @ Dt, b @ Dt, Q @ Dt
        t_active, u_active = problem.t_scale > 0, problem.u_scale > 0
        if floor is None and not top_only:
            val, _, _ = box_maximum(c, a, b, Q, t_active, u_active)
        else:  # the maximum only where the cheap bound exceeds the floor
            val = box_upper_bound(c, a, b, Q, t_active, u_active)
            low = floor
            if floor is None:  # the chunk's best upper bound, maximised, is attained: a floor of its maximum
                d = np.arange(val.shape[1])
                n = np.argmax(val, axis=0)
                sub = (c[n, d], a[n, :, d], b[n, :, d], Q[n, :, :, d])
                low = val[n, d] = box_maximum(*(x[..., None] for x in sub), t_active, u_active)[0][:, 0]
            n, d = np.nonzero(val > low)
            if n.size:
                sub = (c[n, d], a[n, :, d], b[n, :, d], Q[n, :, :, d])
                val[n, d] = box_maximum(*(x[..., None] for x in sub), t_active, u_active)[0][:, 0]
        size = np.abs(c).max(axis=0)
        dep = np.vstack([np.abs(b).max(axis=0) + np.abs(Q).max(axis=(0, 2)), np.abs(a).max(axis=0)])  # (2m, D)
        out.append((val, dep, size))
    return tuple(np.max([o[j] for o in out], axis=0) for j in range(3))


def inner_maxima(problem: Problem, q, directions, index, progress, pool, floor=None, variants=None, top_only=False):
    """Max over the velocity/torque box of ``d . p`` at every position and direction.

    ``variants``: the first that many true robots (default all); the
    design's landscape is drawn on the first alone (:func:`support_pass`).

    ``top_only``: only the largest value per direction is wanted exactly
    (one start per direction): each chunk of positions maximises its best
    upper bound first and uses that value as the floor below.

    ``floor`` (D,): only values above it are wanted (a verification looks
    for positions that beat the support values); a position whose cheap
    upper bound (:func:`~polyrob.bounds.extremes.box_upper_bound`) is at
    most the floor keeps that bound instead of its maximum.

    Returns
    -------
    vals : ndarray (N, D)
        Attained values (vertices and coordinate ascent beyond four joints,
        see :func:`polyrob.bounds.extremes.box_maximum`), or the upper bound
        at most ``floor``.
    depends : ndarray (D, 2m) bool
        Which velocities and torques each direction depends on at all.
    """
    chunks = np.array_split(np.arange(len(q)), max(1, int(np.ceil(len(q) / 128))))
    variants = len(problem.variants) if variants is None else int(variants)
    items = [(q[c], directions, index, floor, variants, top_only) for c in chunks]
    results = pool.map(_inner_task, items, progress=progress, label="bounding")
    vals = np.vstack([r[0] for r in results])
    size = np.max([r[2] for r in results], axis=0)
    dep = np.max([r[1] for r in results], axis=0)
    depends = (dep > DEPENDENCE_RTOL * np.maximum(size + dep.max(axis=0), 1e-300)).T
    return vals, depends


def support_pass(problem: Problem, q, directions, index, progress, pool, n_starts: int = 8, extra=None):
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
    # the landscape of the first true robot alone: an inner loop's true robots are the same arm with
    # masses a few % apart, their peaks lie at the same positions, and the starts' exact witnesses, the
    # local searches and the verification take every true robot (five times fewer Jacobians here)
    # with one start per direction the landscape's highest peak is its largest value: the positions below
    # a floor attained in their chunk keep their upper bound (these maxima were most of the pass's time)
    vals, depends = inner_maxima(problem, q, directions, index, progress, pool, variants=1, top_only=n_starts == 1)
    positions = q[landscape_peaks(problem, q, vals, n_starts)]  # (D, S, m)
    if extra is not None:
        positions = np.concatenate([positions, extra], axis=1)
    starts, start_vals = exact_witnesses(problem, positions, directions, index, pool)
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
