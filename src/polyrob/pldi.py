"""The PLDI: every Jacobian the robot can have inside the domain, bounded.

:func:`bound_pldi` takes a robot and a :class:`~polyrob.domain.Domain` and
returns a :class:`PLDI`: the nominal pair ``(A0, B0)`` at an equilibrium, the
interval of every entry of ``A`` and ``B`` (the paper's eq. 9 table), the
witnesses where each bound is attained, and a polytope (half-spaces, and
vertices where the dimension allows) that holds every Jacobian found.

How the bounds are found (``enclosure = "sampled"``):

1. position coordinates the dynamics do not depend on are detected and dropped;
2. the remaining positions are sampled with a scrambled Sobol' design plus the
   corners of their box; for each position the extremes over the
   velocity/torque box are exact (:mod:`polyrob.extremes`);
3. each extreme is refined by a bounded local search (L-BFGS-B over positions,
   velocities and torques), and the widening it brought is reported;
4. the support values along ``+-e_i`` (the intervals) and along the principal
   directions of the Jacobian cloud give the polytope's half-spaces;
   linear programs (HiGHS) give its bounding box, an interior point and,
   in up to :data:`VERTEX_MAX_DIM` reduced dimensions, its vertices;
5. fresh random points of the domain check the coverage (it must be 1.0).

With ``certify=True`` the intervals are replaced by a guaranteed enclosure
computed by interval arithmetic (:mod:`polyrob.certify`); ``enclosure`` is
then ``"certified"``.

Examples
--------
>>> from polyrob import load_robot, Domain, bound_pldi
>>> robot = load_robot("planar_2r")
>>> pldi = bound_pldi(robot, Domain.from_robot(robot, u_max=0.0), samples=256, coverage=500, progress=False)
>>> pldi.enclosure, pldi.coverage
('sampled', 1.0)
>>> lo, hi = pldi.interval("b31")
>>> round(lo, 4), round(hi, 4)
(0.0286, 0.0312)
"""

from __future__ import annotations

import json
import os
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import optimize
from scipy.stats import qmc

from .domain import Domain
from .errors import BoundsError, CertificationError
from .extremes import box_maximum, polynomial_coefficients

__all__ = ["PLDI", "Polytope", "bound_pldi", "entry_name", "VERTEX_MAX_DIM"]

#: Vertices are enumerated when the Jacobian cloud spans at most this many dimensions.
VERTEX_MAX_DIM = 6
#: Relative tolerance for "inside" in the coverage check (rounding only).
COVERAGE_RTOL = 1e-9


def entry_name(matrix: str, row: int, col: int, n: int) -> str:
    """The paper's name of an entry (1-based): ``a32``, ``b41``; ``a10_11`` when n >= 10."""
    sep = "_" if n >= 10 else ""
    return f"{matrix.lower()}{row + 1}{sep}{col + 1}"


# --------------------------------------------------------------------------- results


@dataclass(frozen=True, eq=False)
class Polytope:
    """``{p : normals @ p <= offsets}`` over the varying entries ``p`` of a PLDI.

    Attributes
    ----------
    normals : ndarray (h, k)
    offsets : ndarray (h,)
    vertices : ndarray (v, k) or None
        Vertices, when the reduced dimension is at most :data:`VERTEX_MAX_DIM`.
    centre : ndarray (k,)
        Mean of the Jacobian cloud; ``p = centre + basis @ z`` are the reduced
        coordinates ``z``.
    basis : ndarray (k, r)
        Principal directions in which the Jacobians vary (normalised units).
    volume_hits, volume_samples : int
        Monte Carlo estimate of the volume of the polytope over that of the
        interval box, both cut by the reduced-coordinate subspace:
        ``volume_hits`` of ``volume_samples`` uniform points of the box lie
        in the polytope.
    """

    normals: np.ndarray
    offsets: np.ndarray
    vertices: np.ndarray | None
    centre: np.ndarray
    basis: np.ndarray
    volume_hits: int
    volume_samples: int

    @property
    def volume_ratio(self) -> float:
        """Estimated volume ratio polytope / interval box (0 when no point hit)."""
        return self.volume_hits / self.volume_samples if self.volume_samples else 1.0

    @property
    def volume_ratio_bound(self) -> float:
        """A 95 % upper bound of the ratio (the rule of three when no point hit)."""
        return max(self.volume_hits, 3) / self.volume_samples if self.volume_samples else 1.0

    @property
    def n_halfspaces(self) -> int:
        return len(self.offsets)

    @property
    def reduced_dim(self) -> int:
        return self.basis.shape[1]

    def contains(self, points, *, rtol: float = COVERAGE_RTOL) -> np.ndarray:
        """Whether points (n, k) satisfy every half-space (up to rounding)."""
        points = np.atleast_2d(points)
        slack = rtol * (1.0 + np.abs(self.offsets))
        return np.all(points @ self.normals.T <= self.offsets + slack, axis=1)


@dataclass(frozen=True, eq=False)
class PLDI:
    """Bounds of ``A = df/dx`` and ``B = df/du`` over a domain, and a polytope.

    Attributes
    ----------
    robot_name, robot_source : str
    domain : Domain
    nominal_point : dict
        ``q``, ``qdot``, ``u`` of the nominal (``None`` for the midpoint nominal).
    A0, B0 : ndarray
        The nominal pair.
    A_lower, A_upper, B_lower, B_upper : ndarray
        Entrywise bounds.
    entries : tuple of str
        Names of the entries that vary (``a32``, ``b41``, ...).
    entry_index : ndarray (k, 3)
        For each varying entry: matrix (0 = A, 1 = B), row, column.
    witness_lower, witness_upper : ndarray (k, 3m)
        A point ``(q, qdot, u)`` at which each sampled bound is attained.
    polytope : Polytope
        Holds every sampled Jacobian; its half-spaces are sampled supports.
    enclosure : {"sampled", "certified"}
        Whether the intervals are extremes found by search or proved.
    coverage : float
        Fraction of fresh random points whose Jacobians lie in the intervals and
        the polytope; ``coverage_points`` of them were drawn.
    refinement : ndarray (k,)
        Relative widening of each interval by the local search.
    dropped_q : tuple of int
        Position coordinates the dynamics do not depend on.
    info : dict
        Samples, timings and notes.
    """

    robot_name: str
    robot_source: str
    domain: Domain
    nominal_point: dict | None
    A0: np.ndarray
    B0: np.ndarray
    A_lower: np.ndarray
    A_upper: np.ndarray
    B_lower: np.ndarray
    B_upper: np.ndarray
    entries: tuple[str, ...]
    entry_index: np.ndarray
    witness_lower: np.ndarray
    witness_upper: np.ndarray
    polytope: Polytope
    enclosure: str
    coverage: float
    coverage_points: int
    refinement: np.ndarray
    dropped_q: tuple[int, ...]
    info: dict = field(default_factory=dict)

    # ------------------------------------------------------------------ views
    @property
    def m(self) -> int:
        return self.B0.shape[1]

    @property
    def robot(self):
        """The robot, loaded again from its source."""
        from .robots import load_robot

        return load_robot(self.robot_source if self.robot_source.endswith(".urdf") else self.robot_name)

    def entry_values(self, A, B) -> np.ndarray:
        """The varying entries of Jacobians ``A`` (n, 2m, 2m), ``B`` (n, 2m, m): (n, k)."""
        A, B = np.asarray(A), np.asarray(B)
        if A.ndim == 2:
            A, B = A[None], B[None]
        idx = self.entry_index
        out = np.empty((A.shape[0], len(idx)))
        isA = idx[:, 0] == 0
        out[:, isA] = A[:, idx[isA, 1], idx[isA, 2]]
        out[:, ~isA] = B[:, idx[~isA, 1], idx[~isA, 2]]
        return out

    @property
    def lower(self) -> np.ndarray:
        """Lower bounds of the varying entries (k,)."""
        return self.entry_values(self.A_lower, self.B_lower)[0]

    @property
    def upper(self) -> np.ndarray:
        return self.entry_values(self.A_upper, self.B_upper)[0]

    @property
    def nominal(self) -> np.ndarray:
        return self.entry_values(self.A0, self.B0)[0]

    def interval(self, name: str) -> tuple[float, float]:
        """``(lower, upper)`` of one entry by its paper name (``"a32"``)."""
        if name not in self.entries:
            raise BoundsError(f"no varying entry '{name}' (entries: {', '.join(self.entries)})")
        k = self.entries.index(name)
        return float(self.lower[k]), float(self.upper[k])

    def contains(self, A, B, *, rtol: float = COVERAGE_RTOL) -> np.ndarray:
        """Whether Jacobians lie inside the intervals (constant entries included)."""
        A, B = np.asarray(A), np.asarray(B)
        if A.ndim == 2:
            A, B = A[None], B[None]

        def inside(X, lo, hi):
            tol = rtol * (1.0 + np.maximum(np.abs(lo), np.abs(hi)))
            return np.all((X >= lo - tol) & (X <= hi + tol), axis=(1, 2))

        return inside(A, self.A_lower, self.A_upper) & inside(B, self.B_lower, self.B_upper)

    def table(self) -> str:
        """The paper-style table: entry, lower, upper, nominal, enclosure."""
        rows = [f"{'entry':<8}{'lower':>14}{'upper':>14}{'nominal':>14}  enclosure"]
        for name, lo, hi, nom in zip(self.entries, self.lower, self.upper, self.nominal):
            # "+ 0.0" prints a negative zero as 0
            rows.append(f"{name:<8}{lo + 0.0:>14.6g}{hi + 0.0:>14.6g}{nom + 0.0:>14.6g}  {self.enclosure}")
        return "\n".join(rows)

    # ------------------------------------------------------------------ serialisation
    _ARRAYS = ("A0", "B0", "A_lower", "A_upper", "B_lower", "B_upper", "entry_index",
               "witness_lower", "witness_upper", "refinement")

    def save(self, path) -> tuple[Path, Path]:
        """Write ``path`` (JSON, readable) and ``path`` with ``.npz`` (all arrays).

        Both are written to temporary files first and renamed, so an
        interrupted save leaves no half-written file.
        """
        path = Path(path)
        npz = path.with_suffix(".npz")
        meta = {
            "format": "polyrob.pldi/1",
            "robot": {"name": self.robot_name, "source": self.robot_source},
            "domain": self.domain.to_dict(),
            "nominal_point": self.nominal_point,
            "enclosure": self.enclosure,
            "coverage": self.coverage,
            "coverage_points": self.coverage_points,
            "dropped_q": list(self.dropped_q),
            "entries": [
                {"name": n, "lower": float(lo), "upper": float(hi), "nominal": float(nm)}
                for n, lo, hi, nm in zip(self.entries, self.lower, self.upper, self.nominal)
            ],
            "polytope": {
                "halfspaces": self.polytope.n_halfspaces,
                "vertices": None if self.polytope.vertices is None else len(self.polytope.vertices),
                "reduced_dim": self.polytope.reduced_dim,
                "volume_hits": self.polytope.volume_hits,
                "volume_samples": self.polytope.volume_samples,
            },
            "info": self.info,
            "arrays": npz.name,
        }
        arrays = {k: getattr(self, k) for k in self._ARRAYS}
        arrays.update(
            polytope_normals=self.polytope.normals,
            polytope_offsets=self.polytope.offsets,
            polytope_centre=self.polytope.centre,
            polytope_basis=self.polytope.basis,
        )
        if self.polytope.vertices is not None:
            arrays["polytope_vertices"] = self.polytope.vertices
        _atomic_write(npz, lambda f: np.savez_compressed(f, **arrays), binary=True)
        _atomic_write(path, lambda f: f.write(json.dumps(meta, indent=2, default=_json_default)))
        return path, npz

    @classmethod
    def load(cls, path) -> "PLDI":
        """Read a PLDI written by :meth:`save`."""
        path = Path(path)
        try:
            meta = json.loads(path.read_text())
            data = np.load(path.parent / meta["arrays"])
        except (OSError, ValueError, KeyError) as exc:
            raise BoundsError(f"{path}: not a PLDI file written by polyrob ({exc})") from None
        polytope = Polytope(
            normals=data["polytope_normals"],
            offsets=data["polytope_offsets"],
            vertices=data["polytope_vertices"] if "polytope_vertices" in data else None,
            centre=data["polytope_centre"],
            basis=data["polytope_basis"],
            volume_hits=meta["polytope"]["volume_hits"],
            volume_samples=meta["polytope"]["volume_samples"],
        )
        return cls(
            robot_name=meta["robot"]["name"],
            robot_source=meta["robot"]["source"],
            domain=Domain.from_dict(meta["domain"]),
            nominal_point=meta["nominal_point"],
            entries=tuple(e["name"] for e in meta["entries"]),
            polytope=polytope,
            enclosure=meta["enclosure"],
            coverage=meta["coverage"],
            coverage_points=meta["coverage_points"],
            dropped_q=tuple(meta["dropped_q"]),
            info=meta["info"],
            **{k: data[k] for k in cls._ARRAYS},
        )


def _json_default(obj):
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(f"cannot serialise {type(obj).__name__}")


def _atomic_write(path: Path, write, *, binary: bool = False) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb" if binary else "w") as f:
            write(f)
        os.chmod(tmp, 0o644)  # mkstemp makes it private; a result file is not
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


# --------------------------------------------------------------------------- bounding


class _Problem:
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


def _dropped_positions(problem: _Problem, rng) -> tuple[int, ...]:
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


def _position_design(problem: _Problem, n: int, dropped, seed) -> np.ndarray:
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


def _pilot(problem: _Problem, seed, n=4096):
    """Random Jacobians: which entries vary, their scale, the principal directions,
    and the points themselves (extra starts for the local search)."""
    q, qdot, u = problem.domain.sample(n, method="uniform", seed=seed)
    vals = problem.entries_at(q, qdot, u)
    spread = vals.max(axis=0) - vals.min(axis=0)
    scale_all = np.maximum(np.abs(vals).max(axis=0), 1e-300)
    varying = spread > 1e-12 * np.maximum(1.0, scale_all)
    return vals, varying, np.hstack([q, qdot, u])


def _principal_directions(vals: np.ndarray, scale: np.ndarray, max_dirs: int = 12):
    """Principal axes of the normalised cloud; rank ``r`` = directions that vary."""
    z = (vals - vals.mean(axis=0)) / scale
    _, s, vt = np.linalg.svd(z, full_matrices=False)
    r = int(np.sum(s > 1e-8 * s[0])) if s.size and s[0] > 0 else 0
    return vt[:r].T, vt[: min(r, max_dirs)]


def _support_pass(problem: _Problem, q, directions, index, progress, workers):
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

    results = _parallel_map(run, chunks, workers, progress, "bounding")
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


def _refine(problem: _Problem, directions, values, starts, index, dropped, progress, workers, maxiter=60):
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
            options={"maxiter": maxiter},
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
    out = _parallel_map(lambda ks: [refine_one(k) for k in ks], chunks, workers, progress, "refining")
    new_values = np.array([o[0][0] for o in out])
    new_witness = np.array([o[0][1] for o in out])
    return new_values, new_witness


_FORK_STATE: dict = {}


def _call_in_fork(i):
    return _FORK_STATE["fn"](_FORK_STATE["items"][i])


def _parallel_map(fn, items, workers, progress, label):
    """Map over items on ``workers`` forked processes (inheriting the robot), with a bar.

    BLAS runs single-threaded inside: the work is many small problems, and a
    multi-threaded OpenBLAS makes each L-BFGS-B step about 10x slower here.
    """
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
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


def _polytope(normals, offsets, n_box, cloud, scale, rng, n_mc=200_000) -> Polytope:
    """Reduced coordinates, LP bounding box, interior point, vertices and volume ratio."""
    from scipy.spatial import HalfspaceIntersection

    centre = cloud.mean(axis=0)
    basis_n, _ = _principal_directions(cloud, scale, max_dirs=0)
    basis = basis_n * scale[:, None]  # p = centre + basis @ z
    r = basis.shape[1]
    G = normals @ basis
    g = offsets - normals @ centre
    vertices = None
    if r == 0:
        return Polytope(normals, offsets, None, centre, basis, 0, 0)
    box_rows = np.arange(len(normals)) < n_box
    # Bounding box, in z, of the interval box cut by the reduced subspace
    # (2r LPs): the volume estimate samples it.
    box_z = []
    for i in range(r):
        bounds = []
        for sgn in (1.0, -1.0):
            c = np.zeros(r)
            c[i] = sgn
            res = optimize.linprog(c, A_ub=G[box_rows], b_ub=g[box_rows], bounds=[(None, None)] * r, method="highs")
            if res.status != 0:
                raise BoundsError(f"the polytope LP failed ({res.message})")
            bounds.append(res.x[i])
        box_z.append(sorted(bounds))
    box_z = np.array(box_z)
    # Interior point (Chebyshev centre) for the vertex enumeration.
    norms = np.linalg.norm(G, axis=1)
    res = optimize.linprog(
        np.r_[np.zeros(r), -1.0], A_ub=np.c_[G, norms], b_ub=g, bounds=[(None, None)] * r + [(0, None)],
        method="highs",
    )
    if r <= VERTEX_MAX_DIM and res.status == 0 and res.x[-1] > 1e-12:
        try:
            hs = HalfspaceIntersection(np.c_[G, -g], res.x[:r])
            vz = np.unique(np.round(hs.intersections, 12), axis=0)
            vertices = centre + vz @ basis.T
        except Exception:  # qhull fails on degenerate inputs: no vertices then
            vertices = None
    # Volume ratio against the interval box (lo <= centre + basis z <= hi), in z.
    z = box_z[:, 0] + rng.random((n_mc, r)) * (box_z[:, 1] - box_z[:, 0])
    in_poly = np.all(z @ G.T <= g + 1e-12, axis=1)
    in_box = np.all(z @ G[box_rows].T <= g[box_rows] + 1e-12, axis=1)
    return Polytope(normals, offsets, vertices, centre, basis, int(in_poly.sum()), int(in_box.sum()))


def _nominal(robot, domain: Domain, nominal):
    m = robot.m
    if isinstance(nominal, str) and nominal == "equilibrium":
        q0 = np.clip(np.zeros(m), domain.q_lower, domain.q_upper)
        qd0 = np.zeros(m)
        # u0 holds the arm still: the gravity torque g(q0) = -M(q0) qddot(q0, 0, 0)
        u0 = -robot.mass_matrix(q0) @ robot.acceleration(q0, qd0, np.zeros(m))
        u0[np.abs(u0) < 1e-12] = 0.0
        return {"q": q0, "qdot": qd0, "u": u0}
    if isinstance(nominal, str) and nominal == "midpoint":
        return None
    if isinstance(nominal, dict):
        return {k: np.asarray(nominal.get(k, np.zeros(m)), float) for k in ("q", "qdot", "u")}
    raise BoundsError(f"unknown nominal '{nominal}': use 'equilibrium', 'midpoint' or a dict with q, qdot, u")


def bound_pldi(
    robot,
    domain: Domain | None = None,
    *,
    samples: int | None = None,
    nominal="equilibrium",
    refine: bool = True,
    coverage: int = 10_000,
    certify: bool = False,
    certify_options: dict | None = None,
    seed: int = 0,
    workers: int | None = None,
    progress: bool | None = None,
) -> PLDI:
    """Bound the Jacobians of ``robot`` over ``domain``: a :class:`PLDI`.

    Parameters
    ----------
    robot : Manipulator
    domain : Domain, optional
        Defaults to ``Domain.from_robot(robot)``.
    samples : int, optional
        Sobol' positions (rounded up to a power of two); default grows with
        the number of positions that matter (256 per dimension, at most 8192).
    nominal : "equilibrium", "midpoint" or dict
        ``(A0, B0)`` at ``q = 0`` (clipped into the domain), ``qdot = 0`` and the
        torque that holds it (``u = g(q)``), at the interval midpoints, or at a
        given ``{"q", "qdot", "u"}``.
    refine : bool
        Refine every extreme by local search.
    coverage : int
        Fresh random points for the coverage check (0 to skip).
    certify : bool
        Replace the intervals by a guaranteed enclosure (interval arithmetic).
    workers : int, optional
        Processes (default: every core).
    progress : bool, optional
        Progress bars (default: when stderr is a terminal).
    """
    import sys

    t_start = time.perf_counter()
    if domain is None:
        domain = Domain.from_robot(robot)
    if tuple(domain.joint_names) != tuple(robot.joint_names):
        raise BoundsError(f"the domain's joints {domain.joint_names} are not the robot's {robot.joint_names}")
    if progress is None:
        progress = sys.stderr.isatty()
    rng = np.random.default_rng(seed)
    certified = None
    if certify:  # first: it gives up at once where it cannot work
        # 1e-5 of each width: tight enough for the paper's printed digits, ~1 s on a 2R
        options = {"rel_tol": 1e-5, **(certify_options or {})}
        certified = _certified(robot, domain, options, progress)
    problem = _Problem(robot, domain)
    m = robot.m

    pilot_vals, varying, pilot_points = _pilot(problem, seed)
    index = problem.all_index[varying]
    k = len(index)
    dropped = _dropped_positions(problem, rng)
    active_q = m - len(dropped)
    if samples is None:
        samples = int(min(8192, max(256, 256 * active_q)))
    q = _position_design(problem, samples, dropped, seed)

    cloud = pilot_vals[:, varying]
    scale = np.maximum(cloud.max(axis=0) - cloud.min(axis=0), 1e-300)
    _, pcs = _principal_directions(cloud, scale)
    directions = np.vstack([np.eye(k), -np.eye(k), pcs / scale, -pcs / scale]) if k else np.zeros((0, 0))
    t0 = time.perf_counter()
    values, starts = _support_pass(problem, q, directions, index, progress, workers) if k else (np.zeros(0), np.zeros((0, 3, 3 * m)))
    if k:
        # the best random pilot point per direction is one more start: a
        # second, independent design catches peaks the Sobol' positions miss
        proj = pilot_vals[:, varying] @ directions.T
        best_pilot = np.argmax(proj, axis=0)
        pilot_value = proj[best_pilot, np.arange(len(directions))]
        starts = np.concatenate([starts, pilot_points[best_pilot][:, None]], axis=1)
        swap = pilot_value > values
        values = np.where(swap, pilot_value, values)
        starts[swap, 0], starts[swap, -1] = starts[swap, -1], starts[swap, 0]
    witnesses = starts[:, 0]
    t_sample = time.perf_counter() - t0
    sampled_width = values[:k] + values[k : 2 * k]
    if refine and k:
        values, witnesses = _refine(problem, directions, values, starts, index, dropped, progress, workers)
    t_refine = time.perf_counter() - t0 - t_sample
    upper, lower = values[:k], -values[k : 2 * k]
    width = upper - lower
    refinement = np.where(sampled_width > 0, width / np.where(sampled_width > 0, sampled_width, 1) - 1.0, 0.0)

    polytope = _polytope(directions, values, 2 * k, cloud, scale, rng)

    # full matrices of bounds (constant entries from any point: here the pilot's first)
    A_any, B_any = robot.jacobians_batch(*domain.sample(1, method="uniform", seed=seed))
    A_lower, A_upper, B_lower, B_upper = A_any[0].copy(), A_any[0].copy(), B_any[0].copy(), B_any[0].copy()
    for (mat, r, c), lo_, hi_ in zip(index, lower, upper):
        (A_lower if mat == 0 else B_lower)[r, c] = lo_
        (A_upper if mat == 0 else B_upper)[r, c] = hi_

    enclosure = "sampled"
    notes = []
    if certify:
        A_lower, A_upper, B_lower, B_upper, cert_info = certified
        enclosure = "certified"
        notes.append("the polytope's half-spaces are sampled supports; the intervals are certified")
        lower_s, upper_s = lower, upper
        tmp = {"A": (A_lower, A_upper), "B": (B_lower, B_upper)}
        lower = np.array([tmp["AB"[mt]][0][r, c] for mt, r, c in index])
        upper = np.array([tmp["AB"[mt]][1][r, c] for mt, r, c in index])
        if np.any(lower > lower_s + COVERAGE_RTOL * (1 + np.abs(lower_s))) or np.any(
            upper < upper_s - COVERAGE_RTOL * (1 + np.abs(upper_s))
        ):
            raise CertificationError("internal error: a sampled Jacobian lies outside the certified bounds")
    else:
        cert_info = None

    point = _nominal(robot, domain, nominal)
    if point is None:
        A0, B0 = 0.5 * (A_lower + A_upper), 0.5 * (B_lower + B_upper)
    else:
        A0, B0 = robot.jacobians(point["q"], point["qdot"], point["u"])
        point = {key: v.tolist() for key, v in point.items()}

    names = tuple(entry_name("AB"[mt], r, c, 2 * m) for mt, r, c in index)
    result = PLDI(
        robot_name=robot.name,
        robot_source=robot.source,
        domain=domain,
        nominal_point=point,
        A0=A0,
        B0=B0,
        A_lower=A_lower,
        A_upper=A_upper,
        B_lower=B_lower,
        B_upper=B_upper,
        entries=names,
        entry_index=index,
        witness_lower=witnesses[k : 2 * k],
        witness_upper=witnesses[:k],
        polytope=polytope,
        enclosure=enclosure,
        coverage=float("nan"),
        coverage_points=0,
        refinement=refinement,
        dropped_q=dropped,
        info={
            "samples": int(len(q)),
            "seconds_sampling": round(t_sample, 3),
            "seconds_refining": round(t_refine, 3),
            "seconds_total": None,
            "max_refinement": float(refinement.max()) if k else 0.0,
            "certify": cert_info,
            "notes": notes,
        },
    )
    if coverage:
        frac = coverage_fraction(result, robot, coverage, seed=seed + 1)
        object.__setattr__(result, "coverage", frac)
        object.__setattr__(result, "coverage_points", int(coverage))
    result.info["seconds_total"] = round(time.perf_counter() - t_start, 3)
    return result


def coverage_fraction(pldi: PLDI, robot, n: int, *, seed=None) -> float:
    """Fraction of ``n`` fresh uniform points whose Jacobians lie in the intervals and polytope."""
    q, qdot, u = pldi.domain.sample(n, method="uniform", seed=seed)
    A, B = robot.jacobians_batch(q, qdot, u)
    inside = pldi.contains(A, B)
    if len(pldi.entries):
        inside &= pldi.polytope.contains(pldi.entry_values(A, B))
    return float(inside.mean())


def _certified(robot, domain: Domain, options: dict, progress: bool):
    from . import certify as certify_module

    model = getattr(robot, "model", None)
    if model is None:
        raise CertificationError(
            f"{robot.name}: certified bounds need a URDF robot (interval evaluation of its rigid-body "
            "dynamics); analytic models get sampled bounds only: drop --certify"
        )
    enc = certify_module.certified_jacobian_bounds(
        model, robot.damping, domain.q_lower, domain.q_upper, domain.qdot_lower, domain.qdot_upper,
        domain.u_lower, domain.u_upper, progress=progress, **options,
    )
    info = {"boxes": int(enc.n_boxes), "seconds": round(float(enc.seconds), 3)}
    return enc.A_lo, enc.A_hi, enc.B_lo, enc.B_hi, info
