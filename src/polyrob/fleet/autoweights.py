"""Default weights for any serial robot: the paper's shape, stretched over the joints, levelled by the domain.

The paper gives W_S / W_T for its two joints only
(:data:`polyrob.plant.weights.PAPER_HYPERPARAMETERS`: joint 1 faster than
joint 2).  For ``m`` joints, :func:`automatic_hyperparameters`

* keeps that shape along the chain: each hyperparameter goes geometrically
  from the paper's joint-1 value at the base to its joint-2 value at the
  last joint (so ``m = 2`` gives the paper's values exactly, and one joint
  gets joint 1's);
* levels the bandwidths ``omega_b`` and ``omega_bt`` by the domain: a
  reference swinging over a joint's half range ``h_q`` at bandwidth ``w``
  needs a velocity of about ``w h_q``, and the paper's weights fit its
  domain's velocity-to-range ratio ``h_qdot / h_q``.  The level factor is
  the geometric mean over the joints of that ratio divided by the same
  mean on the paper's domain (``paper_2r --domain paper``), clipped to
  ``[1/8, 8]``; it is 1 on the paper's domain.

The result is a starting point, not a tuned design: the bandwidth search
(:func:`polyrob.pipeline.design_max_bandwidth`) then scales both bandwidths
to the largest factor with certified μ < 1.

Examples
--------
>>> h = automatic_hyperparameters(2)
>>> h["omega_b"], h["M_s"]
((0.5, 0.1), (2.0, 3.0))
>>> [round(w, 3) for w in automatic_hyperparameters(3)["omega_b"]]
[0.5, 0.224, 0.1]
"""

from __future__ import annotations

import math

from polyrob.errors import ArgumentError

__all__ = ["automatic_hyperparameters", "domain_level", "PAPER_DOMAIN_RATIO", "LEVEL_LIMITS"]

#: Geometric mean over the joints of ``h_qdot / h_q`` on the paper's domain (|qdot| <= 3.9564, 9.9561; q in +-pi).
PAPER_DOMAIN_RATIO = math.sqrt(3.9564 * 9.9561) / math.pi
#: The domain level factor is clipped to this range (a degenerate domain must not ask for absurd bandwidths).
LEVEL_LIMITS = (0.125, 8.0)


def _half_width(interval) -> float:
    lo, hi = (float(v) for v in interval)
    return 0.5 * (hi - lo)


def domain_level(domain) -> float:
    """The bandwidth level factor of ``domain`` (1 on the paper's; see the module text).

    Joints with a zero position or velocity range are left out of the mean;
    without any joint left the factor is 1.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> d = SimpleNamespace(to_dict=lambda: {"q": {"a": [-math.pi, math.pi], "b": [-math.pi, math.pi]},
    ...                                       "qdot": {"a": [-3.9564, 3.9564], "b": [-9.9561, 9.9561]}})
    >>> round(domain_level(d), 12)
    1.0
    """
    d = domain.to_dict()
    logs = []
    for joint, q in d["q"].items():
        hq, hv = _half_width(q), _half_width(d["qdot"][joint])
        if hq > 0 and hv > 0:
            logs.append(math.log(hv / hq))
    if not logs:
        return 1.0
    level = math.exp(sum(logs) / len(logs)) / PAPER_DOMAIN_RATIO
    return min(max(level, LEVEL_LIMITS[0]), LEVEL_LIMITS[1])


def automatic_hyperparameters(m: int, domain=None, overrides: dict | None = None) -> dict:
    """W_S / W_T hyperparameters for ``m`` joints over ``domain`` (the paper's shape).

    Parameters
    ----------
    m : int
        Number of actuated joints (>= 1).
    domain : Domain, optional
        Levels the bandwidths (:func:`domain_level`); default: level 1.
    overrides : dict, optional
        ``key -> sequence`` of 1 or ``m`` values, applied after (as in
        :func:`polyrob.pipeline.default_hyperparameters`; not levelled).

    Returns
    -------
    dict
        ``key -> tuple`` of ``m`` floats, keys of :data:`polyrob.pipeline.WEIGHT_KEYS`.
    """
    from polyrob.pipeline.problem import default_hyperparameters
    from polyrob.plant.weights import PAPER_HYPERPARAMETERS

    if int(m) < 1:
        raise ArgumentError(f"a robot needs at least one joint, got m = {m}")
    m = int(m)
    level = 1.0 if domain is None else domain_level(domain)
    shaped = {}
    for key, paper in PAPER_HYPERPARAMETERS.items():
        first, last = float(paper[0]), float(paper[-1])
        # ends exact (m = 2 is the paper's to the last bit), geometric in between
        vals = [first] + [first * (last / first) ** (j / (m - 1)) for j in range(1, m - 1)] + [last]
        vals = vals[:m]
        if key in ("omega_b", "omega_bt"):
            vals = [v * level for v in vals]
        shaped[key] = vals
    # the user's overrides replace the shaped values as given
    shaped.update({k: list(v) for k, v in (overrides or {}).items()})
    return default_hyperparameters(m, shaped)
