"""Result objects of the time-varying certificates (:mod:`polyrob.analysis.time_varying.quadratic`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["QuadStabResult", "QuadPerfResult", "COVERS_NONLINEAR", "covers_text"]

#: The sentence the CLI prints beside the two verdicts.
COVERS_NONLINEAR = (
    "Only the time-varying certificate (quadratic stability/performance on the PLDI's vertices) can cover the "
    "moving nonlinear robot: when its status says certified, and only while the robot's state and its torques (accelerations, for a task domain) stay "
    "inside the domain the PLDI was bounded on; mu with constant parameters certifies each frozen robot of "
    "the set, not the robot in motion."
)


def covers_text(vs, what: str) -> str:
    """The precise scope of a vertex certificate (``what``: the property proved)."""
    return (
        f"{what} for every trajectory of xdot = A(t) x + B(t) u, u = K(r - y), y = [I 0] x, with "
        f"(A(t), B(t)) in Co{{(A_i, B_i)}} over the {vs.n_vertices} vertices of the PLDI's {vs.source} "
        f"({vs.enclosure} bounds), varying arbitrarily fast inside the domain D; for the nonlinear robot "
        "this holds for the deviation from an equilibrium (x_e, u_e) inside D while the state and the "
        "torque stay in D (the Jacobians of f there lie in the PLDI)"
        + ("" if vs.enclosure == "certified" else ", as far as the sampled bounds hold")
    )


@dataclass(frozen=True, eq=False)
class QuadStabResult:
    """Quadratic stability of the closed loop over a PLDI (one ``V = x^T P x`` for all vertices).

    Attributes
    ----------
    holds : bool
        Every vertex inequality verified with the returned ``P``.
    margin : float
        Verified decay rate of ``V`` (1/s): ``V' <= -margin V`` along every
        admissible trajectory; ``<= 0`` or ``nan`` when not verified.
    n_vertices : int
    vertex_source, enclosure : str
        Which vertex set was used and what its bounds are (see :class:`VertexSet`).
    P : ndarray or None
        The Lyapunov matrix in the closed loop's own coordinates ``[x, x_K]``.
    cond_P : float
    solver_status : str
    seconds : float
    covers : str
        What the certificate covers, precisely.
    info : dict
    """

    holds: bool
    margin: float
    n_vertices: int
    vertex_source: str
    enclosure: str
    P: np.ndarray | None
    cond_P: float
    solver_status: str
    seconds: float
    covers: str
    info: dict = field(default_factory=dict)


@dataclass(frozen=True, eq=False)
class QuadPerfResult:
    """Quadratic H∞ performance of the mixed-sensitivity loop over a PLDI.

    Attributes
    ----------
    holds : bool
        ``gamma < 1`` verified (performance, and quadratic stability, for
        every admissible variation).
    gamma : float
        Verified common-``P`` bound of the L2 gain ``r -> z`` (``inf`` when
        no level was verified); an upper bound of every vertex's H∞ norm.
    margin : float
        ``1 - gamma``.
    worst_vertex_hinf : float
        Largest H∞ norm of a frozen vertex (a lower bound of the best
        ``gamma`` any common ``P`` can give); ``nan`` when not computed.
    n_vertices : int
    vertex_source, enclosure : str
    P : ndarray or None
        In the closed loop's coordinates ``[x, W_S, W_T, W_KS, x_K]``.
    solver_gamma : float
        The level the solver returned (before the verification).
    solver_status : str
    seconds : float
    covers : str
    info : dict
    """

    holds: bool
    gamma: float
    margin: float
    worst_vertex_hinf: float
    n_vertices: int
    vertex_source: str
    enclosure: str
    P: np.ndarray | None
    solver_gamma: float
    solver_status: str
    seconds: float
    covers: str
    info: dict = field(default_factory=dict)
