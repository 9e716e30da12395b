"""C code and JSON of a discrete controller in second-order sections.

:func:`write_c` writes ``controller.h`` and ``controller.c`` (C99, no
dependencies, no dynamic memory): ``controller_reset(&state)`` and
``controller_step(&state, e, u)`` run the difference equations of every
biquad (transposed direct form II) in exactly the order of
:meth:`~polyrob.validate.quantize.SOSController.run`, so the C output equals
Python's to rounding.

Floating point (``real="double"`` or ``"float"``) is the datapath.  A quantised
controller (:func:`~polyrob.validate.quantize.quantize`) is written with its
fixed-point coefficients: each appears as its exact value together with its
integer mantissa and Q format in a comment (``/* 12345 * 2^-14 */``), so a
fixed-point port can take the integers as they are.

:func:`write_json` writes the same sections (and the discrete state-space
form) as JSON.

Examples
--------
>>> import control, tempfile, pathlib
>>> from polyrob.validate.discretize import discretize
>>> from polyrob.validate.quantize import sos_realization
>>> from polyrob.validate.export_c import write_c
>>> sos = sos_realization(discretize(control.tf([1.0], [1.0, 1.0]), 50.0))
>>> h, c = write_c(sos, pathlib.Path(tempfile.mkdtemp()))
>>> h.name, "controller_step" in c.read_text()
('controller.h', True)
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from polyrob.errors import PolyrobError
from polyrob.io.atomic import atomic_write, json_default
from polyrob.validate.quantize import SOSController, _offset_section

__all__ = [
    "write_c",
    "Signals",
    "write_json",
    "c_sources",
    "export_controller",
    "ExportResult",
    "WordLengthCheck",
    "check_export_word_length",
    "lowest_rate_of_controller",
    "check_export_rate",
    "RateCheck",
    "nominal_arm",
    "LowestRate",
]

#: The report's word-length analysis: μ of the discretised loop within 5 % of the continuous loop's,
#: word lengths searched up to 40 bits (polyrob.report.build.validate_controller).
MU_MARGIN = 1.05
LONGEST_WORD = 40


def _num(x: float, real: str) -> str:
    text = repr(float(x))
    if "e" not in text and "." not in text and "inf" not in text and "nan" not in text:
        text += ".0"
    return text + ("f" if real == "float" else "")


@dataclass(frozen=True)
class Signals:
    """What the exported controller's signals mean, and the conditions it was exported for (the header's words).

    Attributes
    ----------
    inner : str or None
        The controller file's ``info["inner"]``: with a computed-torque inner
        layer the output is its acceleration command ``v`` (rad/s^2), else a
        joint torque deviation (N m).
    lower, upper : tuple of float or None
        Output limits in the output's unit (``None``: no limit known).
    limit_source : str
        Where the limits come from.
    delay : str
        The computation delay the controller was checked with.
    checked : str
        What was checked at export (rate, word length), in words.
    realisation : str
        The realisation and arithmetic of the coefficients.
    warnings : tuple of str
        What was written against a check's advice (``--allow-low-rate``, ``--force``): a WARNING line each.
    """

    inner: str | None = None
    lower: tuple | None = None
    upper: tuple | None = None
    limit_source: str = "no limit known: set them with the _set_limits function"
    delay: str = "none modelled: u[k] is computed from e[k] and applied at once (the export's checks assume no delay)"
    checked: str = "nothing checked at export"
    realisation: str = ""
    warnings: tuple = ()

    @property
    def acceleration(self) -> bool:
        return bool(self.inner) and not str(self.inner).startswith("inner layer: none")


def _wrap(text: str, lead: str = " *   ", width: int = 100) -> str:
    words = " ".join(str(text).replace("*/", "* /").replace("±", "+-").split()).split(" ")
    lines, line = [], ""
    for w in words:
        if line and len(lead) + len(line) + len(w) > width:
            lines.append(line.rstrip())
            line = ""
        line += w + " "
    lines.append(line.rstrip())
    return "\n".join(lead + x for x in lines)


def _limit_text(values, real) -> str:
    return ", ".join(_num(v, real) if np.isfinite(v) else ("-HUGE_VAL" if v < 0 else "HUGE_VAL") for v in values)


def c_sources(
    sos: SOSController,
    *,
    name: str = "controller",
    real: str = "double",
    inner: str | None = None,
    signals: Signals | None = None,
) -> tuple[str, str]:
    """The text of ``name.h`` and ``name.c``; ``signals``: what the header says (``inner``: its inner layer only)."""
    if real not in ("double", "float"):
        raise PolyrobError(f"real must be 'double' or 'float', got '{real}'")
    if not name.isidentifier():
        raise PolyrobError(f"'{name}' is not a C identifier")
    sig = signals if signals is not None else Signals(inner=inner)
    P = name.upper()
    entries = list(sos.entries())
    ns = max(1, sos.n_sections)
    guard = f"{P}_H"
    wl = "double precision" if sos.word_length is None else f"{sos.word_length}-bit fixed-point coefficients"
    if sos.word_length is None and sos.info.get("arithmetic") == "float":
        wl = "single-precision (float) coefficients"
    n_out = sos.n_outputs
    lower = sig.lower if sig.lower is not None else (-np.inf,) * n_out
    upper = sig.upper if sig.upper is not None else (np.inf,) * n_out
    if sig.acceleration:
        meaning = (
            "u[i] = v[i], the acceleration command of joint i, rad/s^2: the outer input v of an inner layer, "
            "which computes the joint torques tau = M_hat(q) v + h_hat(q, qdot) (N m) from its model at the measured "
            "q, qdot at every sample, beside this filter"
        )
        unit = "rad/s^2"
    else:
        meaning = (
            "u[i] = the torque deviation of joint i, N m: apply tau = u_eq + u, u_eq the equilibrium torque "
            "(gravity at the operating point), which this filter does not add"
        )
        unit = "N m"
    lines = [
        f"/* {name}.h: discrete controller generated by polyrob ({wl}).",
        " *",
        *(_wrap(f"WARNING: {w}", " * ") for w in sig.warnings),
        *((" *",) if sig.warnings else ()),
        " * Signals (SI units):",
        _wrap("e[j] = r[j] - q[j], the tracking error of joint j (reference minus measured position), rad"),
        _wrap(meaning),
    ]
    if sig.acceleration:
        lines.append(_wrap(str(sig.inner)))
    lines += [
        _wrap(
            f"output limits, {unit}: lower[i] <= u[i] <= upper[i] ({sig.limit_source}); while an output "
            "saturates, the states of its sections hold (anti-windup by conditional integration); "
            f"{name}_set_limits() changes the limits"
        ),
        " *",
        _wrap(f"sample rate: {sos.rate:.9g} Hz (period {sos.dt!r} s): call {name}_step() once per period", " * "),
        _wrap(f"computation delay: {sig.delay}", " * "),
        _wrap(f"coefficients: {wl}, {real} signals; {sig.realisation}".rstrip("; "), " * "),
        _wrap(f"checked at export: {sig.checked}", " * "),
        _wrap(
            f"{name}_reset() zeroes the states; {name}_bumpless(state, e, u) sets them so that the next "
            f"{name}_step() with the same e outputs exactly u (switching in without a jump)",
            " * ",
        ),
    ]
    head = "\n".join(lines)
    header = f"""{head}
 */
#ifndef {guard}
#define {guard}

#define {P}_N_INPUTS {sos.n_inputs}
#define {P}_N_OUTPUTS {sos.n_outputs}
#define {P}_N_SECTIONS {sos.n_sections}
#define {P}_SAMPLE_PERIOD {_num(sos.dt, "double")}
#define {P}_RATE_HZ {_num(sos.rate, "double")}

typedef struct {{
    {real} s[{ns}][2];
    {real} lower[{P}_N_OUTPUTS];
    {real} upper[{P}_N_OUTPUTS];
}} {name}_state_t;

void {name}_reset({name}_state_t *state);
void {name}_set_limits({name}_state_t *state, const {real} lower[{P}_N_OUTPUTS], const {real} upper[{P}_N_OUTPUTS]);
void {name}_bumpless({name}_state_t *state, const {real} e[{P}_N_INPUTS], const {real} u[{P}_N_OUTPUTS]);
void {name}_step({name}_state_t *state, const {real} e[{P}_N_INPUTS], {real} u[{P}_N_OUTPUTS]);

#endif /* {guard} */
"""
    rows, ent, offset = [], [], []
    k = 0
    for i, j, secs in entries:
        ent.append(f"    {{{i}, {j}, {k}, {secs.shape[0]}}}")
        offset.append(k + _offset_section(secs))
        for n, s in enumerate(secs):
            coefs = [s[0], s[1], s[2], s[4], s[5]]
            note = ""
            if sos.formats is not None:
                fb, fa = (int(v) for v in sos.formats[i][j][n])
                mant = [int(round(c * 2.0**f)) for c, f in zip(coefs, (fb, fb, fb, fa, fa))]
                note = f" /* Q: b * 2^-{fb}, a * 2^-{fa}; mantissas {mant} */"
            rows.append("    {" + ", ".join(_num(c, real) for c in coefs) + "}," + note)
            k += 1
    if not rows:
        rows = ["    {0, 0, 0, 0, 0}, /* zero controller */"]
    ent_text = ",\n".join(ent) if ent else "    {0, 0, 0, 0}"
    off_text = ", ".join(str(o) for o in offset) if offset else "0"
    n_ent = len(entries)
    source = f"""/* {name}.c: generated by polyrob; see {name}.h. */
#include <math.h>
#include "{name}.h"

/* per section: b0, b1, b2, a1, a2 (a0 = 1) */
static const {real} coef[{ns}][5] = {{
{chr(10).join(rows)}
}};

/* per entry: output i, input j, first section, number of sections */
static const int entry[{max(1, n_ent)}][4] = {{
{ent_text}
}};

/* per entry: the section whose s[0] a bumpless start sets (its last integrator section, else its last) */
static const int offset_section[{max(1, n_ent)}] = {{{off_text}}};

static const {real} default_lower[{P}_N_OUTPUTS] = {{{_limit_text(lower, real)}}};
static const {real} default_upper[{P}_N_OUTPUTS] = {{{_limit_text(upper, real)}}};

void {name}_reset({name}_state_t *state)
{{
    int k;
    for (k = 0; k < {ns}; ++k) {{
        state->s[k][0] = 0;
        state->s[k][1] = 0;
    }}
    for (k = 0; k < {P}_N_OUTPUTS; ++k) {{
        state->lower[k] = default_lower[k];
        state->upper[k] = default_upper[k];
    }}
}}

void {name}_set_limits({name}_state_t *state, const {real} lower[{P}_N_OUTPUTS], const {real} upper[{P}_N_OUTPUTS])
{{
    int i;
    for (i = 0; i < {P}_N_OUTPUTS; ++i) {{
        state->lower[i] = lower[i];
        state->upper[i] = upper[i];
    }}
}}

void {name}_bumpless({name}_state_t *state, const {real} e[{P}_N_INPUTS], const {real} u[{P}_N_OUTPUTS])
{{
    int i, n, done[{P}_N_OUTPUTS];
    {real} v[{P}_N_OUTPUTS];
    for (n = 0; n < {ns}; ++n) {{
        state->s[n][0] = 0;
        state->s[n][1] = 0;
    }}
    for (i = 0; i < {P}_N_OUTPUTS; ++i) {{
        v[i] = 0;
        done[i] = 0;
    }}
    for (i = 0; i < {n_ent}; ++i) {{
        {real} x = e[entry[i][1]];
        for (n = 0; n < entry[i][3]; ++n) {{
            x = coef[entry[i][2] + n][0] * x;
        }}
        v[entry[i][0]] += x;
    }}
    for (i = 0; i < {n_ent}; ++i) {{
        {real} gain = 1;
        if (done[entry[i][0]]) {{
            continue;
        }}
        done[entry[i][0]] = 1;
        for (n = offset_section[i] + 1; n < entry[i][2] + entry[i][3]; ++n) {{
            gain *= coef[n][0];
        }}
        state->s[offset_section[i]][0] = (u[entry[i][0]] - v[entry[i][0]]) / gain;
    }}
}}

void {name}_step({name}_state_t *state, const {real} e[{P}_N_INPUTS], {real} u[{P}_N_OUTPUTS])
{{
    int i, n, k;
    {real} before[{ns}][2];
    for (n = 0; n < {ns}; ++n) {{
        before[n][0] = state->s[n][0];
        before[n][1] = state->s[n][1];
    }}
    for (i = 0; i < {P}_N_OUTPUTS; ++i) {{
        u[i] = 0;
    }}
    for (i = 0; i < {n_ent}; ++i) {{
        {real} x = e[entry[i][1]];
        for (n = 0; n < entry[i][3]; ++n) {{
            const {real} *c = coef[entry[i][2] + n];
            {real} *s = state->s[entry[i][2] + n];
            {real} y = c[0] * x + s[0];
            s[0] = c[1] * x - c[3] * y + s[1];
            s[1] = c[2] * x - c[4] * y;
            x = y;
        }}
        u[entry[i][0]] += x;
    }}
    for (i = 0; i < {P}_N_OUTPUTS; ++i) {{
        {real} v = u[i];
        u[i] = v < state->lower[i] ? state->lower[i] : (v > state->upper[i] ? state->upper[i] : v);
        if (u[i] != v) {{ /* saturated: the states of this output's sections hold (anti-windup) */
            for (k = 0; k < {n_ent}; ++k) {{
                if (entry[k][0] == i) {{
                    for (n = entry[k][2]; n < entry[k][2] + entry[k][3]; ++n) {{
                        state->s[n][0] = before[n][0];
                        state->s[n][1] = before[n][1];
                    }}
                }}
            }}
        }}
    }}
}}
"""
    return header, source


def write_c(
    sos: SOSController,
    out_dir,
    *,
    name: str = "controller",
    real: str = "double",
    inner: str | None = None,
    signals: Signals | None = None,
) -> tuple[Path, Path]:
    """Write ``out_dir/name.h`` and ``out_dir/name.c`` (atomically); returns both paths."""
    out = Path(out_dir)
    header, source = c_sources(sos, name=name, real=real, inner=inner, signals=signals)
    h, c = out / f"{name}.h", out / f"{name}.c"
    atomic_write(h, lambda f: f.write(header))
    atomic_write(c, lambda f: f.write(source))
    return h, c


def write_json(sos: SOSController, path, *, discrete=None, extra: dict | None = None) -> Path:
    """Write the sections (and optionally the discrete state space and more) as JSON."""
    path = Path(path)
    doc = sos.to_dict()
    if discrete is not None:
        sysd = getattr(discrete, "system", discrete)
        doc["state_space"] = {k: np.asarray(getattr(sysd, k), float).tolist() for k in "ABCD"}
        if hasattr(discrete, "method"):
            doc["method"], doc["prewarp_rad_s"] = discrete.method, discrete.prewarp
    if extra:
        doc.update(extra)
    atomic_write(path, lambda f: f.write(json.dumps(doc, indent=1, default=json_default)))
    return path


@dataclass(frozen=True, eq=False)
class ExportResult:
    """What :func:`export_controller` wrote and the controller it wrote."""

    header: Path
    source: Path
    json: Path
    sos: SOSController
    discrete: object

    def summary(self) -> dict:
        return {
            "header": str(self.header),
            "source": str(self.source),
            "json": str(self.json),
            "rate_hz": self.sos.rate,
            "word_length": self.sos.word_length,
            "sections": self.sos.n_sections,
            "method": self.discrete.method,
            "prewarp_rad_s": self.discrete.prewarp,
        }


def export_controller(
    K,
    rate: float,
    out_dir,
    *,
    word_length: int | None = None,
    method: str = "tustin",
    prewarp: float | None = None,
    real: str = "double",
    name: str = "controller",
    extra: dict | None = None,
    inner: str | None = None,
    signals: Signals | None = None,
) -> ExportResult:
    """``polyrob export``: discretise ``K`` at ``rate`` Hz, biquads per entry, optional quantisation, C + JSON.

    Writes ``out_dir/<name>.h``, ``out_dir/<name>.c`` and ``out_dir/<name>.json``.
    ``inner`` (a controller file's ``info["inner"]``, :meth:`polyrob.model.inner.InnerLoopRobot.words`)
    says in the header what the inner layer computes at run time; ``signals`` says more
    (limits, delay, checks).  With ``real="float"`` the coefficients are those C's ``float``
    holds (:func:`~polyrob.validate.quantize.round_to_float`).

    Examples
    --------
    >>> import tempfile, polyrob
    >>> from polyrob.validate.export_c import export_controller
    >>> res = export_controller(polyrob.paper_controller(), 1000.0, tempfile.mkdtemp(), word_length=24, prewarp=10.0)
    >>> res.header.name, res.sos.word_length, res.sos.n_sections
    ('controller.h', 24, 8)
    """
    from polyrob.validate.discretize import discretize
    from polyrob.validate.quantize import quantize, round_to_float, sos_realization

    dc = discretize(K, rate, method=method, prewarp=prewarp)
    sos = sos_realization(dc)
    if word_length is not None:
        sos = quantize(sos, word_length)
    if real == "float":
        sos = round_to_float(sos)
    h, c = write_c(sos, out_dir, name=name, real=real, inner=inner, signals=signals)
    j = write_json(sos, Path(out_dir) / f"{name}.json", discrete=dc, extra=extra)
    return ExportResult(header=h, source=c, json=j, sos=sos, discrete=dc)


#: The phase the hold's half-sample delay may cost at the loop's crossover: 10 degrees.
HOLD_PHASE = math.radians(10.0)


def nominal_arm(m: int, inverse_mass=None):
    """The arm's nominal plant for the crossover: ``M^-1 / s^2`` (``inverse_mass``, identity by default).

    With a computed-torque inner layer ``q'' = v`` (identity); on the torque, the
    mass matrix at the domain's pose (gravity's stiffness neglected).
    """
    import control

    Minv = np.eye(m) if inverse_mass is None else np.asarray(inverse_mass, float)
    Z, Id = np.zeros((m, m)), np.eye(m)
    return control.ss(np.block([[Z, Id], [Z, Z]]), np.vstack([Z, Minv]), np.hstack([Id, Z]), Z)


@dataclass(frozen=True)
class LowestRate:
    """The lowest sample rate (Hz) for a controller, and on what it rests (``basis``, words)."""

    rate: float
    basis: str


def lowest_rate_of_controller(K, plant=None) -> LowestRate:
    """The lowest rate (Hz) at which the hold costs the loop at most :data:`HOLD_PHASE` at crossover.

    ``plant``: the nominal plant (:func:`nominal_arm`); the loop's gain
    crossover ``ω_c`` (:func:`~polyrob.validate.discretize.crossover_frequency`)
    then needs ``ω_c h / 2 <= 10°``.  Without a plant: the Nyquist frequency at
    twice the controller's fastest mode (cruder: a fast mode far above
    crossover asks for more than the loop needs).
    """
    import control

    from polyrob.plant.generalized import as_controller_ss
    from polyrob.validate.discretize import crossover_frequency

    Ks = K if isinstance(K, control.StateSpace) else as_controller_ss(K, *_shape(K))
    if plant is not None:
        wc = crossover_frequency(plant, Ks, np.logspace(-3, 6, 1800))
        return LowestRate(
            wc / (2.0 * HOLD_PHASE),
            f"the hold's half-sample delay costs at most 10 degrees of phase at the loop's crossover, "
            f"{wc:.4g} rad/s on the nominal arm",
        )
    if Ks.nstates == 0:
        return LowestRate(0.0, "a static gain: any rate")
    fastest = float(np.max(np.abs(np.linalg.eigvals(np.asarray(Ks.A, float)))))
    return LowestRate(
        2.0 * fastest / np.pi,
        f"the Nyquist frequency at twice the controller's fastest mode, {fastest:.4g} rad/s (no plant known)",
    )


def _shape(K):
    return (K.noutputs, K.ninputs) if hasattr(K, "noutputs") else np.atleast_2d(np.asarray(K, float)).shape


@dataclass(frozen=True)
class RateCheck:
    """Whether the discretised loop (exact coefficients) at ``rate`` keeps μ within 5 % of the continuous loop's.

    ``lowest``: when not, the lowest rate that does
    (:func:`~polyrob.validate.discretize.min_sample_rate`; ``None``: none up to ``ceiling`` Hz).
    """

    rate: float
    ok: bool
    stable: bool
    mu: float
    threshold: float
    lowest: float | None = None
    ceiling: float = 0.0

    def line(self) -> str:
        state = f"μ {self.mu:.4g} above {self.threshold:.4g} (the continuous loop's + 5 %)" if self.stable else "unstable"
        head = f"at {self.rate:g} Hz the discretised loop (exact coefficients) is {state}"
        if self.ok or not self.ceiling:
            return head
        if self.lowest is None:
            return f"{head}; no rate up to {self.ceiling:g} Hz keeps it"
        return f"{head}; it keeps μ within 5 % from about {self.lowest:.4g} Hz (a 10 % bisection's lowest passing rate)"


def check_export_rate(
    P, K, rate: float, *, method: str = "tustin", prewarp: float | None = None, omega=None, search: bool = True
):
    """μ of ``K`` discretised as the export does at ``rate``, closed around ``P`` by zero-order hold (the report's check).

    Returns ``(RateCheck, threshold)``; the lowest rate is searched (bisection in log
    rate to 10 %, as the report's) only when ``rate`` fails and ``search``.
    """
    from polyrob.report.build import DISCRETE_GRID
    from polyrob.validate.discretize import continuous_mu, min_sample_rate, sampled_data_mu

    grid = DISCRETE_GRID if omega is None else np.asarray(omega, float)
    mu_c = continuous_mu(P, K, grid)
    threshold = MU_MARGIN * mu_c
    sd = sampled_data_mu(P, K, rate, method=method, prewarp=prewarp, omega=grid, upper_only=True)
    ok = bool(sd.stable and sd.mu_upper <= threshold)
    if ok or not search:
        return RateCheck(float(rate), ok, bool(sd.stable), float(sd.mu_upper), float(threshold)), threshold
    ceiling = 20.0 * float(rate)
    found = min_sample_rate(
        P, K, mu_continuous=mu_c, omega=grid, method=method, prewarp=prewarp, rel_tol=0.1, rate_bounds=(rate, ceiling)
    )
    return (
        RateCheck(float(rate), False, bool(sd.stable), float(sd.mu_upper), float(threshold), found.rate, ceiling),
        threshold,
    )


@dataclass(frozen=True, eq=False)
class WordLengthCheck:
    """Whether ``word_length``-bit coefficients keep the discretised loop as the report's analysis asks.

    ``ok``: the loop (plant by zero-order hold, the quantised controller) is
    stable with μ <= ``threshold`` (:data:`MU_MARGIN` times the continuous
    loop's μ on the same grid).  When not, ``smallest`` is the shortest word
    length up to ``longest`` bits that does (``None``: none does).
    """

    word_length: int
    rate: float
    ok: bool
    stable: bool
    mu: float
    threshold: float
    smallest: int | None = None
    longest: int = LONGEST_WORD

    def reason(self) -> str:
        if not self.stable:
            return "unstable"
        return f"μ {self.mu:.4g} above {self.threshold:.4g} (the continuous loop's + 5 %)"

    def line(self) -> str:
        """One line: the refusal's (or the warning's) words."""
        head = (
            f"{self.word_length}-bit coefficients do not keep the discretised loop at {self.rate:g} Hz "
            f"stable with μ within 5 % of the continuous loop's ({self.reason()})"
        )
        if self.smallest is not None:
            return f"{head}; the smallest word length that does is {self.smallest} bits (--word-length {self.smallest})"
        return f"{head}; no word length up to {max(self.longest, self.word_length)} bits does"

    def summary(self) -> dict:
        return {
            "word_length": self.word_length,
            "ok": self.ok,
            "stable": self.stable,
            "mu": self.mu,
            "threshold": self.threshold,
            "smallest_word_length": self.smallest,
            "longest_checked": max(self.longest, self.word_length),
        }


def check_export_word_length(
    P,
    K,
    rate: float,
    word_length: int,
    *,
    method: str = "tustin",
    prewarp: float | None = None,
    omega=None,
    longest: int = LONGEST_WORD,
) -> WordLengthCheck:
    """The report's word-length analysis on the controller ``polyrob export`` writes.

    ``K`` discretised as the export does (``method``, ``prewarp``), in second-order
    sections, rounded to ``word_length`` bits, closed around ``P`` (the
    generalized plant) sampled by zero-order hold: stable with μ within 5 % of
    the continuous loop's on ``omega`` (default the report's grid,
    :data:`polyrob.report.build.DISCRETE_GRID`)?  When not, the shortest
    word length from ``word_length + 1`` to ``longest`` that is
    (:func:`~polyrob.validate.quantize.min_word_length`, bisection).
    """
    from polyrob.report.build import DISCRETE_GRID
    from polyrob.validate.discretize import continuous_mu, discretize
    from polyrob.validate.quantize import check_word_length, min_word_length, sos_realization

    W = int(word_length)
    grid = DISCRETE_GRID if omega is None else np.asarray(omega, float)
    sos = sos_realization(discretize(K, rate, method=method, prewarp=prewarp))
    threshold = MU_MARGIN * continuous_mu(P, K, grid)
    ok, mu, stable, _ = check_word_length(P, sos, W, threshold=threshold, omega=grid)
    smallest = None
    if not ok and W < longest:
        smallest = min_word_length(P, sos, threshold=threshold, lengths=(W + 1, longest), omega=grid).word_length
    return WordLengthCheck(W, float(rate), ok, stable, mu, float(threshold), smallest, int(longest))
