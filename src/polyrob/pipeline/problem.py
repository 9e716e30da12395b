"""Robot + domain + weights -> PLDI -> uncertain plant -> generalized plant, written once.

The CLI's ``analyze``, ``synth`` and ``run`` and the benchmarks all start
from the same three steps; :func:`build_problem` does them and returns a
frozen :class:`Problem` that also knows how to describe itself in a
controller file and how to compare itself with what a file says.

Examples
--------
>>> import polyrob
>>> from polyrob.pipeline import build_problem
>>> robot = polyrob.load_robot("paper_2r")
>>> prob = build_problem(robot, uncertainty="box", bound_options={"samples": 256}, progress=False)
>>> prob.unc.n_params, prob.P.n_u, prob.model
(10, 2, 'box')
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

from polyrob.errors import ArgumentError

__all__ = ["Problem", "build_problem", "default_hyperparameters", "UNCERTAINTY_MODELS", "WEIGHT_KEYS"]

#: Uncertainty models of :func:`polyrob.plant.uncertainty.uncertain_plant` (``box`` is the paper's).
UNCERTAINTY_MODELS = ("auto", "box", "axes", "lft", "lft-torque", "inertia", "inner-links-real")
#: The weight hyperparameters, in the order of :func:`polyrob.plant.weights.paper_weights`.
WEIGHT_KEYS = ("omega_b", "M_s", "A_s", "omega_bt", "M_t", "A_t")


def default_hyperparameters(m: int, overrides: dict | None = None, *, bandwidth_scale: float = 1.0) -> dict:
    """The paper's weight hyperparameters for ``m`` channels, with overrides.

    Parameters
    ----------
    m : int
        Number of channels (actuated joints).
    overrides : dict, optional
        ``key -> sequence`` of 1 or ``m`` values (keys in :data:`WEIGHT_KEYS`).
    bandwidth_scale : float
        Multiplies ``omega_b`` and ``omega_bt``.

    Returns
    -------
    dict
        ``key -> tuple`` of ``m`` floats.

    Examples
    --------
    >>> default_hyperparameters(3, {"M_s": [2.5]})["M_s"]
    (2.5, 2.5, 2.5)
    >>> default_hyperparameters(2, bandwidth_scale=2)["omega_b"]
    (1.0, 0.2)
    """
    from polyrob.plant.weights import LIMIT_KEYS, PAPER_HYPERPARAMETERS

    overrides = dict(overrides or {})
    unknown = sorted(set(overrides) - set(WEIGHT_KEYS) - set(LIMIT_KEYS))
    if unknown:
        raise ArgumentError(f"unknown weight hyperparameter(s) {unknown}; known: {list(WEIGHT_KEYS + LIMIT_KEYS)}")
    h = {}
    # the limit weights (effort, noise) are kept only when given: without them the problem is the paper's
    for key in WEIGHT_KEYS + tuple(k for k in LIMIT_KEYS if k in overrides):
        paper = PAPER_HYPERPARAMETERS.get(key)
        vals = overrides.get(key)
        if vals is None:
            vals = list(paper) if m == len(paper) else [paper[0]] * m
        else:
            vals = [float(v) for v in vals]
            vals = vals * m if len(vals) == 1 else vals
            if len(vals) != m:
                raise ArgumentError(f"weight {key}: give 1 or {m} values (one per joint), got {len(vals)}")
        if key in ("omega_b", "omega_bt"):
            vals = [v * bandwidth_scale for v in vals]
        h[key] = tuple(float(v) for v in vals)
    return h


def make_uncertain_plant(pldi, uncertainty: str = "auto", *, merge_symmetric: bool = False):
    """:func:`~polyrob.plant.uncertainty.uncertain_plant` with a named model; returns ``(unc, model)``.

    ``model`` is the model actually built (what ``"auto"`` resolved to).  The
    build checks the model's coverage on fresh domain points (a minute on a
    six-joint arm): for three joints or more a log line says so first.
    """
    from polyrob.plant.uncertainty import uncertain_plant

    if uncertainty not in UNCERTAINTY_MODELS:
        raise ArgumentError(f"unknown uncertainty model {uncertainty!r}: use one of {', '.join(UNCERTAINTY_MODELS)}")
    if pldi.m >= 3:  # a minute and more on a spatial arm, instant on a planar pair: say it only where it is long
        logging.getLogger("polyrob").info(
            "uncertainty model '%s' of %s: building it and checking its coverage on fresh domain points",
            uncertainty,
            getattr(pldi, "robot_name", "the robot"),
        )
    unc = uncertain_plant(pldi, model=uncertainty, merge_symmetric=merge_symmetric)
    return unc, str(unc.model)


@dataclass(frozen=True, eq=False)
class Problem:
    """One robust-control problem: the PLDI, its uncertain plant and the generalized plant.

    Attributes
    ----------
    robot : Manipulator
        The robot the PLDI bounds (with its inner layer, if any).
    pldi : PLDI
    unc : UncertainPlant
    P : GeneralizedPlant
    hyperparameters : dict
        Weight hyperparameters (``key -> tuple`` per channel).
    uncertainty : str
        The model asked for (``"auto"``, ``"box"``, ...).
    model : str
        The model built (what ``"auto"`` resolved to).
    merge_symmetric : bool
    """

    robot: object
    pldi: object
    unc: object
    P: object
    hyperparameters: dict
    uncertainty: str
    model: str
    merge_symmetric: bool = False

    @property
    def domain(self):
        return self.pldi.domain

    def performance_limit(self, hyperparameters: dict | None = None, **options):
        """The floor under every controller's robust-performance μ at these weights.

        :func:`polyrob.analysis.limits.performance_limit` of the robot over the
        domain with this problem's ``W_T`` (or that of ``hyperparameters``).
        """
        from polyrob.analysis.limits import performance_limit
        from polyrob.plant.weights import paper_weights

        h = self.hyperparameters if hyperparameters is None else hyperparameters
        return performance_limit(self.robot, self.domain, paper_weights(h)[1], **options)

    def description(self) -> dict:
        """What a controller file records about the problem it was made for."""
        return {
            "robot": self.robot.name,
            "m": int(self.robot.m),
            "reflected_inertia": str(getattr(self.robot, "reflected_inertia", "unknown")),
            **({"inner": self.robot.words()} if hasattr(self.robot, "inner") else {}),
            "domain": self.domain.to_dict(),
            "weights": {k: list(v) for k, v in self.hyperparameters.items()},
            "uncertainty": {
                "requested": self.uncertainty,
                "model": self.model,
                "merge_symmetric": bool(self.merge_symmetric),
            },
            "enclosure": self.pldi.enclosure,
            "parameters": int(self.unc.n_params),
        }

    def scope(self, variation: str | None = None):
        """What a certificate on this problem covers (:class:`~polyrob.analysis.certificate.Scope`).

        The enclosure is the weakest of the PLDI's and the uncertainty
        model's own inputs (an ``axes`` model's ranges are sampled, whatever
        the PLDI); the model's coverage is the one measured when it was built
        (``None``: not checked).
        """
        import math

        from polyrob.analysis.certificate import FROZEN, Scope, weakest_enclosure
        from polyrob.plant.models.registry import enclosure_inputs, model_of

        # the weakest of every input: the PLDI, and the model's own ranges (an axes model's are sampled); a model
        # that names its inputs without the PLDI rests on them alone (inner-gain on proved factor ranges)
        own = model_of(self.unc).enclosure(self.unc)
        on_pldi = "PLDI" in enclosure_inputs(self.unc)
        enclosure = weakest_enclosure(self.pldi.enclosure, own) if on_pldi else own
        coverage = getattr(self.unc, "coverage", float("nan"))
        points = int(getattr(self.unc, "coverage_points", 0) or 0)
        checked = coverage is not None and not math.isnan(float(coverage)) and points > 0
        return Scope(
            variation=variation or FROZEN,
            model=self.model,
            coverage=float(coverage) if checked else None,
            coverage_points=points if checked else 0,
            enclosure=enclosure,
            domain=_domain_words(self.domain),
            notes=tuple(getattr(self.robot, "notes", ()) or ())
            + (f"reflected rotor inertia: {getattr(self.robot, 'reflected_inertia', 'unknown')}",)
            + ((self.robot.words(bounds_used=on_pldi),) if hasattr(self.robot, "inner") else ())
            + _work_limit_words(self.pldi, enclosure),
            robot=str(self.robot.name),
        )


def _work_limit_words(pldi, enclosure: str) -> tuple:
    """A note when the proved factor ranges a certificate rests on are those of a proof stopped at its work limit."""
    proof = (pldi.info or {}).get("certify") or {}
    if enclosure != "certified" or not proof.get("factors") or proof.get("done", 1.0) >= 1.0:
        return ()
    tight = proof.get("tightness") or {}
    return (
        f"factor ranges proved at the proof's work limit ({proof['boxes']} boxes, "
        f"{100 * proof['done']:.1f} % of its refinement done): they hold, wider than its tolerance "
        f"(widths up to {tight.get('max', float('nan')):.3g}x the values attained)",
    )


def _domain_words(domain) -> str:
    """The domain's name and what it bounds, per joint: ``paper: q ±(3.14, 3.14), qdot ±(3.96, 9.96), u 0``."""
    import numpy as np

    if hasattr(domain, "words"):  # a task domain says it itself (pose, accelerations, payload)
        return domain.words()

    def group(lo, hi):
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        if not np.any(lo) and not np.any(hi):
            return "0"
        if np.allclose(lo, -hi):
            return "±(" + ", ".join(f"{h:.3g}" for h in hi) + ")"
        return "[" + ", ".join(f"{a:.3g}:{b:.3g}" for a, b in zip(lo, hi)) + "]"

    return (
        f"{domain.name}: q {group(domain.q_lower, domain.q_upper)}, "
        f"qdot {group(domain.qdot_lower, domain.qdot_upper)}, u {group(domain.u_lower, domain.u_upper)}"
    )


def _check_pldi(robot, pldi, domain) -> None:
    if pldi.robot_name != robot.name or pldi.m != robot.m:
        raise ArgumentError(
            f"the PLDI file is for robot '{pldi.robot_name}' ({pldi.m} joints), not '{robot.name}' "
            f"({robot.m} joints): give robot {pldi.robot_name} or bound {robot.name} with `polyrob bounds`"
        )
    if domain is not None and domain.to_dict() != pldi.domain.to_dict():
        raise ArgumentError("give either a PLDI file or domain options, not both (the PLDI file holds its domain)")


def build_problem(
    robot,
    domain=None,
    *,
    hyperparameters: dict | None = None,
    uncertainty: str = "auto",
    pldi=None,
    merge_symmetric: bool = False,
    progress: bool | None = None,
    bound_options: dict | None = None,
) -> Problem:
    """Bound the Jacobians (or take ``pldi``), build the uncertain and the generalized plant.

    Parameters
    ----------
    robot : Manipulator
        From :func:`polyrob.load_robot`.
    domain : Domain, optional
        Default: the robot's default domain.  Not with ``pldi``.
    hyperparameters : dict, optional
        Weight hyperparameters (see :func:`default_hyperparameters`); default the paper's.
    uncertainty : {"auto", "box", "axes", "lft", "lft-torque", "inertia"}
        Model of :func:`polyrob.plant.uncertainty.uncertain_plant`; ``"box"``
        is the paper's (one independent real parameter per entry).
    pldi : PLDI, optional
        A PLDI already computed (e.g. :meth:`polyrob.PLDI.load`); it must be
        of ``robot``.
    merge_symmetric : bool
        One repeated parameter for entries equal by symmetry.
    progress : bool, optional
        Progress bars of the bounding step (default: on a terminal).
    bound_options : dict, optional
        Passed to :func:`polyrob.bound_pldi` (``samples``, ``certify``, ...;
        ``coverage`` defaults to 0 here).

    Returns
    -------
    Problem

    Raises
    ------
    ArgumentError
        A PLDI of another robot, weights of the wrong length, unknown model.
    """
    from polyrob.plant.generalized import generalized_plant
    from polyrob.plant.weights import plant_weights

    h = default_hyperparameters(robot.m) if hyperparameters is None else dict(hyperparameters)
    if {len(v) for v in h.values()} != {robot.m}:
        raise ArgumentError(f"weight hyperparameters need {robot.m} values each (one per joint of {robot.name})")
    if pldi is None:
        from polyrob.bounds.pldi import bound_pldi
        from polyrob.domains.torque_box import Domain

        domain = Domain.from_robot(robot) if domain is None else domain
        options = {"coverage": 0, **(bound_options or {})}
        pldi = bound_pldi(robot, domain, progress=progress, **options)
    else:
        _check_pldi(robot, pldi, domain)
    unc, model = make_uncertain_plant(pldi, uncertainty, merge_symmetric=merge_symmetric)
    P = generalized_plant(unc, **plant_weights(h))
    return Problem(
        robot=robot,
        pldi=pldi,
        unc=unc,
        P=P,
        hyperparameters={k: tuple(v) for k, v in h.items()},
        uncertainty=uncertainty,
        model=model,
        merge_symmetric=merge_symmetric,
    )
