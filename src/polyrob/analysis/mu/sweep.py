"""The μ sweep over frequency: the upper bound by the chosen method at each point, the lower bound, peak refinement.

:func:`polyrob.analysis.mu.bounds.mu_bounds` checks its arguments and chooses
the method by the structure; :func:`run_sweep` does the work.
"""

from __future__ import annotations

import numpy as np

from polyrob.analysis.mu import upper as mu_upper
from polyrob.analysis.mu.blocks import BlockStructure
from polyrob.analysis.mu.frequency import freqresp, refine_peaks
from polyrob.analysis.mu.gradient import GradientUpper
from polyrob.analysis.mu.lower import lower_bound
from polyrob.analysis.mu.results import MuBoundsResult
from polyrob.analysis.mu.upper import LmiUpper
from polyrob.analysis.timelimit import TimeLimitedCall
from polyrob.progress import report

__all__ = [
    "run_sweep",
    "relaxation_note",
    "DESCENT_ABOVE",
    "MANY_REAL_SCALARS",
    "relaxed_is_cheap",
    "AB13MD_SAFETY_TIMEOUT",
    "LARGE_AB13MD_TIMEOUT",
]

#: ``method="auto"`` bounds repeated scalar blocks by descent on the D-G scalings above this padded
#: size: the D-G LMI of an 89-channel structure (ur5's axes model) takes minutes per frequency.
DESCENT_ABOVE = 24
#: ``method="auto"`` bounds a structure without repeated blocks by descent instead of AB13MD when it
#: has more real scalar blocks than this: AB13MD's time grows with them (seconds per frequency with
#: 72, talos_left_arm's ``axes`` model, against about a second for descent at the same bound:
#: ``benchmarks/mu.py --choice``; milliseconds with the 6 of an arm's relaxed ``inner-gain`` structure).
MANY_REAL_SCALARS = 16
#: A descent bound more than this factor above the lower bound at a frequency is tried again: by descent
#: from a cold start, then by AB13MD on the relaxed structure (when that structure has at most
#: :data:`MANY_REAL_SCALARS` real scalars).
SECOND_BOUND_GAP = 1.02
#: ... at the frequencies whose bound is at least this fraction of the sweep's peak (or at least 1).
SECOND_BOUND_PEAK = 0.9
#: Wall-clock seconds a cold AB13MD call of a sweep may take before it is taken for hung (default
#: of :func:`mu_bounds`' ``ab13md_timeout`` and ``warm_timeout``).  A safety net, not a choice of
#: method: it must never fire on a call that is merely slow or on a busy machine.  Slow calls do
#: happen on structures with real blocks: measured 49 s of CPU time for one cold call (eight real
#: scalars, the robust-stability loop of ``tests/fixtures/validate_planar_2r_K.json`` on the
#: ``paper_2r`` plant of ``tests/test_report.py``, at 10**3.2 rad/s).
AB13MD_SAFETY_TIMEOUT = 300.0
#: The least AB13MD safety limit on structures above :data:`DESCENT_ABOVE` padded channels
#: (measured: AB13MD on ur5's relaxed structure 26-37 s per frequency; on a random matrix against
#: a 114-channel structure 196 s on a busy machine).
LARGE_AB13MD_TIMEOUT = 1200.0


def relaxed_is_cheap(st: BlockStructure) -> bool:
    """Whether AB13MD on ``st``'s relaxed structure is cheap: at most :data:`MANY_REAL_SCALARS` real scalars."""
    return sum(b.kind == "real" for b in st.relaxed().blocks) <= MANY_REAL_SCALARS


def relaxation_note(st: BlockStructure) -> str:
    """The note of a sweep whose upper bound is on the relaxed structure."""
    return (
        f"upper bound on the relaxed structure {st.relaxed()} (each repeated scalar as independent scalars or a "
        "full block, a superset: conservative, still an upper bound); lower bound on the structure itself"
    )


def run_sweep(
    sys, st, omega, is_frd, meth, refine_peak, warm_start, warm_timeout, progress, rtol, solver, bits, cold_timeout
):
    from tqdm import tqdm

    # "relaxed": AB13MD on a superset structure (repeated scalars split); the lower bound stays on st
    st_up = st.relaxed()
    lmi = LmiUpper(st, solver) if meth == "lmi" else None
    descent = GradientUpper(st) if meth == "gradient" else None
    large = st.padded_size > DESCENT_ABOVE
    if cold_timeout and large:
        cold_timeout = max(cold_timeout, LARGE_AB13MD_TIMEOUT)
    cold = None
    if meth in ("ab13md", "relaxed"):
        # the safety net's fallback is fixed by the structure too: the LMI takes minutes on large ones
        fallback = (GradientUpper(st_up), "D-G descent") if large else (None, "D-G LMI")
        cold = mu_upper.TimedAb13md(st_up, cold_timeout, solver, rtol, fallback=fallback[0], fallback_name=fallback[1])
    # descent can stall on a large, ill-conditioned response (xarm7's PID loops at high frequency, docs/mu.md):
    # where the relaxed structure has few real scalars AB13MD is cheap, its scalings are admissible here, and
    # it answers wherever descent leaves a gap above the lower bound
    second = None
    if meth == "gradient" and relaxed_is_cheap(st):
        second = mu_upper.TimedAb13md(st_up, cold_timeout, solver, rtol, fallback=GradientUpper(st_up))
    guard = None
    if warm_start and meth in ("ab13md", "relaxed"):
        guard = TimeLimitedCall(mu_upper.worker_function(), warm_timeout)
    fallbacks, notes = 0, ([relaxation_note(st)] if meth == "relaxed" else [])
    state = {"x": None, "pi": None, "xg": None}
    n = st.padded_size

    def upper_at(Ms, lo=0.0):
        nonlocal fallbacks, guard
        if not np.all(np.isfinite(Ms)):  # on a pole of M: mu is infinite
            return np.inf, np.eye(n), np.zeros((n, n))
        if lmi is not None:
            return lmi(Ms, lo=lo, rtol=rtol)
        if descent is not None:
            up, D, G, state["xg"] = descent(Ms, state["xg"])
            return up, D, G
        res = None
        if guard is not None and state["x"] is not None and np.any(Ms):
            ok, val = guard(Ms, *st_up.ab13md_args, state["x"])
            if ok:
                res = val
            else:  # hung or failed once: stop warm-starting for this sweep
                fallbacks += 1
                notes.append(
                    f"AB13MD warm start failed or exceeded its {warm_timeout:g} s wall-clock safety limit ({val}); "
                    "cold calls from then on"
                )
                guard.close()
                guard = None
        up, D, G, x = mu_upper.upper_ab13md(Ms, st_up, res) if res is not None else cold(Ms, lo)
        state["x"] = x if x is not None else state["x"]
        return up, D, G

    def tightened(Ms, up, D, G, lo):
        """The relaxed AB13MD bound where it is below descent's, which left a gap above the lower bound."""
        if second is None or up <= SECOND_BOUND_GAP * lo or not np.all(np.isfinite(Ms)):
            return up, D, G
        up2, D2, G2 = second(Ms, lo)[:3]
        return (up2, D2, G2) if up2 < up else (up, D, G)

    def lower_at(Ms, refine=False, target=np.inf, D=None):
        if not np.all(np.isfinite(Ms)):
            return np.inf, np.zeros((n, n), complex)
        lo, dsq, pi = lower_bound(
            Ms, st, starts=1 if not refine else 4, refine=refine, init=state["pi"], target=target, D=D
        )
        state["pi"] = pi if pi is not None else state["pi"]
        return lo, dsq

    cold_tried = set()

    def cold_from_the_top():
        """Descent from a cold start at the peak while it has a gap above the lower bound (smaller bound kept).

        Descent warm-starts from the previous frequency's scalings and can settle in a poor stationary
        point of their non-convex parametrisation (ur5's engineer's set, a PID tuned on true robots: 4.51
        at 0.46 rad/s warm, 1.17 cold, lower bound 1.14).  The peak alone decides the verdict, so a point
        below it is not retried (where a lower bound failed, every point would be a candidate).
        """
        while descent is not None:
            i = int(np.argmax(np.where(np.isfinite(up), up, -np.inf)))
            if i in cold_tried or up[i] <= SECOND_BOUND_GAP * lo[i] or not np.all(np.isfinite(H[i])):
                return
            cold_tried.add(i)
            up_cold, D_cold, G_cold = descent(H[i], None)[:3]
            if up_cold < up[i]:
                up[i], Ds[i], Gs[i] = up_cold, D_cold, G_cold

    H = st.pad(freqresp(sys, omega, bits=bits))
    show = (omega.size >= 50) if progress is None else progress
    up, lo = np.zeros(omega.size), np.zeros(omega.size)
    Ds, Gs = np.zeros((omega.size, n, n), complex), np.zeros((omega.size, n, n), complex)
    deltas = {}
    try:
        for i in tqdm(range(omega.size), disable=None if show else True, desc="mu", leave=False):
            if lmi is not None:  # the bisection wants the lower bound as bracket
                lo[i], deltas[i] = lower_at(H[i])
            up[i], Ds[i], Gs[i] = upper_at(H[i], lo[i])
            l2, d2 = lower_at(H[i], D=Ds[i])
            if l2 >= lo[i]:
                lo[i], deltas[i] = l2, d2
            report(i + 1, omega.size)  # the grid is the sweep's work: its points move the job's line
        cold_from_the_top()  # before the peak is refined: a false peak would draw the refinement
        extra = []
        can_eval = not is_frd or getattr(sys, "ifunc", None) is not None
        if refine_peak and can_eval and omega.size >= 3:
            extra = refine_peaks(omega, up, lambda w: upper_at(st.pad(freqresp(sys, np.array([w]), bits=bits))[0])[0])
        # refined points (and the best lower-bound points) get the full treatment
        w_new = np.array([w for w in extra if w not in omega])
        if w_new.size:
            Hn = st.pad(freqresp(sys, w_new, bits=bits))
            res = []
            for k in range(w_new.size):
                u = upper_at(Hn[k])
                res.append((u, lower_at(Hn[k], refine=True, target=u[0], D=u[1])))
            omega = np.concatenate([omega, w_new])
            H = np.concatenate([H, Hn])
            up = np.concatenate([up, [r[0][0] for r in res]])
            lo = np.concatenate([lo, [r[1][0] for r in res]])
            Ds = np.concatenate([Ds, np.array([r[0][1] for r in res])])
            Gs = np.concatenate([Gs, np.array([r[0][2] for r in res])])
            for k, r in enumerate(res):
                deltas[omega.size - w_new.size + k] = r[1][1]
        cold_from_the_top()
        # AB13MD on the relaxed structure where descent left a gap, from the top down to where the bound
        # matters (within SECOND_BOUND_PEAK of the peak, or at least 1): the peak and the decision
        tried = set()
        while second is not None:
            level = min(SECOND_BOUND_PEAK * np.max(up[np.isfinite(up)], initial=0.0), 1.0)
            todo = [i for i in range(up.size) if i not in tried and up[i] >= level and up[i] > SECOND_BOUND_GAP * lo[i]]
            if not todo:
                break
            for i in todo:
                tried.add(i)
                up[i], Ds[i], Gs[i] = tightened(H[i], up[i], Ds[i], Gs[i], lo[i])
        # refine the lower bound where it matters: at its own and at the upper peak
        for i in {int(np.argmax(lo)), int(np.argmax(up))}:
            if lo[i] >= up[i] * (1 - 1e-7):
                continue
            lo_i, d_i = lower_at(H[i], refine=True, target=up[i], D=Ds[i])
            if lo_i > lo[i]:
                lo[i], deltas[i] = lo_i, d_i
    finally:
        if guard is not None:
            guard.close()
        for timed in (cold, second):
            if timed is not None:
                timed.close()
    up = np.maximum(up, lo)
    order = np.argsort(omega)
    iu, il = int(np.argmax(up)), int(np.argmax(lo))
    return MuBoundsResult(
        omega=omega[order],
        upper=up[order],
        lower=lo[order],
        D=Ds[order],
        G=Gs[order],
        peak_upper=float(up[iu]),
        peak_upper_frequency=float(omega[iu]),
        peak_lower=float(lo[il]),
        critical_frequency=float(omega[il]),
        worst_delta=st.unpad_delta(deltas[il]),
        structure=st,
        method=meth,
        warm_start_fallbacks=fallbacks,
        notes=tuple(
            notes
            + ([] if lmi is None else lmi.events)
            + (
                [
                    f"AB13MD exceeded its {cold_timeout:g} s wall-clock safety limit at {cold.fallbacks} "
                    f"frequencies (taken for hung): {cold.fallback_name} upper bound used there, a true bound "
                    "but not AB13MD's figure, so these points depend on the machine's speed"
                ]
                if cold is not None and cold.fallbacks
                else []
            )
            + ([] if cold is None else cold.events)
            + ([] if bits is None else [f"frequency responses evaluated at {bits} bits"])
        ),
    )


# Public name for the D-scale fit of the synthesis stage; the private spelling
# stays until polyrob.synthesis.scalings.dscale has moved over to the public one.
