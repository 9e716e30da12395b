"""What :func:`~polyrob.synthesis.mu_synthesis.musyn` is asked to do: MATLAB's ``musynOptions``, and the method.

:class:`MusynOptions` holds what every synthesis shares (stopping rules,
grids, the start, progress, the safety-net time limit) and the method, one
of two strategies:

:class:`FullOrder`
    The full-order D-K / D-G-K iteration and its scaling fits.
:class:`FixedStructure`
    A controller of a prescribed structure (``"tfN"``, ``"pid"``,
    ``"ss:N"``) searched by the fixed-structure D-G-K iteration, from a
    number of starts.

``musyn`` still takes the flat keywords of earlier versions (``structure``,
``starts``, ``d_order``, ...); :meth:`MusynOptions.build` sorts them into
the options and the method, refusing a method's option given to the other.

Examples
--------
>>> from polyrob.synthesis.options import FixedStructure, MusynOptions
>>> opts = MusynOptions.build(structure="pid", starts=2, max_iter=10)
>>> opts.method, opts.max_iter
(FixedStructure(structure='pid', starts=2, seed=0, init=None, tuning=None), 10)
>>> MusynOptions.build(opts, max_iter=3).method.structure
'pid'
>>> MusynOptions.build(structure="pid", d_order=(0, 1))
Traceback (most recent call last):
...
polyrob.errors.ArgumentError: options ['d_order'] apply to the full-order synthesis only, not to 'pid'
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace

from polyrob.errors import ArgumentError
from polyrob.synthesis.fixed.options import FixedStructureOptions

__all__ = ["MusynOptions", "FullOrder", "FixedStructure"]


@dataclass(frozen=True)
class FullOrder:
    """The full-order D-K / D-G-K iteration (:class:`~polyrob.synthesis.dk.iteration.DKIteration`).

    Attributes
    ----------
    patience : int, optional
        Iterations without progress before stopping (default 2).
    d_order, g_order : sequence of int, optional
        Candidate orders of the D and G fits (the lowest that fits is used;
        default ``0..4`` and ``0..2``, constant on large structures:
        :func:`~polyrob.synthesis.mu_synthesis.scaling_order_defaults`).
    fit_tol : float, optional
        Relative tolerance of the fitted bound (default 0.01).
    mu_bound, d_fit, hinf_step : strategy objects, optional
        Replace the iteration's μ bound, scaling fit and H∞ step.
    """

    patience: int | None = None
    d_order: tuple | None = None
    g_order: tuple | None = None
    fit_tol: float | None = None
    mu_bound: object = None
    d_fit: object = None
    hinf_step: object = None

    @property
    def structure(self) -> str:
        return "full"


@dataclass(frozen=True)
class FixedStructure:
    """A controller of a fixed structure (:func:`~polyrob.synthesis.fixed.synthesis.fixed_structure_musyn`).

    Attributes
    ----------
    structure : str or ControllerStructure
        ``"tfN"``, ``"pid"`` or ``"ss:N"``
        (:func:`~polyrob.synthesis.fixed.structures.controller_structure`).
    starts : int
        ``init`` (or an H2 design fitted to the structure), then random perturbations of it.
    seed : int
        Seed of the perturbations: same seed, same result.
    init : "paper", LTI, MusynResult, array or None
        Starting controller fitted to the structure (``"paper"``: the paper's ``K*``).
    tuning : FixedStructureOptions, optional
        The iteration's knobs (grids, K-step, certificate rounds).
    """

    structure: object = "tf3"
    starts: int = 5
    seed: int = 0
    init: object = None
    tuning: FixedStructureOptions | None = None


_FULL = frozenset(f.name for f in fields(FullOrder))
_FIXED = frozenset(f.name for f in fields(FixedStructure)) - {"structure"}
#: The flat keyword of earlier versions for :attr:`FixedStructure.tuning`.
_TUNING_KEYWORD = "options"


@dataclass(frozen=True)
class MusynOptions:
    """Options of :func:`~polyrob.synthesis.mu_synthesis.musyn` (MATLAB's ``musynOptions``).

    Attributes
    ----------
    method : FullOrder or FixedStructure
        The synthesis (default :class:`FullOrder`).
    mixed : bool, optional
        D-G-K with real blocks kept real; ``False``: every block complex
        (D-K).  Default: D-G-K when the block structure has real blocks.
    max_iter : int, optional
        Iterations (per start); default 20 (full order), 40 (fixed structure).
    tol : float, optional
        Relative progress below which an iteration counts as stalled.
    target : float, optional
        Stop once the grid peak μ is below it (MATLAB's ``TargetPerf``).
    omega : array_like, optional
        The iteration's grid (rad/s); default chosen from the plant.
    certify_omega : array_like, optional
        Grid of the final certificate (default the loop's own,
        :func:`polyrob.analysis.certificate.certify_loop`).
    initial_controller : LTI, "pid" or None
        Start from this controller (``"pid"``: the per-joint PID tuned to the weights).
    progress : bool or callable, optional
        One line per iteration (default only on a terminal).
    check_weights : bool
        Refuse weights that alone force μ > 1 (full order).
    time_limit : float, optional
        A safety net the user sets (default none): seconds of wall clock after
        which no new iteration or start begins; the result names the limit
        ("the time limit of N s you set").
    """

    method: FullOrder | FixedStructure = field(default_factory=FullOrder)
    mixed: bool | None = None
    max_iter: int | None = None
    tol: float | None = None
    target: float | None = None
    omega: object = None
    certify_omega: object = None
    initial_controller: object = None
    progress: object = None
    check_weights: bool = True
    time_limit: float | None = None

    @property
    def structure(self):
        """``"full"`` or the fixed structure."""
        return self.method.structure

    @classmethod
    def build(cls, options=None, *, default_method=None, **keywords) -> MusynOptions:
        """``options`` (or the defaults) with the flat ``keywords`` of earlier versions applied.

        ``structure="full"`` chooses :class:`FullOrder`, another structure
        :class:`FixedStructure`; ``patience``, ``d_order``, ... go to the
        full-order method, ``starts``, ``seed``, ``init`` and ``options`` (a
        :class:`FixedStructureOptions`) to the fixed structure.  A
        :class:`FixedStructureOptions` given as ``options`` is the fixed
        structure's tuning.

        Raises
        ------
        ArgumentError
            An unknown keyword, or a method's option given to the other method.
        """
        if isinstance(options, FixedStructureOptions):
            keywords = {_TUNING_KEYWORD: options, **keywords}
            options = None
        if options is not None and not isinstance(options, MusynOptions):
            raise ArgumentError(f"options must be a MusynOptions, got {type(options).__name__}")
        base = options or cls(method=default_method or FullOrder())
        if _TUNING_KEYWORD in keywords:
            keywords["tuning"] = keywords.pop(_TUNING_KEYWORD)
        common = {name: keywords.pop(name) for name in list(keywords) if name in _COMMON}
        method = base.method
        if "structure" in keywords:
            structure = keywords.pop("structure")
            if structure == "full":
                method = method if isinstance(method, FullOrder) else FullOrder()
            elif isinstance(method, FixedStructure):
                method = replace(method, structure=structure)
            else:
                method = FixedStructure(structure)
        unknown = sorted(set(keywords) - _FULL - _FIXED)
        if unknown:
            raise ArgumentError(f"unknown musyn options {unknown}")
        own = _FULL if isinstance(method, FullOrder) else _FIXED
        wrong = sorted(name for name in set(keywords) - own if keywords[name] is not None)
        if wrong and isinstance(method, FullOrder):
            raise ArgumentError(f"unexpected options for a full-order synthesis: {wrong}")
        if wrong:
            raise ArgumentError(f"options {wrong} apply to the full-order synthesis only, not to {method.structure!r}")
        keywords = {name: value for name, value in keywords.items() if name in own}
        return replace(base, method=replace(method, **keywords), **common)


_COMMON = frozenset(f.name for f in fields(MusynOptions)) - {"method"}
