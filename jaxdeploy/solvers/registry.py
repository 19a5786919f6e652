"""Solvers by name, for `simulate(..., solver="kvaerno5")` and the CLI."""

from __future__ import annotations

import diffrax as dfx
import jax.numpy as jnp
import optimistix as optx

from .._validation import is_concrete
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
SOLVER_NAMES = ("generalized_alpha", *_DIFFRAX, "auto")

# `solver="auto"`: the method chosen by the tolerance. A high-order method does more work per
# step and takes far fewer steps at a tight tolerance, so below some tolerance it is cheaper at
# equal error; DifferentialEquations.jl's default ODE algorithm takes Tsit5 for reltol ≥ 1e-6
# and Vern7 below (OrdinaryDiffEq.jl, lib/OrdinaryDiffEqDefault/src/default_alg.jl,
# `nonstiffchoice`). Here: Tsit5 for rtol ≥ AUTO_TIGHT_RTOL (and for fixed steps), Dopri8
# below. The crossover is measured on slider_crank against the independent reference
# (docs/solver_by_tolerance.md, `tests/independent/solver_crossover.py`). "auto:NAME" keeps
# NAME (a name of SOLVER_NAMES) above the crossover instead of Tsit5: a scene whose default
# method is not Tsit5 keeps its default runs and still gets Dopri8 at a tight tolerance.
AUTO = "auto"
AUTO_LOOSE_SOLVER = "tsit5"
AUTO_TIGHT_SOLVER = "dopri8"
AUTO_TIGHT_RTOL = 1e-8

# Newton tolerances of the implicit stages when no step-size controller supplies them.
FIXED_STEP_ROOT_RTOL = 1e-10
FIXED_STEP_ROOT_ATOL = 1e-12


def auto_loose_solver(name) -> str | None:
    """For an automatic choice (`"auto"` or `"auto:NAME"`) the method used at loose
    tolerances and for fixed steps; None for any other solver (name or object). An
    `"auto:NAME"` whose NAME is not a method name raises `ValueError`."""
    if not isinstance(name, str) or not (name == AUTO or name.startswith(AUTO + ":")):
        return None
    loose = name.partition(":")[2] or AUTO_LOOSE_SOLVER
    if loose not in SOLVER_NAMES or loose == AUTO:
        raise ValueError(
            f"solver = {name!r} is invalid: after 'auto:' give one of "
            f"{', '.join(n for n in SOLVER_NAMES if n != AUTO)}"
        )
    return loose


def is_solver_name(name) -> bool:
    """True for a name of `SOLVER_NAMES` or an `"auto:NAME"` (NAME one of them)."""
    if not isinstance(name, str):
        return False
    try:
        return name in SOLVER_NAMES or auto_loose_solver(name) is not None
    except ValueError:
        return False


def resolve_solver(solver, rtol=None, atol=None):
    """The solver a run uses: an automatic choice resolved by the tolerance (Dopri8 when the
    run is adaptive with `rtol` < `AUTO_TIGHT_RTOL`, otherwise its loose method); anything
    else as it is. The tolerance must be a number here (not traced): the choice is made when
    the program is built."""
    loose = auto_loose_solver(solver)
    if loose is None:
        return solver
    if rtol is None:  # fixed steps, or adaptive on atol alone (the controller's rtol is 1e-6)
        return loose
    if not is_concrete(rtol):
        raise ValueError(
            f"solver = {solver!r} chooses its method by rtol, which must then be a number, "
            "not a traced value: give a method name"
        )
    return AUTO_TIGHT_SOLVER if float(rtol) < AUTO_TIGHT_RTOL else loose


def solver_by_name(name: str, *, rtol=None, atol=None, **options):
    """The solver called `name` (one of `SOLVER_NAMES`).

    `"auto"` / `"auto:NAME"` are resolved by `resolve_solver` from `rtol` first.
    `"generalized_alpha"` takes `GeneralizedAlpha` options (e.g. `rho_inf`). The diffrax names
    give a `MechanismODESolver` (index-1 ODE with projection) around that diffrax solver;
    `options` go to `MechanismODESolver` (`baumgarte`, `project`, `resolve_switches`). Implicit
    methods get an `optimistix.Chord` root finder with the controller's `rtol`/`atol` (diffrax's
    default coupling) or, for fixed steps, 1e-10/1e-12.
    """
    name = resolve_solver(name, rtol, atol)
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
