"""polyrob: robust controllers with a mathematical guarantee for serial robots.

The data flow is one way: a robot (:func:`load_robot`) and a :class:`Domain`
give a PLDI (bounds of the Jacobians over the domain), the PLDI an uncertain
plant, the plant with weights a generalized plant, and that a controller with
its structured-singular-value certificate.
"""

from polyrob.errors import (
    BoundsError,
    CertificationError,
    DomainError,
    PolyrobError,
    RobotError,
    SolverError,
    SynthesisError,
)
from polyrob.model.robots import Manipulator, Robot, available_robots, load_robot
from polyrob.model.analytic import AnalyticRobot
from polyrob.bounds.domain import Domain
from polyrob.plant import weights
from polyrob.bounds.pldi import PLDI, bound_pldi
from polyrob.plant.uncertainty import UncertainPlant, uncertain_plant
from polyrob.plant.generalized import GeneralizedPlant, closed_loop, generalized_plant, lft, nominal_closed_loop, paper_controller

__version__ = "0.1.0"

__all__ = [
    "AnalyticRobot",
    "BoundsError",
    "CertificationError",
    "Domain",
    "DomainError",
    "Manipulator",
    "PolyrobError",
    "Robot",
    "RobotError",
    "SolverError",
    "SynthesisError",
    "GeneralizedPlant",
    "PLDI",
    "UncertainPlant",
    "closed_loop",
    "generalized_plant",
    "lft",
    "nominal_closed_loop",
    "paper_controller",
    "uncertain_plant",
    "weights",
    "available_robots",
    "bound_pldi",
    "load_robot",
]
