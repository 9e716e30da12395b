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

from polyrob.io.atomic import atomic_write, json_default
from polyrob.validate.c_source import Signals, c_sources
from polyrob.validate.quantize import SOSController

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
    "has_inner_layer",
    "output_limits",
    "nominal_plant",
    "nominal_arm",
    "LowestRate",
]

#: The report's word-length analysis: μ of the discretised loop within 5 % of the continuous loop's,
#: word lengths searched up to 40 bits (polyrob.report.build.validate_controller).
MU_MARGIN = 1.05
LONGEST_WORD = 40


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
            "form": self.sos.form,
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
    form: str = "shift",
) -> ExportResult:
    """``polyrob export``: discretise ``K`` at ``rate`` Hz, biquads per entry, optional quantisation, C + JSON.

    Writes ``out_dir/<name>.h``, ``out_dir/<name>.c`` and ``out_dir/<name>.json``.
    ``inner`` (a controller file's ``info["inner"]``, :meth:`polyrob.model.inner.InnerLoopRobot.words`)
    says in the header what the inner layer computes at run time; ``signals`` says more
    (limits, delay, checks); ``form``: the sections' operator, ``"shift"`` or ``"delta"``
    (:mod:`~polyrob.validate.delta_sections`).  With ``real="float"`` the coefficients are those C's ``float``
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
    sos = sos_realization(dc, form=form)
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
    from polyrob.controller import Controller
    from polyrob.validate.discretize import crossover_frequency

    K = Controller.of(K)  # once: crossover_frequency takes it as it is
    if plant is not None:
        wc = crossover_frequency(plant, K, np.logspace(-3, 6, 1800))
        return LowestRate(
            wc / (2.0 * HOLD_PHASE),
            f"the hold's half-sample delay costs at most 10 degrees of phase at the loop's crossover, "
            f"{wc:.4g} rad/s on the nominal arm",
        )
    if K.order == 0:
        return LowestRate(0.0, "a static gain: any rate")
    fastest = float(np.max(np.abs(np.linalg.eigvals(K.A))))
    return LowestRate(
        2.0 * fastest / np.pi,
        f"the Nyquist frequency at twice the controller's fastest mode, {fastest:.4g} rad/s (no plant known)",
    )


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
        state = (
            f"μ {self.mu:.4g} above {self.threshold:.4g} (the continuous loop's + 5 %)" if self.stable else "unstable"
        )
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
    ok = bool(sd.stable and sd.mu_upper_grid <= threshold)
    if ok or not search:
        return RateCheck(float(rate), ok, bool(sd.stable), float(sd.mu_upper_grid), float(threshold)), threshold
    ceiling = 20.0 * float(rate)
    found = min_sample_rate(
        P, K, mu_continuous=mu_c, omega=grid, method=method, prewarp=prewarp, rel_tol=0.1, rate_bounds=(rate, ceiling)
    )
    return (
        RateCheck(float(rate), False, bool(sd.stable), float(sd.mu_upper_grid), float(threshold), found.rate, ceiling),
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
    form: str = "shift",
) -> WordLengthCheck:
    """The report's word-length analysis on the controller ``polyrob export`` writes.

    ``K`` discretised as the export does (``method``, ``prewarp``), in second-order
    sections (``form``), rounded to ``word_length`` bits, closed around ``P`` (the
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
    sos = sos_realization(discretize(K, rate, method=method, prewarp=prewarp), form=form)
    threshold = MU_MARGIN * continuous_mu(P, K, grid)
    ok, mu, stable, _ = check_word_length(P, sos, W, threshold=threshold, omega=grid)
    smallest = None
    if not ok and W < longest:
        smallest = min_word_length(P, sos, threshold=threshold, lengths=(W + 1, longest), omega=grid).word_length
    return WordLengthCheck(W, float(rate), ok, stable, mu, float(threshold), smallest, int(longest))


def has_inner_layer(info: dict) -> bool:
    """Whether a controller file's ``info`` records an inner layer (its output is then ``v``, rad/s^2)."""
    return bool(info.get("inner")) and not str(info["inner"]).startswith("inner layer: none")


def output_limits(info: dict, m: int):
    """``(lower, upper, where from)`` of the controller's output in its unit, or ``(None, None, why)``."""
    domain = info.get("domain") if isinstance(info.get("domain"), dict) else {}
    if has_inner_layer(info):
        acc = domain.get("qddot")
        if isinstance(acc, dict) and len(acc) == m:
            lo, hi = zip(*(acc[j] for j in acc))
            return tuple(map(float, lo)), tuple(map(float, hi)), "the task's acceleration bounds qddot, rad/s^2"
        return None, None, "no acceleration bound recorded: set them with the _set_limits function"
    if info.get("robot"):
        import polyrob

        try:
            effort = np.asarray(polyrob.load_robot(info["robot"]).effort_limit, float)
        except Exception:  # noqa: BLE001 - a robot that no longer loads: no limit, said in the header
            effort = np.full(m, np.inf)
        if effort.size == m and np.all(np.isfinite(effort)) and np.all(effort > 0):
            return (
                tuple(-effort),
                tuple(effort),
                f"the URDF effort limits of {info['robot']}, N m, on the deviation u; with u_eq known set "
                "lower = -effort - u_eq, upper = effort - u_eq",
            )
    return None, None, "no effort limit known: set them with the _set_limits function"


def nominal_plant(info: dict, K):
    """The arm's nominal plant for the rate check (:func:`~polyrob.validate.export_c.nominal_arm`), or None."""
    m = K.noutputs
    if K.ninputs != m:
        return None
    if has_inner_layer(info):
        return nominal_arm(m)
    domain = info.get("domain") if isinstance(info.get("domain"), dict) else {}
    if not info.get("robot"):
        return None
    pose = domain.get("pose")
    if pose is None and isinstance(domain.get("q"), dict):
        pose = [0.5 * (lo + hi) for lo, hi in domain["q"].values()]
    try:
        import polyrob

        robot = polyrob.load_robot(info["robot"])
        q = np.zeros(robot.m) if pose is None else np.asarray(pose, float)
        return nominal_arm(m, np.linalg.inv(robot.mass_matrix(q))) if robot.m == m else None
    except Exception:  # noqa: BLE001 - a robot that no longer loads: the controller-only rule
        return None
