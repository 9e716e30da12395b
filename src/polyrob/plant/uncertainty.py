"""The uncertain plant of a PLDI: one entry point, several uncertainty models.

:func:`uncertain_plant` turns a :class:`~polyrob.bounds.pldi.PLDI` into an
:class:`~polyrob.plant.lftplant.UncertainPlant` (MATLAB's ``uss``), the
object the generalized plant, μ-analysis and synthesis consume, with one of
these models of the set of Jacobians (docs/uncertainty.md):

``"box"``
    The paper's: one independent real parameter per varying entry, the
    interval box (:mod:`polyrob.plant.models.box`).
``"axes"``
    An oriented box in the principal directions of the Jacobian cloud plus
    a norm-bounded residual block (:mod:`polyrob.plant.models.axes`); any robot.
``"lft"``
    The inverse inertia as an exact LFT in the cos/sin of the joint angles
    it depends on, times a box on the torque-side Jacobian
    (:mod:`polyrob.plant.models.inertia_lft`); robots whose inertia is affine in
    single-angle cos/sin terms (planar 2R arms, analytic or URDF).
``"lft-torque"``
    The same inverse inertia times a box on the torque-side Jacobian
    ``N = M(q) A_low`` instead of the entries of ``A_low``
    (``[A_low B_low] = M(q)^{-1} [N I]``, ``a_part="torque"``): fewer
    parameters and ``A`` moves with the inertia, but the product can leave
    the entries' intervals.
``"inertia"``
    ``M(q)`` on the intervals of its ``L D Lᵀ`` factors (every member
    positive definite, so is every member's input matrix ``M⁻¹``, an exact
    LFT of them) times an ``axes`` model of the torque-side Jacobian
    ``N = M(q) A_low`` (:mod:`polyrob.plant.models.inertia_plant`); any arm whose
    ``B`` is ``[0; M(q)⁻¹]``.
``"auto"`` (default)
    ``lft`` where it applies, else ``axes`` (:data:`AUTO`); the choice and
    its reason are in ``info["auto"]``.

Each model is one class of :mod:`polyrob.plant.models`, registered in
:data:`MODELS` (name to instance; ``"auto"`` is a choice of
:func:`uncertain_plant`, not a model).  ``model_of(unc)`` is the model that
built a plant: ``model_of(unc).contains(unc, A, B)``,
``model_of(unc).describe(unc)`` (what set it is) and
``model_of(unc).enclosure(unc)`` (``"sampled"`` or ``"certified"``, the
weakest of its inputs: ``axes`` is sampled even on a certified PLDI).

Every result carries its ``coverage`` (fraction of fresh domain samples whose
Jacobians it contains; must be 1.0) and ``volume_ratio`` (its size over the
PLDI polytope's, :func:`polyrob.plant.coverage.volume_ratio`).

Examples
--------
>>> import polyrob
>>> from polyrob.plant.uncertainty import model_of, uncertain_plant
>>> pldi = polyrob.bound_pldi(polyrob.load_robot("paper_2r"), samples=256, coverage=0, progress=False)
>>> box = uncertain_plant(pldi, model="box")
>>> box.n_params, box.coverage
(10, 1.0)
>>> tight = uncertain_plant(pldi)
>>> tight.model, tight.parameter_names[-2:], tight.coverage
('lft', ('cos(q2)#1', 'cos(q2)#2'), 1.0)
>>> model_of(tight).enclosure(tight), model_of(box).name
('sampled', 'box')
"""

from __future__ import annotations

import numpy as np

from polyrob.errors import ArgumentError, NotApplicable
from polyrob.plant.lftplant import MAX_CORNERS, UncertainPlant, upper_lft
from polyrob.plant.models import MODELS, UncertaintyModel, model_of
from polyrob.plant.models.box import SYMMETRY_RTOL

__all__ = [
    "UncertainPlant",
    "uncertain_plant",
    "upper_lft",
    "MODELS",
    "CHOICES",
    "AUTO",
    "model_of",
    "describe",
    "MAX_CORNERS",
    "SYMMETRY_RTOL",
]

#: ``model="auto"`` builds the first of these models that applies (the last always does).
AUTO = ("inner-links", "inner-gain", "lft", "axes")

#: The choices of :func:`uncertain_plant`: ``"auto"`` and every registered model.
CHOICES = ("auto", *MODELS)


def _build(chosen: UncertaintyModel, pldi, options: dict) -> UncertainPlant:
    """``chosen.build`` with the options it takes."""
    return chosen.build(pldi, **{key: v for key, v in options.items() if key in chosen.options})


def _auto(pldi, options: dict) -> tuple[UncertainPlant, str]:
    """The first model of :data:`AUTO` that applies, and why it was taken."""
    reasons = []
    for name in AUTO[:-1]:
        try:
            return _build(MODELS[name], pldi, options), f"{name}: {MODELS[name].applies}"
        except NotApplicable as exc:
            reasons.append(str(exc))
    return _build(MODELS[AUTO[-1]], pldi, options), f"{AUTO[-1]}: {'; '.join(reasons)}"


def uncertain_plant(
    pldi,
    *,
    model: str = "auto",
    nominal: str = "pldi",
    merge_symmetric: bool = False,
    n_directions: int | None = None,
    residual_tol: float | None = None,
    repeated: bool = False,
    robot=None,
    coverage: int = 2000,
    volume_samples: int = 200_000,
    seed: int = 12345,
) -> UncertainPlant:
    """The uncertain plant of a PLDI under an uncertainty model.

    Parameters
    ----------
    pldi : PLDI
        From :func:`polyrob.bound_pldi`.
    model : {"auto", "box", "axes", "lft", "lft-torque", "inertia"}
        See the module docstring.  ``"box"`` is the paper's model, unchanged.
    nominal : {"pldi", "midpoint"}
        ``G_n`` is the PLDI's nominal ``(A0, B0)`` or the model's centre.
    merge_symmetric : bool
        ``box`` only: entries equal by symmetry of ``M(q)^{-1}`` share one
        repeated parameter (block ``[-2, 0]``).
    n_directions, residual_tol
        ``axes`` (and ``inertia``'s model of ``N``): retained principal
        directions (default automatic) and the residual tolerance of the
        automatic choice.
    repeated : bool
        ``lft`` only: exact repeated scalars (``True``) or independent
        rank-one pieces (``False``, default; see :func:`~polyrob.plant.models.inertia_lft.inertia_lft_plant`).
    robot : Manipulator, optional
        For the ``lft`` model and the coverage check (default: loaded from the PLDI).
    coverage : int
        Fresh domain samples for the coverage check (0 to skip: ``coverage`` is NaN).
    volume_samples : int
        Points of the interval box for the volume ratio (0 to skip).
    seed : int
        Seed of the coverage and volume samples.

    Returns
    -------
    UncertainPlant
        ``model_of(unc)`` (:func:`polyrob.plant.models.model_of`) is the model
        that built it: its ``describe(unc)`` and ``enclosure(unc)``.

    Raises
    ------
    ArgumentError
        Unknown model, or an option of another model.
    BoundsError
        Inverted or non-finite intervals.
    """
    from polyrob.plant.coverage import coverage_fraction, volume_ratio

    if model not in CHOICES:
        raise ArgumentError(f"unknown uncertainty model '{model}': use one of {', '.join(CHOICES)}")
    candidates = [MODELS[name] for name in (AUTO if model == "auto" else (model,))]
    options = {
        "nominal": nominal,
        "merge_symmetric": merge_symmetric,
        "n_directions": n_directions,
        "residual_tol": residual_tol,
        "repeated": repeated,
        "robot": robot,
    }
    taken = {key for c in candidates for key in c.options}
    for owner in MODELS.values():
        if any(options[key] != default and key not in taken for key, default in owner.exclusive.items()):
            verb = "applies" if len(owner.exclusive) == 1 else "apply"
            takers = [f"'{o.name}'" for o in MODELS.values() if set(owner.exclusive) <= set(o.options)]
            raise ArgumentError(f"{' and '.join(owner.exclusive)} {verb} to model={' or '.join(takers)} only")
    if robot is None and (coverage or any(c.needs_robot for c in candidates)):
        options["robot"] = robot = pldi.robot
    if model == "auto":
        unc, note = _auto(pldi, options)
    else:
        unc, note = _build(candidates[0], pldi, options), None
    figures = {}
    if coverage:
        figures["coverage"] = coverage_fraction(unc, robot, pldi.domain, coverage, seed=seed)
        figures["coverage_points"] = int(coverage)
    info = dict(unc.info)
    if note:
        info["auto"] = note
    if volume_samples and len(pldi.entries) and pldi.polytope.reduced_dim:
        vol = volume_ratio(unc, pldi, volume_samples, seed=seed)
        figures["volume_ratio"] = vol["model_over_polytope"]
        info["volume"] = vol
    figures["info"] = info
    return unc.with_figures(**figures)


def describe(unc: UncertainPlant) -> str:
    """One line: model, parameters, blocks, coverage and volume ratio (for the CLI)."""
    blocks = ", ".join(f"[{r} {c}]" for r, c in np.asarray(unc.block_structure).tolist())
    return (
        f"uncertainty model {unc.model}: {unc.n_params} real parameters, {unc.n_delta} channels, "
        f"blocks {blocks}; coverage {unc.coverage:.4g} on {unc.coverage_points} fresh samples; "
        f"volume / polytope {unc.volume_ratio:.3g}"
    )
