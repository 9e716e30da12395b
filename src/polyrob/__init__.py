"""polyrob: robust controllers with a mathematical guarantee for serial robots.

The data flow is one way, in MATLAB's vocabulary: a robot
(:func:`load_robot`) and a :class:`Domain` give a :class:`PLDI`
(:func:`bound_pldi`: bounds of the Jacobians over the domain), the PLDI an
:class:`UncertainPlant` (:func:`uncertain_plant`), the plant with weights a
:class:`GeneralizedPlant` (:func:`generalized_plant`); :func:`musyn` gives a
controller with its structured-singular-value certificate,
:func:`reduce_controller` a smaller one, and :func:`mussv`,
:func:`mu_bounds`, :func:`robstab`, :func:`robperf` analyse a loop.
:func:`build_problem` runs the first three steps at once.

The names are imported on first use (PEP 562), so ``import polyrob`` and the
``polyrob`` command start fast; every name also stays importable from its
module (``polyrob.synthesis.dk.iteration.HinfStep``, ...).

Examples
--------
>>> import polyrob
>>> "musyn" in polyrob.__all__ and callable(polyrob.load_robot)
True
"""

from __future__ import annotations

import importlib
import logging

from polyrob import errors

__version__ = "0.1.0"

# the library reports progress on the "polyrob" logger; the CLI shows it on stderr
logging.getLogger("polyrob").addHandler(logging.NullHandler())

#: public name -> module that defines it
_LAZY = {
    "load_robot": "polyrob.model.robots",
    "available_robots": "polyrob.model.robots",
    "Robot": "polyrob.model.robots",
    "Manipulator": "polyrob.model.robots",
    "AnalyticRobot": "polyrob.model.analytic",
    "Domain": "polyrob.domains.torque_box",
    "PLDI": "polyrob.bounds.pldi",
    "bound_pldi": "polyrob.bounds.pldi",
    "UncertainPlant": "polyrob.plant.uncertainty",
    "uncertain_plant": "polyrob.plant.uncertainty",
    "GeneralizedPlant": "polyrob.plant.generalized",
    "generalized_plant": "polyrob.plant.generalized",
    "lft": "polyrob.plant.generalized",
    "closed_loop": "polyrob.plant.generalized",
    "nominal_closed_loop": "polyrob.plant.generalized",
    "paper_controller": "polyrob.plant.generalized",
    "makeweight": "polyrob.plant.weights",
    "paper_weights": "polyrob.plant.weights",
    "mussv": "polyrob.analysis.mu.bounds",
    "mu_bounds": "polyrob.analysis.mu.bounds",
    "certify_loop": "polyrob.analysis.certificate",
    "Certificate": "polyrob.analysis.certificate",
    "Status": "polyrob.analysis.certificate",
    "robstab": "polyrob.analysis.robust",
    "robperf": "polyrob.analysis.robust",
    "lpvnorm": "polyrob.analysis.lpv",
    "LpvNormResult": "polyrob.analysis.lpv",
    "musyn": "polyrob.synthesis",
    "MusynOptions": "polyrob.synthesis",
    "MusynResult": "polyrob.synthesis",
    "reduce_controller": "polyrob.synthesis",
    "load_controller": "polyrob.io.controller",
    "save_controller": "polyrob.io.controller",
    "Problem": "polyrob.pipeline.problem",
    "build_problem": "polyrob.pipeline.problem",
    "analyze_controller": "polyrob.pipeline.analysis",
}
#: modules reachable as attributes (``polyrob.weights.paper_weights``)
_SUBMODULES = {"weights": "polyrob.plant.weights"}

__all__ = [
    # the pipeline, in MATLAB's vocabulary
    "load_robot",
    "Domain",
    "bound_pldi",
    "uncertain_plant",
    "generalized_plant",
    "mussv",
    "mu_bounds",
    "certify_loop",
    "Certificate",
    "Status",
    "robstab",
    "robperf",
    "lpvnorm",
    "musyn",
    "MusynOptions",
    "reduce_controller",
    "load_controller",
    "save_controller",
    "build_problem",
    "analyze_controller",
    "makeweight",
    "paper_weights",
    "paper_controller",
    "available_robots",
    # the objects they return
    "Robot",
    "PLDI",
    "UncertainPlant",
    "GeneralizedPlant",
    "MusynResult",
    "LpvNormResult",
    "Problem",
    # errors
    *errors.__all__,
]


def __getattr__(name: str):
    if name in errors.__all__:  # the one error hierarchy: every class of it is public here
        value = getattr(errors, name)
    elif name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
    elif name in _SUBMODULES:
        value = importlib.import_module(_SUBMODULES[name])
    else:
        raise AttributeError(f"module 'polyrob' has no attribute {name!r}")
    globals()[name] = value  # the next access skips __getattr__
    return value


def __dir__():
    return sorted(set(globals()) | set(_LAZY) | set(_SUBMODULES) | set(errors.__all__))
