"""Arguments the commands share, each checked where it is parsed: a bad value stops the command
with exit code 2 and a message naming the flag and its valid range, before any file is written
or anything is compiled.

Keep this module light (no JAX, no diffrax at import): `jaxdeploy --help` imports it.
"""

from __future__ import annotations

import argparse
import math
import sys

from . import (  # noqa: F401 - the exit codes, for the command modules
    EXIT_FAILED,
    EXIT_IMPLAUSIBLE,
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_REFUSED,
)

STEP_CONTROL_FLAGS = ("--solver", "--rtol", "--atol", "--dt-max", "--dt")
# Named here for the help texts, which must not import JAX: the presets of
# `jaxdeploy.objectives.PRESETS`, `jaxdeploy.sweep.DEFAULT_CHUNK_SIZE` and
# `jaxdeploy.sweep.AUTO_EACH_CASES_PER_CORE` (tests/test_cli_help.py checks that they agree).
OBJECTIVE_PRESETS = ("paper", "paper_reproducible", "quiet", "fast_decay")
SWEEP_CHUNK_SIZE = 64
SWEEP_AUTO_EACH_CASES_PER_CORE = 2
RTOL_FLOOR = 1e-10  # jaxdeploy.fit.RTOL_FLOOR: the tightest rtol the fit chooses
SET_HELP = (
    "scene parameter NAME=VALUE in SI units (repeatable, each NAME once); `jaxdeploy scenes "
    "SCENE` lists the parameters with their units and valid ranges; default: none (the "
    "scene's defaults)"
)


def refuse(message: str) -> int:
    """Print `error: message` to stderr; return `EXIT_REFUSED`."""
    print(f"error: {message}", file=sys.stderr)
    return EXIT_REFUSED


def number_in(
    flag: str, low: float, high: float, *, unit: str = "", low_open=True, high_open=False
):
    """An argparse `type` accepting a finite number in the range (`low_open`/`high_open`
    exclude the ends), refusing anything else with the flag, the value and the range."""
    brackets = ("(" if low_open else "[", ")" if high_open else "]")
    shown_high = "inf" if high == math.inf else f"{high:g}"
    valid = f"{brackets[0]}{low:g}, {shown_high}{brackets[1]}" + (f" {unit}" if unit else "")

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"{flag} = {text!r} is not a number; it must be in {valid}"
            ) from None
        too_low = value <= low if low_open else value < low
        too_high = value >= high if high_open else value > high
        if not math.isfinite(value) or too_low or too_high:
            raise argparse.ArgumentTypeError(
                f"{flag} = {text} is invalid: it must be finite and in {valid}"
            )
        return value

    parse.unit = unit  # the help must name it (tests/test_cli_help.py)
    return parse


def positive(flag: str, unit: str = ""):
    """A finite number > 0."""
    return number_in(flag, 0.0, math.inf, unit=unit, high_open=True)


def integer_at_least(flag: str, low: int, high: int | None = None):
    """An argparse `type` accepting an integer ≥ `low` (and ≤ `high`)."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{flag} = {text!r} is not an integer") from None
        if value < low or (high is not None and value > high):
            valid = f"≥ {low}" if high is None else f"in [{low}, {high}]"
            raise argparse.ArgumentTypeError(f"{flag} = {text} is invalid: it must be {valid}")
        return value

    return parse


def _solver_name(text: str) -> str:
    from ..solvers.registry import SOLVER_NAMES, is_solver_name

    if not is_solver_name(text):
        raise argparse.ArgumentTypeError(
            f"--solver = {text!r} is unknown; valid: {', '.join(SOLVER_NAMES)} or auto:NAME"
        )
    return text


def add_step_control(parser, unset: str | None = None, default: str = "the scene's") -> None:
    """The one argument group of solver and step control, for every command that runs
    simulations (`simulate`, `sweep`, `fit`, `optimize`); `step_control(args, scene)` turns
    it into a `StepControl`. `unset`: what the group's description says happens to unset
    values (default: they keep the scene's default); `default`: each flag's default, as its
    help says it."""
    if unset is None:
        unset = "Unset values keep the scene's default (`jaxdeploy scenes SCENE` lists it)."
    group = parser.add_argument_group(
        "solver and step control",
        f"{unset} --rtol or --atol: adaptive steps; --dt alone: fixed steps of that size. "
        "Recorded with the result.",
    )
    group.add_argument(
        "--solver",
        type=_solver_name,
        default=None,
        metavar="NAME",
        help="generalized_alpha (index-3, implicit), or on the index-1 path tsit5, dopri5, "
        "dopri8 (explicit), kvaerno3, kvaerno4, kvaerno5 (implicit); auto: tsit5, or dopri8 "
        "at a tight rtol (auto:NAME: NAME instead of tsit5; docs/solver_by_tolerance.md). "
        f"summary.json records the solver that ran. Default: {default}",
    )
    group.add_argument(
        "--rtol",
        type=number_in("--rtol", 0.0, 1.0, high_open=True),
        default=None,
        help="relative tolerance of an adaptive step, in (0, 1) (dimensionless); default: "
        + default,
    )
    group.add_argument(
        "--atol",
        type=positive("--atol"),
        default=None,
        help="absolute tolerance of an adaptive step (positions in m and rad, velocities in "
        f"m/s and rad/s), > 0; default: {default}",
    )
    group.add_argument(
        "--dt-max",
        type=positive("--dt-max", "s"),
        default=None,
        help=f"largest adaptive step [s], > 0; default: {default}",
    )
    group.add_argument(
        "--dt",
        type=positive("--dt", "s"),
        default=None,
        help="fixed step [s] (alone), or the first adaptive step with --rtol/--atol, > 0; "
        f"default: {default}",
    )


def add_derivative_tolerance_check(parser, when: str, what: str, default: str) -> None:
    """`--derivative-change` and `--no-step-tolerance-check`, for the commands that
    differentiate runs (`gradcheck`, `optimize --gradient pathwise`): the step tolerance is
    tightened from `--rtol` (or the scene's) until `what` (e.g. "the AD derivatives") changes
    by at most a fraction at a 10x tighter one (`solvers.tolerances_as_data`). `when`: the
    condition under which the flags apply, prefixed to their help ("" for always);
    `default`: `--derivative-change`'s default, as its help says it."""
    group = parser.add_argument_group(
        "derivative tolerance check",
        f"{when}derivatives need a tighter step tolerance than values; the tolerance is "
        "checked before the derivatives are used.",
    )
    group.add_argument(
        "--derivative-change",
        type=number_in("--derivative-change", 0.0, 1.0, high_open=True),
        default=None,
        help=f"{when}the step tolerance is tightened (by 10 at a time, from --rtol or the "
        f"scene's) until {what} changes by at most this fraction at a 10x tighter one, in "
        f"(0, 1) (default: {default})",
    )
    group.add_argument(
        "--no-step-tolerance-check",
        action="store_true",
        help=f"{when}run at --rtol (or the scene's) as given, without checking that {what} "
        "has converged there",
    )


def step_control(args, scene):
    """The `StepControl` of a run of `scene` from the shared flags: the scene's default with
    the flags given applied. `--dt` without `--rtol`/`--atol` makes the steps fixed. A
    combination no run can honour raises `ValueError` naming the flags."""
    control = scene.default_control
    changes = {}
    if args.solver is not None:
        changes["solver"] = args.solver
    if args.dt is not None and args.rtol is None and args.atol is None:
        if args.dt_max is not None:
            raise ValueError(
                "--dt-max bounds adaptive steps: with a fixed step (--dt without --rtol/--atol) "
                "leave it out"
            )
        changes.update(rtol=None, atol=None, dt_min=None, dt_max=None, dt=args.dt)
    else:
        for key in ("rtol", "atol", "dt_max", "dt"):
            if getattr(args, key) is not None:
                changes[key] = getattr(args, key)
        if not control.adaptive and not ({"rtol", "atol"} & set(changes)) and changes:
            if "dt_max" in changes:
                raise ValueError(
                    f"--dt-max bounds adaptive steps; scene {scene.name!r} steps with a fixed "
                    f"dt = {control.dt:g} s: give --rtol/--atol too"
                )
    updated = control.replace(**changes) if changes else control
    if updated.adaptive and updated.dt is not None and updated.dt_max is not None:
        if updated.dt > updated.dt_max:
            raise ValueError(
                f"--dt = {updated.dt:g} s is invalid: the first adaptive step must be ≤ "
                f"--dt-max = {updated.dt_max:g} s"
            )
    return updated


def parse_assignments(items, flag: str = "--set") -> dict[str, float]:
    """`NAME=VALUE` items of a repeatable flag as `{name: float}` (SI units); a malformed
    item, a value that is not a number or a name given twice raises `ValueError` naming the
    flag (ranges are the scene's to check: `Scene.resolve_params`)."""
    out = {}
    for item in items:
        name, sep, value = item.partition("=")
        name = name.strip()
        if not sep or not name:
            raise ValueError(f"{flag} expects NAME=VALUE, got {item!r}")
        if name in out:
            raise ValueError(f"{flag} {name} is given twice ({out[name]!r} and {value.strip()})")
        try:
            number = float(value)
        except ValueError:
            raise ValueError(f"{flag} {name}: {value!r} is not a number (SI units)") from None
        out[name] = number
    return out


SCENE_OPTION_HELP = (
    "scene option KEY=VALUE (repeatable), e.g. impact_velocity_rule=running_max; "
    "`jaxdeploy scenes SCENE` lists a scene's options with their choices; default: none (the "
    "scene's defaults)"
)


def parse_pairs(items, flag: str) -> dict:
    """`KEY=VALUE` items of a repeatable flag; a VALUE that parses as JSON (e.g. `true`,
    `{"J1": "panel1"}`) is decoded, anything else is kept as a string. A malformed or repeated
    KEY raises ValueError naming `flag`."""
    import json

    out = {}
    for item in items:
        if "=" not in item:
            raise ValueError(f"{flag} expects KEY=VALUE, got {item!r}")
        key, value = (s.strip() for s in item.split("=", 1))
        if key in out:
            raise ValueError(f"{flag} {key} is given twice")
        try:
            out[key] = json.loads(value)
        except json.JSONDecodeError:
            out[key] = value
    return out


def check_used(scene, names, flag: str) -> None:
    """Refuse (`ValueError`) a parameter in `names` that the scene's options make irrelevant
    (`Scene.ignored_params`), naming the option setting that makes it count."""
    ignored = scene.ignored_params()
    for name in names:
        if name in ignored:
            options = ", ".join(f"{k}={v}" for k, v in scene.options.items())
            raise ValueError(
                f"{flag} {name}: scene {scene.name!r} with {options} does not use {name!r}; it "
                f"counts with --scene-option {ignored[name]}"
            )


def scene_of(name: str, args):
    """The scene `name` of a command line, built with its `--scene-option`s; an unknown scene
    or option, or a bad option value, raises `ValueError` naming the valid ones."""
    from ..scenes import SCENES, get_scene

    if name not in SCENES:
        raise ValueError(f"unknown scene {name!r}; valid: {', '.join(sorted(SCENES))}")
    try:
        return get_scene(name, **parse_pairs(args.scene_option, "--scene-option"))
    except (ValueError, TypeError) as err:
        raise ValueError(f"--scene-option: {err}") from None


def scene_settings(scene, args) -> tuple[dict, dict, object]:
    """`(assignments, params, control)` of a command line for `scene`: its `--set` values,
    checked (names, ranges, and used by the scene's options); the complete parameters; the
    `StepControl` of the step-control flags. A bad one raises `ValueError` naming it."""
    assignments = parse_assignments(args.set)
    params = scene.resolve_params(assignments)
    check_used(scene, assignments, "--set")
    return assignments, params, step_control(args, scene)
