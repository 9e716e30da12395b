"""How tight proved factor ranges are: the ratio of proved to sampled widths, on the entries where it means something.

A ratio ``proved width / sampled width`` is ill-defined on entries whose
true width is (nearly) zero: constant entries, structural zeros, entries
that do not depend on the box's variables.  An enclosure's over-estimation
there is an absolute amount (rounding margins, the dependency of the ball
arithmetic), and dividing it by a sampled width of 1e-6 makes a ratio of
thousands out of an excess the model never feels.  So:

* an entry is *significant* when its sampled width is at least ``floor``
  times its factor's scale (the largest magnitude sampled in any entry of
  that factor); the ratio is reported on those (max and median);
* on the others the excess ``proved width - sampled width`` is reported
  relative to the factor's scale (max).

The sampled width is attained (a lower bound of the true width), so both
figures are upper bounds of the true over-estimation, up to sampling.
``outside`` counts the entries whose sampled values leave the proved
interval by more than :data:`OUTSIDE_TOL` of the factor's scale: with
values computed apart from the proof (Pinocchio's floats), a check of the
proof itself, which must read 0.

Examples
--------
>>> import numpy as np
>>> lo, hi = np.array([[[0.0, -1e-3]]]), np.array([[[1.1, 1e-3]]])
>>> r = width_ratios(lo, hi, np.array([[[0.0, -1e-7]]]), np.array([[[1.0, 1e-7]]]))
>>> r["max"], r["entries"], r["excess_max"], r["outside"]
(1.1, 1, 0.0019998, 0)
>>> width_ratios(lo, hi, np.array([[[0.0, -1e-7]]]), np.array([[[1.2, 1e-7]]]))["outside"]  # 1.2 > 1.1
1
"""

from __future__ import annotations

import numpy as np

__all__ = ["width_ratios", "closing_tolerance", "FLOOR"]

#: An entry whose sampled width is below this fraction of its factor's scale is reported by its excess, not its ratio.
FLOOR = 1e-3
#: A sampled value beyond a proved bound by more than this fraction of its factor's scale is outside (float samples
#: carry their own rounding, about 1e-13 of the scale).
OUTSIDE_TOL = 1e-9


def width_ratios(lower, upper, sampled_lower, sampled_upper, floor: float = FLOOR) -> dict:
    """Ratios of proved to sampled widths of factor entries ``(F, ...)``, and the excess on the thin entries.

    Returns
    -------
    dict
        ``max``, ``median`` (ratios on the significant entries, ``nan`` if
        none), ``entries`` (how many), ``floor``, ``excess_max`` (largest
        ``(proved - sampled width) / scale`` on the other entries, 0 if none),
        ``thin_entries`` (how many) and ``outside`` (entries whose sampled
        values leave the proved interval: 0 for a proof that holds them).
    """
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    s_lo, s_hi = np.asarray(sampled_lower, float), np.asarray(sampled_upper, float)
    axes = tuple(range(1, s_lo.ndim))
    scale = np.maximum(np.abs(s_lo), np.abs(s_hi)).max(axis=axes, keepdims=True)
    width, sampled = upper - lower, s_hi - s_lo
    significant = sampled >= floor * scale
    ratio = width[significant] / sampled[significant]
    excess = ((width - sampled) / np.where(scale > 0, scale, 1.0))[~significant]
    return {
        "max": float(ratio.max()) if ratio.size else float("nan"),
        "median": float(np.median(ratio)) if ratio.size else float("nan"),
        "entries": int(significant.sum()),
        "floor": floor,
        "excess_max": round(float(excess.max()), 12) if excess.size else 0.0,
        "thin_entries": int((~significant).sum()),
        "outside": int(((s_lo < lower - OUTSIDE_TOL * scale) | (s_hi > upper + OUTSIDE_TOL * scale)).sum()),
    }


def closing_tolerance(attained_lower, attained_upper, rel_tol: float, floor: float = FLOOR) -> np.ndarray:
    """How far past the attained values a proved side may stay and count as closed, per entry ``(F, ...)``.

    ``rel_tol`` of the entry's attained width, or of ``floor`` times its
    factor's scale for a thinner entry (judged by its excess against that
    scale, as :func:`width_ratios` reports it); ``1e-8`` of the scale on top,
    far above the propagated rounding margins (about 1e-10 of a factor's
    largest entry).  The branch and bound of
    :func:`~polyrob.bounds.certified.factors.prove_factor_ranges` closes its
    sides with it.

    Examples
    --------
    >>> import numpy as np
    >>> closing_tolerance(np.array([[0.0, -1e-6]]), np.array([[2.0, 1e-6]]), 0.04).round(10).tolist()
    [[0.08000002, 8.002e-05]]
    """
    lo, hi = np.asarray(attained_lower, float), np.asarray(attained_upper, float)
    axes = tuple(range(1, lo.ndim))
    scale = np.maximum(np.maximum(np.abs(lo), np.abs(hi)).max(axis=axes, keepdims=True), 1e-300)
    return rel_tol * np.maximum(hi - lo, floor * scale) + 1e-8 * scale
