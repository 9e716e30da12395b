"""The worst-case gain over the whole uncertainty set, as MATLAB's ``wcgain``: an upper bound proved at every frequency.

Robust performance asks whether *every* member of the set meets the
weights (μ < 1 of the loop with the performance block).  When it does not,
:mod:`polyrob.analysis.margins` says for how much of the set it would
(``robgain``: the set shrunk by ``1/β``).  An engineer stating the set
usually wants the other reading: on the **whole** set, is every member
stable, and how far does the worst one miss the weights?  That is the
worst-case gain ``sup_Δ ||F_u(N, Δ)||_∞`` over the set (``∞`` when a member
is unstable), MATLAB's ``wcgain``.

By the main loop theorem (Packard & Doyle 1993) with the performance
channels scaled: let ``N_γ`` be the closed loop with its performance inputs
``w`` divided by ``γ``.  If μ of ``N_γ`` (against the uncertainty blocks and
the full performance block) is at most ``b < 1`` at every frequency and
the loop is stable at ``Δ = 0``, every member with ``||Δ|| ≤ 1/b`` (so
every member of the set) is stable and has ``||F_u(N, Δ)||_∞ ≤ b γ``.  This
is the skewed μ of the robust control literature (Fan & Tits; MATLAB's
``wcgain`` upper bound).  So:

1. on the sweep's frequency grid the smallest ``γ`` whose μ upper bound is
   below 1 is found (bisection in ``log γ``, each frequency started from the
   largest ``γ`` found so far, so that most frequencies cost one μ bound);
2. the loop with ``w / γ`` (``γ`` a little above that) is certified with
   :func:`~polyrob.analysis.certificate.certify_loop`, the frozen
   certificate's machinery: the stability at ``Δ = 0``, μ on the grid and
   the check between its points; a certified bound ``b`` gives the upper
   bound ``b γ`` **at every frequency**.  If it does not certify, ``γ`` is
   raised (a few tries) and otherwise no upper bound is claimed;
3. the lower bound is a member's gain: each μ lower bound's worst
   perturbation, its uncertainty part brought inside the unit ball, is
   closed around the loop at its frequency and ``σ̄(F_u(N(jω), Δ))`` is
   computed exactly (a member of the *model's* set; ``∞`` if it makes the
   loop singular there).

Examples
--------
A first-order loop ``x' = -x + 0.5 δ x + w``, ``z = x``, with one real
scalar ``δ ∈ [-1, 1]`` (``d = δ v``, ``v = x``): ``F_u = 1/(s + 1 - 0.5 δ)``,
whose worst member is ``δ = 1`` with the DC gain 2:

>>> import control
>>> from polyrob.analysis.worst_case import wcgain
>>> P = control.ss([[-1.0]], [[0.5, 1.0, 0.0]], [[1.0], [1.0], [0.0]], [[0.0] * 3] * 3)
>>> g = wcgain(P, 0.0, [[-1, 0], [1, 1]], n_u=1, n_y=1)     # inputs [d, w, u], outputs [v, z, y]
>>> g.proved, round(g.lower, 3), bool(2.0 <= g.upper <= 2.0 * 1.03)
(True, 2.0, True)
>>> g.sentence()
'worst-case gain between 2 and 2.02 (every member stable; upper bound at every frequency)'
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from polyrob._threads import single_blas_thread
from polyrob.errors import ArgumentError

__all__ = ["WorstCaseGain", "wcgain", "performance_scaled"]

#: Relative width of the bisection on ``γ`` at each frequency, and the margin the certified ``γ`` starts above it.
RTOL = 0.01
#: Certification attempts, ``γ`` raised by :data:`RAISE` after each one that does not certify.
TRIES = 3
RAISE = 1.1
#: Shares of the job's line: the grid's level (of which the first pass), then the certificate.
GRID_SHARE, FIRST_SHARE = 0.5, 0.7
#: Frequencies (the first pass's hardest) where members are also searched at levels below the grid's.
MEMBER_FREQUENCIES = 5
#: ``γ`` doublings before a frequency is declared unbounded (μ of the uncertainty alone near or above 1).
MAX_DOUBLINGS = 40


@dataclass(frozen=True, eq=False)
class WorstCaseGain:
    """Bounds on the worst-case weighted gain over the uncertainty set (MATLAB ``wcgain``).

    Attributes
    ----------
    lower : float
        The weighted gain of a member of the model's set at
        ``critical_frequency`` (``inf``: a member makes the loop singular
        there).  A lower bound of the worst case.
    upper : float
        Proved at every frequency when :attr:`proved` (every member of the
        set stable with ``||W F||_∞ ≤ upper``); ``inf`` otherwise.
    critical_frequency : float
        Where the lower bound was found (rad/s).
    grid_level : float
        The smallest ``γ`` whose μ upper bound is below 1 at every grid
        point (``inf`` when some point has none).
    certificate : Certificate or None
        The certificate of the loop with its performance inputs divided by
        the ``γ`` tried last (its status decides :attr:`proved`).
    reason : str
        Why no upper bound was proved (empty when one was).
    seconds : float
    """

    lower: float
    upper: float
    critical_frequency: float
    grid_level: float
    certificate: object | None
    reason: str = ""
    seconds: float = 0.0

    @property
    def proved(self) -> bool:
        """The upper bound holds at every frequency: its certificate's status is CERTIFIED."""
        return self.certificate is not None and self.certificate.certified

    def sentence(self) -> str:
        """One line in MATLAB's words: the two bounds and what the upper one covers."""
        if not np.isfinite(self.lower):
            return (f"worst-case gain infinite: a member of the model's set makes the loop singular at "
                    f"{self.critical_frequency:.3g} rad/s (robust stability fails)")  # fmt: skip
        low = f"{self.lower:.3g}"
        if self.proved:
            return f"worst-case gain between {low} and {self.upper:.3g} (every member stable; upper bound at every frequency)"
        return f"worst-case gain at least {low}; no upper bound proved ({self.reason})"

    def summary(self) -> dict:
        """Strict JSON (no NaN)."""
        from polyrob.analysis.scope import finite_or_none

        return {
            "lower": float(self.lower) if np.isfinite(self.lower) else "inf",
            "upper": float(self.upper) if self.proved else None,
            "proved": bool(self.proved),
            "critical_frequency": finite_or_none(self.critical_frequency),  # none: no member was claimed
            "grid_level": float(self.grid_level) if np.isfinite(self.grid_level) else "inf",
            "reason": self.reason,
            "certificate": None if self.certificate is None else self.certificate.summary(),
            "seconds": round(float(self.seconds), 1),
        }


def performance_scaled(system, gamma: float, n_w: int, n_u: int):
    """``system`` with its performance inputs (the ``n_w`` inputs before the last ``n_u``) divided by ``gamma``."""
    import control

    sys = control.ss(system)
    B, D = np.array(sys.B, float), np.array(sys.D, float)
    cols = slice(B.shape[1] - n_u - n_w, B.shape[1] - n_u)
    B[:, cols] /= gamma
    D[:, cols] /= gamma
    return control.ss(np.asarray(sys.A, float), B, np.asarray(sys.C, float), D)


def _member_gain(H, delta, n_d: int, n_v: int) -> float:
    """The largest ``σ̄(F_u(H, Δ_u))`` of the uncertainty part of ``delta``, brought into the set or onto its boundary.

    ``inf`` when ``I - H_vd Δ_u`` is singular (condition above 1e12).  The
    μ lower bound's perturbation is on the structure's own blocks, its
    largest block of size ``1/ℓ``: shrunk into the set when ``ℓ < 1``, and
    also scaled onto the boundary (the largest block of size 1), which is a
    member too and often a worse one.  The largest block's size is the
    block-diagonal matrix's norm.
    """
    Du = np.asarray(delta)[:n_d, :n_v]
    size = float(np.linalg.norm(Du, 2)) if Du.size else 0.0
    if size == 0.0:
        return float(np.linalg.norm(H[n_v:, n_d:], 2))
    best = 0.0
    for scale in {1.0 / max(1.0, size), 1.0 / size}:
        A = np.eye(n_v) - H[:n_v, :n_d] @ (scale * Du)
        if np.linalg.cond(A) > 1e12:
            return float("inf")
        F = H[n_v:, n_d:] + H[n_v:, :n_d] @ (scale * Du) @ np.linalg.solve(A, H[:n_v, n_d:])
        best = max(best, float(np.linalg.norm(F, 2)))
    return best


class _Skewed:
    """μ of the loop's responses ``H`` with the performance inputs divided by ``γ``, warm-started per frequency.

    ``upper(k, γ)``: the upper bound at the ``k``-th frequency (descent on
    the D-G scalings from that frequency's last ones, where the structure
    takes descent; otherwise :func:`~polyrob.analysis.mu.bounds.mussv`).
    ``member(k, γ)``: the μ lower bound's perturbation there, its gain as a
    member (kept when it is the largest so far, with its frequency).
    """

    def __init__(self, H, st, n_d: int, n_v: int, members: bool):
        from polyrob.analysis.mu.bounds import resolve_method
        from polyrob.analysis.mu.gradient import GradientUpper

        self.H, self.st, self.n_d, self.n_v, self.members = H, st, n_d, n_v, members
        self.descent = GradientUpper(st) if resolve_method(st, "auto") == "gradient" else None
        self.x, self.last, self.lower, self.at = {}, None, 0.0, None

    def _scaled(self, k: int, gamma: float) -> np.ndarray:
        Hs = self.H[k].copy()
        Hs[:, self.n_d :] /= gamma
        return Hs

    def upper(self, k: int, gamma: float) -> float:
        from polyrob.analysis.mu.bounds import mussv

        if self.descent is None:
            return float(mussv(self._scaled(k, gamma), self.st, lower=False).upper)
        # from this frequency's last scalings, else the neighbour's (descent also tries its own start); a
        # warm start can settle in a poor stationary point (docs/mu.md): where the bound decides (>= 1), cold too
        Ms = self.st.pad(self._scaled(k, gamma))
        beta, _, _, x = self.descent(Ms, x0=self.x.get(k, self.last))
        if beta >= 1.0 and (k in self.x or self.last is not None):
            cold = self.descent(Ms, x0=None)
            if cold[0] < beta:
                beta, x = cold[0], cold[3]
        self.x[k] = self.last = x
        return float(beta)

    def member(self, k: int, gamma: float) -> None:
        from polyrob.analysis.mu.lower import lower_bound

        if not self.members:
            return
        _, dsq, _ = lower_bound(self.st.pad(self._scaled(k, gamma)), self.st)
        g = _member_gain(self.H[k], self.st.unpad_delta(dsq), self.n_d, self.n_v)
        if g > self.lower:
            self.lower, self.at = g, k


def _grid_level(H, st, n_d: int, n_v: int, members: bool, rtol: float):
    """``(γ, skewed)``: the smallest ``γ`` (within ``rtol``) whose μ upper bound is below 1 at every grid point.

    Each frequency is tried at the largest ``γ`` found so far (most pass at
    once); where it does not, ``γ`` is doubled until it does (``inf`` after
    :data:`MAX_DOUBLINGS`: μ of the uncertainty alone near 1) and bisected.
    The members found on the way are in ``skewed``.
    """
    from polyrob.progress import report, span

    skewed = _Skewed(H, st, n_d, n_v, members)
    nominal = np.array([np.linalg.norm(H[k][n_v:, n_d:], 2) for k in range(len(H))])
    gamma = max(float(nominal.max()), 1e-12)
    if members:  # Δ = 0 is a member
        skewed.lower, skewed.at = float(nominal.max()), int(nominal.argmax())
    first = np.zeros(len(H))
    with span(0.0, FIRST_SHARE):  # one μ bound a frequency: most pass at once
        for k in range(len(H)):
            first[k] = skewed.upper(k, gamma)
            report(k + 1, len(H))
    grid_level = gamma
    for k in np.argsort(-first):
        if first[k] < 1.0 or skewed.upper(k, grid_level) < 1.0:
            continue
        lo, hi, doublings = grid_level, 2.0 * grid_level, 0
        while skewed.upper(k, hi) >= 1.0:
            lo, hi, doublings = hi, 2.0 * hi, doublings + 1
            if doublings > MAX_DOUBLINGS:
                hi = float("inf")
                break
        if not np.isfinite(hi):
            skewed.member(k, lo)
            return hi, skewed
        while hi / lo > 1.0 + rtol:
            mid = np.sqrt(lo * hi)
            lo, hi = (lo, mid) if skewed.upper(k, mid) < 1.0 else (mid, hi)
        skewed.member(k, lo)  # a member near the boundary: μ there is at least about 1
        grid_level = hi
    if members:  # where the first pass was hardest, members between the nominal gain and the level
        for k in np.argsort(-first)[:MEMBER_FREQUENCIES]:
            for g in {gamma, float(np.sqrt(gamma * grid_level))} if np.isfinite(grid_level) else {gamma}:
                skewed.member(int(k), g)
    return grid_level, skewed


def wcgain(
    P,
    K,
    blk=None,
    omega=None,
    *,
    n_u: int | None = None,
    n_y: int | None = None,
    n_w: int | None = None,
    n_z: int | None = None,
    members: bool = True,
    scope=None,
    rtol: float = RTOL,
    tries: int = TRIES,
    **mu_options,
) -> WorstCaseGain:
    """Worst-case weighted gain of ``lft(P, K)`` over the uncertainty set, with an upper bound proved at every frequency.

    Parameters
    ----------
    P : GeneralizedPlant or control.StateSpace
        A bare state space needs ``blk``, ``n_u`` and ``n_y``: its inputs
        are ``[d, w, u]`` and outputs ``[v, z, y]``, the controls and
        measurements last, the performance inputs ``w`` the ``n_w`` before
        the controls.
    K : controller (``n_u x n_y``)
    blk : block structure, optional
        The robust-performance structure, the performance block last
        (default ``P.block_structure_rp``).  It may be a sufficient test's
        structure (the moving robot's merged block): then pass
        ``members=False``.
    omega : array_like, optional
        Frequencies; default the loop's own grid, as every certificate's.
    n_w, n_z : int, optional
        Performance inputs and outputs (default ``P.n_w`` and ``P.n_z``, or
        the last block's inputs and outputs).
    members : bool
        Read each μ lower bound's perturbation as a member of the set (its
        gain is the lower bound).  False for a structure that is only a
        sufficient test: no lower bound is then claimed (``lower`` 0).
    scope : Scope, optional
        What the inputs cover, passed to the certificate.
    rtol : float
        Relative width of the bisection on ``γ`` per frequency.
    tries : int
        Certification attempts, ``γ`` raised by 10 % after each failure.
    **mu_options
        Passed to :func:`~polyrob.analysis.certificate.certify_loop`.

    Returns
    -------
    WorstCaseGain

    Raises
    ------
    ArgumentError
        A bare state space without ``blk``, ``n_u`` and ``n_y``, or a
        performance block that does not match ``n_w``.
    """
    from polyrob.analysis.certificate import certify_loop
    from polyrob.analysis.loop_sweep import FLAT_RTOL, POINTS_PER_DECADE
    from polyrob.analysis.mu.blocks import as_block_structure
    from polyrob.analysis.mu.frequency import default_grid, matrix_response, thin_flat_ends
    from polyrob.plant.loops import lft
    from polyrob.progress import span

    t0 = time.perf_counter()
    if hasattr(P, "system"):  # a GeneralizedPlant
        blk = P.block_structure_rp if blk is None else blk
        n_w, n_z = P.n_w if n_w is None else n_w, P.n_z if n_z is None else n_z
        n_u, n_y, system = P.n_u, P.n_y, P.system
    else:
        if blk is None or n_u is None or n_y is None:
            raise ArgumentError("wcgain: a bare state space needs blk, n_u and n_y")
        system = P
    st = as_block_structure(blk)
    last = st.blocks[-1]
    n_w, n_z = last.rows if n_w is None else int(n_w), last.cols if n_z is None else int(n_z)
    if last.kind == "real" or not (1 <= n_w <= last.rows and 1 <= n_z <= last.cols):
        raise ArgumentError(f"wcgain: the last block must be a full block holding the {n_w} performance inputs")
    n_in, n_out = sum(b.rows for b in st.blocks), sum(b.cols for b in st.blocks)
    n_d, n_v = n_in - n_w, n_out - n_z
    N = lft(system, K, n_u=n_u, n_y=n_y)
    w = np.asarray(omega, float).ravel() if omega is not None else thin_flat_ends(
        N, default_grid(N, per_decade=POINTS_PER_DECADE), FLAT_RTOL)  # fmt: skip
    w = np.union1d(w, [0.0])  # real μ is discontinuous there, and a gain often peaks there
    H = matrix_response(*(np.asarray(X, float) for X in (N.A, N.B, N.C, N.D)))(w)
    with single_blas_thread(), span(0.0, GRID_SHARE):  # small dense problems one after another (as mu_bounds)
        grid_level, skewed = _grid_level(H, st, n_d, n_v, members, rtol)
    lower, at = skewed.lower, float(w[skewed.at]) if skewed.at is not None else float("nan")
    if not np.isfinite(grid_level):
        return WorstCaseGain(lower, float("inf"), at, grid_level, None,
                             "mu of the uncertainty channels alone reaches 1 on the grid: robust stability is not proved",
                             time.perf_counter() - t0)  # fmt: skip
    cert, level, tries = None, grid_level * (1.0 + rtol), max(1, int(tries))
    for t in range(tries):
        plant = performance_scaled(system, level, n_w, n_u)
        with span(GRID_SHARE + (1 - GRID_SHARE) * t / tries, GRID_SHARE + (1 - GRID_SHARE) * (t + 1) / tries):
            cert = certify_loop(plant, K, st, w, n_u=n_u, n_y=n_y, scope=scope, lower_bound_disproves=False,
                                **mu_options)  # fmt: skip
        if cert.certified:
            break
        level *= RAISE
    seconds = time.perf_counter() - t0
    if cert.certified:
        upper = float(cert.bound) * level  # b γ: μ ≤ b < 1 covers every member with ||Δ|| ≤ 1/b
        note = f"the performance inputs divided by {level:.4g}: mu <= {cert.bound:.4g} gives the gain <= {upper:.4g}"
        cert = replace(cert, scope=replace(cert.scope, kind="worst-case gain", notes=(note,) + tuple(cert.scope.notes)))
        return WorstCaseGain(lower, upper, at, grid_level, cert, "", seconds)
    why = "; ".join(cert.reasons) or str(cert.status)
    return WorstCaseGain(lower, float("inf"), at, grid_level, cert, f"not certified at {level:.4g}: {why}", seconds)
