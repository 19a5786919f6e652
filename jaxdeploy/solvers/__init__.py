"""Time integrators for mechanisms."""

from .generalized_alpha import (
    AlphaCoefficients,
    GeneralizedAlpha,
    GeneralizedAlphaState,
    chung_hulbert,
)
from .term import MechanismState, MechanismTerm

__all__ = [
    "AlphaCoefficients",
    "GeneralizedAlpha",
    "GeneralizedAlphaState",
    "MechanismState",
    "MechanismTerm",
    "chung_hulbert",
]
