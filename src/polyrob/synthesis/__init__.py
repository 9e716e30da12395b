"""Controller synthesis: H∞, full-order D-K / D-G-K μ-synthesis, order reduction.

* :func:`hinfsyn` - H∞ synthesis with scaling, documented regularisation,
  own γ bisection around SLICOT SB10FD and an LMI fallback.
* :func:`musyn` - μ-synthesis (D-K for complex, D-G-K for mixed real/complex
  uncertainty) returning a :class:`MusynResult` with a certified μ; what it
  does is a :class:`MusynOptions` whose method is a :class:`FullOrder`
  iteration or a :class:`FixedStructure` (delegated to
  :mod:`polyrob.synthesis.fixed.synthesis`).
* :func:`max_bandwidth_scaling` - the largest scaling of the weights'
  bandwidths that still certifies μ < 1.
* :func:`reduce_controller` - smallest balanced-truncation order whose
  certified μ stays within a tolerance of the full-order one.
"""

from polyrob.analysis.norms import hinf_norm
from polyrob.synthesis.bandwidth import BandwidthScalingResult, max_bandwidth_scaling, scaled_hyperparameters
from polyrob.synthesis.dk.frequency import frequency_grid, performance_lower_bound
from polyrob.synthesis.dk.iteration import DKIteration
from polyrob.synthesis.dk.strategies import HinfStep, MuUpperBound
from polyrob.synthesis.fixed.options import FixedStructureOptions
from polyrob.synthesis.fixed.structures import controller_structure
from polyrob.synthesis.fixed.synthesis import fixed_structure_musyn
from polyrob.synthesis.hinf.synthesis import HinfResult, hinfsyn
from polyrob.synthesis.mu_synthesis import musyn
from polyrob.synthesis.options import FixedStructure, FullOrder, MusynOptions
from polyrob.synthesis.reduction import ReductionResult, reduce_controller
from polyrob.synthesis.result import MusynResult
from polyrob.synthesis.scalings.dfit import LogMagnitudeFit, SlicotMagnitudeFit

__all__ = [
    "MusynResult",
    "HinfResult",
    "hinfsyn",
    "hinf_norm",
    "musyn",
    "MusynOptions",
    "FullOrder",
    "FixedStructure",
    "DKIteration",
    "MuUpperBound",
    "HinfStep",
    "LogMagnitudeFit",
    "SlicotMagnitudeFit",
    "frequency_grid",
    "performance_lower_bound",
    "BandwidthScalingResult",
    "max_bandwidth_scaling",
    "scaled_hyperparameters",
    "ReductionResult",
    "reduce_controller",
    "FixedStructureOptions",
    "fixed_structure_musyn",
    "controller_structure",
]
