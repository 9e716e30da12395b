"""A controller judged on a problem: nominal and robust stability/performance, sampling, one verdict.

``polyrob analyze`` and ``polyrob run`` call :func:`analyze_controller` and
print the same :func:`verdict` line; ``polyrob synth`` prints the verdict of
the synthesis certificate with the same words.

Examples
--------
>>> verdict(0.8, 0.79, covers="the box")
'verdict: robust performance CERTIFIED (peak mu upper bound 0.8 < 1 on the frequency grid) for the box'
>>> verdict(2.23, 2.22, covers="the box").split(";")[0]
'verdict: robust performance VIOLATED (mu lower bound 2.22 >= 1: some parameters in the set break it) for the box'
"""

from __future__ import annotations

from dataclasses import dataclass

from polyrob.errors import ArgumentError

__all__ = ["ControllerAnalysis", "analyze_controller", "verdict", "frequency_grid", "controller_order", "NEXT_STEPS"]

#: What to try when robust performance is not certified.
NEXT_STEPS = (
    "try: other performance targets (--bandwidth-scale; `polyrob synth --max-bandwidth` finds the largest "
    "bandwidth factor with mu < 1, and the performance limit that synth prints says below which no controller "
    "can reach it), a smaller domain (--qdot-max, --u-max, --q-range), or a tighter uncertainty model "
    "(--uncertainty)"
)


def verdict(
    mu_upper: float,
    mu_lower: float,
    *,
    nominally_stable: bool = True,
    covers: str = "",
    failed=(),
    everywhere: float | None = None,
) -> str:
    """One plain line: the robust-performance verdict, what it covers, what to try next when it fails.

    ``failed`` are the analysis' own reasons not to certify (e.g. the loop at
    ``Δ = 0`` not proved stable); with any, μ < 1 certifies nothing.
    ``everywhere`` is a μ bound verified at every frequency
    (:attr:`polyrob.analysis.mu.results.MuBoundsResult.upper_everywhere`), if any.
    """
    where = f" for {covers}" if covers else ""
    if not nominally_stable:
        return (
            "verdict: NOT certified: the nominal closed loop is unstable, so mu certifies nothing; "
            "try another controller (e.g. `polyrob synth`)"
        )
    blocking = [f for f in failed if "mu upper bound" not in f]
    if mu_upper < 1 and blocking:
        return (
            f"verdict: robust performance NOT certified although mu < 1 ({'; '.join(blocking)}){where}; "
            "try another controller (e.g. `polyrob synth`)"
        )
    if everywhere is not None and mu_upper < 1 <= everywhere:
        return (
            f"verdict: robust performance NOT certified: mu < 1 on the frequency grid ({mu_upper:.4g}) but up to "
            f"{everywhere:.4g} between its points{where}; {NEXT_STEPS}"
        )
    if everywhere is not None and everywhere < 1:
        return (
            f"verdict: robust performance CERTIFIED (mu upper bound {everywhere:.4g} < 1 at every frequency; "
            f"peak {mu_upper:.4g} on the grid){where}"
        )
    if mu_upper < 1:
        return f"verdict: robust performance CERTIFIED (peak mu upper bound {mu_upper:.4g} < 1 on the frequency grid){where}"
    if mu_lower >= 1:
        return (
            f"verdict: robust performance VIOLATED (mu lower bound {mu_lower:.4g} >= 1: some parameters "
            f"in the set break it){where}; {NEXT_STEPS}"
        )
    return (
        f"verdict: robust performance NOT certified (mu in [{mu_lower:.4g}, {mu_upper:.4g}] straddles 1){where}; "
        f"{NEXT_STEPS}"
    )


def frequency_grid(lo: float, hi: float, n: int):
    """``n`` log-spaced frequencies from ``lo`` to ``hi`` (rad/s)."""
    import numpy as np

    if not (0 < lo < hi and n >= 2):
        raise ArgumentError(f"frequency grid: need 0 < LO < HI and N >= 2, got {lo}:{hi}:{n}")
    return np.logspace(np.log10(lo), np.log10(hi), int(n))


def controller_order(K) -> int:
    """Number of states of a minimal-looking realisation of ``K`` (``control.ss(K).nstates``)."""
    import control

    return int(control.ss(K).nstates)


def _check_sizes(problem, K) -> None:
    import control

    Kss = control.ss(K)
    P = problem.P
    if (Kss.noutputs, Kss.ninputs) != (P.n_u, P.n_y):
        raise ArgumentError(
            f"the controller has {Kss.ninputs} input(s) and {Kss.noutputs} output(s); "
            f"{problem.robot.name} needs {P.n_y} measurement input(s) and {P.n_u} torque output(s)"
        )


@dataclass(frozen=True, eq=False)
class ControllerAnalysis:
    """What :func:`analyze_controller` found.

    Attributes
    ----------
    robust_stability, robust_performance : RobustnessResult
    nominal_performance : float
        ``||N_zw||∞`` around the nominal plant (``inf`` if the loop is unstable).
    sampling : StabilitySampling
    order : int
    covers : str
        What the μ verdict covers.
    time_varying : TimeVaryingCertificate or None
        The certificate for Jacobians varying in time (the moving robot),
        :func:`polyrob.pipeline.time_varying.time_varying_certificate`;
        ``None`` when not asked for.
    """

    robust_stability: object
    robust_performance: object
    nominal_performance: float
    sampling: object
    order: int
    covers: str
    time_varying: object = None

    @property
    def verdict(self) -> str:
        rp = self.robust_performance
        return verdict(
            rp.mu_upper,
            rp.mu_lower,
            nominally_stable=self.robust_stability.nominally_stable,
            covers=self.covers,
            failed=tuple(getattr(rp, "failed", ())),
            everywhere=getattr(rp.mu, "upper_everywhere", None),
        )

    @staticmethod
    def status(r) -> str:
        """``certified`` / ``violated`` / ``not certified`` for one robustness result."""
        if not r.nominally_stable:
            return "not certified (nominally unstable)"
        if r.mu_lower >= 1:
            return "violated"
        return "certified" if getattr(r, "robust", r.mu_upper < 1) and r.mu_upper < 1 else "not certified"

    def summary(self) -> dict:
        s = self.sampling
        rs, rp = self.robust_stability.summary(), self.robust_performance.summary()
        rs["status"], rp["status"] = self.status(self.robust_stability), self.status(self.robust_performance)
        return {
            "controller_order": self.order,
            "nominal_stability": bool(self.robust_stability.nominally_stable),
            "nominal_performance_hinf": float(self.nominal_performance),
            "robust_stability": rs,
            "robust_performance": rp,
            "monte_carlo": {"samples": s.random, "stable_fraction": s.random_stable},
            "corners": {"count": s.corners, "stable_fraction": s.corners_stable},
            "worst_sampled": {
                "delta": [float(x) for x in s.worst_delta.ravel()],
                "max_pole_real_part": float(s.worst_abscissa),
            },
            "covers": self.covers,
            "verdict": self.verdict,
            "time_varying": None if self.time_varying is None else self.time_varying.summary(),
        }


def analyze_controller(
    problem,
    K,
    *,
    omega=None,
    mc: int = 500,
    seed: int = 0,
    progress: bool | None = None,
    time_varying: bool = True,
) -> ControllerAnalysis:
    """Nominal/robust stability and performance of ``K`` on ``problem``, and sampled stability.

    Parameters
    ----------
    problem : Problem
    K : LTI
        ``n_u x n_y`` controller.
    omega : array_like, optional
        Frequency grid (default: automatic, peak-refined).
    mc : int
        Random parameter sets for the sampled stability check (>= 1).
    seed : int
    progress : bool, optional
        Progress bars of the μ sweeps.
    time_varying : bool
        Also compute the time-varying certificate (quadratic stability and
        performance on the PLDI's vertices, or the constant-D small gain).
    """
    from polyrob.analysis.robust import nominal_performance, robperf, robstab, sample_stability

    if int(mc) < 1:
        raise ArgumentError(f"Monte Carlo samples must be >= 1, got {mc}")
    _check_sizes(problem, K)
    options = {"progress": progress}
    rs = robstab(problem.P, K, omega, **options)
    rp = robperf(problem.P, K, omega, **options)
    npf = nominal_performance(problem.P, K)
    sampling = sample_stability(problem.unc, K, n=int(mc), seed=seed)
    covers = getattr(rp, "covers", None)  # the analysis' own wording when it provides one
    covers = covers() if callable(covers) else covers
    covers = covers or problem.covers()
    tv = None
    if time_varying:
        from polyrob.pipeline.time_varying import time_varying_certificate

        tv = time_varying_certificate(problem, K)
    return ControllerAnalysis(
        robust_stability=rs,
        robust_performance=rp,
        nominal_performance=float(npf),
        sampling=sampling,
        order=controller_order(K),
        covers=str(covers),
        time_varying=tv,
    )
