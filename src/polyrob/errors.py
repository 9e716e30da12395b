"""The one error hierarchy of polyrob.

Every error a user can cause derives from :class:`PolyrobError`; the CLI turns
it into one line on stderr and a non-zero exit status.
"""

from __future__ import annotations

__all__ = [
    "PolyrobError",
    "RobotError",
    "DomainError",
    "BoundsError",
    "CertificationError",
    "SolverError",
    "SynthesisError",
    "ArgumentError",
    "ControllerFileError",
    "NotApplicable",
]


class PolyrobError(Exception):
    """Base class of every error polyrob raises on bad input or failed solves."""


class RobotError(PolyrobError):
    """A robot cannot be loaded: missing/malformed URDF, floating base, tree, ..."""


class DomainError(PolyrobError):
    """A domain is invalid: zero, missing, NaN or inverted limits, bad file."""


class BoundsError(PolyrobError):
    """Bounding the Jacobians over a domain failed."""


class CertificationError(BoundsError):
    """A guaranteed (interval-arithmetic) enclosure cannot be produced."""


class SolverError(PolyrobError):
    """A numerical solver (LP, LMI, Riccati, SLICOT) failed or did not converge."""


class SynthesisError(SolverError):
    """A controller synthesis problem is infeasible or could not be solved."""


class ArgumentError(PolyrobError, ValueError):
    """An argument or option has a wrong value or kind (also a ``ValueError``, as python-control's)."""


class ControllerFileError(PolyrobError):
    """A controller file is missing, malformed, of another format, or made for another problem."""


class NotApplicable(PolyrobError):
    """An uncertainty model does not apply to this robot (e.g. ``lft``: inertia not affine in single-angle terms)."""
