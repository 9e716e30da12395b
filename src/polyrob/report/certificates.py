"""The certificates a run report shows: one record per certificate, one row per record.

A record is what :meth:`~polyrob.analysis.certificate.Certificate.summary`
gives (``status``, ``bound``, ``scope``, ``verdict``, ...) with ``covers``,
the scope's sentence, and ``sweep``, the μ sweep it was decided on (its grid,
ω = 0 included when swept: the report's μ figure shows it); a run directory
stores these records, so that the report rebuilt from the files shows the
same rows and the same μ figure.  The status is the one
:mod:`polyrob.analysis.certificate` decided; nothing here decides or words
it otherwise.

Examples
--------
>>> from polyrob.analysis.certificate import Certificate, Scope, Status
>>> c = Certificate(Status.GRID_ONLY, 0.9, 0.9, 0.8, None, Scope(frequencies="the grid"), ("not checked",))
>>> certificate_rows({FROZEN_ROW: c})
[('frozen robot (μ)', 'GRID_ONLY', 0.9, 'for constant parameters (every frozen robot of the set), on the grid')]
>>> frozen_status({FROZEN_ROW: certificate_record(c)})
'GRID_ONLY'
>>> headline({FROZEN_ROW: c})
'Frozen robot, robust performance: GRID_ONLY, mu < 1 on the frequency grid only (peak 0.9), not proved between its points'
>>> plain_words(c)
'Not proved: every frozen robot of the set meets the performance weights at the frequencies of the grid (peak mu 0.9), but nothing is shown between them'
"""

from __future__ import annotations

import math
from dataclasses import fields

import numpy as np

from polyrob.analysis.certificate import ARBITRARY, FROZEN, Scope, Status

__all__ = [
    "headline",
    "headline_name",
    "plain_words",
    "FROZEN_ROW",
    "TIME_VARYING_ROW",
    "MOVING_ROW",
    "certificate_record",
    "certificate_rows",
    "lower_bound_words",
    "certificate_sweep",
    "frozen_status",
    "is_decided",
    "is_frozen",
]

#: Row names of a run's certificates: the frozen robot's μ, arbitrarily fast variation, the moving robot.
FROZEN_ROW = "frozen robot (μ)"
TIME_VARYING_ROW = "arbitrarily fast variation"
MOVING_ROW = "moving robot"


def _scope_sentence(scope: dict) -> str:
    names = {f.name for f in fields(Scope)}
    return Scope(**{k: v for k, v in scope.items() if k in names}).sentence()


def certificate_record(cert) -> dict:
    """A certificate as a run stores and the report shows it: ``summary()`` with ``covers``, the scope's sentence.

    ``cert`` is a :class:`~polyrob.analysis.certificate.Certificate`, a
    ``TimeVaryingCertificate`` (its robust-performance certificate; its own
    verdict line, and its figures under ``"time_varying"``), a
    ``MovingRobotCertificate`` (likewise, under ``"moving"``), or a record.
    """
    if isinstance(cert, dict):
        rec = dict(cert)
        if isinstance(rec.get("scope"), dict):
            rec["covers"] = _scope_sentence(rec["scope"])
        return rec
    inner = cert if hasattr(cert, "status") else cert.certificate
    rec = inner.summary()
    rec["covers"] = inner.scope.sentence()
    sweep = _sweep(getattr(inner, "mu", None))
    if sweep is not None:
        rec["sweep"] = sweep
    if inner is not cert:
        rec["verdict"] = cert.verdict
        rec[getattr(cert, "record_key", "time_varying")] = cert.summary()
    return rec


def _sweep(mu) -> dict | None:
    """The μ sweep a certificate was decided on, as lists (its grid, ω = 0 included when swept), or ``None``."""
    try:
        w, up, lo = (np.asarray(getattr(mu, k), float).ravel() for k in ("omega", "upper", "lower"))
    except (AttributeError, TypeError, ValueError):  # no sweep (e.g. a gain certificate)
        return None
    if not w.size or not (w.shape == up.shape == lo.shape):
        return None
    return {"omega": w.tolist(), "upper": up.tolist(), "lower": lo.tolist()}


def certificate_sweep(record):
    """``(omega, upper, lower)`` arrays of a record's (or certificate's) μ sweep, or ``None``.

    A stored figure that was not finite is ``null`` in the file, NaN here.
    """
    record = _as_record(record)
    sweep = record.get("sweep") if isinstance(record, dict) else None
    if not isinstance(sweep, dict):
        return None
    try:
        w, up, lo = (np.array(sweep[k], dtype=float).ravel() for k in ("omega", "upper", "lower"))
    except (KeyError, TypeError, ValueError):
        return None
    return (w, up, lo) if w.size and w.shape == up.shape == lo.shape else None


def _as_record(record):
    return record if isinstance(record, dict) or record is None else certificate_record(record)


def is_decided(record) -> bool:
    """A record (or certificate) whose status :mod:`polyrob.analysis.certificate` decided."""
    record = _as_record(record)
    return isinstance(record, dict) and record.get("status") in {s.value for s in Status}


def is_frozen(record) -> bool:
    """A certificate for constant parameters (each frozen robot of the set)."""
    record = _as_record(record)
    scope = record.get("scope") if isinstance(record, dict) else None
    return isinstance(scope, dict) and scope.get("variation") == FROZEN


def frozen_status(records: dict) -> str | None:
    """The report's verdict: the status of the frozen robot's robust-performance certificate (``None``: none given)."""
    name = headline_name(records)
    return None if name is None else certificate_record(records[name])["status"]


def _bound(x) -> float | None:
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def certificate_rows(records: dict) -> list[tuple]:
    """``(name, status, bound, what it covers)`` per certificate; ``bound`` is ``None`` when no finite one exists."""
    rows = []
    for name, cert in records.items():
        rec = certificate_record(cert)
        rows.append((str(name), str(rec["status"]), _bound(rec.get("bound")), str(rec.get("covers") or "not stated")))
    return rows


def lower_bound_words(record) -> str:
    """The lower bound beside a certificate's bound, in words: what no certificate of this kind can go below.

    The frozen robot's: μ's lower bound (μ itself is at least this, so no
    upper bound can go below it).  The moving robot's: the largest gain found along admissible
    trajectories when the record carries one (``moving.lower_bound``).  Else
    ``"not computed"``.

    >>> lower_bound_words({"mu_lower": 0.93, "scope": {"variation": FROZEN}})
    'mu >= 0.93 (mu itself is at least this: no bound of this kind goes below)'
    >>> lower_bound_words({"moving": {"lower_bound": 0.726}, "scope": {}})
    'gain >= 0.726 (the largest found along admissible trajectories)'
    >>> lower_bound_words({"moving": {"lower_bound": 1.271}, "scope": {}})
    'gain >= 1.271 (the largest found along admissible trajectories: at or above 1, robust performance fails for the linearised robot in motion, simulated)'
    >>> lower_bound_words({"scope": {"variation": ARBITRARY}})
    'not computed'
    """
    record = _as_record(record)
    scope = record.get("scope") or {}
    moving = record.get("moving") if isinstance(record.get("moving"), dict) else {}
    found = _bound(moving.get("lower_bound"))
    if found is not None:
        fails = ": at or above 1, robust performance fails for the linearised robot in motion, simulated" if found >= 1.0 else ""
        return f"gain >= {found:.4g} (the largest found along admissible trajectories{fails})"
    mu_lower = _bound(record.get("mu_lower"))
    if scope.get("variation") == FROZEN and mu_lower is not None:
        return f"mu >= {mu_lower:.4g} (mu itself is at least this: no bound of this kind goes below)"
    return "not computed"


# ---------------------------------------------------------------------- in words
# How a reader reads a record: what it is about, and what its status means.  The
# status is the one polyrob.analysis.certificate decided; these only word it.

#: Who a certificate is about, by its scope's variation: (short subject of the headline, subject of a sentence).
_SUBJECTS = {
    FROZEN: ("Frozen robot", "every frozen robot of the set"),
    ARBITRARY: ("Arbitrarily fast variation", "the robot with its parameters varying arbitrarily fast in the set"),
}

#: What holds when a certificate of each kind holds.
_PROPERTIES = {
    "robust performance": "meets the performance weights",
    "robust stability": "is stable",
}


def _subject(scope: dict) -> tuple[str, str]:
    variation = str(scope.get("variation") or "")
    if variation in _SUBJECTS:
        return _SUBJECTS[variation]
    return "Moving robot", f"the moving robot ({variation})" if variation else "the robot"


def _figure(record: dict) -> str:
    """What the status rests on, e.g. ``mu <= 0.9449 at every frequency`` (the certificate's ``figure``)."""
    if record.get("figure"):
        return str(record["figure"])
    bound = _bound(record.get("bound"))
    return "" if bound is None else f"bound {bound:.4g}"


def _reason(record: dict) -> str:
    reasons = record.get("reasons") or []
    return str(reasons[0]) if reasons else ""


def headline_name(records: dict) -> str | None:
    """The name of the certificate the report opens with: the frozen robot's robust performance (else any frozen one)."""
    frozen = {k: r for k, r in ((k, certificate_record(v)) for k, v in records.items()) if is_frozen(r)}
    perf = [k for k, r in frozen.items() if r["scope"].get("kind") == "robust performance"]
    return (perf or list(frozen) or [None])[0]


def headline(records: dict) -> str | None:
    """The report's first line: which certificate it is, its status and what it rests on (``None``: no frozen one).

    It is the frozen robot's robust-performance certificate (:func:`frozen_status`), named as such, e.g.
    ``Frozen robot, robust performance: CERTIFIED, mu <= 0.9449 at every frequency``.
    """
    name = headline_name(records)
    if name is None:
        return None
    record = certificate_record(records[name])
    status = record["status"]
    short, _ = _subject(record["scope"])
    kind = record["scope"].get("kind") or "certificate"
    if status == Status.CERTIFIED.value:
        tail = _figure(record)
    elif status == Status.GRID_ONLY.value:
        grid = _bound(record.get("mu_upper_grid"))
        peak = f" (peak {grid:.4g})" if grid is not None else ""
        tail = f"mu < 1 on the frequency grid only{peak}, not proved between its points"
    elif status == Status.VIOLATED.value:
        tail = "disproved" + (f": {_reason(record)}" if _reason(record) else "")
    else:
        tail = "not proved either way" + (f": {_reason(record)}" if _reason(record) else "")
    return f"{short}, {kind}: {status}" + (f", {tail}" if tail else "")


def plain_words(record) -> str:
    """What a record's status says about the robot, in one sentence (the table's "in plain words" column)."""
    record = certificate_record(record)
    scope = record.get("scope") or {}
    _, who = _subject(scope)
    holds = _PROPERTIES.get(scope.get("kind"), "meets the certificate's property")
    status, reason, figure = record["status"], _reason(record), _figure(record)
    if status == Status.CERTIFIED.value:
        return f"Proved: {who} {holds}" + (f" ({figure})" if figure else "")
    if status == Status.GRID_ONLY.value:
        grid = _bound(record.get("mu_upper_grid"))
        peak = f" (peak mu {grid:.4g})" if grid is not None else ""
        return f"Not proved: {who} {holds} at the frequencies of the grid{peak}, but nothing is shown between them"
    if status == Status.VIOLATED.value:
        return f"Disproved: not every robot of the set {holds}" + (f" ({reason})" if reason else "")
    return f"Not proved either way: it is not shown that {who} {holds}" + (f" ({reason})" if reason else "")
