"""Identification: fit scene parameters to measured channels, with honest uncertainties.

`parameter_jacobian` differentiates any output of a run with respect to scene parameters
(reverse or forward mode through the solver); `gradient_function` / `parameter_gradient` give
a scalar loss and its gradient, in the mode the parameter count makes cheaper
(`gradient_mode`); `derivative_tolerance` chooses a step tolerance at which those
derivatives, not only the values, have converged (`gradient_check` runs at it).
`load_measurements` reads CSV/npz data; `fit` runs Levenberg–Marquardt through the simulation
(forward-mode derivatives through the generalized-α solver); `FitResult` reports estimates,
standard errors, correlations and the loss history; `synthesize` makes noisy synthetic data
from a scene. See docs/identification.md.
"""

from ._data import MeasurementError, Measurements, load_measurements
from ._derivative_tolerance import (
    DERIVATIVE_CHANGE,
    DerivativeTolerance,
    converged_tolerance,
    derivative_tolerance,
)
from ._derivatives import (
    FORWARD_MODE_MAX_PARAMETERS,
    central_differences,
    gradient_at_tolerances,
    gradient_function,
    gradient_mode,
    output_function,
    parameter_gradient,
    parameter_jacobian,
)
from ._fit import (
    JACOBIAN_CHANGE,
    RTOL_CHECK_FLOOR,
    FitResult,
    fit,
    levenberg_marquardt,
    prepare_fit,
    refit_until_reproducible,
    tolerance_at_estimate,
    tolerance_check,
)
from ._gradcheck import DEFAULT_STEPS, GradientCheck, gradient_check
from ._parameters import FitParameter, check_not_ignored, make_parameters, parse_param_spec
from ._plots import plot_fit
from ._residuals import Comparison, ResidualSpec
from ._schedule import (
    MODEL_ERROR,
    RTOL_FLOOR,
    choose_tolerance,
    first_tolerance,
    impact_horizons,
    onset_times,
    run_channels,
)
from ._synthetic import model_channels, synthesize

__all__ = [
    "DERIVATIVE_CHANGE",
    "DerivativeTolerance",
    "converged_tolerance",
    "derivative_tolerance",
    "gradient_at_tolerances",
    "FORWARD_MODE_MAX_PARAMETERS",
    "JACOBIAN_CHANGE",
    "RTOL_CHECK_FLOOR",
    "RTOL_FLOOR",
    "MODEL_ERROR",
    "Comparison",
    "check_not_ignored",
    "choose_tolerance",
    "first_tolerance",
    "impact_horizons",
    "onset_times",
    "refit_until_reproducible",
    "run_channels",
    "tolerance_at_estimate",
    "tolerance_check",
    "central_differences",
    "DEFAULT_STEPS",
    "GradientCheck",
    "gradient_check",
    "FitParameter",
    "FitResult",
    "MeasurementError",
    "Measurements",
    "ResidualSpec",
    "fit",
    "prepare_fit",
    "gradient_function",
    "gradient_mode",
    "levenberg_marquardt",
    "load_measurements",
    "make_parameters",
    "model_channels",
    "output_function",
    "parameter_jacobian",
    "parameter_gradient",
    "parse_param_spec",
    "plot_fit",
    "synthesize",
]
