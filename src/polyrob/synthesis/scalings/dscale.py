"""D and G scalings for D-K / D-G-K iteration: frequency data, rational fits, scaled plants.

The D-step of μ-synthesis gives, at each frequency of a grid, the scalings
of the μ upper bound of the closed loop ``N = Fl(P, K)`` (see
:mod:`polyrob.analysis.mu.bounds`): ``D(ω) > 0`` commuting with ``Δ`` and, for real blocks,
``G(ω) = G(ω)^H`` with

.. math:: N^H D^2 N + j(G N - N^H G) - \\beta^2 D^2 \\preceq 0 .

The K-step needs them as stable rational filters.  This module

* extracts one scalar ``d_i(ω)`` (and ``g_i(ω)`` for real scalars) per block,
  normalised so that the last block (the performance block) has ``d = 1``
  (:func:`scaling_data`);
* fits ``d_i`` with a stable, minimum-phase, biproper filter of bounded
  order by a weighted least-squares fit of the **log-magnitude** over a
  second-order-section parametrisation (:func:`fit_magnitude`), realised in a
  **balanced** form (canonical forms of these filters reach entries ~1e10);
* for real scalars, fits a stable filter ``F_i`` that realises the G scaling
  (:func:`fit_g`) and builds the transformed plant of the D-G-K K-step
  (:func:`scaled_plant`).

How the G scaling enters the K-step (the method, and why)
---------------------------------------------------------
For a real scalar block with scalings ``p = d^2`` and ``g`` at level ``β``,
the 2x2 multiplier ``Π = [[p, -j g/β], [j g/β, -p]]`` on ``(y_i, x_i)`` (the
block's output/input of ``N/β``) certifies ``μ ≤ β``.  Young's D-G-K
(P. M. Young, "Controller design with real parametric uncertainty", Int. J.
Control 65(3), 1996) writes the test as
``σ̄((D N D^{-1}/β - jG̃)(I + G̃^2)^{-1/2}) ≤ 1``; its term ``jG̃(ω)`` is purely
imaginary at every frequency, and no stable real-rational filter has a
purely imaginary frequency response, so it cannot be fitted as it stands.
We use instead the J-spectral factorisation ``Π = Ψ^* diag(1, -1) Ψ`` with
the real-rational factor

.. math:: Ψ = d \\begin{pmatrix} 1 & F \\\\ F & 1 \\end{pmatrix},\\qquad
          p = |d|^2 (1 - |F|^2),\\quad g/β = -2 |d|^2 \\operatorname{Im} F,

where ``F`` is any stable filter with ``‖F‖∞ < 1``: the freedom in
``Re F`` is what makes ``F`` realisable.  The certificate then reads
``‖T‖ ≤ 1`` for the Möbius-transformed loop

.. math:: T = D\\,(N/β + F)(I + F N/β)^{-1} D^{-1},

a linear-fractional function of ``N`` and hence of ``K``: the K-step is a
standard H∞ problem for a new generalized plant (:func:`scaled_plant`).
This is the multiplier factorisation used for IQC synthesis (J. Veenman,
C. W. Scherer, "IQC-synthesis with general dynamic multipliers", Int. J.
Robust Nonlinear Control 24(17), 2014), specialised to Young's D-G
scalings.  With ``F = 0`` it is the classical D-K step ``D N D^{-1}``.

Examples
--------
>>> import numpy as np
>>> from polyrob.synthesis.scalings.dscale import fit_magnitude
>>> w = np.logspace(-2, 2, 50)
>>> mag = np.abs((1j * w + 1) / (1j * w + 10))          # a first-order scaling
>>> fit = fit_magnitude(w, mag, order=1)
>>> fit.order, bool(fit.error < 1e-6)
(1, True)
>>> sorted(np.round(-fit.poles.real, 4).tolist()), sorted(np.round(-fit.zeros.real, 4).tolist())
([10.0], [1.0])
"""

from __future__ import annotations

from polyrob.synthesis.balanced import balanced_realization
from polyrob.synthesis.dk.musweep import MuSweep
from polyrob.synthesis.scalings.data import BlockScaling, ScalingData, Scalings, scaling_data
from polyrob.synthesis.scalings.dfit import LogMagnitudeFit, SlicotMagnitudeFit
from polyrob.synthesis.scalings.gfit import GFit, fit_g
from polyrob.synthesis.scalings.magfit import MagnitudeFit, fit_magnitude
from polyrob.synthesis.scalings.scaled_plant import scaled_plant

__all__ = [
    "MagnitudeFit",
    "GFit",
    "BlockScaling",
    "Scalings",
    "ScalingData",
    "scaling_data",
    "fit_magnitude",
    "fit_g",
    "LogMagnitudeFit",
    "SlicotMagnitudeFit",
    "scaled_plant",
    "balanced_realization",
    "MuSweep",
]
