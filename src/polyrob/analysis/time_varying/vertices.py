"""Vertices of a PLDI and the closed loops they give with a fixed controller.

The time-varying certificates of :mod:`polyrob.analysis.time_varying.quadratic` check an
LMI at every vertex ``(A_i, B_i)`` of the PLDI.  For a fixed controller the
closed-loop matrices are affine in ``(A, B)`` (``A`` enters once, ``B`` once,
multiplied by the controller's fixed ``D_K C`` and ``C_K``), so the vertices
of the PLDI map to vertices of the set of closed loops, and an LMI that is
affine in the closed-loop matrices (Lyapunov, bounded real) holds on the
whole convex hull once it holds at these vertices.

:func:`vertex_set` picks the vertex set of a :class:`~polyrob.bounds.pldi.PLDI`:

``"polytope"``
    the vertices of the PLDI's polytope (the interval box cut by the
    principal-direction half-spaces).  They are enumerated
    (:func:`polyrob.bounds.polytope.polytope_vertices`, qhull in the
    polytope's reduced coordinates) when the PLDI did not store them, up to
    :data:`POLYTOPE_MAX_DIM` reduced dimensions.
``"box"``
    the ``2^k`` corners of the interval box of the ``k`` varying entries
    (:func:`polyrob.bounds.polytope.box_corners`):
    a superset of the polytope, with fewer vertices in low dimension.
``"auto"``
    the polytope when its vertices are enumerated and fit in ``max_vertices``
    (it is the tighter set), else the box's corners when they fit; the one
    used is recorded in :attr:`VertexSet.source`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from polyrob.bounds.polytope import box_corners, polytope_vertices
from polyrob.errors import ArgumentError, NotApplicable, PolyrobError

__all__ = [
    "VertexSet",
    "vertex_set",
    "closed_loop_vertices",
    "augmented_vertices",
    "performance_vertices",
    "controller_mats",
    "weight_mats",
    "POLYTOPE_MAX_DIM",
    "MAX_VERTICES",
]

#: Reduced dimension up to which the polytope's vertices are enumerated here.
POLYTOPE_MAX_DIM = 8
#: Default largest number of vertices a vertex LMI is set up for.
MAX_VERTICES = 4096


@dataclass(frozen=True, eq=False)
class VertexSet:
    """Plants ``(A_i, B_i, C, 0)`` whose convex hull the certificate covers.

    Attributes
    ----------
    A : ndarray (v, n, n)
    B : ndarray (v, n, m)
    C : ndarray (m, n)
        ``[I_m 0]`` for a robot (``y = q``).
    source : str
        ``"polytope"``, ``"box"`` or ``"given"``.
    enclosure : str
        What the PLDI's bounds are (``"sampled"``/``"certified"``) or
        ``"given"``: a certificate on the vertices covers the robot's Jacobians
        only as far as the enclosure does.
    note : str
        How the set was chosen (counts of the alternatives).
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    source: str
    enclosure: str
    note: str = ""

    @property
    def n_vertices(self) -> int:
        return self.A.shape[0]

    @property
    def n_x(self) -> int:
        return self.A.shape[1]

    @property
    def m(self) -> int:
        return self.B.shape[2]


def _matrices(pldi, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Full ``A_i``, ``B_i`` from the varying entries ``points`` (v, k)."""
    A_c = 0.5 * (np.asarray(pldi.A_lower) + np.asarray(pldi.A_upper))
    B_c = 0.5 * (np.asarray(pldi.B_lower) + np.asarray(pldi.B_upper))
    v = points.shape[0]
    A = np.repeat(A_c[None], v, axis=0)
    B = np.repeat(B_c[None], v, axis=0)
    for k, (mat, i, j) in enumerate(np.asarray(pldi.entry_index, int)):
        (A if mat == 0 else B)[:, i, j] = points[:, k]
    return A, B


def vertex_set(source, *, which: str = "auto", max_vertices: int = MAX_VERTICES) -> VertexSet:
    """The vertex plants of a PLDI, or given vertex matrices.

    Parameters
    ----------
    source : PLDI, VertexSet or sequence of (A_i, B_i)
        A :class:`~polyrob.bounds.pldi.PLDI`, or the vertices themselves
        (``C = [I_m 0]`` is assumed).
    which : {"auto", "polytope", "box"}
        Vertex set of a PLDI (see the module docstring).
    max_vertices : int
        Largest acceptable number of vertices.

    Raises
    ------
    PolyrobError
        No vertex set fits in ``max_vertices`` (use
        :func:`polyrob.analysis.time_varying.smallgain.scaled_small_gain` on an LFT
        model instead), or malformed vertices.

    Examples
    --------
    >>> import numpy as np
    >>> from polyrob.analysis.time_varying.vertices import vertex_set
    >>> vs = vertex_set([(np.zeros((2, 2)), np.array([[0.0], [1.0]]))])
    >>> vs.n_vertices, vs.C.tolist(), vs.source
    (1, [[1.0, 0.0]], 'given')
    """
    if isinstance(source, VertexSet):
        return source
    if hasattr(source, "polytope") and hasattr(source, "entry_index"):
        return _from_pldi(source, which, int(max_vertices))
    try:
        pairs = [(np.asarray(a, float), np.asarray(b, float)) for a, b in source]
    except (TypeError, ValueError):
        raise ArgumentError("vertices must be a PLDI or a sequence of (A_i, B_i) pairs") from None
    if not pairs:
        raise ArgumentError("no vertices given")
    n, m = pairs[0][0].shape[0], pairs[0][1].shape[1]
    if n != 2 * m or any(a.shape != (n, n) or b.shape != (n, m) for a, b in pairs):
        raise ArgumentError(
            f"every vertex must be (A: 2m x 2m, B: 2m x m); got A {pairs[0][0].shape}, B {pairs[0][1].shape}"
        )
    C = np.hstack([np.eye(m), np.zeros((m, m))])
    return VertexSet(np.stack([a for a, _ in pairs]), np.stack([b for _, b in pairs]), C, "given", "given")


def _from_pldi(pldi, which: str, max_vertices: int) -> VertexSet:
    if which not in ("auto", "polytope", "box"):
        raise ArgumentError(f"which must be 'auto', 'polytope' or 'box', got {which!r}")
    lo, hi = np.asarray(pldi.lower, float), np.asarray(pldi.upper, float)
    n_box = 2 ** int(np.count_nonzero(hi > lo))  # what box_corners gives: 2^k for k varying entries
    poly_pts = polytope_vertices(pldi.polytope, POLYTOPE_MAX_DIM) if which in ("auto", "polytope") else None
    n_poly = None if poly_pts is None else len(poly_pts)
    note = f"polytope vertices: {n_poly if n_poly is not None else 'not enumerated'}; box corners: {n_box}"
    choices = []
    if poly_pts is not None and n_poly <= max_vertices:
        choices.append((n_poly, "polytope"))
    if which in ("auto", "box") and n_box <= max_vertices:
        choices.append((n_box, "box"))
    if which != "auto":
        choices = [c for c in choices if c[1] == which]
    if not choices:
        raise NotApplicable(
            f"no '{which}' vertex set with at most {max_vertices} vertices ({note}); use the constant-D "
            "scaled small-gain test on an LFT model (polyrob.analysis.time_varying.smallgain.scaled_small_gain)"
        )
    src = choices[0][1]  # the polytope first: it is the tighter of the two
    pts = box_corners(lo, hi) if src == "box" else poly_pts
    A, B = _matrices(pldi, pts)
    m = B.shape[2]
    C = np.hstack([np.eye(m), np.zeros((m, m))])
    # the box corners are as proved as the intervals; the polytope's other half-spaces are
    # sampled supports even when the intervals are certified (bound_pldi's note says so)
    enclosure = str(pldi.enclosure) if src == "box" else "sampled"
    return VertexSet(A, B, C, src, enclosure, note)


# --------------------------------------------------------------------------- closed loops


def weight_mats(W, m: int, name: str):
    """``(A, B, C, D)`` of an ``m x m`` weight (SISO: one copy per channel); ``None`` omits it."""
    import control

    from polyrob.controller import as_controller_ss

    if W is None:
        return None
    if isinstance(W, control.LTI) and (W.ninputs, W.noutputs) == (1, 1) and m > 1:
        g = as_controller_ss(W, 1, 1)
        a, b, c, d = (np.asarray(X, float) for X in (g.A, g.B, g.C, g.D))
        eye = np.eye(m)
        return np.kron(eye, a), np.kron(eye, b), np.kron(eye, c), np.kron(eye, d)
    try:
        g = as_controller_ss(W, m, m)
    except PolyrobError as exc:
        raise ArgumentError(f"{name}: {exc}") from None
    return tuple(np.asarray(X, float) for X in (g.A, g.B, g.C, g.D))


def controller_mats(K, m: int):
    """``(A_K, B_K, C_K, D_K)`` of an ``m x m`` controller ``u = K e`` (any form :meth:`~polyrob.controller.Controller.of` takes)."""
    from polyrob.controller import Controller

    return Controller.of(K, m, m).matrices


def closed_loop_vertices(vs: VertexSet, K) -> np.ndarray:
    """State matrices (v, n + n_K, n + n_K) of ``u = K (r - C x)`` at every vertex.

    Examples
    --------
    >>> import numpy as np
    >>> from polyrob.analysis.time_varying.vertices import vertex_set, closed_loop_vertices
    >>> vs = vertex_set([(np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0], [1.0]]))])
    >>> closed_loop_vertices(vs, (np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), np.array([[2.0]])))[0].tolist()
    [[0.0, 1.0], [-2.0, 0.0]]
    """
    Ak, Bk, Ck, Dk = controller_mats(K, vs.m)
    C = vs.C
    top = np.concatenate([vs.A - vs.B @ (Dk @ C), np.broadcast_to(vs.B @ Ck, vs.B.shape[:2] + (Ck.shape[1],))], axis=2)
    bot = np.broadcast_to(np.hstack([-Bk @ C, Ak]), (vs.n_vertices, Ak.shape[0], vs.n_x + Ak.shape[0]))
    return np.concatenate([top, bot], axis=1)


def augmented_vertices(vs: VertexSet, W_S=None, W_T=None, W_KS=None):
    """Open weighted plants ``[r; u] -> [z; e]`` at every vertex: stacks ``(A, B, C, D)``.

    The same channels, states and realisation of the weights as
    :func:`polyrob.plant.generalized.generalized_plant` without the
    uncertainty channels: ``z = [W_S e; W_T y; W_KS u]``, ``e = r - y``,
    states ``[x, W_S, W_T, W_KS]``.
    """
    m, n = vs.m, vs.n_x
    ws = [
        (w, lab)
        for w, lab in (
            (weight_mats(W_S, m, "W_S"), "e"),
            (weight_mats(W_T, m, "W_T"), "y"),
            (weight_mats(W_KS, m, "W_KS"), "u"),
        )
        if w is not None
    ]
    if not ws:
        raise ArgumentError("give at least one weight (W_S, W_T or W_KS)")
    C = vs.C
    I_m, Z_m = np.eye(m), np.zeros((m, m))
    feeds = {"e": (-C, I_m, Z_m), "y": (C, Z_m, Z_m), "u": (np.zeros((m, n)), Z_m, I_m)}
    N = n + sum(w[0].shape[0] for w, _ in ws)
    nz, v = m * len(ws), vs.n_vertices
    A = np.zeros((v, N, N))
    B = np.zeros((v, N, 2 * m))
    Cz = np.zeros((v, nz + m, N))
    D = np.zeros((v, nz + m, 2 * m))
    A[:, :n, :n], B[:, :n, m:] = vs.A, vs.B
    s, row = n, 0
    for (Aw, Bw, Cw, Dw), lab in ws:
        fx, fr, fu = feeds[lab]
        sl = slice(s, s + Aw.shape[0])
        A[:, sl, sl], A[:, sl, :n] = Aw, Bw @ fx
        B[:, sl] = Bw @ np.hstack([fr, fu])
        Cz[:, row : row + m, sl], Cz[:, row : row + m, :n] = Cw, Dw @ fx
        D[:, row : row + m] = Dw @ np.hstack([fr, fu])
        s, row = s + Aw.shape[0], row + m
    Cz[:, nz:, :n], D[:, nz:, :m] = -C, I_m  # the measurement e = r - y
    return A, B, Cz, D


def performance_vertices(vs: VertexSet, K, W_S=None, W_T=None, W_KS=None):
    """Closed loops ``r -> z = [W_S e; W_T y; W_KS u]`` at every vertex: stacks ``(A, B, C, D)``.

    States ``[x, W_S, W_T, W_KS, x_K]`` (see :func:`augmented_vertices`).
    """
    from polyrob.plant.generalized import lower_lft_matrices

    Kmats = controller_mats(K, vs.m)
    out = [lower_lft_matrices(*mats, *Kmats, vs.m, vs.m) for mats in zip(*augmented_vertices(vs, W_S, W_T, W_KS))]
    return tuple(np.stack(X) for X in zip(*out))
