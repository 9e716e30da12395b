"""How well an uncertainty model fits the robot: coverage on fresh samples and size against the polytope.

* :func:`model_contains` — whether given Jacobians lie in a model's set
  (each model has its own exact membership test);
* :func:`coverage_fraction` — the fraction of fresh uniform points of the
  domain whose Jacobians the model contains (it must be 1.0); for an inner
  loop over a set, half of the points on the true robots the bounds were
  taken over and half on *fresh* true robots of the set, half of those at
  its vertices frozen at corners of the domain;
* :func:`volume_ratio` — the model's size over the PLDI polytope's, in the
  polytope's reduced coordinates: ``vol(model ∩ interval box) / vol(polytope)``
  estimated on the same uniform points of the interval box (the polytope
  and the box model lie inside the box; for the other models the part
  outside the box is not counted, see docs/uncertainty.md).  A model that is
  lower-dimensional (the ``lft`` model's ``B`` block is a curve) has ratio 0
  by this measure; :func:`det_b_range` gives a number that separates them;
* :func:`input_definiteness` — how many of the model's members have an input
  matrix ``B_low`` that is not positive definite, which the robot's
  ``M(q)^{-1}`` always is.
"""

from __future__ import annotations

import numpy as np

from polyrob.errors import ArgumentError
from polyrob.plant.lftplant import UncertainPlant
from polyrob.plant.models import MODELS

__all__ = ["model_contains", "coverage_fraction", "volume_ratio", "det_b_range", "input_definiteness", "FRESH_POINTS"]

#: Points per fresh true robot of the coverage check (its robots are drawn anew: the model must hold them too).
FRESH_POINTS = 10


def model_contains(unc: UncertainPlant, A, B) -> np.ndarray:
    """Whether Jacobians ``A`` (n, 2m, 2m), ``B`` (n, 2m, m) lie in the model's set (n,) bool.

    The test of the model that built ``unc`` (:func:`polyrob.plant.models.model_of`).
    """
    if unc.model not in MODELS:
        raise ArgumentError(f"no membership test for the model '{unc.model}'")
    return MODELS[unc.model].contains(unc, A, B)


def coverage_fraction(unc: UncertainPlant, robot, domain, n: int = 2000, *, seed: int = 12345) -> float:
    """Fraction of ``n`` fresh points of ``domain`` whose Jacobians the model contains.

    The points are drawn with a seed of their own, not the PLDI's design.
    For an inner loop (:mod:`polyrob.model.inner`) the points are shared
    among its true robots (``robot.variants()``, each with the inputs of its
    own inverse dynamics on a task domain), as the bounds were taken over
    them.  When its set has more than one robot (a model error, a payload
    range, a robot-uncertainty set), half of the ``n`` points go instead to
    true robots drawn anew from the set (``robot.drawn``), :data:`FRESH_POINTS`
    each: half of those robots inside the set at uniform points, half at its
    vertices (:data:`~polyrob.uncertainty_set.draw.EXTREME_SHARE`) at random
    corners of the domain, where a frozen Jacobian is most often extreme.
    """
    from polyrob.bounds.search import Problem
    from polyrob.uncertainty_set.draw import EXTREME_SHARE, at_vertices

    problem = Problem(robot, domain)
    fresh = len(problem.variants) > 1 and callable(getattr(robot, "drawn", None)) and int(n) >= 2 * FRESH_POINTS
    listed = int(n) - int(n) // 2 if fresh else int(n)
    share = max(1, listed // len(problem.variants))
    inside = []
    for i, (variant, dom) in enumerate(zip(problem.variants, problem.domains)):
        q, qdot, u = dom.sample(share, method="uniform", seed=[seed, i] if i else seed)
        A, B = variant.jacobians_batch(q, qdot, u)
        inside.append(model_contains(unc, A, B))
    if fresh:
        rng = np.random.default_rng([seed, 41])
        robots = (int(n) // 2) // FRESH_POINTS
        at_inside = robots - at_vertices(robots, EXTREME_SHARE)
        m = robot.m
        for k in range(robots):
            true = robot.drawn(rng, extreme=k >= at_inside)
            (dom,) = Problem(true, domain).domains
            if k < at_inside:
                q, qdot, u = dom.sample(FRESH_POINTS, method="uniform", seed=int(rng.integers(2**31)))
            else:
                lo, hi = np.asarray(domain.lower, float), np.asarray(domain.upper, float)
                x = np.where(rng.integers(0, 2, size=(FRESH_POINTS, len(lo))) == 1, hi, lo)
                q, qdot, w = x[:, :m], x[:, m : 2 * m], x[:, 2 * m :]
                u = dom.inputs(q, qdot, w)
            A, B = true.jacobians_batch(q, qdot, u)
            inside.append(model_contains(unc, A, B))
    return float(np.concatenate(inside).mean())


def _box_points(pldi, n: int, rng):
    """Uniform points of the interval box in the polytope's reduced coordinates, and their entries."""
    from polyrob.bounds.polytope import bounding_box, constraining_rows

    poly = pldi.polytope
    lo, hi = np.asarray(pldi.lower, float), np.asarray(pldi.upper, float)
    k = len(lo)
    normals = poly.normals[: 2 * k]
    G = normals @ poly.basis
    g = poly.offsets[: 2 * k] - normals @ poly.centre
    keep = constraining_rows(G, normals, hi - lo)  # as the polytope's own bounding box: the same LPs
    r = poly.basis.shape[1]
    box_z = bounding_box(G[keep], g[keep], poly.offsets)
    z = box_z[:, 0] + rng.random((n, r)) * (box_z[:, 1] - box_z[:, 0])
    p = poly.centre + z @ poly.basis.T
    in_box = np.all((p >= lo - 1e-12 * (1 + abs(lo))) & (p <= hi + 1e-12 * (1 + abs(hi))), axis=1)
    return p[in_box]


def volume_ratio(unc: UncertainPlant, pldi, n: int = 100_000, *, seed: int = 0) -> dict:
    """``vol(model ∩ box) / vol(polytope)`` and ``vol(box) / vol(polytope)`` by Monte Carlo.

    Returns a dict with ``model_over_polytope``, ``box_over_polytope``,
    ``box_points`` and ``polytope_hits`` (the sampling behind them).
    """
    rng = np.random.default_rng(seed)
    p = _box_points(pldi, n, rng)
    in_poly = pldi.polytope.contains(p)
    m = pldi.m
    A = np.repeat(np.asarray(unc.A_mid, float)[None], len(p), axis=0)
    B = np.repeat(np.asarray(unc.B_mid, float)[None], len(p), axis=0)
    for j, (mat, r, c) in enumerate(np.asarray(pldi.entry_index, int).reshape(-1, 3)):
        (A if mat == 0 else B)[:, r, c] = p[:, j]
    # the constant entries are the PLDI's
    A[:, :m] = np.asarray(pldi.A0, float)[:m]
    in_model = model_contains(unc, A, B) if len(p) else np.zeros(0, bool)
    hits = int(in_poly.sum())
    return {
        "model_over_polytope": float(in_model.sum() / hits) if hits else float("nan"),
        "box_over_polytope": float(len(p) / hits) if hits else float("inf"),
        "box_points": int(len(p)),
        "polytope_hits": hits,
    }


def det_b_range(unc: UncertainPlant, n: int = 4000, *, seed: int = 0) -> tuple[float, float]:
    """Range of ``det B_low`` over random members of the model, relative to the centre's.

    The paper's box lets ``det B`` fall far below anything the arm reaches
    (12 % of its midpoint on ``paper_2r``); a tight model keeps it in range.
    """
    m = unc.m
    deltas = unc.delta_samples(n, kind="uniform", seed=seed)
    corners = unc.delta_samples(min(n, 2**unc.n_params), kind="corners", seed=seed + 1)
    res = unc.residual_samples(2 * n, seed=seed + 2)
    d0 = np.linalg.det(unc.B_mid[m:])
    vals = []
    for d, r in zip(np.vstack([deltas, corners]), res):
        vals.append(np.linalg.det(unc.matrices_at(d, residual=r if r else None)[1][m:]))
    vals = np.real(np.array(vals)) / d0
    return float(vals.min()), float(vals.max())


def input_definiteness(unc: UncertainPlant, n: int = 1000, *, seed: int = 0) -> dict:
    """How often the model's input matrix ``B_low`` loses the definiteness of the robot's ``M(q)^{-1}``.

    The robot's ``B_low = M(q)^{-1}`` is symmetric positive definite at every
    configuration.  A model that contains members whose ``B_low`` (its
    symmetric part) has a zero or negative eigenvalue asks a robust
    controller to cope with an input direction that does nothing or acts in
    reverse (ur5's ``axes`` model: two thirds of its members, and μ in the
    hundreds for every controller polyrob found on it, see docs/uncertainty.md).
    Members are sampled uniformly in the real parameters, with the full
    blocks at zero (the residual only adds to the spread).

    Returns
    -------
    dict
        ``fraction`` of members not positive definite, ``least`` eigenvalue
        seen over them, ``centre`` least eigenvalue of the model's centre,
        ``samples``.

    Examples
    --------
    >>> import polyrob
    >>> from polyrob.plant.coverage import input_definiteness
    >>> from polyrob.plant.uncertainty import uncertain_plant
    >>> robot = polyrob.load_robot("paper_2r")
    >>> pldi = polyrob.bound_pldi(robot, polyrob.Domain.from_robot(robot, "paper"), samples=256, progress=False)
    >>> input_definiteness(uncertain_plant(pldi, model="lft"), 200)["fraction"]
    0.0
    """
    m = unc.m
    deltas = unc.delta_samples(n, kind="uniform", seed=seed)
    least = []
    for d in deltas:
        B = unc.matrices_at(d)[1][m:]
        least.append(np.linalg.eigvalsh(0.5 * (B + B.T)).min())
    least = np.array(least)
    centre = np.linalg.eigvalsh(0.5 * (unc.B_mid[m:] + unc.B_mid[m:].T)).min()
    return {
        "fraction": float(np.mean(least <= 0.0)),
        "least": float(least.min()),
        "centre": float(centre),
        "samples": int(n),
    }
