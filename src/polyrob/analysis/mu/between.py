"""The μ upper bound between the grid points: a check over every frequency.

A μ sweep bounds μ at the frequencies of its grid only; a resonance between
two points can be missed.  The D-G scalings found at a grid point
``ω_i`` certify the level ``β`` there because

.. math::

    Φ_i(ω) = \\begin{bmatrix} M(jω) \\\\ I \\end{bmatrix}^*
    \\begin{bmatrix} P_i & -jG_i \\\\ jG_i & -β^2 P_i \\end{bmatrix}
    \\begin{bmatrix} M(jω) \\\\ I \\end{bmatrix} \\prec 0

at ``ω = ω_i`` (``P_i = D_i²``).  The same constant scalings certify ``β`` at
every ω where :math:`Φ_i(ω) \\prec 0`, and :math:`Φ_i(ω)` can only stop being
negative definite where it is singular: where ``jω`` is an eigenvalue of the
Hamiltonian-like matrix of the para-Hermitian :math:`Φ_i(s)`
(:func:`crossing_frequencies`).  So an interval between two grid points is
covered when one endpoint's scalings have no such crossing inside it, and
otherwise it is split at its (logarithmic) middle, where μ is bounded anew.
This is the frequency-interval idea of MATLAB's ``robstab``/``robgain``
(Hamiltonian tests rather than a grid; Young, Newlin & Doyle) written out,
because neither SLICOT nor python-control offers it.

:func:`verify_between` returns whether ``β`` bounds μ at **every**
frequency ``ω ≥ 0``, up to the eigenvalue solver's accuracy: near-imaginary
eigenvalues are all candidate crossings, a candidate is dropped only where
``Φ`` is clearly negative definite, and ``Φ`` is also evaluated inside every
interval the test passes; a failure there means the test missed a crossing
in that interval, so the interval and its parts are left to the
perturbation radii (:mod:`~polyrob.analysis.mu.radius`, norm bounds), and
the result counts them (on the interval up to infinity, which no radius
reaches, the check stops).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np
from scipy.linalg import matrix_balance

from polyrob.analysis.mu.blocks import as_block_structure
from polyrob.analysis.mu.frequency import matrix_response
from polyrob.analysis.mu.radius import covering_radius
from polyrob.errors import ArgumentError
from polyrob.progress import report

__all__ = [
    "BetweenGridResult",
    "verify_between",
    "with_between",
    "crossing_frequencies",
    "crossings_around",
    "normalised_loop",
]

#: Level above the grid's peak upper bound that is checked by default (relative).
LEVEL_MARGIN = 1e-2
#: Candidates for crossings: eigenvalues ``λ`` of the Hamiltonian ``H`` with
#: ``|Re λ| <= CANDIDATE_TOL (|λ| + ‖H‖_F)`` (generous: eigenvalues of a badly
#: scaled ``H`` are accurate to about ``eps ‖H‖`` only).  ``Φ`` is then
#: evaluated at each candidate ``ω = |Im λ|``: one where it is clearly negative
#: definite (largest eigenvalue below ``-CROSSING_TOL β² ‖P‖``) is not a crossing.
#: The margin is wide because ``Im λ`` carries the same rounding error: a true
#: crossing evaluated slightly off must not look negative.
CANDIDATE_TOL = 1e-8
CROSSING_TOL = 1e-3
#: Interior points of each covered interval where ``Φ`` is also evaluated: a
#: failure there means the Hamiltonian test is not reliable on this realisation.
SPOT_CHECKS = 3
#: Past this frequency (rad/s) the last interval must be covered by the scalings of ∞ or of its start.
TOP_FREQUENCY = 1e12
#: Powers ``t`` of an end's scalings also tried when its own fail an interval: ``D^t`` and ``t G~`` are
#: admissible scalings too (block diagonal as ``D``), valid wherever ``Φ`` is negative at the end.  Scalings
#: that spread the blocks over four decades (ur5's per-link PID at 1e-3 rad/s) make ``Φ(∞)`` singular, so
#: the Hamiltonian test cannot run, where their square roots certify the level with room to spare.
TEMPERED = (0.5, 0.25)
#: Frequencies bounded anew before the check gives up (a count, never seconds: the verdict must not depend
#: on the machine's load).  Well above what certified loops need (panda's PID start: see tests/test_mu_between.py).
MAX_POINTS = 200


@dataclass(frozen=True)
class BetweenGridResult:
    """Whether a level bounds μ at every frequency, from the grid's own scalings.

    Attributes
    ----------
    level : float
        The level ``β`` checked.
    holds : bool
        ``μ(M(jω)) ≤ β`` for every ``ω ≥ 0`` (and at ``ω = ∞``).
    peak_upper : float
        Largest upper bound met: the grid's and the added points'.
    intervals : int
        Intervals covered.
    points_added : int
        Frequencies where μ was bounded anew (interval middles).
    failed_at : float or None
        A frequency whose own upper bound exceeds a given ``level`` (then ``holds`` is False).
    reason : str
        Why it does not hold (empty when it does).
    seconds : float
    by_radius : int
        Of the intervals covered, those covered by the ends' perturbation
        radii (:mod:`~polyrob.analysis.mu.radius`); the others by Hamiltonian tests.
    refuted : int
        Intervals whose Hamiltonian test passed while ``Φ`` failed at one of
        their inner points: not trusted, they and their parts are left to
        the perturbation radii.
    """

    level: float
    holds: bool
    peak_upper: float
    intervals: int
    points_added: int
    failed_at: float | None
    reason: str
    seconds: float
    by_radius: int = 0
    refuted: int = 0

    def sentence(self) -> str:
        """One clause for a verdict."""
        if self.holds:
            tests = [name for name, n in (("Hamiltonian tests", self.intervals - self.by_radius),
                                          ("perturbation bounds", self.by_radius)) if n]  # fmt: skip
            return (
                f"mu <= {self.level:.4g} at every frequency (the grid's D-G scalings verified between its points by "
                f"{' and '.join(tests) or 'Hamiltonian tests'}, "
                f"{self.points_added} point{'' if self.points_added == 1 else 's'} added{self._refuted_words()})"
            )
        return f"not verified between the grid points: {self.reason}{self._refuted_words()}"

    def _refuted_words(self) -> str:
        if not self.refuted:
            return ""
        n = self.refuted
        return f"; {n} interval{'' if n == 1 else 's'} whose Hamiltonian test an inner point refuted left to the radii"

    def summary(self) -> dict:
        return dict(self.__dict__)


def _padded_state_space(sys, st):
    """``(A, B, C, D)`` of the padded square ``M(s)``."""
    import control

    ss = control.ss(sys)
    A, B, C, D = (np.asarray(X, float) for X in (ss.A, ss.B, ss.C, ss.D))
    if A.size:  # a diagonal similarity (LAPACK's balancing) evens out the state scaling
        A, T = matrix_balance(A, permute=False)
        B, C = B / np.diag(T)[:, None], C * np.diag(T)[None, :]
    n = st.padded_size
    ec, er = st.embeddings()
    Er = np.zeros((n, B.shape[1]))
    Er[er, np.arange(B.shape[1])] = 1.0
    Ec = np.zeros((n, C.shape[0]))
    Ec[ec, np.arange(C.shape[0])] = 1.0
    return A, B @ Er.T, Ec @ C, Ec @ D @ Er.T


def _hamiltonian_eigenvalues(A, B, C, D, P, G, level):
    """``(λ, ‖H‖_F)``: the eigenvalues of the Hamiltonian of ``Φ(s)``; ``None`` when ``Φ(∞)`` is singular.

    Complex ``A, B, C, D`` are allowed (:func:`crossings_around`); every
    transpose is the conjugate one.
    """
    n, k = A.shape[0], B.shape[1]
    Pi = np.block([[P, -1j * G], [1j * G, -(level**2) * P]])
    Cw = np.vstack([C, np.zeros((k, n))])
    Dw = np.vstack([D, np.eye(k)])
    R = Dw.conj().T @ Pi @ Dw
    R = (R + R.conj().T) / 2
    ev = np.linalg.eigvalsh(R)
    if np.min(np.abs(ev)) <= 1e-12 * max(np.max(np.abs(ev)), 1e-300):
        return None
    Q = Cw.conj().T @ Pi @ Cw
    S = Cw.conj().T @ Pi @ Dw
    Rinv = np.linalg.inv(R)
    Bh = B.conj().T
    H = np.block(
        [[A - B @ Rinv @ S.conj().T, -B @ Rinv @ Bh], [-Q + S @ Rinv @ S.conj().T, -A.conj().T + S @ Rinv @ Bh]]
    )
    return np.linalg.eigvals(H), np.linalg.norm(H)


def _near_imaginary(lam, norm) -> np.ndarray:
    """The eigenvalues that are candidate crossings (:data:`CANDIDATE_TOL`)."""
    return lam[np.abs(lam.real) <= CANDIDATE_TOL * (np.abs(lam) + norm)]


def crossing_frequencies(A, B, C, D, P, G, level) -> np.ndarray | None:
    """Frequencies ``ω ≥ 0`` where ``Φ(ω)`` (module docstring) is singular.

    ``None`` when the test does not apply (``Φ(∞)`` singular).  ``A`` must have
    no eigenvalue on the imaginary axis.
    """
    eig = _hamiltonian_eigenvalues(A, B, C, D, P, G, level)
    if eig is None:
        return None
    scale = CROSSING_TOL * level**2 * max(1.0, np.linalg.norm(P, 2))
    candidates = np.unique(np.abs(_near_imaginary(*eig).imag))
    found = [w for w in candidates if _largest_eigenvalue(A, B, C, D, P, G, level, w) > -scale]
    return np.array(found, float)


def crossings_around(A, B, C, D, P, G, level, centre: float) -> np.ndarray | None:
    """:func:`crossing_frequencies` with the frequency axis turned so that ``ω = ∞`` lands on ``centre``.

    The Hamiltonian test needs ``Φ(∞)`` nonsingular, which fails for scalings
    that spread over many decades on a loop with a large feedthrough (so101's
    cells at low frequency: ``Φ(∞)`` of order 1e14 against ``Φ(ω_i)`` of
    order 1), although the scalings certify the level over a wide interval
    around their own frequency.  ``s = jω_c + ω_k / z`` maps the imaginary
    axis of ``z`` onto that of ``s`` and ``z = ∞`` onto ``s = jω_c``, so the
    loop ``M(jω_c + ω_k/z)`` -- a complex realisation: ``A_c = A - jω_c I``,
    ``(ω_k A_c^-1, ω_k A_c^-1 B, -C A_c^-1, M(jω_c))`` -- has ``Φ(jω_c)`` as
    its value at infinity, negative definite at the end's own frequency
    ``ω_c`` (the caller's condition), and its Hamiltonian's imaginary
    eigenvalues ``jν`` are the crossings ``ω = ω_c - ω_k / ν`` of the loop
    itself (``|ω|``: ``Φ(-ω)`` of a real loop has the eigenvalues of
    ``Φ(ω)``; ``ν = 0`` is ``ω = ∞``).  Each candidate is evaluated on the
    loop itself, as in :func:`crossing_frequencies`.  ``None`` when the
    test does not apply here either (``Φ(jω_c)`` singular, or ``A_c`` is).
    """
    n = A.shape[0]
    if not n:
        return np.zeros(0)
    k = float(centre) if centre > 0 else 1.0
    Ac = A - 1j * float(centre) * np.eye(n)
    try:
        Ai = np.linalg.inv(Ac)
    except np.linalg.LinAlgError:
        return None
    if not np.all(np.isfinite(Ai)):
        return None
    eig = _hamiltonian_eigenvalues(k * Ai, k * (Ai @ B), -(C @ Ai), D - C @ (Ai @ B), P, G, level)
    if eig is None:
        return None
    nu = _near_imaginary(*eig).imag
    tiny = np.abs(nu) <= 1e-300
    omega = np.where(tiny, np.inf, np.abs(float(centre) - k / np.where(tiny, 1.0, nu)))
    scale = CROSSING_TOL * level**2 * max(1.0, np.linalg.norm(P, 2))
    found = [w for w in np.unique(omega) if _largest_eigenvalue(A, B, C, D, P, G, level, w) > -scale]
    return np.array(found, float)


def normalised_loop(A, B, C, D, scaling, power: float = 1.0):
    """``(A, B D^-1, D C, D D_f D^-1, I, G~)``: the loop scaled so that ``P = I``, ``G~ = D^-1 G D^-1``.

    Terms of one size (``P`` can span 16 decades); ``Φ ≺ 0`` iff its
    normalised form is.  ``scaling`` is ``(D, G)`` (``D = P^1/2``);
    ``power`` ``t < 1``: the admissible scalings ``D^t`` and ``t G~``
    instead (:data:`TEMPERED`; a power of a block-diagonal ``D`` keeps its
    blocks, and ``t G~`` the real blocks' ``G~``).
    """
    Dh, G = scaling
    Di = np.linalg.inv(Dh)
    Gt = Di @ G @ Di
    Gt = (Gt + Gt.conj().T) / 2
    if power != 1.0:
        values, vectors = np.linalg.eigh((Dh + Dh.conj().T) / 2)
        Dh = (vectors * values**power) @ vectors.conj().T
        Di, Gt = np.linalg.inv(Dh), power * Gt
    return A, B @ Di, Dh @ C, Dh @ D @ Di, np.eye(len(Dh)), Gt


def _at(A, B, C, D, w) -> np.ndarray:
    """``M(jω)`` by one direct solve (the frequency module's raw-matrix evaluation); ``w = inf``: ``D``."""
    return D if np.isinf(w) else matrix_response(A, B, C, D, modal=False)([w])[0]


def _largest_eigenvalue(A, B, C, D, P, G, level, w) -> float:
    """Largest eigenvalue of ``Φ(ω)`` (``w = inf``: the feedthrough)."""
    if not B.shape[1]:
        return -np.inf
    M = _at(A, B, C, D, w)
    L = M.conj().T @ P @ M + 1j * (G @ M - M.conj().T @ G) - level**2 * P
    return float(np.linalg.eigvalsh((L + L.conj().T) / 2)[-1])


def _negative_at(A, B, C, D, P, G, level, w) -> bool:
    """``Φ(ω) ≺ 0`` at one frequency (``w = inf``: the feedthrough)."""
    return _largest_eigenvalue(A, B, C, D, P, G, level, w) < 0


def verify_between(
    sys,
    mu,
    *,
    level: float | None = None,
    method: str | None = None,
    max_points: int = MAX_POINTS,
    time_limit: float | None = None,
) -> BetweenGridResult:
    """Check that a level bounds μ of ``sys`` between the points of a sweep.

    Parameters
    ----------
    sys : control.StateSpace or TransferFunction
        The ``M`` of the sweep (stable).
    mu : MuBoundsResult
        The sweep (:func:`polyrob.analysis.mu.bounds.mu_bounds`): its grid and scalings.
    level : float, optional
        The level to verify; the first point found above it ends the check
        (``holds=False``).  Default: the sweep's peak upper bound times
        ``1 + LEVEL_MARGIN``, raised to ``1 + LEVEL_MARGIN`` times any larger
        bound found between the grid points (the result's ``level`` is then a
        bound of μ over every frequency).  A peak below 1 that the margin
        would lift to 1 or above is checked at the middle between it and 1
        instead: the level that decides whether μ < 1 at every frequency.
    method : str, optional
        Upper-bound method of the added points (default: the sweep's).
    max_points : int
        Most frequencies bounded anew before giving up (then ``holds=False``
        and the reason says so: the grid's own bounds stand, nothing is
        claimed between).  The check's only default bound: a count of work,
        so the answer is the same on an idle and on a loaded machine.
    time_limit : float, optional
        A safety net the caller sets: wall-clock seconds before giving up;
        the reason then names it ("stopped by the time limit of N s you
        set").  ``None`` (default): no wall-clock limit.

    Examples
    --------
    >>> import control
    >>> from polyrob.analysis.mu.bounds import mu_bounds
    >>> from polyrob.analysis.mu.between import verify_between
    >>> G = control.tf([1], [1, 0.02, 1])         # a sharp resonance at 1 rad/s, peak 50
    >>> coarse = mu_bounds(G, [[1, 1]], [0.1, 0.5, 2.0, 10.0], refine_peak=False, progress=False)
    >>> round(coarse.peak_upper, 3)               # the grid misses it
    1.333
    >>> verify_between(G, coarse, level=1.4).holds
    False
    >>> everywhere = verify_between(G, coarse)     # the level rises to what lies between the points
    >>> everywhere.holds, everywhere.level > 50.0
    (True, True)
    """
    from polyrob.analysis.mu.bounds import mussv
    from polyrob.analysis.mu.sweep import relaxed_is_cheap

    if time_limit is not None and not time_limit > 0:
        raise ArgumentError(f"time_limit must be > 0 seconds or None, got {time_limit}")
    t0 = time.perf_counter()
    st = as_block_structure(mu.structure)
    A, B, C, D = _padded_state_space(sys, st)
    if A.size and np.max(np.linalg.eigvals(A).real) >= 0:
        return BetweenGridResult(np.nan, False, float(mu.peak_upper), 0, 0, None, "M is not stable", 0.0)
    adaptive = level is None
    beta = float(mu.peak_upper) * (1.0 + LEVEL_MARGIN) if adaptive else float(level)
    if adaptive and float(mu.peak_upper) < 1.0 <= beta:
        # the margin would lift a peak just below 1 over it: the level that decides the verdict lies between
        beta = 0.5 * (float(mu.peak_upper) + 1.0)
    how = method or (mu.method if mu.method in ("ab13md", "lmi", "gradient") else "auto")
    second = how == "gradient" and relaxed_is_cheap(st)
    w = np.asarray(mu.omega, float)
    scalings = [(mu.D[i], mu.G[i]) for i in range(len(w))]
    peak, added = float(np.max(mu.upper)), 0
    by_radius = 0  # intervals the perturbation radii covered
    refuted = set()  # intervals whose Hamiltonian test the inner points refuted: their parts by radii alone

    def result(holds, failed_at=None, reason="", intervals=0):
        return BetweenGridResult(
            beta,
            holds,
            peak,
            intervals,
            added,
            failed_at,
            reason,
            round(time.perf_counter() - t0, 3),
            by_radius,
            len(refuted),
        )

    memo = {}  # per end (each serves two intervals): its normalised loop, crossings and radius at the level

    def normalised(scaling, at, power=1.0):
        key = ("loop", at, power)
        if key not in memo:
            memo[key] = normalised_loop(A, B, C, D, scaling, power)
        return memo[key]

    def crossings_of(scaling, at, power=1.0):
        key = (at, beta, power)
        if key not in memo:
            # Φ ≺ 0 iff D^-1 Φ D^-1 ≺ 0: the test runs on the normalised loop
            scaled = normalised(scaling, at, power) + (beta,)
            cross = None
            if _negative_at(*scaled, at):
                cross = crossing_frequencies(*scaled)
                if cross is None and np.isfinite(at):  # Φ(∞) singular: the axis turned to put ∞ at the end
                    cross = crossings_around(*scaled, at)
            memo[key] = (scaled, cross)
        return memo[key]

    def radius(scaling, at) -> float:
        key = ("radius", at, beta)
        if key not in memo:
            An, Bn, Cn, Dn, _, Gt = normalised(scaling, at)
            memo[key] = covering_radius(An, Bn, Cn, Dn, Gt, beta, at)
        return memo[key]

    def near_enough(ends, lo, hi) -> bool:
        """The ends' perturbation radii (:mod:`~polyrob.analysis.mu.radius`) reach across ``[lo, hi]``."""
        if not np.isfinite(hi):
            return False
        reach = sum(radius(pg, at) for at, pg in ends if np.isfinite(at))
        return bool(reach >= hi - lo)

    def covers(scaling, at, lo, hi) -> bool:
        """The scalings found at ``at`` (or a power of them, :data:`TEMPERED`) keep ``Φ`` negative definite on ``[lo, hi]``."""
        refuted = None
        try:
            if covers_with(scaling, at, lo, hi, 1.0):
                return True
        except _Unreliable as own:  # the powers may still cover it; if none does, the check stops as before
            refuted = own
        for power in TEMPERED:
            try:
                if covers_with(scaling, at, lo, hi, power):
                    return True
            except _Unreliable:  # a power's test that the inner points refute only fails to cover
                continue
        if refuted is not None:
            raise refuted
        return False

    def covers_with(scaling, at, lo, hi, power) -> bool:
        scaled, cross = crossings_of(scaling, at, power)
        if cross is None or np.any((cross >= lo * (1 - 1e-12)) & (cross <= hi * (1 + 1e-12))):
            return False
        top = hi if np.isfinite(hi) else 1e3 * max(lo, 1.0)
        inside = np.geomspace(max(lo, 1e-3 * top), top, SPOT_CHECKS + 2)[1:-1]
        if not all(_negative_at(*scaled, x) for x in inside):
            raise _Unreliable(lo, hi)
        return True

    def bound_at(x):
        M = _at(A, B, C, D, x)
        ec, er = st.embeddings()
        r = mussv(M[np.ix_(ec, er)], st, method=how, lower=False)
        if second:
            # descent can stall where the sweep's own second bound answered (sweep.py): the relaxed
            # structure's AB13MD scalings are admissible too, and the smaller bound is kept
            r2 = mussv(M[np.ix_(ec, er)], st, method="relaxed", lower=False)
            r = r2 if r2.upper < r.upper else r
        return float(r.upper), (r.D, r.G)

    # intervals [w_i, w_{i+1}], [0, w_0] if the grid starts above 0, and [w_last, inf);
    # each with the scalings of its ends (frequency, (P, G)) that are known
    stack = []
    if w[0] > 0:
        stack.append((0.0, w[0], [(w[0], scalings[0])]))
    for i in range(len(w) - 1):
        stack.append((w[i], w[i + 1], [(w[i], scalings[i]), (w[i + 1], scalings[i + 1])]))
    # μ at ω = ∞ (the feedthrough) is bounded too, and its scalings tried on the last interval
    upper_inf, at_inf = bound_at(np.inf)
    added += 1
    peak = max(peak, upper_inf)
    if not upper_inf < beta:
        if not adaptive:
            return result(False, np.inf, f"mu upper bound {upper_inf:.4g} >= {beta:.4g} at infinite frequency")
        beta = upper_inf * (1.0 + LEVEL_MARGIN)
    stack.append((w[-1], np.inf, [(w[-1], scalings[-1]), (np.inf, at_inf)]))
    done = 0
    while stack:
        lo, hi, ends = stack.pop()
        near = near_enough(ends, lo, hi)
        by_radius += near
        covered = near
        if not near and not any(a <= lo and hi <= b for a, b in refuted):
            try:
                covered = any(covers(pg, at, lo, hi) for at, pg in ends)
            except _Unreliable:
                if not np.isfinite(hi):  # no radius reaches infinity: nothing else can cover it
                    why = (
                        f"the Hamiltonian test is not reliable on this loop's realisation (it passed [{lo:.4g}, "
                        f"{hi:.4g}] rad/s, where the scalings fail at an inner point)"
                    )
                    return result(False, None, why, done)
                refuted.add((lo, hi))
        if covered:
            done += 1
            report(done, done + len(stack))  # intervals split as they go: a share of the ones known so far
            continue
        if added >= max_points:
            spent = f"{_points(added)} added (the check's limit of {_points(max_points)})"
            return result(False, None, f"{spent} and an interval near {lo:.4g} rad/s still open", done)
        if time_limit is not None and time.perf_counter() - t0 > time_limit:
            spent = f"stopped by the time limit of {time_limit:g} s you set, after {_points(added)} added"
            return result(False, None, f"{spent}, with an interval near {lo:.4g} rad/s still open", done)
        if not np.isfinite(hi):
            if lo > TOP_FREQUENCY:
                return result(False, None, f"the interval above {lo:.4g} rad/s is not covered", done)
            mid = 10.0 * max(lo, 1e-6)
        else:
            mid = float(np.sqrt(lo * hi)) if lo > 0 else hi / 10.0
        upper, pg = bound_at(mid)
        added += 1
        peak = max(peak, upper)
        if not upper < beta:
            if not adaptive:
                return result(False, float(mid), f"mu upper bound {upper:.4g} >= {beta:.4g} at {mid:.4g} rad/s", done)
            # a higher level keeps every interval covered so far covered (Φ only decreases)
            beta = upper * (1.0 + LEVEL_MARGIN)
        stack.append((lo, mid, [e for e in ends if e[0] == lo] + [(mid, pg)]))
        stack.append((mid, hi, [(mid, pg)] + [e for e in ends if e[0] == hi]))
    return result(True, intervals=done)


def _points(n: int) -> str:
    return f"{n} point{'' if n == 1 else 's'}"


class _Unreliable(Exception):
    """The Hamiltonian test passed an interval inside which ``Φ`` is not negative definite."""


def with_between(sys, mu, *, response_bits: int | None = None):
    """The sweep ``mu`` with its check between the grid points (``mu.between``), or why none was made.

    It is made for a sweep whose peak is below 1 (a certificate to extend to
    every frequency; above 1 the verdict is "not certified" whatever lies
    between the points).  The test needs a state space evaluated in double
    precision: a frequency-response model, or a loop whose response needed
    extended precision (``response_bits``), is left unverified, and
    ``between.reason`` says so.
    """
    import control

    why = None
    if not float(mu.peak_upper) < 1.0:
        why = f"the grid's peak {float(mu.peak_upper):.4g} is not below 1: there is no certificate to extend"
    elif isinstance(sys, control.FrequencyResponseData):
        why = "a frequency-response model has no state space"
    elif response_bits:
        why = "the loop's realisation needs extended precision; the Hamiltonian test runs in double"
    between = (
        verify_between(sys, mu)
        if why is None
        else BetweenGridResult(float("nan"), False, float(mu.peak_upper), 0, 0, None, why, 0.0)
    )
    return dataclasses.replace(mu, between=between)
