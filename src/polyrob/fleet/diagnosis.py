"""Why a robot of a batch is left without a certificate, in one line.

Two obstacles are structural, and no synthesis effort removes them:

* the **performance limit** of the robot's unstable open-loop poles at the
  weights used (:mod:`polyrob.analysis.limits`): at least 1 means no
  controller reaches μ < 1 at these bandwidths;
* a model whose members include input matrices ``B = M(q)^-1`` that are not
  positive definite (:func:`polyrob.plant.coverage.input_definiteness`;
  the robot's always is): robust stability on it asks for inputs that act in
  reverse, at every bandwidth.

:func:`search_skipped` says when the second makes a bandwidth search
pointless; :func:`why_not_certified` names whichever holds for a robot left
with μ ≥ 1, or says that neither was found.
"""

from __future__ import annotations

__all__ = ["search_skipped", "why_not_certified"]


def search_skipped(problem, details: dict) -> str | None:
    """Why the bandwidth search would be pointless on ``problem``'s model, or ``None``.

    The input check goes into ``details`` (``"input_definiteness"``), where
    :func:`why_not_certified` finds it instead of sampling the model again.
    """
    from polyrob.plant.coverage import input_definiteness

    check = details["input_definiteness"] = input_definiteness(problem.unc)
    if check["fraction"] <= 0:
        return None
    # every factor would meet the same reversed inputs: one synthesis says how far off it is
    return (
        f"{100 * check['fraction']:.0f} % of the model's members have "
        "B = M^-1 not positive definite, so no bandwidth gives mu < 1 on it"
    )


def why_not_certified(problem, details: dict, certificate=None) -> str:
    """What stands between this robot and a certificate, in one line; the evidence goes into ``details``.

    With ``certificate`` (the row's frozen-robot one) below 1 on the grid,
    μ is not what stands in the way: its own reasons are (a model that
    does not cover the robot's fresh Jacobians, a check between the grid
    points that failed).  Otherwise what keeps μ from falling below 1.
    """
    from polyrob.plant.coverage import input_definiteness

    if certificate is not None and certificate.mu_upper_grid < 1.0 and certificate.reasons:
        return "; ".join(certificate.reasons)
    parts = []
    limit = problem.performance_limit(samples=1024, starts=2)
    details["performance_limit"] = limit.to_dict()
    if limit.excludes_mu_below_one:
        parts.append(
            f"performance limit {limit.bound:.3g} >= 1 at these weights (unstable pole {abs(limit.pole):.3g} rad/s): "
            "no controller reaches mu < 1 without higher bandwidths"
        )
    if "input_definiteness" not in details:
        details["input_definiteness"] = input_definiteness(problem.unc)
    check = details["input_definiteness"]
    if check["fraction"] > 0:
        parts.append(
            f"{100 * check['fraction']:.0f} % of the {problem.model} model's members have B = M^-1 not positive "
            "definite (the robot's always is): robust stability on this model asks for inputs acting in reverse"
        )
    if not parts:
        parts.append("mu >= 1 is the synthesis' best at these weights (no structural obstacle found)")
    return "; ".join(parts)
