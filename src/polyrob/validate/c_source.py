"""The C text of a discrete controller in second-order sections (:func:`c_sources`), and what its header says.

``controller_step`` runs the biquads (transposed direct form II; in the delta
form, :mod:`~polyrob.validate.delta_sections`, with the state update
``s += T w``) in exactly the order of :meth:`~polyrob.validate.quantize.SOSController.run`, saturates each
output at its limits and holds the states of a saturated output's sections
(anti-windup by conditional integration); ``controller_bumpless`` sets the
states so that the next step outputs a given value (switching in without a
jump).  :class:`Signals` carries the header's words: what each signal means
and its unit, the rate, the delay, the coefficients and what was checked.
:func:`polyrob.validate.export_c.write_c` writes the files.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from polyrob.errors import ArgumentError
from polyrob.validate.quantize import SOSController, offset_section

__all__ = ["Signals", "c_sources"]


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
        raise ArgumentError(f"real must be 'double' or 'float', got '{real}'")
    if not name.isidentifier():
        raise ArgumentError(f"'{name}' is not a C identifier")
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
    if sos.form == "delta":
        lines += [
            " *",
            _wrap(
                "realisation: delta-operator sections (Middleton & Goodwin), d = (z - 1)/T with T = "
                f"{P}_SAMPLE_PERIOD: each row of coef[] is beta0, beta1, beta2, alpha1, alpha2 of "
                "(beta0 d^2 + beta1 d + beta2)/(d^2 + alpha1 d + alpha2) (a first-order section has beta2 = alpha2 = 0), "
                "run as y = beta0 x + s0; s0 += T (beta1 x - alpha1 y + s1); s1 += T (beta2 x - alpha2 y). "
                "A pole at z = 1 (an integrator) is alpha = 0 exactly; a slow pole near z = 1 is an ordinary-sized "
                "alpha instead of the tiny sum 1 + a1 + a2 of the shift form, so short words keep it",
                " * ",
            ),
        ]
    else:
        lines += [
            " *",
            _wrap(
                "realisation: shift-operator sections: each row of coef[] is b0, b1, b2, a1, a2 of "
                "(b0 + b1 z^-1 + b2 z^-2)/(1 + a1 z^-1 + a2 z^-2), run as y = b0 x + s0; s0 = b1 x - a1 y + s1; "
                "s1 = b2 x - a2 y",
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
        offset.append(k + offset_section(secs, sos.form))
        for n, s in enumerate(secs):
            coefs = [s[0], s[1], s[2], s[4], s[5]]
            note = ""
            if sos.formats is not None:
                fb, fa = (int(v) for v in sos.formats[i][j][n])
                mant = [int(round(c * 2.0**f)) for c, f in zip(coefs, (fb, fb, fb, fa, fa))]
                b, a = ("beta", "alpha") if sos.form == "delta" else ("b", "a")
                note = f" /* Q: {b} * 2^-{fb}, {a} * 2^-{fa}; mantissas {mant} */"
            rows.append("    {" + ", ".join(_num(c, real) for c in coefs) + "}," + note)
            k += 1
    if not rows:
        rows = ["    {0, 0, 0, 0, 0}, /* zero controller */"]
    ent_text = ",\n".join(ent) if ent else "    {0, 0, 0, 0}"
    off_text = ", ".join(str(o) for o in offset) if offset else "0"
    n_ent = len(entries)
    if sos.form == "delta":
        coef_words = "per section: beta0, beta1, beta2, alpha1, alpha2 in d = (z - 1)/T (see the header)"
        update = """            s[0] = s[0] + delta_T * (c[1] * x - c[3] * y + s[1]);
            s[1] = s[1] + delta_T * (c[2] * x - c[4] * y);"""
        period = (
            f"\n/* the delta operator's sample period T, s */\nstatic const {real} delta_T = {_num(sos.dt, real)};\n"
        )
    else:
        coef_words = "per section: b0, b1, b2, a1, a2 (a0 = 1) of the shift form (see the header)"
        update = """            s[0] = c[1] * x - c[3] * y + s[1];
            s[1] = c[2] * x - c[4] * y;"""
        period = ""
    source = f"""/* {name}.c: generated by polyrob; see {name}.h. */
#include <math.h>
#include "{name}.h"

/* {coef_words} */
static const {real} coef[{ns}][5] = {{
{chr(10).join(rows)}
}};

/* per entry: output i, input j, first section, number of sections */
static const int entry[{max(1, n_ent)}][4] = {{
{ent_text}
}};

/* per entry: the section whose s[0] a bumpless start sets (its last integrator section, else its last) */
static const int offset_section[{max(1, n_ent)}] = {{{off_text}}};
{period}
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
{update}
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
