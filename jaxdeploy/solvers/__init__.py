"""Time integrators for mechanisms."""

from .episodes import EpisodeLog, step_maxima, step_maximum
from .event_location import LocateEvents
from .extremes import (
    TrackedState,
    TrackExtremes,
    tracked_episodes,
    tracked_extremes,
    untracked,
)
from .generalized_alpha import (
    AlphaCoefficients,
    GeneralizedAlpha,
    GeneralizedAlphaState,
    chung_hulbert,
)
from .index1 import (
    Index1Field,
    MechanismODESolver,
    project_onto_constraints,
    stabilised_accelerations,
    state_norm,
)
from .non_finite import stop_at_non_finite
from .registry import AUTO_TIGHT_RTOL, SOLVER_NAMES, resolve_solver, solver_by_name
from .step_control import (
    SolverChoiceWarning,
    StepControl,
    default_control,
    solver_advice,
    split_tolerances,
    tolerances_as_data,
    with_tolerances,
)
from .term import MechanismState, MechanismTerm

__all__ = [
    "AUTO_TIGHT_RTOL",
    "SOLVER_NAMES",
    "AlphaCoefficients",
    "EpisodeLog",
    "GeneralizedAlpha",
    "GeneralizedAlphaState",
    "Index1Field",
    "LocateEvents",
    "MechanismODESolver",
    "MechanismState",
    "MechanismTerm",
    "SolverChoiceWarning",
    "StepControl",
    "default_control",
    "solver_advice",
    "chung_hulbert",
    "project_onto_constraints",
    "resolve_solver",
    "solver_by_name",
    "stabilised_accelerations",
    "state_norm",
    "step_maxima",
    "step_maximum",
    "split_tolerances",
    "tolerances_as_data",
    "with_tolerances",
    "stop_at_non_finite",
    "TrackExtremes",
    "TrackedState",
    "tracked_episodes",
    "tracked_extremes",
    "untracked",
]
