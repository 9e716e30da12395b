"""What :func:`~polyrob.bounds.pldi.bound_pldi` is asked to do: the search's effort, the checks, the enclosure.

:class:`SearchEffort` is how hard the extreme search works (the sampled
design, the screens, the local searches, the verification rounds: what
:func:`~polyrob.bounds.supports.support_values` runs); :class:`BoundOptions`
holds it with the rest: the nominal pair, the coverage check, whether the
intervals are proved (``certify``), the worker processes.  ``bound_pldi``
also takes every field as a flat keyword (:meth:`BoundOptions.build`).

Examples
--------
>>> from polyrob.bounds.options import BoundOptions
>>> opts = BoundOptions.build(samples=256, coverage=0)
>>> opts.search.samples, opts.coverage, opts.search.verify_rounds
(256, 0, 3)
>>> BoundOptions.build(samples=0)
Traceback (most recent call last):
...
polyrob.errors.ArgumentError: samples must be >= 1, got 0
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace

import numpy as np

from polyrob.errors import ArgumentError

__all__ = ["BoundOptions", "SearchEffort"]


def _check_count(name: str, value, least: int) -> None:
    """A sample count is a whole number, at least ``least`` (``None``: the default)."""
    if value is None:
        return
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ArgumentError(f"{name} must be a whole number, got {value!r}")
    if value < least:
        raise ArgumentError(f"{name} must be >= {least}, got {value}")


@dataclass(frozen=True)
class SearchEffort:
    """How hard the extreme search of the PLDI works.

    Attributes
    ----------
    samples : int, optional
        Sobol' positions (rounded up to a power of two); default grows with
        the number of positions that matter (512 per dimension, at most 8192).
    refine : bool
        Refine every extreme by local search.
    verify_rounds : int
        After refining, up to this many fresh designs (another scramble of the
        positions) are searched; support values they beat are refined again.
    starts_per_direction : int
        Local searches per direction (and per beaten direction in each
        verification round) from the highest peaks of the sampled landscape.
    screen : int, optional
        Random points of the domain screened for more starts (0 to skip):
        once uniformly, once around the witnesses found; default 65,536 per
        position that matters, at most 524,288.
    screen_starts : int
        Starts per direction each screen gives.
    seed : int
    """

    samples: int | None = None
    refine: bool = True
    verify_rounds: int = 3
    starts_per_direction: int = 3
    screen: int | None = None
    screen_starts: int = 4
    seed: int = 0

    def __post_init__(self):
        for name, least in (("samples", 1), ("starts_per_direction", 1), ("verify_rounds", 0)):
            _check_count(name, getattr(self, name), least)
        for name in ("screen", "screen_starts"):
            _check_count(name, getattr(self, name), 0)

    def sized(self, active_positions: int) -> SearchEffort:
        """The effort with its defaults sized to the number of positions the dynamics depend on."""
        samples = self.samples
        if samples is None:
            samples = int(min(8192, max(256, 512 * active_positions)))
        screen = self.screen
        if screen is None:
            screen = int(min(2**19, 2**16 * active_positions))
        return replace(self, samples=samples, screen=screen)


@dataclass(frozen=True)
class BoundOptions:
    """Options of :func:`~polyrob.bounds.pldi.bound_pldi`.

    Attributes
    ----------
    search : SearchEffort
    nominal : "equilibrium", "midpoint" or dict
        ``(A0, B0)`` at ``q = 0`` (clipped into the domain; a task domain's
        reference pose), ``qdot = 0`` and the torque that holds it
        (``u = g(q)``), at the interval midpoints, or at a given
        ``{"q", "qdot", "u"}``.
    coverage : int
        Fresh random points for the coverage check (0 to skip).
    describe_polytope : bool
        The polytope's vertices and volume ratio (LPs, sampling); ``False``
        keeps its half-spaces alone (an uncertainty model's factor loops).
    certify : bool
        Replace the intervals by a guaranteed enclosure (interval arithmetic).
    certify_options : dict, optional
        Keyword arguments of
        :func:`~polyrob.bounds.certified.enclosure.certified_jacobian_bounds`:
        ``rel_tol`` (default here 1e-5), ``max_boxes`` (a count of work),
        ``time_limit`` (s, a safety net the caller sets; default none),
        ``max_joints`` (default 3); an arm's factor proof also takes
        ``checkpoint_dir`` (where it keeps its state and finished proofs,
        default :func:`~polyrob.io.paths.cache_dir` ``("proofs")``; ``None``
        keeps nothing) and ``partial`` (default ``True``: at ``max_boxes``, the
        ranges proved by then, wider than its tolerance, their fraction of the
        refinement done and tightness in ``info["certify"]``; ``False`` gives up
        there).
    workers : int, optional
        Worker processes (spawned; ``1`` runs everything in this process).
        Default: one for robots whose dynamics depend on few positions, else
        every available core.
    progress : bool, optional
        Progress bars (default: when stderr is a terminal).
    """

    search: SearchEffort = field(default_factory=SearchEffort)
    nominal: object = "equilibrium"
    coverage: int = 10_000
    describe_polytope: bool = True
    certify: bool = False
    certify_options: dict | None = None
    workers: int | None = None
    progress: bool | None = None

    def __post_init__(self):
        _check_count("coverage", self.coverage, 0)
        _check_count("workers", self.workers, 1)

    @property
    def seed(self) -> int:
        return self.search.seed

    @classmethod
    def build(cls, options: BoundOptions | None = None, **keywords) -> BoundOptions:
        """``options`` (or the defaults) with flat keywords applied: :class:`SearchEffort`'s fields go to ``search``.

        Raises
        ------
        ArgumentError
            An unknown keyword or a bad count.
        """
        if options is not None and not isinstance(options, BoundOptions):
            raise ArgumentError(f"options must be a BoundOptions, got {type(options).__name__}")
        base = options or cls()
        effort = {name: keywords.pop(name) for name in list(keywords) if name in _SEARCH}
        unknown = sorted(set(keywords) - _OWN)
        if unknown:
            raise ArgumentError(f"unknown bound_pldi options {unknown}")
        return replace(base, search=replace(base.search, **effort), **keywords)


_SEARCH = frozenset(f.name for f in fields(SearchEffort))
_OWN = frozenset(f.name for f in fields(BoundOptions)) - {"search"}
