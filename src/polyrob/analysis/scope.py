"""What a certificate covers: its :class:`Scope`, and how the enclosures of its inputs combine.

:mod:`polyrob.analysis.certificate` decides the status; this module says
what the decision is about (kind, variation, frequencies, model and its
coverage, domain, enclosure).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from polyrob.plant.lftplant import weakest_enclosure  # one rule: a missing or sampled input is sampled

__all__ = ["Scope", "FROZEN", "ARBITRARY", "weakest_enclosure", "finite_or_none", "strict_json"]


def finite_or_none(x):
    """``x`` as a float, or ``None`` when it is not finite (strict JSON)."""
    x = float(x)
    return x if np.isfinite(x) else None


def strict_json(d: dict) -> dict:
    """A summary with non-finite floats as ``None`` (strict JSON)."""
    return {k: finite_or_none(v) if isinstance(v, float) else v for k, v in d.items()}


#: The variations of the parameters a certificate can cover.
FROZEN = "constant parameters (every frozen robot of the set)"
ARBITRARY = "parameters varying arbitrarily fast inside the set"


@dataclass(frozen=True)
class Scope:
    """What a certificate covers.

    Attributes
    ----------
    kind : {"robust performance", "robust stability"}
    variation : str
        :data:`FROZEN`, :data:`ARBITRARY`, or a rate bound.
    model : str
        The uncertainty model (``""`` for a bare loop).
    coverage : float or None
        Fraction of fresh domain samples whose Jacobians the model contains;
        ``None`` when it was not checked.
    coverage_points : int
    enclosure : {"sampled", "certified", "unknown"}
        How the inputs were bounded (the PLDI, and the model's own ranges);
        the weakest input wins (:func:`weakest_enclosure`).
    domain : str
        The domain's name and what it bounds.
    robot : str
    frequencies : str
        Set by the decision: "every frequency" or the grid it rests on.
    vertices_from : str
        For a vertex (time-varying) certificate: the set the vertices came from.
    notes : tuple of str
        What else limits it, e.g. a mimic joint the robot model locked.
    sampling : str
        Empty for the continuous-time loop; else the sampled-data loop it
        covers (rate, delay, hold: :mod:`polyrob.analysis.sampled_data`).
    """

    kind: str = "robust performance"
    variation: str = FROZEN
    model: str = ""
    coverage: float | None = None
    coverage_points: int = 0
    enclosure: str = "unknown"
    domain: str = ""
    robot: str = ""
    frequencies: str = ""
    vertices_from: str = ""
    notes: tuple = ()
    sampling: str = ""

    def sentence(self) -> str:
        """The scope in one sentence (what the verdict line leaves out)."""
        parts = [f"for {self.variation}"]
        if self.frequencies:
            parts.append(f"on {self.frequencies}")
        if self.sampling:
            parts.append(f"of the loop {self.sampling}")
        if self.model:
            cov = (
                "coverage not checked"
                if self.coverage is None
                else f"coverage {self.coverage:.4g} of {self.coverage_points} fresh domain points"
            )
            parts.append(f"of the '{self.model}' uncertainty model ({cov})")
        if self.vertices_from:
            parts.append(f"with vertices from {self.vertices_from}")
        if self.robot or self.domain:
            encl = {"certified": "proved (interval arithmetic)", "sampled": "sampled and searched, not proved"}.get(
                self.enclosure, "of unknown enclosure"
            )
            parts.append(f"around the PLDI of {self.robot or 'the robot'} over domain {self.domain!r}, {encl}")
        text = ", ".join(parts)
        return text + "".join(f"; note: {n}" for n in self.notes)

    def summary(self) -> dict:
        return strict_json(dict(self.__dict__))
