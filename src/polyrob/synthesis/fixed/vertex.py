"""Fixed-structure synthesis for the time-varying certificate (multi-vertex H∞).

What HIFOO and MATLAB's ``systune`` do against several plants at once:
minimise, over the parameters ``θ`` of a fixed controller structure
(:mod:`polyrob.synthesis.fixed.structures`, e.g. ``"tf3"``: each ``K_ij`` of third
order), the worst closed-loop mixed-sensitivity H∞ norm over the vertices of
the PLDI,

.. math:: \\min_\\theta \\max_i \\| [W_S S_i;\\ W_T T_i] \\|_\\infty ,

then certify the result with the common-Lyapunov LMIs
(:func:`~polyrob.analysis.time_varying.quadratic.quadstab`,
:func:`~polyrob.analysis.time_varying.quadratic.quadperf`), which cover arbitrarily fast
variation inside the PLDI.  The worst vertex norm is a lower bound of the
common-``P`` level, so driving it down is necessary for ``quadperf`` to pass;
it is not sufficient, which is why the verdict is the LMI's, never the
optimiser's.

The optimiser works on a frequency grid (the plants' responses at every
vertex are computed once): a log-sum-exp smoothing of the largest singular
value over all (vertex, frequency) pairs with its analytic gradient
(through :meth:`ControllerStructure.freqresp`), minimised by BFGS, with a
barrier that rejects any ``θ`` leaving a frozen vertex unstable.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize

from polyrob.analysis.time_varying.quadratic import QuadPerfResult, QuadStabResult, quadperf, quadstab
from polyrob.analysis.time_varying.vertices import (
    MAX_VERTICES,
    augmented_vertices,
    closed_loop_vertices,
    vertex_set,
)
from polyrob.errors import SynthesisError
from polyrob.progress import report

__all__ = ["VertexSynthesisResult", "vertex_synthesis", "vertex_peak", "vertex_peaks"]

#: Frequency grid of the optimiser (rad/s).
DEFAULT_OMEGA = np.logspace(-3, 3, 90)
#: Gains tried on the warm start when it leaves a frozen vertex unstable.
GAIN_SCAN = (1.0, 2.0, 3.0, 5.0, 0.5, 8.0, 0.3)


@dataclass(frozen=True, eq=False)
class VertexSynthesisResult:
    """A fixed-structure controller tuned on the PLDI's vertices, and its certificates.

    Attributes
    ----------
    controller : control.StateSpace
    theta : ndarray
    structure : str
    order : int
    grid_peak : float
        Worst vertex's largest singular value of ``[W_S S; W_T T]`` on the
        optimiser's grid (a lower bound of its H∞ norm; not a certificate).
    initial_grid_peak : float
        The same at the warm start (after the gain scan).
    warm_gain : float
        Gain applied to the warm start so that every frozen vertex is stable.
    quadstab, quadperf : QuadStabResult or None
        The certificates (``None`` when ``certify=False``; ``quadperf`` is
        also ``None`` when it cannot hold, the reason in
        ``info["quadperf_skipped"]``).
    n_vertices : int
    vertex_source : str
    seconds : float
    info : dict
    """

    controller: object
    theta: np.ndarray
    structure: str
    order: int
    grid_peak: float
    initial_grid_peak: float
    warm_gain: float
    quadstab: QuadStabResult | None
    quadperf: QuadPerfResult | None
    n_vertices: int
    vertex_source: str
    seconds: float
    info: dict = field(default_factory=dict)

    def summary(self) -> dict:
        """JSON-ready figures."""
        qs, qp = self.quadstab, self.quadperf
        return {
            "structure": self.structure,
            "order": self.order,
            "n_vertices": self.n_vertices,
            "vertex_source": self.vertex_source,
            "grid_peak": self.grid_peak,
            "initial_grid_peak": self.initial_grid_peak,
            "warm_gain": self.warm_gain,
            "quadstab": None
            if qs is None
            else {"holds": qs.holds, "decay_rate": qs.margin, "lmi_vertices": qs.info.get("lmi_vertices")},
            "quadperf": (
                {"holds": False, "not_run": self.info.get("quadperf_skipped")}
                if qp is None
                else {"holds": qp.holds, "gamma": qp.gamma, "lmi_vertices": qp.info.get("lmi_vertices")}
            ),
            "seconds": round(self.seconds, 2),
        }


class _Grid:
    """The vertices' open-loop responses on the grid, and the closed loop for a ``K(jω)``."""

    def __init__(self, vs, W_S, W_T, W_KS, omega):
        A, B, C, D = augmented_vertices(vs, W_S, W_T, W_KS)
        m = vs.m
        s = 1j * np.asarray(omega, float)
        n = A.shape[1]
        # H[v, f] = C (sI - A)^-1 B + D, all vertices and frequencies at once
        M = s[None, :, None, None] * np.eye(n) - A[:, None]
        H = C[:, None] @ np.linalg.solve(M, np.broadcast_to(B[:, None], M.shape[:2] + B.shape[1:])) + D[:, None]
        nz = H.shape[2] - m
        self.P11, self.P12 = H[:, :, :nz, :m], H[:, :, :nz, m:]
        self.P21, self.P22 = H[:, :, nz:, :m], H[:, :, nz:, m:]
        self.m = m

    def subset(self, idx) -> _Grid:
        out = object.__new__(_Grid)
        out.P11, out.P12, out.P21, out.P22 = (X[idx] for X in (self.P11, self.P12, self.P21, self.P22))
        out.m = self.m
        return out

    def peaks(self, K, dK=None):
        """σ_max of the closed loop at every (vertex, frequency), and its gradient data."""
        I = np.eye(self.m)
        R = np.linalg.inv(I - self.P22 @ K[None])  # (I - P22 K)^-1
        T = self.P11 + self.P12 @ K[None] @ R @ self.P21
        U, S, Vh = np.linalg.svd(T)
        sig = S[..., 0]
        if dK is None:
            return sig, None
        # dT = P12 (I - K P22)^-1 dK (I - P22 K)^-1 P21 ; dσ = Re(u^H dT v)
        L = self.P12 @ np.linalg.inv(I - K[None] @ self.P22)
        a = np.einsum("vfzi,vfz->vfi", L.conj(), U[..., :, 0])  # conj of (u^H L)
        b = R @ self.P21 @ Vh[..., 0, :].conj()[..., None]
        return sig, (a.conj(), b[..., 0])


def _abscissae(vs, structure, theta) -> np.ndarray:
    """Spectral abscissa of every frozen vertex's closed loop."""
    As = closed_loop_vertices(vs, structure.realization(theta))
    return np.linalg.eigvals(As).real.max(axis=1)


def _abscissa(vs, structure, theta) -> float:
    return float(np.max(_abscissae(vs, structure, theta)))


def _sub(vs, idx):
    from polyrob.analysis.time_varying.vertices import VertexSet

    return VertexSet(vs.A[idx], vs.B[idx], vs.C, vs.source, vs.enclosure, vs.note)


def vertex_peaks(vertices, K, W_S=None, W_T=None, W_KS=None, *, omega=DEFAULT_OMEGA) -> np.ndarray:
    """Each vertex's sampled peak of ``σ_max([W_S S; W_T T; W_KS K S])`` on ``omega`` (a lower bound of its H∞ norm)."""
    from polyrob.analysis.time_varying.vertices import controller_mats

    vs = vertex_set(vertices)
    Ak, Bk, Ck, Dk = controller_mats(K, vs.m)
    grid = _Grid(vs, W_S, W_T, W_KS, omega)
    s = 1j * np.asarray(omega, float)
    Kw = np.array([Ck @ np.linalg.solve(si * np.eye(len(Ak)) - Ak, Bk) + Dk if len(Ak) else Dk for si in s])
    return grid.peaks(Kw)[0].max(axis=1)


def vertex_peak(vertices, K, W_S=None, W_T=None, W_KS=None, *, omega=DEFAULT_OMEGA) -> float:
    """Worst vertex's sampled peak of ``σ_max([W_S S; W_T T; W_KS K S])`` on ``omega`` (a lower bound of its H∞ norm)."""
    return float(vertex_peaks(vertices, K, W_S, W_T, W_KS, omega=omega).max())


def vertex_synthesis(
    vertices,
    W_S=None,
    W_T=None,
    W_KS=None,
    *,
    structure="tf3",
    initial=None,
    omega=DEFAULT_OMEGA,
    which: str = "auto",
    max_vertices: int = MAX_VERTICES,
    max_iter: int = 150,
    rounds: int = 3,
    n_active: int = 64,
    min_decay: float = 1e-4,
    certify: bool = True,
    progress=None,
) -> VertexSynthesisResult:
    """Tune a fixed-structure controller on the worst vertex, then certify it for time-varying Jacobians.

    Parameters
    ----------
    vertices : PLDI, VertexSet or sequence of (A_i, B_i)
    W_S, W_T, W_KS : weights as in :func:`polyrob.plant.generalized.generalized_plant`
    structure : str or ControllerStructure
        ``"tf3"`` (the paper's K* structure), ``"pid"``, ``"ss:N"``, ...
    initial : LTI system, optional
        Warm start (default: the paper's ``K*``).  If it leaves a frozen
        vertex unstable, the gains :data:`GAIN_SCAN` are tried on it first.
    omega : array_like
        Frequency grid of the optimiser.
    max_iter : int
        BFGS iterations in all.
    rounds, n_active : int
        The optimiser works on the ``n_active`` vertices of highest peak (and
        the least stable ones), re-selected ``rounds`` times; every vertex is
        checked after each round and a round that does not lower the worst
        vertex over all of them ends the search.
    min_decay : float
        Every frozen vertex's closed-loop abscissa must stay below ``-min_decay``.
    certify : bool
        Run :func:`quadstab` and :func:`quadperf` on the result.

    Raises
    ------
    SynthesisError
        No gain of the warm start stabilises every frozen vertex.
    """
    from polyrob.plant.generalized import paper_controller
    from polyrob.synthesis.fixed.structures import controller_structure

    t0 = time.perf_counter()
    say = progress or (lambda msg: None)
    vs = vertex_set(vertices, which=which, max_vertices=max_vertices)
    st = controller_structure(structure, vs.m, vs.m)
    K0 = paper_controller() if initial is None else initial
    theta0, gain = None, None
    for g in GAIN_SCAN:
        th = st.from_controller(K0 * g)
        if _abscissa(vs, st, th) < -min_decay:
            theta0, gain = th, g
            break
    if theta0 is None:
        raise SynthesisError(
            f"no gain in {GAIN_SCAN} of the warm-start controller stabilises every frozen vertex of the "
            f"{vs.source} ({vs.n_vertices} vertices); give another initial controller"
        )
    omega = np.asarray(omega, float)
    grid = _Grid(vs, W_S, W_T, W_KS, omega)
    best = {"f": np.inf, "theta": theta0}

    def full_check(th):
        """Worst grid peak over all vertices, or inf if a frozen vertex is not stable enough."""
        if _abscissa(vs, st, th) >= -min_decay:
            return np.inf, None
        sig = grid.peaks(st.freqresp(th, omega))[0]
        return float(sig.max()), sig.max(axis=1)

    initial_peak, vpk = full_check(theta0)
    say(f"warm start (gain {gain}): worst vertex grid peak {initial_peak:.4g}")
    best.update(f=initial_peak, theta=theta0)
    theta, nit, msg = theta0, 0, ""
    for rnd in range(rounds):
        # cutting planes again: optimise on the vertices that matter now (highest peaks, least stable),
        # then check every vertex; most vertices never come near the worst one
        ab = _abscissae(vs, st, theta)
        idx = np.union1d(np.argsort(-vpk)[:n_active], np.argsort(-ab)[: max(n_active // 4, 1)])
        sub_vs, sub_grid = _sub(vs, idx), grid.subset(idx)
        scale = st.scale(theta)
        th_start = theta

        def objective(x):
            th = th_start + scale * x
            K, dK = st.freqresp(th, omega, jac=True)
            sig, (a, b) = sub_grid.peaks(K, dK)
            top = sig.max()
            if _abscissa(sub_vs, st, th) >= -min_decay:  # barrier: a frozen vertex lost stability
                return 1e3 * (1 + top), np.zeros_like(x)
            kappa = 40.0 / top
            w = np.exp(kappa * (sig - top))
            f = top + np.log(w.sum()) / kappa
            w /= w.sum()
            ab_ = np.einsum("vf,vfi,vfl->fil", w, a, b)  # a is the row u^H L
            return f, np.einsum("fil,fpil->p", ab_, dK).real * scale

        res = optimize.minimize(
            objective,
            np.zeros_like(theta),
            jac=True,
            method="BFGS",
            options={"maxiter": max(int(max_iter) // rounds, 1), "gtol": 1e-8},
        )
        nit, msg = nit + int(res.nit), str(res.message)
        cand = th_start + scale * res.x
        peak_c, vpk_c = full_check(cand)
        say(f"round {rnd + 1}: {idx.size} active vertices, worst vertex grid peak {peak_c:.4g}")
        report(rnd + 1, rounds)
        if not peak_c < best["f"] * (1 - 1e-4):
            break
        best.update(f=peak_c, theta=cand)
        theta, vpk = cand, vpk_c
    theta, peak = best["theta"], float(best["f"])
    K = st.controller(theta)
    qs = qp = None
    skipped = None
    if certify:
        qs = quadstab(vs, K)
        say(f"quadstab {qs.holds} ({qs.solver_status})")
        # gamma >= every vertex's H∞ norm >= its sampled peak, and the bounded-real LMI contains the
        # Lyapunov one: when either fails already, quadperf cannot hold and is not run
        if peak >= 1.0:
            skipped = f"worst vertex's sampled peak {peak:.4g} >= 1 (a lower bound of gamma)"
        elif not qs.holds and "infeasible" in qs.solver_status:
            skipped = "no common Lyapunov matrix exists (quadstab infeasible)"
        else:
            qp = quadperf(vs, K, W_S, W_T, W_KS, vertex_norms=False)
            say(f"quadperf gamma {qp.gamma:.4g}")
    return VertexSynthesisResult(
        controller=K,
        theta=theta,
        structure=st.name,
        order=st.order,
        grid_peak=peak,
        initial_grid_peak=initial_peak,
        warm_gain=float(gain),
        quadstab=qs,
        quadperf=qp,
        n_vertices=vs.n_vertices,
        vertex_source=vs.source,
        seconds=time.perf_counter() - t0,
        info={
            "quadperf_skipped": skipped,
            "bfgs_iterations": nit,
            "bfgs_message": msg,
            "omega": [omega[0], omega[-1], len(omega)],
        },
    )
