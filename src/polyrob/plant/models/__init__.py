"""The uncertainty models, one module each, behind one interface (:mod:`~polyrob.plant.models.registry`).

``MODELS``, ``UncertaintyModel`` and ``model_of`` are the registry's, named here
so that ``from polyrob.plant.models import MODELS`` reads as what it is.
"""

from polyrob.plant.models.registry import MODELS, UncertaintyModel, model_of

__all__ = ["MODELS", "UncertaintyModel", "model_of"]
