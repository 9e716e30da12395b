"""The PLDI: every Jacobian the robot can have inside the domain, bounded.

:func:`bound_pldi` takes a robot and a :class:`~polyrob.bounds.domain.Domain` and
returns a :class:`PLDI`: the nominal pair ``(A0, B0)`` at an equilibrium, the
interval of every entry of ``A`` and ``B`` (the paper's eq. 9 table), the
witnesses where each bound is attained, and a polytope (half-spaces, and
vertices where the dimension allows) that holds every Jacobian found.

How the bounds are found (``enclosure = "sampled"``):

1. position coordinates the dynamics do not depend on are detected and dropped;
2. the remaining positions are sampled with a scrambled Sobol' design plus the
   corners of their box; for each position the extremes over the
   velocity/torque box are computed exactly, or attained and nearly always
   exact beyond four joints (:mod:`polyrob.bounds.extremes`);
3. a dense uniform screen of the whole domain (one Jacobian per point) adds
   starts near narrow peaks the design straddles;
4. each extreme is searched by L-BFGS-B over positions, velocities and torques
   from the highest peaks of the sampled landscape and the best screened
   points, then from the other directions' witnesses where these are higher
   (the entries share their sharp peaks, near singular mass matrices), then
   from a second screen drawn around all witnesses; fresh designs verify the
   result; the widening all this brought is reported;
5. the support values along ``+-e_i`` (the intervals) and along the principal
   directions of the Jacobian cloud give the polytope's half-spaces;
   linear programs (HiGHS) give its bounding box, an interior point and,
   in up to :data:`VERTEX_MAX_DIM` reduced dimensions, its vertices;
6. fresh random points of the domain check the coverage (it must be 1.0).

With ``certify=True`` the intervals are replaced by a guaranteed enclosure
computed by interval arithmetic (:mod:`polyrob.bounds.certify`); ``enclosure`` is
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
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from polyrob.bounds import search
from polyrob.io.atomic import atomic_write, json_default
from polyrob.bounds.domain import Domain
from polyrob.errors import BoundsError, CertificationError
from polyrob.bounds.polytope import COVERAGE_RTOL, VERTEX_MAX_DIM, Polytope, build_polytope, principal_directions

#: Principal directions of the Jacobian cloud searched besides +-e_i.
PRINCIPAL_DIRECTIONS = 12

__all__ = ["PLDI", "Polytope", "bound_pldi", "entry_name", "VERTEX_MAX_DIM"]



def entry_name(matrix: str, row: int, col: int, n: int) -> str:
    """The paper's name of an entry (1-based): ``a32``, ``b41``; ``a10_11`` when n >= 10."""
    sep = "_" if n >= 10 else ""
    return f"{matrix.lower()}{row + 1}{sep}{col + 1}"


# --------------------------------------------------------------------------- results


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
        from polyrob.model.robots import load_robot

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
        atomic_write(npz, lambda f: np.savez_compressed(f, **arrays), binary=True)
        atomic_write(path, lambda f: f.write(json.dumps(meta, indent=2, default=json_default)))
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


# --------------------------------------------------------------------------- bounding


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
    verify_rounds: int = 3,
    starts_per_direction: int = 3,
    screen: int | None = None,
    screen_starts: int = 4,
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
        the number of positions that matter (512 per dimension, at most 8192).
    nominal : "equilibrium", "midpoint" or dict
        ``(A0, B0)`` at ``q = 0`` (clipped into the domain), ``qdot = 0`` and the
        torque that holds it (``u = g(q)``), at the interval midpoints, or at a
        given ``{"q", "qdot", "u"}``.
    refine : bool
        Refine every extreme by local search.
    verify_rounds : int
        After refining, up to this many fresh designs (another scramble of the
        positions) are searched; support values they beat are refined again.
    starts_per_direction : int
        Local searches per direction (and per beaten direction in each
        verification round) from the highest peaks of the sampled landscape.
    screen : int, optional
        Random points of the domain screened for more starts (0 to skip):
        once uniformly, once around the witnesses found; default 65,536 per
        position that matters, at most 524,288.
    screen_starts : int
        Starts per direction each screen gives.
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
    problem = search.Problem(robot, domain)
    m = robot.m

    pilot_vals, varying = search.pilot(problem, seed)
    index = problem.all_index[varying]
    k = len(index)
    dropped = search.dropped_positions(problem, rng)
    active_q = m - len(dropped)
    if samples is None:
        samples = int(min(8192, max(256, 512 * active_q)))
    q = search.position_design(problem, samples, dropped, seed)
    if screen is None:
        screen = int(min(2**19, 2**16 * active_q))

    cloud = pilot_vals[:, varying]
    scale = np.maximum(cloud.max(axis=0) - cloud.min(axis=0), 1e-300)
    axes = principal_directions(cloud, scale)
    pcs = axes[:, :PRINCIPAL_DIRECTIONS].T
    directions = np.vstack([np.eye(k), -np.eye(k), pcs / scale, -pcs / scale]) if k else np.zeros((0, 0))
    t0 = time.perf_counter()
    stages = {}
    if k:
        # a dense uniform screen of the whole domain adds start positions
        # near narrow peaks that the position design straddles
        extra = search.screen(problem, directions, index, screen, screen_starts, seed, workers) if screen else None
        stages["screen"] = time.perf_counter() - t0
        values, starts, depends = search.support_pass(
            problem, q, directions, index, progress, workers, starts_per_direction, extra
        )
        stages["design"] = time.perf_counter() - t0 - stages["screen"]
    else:
        values, starts, depends = np.zeros(0), np.zeros((0, 1, 3 * m)), np.zeros((0, 2 * m), bool)
    witnesses = starts[:, 0].copy()
    t_sample = time.perf_counter() - t0
    sampled_width = values[:k] + values[k : 2 * k]
    rounds = 0
    if refine and k:
        t1 = time.perf_counter()
        values, witnesses = search.refine(
            problem, directions, values, starts, index, dropped, progress, workers, depends
        )
        stages["refine"] = time.perf_counter() - t1
        values, witnesses = search.cross_seed(
            problem, directions, values, witnesses, index, dropped, depends, progress, workers
        )
        stages["cross_seed"] = time.perf_counter() - t1 - stages["refine"]
        t1 = time.perf_counter()
        if screen:
            # a second screen, around the witnesses of every direction
            near = search.screen(problem, directions, index, screen, screen_starts, seed + 1, workers, witnesses)
            starts, _ = search.exact_witnesses(problem, near, directions, index, workers)
            starts = np.concatenate([witnesses[:, None], starts], axis=1)
            values, witnesses = search.refine(
                problem, directions, values, starts, index, dropped, progress, workers, depends
            )
            values, witnesses = search.cross_seed(
                problem, directions, values, witnesses, index, dropped, depends, progress, workers
            )
        stages["screen_near_witnesses"] = time.perf_counter() - t1
        t1 = time.perf_counter()
        # Verification rounds: a fresh design (another scramble) must not beat
        # any support value; where it does, refine again from its witness.
        for rounds in range(1, verify_rounds + 1):
            q_new = search.position_design(problem, samples, dropped, seed + 7919 * rounds)
            v_new, _ = search.inner_maxima(problem, q_new, directions, index, progress, workers)
            beaten = np.flatnonzero(v_new.max(axis=0) > values + 1e-9 * (1.0 + np.abs(values)))
            if not beaten.size:
                break
            peaks = q_new[search.landscape_peaks(problem, q_new, v_new[:, beaten], starts_per_direction)]
            s_new, v_start = search.exact_witnesses(problem, peaks, directions[beaten], index, workers)
            v_ref, w_ref = search.refine(
                problem, directions[beaten], v_start[:, 0], s_new, index, dropped, progress, workers,
                depends[beaten],
            )
            values[beaten], witnesses[beaten] = v_ref, w_ref
            values, witnesses = search.cross_seed(
                problem, directions, values, witnesses, index, dropped, depends, progress, workers
            )
        stages["verification"] = time.perf_counter() - t1
    t_refine = time.perf_counter() - t0 - t_sample
    upper, lower = values[:k], -values[k : 2 * k]
    width = upper - lower
    refinement = np.where(sampled_width > 0, width / np.where(sampled_width > 0, sampled_width, 1) - 1.0, 0.0)

    polytope = build_polytope(directions, values, 2 * k, cloud, scale, axes, rng)

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
            "seconds_stages": {key: round(v, 3) for key, v in stages.items()},
            "seconds_total": None,
            "max_refinement": float(refinement.max()) if k else 0.0,
            "verification_rounds": rounds,
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
    from polyrob.bounds import certify as certify_module

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
