"""The μ sweep a certificate rests on: the loop's own frequency grid, its precision, and the words for it.

:func:`polyrob.analysis.certificate.certify_loop` closes the loop and decides;
the sweep itself is here, so that every caller certifies one controller on
the same grid (:data:`POINTS_PER_DECADE`, thinned where the response is flat,
:data:`FLAT_RTOL`) and in enough precision (:data:`RESPONSE_BITS`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["sweep_loop", "grid_words", "POINTS_PER_DECADE", "FLAT_RTOL", "RESPONSE_BITS", "RESPONSE_TOL"]

#: Density of the certificate's default grid (log-spaced, plus the loop's natural frequencies, refined
#: around the peak).  The check between the grid points makes the density a matter of tightness and
#: time, not of soundness: a peak between two points is found there (measured on the paper's K* loop:
#: 12 per decade gives the same peak as 40, in 19 s instead of 62 s).
POINTS_PER_DECADE = 12
#: Where the loop's response has settled at either end of that grid (every entry within this fraction of
#: its largest magnitude), one point per decade is kept (:func:`~polyrob.analysis.mu.frequency.thin_flat_ends`):
#: a PID's near-cancelled integrator pole stretches the grid over decades where nothing happens.
FLAT_RTOL = 1e-4

#: Extended precision of the response check, and the relative error above which it is used for the whole sweep.
RESPONSE_BITS, RESPONSE_TOL = 212, 1e-6


def sweep_loop(M, blk, omega=None, **mu_options):
    """μ of ``M`` against ``blk`` on ``omega`` (default: the loop's own grid); returns ``(mu, response_bits)``.

    ω = 0 is added for real blocks (real μ is discontinuous there);
    ``response_bits`` is the precision the responses needed (``None``: double).
    ``mu_options`` go to :func:`polyrob.analysis.mu.bounds.mu_bounds`.
    """
    from polyrob.analysis.mu.blocks import as_block_structure
    from polyrob.analysis.mu.bounds import mu_bounds
    from polyrob.analysis.mu.frequency import default_grid, needs_extended_precision, thin_flat_ends

    st = as_block_structure(blk)
    if omega is None:
        w = thin_flat_ends(M, default_grid(M, per_decade=POINTS_PER_DECADE), FLAT_RTOL)
    else:
        w = np.asarray(omega, dtype=float).ravel()
    if st.has_real:
        w = np.union1d(w, [0.0])
    # double-precision responses of a badly conditioned realisation can be wrong in
    # every digit: a few frequencies are checked in 212-bit arithmetic, and the whole
    # sweep is evaluated there when double precision is off by more than 1e-6
    if "response_bits" not in mu_options and needs_extended_precision(M, w, RESPONSE_BITS, RESPONSE_TOL):
        mu_options["response_bits"] = RESPONSE_BITS
    mu_options.setdefault("progress", False)
    return mu_bounds(M, st, w, **mu_options), mu_options.get("response_bits")


def grid_words(omega) -> str:
    """``a grid of N frequencies from LO to HI rad/s (and at 0)``: what a sweep's frequencies cover."""
    w = np.asarray(omega, float)
    pos = w[w > 0]
    zero = " and at 0" if np.any(w == 0) else ""
    return (
        f"a grid of {w.size} frequencies from {pos.min():.3g} to {pos.max():.3g} rad/s{zero}"
        if pos.size
        else "the grid"
    )
