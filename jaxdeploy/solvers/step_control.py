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

import contextlib
import dataclasses
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import diffrax as dfx
import optimistix as optx

from .._validation import (
    check_nonnegative,
    check_positive,
    check_range,
    float_data,
    is_concrete,
)
from ..mechanism import RevoluteClearance
from .generalized_alpha import GeneralizedAlpha
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
            return None if x is None else float_data(x)

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


def tolerances_as_data(function: Callable) -> Callable:
    """`call(control, *args) = function(control, *args)`, jit-compiled with `control`'s rtol
    and atol passed as data (traced scalars; `StepControl` checks values only when they are
    concrete, and the controller takes them as arrays): controls that differ only in their
    tolerances share one compiled program. A program is compiled per solver (an automatic
    choice is resolved by each control's concrete rtol first, so `"auto"` crossing
    `AUTO_TIGHT_RTOL` compiles once more) and per other step setting; a fixed-step control
    is closed over as it is. Why: a program traced with a control's tolerances holds them
    as constants, and a search over tolerances (a derivative's convergence,
    `fit.derivative_tolerance`; a design's gradient, `optimize`) would compile one
    program per tolerance, each the cost of the whole program (minutes for a deploy_array
    derivative). `call.programs` holds the compiled programs by setting."""
    import jax

    programs = {}

    def call(control: StepControl, *args):
        structure, rtol, atol = split_tolerances(control)
        if structure not in programs:
            if not structure.adaptive:  # a fixed-step control is closed over as it is
                programs[structure] = jax.jit(lambda *a: function(structure, *a))
            else:

                def run(rtol, atol, *a, structure=structure):
                    return function(with_tolerances(structure, rtol, atol), *a)

                programs[structure] = jax.jit(run)
        if not structure.adaptive:
            return programs[structure](*args)
        return programs[structure](rtol, atol, *args)

    call.programs = programs
    return call


def split_tolerances(control: StepControl) -> tuple[StepControl, float, float]:
    """`(structure, rtol, atol)`: what a compiled program of `control` is made of (its
    method, resolved by the concrete rtol when automatic, and every other setting, with
    placeholders for the tolerances it has) and the tolerances as numbers (0 where absent),
    its data (`tolerances_as_data`, the fit's model programs). A fixed-step control is its
    own structure."""
    if not control.adaptive:
        return control, 0.0, 0.0
    has_rtol, has_atol = control.rtol is not None, control.atol is not None
    structure = control.replace(
        solver=control.resolved_solver(),
        rtol=0.5 if has_rtol else None,
        atol=1.0 if has_atol else None,
    )
    return (
        structure,
        float(control.rtol) if has_rtol else 0.0,
        float(control.atol) if has_atol else 0.0,
    )


def with_tolerances(structure: StepControl, rtol, atol) -> StepControl:
    """The control of `structure` (`split_tolerances`) with its tolerances `rtol`, `atol`
    (traced values inside a program)."""
    if not structure.adaptive:
        return structure
    return structure.replace(
        rtol=None if structure.rtol is None else rtol,
        atol=None if structure.atol is None else atol,
    )


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


# --- the step control a mechanism gets when the caller gives none -------------------------------

# With clearance joints: the Runge–Kutta path with event location, the method chosen by the
# tolerance ("auto": Dopri8 below AUTO_TIGHT_RTOL), at rtol 1e-9, atol 1e-12 (atol = 1e-3 rtol, as
# measured). rtol 1e-9 is the loosest tolerance at which every verified clearance case stayed
# within 1e-5 m of its independent reference over its whole horizon
# (docs/solver_by_tolerance.md, slider_crank over two revolutions, 26 and 43 impacts: Dopri8 at
# rtol 1e-9 1.1e-9 m without friction and 3.9e-7 m with μ = 0.01; at rtol 1e-8 the friction
# case is off by 5.7e-5 m (Dopri8) and 1.1e-4 m (Tsit5) and finds 42 or 44 impacts), and the
# tutorial's pendulum on a clearance pivot over its 8 impacts (tests/independent/
# pendulum_clearance.py: 1.3e-13 m, every episode found; tests/test_independent_pendulum.py).
# Event location ends a step on every contact onset and separation, so v⁻ is as accurate as
# the state.
CLEARANCE_DEFAULT = StepControl("auto", rtol=1e-9, atol=1e-12)
# Without clearance joints the equations are smooth and the measurements favour the Runge–Kutta
# path too: on Andrews' squeezer (docs/performance.md) Tsit5 at rtol 1e-8 is within 2.1e-9
# (relative) of the Test Set's solution in 256 steps, where generalized-α at the same rtol is off
# by 4.1e-6 after 6163 steps.
SMOOTH_DEFAULT = StepControl("auto", rtol=1e-8, atol=1e-11)

# Generalized-α on a mechanism with clearance joints is measured less accurate than the
# Runge–Kutta path at every tolerance looser than this one (docs/solver_by_tolerance.md): at
# rtol 1e-6 … 1e-8 over two slider_crank revolutions its error is of the order of the clearance
# (5.4e-4, 3.4e-4, 6.4e-4 m against Tsit5's 7.0e-5, 1.5e-5, 2.5e-6 m) and it counts 28 impacts
# where there are 26; at rtol 1e-10 (4 ms) 9.4e-9 m against Tsit5's 2.6e-11 m; at rtol 1e-12
# both are within 5e-10 m. On the tutorial's pendulum (40 ms, 8 impacts) it failed at rtol 1e-6
# (non-finite after 523 405 steps) and at 1e-10 (2 000 000 steps reached at t = 0.026 s) and was
# off by 9.1e-8 … 4.4e-9 m at rtol 1e-7 … 1e-9, where Dopri8 at the same rtol was within
# 1.3e-11 … 1.3e-13 m in 299 … 385 steps. Fixed steps are not error-controlled at all.
GENERALIZED_ALPHA_CLEARANCE_RTOL = 1e-12


class SolverChoiceWarning(UserWarning):
    """A step control known, by measurement, to be less accurate for this mechanism than the
    default (`default_control`)."""


def default_control(mechanism) -> StepControl:
    """The step control `simulate` uses for `mechanism` when the caller gives none:
    `CLEARANCE_DEFAULT` (`"auto"`, rtol 1e-9, atol 1e-12, event location) for a mechanism with
    clearance joints, `SMOOTH_DEFAULT` (`"auto"`, rtol 1e-8, atol 1e-11) without; the
    measurements behind each are beside their definitions (solvers/step_control.py)."""
    return CLEARANCE_DEFAULT if _has_clearance_joints(mechanism) else SMOOTH_DEFAULT


def _has_clearance_joints(mechanism) -> bool:
    return bool(mechanism.find(RevoluteClearance))


def _is_generalized_alpha(solver) -> bool:
    return solver == "generalized_alpha" or isinstance(solver, GeneralizedAlpha)


def solver_advice(mechanism, control: StepControl) -> str | None:
    """Why `control` is known to be less accurate for `mechanism` than the default, or None:
    generalized-α on a mechanism with clearance joints with fixed steps or at an rtol looser
    than `GENERALIZED_ALPHA_CLEARANCE_RTOL` (the measurements are beside it)."""
    if not _is_generalized_alpha(control.resolved_solver()):
        return None
    if not _has_clearance_joints(mechanism):
        return None
    if control.adaptive:
        rtol = 1e-6 if control.rtol is None else control.rtol
        if not is_concrete(rtol) or float(rtol) <= GENERALIZED_ALPHA_CLEARANCE_RTOL:
            return None
        setting = f"rtol {float(rtol):g}"
    else:
        setting = f"fixed steps of {float(control.dt):g} s"
    return (
        f"generalized-α with {setting} on a mechanism with clearance joints: measured less "
        "accurate than the Runge–Kutta path with event location at every rtol above "
        f"{GENERALIZED_ALPHA_CLEARANCE_RTOL:g} (slider_crank, two revolutions: x_s off by "
        "3.4e-4 to 6.4e-4 m at rtol 1e-6 to 1e-8, about the clearance, and 28 impacts found "
        "where there are 26, against Tsit5's 7.0e-5 to 2.5e-6 m; docs/solver_by_tolerance.md; "
        "a pendulum on a clearance pivot: failed at rtol 1e-6 and 1e-10, 7e3 to 4e4 × "
        "Dopri8's error at 1e-7 to 1e-9; docs/tutorial.md). "
        "Leave the step control out for the default (solver 'auto', rtol 1e-9, atol 1e-12: "
        "jaxdeploy.solvers.default_control), or give a tighter rtol"
    )


def warn_solver_choice(mechanism, control: StepControl, stacklevel: int = 3) -> None:
    """`SolverChoiceWarning` with `solver_advice`'s reason, if it has one."""
    advice = solver_advice(mechanism, control)
    if advice is not None:
        warnings.warn(advice, SolverChoiceWarning, stacklevel=stacklevel)


@contextlib.contextmanager
def scene_default_choice(control: StepControl, scene_default: StepControl):
    """Inside it, no `SolverChoiceWarning` for `control` when it is `scene_default`: a scene's
    own default step control was chosen and verified for that scene (the impact scene's
    generalized-α against Johnson's closed forms, docs/verification.md), so only a step control
    the user changed is judged."""
    with warnings.catch_warnings():
        # Traced tolerances (a derivative program taking them as data) cannot be compared;
        # `solver_advice` judges no traced rtol either.
        if is_concrete((control.rtol, control.atol)) and control == scene_default:
            warnings.simplefilter("ignore", SolverChoiceWarning)
        yield
