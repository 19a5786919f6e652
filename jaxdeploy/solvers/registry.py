"""Solvers by name, for `simulate(..., solver="kvaerno5")` and the CLI."""

from __future__ import annotations

import diffrax as dfx
import jax.numpy as jnp
import optimistix as optx

from .generalized_alpha import GeneralizedAlpha
from .index1 import MechanismODESolver

# Implicit (stiff) and explicit diffrax methods for the index-1 ODE path.
_DIFFRAX = {
    "kvaerno3": dfx.Kvaerno3,
    "kvaerno4": dfx.Kvaerno4,
    "kvaerno5": dfx.Kvaerno5,
    "tsit5": dfx.Tsit5,
    "dopri5": dfx.Dopri5,
    "dopri8": dfx.Dopri8,
}
SOLVER_NAMES = ("generalized_alpha", *_DIFFRAX)

# Newton tolerances of the implicit stages when no step-size controller supplies them.
FIXED_STEP_ROOT_RTOL = 1e-10
FIXED_STEP_ROOT_ATOL = 1e-12


def solver_by_name(name: str, *, rtol=None, atol=None, **options):
    """The solver called `name` (one of `SOLVER_NAMES`).

    `"generalized_alpha"` takes `GeneralizedAlpha` options (e.g. `rho_inf`). The diffrax names
    give a `MechanismODESolver` (index-1 ODE with projection) around that diffrax solver;
    `options` go to `MechanismODESolver` (`baumgarte`, `project`, `resolve_switches`). Implicit
    methods get an `optimistix.Chord` root finder with the controller's `rtol`/`atol` (diffrax's
    default coupling) or, for fixed steps, 1e-10/1e-12.
    """
    if name == "generalized_alpha":
        return GeneralizedAlpha(**options)
    if name not in _DIFFRAX:
        raise ValueError(f"solver = {name!r} is invalid; valid: {', '.join(SOLVER_NAMES)}")
    cls = _DIFFRAX[name]
    if issubclass(cls, dfx.AbstractImplicitSolver):
        # Arrays, so that a new tolerance is data and does not recompile.
        # Chord (one Jacobian per stage), not diffrax's default VeryChord (one per step): at a
        # contact onset the stiffness changes within the step, VeryChord's iteration then
        # diverges and the step is rejected — 6x more steps on slider_crank at rtol 1e-8.
        root = optx.Chord(
            rtol=jnp.asarray(FIXED_STEP_ROOT_RTOL if rtol is None else rtol, dtype=float),
            atol=jnp.asarray(FIXED_STEP_ROOT_ATOL if atol is None else atol, dtype=float),
            norm=optx.rms_norm,
        )
        inner = cls(root_finder=root)
    else:
        inner = cls()
    return MechanismODESolver(inner, **options)
