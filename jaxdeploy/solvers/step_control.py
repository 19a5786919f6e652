"""`StepControl`: how a run chooses its solver and its steps, one object built once and handed
to `simulate`, `simulate_batch`, `sweep`, `fit` and `optimize` (and recorded with their
results).

Fixed step: `dt` alone. Adaptive step: `rtol` and/or `atol` on the solver's local error
estimate of the positions and velocities (a mixed error test per component,
|e_i| ≤ atol + rtol·|y_i|, then a root-mean-square norm; Hairer, Nørsett & Wanner 1993,
"Solving Ordinary Differential Equations I", §II.4, eq. 4.10–4.11), with `dt_min`/`dt_max`
bounding the step and `dt` (if given) the first one. `locate_events`: an adaptive step in
which a clearance joint's impact velocity is set is redone to end just past that event
(`LocateEvents`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass

import diffrax as dfx
import jax.numpy as jnp
import optimistix as optx

from .._validation import check_nonnegative, check_positive, check_range, is_concrete
from .registry import (
    AUTO_TIGHT_RTOL,
    AUTO_TIGHT_SOLVER,
    SOLVER_NAMES,
    auto_loose_solver,
    is_solver_name,
    resolve_solver,
    solver_by_name,
)

DEFAULT_SOLVER = "generalized_alpha"
DEFAULT_MAX_STEPS = 2_000_000
# The first step of an adaptive run when `dt` is not given [s]: short enough for every scene's
# fastest contact (the controller grows it by up to 5x per step).
DEFAULT_FIRST_STEP = 1e-6


@dataclass(frozen=True)
class StepControl:
    """The solver and its step control.

    **Fields** (SI units; positions in m and rad, velocities in m/s and rad/s):
    - `solver`: a name from `jaxdeploy.solvers.SOLVER_NAMES` (`"generalized_alpha"`, the
      default; `"tsit5"`, `"kvaerno5"`, … on the index-1 path), `"auto"` (Tsit5, or Dopri8
      for an adaptive run at rtol < `AUTO_TIGHT_RTOL`; `"auto:NAME"`: NAME instead of Tsit5;
      `jaxdeploy.solvers.resolve_solver`), or a solver object.
    - `rtol`, `atol`: tolerances of the adaptive step, rtol in (0, 1), atol > 0. With neither,
      the step is fixed: `dt`.
    - `dt` [s]: the fixed step, or the first step of an adaptive run (default
      min(1e-6 s, dt_max)).
    - `dt_min`, `dt_max` [s]: bounds of an adaptive step.
    - `max_steps`: the run fails (status says so) after this many steps.
    - `locate_events`: redo an adaptive step that contains a clearance joint's impact
      velocity event so that it ends just past it.

    Frozen and hashable; derive variants with `replace(rtol=...)`. Values are checked on
    construction (when concrete), naming the field and its valid range. Tolerances and steps
    become data of the compiled program: changing them does not recompile; the solver, the
    kind of step (fixed or adaptive) and `locate_events` do.
    """

    solver: object = DEFAULT_SOLVER
    rtol: float | None = None
    atol: float | None = None
    dt: float | None = None
    dt_min: float | None = None
    dt_max: float | None = None
    max_steps: int = DEFAULT_MAX_STEPS
    locate_events: bool = True

    def __post_init__(self):
        if isinstance(self.solver, str) and not is_solver_name(self.solver):
            auto_loose_solver(self.solver)  # an "auto:NAME" with a bad NAME says so
            raise ValueError(
                f"solver = {self.solver!r} is invalid; valid: {', '.join(SOLVER_NAMES)} "
                "or auto:NAME"
            )
        if self.solver is None:
            object.__setattr__(self, "solver", DEFAULT_SOLVER)
        if self.rtol is not None:
            check_range("rtol", self.rtol, 0.0, 1.0, low_inclusive=False, high_inclusive=False)
        if self.atol is not None:
            check_positive("atol", self.atol)
        if self.dt is not None:
            check_positive("dt", self.dt, "s")
        if self.dt_min is not None:
            check_nonnegative("dt_min", self.dt_min, "s")
        if self.dt_max is not None:
            check_positive("dt_max", self.dt_max, "s")
        if (
            self.dt_min is not None
            and self.dt_max is not None
            and is_concrete((self.dt_min, self.dt_max))
            and float(self.dt_min) > float(self.dt_max)
        ):
            raise ValueError(
                f"dt_min = {self.dt_min!r} s is invalid: it must be ≤ dt_max = {self.dt_max!r} s"
            )
        if not (
            isinstance(self.max_steps, int)
            and not isinstance(self.max_steps, bool)
            and self.max_steps > 0
        ):
            raise ValueError(
                f"max_steps = {self.max_steps!r} is invalid: it must be a positive integer"
            )
        if not isinstance(self.locate_events, bool):
            raise ValueError(
                f"locate_events = {self.locate_events!r} is invalid: it must be True or False"
            )
        if self.dt is None and not self.adaptive:
            raise ValueError("give dt (fixed step) or rtol/atol (adaptive step)")

    @property
    def adaptive(self) -> bool:
        return self.rtol is not None or self.atol is not None

    def replace(self, **changes) -> StepControl:
        """A copy with `changes` (field names), checked like a new one."""
        return dataclasses.replace(self, **changes)

    def updated(self, overrides: Mapping | None) -> StepControl:
        """A copy with the entries of `overrides` (a mapping of field names, e.g. from an
        older caller's step-control dict); an unknown key raises `ValueError` listing the
        fields."""
        overrides = dict(overrides or {})
        unknown = sorted(set(overrides) - set(FIELDS))
        if unknown:
            raise ValueError(
                f"step control: unknown setting(s) {', '.join(unknown)}; valid: "
                + ", ".join(FIELDS)
            )
        return self.replace(**overrides) if overrides else self

    def settings(self) -> dict:
        """The fields that differ from `StepControl()`'s defaults, as keywords of `simulate`
        (`simulate(..., **c.settings())` runs as `simulate(..., control=c)`)."""
        return {
            f.name: getattr(self, f.name)
            for f in dataclasses.fields(self)
            if getattr(self, f.name) is not f.default and getattr(self, f.name) != f.default
        }

    # Read as a mapping, a StepControl is its `settings()`: `simulate(..., **control)`,
    # `dict(control)` and `{**control, "rtol": 1e-8}` work as they did when scenes' step
    # controls were dicts.
    def keys(self):
        return self.settings().keys()

    def __getitem__(self, key):
        return self.settings()[key]

    def __iter__(self):
        return iter(self.settings())

    def __len__(self) -> int:
        return len(self.settings())

    def items(self):
        return self.settings().items()

    def get(self, key, default=None):
        return self.settings().get(key, default)

    def first_step(self) -> float:
        """The first step [s]: `dt`, or for an adaptive run without it min(1e-6 s, dt_max)."""
        if self.dt is not None:
            return self.dt
        return DEFAULT_FIRST_STEP if self.dt_max is None else min(DEFAULT_FIRST_STEP, self.dt_max)

    def resolved_solver(self):
        """The solver this control runs: `solver`, with an automatic choice (`"auto"`,
        `"auto:NAME"`) resolved by `rtol` (`jaxdeploy.solvers.resolve_solver`)."""
        return resolve_solver(self.solver, self.rtol if self.adaptive else None, self.atol)

    def make_solver(self):
        """The solver object (a name is resolved by `solver_by_name`; implicit methods take
        their Newton tolerances from `rtol`/`atol`)."""
        solver = self.resolved_solver()
        if isinstance(solver, str):
            return solver_by_name(solver, rtol=self.rtol, atol=self.atol)
        return solver

    def controller(self, norm=None):
        """The diffrax step-size controller: `ConstantStepSize` for a fixed step, otherwise a
        PI controller on `norm` (default root-mean-square). Tolerances and step bounds are
        arrays, so they are data of the compiled program."""
        if not self.adaptive:
            return dfx.ConstantStepSize()

        def data(x):
            return None if x is None else jnp.asarray(x, dtype=float)

        # PI coefficients suited to stiff problems (diffrax's `PIDController` docstring).
        return dfx.PIDController(
            rtol=data(1e-6 if self.rtol is None else self.rtol),
            atol=data(1e-9 if self.atol is None else self.atol),
            pcoeff=0.3,
            icoeff=0.4,
            dtmin=data(self.dt_min),
            dtmax=data(self.dt_max),
            factormax=5.0,
            norm=optx.rms_norm if norm is None else norm,
        )

    def solver_name(self) -> str:
        """The name of the solver that runs (an automatic choice resolved), or for a solver
        object a deterministic description of it."""
        solver = self.resolved_solver()
        return solver if isinstance(solver, str) else repr(solver)

    def solver_rule(self) -> str | None:
        """For an automatic choice, the rule and the method it chose (as results record it);
        None otherwise."""
        loose = auto_loose_solver(self.solver)
        if loose is None:
            return None
        return (
            f"{self.solver}: {loose} for rtol ≥ {AUTO_TIGHT_RTOL:g} and fixed steps, "
            f"{AUTO_TIGHT_SOLVER} below; chose {self.solver_name()}"
        )

    def to_json(self) -> dict:
        """Every field as JSON (numbers as floats), as results record it: `solver` is the
        solver that runs (`solver_name`), `solver_rule` the automatic choice that picked it
        (None when the solver was given)."""

        def number(x):
            return None if x is None else float(x)

        return {
            "solver": self.solver_name(),
            "solver_rule": self.solver_rule(),
            "rtol": number(self.rtol),
            "atol": number(self.atol),
            "dt": number(self.dt),
            "dt_min": number(self.dt_min),
            "dt_max": number(self.dt_max),
            "max_steps": int(self.max_steps),
            "locate_events": bool(self.locate_events),
            "adaptive": self.adaptive,
        }

    @classmethod
    def from_json(cls, record: Mapping) -> StepControl:
        """The step control `to_json` recorded (a solver object recorded by its description
        cannot be rebuilt: `ValueError`)."""
        values = {k: record[k] for k in FIELDS if k in record}
        rule = record.get("solver_rule")
        if rule:  # the automatic choice, not the method it chose for these tolerances
            values["solver"] = rule.partition(": ")[0]
        return cls(**values)


FIELDS = tuple(f.name for f in dataclasses.fields(StepControl))


def as_step_control(control, base: StepControl | None = None) -> StepControl:
    """`control` as a `StepControl`: a `StepControl` as it is; a mapping of field names (or
    None) as overrides of `base` (a scene's default; required for a mapping)."""
    if isinstance(control, StepControl):
        return control
    if control is not None and not isinstance(control, Mapping):
        raise TypeError(
            f"control = {control!r} is invalid: give a StepControl or a mapping of its fields"
        )
    if base is None:
        return StepControl(**dict(control or {}))
    return base.updated(control)
