"""The PLDI object: bounds of the Jacobians over a domain, and its files.

:class:`PLDI` is what :func:`polyrob.bounds.pldi.bound_pldi` returns; it is
saved as two files from one stem (:func:`save_pldi`): ``stem.json``, readable
(robot, domain, intervals, notes, the provenance of :mod:`polyrob.provenance`;
``format`` ``polyrob.pldi/1``), and
``stem.npz`` with every array.  :func:`load_pldi` checks the format.

Examples
--------
>>> entry_name("A", 2, 1, 4), entry_name("B", 9, 0, 12)
('a32', 'b10_1')
>>> pldi_paths("out/panda.npz")
(PosixPath('out/panda.json'), PosixPath('out/panda.npz'))
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from polyrob.bounds.polytope import COVERAGE_RTOL, Polytope
from polyrob.domains.task import domain_from_dict
from polyrob.domains.torque_box import Domain
from polyrob.errors import BoundsError, DomainError
from polyrob.io.atomic import atomic_write, json_default

__all__ = ["PLDI", "entry_name", "save_pldi", "load_pldi", "pldi_paths", "PLDI_FORMAT"]

#: The ``format`` field of a PLDI file this version writes and reads.
PLDI_FORMAT = "polyrob.pldi/1"
_ARRAYS = (
    "A0",
    "B0",
    "A_lower",
    "A_upper",
    "B_lower",
    "B_upper",
    "entry_index",
    "witness_lower",
    "witness_upper",
    "refinement",
)
_SUFFIXES = (".json", ".npz")


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
    robot_locked : tuple of str or None
        The joints locked when the robot was loaded (None: not recorded, the
        defaults apply); :attr:`robot` locks them again.
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
    robot_locked: tuple[str, ...] | None = None
    source_robot: object = field(default=None, repr=False, compare=False)

    # ------------------------------------------------------------------ views
    @property
    def m(self) -> int:
        return self.B0.shape[1]

    @property
    def robot(self):
        """The robot the PLDI was computed for.

        In the process that bounded it, the very object (an inner loop with
        its true robots, an armature override); otherwise the robot of a task
        domain, else the robot loaded again from its source, with the same
        joints locked (a PLDI file does not record an inner layer).
        """
        if self.source_robot is not None:
            return self.source_robot
        if getattr(self.domain, "robot", None) is not None:
            return self.domain.robot
        from polyrob.model.robots import load_robot

        source = self.robot_source if self.robot_source.endswith(".urdf") else self.robot_name
        lock = None if self.robot_locked is None else list(self.robot_locked)
        return load_robot(source, lock=lock)

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
        from polyrob.report.numbers import zero_round_off

        rows = [f"{'entry':<8}{'lower':>14}{'upper':>14}{'nominal':>14}  enclosure"]
        # round-off (e.g. a nominal -1.944e-42 of an entry that is 0 there) prints as 0
        figures = zero_round_off(np.column_stack([self.lower, self.upper, self.nominal]))
        for name, (lo, hi, nom) in zip(self.entries, figures):
            rows.append(f"{name:<8}{lo:>14.6g}{hi:>14.6g}{nom:>14.6g}  {self.enclosure}")
        return "\n".join(rows)

    # ------------------------------------------------------------------ files
    def save(self, path) -> tuple[Path, Path]:
        """Write ``stem.json`` (readable) and ``stem.npz`` (all arrays); see :func:`pldi_paths`.

        ``path`` may name either file or the stem: ``p``, ``p.json`` and
        ``p.npz`` all write ``p.json`` and ``p.npz``.  Both are written to
        temporary files first and renamed, so an interrupted save leaves no
        half-written file.  Returns the two paths.
        """
        return save_pldi(self, path)

    @classmethod
    def load(cls, path) -> PLDI:
        """Read a PLDI written by :meth:`save` (``path``: the JSON, the npz or the stem)."""
        return load_pldi(path)


def pldi_paths(path) -> tuple[Path, Path]:
    """``(stem.json, stem.npz)`` for a path naming either file or the stem.

    Only the suffixes ``.json`` and ``.npz`` are replaced; any other name is
    the stem itself (``p.v2`` gives ``p.v2.json``, ``p.v2.npz``).
    """
    path = Path(path)
    stem = path.with_suffix("") if path.suffix.lower() in _SUFFIXES else path
    return stem.with_name(stem.name + ".json"), stem.with_name(stem.name + ".npz")


def save_pldi(pldi: PLDI, path) -> tuple[Path, Path]:
    """Write ``pldi`` as ``stem.json`` + ``stem.npz`` (see :meth:`PLDI.save`)."""
    path, npz = pldi_paths(path)
    poly = pldi.polytope
    meta = {
        "format": PLDI_FORMAT,
        "robot": {
            "name": pldi.robot_name,
            "source": pldi.robot_source,
            "locked": None if pldi.robot_locked is None else list(pldi.robot_locked),
        },
        "domain": pldi.domain.to_dict(),
        "nominal_point": pldi.nominal_point,
        "enclosure": pldi.enclosure,
        "coverage": pldi.coverage,
        "coverage_points": pldi.coverage_points,
        "dropped_q": list(pldi.dropped_q),
        "entries": [
            {"name": n, "lower": float(lo), "upper": float(hi), "nominal": float(nm)}
            for n, lo, hi, nm in zip(pldi.entries, pldi.lower, pldi.upper, pldi.nominal)
        ],
        "polytope": {
            "halfspaces": poly.n_halfspaces,
            "vertices": None if poly.vertices is None else len(poly.vertices),
            "reduced_dim": poly.reduced_dim,
            "volume_hits": poly.volume_hits,
            "volume_samples": poly.volume_samples,
            "volume_ratio": poly.volume_ratio,
            "volume_note": poly.volume_note,
        },
        "info": pldi.info,
        "arrays": npz.name,
        "provenance": _provenance(pldi).to_dict(),
    }
    arrays = {k: getattr(pldi, k) for k in _ARRAYS}
    arrays.update(
        polytope_normals=poly.normals,
        polytope_offsets=poly.offsets,
        polytope_centre=poly.centre,
        polytope_basis=poly.basis,
    )
    if poly.vertices is not None:
        arrays["polytope_vertices"] = poly.vertices
    atomic_write(npz, lambda f: np.savez_compressed(f, **arrays), binary=True)
    atomic_write(path, lambda f: f.write(json.dumps(meta, indent=2, default=json_default)))
    return path, npz


def _provenance(pldi: PLDI):
    """What made the PLDI file: versions, command, the URDF's and the domain's hashes (polyrob.provenance)."""
    from polyrob.provenance import Provenance

    return Provenance.capture(
        robot=pldi.source_robot,
        urdf=pldi.robot_source,
        description={"robot": pldi.robot_name, "domain": pldi.domain.to_dict()},
        function="polyrob.bounds.pldi_result.save_pldi",
    )


def load_pldi(path) -> PLDI:
    """Read a PLDI written by :func:`save_pldi`; the file's ``format`` must be :data:`PLDI_FORMAT`.

    Raises
    ------
    BoundsError
        Missing or unreadable files, another format or version, missing fields.
    """
    path, _ = pldi_paths(path)
    try:
        meta = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise BoundsError(f"{path}: not a PLDI file written by polyrob ({exc})") from None
    fmt = meta.get("format") if isinstance(meta, dict) else None
    if not isinstance(fmt, str) or not fmt.startswith("polyrob.pldi/"):
        raise BoundsError(f"{path}: not a PLDI file written by polyrob (no 'format': '{PLDI_FORMAT}')")
    if fmt != PLDI_FORMAT:
        raise BoundsError(
            f"{path}: PLDI format '{fmt}' is not supported by this polyrob (it reads '{PLDI_FORMAT}'): "
            "compute the bounds again with `polyrob bounds`"
        )
    try:
        with np.load(path.parent / meta["arrays"]) as npz:
            data = {k: npz[k] for k in npz.files}
        poly = meta["polytope"]
        polytope = Polytope(
            normals=data["polytope_normals"],
            offsets=data["polytope_offsets"],
            vertices=data.get("polytope_vertices"),
            centre=data["polytope_centre"],
            basis=data["polytope_basis"],
            volume_hits=poly["volume_hits"],
            volume_samples=poly["volume_samples"],
            volume_note=poly.get("volume_note", ""),
        )
        locked = meta["robot"].get("locked")
        pldi = PLDI(
            robot_name=meta["robot"]["name"],
            robot_source=meta["robot"]["source"],
            domain=domain_from_dict(meta["domain"]),
            nominal_point=meta["nominal_point"],
            entries=tuple(e["name"] for e in meta["entries"]),
            polytope=polytope,
            enclosure=meta["enclosure"],
            coverage=meta["coverage"],
            coverage_points=meta["coverage_points"],
            dropped_q=tuple(meta["dropped_q"]),
            info=meta["info"],
            robot_locked=None if locked is None else tuple(locked),
            **{k: data[k] for k in _ARRAYS},
        )
        if getattr(pldi.domain, "kind", "box") == "task":  # its torques need the robot's inverse dynamics
            object.__setattr__(pldi.domain, "robot", pldi.robot)
        return pldi
    except (OSError, ValueError, KeyError, TypeError, DomainError) as exc:
        raise BoundsError(f"{path}: not a PLDI file written by polyrob ({type(exc).__name__}: {exc})") from None
