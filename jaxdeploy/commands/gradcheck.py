"""`jaxdeploy gradcheck SCENE --output NAME --params P ... [--set ...] [--out DIR]`: check
the derivative of one scalar output (an event time such as deploy_array's `lock_time`, or
slider_crank's `first_onset_time`) by AD, forward and reverse mode, against central
differences over a sweep of steps, replayed and rerun (`jaxdeploy.fit.gradient_check`).
By default every run is at a step tolerance checked for its derivatives (tightened until the
AD derivatives change by at most --derivative-change at a 10x tighter one; the line
"step tolerance: …" and gradcheck.json's `step_tolerance` say which and why).
Writes gradcheck.json and gradcheck.png; exit code 0 when AD agrees with the converged
differences for every parameter, 1 when not."""

from __future__ import annotations

import sys

from ._args import (
    SCENE_OPTION_HELP,
    SET_HELP,
    add_derivative_tolerance_check,
    add_step_control,
    integer_at_least,
    number_in,
    positive,
    refuse,
    scene_of,
    scene_settings,
)

NAME = "gradcheck"
HELP = "check an output's derivative: AD (forward, reverse) against differences over steps"
MODES = ("forward", "reverse")


def add_arguments(parser) -> None:
    parser.add_argument("scene", help="scene name (`jaxdeploy scenes` lists them)")
    parser.add_argument(
        "--output",
        required=True,
        help="a scalar output of the scene: an event output (deploy_array: lock_time, "
        "panel1_first_onset_time, …; slider_crank: first_onset_time)",
    )
    parser.add_argument(
        "--params", nargs="+", required=True, metavar="P", help="parameters to differentiate"
    )
    parser.add_argument(
        "--scene-option", action="append", default=[], metavar="KEY=VALUE", help=SCENE_OPTION_HELP
    )
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help=SET_HELP)
    parser.add_argument(
        "--t-end",
        type=positive("--t-end", "s"),
        default=None,
        help="horizon [s] (default: the scene's; it must reach the event)",
    )
    parser.add_argument(
        "--steps",
        nargs="+",
        type=number_in("--steps", 0.0, 1.0, high_open=True),
        default=None,
        metavar="H",
        help="relative steps h/|θ| of the sweep, each in (0, 1) (default 1e-2 … 1e-7)",
    )
    parser.add_argument(
        "--tolerance",
        type=number_in("--tolerance", 0.0, 1.0, high_open=True),
        default=1e-2,
        help="relative agreement of AD with the converged differences, in (0, 1) (default 0.01)",
    )
    add_derivative_tolerance_check(parser, "", "the AD derivatives", "--tolerance / 10")
    parser.add_argument(
        "--modes",
        nargs="+",
        choices=MODES,
        default=list(MODES),
        help="AD modes (the first is judged, the others reported; default forward reverse)",
    )
    parser.add_argument(
        "--n-save",
        type=integer_at_least("--n-save", 2),
        default=2,
        help="saved states, ≥ 2 (default 2)",
    )
    parser.add_argument(
        "--out", default=None, help="output folder (default results/gradcheck/SCENE-DATE-TIME)"
    )
    parser.add_argument("--overwrite", action="store_true", help="replace an existing result")
    parser.add_argument("--quiet", action="store_true", help="no progress lines")
    add_step_control(parser)


def _validate(args):
    """Every refusal, before anything is compiled: `(scene, params, control, out)`."""
    from ..io import check_output_dir, default_output_dir

    scene = scene_of(args.scene, args)
    _, params, control = scene_settings(scene, args)
    unknown = [p for p in args.params if p not in scene.params]
    if unknown:
        raise ValueError(
            f"--params: unknown parameter {unknown[0]!r} for scene {scene.name!r}; valid: "
            + ", ".join(sorted(scene.params))
        )
    if len(set(args.params)) != len(args.params):
        raise ValueError("--params: a parameter is given twice")
    ignored = scene.ignored_params()
    unused = [p for p in args.params if p in ignored]
    if unused:
        raise ValueError(
            f"--params {unused[0]}: scene {scene.name!r} does not use it (it counts with "
            f"--scene-option {ignored[unused[0]]})"
        )
    if len(set(args.modes)) != len(args.modes):
        raise ValueError("--modes: a mode is given twice")
    out = args.out or default_output_dir("gradcheck", scene.name)
    check_output_dir(out, args.overwrite)
    _plan_run(args, scene, params, control)
    return scene, params, control, out


def _plan_run(args, scene, params, control) -> None:
    from . import _plan

    _plan.check_derivative_run(
        scene,
        params,
        control,
        args.n_save,
        f"--n-save = {args.n_save} saved states of {scene.name} (a run, its derivative and a "
        "difference run)",
        "lower --n-save",
    )


# Without --t-end, an event time is checked over a horizon this much past the event (the
# largest default step, 1e-2, moves deploy_array's lock by ~0.5 %).
HORIZON_MARGIN = 1.05


def _horizon(scene, params, args, control) -> float:
    """The run's horizon without --t-end: for an event time (`*_time`), one run to the scene's
    default horizon finds the event and the check runs to `HORIZON_MARGIN` times it (the cost
    of every difference run is then that of reaching the event); else the scene's horizon."""
    import math

    import jax

    from ..batch import run_scene

    if not args.output.endswith("_time"):
        return scene.default_t_end
    horizon = scene.default_t_end
    if not args.quiet:
        print(
            f"gradcheck: locating {args.output} within the scene's horizon {horizon:g} s "
            "(give --t-end to skip)",
            file=sys.stderr,
            flush=True,
        )
    run = jax.jit(lambda: run_scene(scene, params, horizon, n_save=2, control=control))()
    events = scene.events(scene.build(params), run)
    if args.output not in events:
        raise ValueError(
            f"output {args.output!r} is not an event output of scene {scene.name!r}; valid: "
            + (", ".join(sorted(events)) or "none")
        )
    t_event = float(events[args.output])
    if not math.isfinite(t_event):
        raise ValueError(f"{args.output} is not reached within {horizon:g} s: give --t-end")
    return min(horizon, HORIZON_MARGIN * t_event)


def _write(folder, check, args, scene, control, t_end) -> None:
    """gradcheck.json and gradcheck.png into the run's staging folder, then moved into place
    (`_output_folder`: an older result is replaced whole)."""
    from ..io import atomic_write_json, run_metadata

    used = control if check.step_tolerance is None else check.step_tolerance.control
    record = {
        **check.to_json(),
        "scene_options": scene.options,
        "t_end_s": t_end,
        "step_control": used.to_json(),
        "meta": run_metadata(),
    }
    atomic_write_json(folder.file("gradcheck.json"), record)
    check.plot(folder.file("gradcheck.png"))
    folder.commit()


def run(args) -> int:
    """validate → plan (tolerances, memory, the folder's lock) → check → write; every refusal
    (exit 2) comes before anything is compiled or written."""
    from . import _plan

    try:
        scene, params, control, out = _validate(args)
        folder = _plan.claim_output(out, args.overwrite)
    except (ValueError, FileExistsError) as err:
        return refuse(str(err))
    with folder:
        return _check(args, scene, params, control, folder)


def _check(args, scene, params, control, folder) -> int:
    from ..fit import DEFAULT_STEPS, gradient_check

    def progress(message):
        if not args.quiet:
            print(f"gradcheck: {message}", file=sys.stderr, flush=True)

    try:
        t_end = args.t_end if args.t_end is not None else _horizon(scene, params, args, control)
        check = gradient_check(
            scene,
            params,
            args.params,
            args.output,
            t_end,
            steps=tuple(args.steps or DEFAULT_STEPS),
            tolerance=args.tolerance,
            modes=tuple(args.modes),
            n_save=args.n_save,
            control=control,
            check_step_tolerance=not args.no_step_tolerance_check,
            derivative_change=args.derivative_change,
            progress=progress,
        )
    except (ValueError, RuntimeError) as err:  # output unknown or not reached, a run failed
        print(f"error: {err}", file=sys.stderr)
        return 1
    _write(folder, check, args, scene, control, t_end)
    print(check.table())
    print(f"wrote {folder.shown}/gradcheck.json, gradcheck.png")
    return 0 if check.verdict == "agree" else 1
