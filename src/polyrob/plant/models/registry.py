"""The uncertainty models: one class each, behind one interface.

Every model of the set of Jacobians is an :class:`UncertaintyModel`:

``name``
    What :func:`~polyrob.plant.uncertainty.uncertain_plant` calls it and what
    the plants it builds record in ``unc.model``.
``build(pldi, **options)``
    The model's :class:`~polyrob.plant.lftplant.UncertainPlant` (without the
    coverage and volume figures, which :func:`uncertain_plant` adds).
``contains(unc, A, B)``
    Whether Jacobians lie in the plant's set, ``(n,)`` bool.
``describe(unc)``
    One sentence: what set the plant is.
``enclosure(unc)``
    ``"sampled"`` or ``"certified"``: the weakest of every input the plant
    was built from (``unc.info["enclosure_inputs"]``).  ``"certified"`` only
    when the PLDI was certified *and* the model's own ranges were proved:
    ``axes`` takes its directional ranges from the PLDI's sampled support
    values, so it is ``"sampled"`` even on a certified PLDI; ``lft-torque``
    is also as weak as its second PLDI, the one of ``N = M(q) A_low``;
    ``inertia`` is sampled always (its factor ranges and ``N`` directions).

:data:`MODELS` maps each name to its instance and :func:`model_of` finds the
instance of a built plant.

Examples
--------
>>> import polyrob
>>> from polyrob.plant.models import MODELS, model_of
>>> list(MODELS)
['box', 'axes', 'lft', 'lft-torque', 'inertia', 'inner-gain', 'inner-links', 'inner-links-real', 'inner-links-moving']
>>> pldi = polyrob.bound_pldi(polyrob.load_robot("paper_2r"), samples=256, coverage=0, progress=False)
>>> unc = MODELS["axes"].build(pldi)
>>> model_of(unc).name, model_of(unc).enclosure(unc), unc.info["enclosure_inputs"]
('axes', 'sampled', {'PLDI': 'sampled', 'directions': 'sampled'})
>>> print(model_of(unc).describe(unc))  # doctest: +NORMALIZE_WHITESPACE
axes: an oriented box along 6 principal directions of the Jacobian cloud, with ranges from the PLDI's sampled
support values, plus a norm-bounded residual block of size 5 (sampled enclosure).
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np

from polyrob.errors import ArgumentError
from polyrob.plant.lftplant import UncertainPlant, weakest_enclosure

__all__ = [
    "UncertaintyModel",
    "BoxModel",
    "AxesModel",
    "InertiaLFTModel",
    "InertiaModel",
    "InnerGainModel",
    "InnerLinksModel",
    "MODELS",
    "model_of",
    "enclosure_inputs",
]


def enclosure_inputs(unc: UncertainPlant) -> dict[str, str]:
    """``{input: "sampled" | "certified"}`` of everything the plant was built from.

    Plants built before the inputs were recorded fall back on their
    ``info["enclosure"]`` (and ``info["N_enclosure"]`` for ``lft-torque``);
    a missing level counts as ``"sampled"``.
    """
    info = unc.info or {}
    if "enclosure_inputs" in info:
        return dict(info["enclosure_inputs"])
    found = {"PLDI": info.get("enclosure") or "sampled"}
    if "N_enclosure" in info:
        found["N PLDI"] = info["N_enclosure"] or "sampled"
    return found


class UncertaintyModel(ABC):
    """One uncertainty model: how a PLDI becomes an uncertain plant, and what set that plant is.

    Attributes
    ----------
    name : str
    options : tuple of str
        Keywords :meth:`build` takes besides the PLDI.
    exclusive : dict
        Options that only this model takes, with their defaults:
        :func:`~polyrob.plant.uncertainty.uncertain_plant` refuses them, when
        set, for any other model.
    needs_robot : bool
        :meth:`build` evaluates the robot (not only the PLDI).
    """

    name: str = ""
    options: tuple[str, ...] = ("nominal",)
    exclusive: dict = {}
    needs_robot: bool = False

    @abstractmethod
    def build(self, pldi, **options) -> UncertainPlant:
        """The model's uncertain plant of ``pldi`` (no coverage or volume figures)."""

    @abstractmethod
    def contains(self, unc: UncertainPlant, A, B) -> np.ndarray:
        """Whether Jacobians ``A`` (n, 2m, 2m), ``B`` (n, 2m, m) lie in the plant's set, (n,) bool."""

    @abstractmethod
    def describe(self, unc: UncertainPlant) -> str:
        """One sentence: what set the plant is."""

    def enclosure(self, unc: UncertainPlant) -> str:
        """``"certified"`` if every input of the plant was proved, else ``"sampled"``."""
        return weakest_enclosure(*enclosure_inputs(unc).values())

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r})"


class BoxModel(UncertaintyModel):
    """The paper's model: one independent real parameter per varying entry (:mod:`polyrob.plant.models.box`)."""

    name = "box"
    options = ("nominal", "merge_symmetric")
    exclusive = {"merge_symmetric": False}

    def build(self, pldi, *, nominal: str = "pldi", merge_symmetric: bool = False) -> UncertainPlant:
        from polyrob.plant.models.box import box_plant

        return box_plant(pldi, nominal=nominal, merge_symmetric=merge_symmetric)

    def contains(self, unc, A, B):
        from polyrob.plant.models.box import box_contains

        return box_contains(unc, A, B)

    def describe(self, unc):
        merged = "; ".join("=".join(pair) for pair in unc.merged)
        shared = f", {merged} sharing one" if merged else ""
        return (
            f"box: the interval box of the PLDI's {len(unc.channel_names)} varying Jacobian entries, "
            f"one independent real parameter per entry{shared} ({self.enclosure(unc)} enclosure)."
        )


class AxesModel(UncertaintyModel):
    """An oriented box in the principal directions plus a residual block (:mod:`polyrob.plant.models.axes`)."""

    name = "axes"
    options = ("nominal", "n_directions", "residual_tol")
    exclusive = {"n_directions": None, "residual_tol": None}

    def build(
        self, pldi, *, nominal: str = "pldi", n_directions: int | None = None, residual_tol: float | None = None
    ) -> UncertainPlant:
        from polyrob.plant.models.axes import RESIDUAL_TOL, axes_plant

        tol = RESIDUAL_TOL if residual_tol is None else residual_tol
        return axes_plant(pldi, n_directions=n_directions, residual_tol=tol, nominal=nominal)

    def contains(self, unc, A, B):
        from polyrob.plant.models.axes import axes_contains

        return axes_contains(unc, A, B)

    def describe(self, unc):
        size = sum(unc.full_blocks)
        residual = f"a norm-bounded residual block of size {size}" if size else "no residual block"
        return (
            f"axes: an oriented box along {unc.n_params} principal directions of the Jacobian cloud, with ranges "
            f"from the PLDI's sampled support values, plus {residual} ({self.enclosure(unc)} enclosure)."
        )


class InertiaLFTModel(UncertaintyModel):
    """The inverse inertia as an exact LFT times a box on ``A`` (``lft``) or on ``N`` (``lft-torque``).

    See :mod:`polyrob.plant.models.inertia_lft`; ``a_part`` is ``"entries"`` or ``"torque"``.
    """

    options = ("nominal", "repeated", "robot")
    needs_robot = True
    #: Why ``model="auto"`` takes this model when it applies.
    applies = "the inertia is affine in single-angle cos/sin terms"

    def __init__(self, name: str, a_part: str):
        self.name, self.a_part = name, a_part

    def build(
        self, pldi, *, nominal: str = "pldi", repeated: bool = False, robot=None, bound_options: dict | None = None
    ) -> UncertainPlant:
        from polyrob.plant.models.inertia_lft import inertia_lft_plant

        return inertia_lft_plant(
            pldi, robot=robot, nominal=nominal, repeated=repeated, a_part=self.a_part, bound_options=bound_options
        )

    def contains(self, unc, A, B):
        from polyrob.plant.models.inertia_lft import inertia_lft_contains

        return inertia_lft_contains(unc, A, B)

    def describe(self, unc):
        n_a = len(unc.info.get("N_index", ()))
        features = sorted({name.split("#")[0] for name in unc.parameter_names[n_a:]})
        how = "one repeated scalar each" if unc.info.get("repeated") else "independent rank-one pieces"
        if self.a_part == "torque":
            a_part = (
                f"times a box on the {n_a} varying entries of the torque-side Jacobian N = M(q) A_low "
                "from a second PLDI"
            )
        else:
            a_part = f"with the PLDI's interval on each of the {n_a} varying entries of A"
        return (
            f"{self.name}: the inverse inertia M(q)^-1 as an exact LFT in {', '.join(features) or 'no terms'} "
            f"over the exact range of each ({how}), {a_part} ({self.enclosure(unc)} enclosure)."
        )


class InertiaModel(UncertaintyModel):
    """``M(q)`` on its ``L D Lᵀ`` factors (every member positive definite), ``M⁻¹`` an exact LFT of them,
    times an ``axes`` model of the torque-side ``N = M(q) A_low`` (:mod:`polyrob.plant.models.inertia_plant`)."""

    name = "inertia"
    options = ("nominal", "robot", "n_directions", "residual_tol")
    needs_robot = True

    def build(
        self,
        pldi,
        *,
        nominal: str = "pldi",
        robot=None,
        n_directions: int | None = None,
        residual_tol: float | None = None,
        bound_options: dict | None = None,
        factor_options: dict | None = None,
    ) -> UncertainPlant:
        from polyrob.plant.models.inertia_plant import inertia_plant

        return inertia_plant(
            pldi,
            robot=robot,
            nominal=nominal,
            n_directions=n_directions,
            residual_tol=residual_tol,
            bound_options=bound_options,
            factor_options=factor_options,
        )

    def contains(self, unc, A, B):
        from polyrob.plant.models.inertia_plant import inertia_contains

        return inertia_contains(unc, A, B)

    def describe(self, unc):
        factors, sub = unc.info["factors"], unc.info["N_plant"]
        size = sum(sub.full_blocks)
        residual = f" plus a norm-bounded residual block of size {size}" if size else ""
        return (
            f"inertia: M(q) = L D L^T with an interval on each of its {len(factors.index)} varying factors "
            f"(positive definite in every member), M(q)^-1 an exact LFT of them, times an axes model of the "
            f"torque-side Jacobian N = M(q) A_low from a second PLDI ({sub.n_params} principal directions"
            f"{residual}) ({self.enclosure(unc)} enclosure)."
        )


class InnerGainModel(UncertaintyModel):
    """Computed torque with one inertia factor: one repeated real gain and a residual (:mod:`polyrob.plant.models.inner_gain`)."""

    name = "inner-gain"
    options = ()
    needs_robot = True
    #: Why ``model="auto"`` takes this model when it applies.
    applies = "a computed-torque inner loop whose model is off by one inertia factor: one gain parameter"

    def build(self, pldi, **options):
        from polyrob.plant.models.inner_gain import inner_gain_plant

        return inner_gain_plant(pldi)

    def contains(self, unc, A, B):
        if "theta_range" in unc.info:
            from polyrob.plant.models.factor_membership import inner_factors_contains

            return inner_factors_contains(unc, A, B)
        from polyrob.plant.models.axes import axes_contains

        return axes_contains(unc, A, B)

    def describe(self, unc):
        if "theta_range" in unc.info:
            size = int(unc.block_structure[0, 0]) if unc.block_structure[0, 1] > 0 else 0
            ranges = ", ".join(f"{n} ±{r:.4g}" for n, r in zip(unc.info["factors"], unc.info["theta_range"]))
            return (
                f"inner-gain: [A_low B_low] = (I - sum theta_k G_k)^-1 [sum theta_k J_k, I] of a computed-torque "
                f"loop (rotor inertia or a payload: M != s M_hat), one repeated real per scalar ({ranges}), "
                f"the spread of the factors [J_k G_k] a residual block of size {size} ({self.enclosure(unc)} enclosure)."
            )
        lo, hi = unc.info["eps_range"]
        size = int(unc.block_structure[0, 0]) if unc.block_structure[0, 1] > 0 else 0
        return (
            f"inner-gain: [A_low B_low] = [0 I] + eps [J I] of a computed-torque loop, eps in [{lo:.4g}, {hi:.4g}] "
            f"one repeated real, J's spread a residual block of size {size} ({self.enclosure(unc)} enclosure)."
        )


class InnerLinksModel(UncertaintyModel):
    """Computed torque over a per-link robot-uncertainty set: the factor exact in the parameters, compressed
    (:mod:`polyrob.plant.models.inner_links`)."""

    options = ("n_directions",)
    needs_robot = True
    #: Why ``model="auto"`` takes this model when it applies.
    applies = "a computed-torque loop over a per-link robot-uncertainty set: the factor linear in the parameters"

    def __init__(self, name: str = "inner-links", residual: str = "block"):
        # "inner-links-real": the state columns' residual as one real scalar per entry (tighter, slower μ)
        self.name, self.residual = name, residual

    def set_loop(self, pldi):
        """The inner loop over a robot-uncertainty set that ``pldi`` was bounded on.

        Raises
        ------
        NotApplicable
            No set recorded with the PLDI.
        """
        from polyrob.errors import NotApplicable

        robot = pldi.source_robot if pldi.source_robot is not None else getattr(pldi.domain, "robot", None)
        if robot is None or getattr(robot, "uncertainty", None) is None:
            raise NotApplicable(f"{self.name}: no robot-uncertainty set recorded with the PLDI")
        return robot

    def build(self, pldi, *, n_directions: int | None = None, **options):
        from polyrob.errors import NotApplicable
        from polyrob.plant.models.inner_links import inner_links_plant

        robot = self.set_loop(pldi)
        try:
            return inner_links_plant(pldi, robot, n_directions=n_directions, residual=self.residual)
        except NotApplicable as exc:  # a stated set is carried by this model or refused, never by another one
            raise ArgumentError(f"robot uncertainty ({robot.uncertainty.words()}): not carried: {exc}") from None

    def contains(self, unc, A, B):
        from polyrob.plant.models.factor_membership import inner_factors_contains

        return inner_factors_contains(unc, A, B)

    def describe(self, unc):
        size = sum(int(b[0]) for b in unc.block_structure if b[1] > 0)
        ranges = ", ".join(f"{n} ±{r:.3g}" for n, r in zip(unc.info["factors"], unc.info["theta_range"]))
        entries = len(unc.info.get("residual_entries", ()))
        rest = f"residual blocks of total size {size}"
        if entries:
            rest = f"{entries} real scalars (the state columns' residual, one per entry) and {rest}"
        if "state_residual_norm" in unc.info:
            rest += (
                f" (the state columns' block of norm <= {unc.info['state_residual_norm']:.3g} in the weights "
                "of its entries' bounds: the residual's norm at the samples, not their entry box)"
            )
        return (
            f"{self.name}: the computed-torque factor [B_low^-1 A_low, I - B_low^-1], exactly linear in the "
            f"{len(unc.info['scalars'])} scalars of the set's parameter box, as {len(unc.info['factors'])} principal "
            f"directions (one repeated real each: {ranges}) and the rest in {rest} "
            f"({_inertia_words(unc)}); "
            f"set: {unc.info['set']} ({self.enclosure(unc)} enclosure over the task domain"
            + (f"; {unc.info['payload_sampling']}" if unc.info.get("payload_sampling") else "")
            + ")."
        )


class MovingLinksModel(InnerLinksModel):
    """A per-link set's computed-torque loop split at the task's centre into what stays and what moves
    (:mod:`polyrob.plant.moving_links`): the moving robot's model, built by its certificate."""

    applies = "the moving robot of a per-link set: its parameters constant, its state moving"

    def __init__(self):
        super().__init__("inner-links-moving")

    def build(self, pldi, *, n_directions: int | None = None, **options):
        from polyrob.plant.moving_links import moving_links_plant

        return moving_links_plant(pldi, self.set_loop(pldi), n_directions=n_directions)

    def contains(self, unc, A, B):
        # its blocks overlap (the centre's and the motion's on the same entries): membership needs the true
        # robot at the task's centre too, polyrob.plant.moving_links.motion_witness
        raise ArgumentError(
            "inner-links-moving: membership needs the true robot (its factor at the task's centre), not a "
            "Jacobian alone: use polyrob.plant.moving_links.motion_coverage"
        )

    def describe(self, unc):
        ranges = ", ".join(f"{n} ±{r:.3g}" for n, r in zip(unc.info["factors"], unc.info["theta_range"]))
        scalars = f"{len(unc.info['factors'])} directions' values there (one repeated real each, constant: {ranges})"
        if unc.info.get("exact_scalars"):
            scalars = (
                f"the set's {len(unc.info['factors'])} link and joint scalars, each within ±1 of its half range and "
                "exact there (one real each, repeated as its factor's rank, constant)"
            )
        norm = unc.info.get("state_residual_norm")
        state = (
            "none for the state columns" if norm is None else f"the state columns' of norm <= {norm:.3g} in its weights"
        )
        payload = unc.info.get("payload_lft")
        if payload is not None:  # the instrument exact at the centre: no constant full block is left
            rest = f"the instrument's part there an exact LFT in its mass and centre of mass ({payload.covers}; 4 reals, constant)"
        else:
            rest = (
                f"the rest there {'(the instrument' + chr(39) + 's part) ' if unc.info.get('exact_scalars') else ''}"
                f"in constant full blocks ({state}; {_inertia_words(unc)})"
            )
        return (
            f"inner-links-moving: the computed-torque factor split at the task's centre: {scalars}, {rest}, "
            f"and the motion K(u, x) - K(u, x_c) in full blocks that vary in time "
            f"(entry bounds of Frobenius norm {unc.info['motion_norm']:.3g}, norms at most "
            f"{', '.join(f'{r:.3g}' for r in unc.info.get('motion_ball', (1.0,)))} in their weights); set: {unc.info['set']} "
            f"({self.enclosure(unc)} enclosure over the task domain)."
        )


def _inertia_words(unc) -> str:
    """How the ``inner-links`` model carries the relative inertia error ``G`` (its acceleration columns)."""
    g = unc.info.get("residual_g_norm", 0.0)
    if unc.info.get("inertia_block") == "shaped":
        values = np.linalg.eigvalsh(unc.info["residual_g_shape"])
        return (
            f"the inertia's M_hat^1/2-weighted block g S^1/2 Delta S^1/2 around a centre fitted to the set, g = {g:.3g}, "
            f"S shaped like the set's inertia errors (eigenvalues {values.min():.2g} to 1; a ball would need "
            f"{unc.info['inertia_ball']:.3g} relative to its room)"
        )
    return (
        f"the inertia's M_hat^1/2-weighted block of norm <= {g:.3g} around "
        f"I - G = {1.0 - float(unc.info['K_offset'][-1, -1]):.3g} I"
    )


#: The uncertainty models by name (``unc.model``).
MODELS: dict[str, UncertaintyModel] = {
    model.name: model
    for model in (
        BoxModel(),
        AxesModel(),
        InertiaLFTModel("lft", "entries"),
        InertiaLFTModel("lft-torque", "torque"),
        InertiaModel(),
        InnerGainModel(),
        InnerLinksModel(),
        InnerLinksModel("inner-links-real", "real"),
        MovingLinksModel(),
    )
}


def model_of(unc: UncertainPlant) -> UncertaintyModel:
    """The model that built ``unc`` (by ``unc.model``).

    Raises
    ------
    PolyrobError
        ``unc.model`` is not a registered model.
    """
    try:
        return MODELS[unc.model]
    except KeyError:
        raise ArgumentError(
            f"unknown uncertainty model '{unc.model}' of the plant: registered are {', '.join(MODELS)}"
        ) from None
