"""What Coulomb friction does to a certified loop: the statement beside its ``covers:`` line.

Coulomb friction is no Jacobian term: a frozen or moving μ certificate does
not cover it.  What the loop does with it is stated instead
(:func:`polyrob.synthesis.integral.coulomb_channel`): the steady-state error
it leaves, the proved H∞ bound of its path to the tracking error, and the
nominal loop's slowest decay.  ``synth``, ``run`` and the batch print the
same statement from here, so a controller gets the same words whichever
command made it.
"""

from __future__ import annotations

__all__ = ["friction_statement"]


def friction_statement(problem, K, given=None) -> dict | None:
    """The Coulomb channel's figures of ``K`` on ``problem``, or ``None`` when no level is stated.

    Parameters
    ----------
    problem : polyrob.pipeline.Problem
        The problem ``K`` was certified on; its robot-uncertainty set states
        the Coulomb levels unless ``given`` does.
    K : control.StateSpace
        The controller.
    given : sequence of float, optional
        ``--coulomb``: one level (N m) for every joint or one per joint; it
        replaces the set's levels.

    Returns
    -------
    dict or None
        :meth:`polyrob.synthesis.integral.CoulombChannel.to_dict` (its
        ``words`` the printed line), or ``None``: neither ``given`` nor the set
        states a Coulomb level.

    Notes
    -----
    Behind an inner layer the friction torque reaches the outer loop through
    ``M_hat(q)^-1``: its entries are bounded by
    :func:`polyrob.fleet.autoweights.inverse_inertia_bound` (sampled over the
    task, not proved) and widened by the model's relative inertia error
    (first order), which the words say.
    """
    from polyrob.fleet.autoweights import inverse_inertia_bound
    from polyrob.synthesis.integral import coulomb_channel, coulomb_levels

    levels, source = coulomb_levels(problem.robot, given)
    if levels is None:
        return None
    inv = inverse_inertia_bound(problem.robot, problem.domain)
    spec = getattr(problem.robot, "uncertainty", None)  # the relative inertia error the model's M_hat may have
    p = max(float(getattr(problem.robot, "model_error", 0.0) or 0.0), float(getattr(spec, "link_error", 0.0) or 0.0))
    p = p if inv is not None else 0.0
    ch = coulomb_channel(problem.unc.nominal_system(), K, levels, source=source, inverse_inertia=inv, model_error=p)
    return ch.to_dict()
