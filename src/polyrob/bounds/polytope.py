"""The polytope of a PLDI: half-spaces, reduced coordinates, vertices, volume.

The half-spaces are support values of the Jacobian entries along the axes
(the interval box) and along the principal directions of the Jacobian cloud;
linear programs (HiGHS) give the bounding box of the box section in reduced
coordinates, an interior point (Chebyshev centre) and, in up to
:data:`VERTEX_MAX_DIM` dimensions, the vertices (qhull).

The package's vertex enumeration is here, once: :func:`box_corners` (the
corners of an interval box) and :func:`halfspace_vertices` (the vertices of
``{z : G z <= g}``), with :func:`polytope_vertices` for a :class:`Polytope`.
The half-space case uses :class:`scipy.spatial.HalfspaceIntersection` (qhull,
a maintained library already needed here; pycddlib would be one more
dependency for the same result).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from scipy import optimize

from polyrob.errors import BoundsError

__all__ = [
    "Polytope",
    "build_polytope",
    "bounding_box",
    "constraining_rows",
    "principal_directions",
    "box_corners",
    "halfspace_vertices",
    "polytope_vertices",
    "VERTEX_MAX_DIM",
    "COVERAGE_RTOL",
]

#: Vertices are enumerated when the Jacobian cloud spans at most this many dimensions.
VERTEX_MAX_DIM = 6
#: Relative tolerance for "inside" in the coverage check (rounding only).
COVERAGE_RTOL = 1e-9


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
    volume_note : str
        Why the volume ratio was not computed ("" when it was).
    """

    normals: np.ndarray
    offsets: np.ndarray
    vertices: np.ndarray | None
    centre: np.ndarray
    basis: np.ndarray
    volume_hits: int
    volume_samples: int
    volume_note: str = ""

    @property
    def volume_ratio(self) -> float | None:
        """Estimated volume ratio polytope / interval box; None when not computed
        (no sample landed in the box: see :attr:`volume_note`)."""
        return self.volume_hits / self.volume_samples if self.volume_samples else None

    @property
    def volume_ratio_bound(self) -> float | None:
        """A 95 % upper bound of the ratio (the rule of three when no point hit); None when not computed."""
        return max(self.volume_hits, 3) / self.volume_samples if self.volume_samples else None

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


def box_corners(lo, hi) -> np.ndarray:
    """The corners of the box ``[lo, hi]`` (``lo <= hi``), one per row.

    In lexicographic order: the last coordinate fastest, ``lo`` before ``hi``.
    A coordinate with ``lo == hi`` has one value, so a box with ``d``
    non-degenerate coordinates has ``2^d`` corners.

    Examples
    --------
    >>> box_corners([0.0, 1.0, 5.0], [1.0, 2.0, 5.0]).tolist()
    [[0.0, 1.0, 5.0], [0.0, 2.0, 5.0], [1.0, 1.0, 5.0], [1.0, 2.0, 5.0]]
    """
    lo, hi = np.asarray(lo, float).reshape(-1), np.asarray(hi, float).reshape(-1)
    levels = [(a,) if a == b else (a, b) for a, b in zip(lo, hi)]
    corners = list(itertools.product(*levels))
    return np.array(corners, dtype=float).reshape(len(corners), len(lo))


def halfspace_vertices(G, g) -> np.ndarray | None:
    """The vertices of the bounded polytope ``{z : G z <= g}``, one per row, or None.

    Rows whose normal vanishes (relative to the largest) do not constrain ``z``
    and are dropped (their ``g`` is 0 up to rounding, possibly < 0).  The
    interior point qhull needs is the Chebyshev centre (an LP, HiGHS); None
    when there is none (an empty or flat polytope) or qhull refuses the input
    (degenerate, unbounded).  Intersections that agree to 1e-9 of the
    polytope's extent (a degenerate vertex, met by more than ``dim`` facets)
    are one vertex, the first one qhull gives; the rows are in qhull's order.

    Examples
    --------
    >>> G = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0], [1.0, 1.0]])
    >>> v = halfspace_vertices(G, np.array([1.0, 1.0, 1.0, 1.0, 1.0]))
    >>> sorted(np.round(v, 12).tolist())
    [[-1.0, -1.0], [-1.0, 1.0], [0.0, 1.0], [1.0, -1.0], [1.0, 0.0]]
    """
    from scipy.spatial import HalfspaceIntersection, QhullError

    G, g = np.atleast_2d(np.asarray(G, float)), np.asarray(g, float).reshape(-1)
    r = G.shape[1]
    if r == 0 or not len(G):
        return None
    moves = np.abs(G).max(axis=1) > 1e-12 * max(np.abs(G).max(), 1e-300)
    G, g = G[moves], g[moves]
    norms = np.linalg.norm(G, axis=1)
    res = optimize.linprog(
        np.r_[np.zeros(r), -1.0], A_ub=np.c_[G, norms], b_ub=g, bounds=[(None, None)] * r + [(0, None)], method="highs"
    )
    if res.status != 0 or res.x[-1] <= 1e-12:
        return None
    try:
        hs = HalfspaceIntersection(np.c_[G, -g], res.x[:r])
    except (QhullError, ValueError):  # degenerate inputs: no vertices then (the half-spaces remain)
        return None
    z = hs.intersections
    ext = np.maximum(np.ptp(z, axis=0), 1e-300)
    _, keep = np.unique(np.round((z - z.min(axis=0)) / ext, 9), axis=0, return_index=True)
    return z[np.sort(keep)]


def polytope_vertices(poly: Polytope, max_dim: int = VERTEX_MAX_DIM) -> np.ndarray | None:
    """A polytope's vertices: the stored ones, else enumerated in its reduced coordinates.

    None when they are not stored and the reduced dimension is 0 or above
    ``max_dim``, or :func:`halfspace_vertices` finds none.
    """
    if poly.vertices is not None:
        return np.asarray(poly.vertices, float)
    r = poly.reduced_dim
    if r == 0 or r > max_dim:
        return None
    z = halfspace_vertices(poly.normals @ poly.basis, poly.offsets - poly.normals @ poly.centre)
    return None if z is None else poly.centre + z @ poly.basis.T


def principal_directions(vals: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Principal axes of the normalised cloud, as columns, strongest first; their
    number is the rank (the directions that vary)."""
    z = (vals - vals.mean(axis=0)) / scale
    _, s, vt = np.linalg.svd(z, full_matrices=False)
    r = int(np.sum(s > 1e-8 * s[0])) if s.size and s[0] > 0 else 0
    return vt[:r].T


def constraining_rows(G, normals, scale) -> np.ndarray:
    """Which rows of ``G z <= g`` constrain ``z`` (``G = normals @ basis``, entries of range ``scale``).

    Rows of entries that are constant over the cloud do not (their ``G`` row
    vanishes; their ``g`` is 0 up to rounding, possibly < 0).  The test is
    relative to each row's own scale: an entry whose range is 1e-12 of another's
    still bounds its principal direction.
    """
    size = np.linalg.norm(np.asarray(normals, float) * np.asarray(scale, float)[None, :], axis=1)
    return (size > 0) & (np.abs(G).max(axis=1) > 1e-9 * np.where(size > 0, size, 1.0))


def bounding_box(G, g, offsets=()) -> np.ndarray:
    """The bounding box ``(r, 2)`` of ``{z : G z <= g}`` (bounded, rows that constrain), by 2r LPs (HiGHS).

    The LPs run on rows and columns scaled to unit size: HiGHS drops
    coefficients below 1e-9, and a principal direction along an entry whose
    range is 1e-12 of the others' has a column that small (ur10's default task:
    the LP was "unbounded").  ``offsets`` (the support values) only word the
    error.

    Raises
    ------
    BoundsError
        An LP failed.
    """
    G, g = np.asarray(G, float), np.asarray(g, float)
    rows = np.abs(G).max(axis=1)
    G, g = G / rows[:, None], g / rows
    cols = np.abs(G).max(axis=0)
    cols = np.where(cols > 0, cols, 1.0)
    Gy, r = G / cols[None, :], G.shape[1]
    box = np.zeros((r, 2))
    for i in range(r):
        for j, sgn in enumerate((1.0, -1.0)):  # min, then max
            c = np.zeros(r)
            c[i] = sgn
            res = optimize.linprog(c, A_ub=Gy, b_ub=g, bounds=[(None, None)] * r, method="highs")
            if res.status != 0:
                raise BoundsError(_lp_failure(res, np.asarray(offsets, float)))
            box[i, j] = res.x[i] / cols[i]
    return box


def build_polytope(normals, offsets, n_box, cloud, scale, basis_n, rng, n_mc=200_000, describe=True) -> Polytope:
    """Reduced coordinates, LP bounding box, interior point, vertices and volume ratio.

    ``basis_n`` are the principal axes of the normalised ``cloud``
    (:func:`principal_directions`).  ``describe=False``: the half-spaces and
    reduced coordinates alone (no LPs, vertices or volume).
    """
    centre = cloud.mean(axis=0)
    basis = basis_n * scale[:, None]  # p = centre + basis @ z
    r = basis.shape[1]
    G = normals @ basis
    g = offsets - normals @ centre
    vertices = None
    if r == 0:
        return Polytope(normals, offsets, None, centre, basis, 0, 0, "no entry varies: there is no volume to compare")
    if not describe:
        return Polytope(normals, offsets, None, centre, basis, 0, 0, "vertices and volume ratio not asked for")
    box_rows = np.arange(len(normals)) < n_box
    moves = constraining_rows(G, normals, scale)
    G, g, box_rows = G[moves], g[moves], box_rows[moves]
    # rows and columns brought to unit size (z = y / cols): see bounding_box
    rows = np.abs(G).max(axis=1)
    G, g = G / rows[:, None], g / rows
    cols = np.abs(G[box_rows]).max(axis=0)
    cols = np.where(cols > 0, cols, 1.0)
    Gy = G / cols[None, :]
    # Bounding box, in z, of the interval box cut by the reduced subspace: the volume estimate samples it
    box_z = bounding_box(G[box_rows], g[box_rows], offsets)
    if r <= VERTEX_MAX_DIM:
        vy = halfspace_vertices(Gy, g)
        vertices = None if vy is None else centre + (vy / cols[None, :]) @ basis.T
    # Volume ratio against the interval box (lo <= centre + basis z <= hi), in z.
    z = box_z[:, 0] + rng.random((n_mc, r)) * (box_z[:, 1] - box_z[:, 0])
    in_poly = np.all(z @ G.T <= g + 1e-12, axis=1)
    in_box = np.all(z @ G[box_rows].T <= g[box_rows] + 1e-12, axis=1)
    note = (
        ""
        if in_box.any()
        else (
            f"volume ratio not computed: none of {n_mc} points drawn in the bounding box of the interval box's "
            f"section ({r} reduced dimensions) landed in the section itself"
        )
    )
    return Polytope(normals, offsets, vertices, centre, basis, int(in_poly.sum()), int(in_box.sum()), note)


def _lp_failure(res, offsets) -> str:
    """One line for a failed LP: what failed, and what to change."""
    span = float(np.max(np.abs(offsets))) if len(offsets) else 0.0
    return (
        f"the polytope's bounding-box LP failed (HiGHS status {res.status}: {res.message}) with support values "
        f"up to {span:.3g}: entries this large usually come from a domain far wider than the robot's real "
        "range; give a smaller domain (--qdot-max, --u-max, --q-range or a domain file)"
    )
