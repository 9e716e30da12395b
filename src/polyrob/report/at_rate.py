"""The report's section "Validation at the rate": the controller as it runs, on true robots drawn from the set.

:func:`add_rate_validation` writes, from a
:meth:`~polyrob.validate.at_rate.runs.RateValidation.summary`, one table per
reference (runs settled, inside the task's q, qdot and qddot bounds, the
worst tracking error, settling time and chatter against the effort limit)
and the one-line verdict, which says it is a simulation and not a certificate.
"""

from __future__ import annotations

from polyrob.report.page import cell

__all__ = ["add_rate_validation"]


def _pct(v) -> str:
    return "not measured" if v is None else f"{v:.3g} %"


def add_rate_validation(doc, summary: dict | None) -> None:
    """The section into ``doc`` (a :class:`~polyrob.report.page.Page`); nothing when ``summary`` is ``None``."""
    if not summary:
        return
    doc.heading("Validation at the rate (true robots drawn from the set)")
    doc.para(
        f"{summary['true_robots']} true robot(s) drawn from {summary['uncertainty']}; the inner layer computes with "
        "the nominal links and the middle payload. Each runs a step and the task's trajectory from a settled "
        "hold. Conditions: " + _conditions(summary["conditions"]) + "."
    )
    rows, bad = [], []
    for name, a in summary["by_reference"].items():
        runs = a["runs"]
        rows.append(
            (
                name,
                f"{a['settled']} of {runs}",
                f"{a['inside_task']} of {runs}",
                cell(a["max_tracking_error_worst"]),
                cell(a["final_tracking_error_worst"]),
                cell(a["settling_time_worst"], "not settled"),
                cell(a["qdot_fraction_worst"], "no bound"),
                cell(a["qddot_fraction_worst"], "no bound"),
                _pct(a["chatter_percent_worst"]),
            )
        )
        if a["settled"] < runs or a["inside_task"] < runs or a["chatter_within_limit"] < runs:
            bad.append(len(rows) - 1)
    doc.table(
        [
            "reference",
            "settled",
            "inside the task",
            "worst max error (rad)",
            "worst final error (rad)",
            "worst settling (s)",
            "worst peak qdot / its bound",
            "worst peak qddot / its bound",
            f"worst chatter (p-p, of the effort limit; bar {summary['chatter_limit_percent']:g} %)",
        ],
        rows,
        bad_rows=bad,
    )
    doc.para(summary["verdict"], bad=not summary["meets_bar"])


def _conditions(c: dict) -> str:
    enc = "exact encoders" if c["encoder_bits"] is None else f"{c['encoder_bits']}-bit encoders"
    return (
        f"{c['rate_hz']:g} Hz, {c['delay_samples']} sample(s) of delay, {enc}, friction not in the inner model "
        f"(viscous {c['friction_viscous']:g} N m s/rad, Coulomb {c['coulomb_model']} with c = "
        f"{c['friction_coulomb']:g} N m), the controller by {c['controller_discretisation']}"
        + (", torques clipped at the effort limit" if c["saturate"] else "")
    )
