"""The pipeline as library functions: what the CLI, ``run`` and the benchmarks call.

:func:`build_problem` (robot, domain, weights -> PLDI -> uncertain plant ->
generalized plant), :func:`design_controller` (μ-synthesis, reduction),
:func:`analyze_controller` (μ analysis and the certificate's verdict), and
:func:`check_controller_problem` (is a controller file made for this problem?) and
:func:`friction_statement` (what Coulomb friction does to a certified loop).
"""

from polyrob.pipeline.analysis import ControllerAnalysis, analyze_controller, controller_order, frequency_grid
from polyrob.pipeline.design import Design, design_controller, design_max_bandwidth, reduce_design, synthesis_options
from polyrob.pipeline.friction import friction_statement
from polyrob.pipeline.matching import check_controller_problem, controller_differences
from polyrob.pipeline.problem import (
    UNCERTAINTY_MODELS,
    WEIGHT_KEYS,
    Problem,
    build_problem,
    default_hyperparameters,
    make_uncertain_plant,
)
from polyrob.pipeline.reports import format_matrix, pldi_report, robot_report

__all__ = [
    "UNCERTAINTY_MODELS",
    "WEIGHT_KEYS",
    "Problem",
    "build_problem",
    "default_hyperparameters",
    "make_uncertain_plant",
    "ControllerAnalysis",
    "analyze_controller",
    "controller_order",
    "frequency_grid",
    "Design",
    "design_controller",
    "reduce_design",
    "design_max_bandwidth",
    "synthesis_options",
    "friction_statement",
    "check_controller_problem",
    "controller_differences",
    "format_matrix",
    "pldi_report",
    "robot_report",
]
