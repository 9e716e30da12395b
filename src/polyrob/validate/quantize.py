"""Second-order sections and fixed-point coefficients of the discrete controller.

:func:`sos_realization` writes each SISO entry ``K_ij(z)`` of a discrete
controller as a cascade of second-order sections (biquads, transposed
direct form II), the numerically sensible realisation for short words: a
section's poles move little when its two coefficients are rounded, whereas
the roots of a high-order polynomial move a lot.  ``u_i = Σ_j K_ij(z) e_j``.
``form="delta"`` writes the sections in ``δ = (z - 1)/T`` instead
(:mod:`~polyrob.validate.delta_sections`): poles near ``z = 1`` then keep
their accuracy in float and in short words.

:func:`quantize` rounds every coefficient to a signed fixed-point number of
``word_length`` bits; the numerator coefficients of a section share one Q
format and its denominator coefficients another (integer bits just enough
for the largest magnitude, the rest fractional).  Only the *coefficients* are
quantised: the arithmetic stays floating point (signal quantisation and
overflow of a fixed-point datapath are not modelled; docs/method.md).

:func:`min_word_length` finds the shortest word length whose quantised
controller keeps the discretised loop stable and its μ below a threshold
(:func:`check_word_length` checks one word length).

Examples
--------
>>> import control, numpy as np
>>> from polyrob.validate.discretize import discretize
>>> from polyrob.validate.quantize import sos_realization, quantize
>>> Kd = discretize(control.tf([1.0, 3.0], [1.0, 2.0, 5.0]), 100.0)
>>> sos = sos_realization(Kd)
>>> sos.sections[0][0].shape
(1, 6)
>>> q = quantize(sos, 12)
>>> q.word_length, bool(np.allclose(q.sections[0][0], sos.sections[0][0], atol=2e-3))
(12, True)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import control
import numpy as np
import scipy.signal as ss

from polyrob.errors import ArgumentError, PolyrobError
from polyrob.validate import delta_sections as delta

__all__ = [
    "SOSController",
    "WordLengthResult",
    "sos_realization",
    "quantize",
    "check_word_length",
    "min_word_length",
    "q_format",
    "offset_section",
    "round_to_float",
    "AccuracyCheck",
    "check_accuracy",
    "smallest_accurate_word_length",
    "POLE_TOLERANCE",
    "DC_TOLERANCE",
    "FORMS",
]

#: How far a rounded pole may move, relative to its distance from z = 1 (1 %: its time constant within 1 %).
POLE_TOLERANCE = 0.01
#: How far an entry's DC gain (its integral gain when it integrates) may move after rounding (0.1 %).
DC_TOLERANCE = 1e-3
#: A pole (or zero) this close to z = 1 is an integrator (a differentiator): it must stay exactly there.
AT_ONE = 1e-12
#: Section forms: ``"shift"`` (rows in z^-1) and ``"delta"`` (rows in δ = (z - 1)/T, :mod:`~polyrob.validate.delta_sections`).
FORMS = ("shift", "delta")


@dataclass(frozen=True, eq=False)
class SOSController:
    """A MIMO discrete controller as cascades of biquads per entry.

    Attributes
    ----------
    sections : tuple of tuple of ndarray
        ``sections[i][j]`` has shape ``(n_sec, 6)``: rows
        ``[b0, b1, b2, 1, a1, a2]`` (scipy's ``sos`` layout) of ``K_ij``;
        zero rows (``n_sec = 0``) for a zero entry.
    dt : float
        Sample period, s.
    word_length : int or None
        Bits of the quantised coefficients (None: double precision).
    formats : tuple of tuple of ndarray or None
        ``formats[i][j]`` ``(n_sec, 2)``: fractional bits of the numerator
        and of the denominator coefficients of each section.
    form : str
        ``"shift"``: rows are polynomials in ``z^-1``; ``"delta"``: rows
        ``[β0, β1, β2, 1, α1, α2]`` in ``δ = (z - 1)/dt``
        (:mod:`~polyrob.validate.delta_sections`).
    """

    sections: tuple
    dt: float
    word_length: int | None = None
    formats: tuple | None = None
    info: dict = field(default_factory=dict)
    form: str = "shift"

    def __post_init__(self):
        if self.form not in FORMS:
            raise ArgumentError(f"the section form must be one of {FORMS}, got '{self.form}'")

    @property
    def n_outputs(self) -> int:
        return len(self.sections)

    @property
    def n_inputs(self) -> int:
        return len(self.sections[0])

    @property
    def rate(self) -> float:
        return 1.0 / self.dt

    @property
    def n_sections(self) -> int:
        return sum(s.shape[0] for row in self.sections for s in row)

    def entries(self):
        """``(i, j, sections)`` of the non-zero entries, in the order the C code runs them."""
        for i, row in enumerate(self.sections):
            for j, s in enumerate(row):
                if s.shape[0]:
                    yield i, j, s

    def run(self, e, *, lower=None, upper=None, initial=None) -> np.ndarray:
        """Response to the input sequence ``e`` (``n_in x N``): ``u`` (``n_out x N``).

        Transposed direct form II (in ``δ`` for the delta form: ``s += T w``)
        with exactly the operation order of the generated C code (so both agree to rounding, bit for bit on IEEE doubles).
        ``lower``/``upper`` (per output): the C code's output saturation with
        its anti-windup (conditional integration: while output ``i``
        saturates, the states of its sections keep their values);
        ``initial``: the states to start from (``n_sections x 2``, C order, e.g.
        :meth:`bumpless_state`), zero by default.
        """
        e = np.atleast_2d(np.asarray(e, float))
        N = e.shape[1]
        u = np.zeros((self.n_outputs, N))
        lo = np.full(self.n_outputs, -np.inf) if lower is None else np.asarray(lower, float)
        hi = np.full(self.n_outputs, np.inf) if upper is None else np.asarray(upper, float)
        states = np.zeros((max(1, self.n_sections), 2)) if initial is None else np.array(initial, float)
        first = self._first_sections()
        T, in_delta = self.dt, self.form == "delta"
        for k in range(N):
            before = states.copy()
            for (i, j, secs), f in zip(self.entries(), first):
                x = float(e[j, k])
                for n, (b0, b1, b2, _, a1, a2) in enumerate(secs):
                    st = states[f + n]
                    y = b0 * x + st[0]
                    if in_delta:
                        st[0] = st[0] + T * (b1 * x - a1 * y + st[1])
                        st[1] = st[1] + T * (b2 * x - a2 * y)
                    else:
                        st[0] = b1 * x - a1 * y + st[1]
                        st[1] = b2 * x - a2 * y
                    x = y
                u[i, k] += x
            for i in range(self.n_outputs):
                v = u[i, k]
                u[i, k] = lo[i] if v < lo[i] else (hi[i] if v > hi[i] else v)
                if u[i, k] != v:  # saturated: this output's states hold (anti-windup)
                    for (ii, _, secs), f in zip(self.entries(), first):
                        if ii == i:
                            states[f : f + secs.shape[0]] = before[f : f + secs.shape[0]]
        return u

    def _first_sections(self) -> list:
        """Index of each entry's first section in the C state array."""
        first, k = [], 0
        for _, _, secs in self.entries():
            first.append(k)
            k += secs.shape[0]
        return first

    def bumpless_state(self, e, u) -> np.ndarray:
        """States (C order) from which one step with input ``e`` outputs exactly ``u`` (the C ``_bumpless``).

        All states zero but one per output: ``s[0]`` of a section of the
        output's first entry (its last integrator section, else its last
        section) takes the difference, scaled by the ``b0`` of the sections after it.
        """
        e, u = np.asarray(e, float), np.asarray(u, float)
        states = np.zeros((max(1, self.n_sections), 2))
        v = np.zeros(self.n_outputs)
        for i, j, secs in self.entries():
            x = float(e[j])
            for row in secs:
                x = row[0] * x
            v[i] += x
        done = set()
        for (i, _, secs), f in zip(self.entries(), self._first_sections()):
            if i in done:
                continue
            done.add(i)
            n = offset_section(secs, self.form)
            gain = float(np.prod(secs[n + 1 :, 0])) if n + 1 < secs.shape[0] else 1.0
            states[f + n, 0] = (u[i] - v[i]) / gain
        return states

    def to_ss(self) -> control.StateSpace:
        """The discrete state-space system of the cascades (block by block, no rounding but the sections')."""
        p, q = self.n_outputs, self.n_inputs
        As, Bs, Cs = [], [], []
        D = np.zeros((p, q))
        for i, j, secs in self.entries():
            A, B, C, d = delta.delta_cascade_ss(secs, self.dt) if self.form == "delta" else _cascade_ss(secs)
            D[i, j] += d
            if A.shape[0]:
                b = np.zeros((A.shape[0], q))
                b[:, j] = B
                c = np.zeros((p, A.shape[0]))
                c[i] = C
                As.append(A)
                Bs.append(b)
                Cs.append(c)
        if not As:
            return control.ss(np.zeros((0, 0)), np.zeros((0, q)), np.zeros((p, 0)), D, dt=self.dt)
        from scipy.linalg import block_diag

        return control.ss(block_diag(*As), np.vstack(Bs), np.hstack(Cs), D, dt=self.dt)

    def to_dict(self) -> dict:
        return {
            "format": "polyrob.sos_controller/1",
            "dt": self.dt,
            "rate_hz": self.rate,
            "word_length": self.word_length,
            "form": self.form,
            "layout": (
                "sections[i][j] = [[b0, b1, b2, 1, a1, a2], ...]; u_i = sum_j K_ij(z) e_j; transposed direct form II"
                if self.form == "shift"
                else "sections[i][j] = [[beta0, beta1, beta2, 1, alpha1, alpha2], ...] = (beta0 d^2 + beta1 d + "
                "beta2)/(d^2 + alpha1 d + alpha2) in d = (z - 1)/dt; u_i = sum_j K_ij e_j; transposed direct form II "
                "in d: y = beta0 x + s1; s1 += dt (beta1 x - alpha1 y + s2); s2 += dt (beta2 x - alpha2 y)"
            ),
            "sections": [[s.tolist() for s in row] for row in self.sections],
            "frac_bits": None if self.formats is None else [[f.tolist() for f in row] for row in self.formats],
            "info": self.info,
        }

    @classmethod
    def from_dict(cls, data: dict) -> SOSController:
        sections = tuple(tuple(np.asarray(s, float).reshape(-1, 6) for s in row) for row in data["sections"])
        fb = data.get("frac_bits")
        formats = None if fb is None else tuple(tuple(np.asarray(f, int).reshape(-1, 2) for f in row) for row in fb)
        info, form = dict(data.get("info", {})), data.get("form", "shift")  # a file without it is shift
        return cls(sections, float(data["dt"]), data.get("word_length"), formats, info, form)


def offset_section(secs, form: str = "shift") -> int:
    """The section whose ``s[0]`` a bumpless start sets: the last integrator section whose later ``b0`` are not zero."""
    n = secs.shape[0] - 1
    for k in range(secs.shape[0] - 1, -1, -1):
        b0, _, _, _, a1, a2 = secs[k]
        integrator = delta.integrates(secs[k]) if form == "delta" else 1.0 + a1 + a2 == 0.0
        if integrator and np.all(secs[k + 1 :, 0] != 0.0):
            return k
    return n


def _cascade_ss(secs):
    """State space ``(A, B, C, D)`` of a biquad cascade (TDF-II states of each section)."""
    n = 2 * secs.shape[0]
    A = np.zeros((n, n))
    B = np.zeros(n)
    C = np.zeros(n)
    # signal into section k = C_prev x + D_prev e
    cin, din = np.zeros(n), 1.0
    for k, (b0, b1, b2, _, a1, a2) in enumerate(secs):
        s = slice(2 * k, 2 * k + 2)
        # y = b0 x + s1; s1' = b1 x - a1 y + s2; s2' = b2 x - a2 y
        cy = b0 * cin
        cy[2 * k] += 1.0
        dy = b0 * din
        A[2 * k] += b1 * cin - a1 * cy
        A[2 * k, 2 * k + 1] += 1.0
        A[2 * k + 1] += b2 * cin - a2 * cy
        B[s] = [b1 * din - a1 * dy, b2 * din - a2 * dy]
        cin, din = cy, dy
    C[:], D = cin, din
    return A, B, C, D


def _structural_entry(sys, i, j) -> control.StateSpace:
    """Entry ``(i, j)`` keeping only the states that ``e_j`` reaches and that reach ``u_i``.

    Exact zeros of the realisation decide (a controller realised entry by
    entry, as polyrob does, keeps them through Tustin and ZOH), so no
    numerical rank decision can keep another entry's modes.
    """
    A, B, C = (np.asarray(X, float) for X in (sys.A, sys.B, sys.C))
    G = np.abs(A) > 0
    reach, obs = B[:, j] != 0, C[i] != 0
    for _ in range(A.shape[0]):
        new_r, new_o = reach | (G @ reach), obs | (G.T @ obs)
        if np.array_equal(new_r, reach) and np.array_equal(new_o, obs):
            break
        reach, obs = new_r, new_o
    k = np.flatnonzero(reach & obs)
    return control.ss(
        A[np.ix_(k, k)], B[k, j : j + 1], C[i : i + 1, k], np.asarray(sys.D)[i : i + 1, j : j + 1], dt=sys.dt
    )


def sos_realization(controller, *, tol: float = 1e-9, form: str = "shift") -> SOSController:
    """Each entry of a discrete controller as biquads (minimal per entry, scipy's pole/zero pairing).

    Parameters
    ----------
    controller : DiscreteController or discrete control.StateSpace
    tol : float
        Tolerance of the per-entry minimal realisation (``control.minreal``).
    form : {"shift", "delta"}
        The sections' operator: ``z^-1`` (shift) or ``δ = (z - 1)/T``
        (:mod:`~polyrob.validate.delta_sections`, accurate in short words
        for poles near ``z = 1``).
    """
    if form not in FORMS:
        raise ArgumentError(f"the section form must be one of {FORMS}, got '{form}'")
    sys = getattr(controller, "system", controller)
    sys = control.ss(sys)
    if sys.dt in (0, None):
        raise ArgumentError("sos_realization needs a discrete-time controller (see discretize)")
    rows = []
    for i in range(sys.noutputs):
        row = []
        for j in range(sys.ninputs):
            g = _structural_entry(sys, i, j)
            if g.nstates:
                g = control.minreal(g, tol=tol, verbose=False)
            if not g.nstates:
                d = float(np.asarray(g.D)[0, 0])
                row.append(np.array([[d, 0.0, 0.0, 1.0, 0.0, 0.0]]) if d else np.zeros((0, 6)))
                continue
            row.append(delta.delta_entry_sections(g, float(sys.dt), AT_ONE) if form == "delta" else _entry_sos(g))
        rows.append(tuple(row))
    return SOSController(tuple(rows), float(sys.dt), info={"source_order": int(sys.nstates)}, form=form)


_clean_pairs = delta.clean_pairs


def _entry_sos(g) -> np.ndarray:
    """Biquads of one SISO entry from its poles (eigenvalues), zeros (SLICOT) and gain.

    Poles and zeros come from the state space directly: expanding a
    polynomial first (``ss2tf``) loses all accuracy for clustered poles near
    ``z = 1``, as slow controller modes at a fast sample rate have.
    """
    p = _clean_pairs(np.linalg.eigvals(np.asarray(g.A)))
    z = _clean_pairs(np.atleast_1d(g.zeros()))
    z = z[np.isfinite(z)]
    z0 = 0.37 + 0.21j  # a point off the unit circle, away from poles and zeros in practice
    H = complex(np.asarray(g(z0)).ravel()[0])
    k = H * np.prod(z0 - p) / np.prod(z0 - z) if z.size else H * np.prod(z0 - p)
    if abs(k.imag) > 1e-6 * max(abs(k), 1e-300):
        raise PolyrobError(f"internal error: complex gain {k} of a real controller entry")
    at_one = np.abs(p - 1.0) <= AT_ONE
    if not at_one.any() or p.size < 2:
        return np.atleast_2d(ss.zpk2sos(z, p, k.real))
    # an integrator gets a first-order section of its own: [1, -1, 0] is exact in every arithmetic,
    # whereas paired with another pole p its a1 = -(1 + p), a2 = p round apart and move it off z = 1
    n_int = int(at_one.sum())
    rest = np.atleast_2d(ss.zpk2sos(z, p[~at_one], k.real)) if (~at_one).any() else np.array([[k.real, 0, 0, 1, 0, 0]])
    integrators = np.tile([1.0, 0.0, 0.0, 1.0, -1.0, 0.0], (n_int, 1))
    return np.vstack([rest, integrators])


def q_format(values, word_length: int) -> int:
    """Fractional bits of a signed ``word_length``-bit format that holds ``max |values|``."""
    peak = float(np.max(np.abs(values))) if np.size(values) else 0.0
    int_bits = 1 if peak == 0.0 else max(1, math.floor(math.log2(peak)) + 2)  # sign bit included
    return int(word_length - int_bits)


def _round(values, frac, word_length):
    scale = 2.0**frac
    mant = np.round(np.asarray(values, float) * scale)
    lim = 2.0 ** (word_length - 1)
    mant = np.clip(mant, -lim, lim - 1)
    return mant / scale


def quantize(sos: SOSController, word_length: int) -> SOSController:
    """Coefficients rounded to ``word_length``-bit fixed point (per section: one Q format for b, one for a)."""
    W = int(word_length)
    if not 2 <= W <= 53:
        raise ArgumentError(f"the word length must lie in [2, 53] bits, got {word_length}")
    rows, fmts = [], []
    for row in sos.sections:
        out_row, fmt_row = [], []
        for secs in row:
            q = secs.copy()
            f = np.zeros((secs.shape[0], 2), dtype=int)
            for k, s in enumerate(secs):
                fb, fa = q_format(s[:3], W), q_format(s[4:], W)
                q[k, :3] = _round(s[:3], fb, W)
                q[k, 4:] = _round(s[4:], fa, W)
                f[k] = fb, fa
            out_row.append(q)
            fmt_row.append(f)
        rows.append(tuple(out_row))
        fmts.append(tuple(fmt_row))
    return SOSController(tuple(rows), sos.dt, W, tuple(fmts), dict(sos.info), sos.form)


def round_to_float(sos: SOSController) -> SOSController:
    """The coefficients as C ``float`` holds them (IEEE single precision, 24-bit significand)."""
    rows = tuple(tuple(np.asarray(s, np.float32).astype(float) for s in row) for row in sos.sections)
    return SOSController(rows, sos.dt, sos.word_length, sos.formats, {**sos.info, "arithmetic": "float"}, sos.form)


def _section_roots(row, part: str) -> np.ndarray:
    c = row[:3] if part == "zeros" else row[3:]
    c = np.trim_zeros(np.asarray(c, float), "b")
    return np.roots(c) if c.size > 1 else np.zeros(0)


def _entry_gain(secs):
    """``(poles, integrators, differentiators, gain)`` of one entry's sections.

    ``gain``: ``(1 - z^-1)^(d - i) K(z)`` at ``z = 1`` (the DC gain, or the
    integral gain of an entry that integrates), from the coefficient sums:
    rooting a numerator with a double zero near ``z = 1`` (a PID's) is too
    ill-conditioned to show what rounding does to it.
    """
    poles, n_int, n_dif, gain = [], 0, 0, 1.0
    for row in secs:
        b0, b1, b2, _, a1, a2 = (float(c) for c in row)
        poles.extend(_section_roots(row, "poles"))
        num, den = b0 + b1 + b2, 1.0 + a1 + a2
        if abs(den) <= AT_ONE * (1.0 + abs(a1) + abs(a2)):
            n_int, den = n_int + 1, 1.0 - a2  # (1 - w)(1 - a2 w): what is left at w = 1
        if abs(num) <= AT_ONE * (abs(b0) + abs(b1) + abs(b2)) and num != 0.0 or (num == 0.0 and b0 != 0.0):
            n_dif, num = n_dif + 1, b0 - b2  # (1 - w)(b0 - b2 w)
        gain = gain * num / den if den != 0.0 else np.inf
    return np.array(poles, complex), n_int, n_dif, gain


@dataclass(frozen=True, eq=False)
class AccuracyCheck:
    """Whether rounded coefficients keep the exact discrete controller's poles and DC gains.

    ``ok``: every pole moved by at most :data:`POLE_TOLERANCE` of its distance
    to ``z = 1``, none reached or crossed the unit circle, every integrator
    stayed exactly at ``z = 1`` and every entry's DC gain (its integral gain
    when it integrates) moved by at most :data:`DC_TOLERANCE`.  ``problem``
    says what broke first (empty when ``ok``).
    """

    arithmetic: str
    ok: bool
    pole_move: float
    dc_error: float
    problem: str = ""

    def summary(self) -> dict:
        return {
            "arithmetic": self.arithmetic,
            "ok": self.ok,
            "worst_pole_move": self.pole_move,
            "worst_dc_gain_error": self.dc_error,
            "problem": self.problem,
        }


def check_accuracy(exact: SOSController, rounded: SOSController, *, arithmetic: str | None = None) -> AccuracyCheck:
    """Poles and DC gain of ``rounded`` against ``exact`` (same sections, e.g. :func:`quantize` of it)."""
    if arithmetic is None:
        arithmetic = "double" if rounded.word_length is None else f"{rounded.word_length}-bit fixed point"
        if rounded.info.get("arithmetic") == "float":
            arithmetic = "float" if rounded.word_length is None else f"{arithmetic} in float"
    worst_move, worst_dc, problem = 0.0, 0.0, ""
    for (i, j, a), (_, _, b) in zip(exact.entries(), rounded.entries()):
        pa, ia, da, ga = delta.delta_entry_gain(a, exact.dt) if exact.form == "delta" else _entry_gain(a)
        pb, ib, db, gb = delta.delta_entry_gain(b, rounded.dt) if rounded.form == "delta" else _entry_gain(b)
        where = f"K[{i}][{j}]"
        for p in pa:
            q = pb[np.argmin(np.abs(pb - p))] if pb.size else np.inf
            if abs(p - 1.0) <= AT_ONE:  # an integrator: exactly at z = 1 or lost
                if abs(q - 1.0) > 0.0 and ib < ia and not problem:
                    problem = f"{where}'s integrator pole moves from z = 1 to z = {complex(q).real:.15g}"
                continue
            move = float(abs(q - p) / abs(1.0 - p))
            worst_move = max(worst_move, move)
            if abs(q) >= 1.0 > abs(p) and not problem:
                problem = (
                    f"{where}'s pole z = {complex(p).real:.15g} moves onto or out of the unit circle "
                    f"(|z| = {abs(q):.15g})"
                )
            elif move > POLE_TOLERANCE and not problem:
                problem = (
                    f"{where}'s pole z = {complex(p).real:.15g} moves by {100 * move:.3g} % of its distance to z = 1"
                )
        if ia == ib and da == db and ga != 0.0:
            err = float(abs(gb - ga) / abs(ga))
            worst_dc = max(worst_dc, err)
            if err > DC_TOLERANCE and not problem:
                kind = "integral gain" if ia > da else "DC gain"
                problem = f"{where}'s {kind} moves by {100 * err:.3g} %"
        elif ib > ia and not problem:
            problem = f"{where} gains a pole at z = 1 that its exact form does not have"
        elif db != da and not problem:
            kind = "integral gain" if ia > da else "DC gain"
            problem = f"{where}'s {kind} is lost (a numerator zero moves {'onto' if db > da else 'off'} z = 1)"
    return AccuracyCheck(arithmetic, not problem, worst_move, worst_dc, problem)


def smallest_accurate_word_length(sos: SOSController, *, longest: int = 53, float_: bool = False) -> int | None:
    """Shortest fixed-point word length (4 .. ``longest``) whose coefficients pass :func:`check_accuracy`."""
    for W in range(4, int(longest) + 1):
        q = quantize(sos, W)
        if float_:
            q = round_to_float(q)
        if check_accuracy(sos, q).ok:
            return W
    return None


@dataclass(frozen=True, eq=False)
class WordLengthResult:
    """Shortest word length found (``None`` if ``lengths[-1]`` fails) and every length tried."""

    word_length: int | None
    mu: float | None
    threshold: float
    history: tuple
    controller: SOSController | None

    def summary(self) -> dict:
        return {
            "min_word_length": self.word_length,
            "mu": self.mu,
            "threshold": self.threshold,
            "history": [list(h) for h in self.history],
        }


def check_word_length(P, sos: SOSController, word_length: int, *, threshold: float, omega=None, **mu_options):
    """One word length: ``(ok, μ upper, stable, quantised controller)`` of the discretised loop.

    The loop is ``P`` by zero-order hold closed by the controller quantised to
    ``word_length`` bits; ``ok`` when it is stable with μ <= ``threshold``
    on ``omega`` (the check of :func:`min_word_length`, and of ``polyrob export``).
    """
    from polyrob.validate.discretize import sampled_data_mu

    q = quantize(sos, word_length)
    res = sampled_data_mu(P, None, sos.rate, controller=q.to_ss(), omega=omega, **{"upper_only": True, **mu_options})
    ok = bool(res.stable and res.mu_upper_grid <= threshold)
    return ok, float(res.mu_upper_grid), bool(res.stable), q


def min_word_length(
    P, sos: SOSController, *, threshold: float, lengths=(4, 40), omega=None, **mu_options
) -> WordLengthResult:
    """Shortest coefficient word length keeping the discretised loop stable with μ <= ``threshold``.

    Bisection over ``lengths = (shortest, longest)`` bits, assuming longer
    words never do worse (checked at ``longest`` first).
    """
    history = []

    def check(W):
        ok, mu, stable, q = check_word_length(P, sos, W, threshold=threshold, omega=omega, **mu_options)
        history.append((int(W), mu, stable, ok))
        return ok, mu, q

    lo, hi = int(lengths[0]), int(lengths[1])
    ok, mu_hi, q_hi = check(hi)
    if not ok:
        return WordLengthResult(None, None, threshold, tuple(history), None)
    best = (hi, mu_hi, q_hi)
    ok, mu_lo, q_lo = check(lo)
    if ok:
        return WordLengthResult(lo, float(mu_lo), threshold, tuple(history), q_lo)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        ok, mu, q = check(mid)
        if ok:
            hi, best = mid, (mid, mu, q)
        else:
            lo = mid
    return WordLengthResult(best[0], float(best[1]), threshold, tuple(history), best[2])
