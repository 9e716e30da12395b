"""The time-varying certificate of a controller on a problem: the robot in motion.

μ with constant parameters (:mod:`polyrob.pipeline.analysis`) certifies each
*frozen* plant of the uncertainty set.  :func:`time_varying_certificate` adds
the test that holds for Jacobians varying arbitrarily fast inside the PLDI,
and so for the moving nonlinear robot while it stays in the domain
(docs/certificates.md):

* on the PLDI's vertices when they can be enumerated (polytope or box
  corners, at most :data:`~polyrob.analysis.time_varying.vertices.MAX_VERTICES`):
  quadratic stability (:func:`~polyrob.analysis.time_varying.quadratic.quadstab`) and,
  when it holds, quadratic H∞ performance
  (:func:`~polyrob.analysis.time_varying.quadratic.quadperf`), one Lyapunov matrix for all
  vertices;
* otherwise (6-7 joints) the constant-D scaled small gain on the LFT model
  (:func:`~polyrob.analysis.time_varying.smallgain.scaled_small_gain`), which
  covers the Jacobians as far as the uncertainty model covers them.

Every figure is a verified bound (the LMI solutions are checked a posteriori);
a test that was not run says why in ``notes``.

Examples
--------
>>> from polyrob import load_robot, paper_controller
>>> from polyrob.pipeline import build_problem
>>> problem = build_problem(load_robot("paper_2r"), bound_options={"samples": 256}, progress=False)
>>> tv = time_varying_certificate(problem, paper_controller())
>>> tv.method, tv.stability_holds          # K* has frozen vertices that are unstable
('vertices', False)
>>> tv.certificate.status.value, tv.verdict.startswith("time-varying verdict [vertices]: robust performance NOT")
('NOT_CERTIFIED', True)
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from polyrob.errors import PolyrobError

__all__ = ["TimeVaryingCertificate", "time_varying_certificate", "covers_nonlinear", "MAX_SMALL_GAIN_STATES"]

#: Largest LFT loop (states) the constant-D small-gain LMI is built for (one
#: KYP LMI whose size and build time grow like n^3).
MAX_SMALL_GAIN_STATES = 60


#: Added when the moving-robot verdict holds the model's physical constants fixed (:mod:`polyrob.analysis.lpv.constant`).
COVERS_WITH_CONSTANTS = (
    "The moving-robot verdict above covers the moving nonlinear robot in the same sense, with the model's "
    "physical constants (masses) fixed and its state moving at any rate."
)


def covers_nonlinear(method: str, constants: bool = False) -> str:
    """The sentence saying which verdicts cover the moving nonlinear robot (``constants``: the moving-robot verdict
    of :mod:`polyrob.analysis.lpv.constant` was computed)."""
    if constants:
        return (
            covers_nonlinear(method).replace("Only the time-varying", "The time-varying") + " " + COVERS_WITH_CONSTANTS
        )
    if method == "scaled small gain":
        return (
            "Only the time-varying certificate (constant-D scaled small gain, with a skew multiplier on each real "
            "repeated scalar, on the LFT model) covers the moving "
            "nonlinear robot, as far as the model covers its Jacobians and only while its state and its torques (accelerations, for a task domain) stay "
            "inside the domain the PLDI was bounded on; mu with constant parameters certifies each frozen robot "
            "of the set, not the robot in motion."
        )
    from polyrob.analysis.time_varying.results import COVERS_NONLINEAR

    return COVERS_NONLINEAR


@dataclass(frozen=True, eq=False)
class TimeVaryingCertificate:
    """Robust stability and performance for time-varying Jacobians.

    Attributes
    ----------
    method : str
        ``"vertices"`` (common Lyapunov matrix on the PLDI's vertices),
        ``"scaled small gain"`` (constant ``D`` on the LFT model), or
        ``"not run"`` (the loop is too large for both; ``notes`` say why).
    stability_holds, performance_holds : bool
        Verified: stability / ``L2 gain r -> z < 1`` for every variation.
    gamma : float
        Verified bound of the ``r -> z`` L2 gain (``inf`` when none was verified
        or the performance test did not run).
    stability, performance : result objects or None
        :class:`~polyrob.analysis.time_varying.results.QuadStabResult` /
        :class:`~polyrob.analysis.time_varying.results.QuadPerfResult`, or
        :class:`~polyrob.analysis.time_varying.smallgain.ScaledSmallGainResult`.
    covers : str
        What the certificate covers, precisely.
    notes : tuple of str
        Why a test did not run or did not hold.
    seconds : float
    """

    method: str
    stability_holds: bool
    performance_holds: bool
    gamma: float
    stability: object
    performance: object
    covers: str
    notes: tuple
    seconds: float
    scope: object = None

    def _decided(self, kind: str):
        from polyrob.analysis.certificate import ARBITRARY, Scope, gain_certificate

        scope = replace(self.scope or Scope(), kind=kind, variation=ARBITRARY, frequencies="")
        why = self.notes[-1] if self.notes else ""
        if kind == "robust stability":
            checked, gamma = self.stability is not None, None
        else:
            checked, gamma = self.performance is not None and self.stability_holds, self.gamma
        return gain_certificate(
            scope, stable=self.stability_holds, checked=checked, gamma=gamma, why=why, notes=self.notes
        )

    @property
    def certificate(self):
        """Robust performance for arbitrarily fast variation, decided by :mod:`polyrob.analysis.certificate`."""
        return self._decided("robust performance")

    @property
    def stability_certificate(self):
        """Robust stability for arbitrarily fast variation."""
        return self._decided("robust stability")

    @property
    def verdict(self) -> str:
        """One line: the performance certificate's verdict, and the stability one's when it differs."""
        perf, stab = self.certificate, self.stability_certificate
        if perf.certified or not stab.certified:
            return f"time-varying verdict [{self.method}]: {perf.verdict}"
        return f"time-varying verdict [{self.method}]: {stab.verdict}; {perf.verdict}"

    def summary(self) -> dict:
        """JSON-ready figures."""

        def margin(r):
            return None if r is None else float(getattr(r, "margin", np.nan))

        s = self.stability
        return {
            "method": self.method,
            "stability_holds": bool(self.stability_holds),
            "performance_holds": bool(self.performance_holds),
            "gamma": float(self.gamma),
            "stability_margin": margin(s) if self.method == "vertices" else None,
            "vertices": getattr(s, "n_vertices", None),
            "vertex_source": getattr(s, "vertex_source", None),
            "enclosure": getattr(s, "enclosure", None),
            "covers": self.covers,
            "status": self.certificate.status.value,
            "certified": self.certificate.certified,
            "stability_status": self.stability_certificate.status.value,
            "scope": self.certificate.scope.summary(),
            "covers_nonlinear": covers_nonlinear(self.method),
            "notes": list(self.notes),
            "seconds": round(float(self.seconds), 3),
            "verdict": self.verdict,
        }


def time_varying_certificate(problem, K, *, performance: bool = True, max_vertices: int | None = None):
    """Quadratic (or constant-D small-gain) stability and performance of ``K`` on ``problem``, with its scope.

    See :func:`_time_varying_tests` for the tests; the scope names the set
    the certificate rests on: the PLDI's vertices (the polytope's half-spaces
    are sampled supports, the box corners as proved as the intervals) or the
    LFT model.
    """
    from polyrob.analysis.certificate import Scope
    from polyrob.controller import Controller

    K = Controller.of(K)  # once: the vertex LMIs and the small-gain test take it as it is
    tv = _time_varying_tests(problem, K, performance=performance, max_vertices=max_vertices)
    scope = problem.scope() if hasattr(problem, "scope") else Scope()  # a bare (pldi, P) pair: no model
    s = tv.stability
    if tv.method == "vertices" and s is not None:
        source = "the polytope's vertices" if s.vertex_source == "polytope" else "the interval box's corners"
        scope = replace(scope, enclosure=s.enclosure, vertices_from=f"{source} of the PLDI ({s.enclosure})", model="")
    return replace(tv, scope=scope)


def _time_varying_tests(problem, K, *, performance: bool = True, max_vertices: int | None = None):
    """Quadratic (or constant-D small-gain) stability and performance of ``K`` on ``problem``.

    The vertex LMIs (one common Lyapunov matrix on the PLDI's vertices) run
    first; when they do not certify everything, or cannot run (too many
    vertices or states), the constant-D scaled small gain on the LFT model
    is tried, and the certificate that proves more is returned (the other's
    outcome is in ``notes``).  Both hold for arbitrarily fast variation; they
    cover different sets (the PLDI's polytope, the LFT model).

    Parameters
    ----------
    problem : polyrob.pipeline.Problem
        Its PLDI gives the vertices, its generalized plant the weights and the LFT.
    K : LTI
        ``m x m`` controller ``u = K (r - q)``.
    performance : bool
        Also test performance (run only when stability holds: it implies it).
    max_vertices : int, optional
        Largest vertex set tried before the small-gain test (default
        :data:`~polyrob.analysis.time_varying.vertices.MAX_VERTICES`).

    Returns
    -------
    TimeVaryingCertificate
    """

    from polyrob.analysis.time_varying.quadratic import MAX_STATES, quadperf, quadstab
    from polyrob.analysis.time_varying.vertices import MAX_VERTICES, controller_mats, vertex_set
    from polyrob.plant.generalized import GeneralizedPlant

    t0 = time.perf_counter()
    P = problem.P
    try:
        vs = vertex_set(problem.pldi, max_vertices=MAX_VERTICES if max_vertices is None else int(max_vertices))
    except PolyrobError as exc:
        return _small_gain(P, K, performance, t0, f"no vertex test: {exc}")
    n_loop = int(vs.A.shape[1]) + int(controller_mats(K, vs.B.shape[2])[0].shape[0])
    if n_loop > MAX_STATES:
        why = f"no vertex test: the closed loop has {n_loop} states (the vertex LMIs take {MAX_STATES})"
        return _small_gain(P, K, performance, t0, why)
    qs = quadstab(vs, K)
    notes, qp = [], None
    if not qs.holds:
        notes.append(f"no common Lyapunov matrix: {qs.solver_status}")
    elif performance:
        qp = quadperf(vs, K, P.W_S, P.W_T, P.W_KS, vertex_norms=False)
        if not qp.holds:
            notes.append(f"performance: {qp.solver_status}")
    else:
        notes.append("performance not tested")
    vertices = _certificate("vertices", qs, qp, notes, t0)
    if (vertices.stability_holds and (vertices.performance_holds or not performance)) or not isinstance(
        P, GeneralizedPlant
    ):
        return vertices
    # the other time-varying test, on the LFT model: a constant D can succeed where one common P fails
    why = "the vertex test did not certify everything (" + "; ".join(notes) + ")"
    other = _small_gain(P, K, performance, t0, why)
    rank = (other.stability_holds, other.performance_holds) > (vertices.stability_holds, vertices.performance_holds)
    if rank:
        return other
    extra = [n for n in other.notes if n != why]
    return _certificate("vertices", qs, qp, notes + [f"scaled small gain on the LFT model: {n}" for n in extra], t0)


def _certificate(method: str, stability, performance, notes, t0: float) -> TimeVaryingCertificate:
    """The certificate from its tests' results (``None``: not run); verdicts and scope follow from them."""
    return TimeVaryingCertificate(
        method=method,
        stability_holds=bool(stability is not None and stability.holds),
        performance_holds=bool(performance is not None and performance.holds),
        gamma=float(performance.gamma) if performance is not None else np.inf,
        stability=stability,
        performance=performance,
        covers=stability.covers if stability is not None else "nothing (no time-varying test was run)",
        notes=tuple(notes),
        seconds=time.perf_counter() - t0,
    )


def _nominal(N, P, performance: bool, t0: float, why: str) -> TimeVaryingCertificate:
    """The loop of an exact model (no uncertainty channel): one LTI system, so its H∞ norm is the test.

    Nothing in the model varies, so "arbitrarily fast variation" adds nothing:
    stability is the loop's (:func:`~polyrob.analysis.stability.stability_verdict`,
    which never reads a bare double-precision sign) and performance its
    H∞ norm, bounded by the small gain on the performance block alone.
    """
    from polyrob.analysis.stability import stability_verdict
    from polyrob.analysis.time_varying.smallgain import ScaledSmallGainResult, scaled_small_gain

    covers = "the exact model's loop (no uncertainty channel: nothing varies), as far as the model is the robot"
    verdict = stability_verdict(N)
    stable = verdict.verdict == "stable"
    rs = ScaledSmallGainResult(
        holds=stable, gamma=0.0 if stable else np.inf, scaled_norm=np.nan, unscaled_norm=np.nan, X_r=None,
        X_c=None, seconds=time.perf_counter() - t0, covers=covers,
        info={"route": "no uncertainty channel: the loop's own stability", "stability": verdict.verdict},
    )  # fmt: skip
    notes, rp = [why, "the model has no uncertainty channel: the loop's stability and H∞ norm decide"], None
    if not stable:
        notes.append(f"the loop is {verdict.verdict}")
    elif performance:
        rp = replace(scaled_small_gain(N, P.block_structure_rp), covers=covers)
        if not rp.holds:
            notes.append(f"performance: H∞ norm bound {rp.gamma:.4g} >= 1")
    return _certificate("scaled small gain", rs, rp, notes, t0)


def _small_gain(P, K, performance: bool, t0: float, why: str) -> TimeVaryingCertificate:
    """Constant-D scaled small gain on the LFT model (too many vertices to enumerate)."""
    from polyrob.analysis.time_varying.smallgain import scaled_small_gain
    from polyrob.plant.generalized import lft

    N = lft(P, K)
    if N.nstates > MAX_SMALL_GAIN_STATES:
        note = (
            f"no small-gain test either: the LFT loop has {N.nstates} states (it takes {MAX_SMALL_GAIN_STATES}); "
            "reduce the controller (--reduce) or use a fixed structure (--structure tf3)"
        )
        return _certificate("not run", None, None, (why, note), t0)
    s_v, s_d = P.output_slices["v"], P.input_slices["d"]
    if s_d.stop == s_d.start:  # an exact model (e.g. computed torque with no model error): nothing varies
        return _nominal(N, P, performance, t0, why)
    rs = scaled_small_gain(N[s_v, s_d], P.block_structure_rs)
    notes, rp = [why], None
    if not rs.holds:
        notes.append(f"scaled small gain {rs.gamma:.4g} >= 1 ({rs.info.get('reason', 'no D brings it below 1')})")
    elif performance:
        rp = scaled_small_gain(N, P.block_structure_rp)
        if not rp.holds:
            notes.append(f"performance: scaled small gain {rp.gamma:.4g} >= 1")
    return _certificate("scaled small gain", rs, rp, notes, t0)
