"""`jaxdeploy optimize --scene deploy_array --objective SPEC [--out DIR]`: choose parameters
(default: per-panel hinge roughness and clearance) within machinable bounds by gradient steps
(optax), writing the best design found, the objective history and its plot (see
`jaxdeploy.optimize`)."""

from __future__ import annotations

import sys

from ._args import (
    OBJECTIVE_PRESETS,
    SCENE_OPTION_HELP,
    SET_HELP,
    add_derivative_tolerance_check,
    add_step_control,
    check_used,
    integer_at_least,
    parse_assignments,
    positive,
    refuse,
    scene_of,
    step_control,
)
from ._devices import DEVICES_HELP

NAME = "optimize"
HELP = "choose Ra, clearance (or any parameter) by gradients on a deployment objective"
DEFAULT_PARAMS = ("panel1_ra", "panel2_ra", "panel1_clearance", "panel2_clearance")


def add_arguments(parser) -> None:
    parser.add_argument(
        "--scene", default="deploy_array", help="scene (needs panel channels; default deploy_array)"
    )
    parser.add_argument(
        "--scene-option", action="append", default=[], metavar="KEY=VALUE", help=SCENE_OPTION_HELP
    )
    parser.add_argument(
        "--objective",
        action="append",
        default=[],
        metavar="PANEL:FEATURE=WEIGHT",
        help="objective terms PANEL:FEATURE=WEIGHT or a preset ("
        + ", ".join(OBJECTIVE_PRESETS)
        + "); repeatable; default: paper",
    )
    parser.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="NAME[=LOW:HIGH]",
        help="design parameter and bounds (SI, LOW < HIGH; each NAME once); *_ra, *_clearance "
        "default to the machinable range. Default: " + ", ".join(DEFAULT_PARAMS),
    )
    parser.add_argument(
        "--start",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="start value of a design parameter, strictly inside its bounds (default: the "
        "scene's value, or the bounds' centre when that lies outside them)",
    )
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help=SET_HELP)
    parser.add_argument(
        "--t-end", type=positive("--t-end", "s"), default=0.75, help="horizon [s] (default 0.75)"
    )
    parser.add_argument(
        "--n-save",
        type=integer_at_least("--n-save", 2),
        default=1501,
        help="saved states, ≥ 2 (default 1501)",
    )
    parser.add_argument(
        "--steps",
        type=integer_at_least("--steps", 1),
        default=12,
        help="gradient evaluations, ≥ 1 (default 12)",
    )
    parser.add_argument(
        "--learning-rate",
        type=positive("--learning-rate"),
        default=0.25,
        help="Adam step in the reparametrised (dimensionless) coordinate u, > 0 (default 0.25)",
    )
    parser.add_argument(
        "--gradient",
        choices=("smoothed", "pathwise"),
        default="smoothed",
        help="smoothed: Stein estimate on a Gaussian smoothing (robust to chatter); "
        "pathwise: AD through the solver (forward mode up to 6 parameters, reverse above); "
        "default smoothed",
    )
    add_derivative_tolerance_check(
        parser, "--gradient pathwise: ", "the gradient at the start", "1e-3, as gradcheck"
    )
    # deploy_array's objectives are rough below about half a unit of ln Ra (contact events
    # shift with the design): smoothing at s = 0.1 follows that roughness, at 0.5 the trend
    # (the 9x9 design study of commit d3c11ca, its section "Gradient-based optimum": `git show
    # d3c11ca:docs/design.md`; today's docs/design.md reruns a 4x4 grid only).
    parser.add_argument(
        "--smoothing",
        type=positive("--smoothing"),
        default=0.5,
        help="standard deviation of the Gaussian smoothing in ln x (dimensionless; --gradient "
        "smoothed), > 0 (default 0.5)",
    )
    parser.add_argument(
        "--pairs",
        type=integer_at_least("--pairs", 1),
        default=4,
        help="antithetic pairs per step, ≥ 1 (default 4)",
    )
    parser.add_argument(
        "--robust",
        action="store_true",
        help="minimise E[J] under manufacturing scatter (--tol-ra, --tol-clearance)",
    )
    parser.add_argument(
        "--tol-ra",
        type=positive("--tol-ra"),
        default=0.25,
        help="manufacturing scatter of the roughness Ra: the standard deviation of ln Ra "
        "(dimensionless, log-normal; --robust), > 0 (default 0.25)",
    )
    parser.add_argument(
        "--tol-clearance",
        type=positive("--tol-clearance", "m"),
        default=5e-6,
        help="manufacturing scatter of the clearance: its standard deviation [m] (--robust), "
        "> 0 (default 5e-06 m)",
    )
    parser.add_argument(
        "--seed", type=int, default=0, help="seed of the smoothing draws (default 0)"
    )
    parser.add_argument(
        "--out", default=None, help="output folder (default results/optimize/SCENE-DATE-TIME)"
    )
    parser.add_argument("--overwrite", action="store_true", help="replace an existing result")
    parser.add_argument("--quiet", action="store_true", help="no progress lines")
    parser.add_argument(
        "--devices",
        type=integer_at_least("--devices", 1),
        default=None,
        help=DEVICES_HELP + "; the smoothed gradient's designs run side by side",
    )
    add_step_control(parser)


def _parse_params(items, scene, machinable):
    import math

    names = {}
    for item in items or DEFAULT_PARAMS:
        name, sep, text = item.partition("=")
        name = name.strip()
        if name not in scene.params:
            raise ValueError(
                f"--param: unknown parameter {name!r} for scene {scene.name!r}; valid: "
                + ", ".join(sorted(scene.params))
            )
        if name in names:
            raise ValueError(f"--param {name} is given twice")
        if sep:
            try:
                low, high = (float(v) for v in text.split(":"))
            except ValueError:
                raise ValueError(f"--param {item!r}: expected NAME=LOW:HIGH") from None
            if not (math.isfinite(low) and math.isfinite(high) and low < high):
                raise ValueError(
                    f"--param {item!r}: bounds must be finite with low < high"
                ) from None
            names[name] = (low, high)
        else:
            names[name] = machinable(scene, [name])[name]
    return names


def _start(scene, bounds, defaults, start):
    """The start design: `--start` values (refused outside the bounds), else the scene's
    value, moved to the bounds' centre when it lies outside them (said in `notes`)."""
    import math

    x0, notes = {}, []
    for name, value in start.items():
        if name not in bounds:
            raise ValueError(f"--start {name}: not a design parameter ({', '.join(bounds)})")
        lo, hi = bounds[name]
        if not lo < value < hi:
            raise ValueError(
                f"--start {name} = {value:g} is invalid: it must lie strictly inside the "
                f"bounds ({lo:g}, {hi:g}) {scene.params[name].unit}".rstrip()
            )
    for name, (lo, hi) in bounds.items():
        value = start.get(name, defaults[name])
        if not lo < value < hi:
            centre = math.sqrt(lo * hi) if lo > 0 else 0.5 * (lo + hi)
            notes.append(
                f"{name}: the scene's value {value:g} lies outside the bounds ({lo:g}, {hi:g}); "
                f"starting at their {'geometric ' if lo > 0 else ''}centre {centre:g}"
            )
            value = centre
        x0[name] = value
    return x0, notes


def run(args) -> int:
    import time

    from ..io import check_output_dir, default_output_dir
    from ..objectives import parse_objective
    from ..optimize import Box, machinable_bounds
    from ._devices import split_host

    # Every refusal happens here, before anything is written or compiled (the ideal
    # reference run of `DesignProblem` is a simulation: it comes after). The devices first:
    # JAX takes their count when it starts.
    refusal = split_host(args.devices)
    if refusal is not None:
        return refuse(refusal)
    try:
        scene = scene_of(args.scene, args)
    except ValueError as err:
        return refuse(str(err))
    try:
        objective = parse_objective(args.objective or ["paper"])
        bounds = _parse_params(args.param, scene, machinable_bounds)
        Box(bounds)
        fixed = parse_assignments(args.set)
        both = sorted(set(fixed) & set(bounds))
        if both:
            raise ValueError(f"{both[0]} is both a design parameter (--param) and fixed (--set)")
        start = parse_assignments(args.start, "--start")
        defaults = scene.resolve_params(fixed)
        check_used(scene, fixed, "--set")
        check_used(scene, bounds, "--param")
        x0, notes = _start(scene, bounds, defaults, start)
        for name, value in x0.items():  # the start must be a valid scene parameter too
            scene.resolve_params({**fixed, name: value})
        _check_tolerance_flags(args)
        control = step_control(args, scene)
        _plan_run(args, scene, scene.resolve_params({**fixed, **x0}), control)
        out = args.out or default_output_dir("optimize", scene.name)
        check_output_dir(out, args.overwrite)
    except (ValueError, FileExistsError) as err:
        return refuse(str(err))
    from . import _plan

    try:
        folder = _plan.claim_output(out, args.overwrite)
    except FileExistsError as err:
        return refuse(str(err))
    if not args.quiet:
        for note in notes:
            print(f"note: {note}", file=sys.stderr)
    began = time.perf_counter()
    with folder:
        return _optimize(args, scene, objective, bounds, fixed, x0, control, folder, began)


def _plan_run(args, scene, params, control) -> None:
    from . import _plan

    _plan.check_derivative_run(
        scene,
        params,
        control,
        args.n_save,
        f"--n-save = {args.n_save} saved states of {scene.name} (a run, its derivative and "
        "the ideal reference)",
        "lower --n-save",
    )


def _optimize(args, scene, objective, bounds, fixed, x0, control, folder, began) -> int:
    """The optimisation's stages: the smoothing, the design batch's runs made ahead (a
    second thread), then the problem (the ideal reference) and the optimisation itself."""
    import diffrax as dfx

    from .. import _program_cache
    from ..fit import gradient_mode

    pathwise = args.gradient == "pathwise" and not args.robust
    # Forward mode up to fit's parameter count (its runs use diffrax.ForwardMode, which
    # reverse mode cannot differentiate), reverse mode with checkpoints above.
    mode = gradient_mode(len(bounds))
    smoothing = _smoothing(args, scene, bounds, scene.resolve_params(fixed), pathwise)
    adjoint = dfx.ForwardMode() if pathwise and mode == "forward" else None
    ahead = None
    if smoothing is not None and _program_cache.folder() is not None:
        ahead = _batch_ahead(scene, objective, args, fixed, control, smoothing, bounds)
        ahead.wait_traced()
    try:
        return _optimize_problem(args, scene, objective, bounds, fixed, x0, control, folder,
                                 began, smoothing, adjoint, mode)  # fmt: skip
    finally:
        if ahead is not None:
            ahead.join()


def _smoothing(args, scene, bounds, params, pathwise):
    """The `Scatter` of the smoothed (or, `--robust`, the tolerance-averaged) objective, or
    None for a pathwise gradient; `params` the resolved scene parameters."""
    from ..optimize import Scatter

    if args.robust:
        ra = {n: args.tol_ra for n in scene.params if n.endswith("_ra")}
        cl = {n: args.tol_clearance for n in scene.params if n.endswith("_clearance")}
        nominal = {n: params[n] for n in (*ra, *cl) if n not in bounds}
        return Scatter(ra, cl, pairs=args.pairs, seed=args.seed, nominal=nominal)
    if pathwise:
        return None
    return Scatter(
        relative={n: args.smoothing for n, (lo, _) in bounds.items() if lo > 0},
        absolute={n: args.smoothing * (hi - lo) for n, (lo, hi) in bounds.items() if lo <= 0},
        pairs=args.pairs,
        seed=args.seed,
    )


def _batch_ahead(scene, objective, args, fixed, control, smoothing, bounds):
    """The design batch's runs program (`optimize.prepare_batch`) made in a second thread
    (`_ahead.Ahead`) while `DesignProblem` runs the ideal reference, whose lock time the
    objective needs but the runs do not: from an empty cache (the README's optimize,
    deploy_array) the reference's assembly, trace and compile (~5 s) came before the batch's
    trace (~5 s) and XLA compile (~7 s); now the reference runs while XLA compiles the batch.
    Only with the program cache on: a plain `jit` call could not find the program again."""
    from ..optimize import DesignRuns, prepare_batch
    from ._ahead import Ahead

    runs = DesignRuns(scene, args.t_end, n_save=args.n_save, fixed=fixed, control=control)
    names = [*smoothing.nominal, *bounds]  # the designs' parameters (`Scatter.antithetic`)

    def make(on_traced):
        prepare_batch(runs, objective, names, 2 * smoothing.pairs, on_traced=on_traced)

    return Ahead("optimize-batch-ahead", make)


def _optimize_problem(
    args, scene, objective, bounds, fixed, x0, control, folder, began, smoothing, adjoint, mode
) -> int:
    import os
    import time

    from ..io import atomic_write_json, run_metadata
    from ..optimize import BatchObjective, DesignProblem, optimize

    pathwise = smoothing is None
    try:
        problem = DesignProblem(
            scene,
            objective,
            args.t_end,
            n_save=args.n_save,
            fixed=fixed,
            control=control,
            adjoint=adjoint,
        )
    except (RuntimeError, ValueError) as err:  # the ideal reference failed or did not lock
        print(f"error: {err}", file=sys.stderr)
        return 1
    loss = problem.evaluate if smoothing is None else BatchObjective(problem)

    def progress(i, result):
        if args.quiet:
            return
        x = ", ".join(f"{k}={v:.4g}" for k, v in result.x[-1].items())
        elapsed = time.perf_counter() - began
        # The first iteration includes compilation; later ones are alike, so the ETA uses them.
        per_step = sum(result.wall_time[1:]) / max(len(result.wall_time) - 1, 1)
        eta = per_step * (args.steps - i - 1) if i > 0 else float("nan")
        eta_text = "" if eta != eta else f", ETA {eta:.0f} s"
        print(
            f"[{i + 1}/{args.steps}] J = {result.objective[-1]:.5g}  {x}  "
            f"(iteration {result.wall_time[-1]:.1f} s, elapsed {elapsed:.0f} s{eta_text})",
            file=sys.stderr,
            flush=True,
        )

    result = optimize(
        loss,
        x0,
        bounds,
        steps=args.steps,
        learning_rate=args.learning_rate,
        smoothing=smoothing,
        callback=progress,
        mode=mode,
        **_tolerance_search(args, problem, pathwise),
    )
    if result.step_tolerance is not None and not args.quiet:
        print(result.step_tolerance.summary(), file=sys.stderr)
    design_control = problem.step_control
    if result.step_tolerance is not None:
        design_control = result.step_tolerance.control
    record = {
        "scene": args.scene,
        "scene_options": scene.options,
        "status": result.status,
        "objective": [f"{t.label}={t.weight}" for t in objective.terms],
        "gradient": "pathwise" if pathwise else ("robust" if args.robust else "smoothed"),
        "bounds": bounds,
        "units": {name: scene.params[name].unit for name in bounds},
        "start": x0,
        "t_end_s": args.t_end,
        "n_save": args.n_save,
        "steps": args.steps,
        "learning_rate": args.learning_rate,
        "seed": args.seed,
        "scatter": None
        if smoothing is None
        else {
            "relative": dict(smoothing.relative),
            "absolute": dict(smoothing.absolute),
            "pairs": smoothing.pairs,
            "nominal": dict(smoothing.nominal),
            # The designs' devices: a vmapped design's last bits depend on its batch.
            "devices": len(loss.devices),
        },
        "params": problem.fixed,
        "step_control": design_control.to_json(),
        "ideal_lock_time_s": problem.lock_time,
        "wall_time_s": time.perf_counter() - began,
        **result.to_json(),
        "versions": run_metadata(),
    }
    figure = os.path.basename(_plot(result, scene, folder.staging))
    atomic_write_json(folder.file("result.json"), record)
    folder.commit()
    out = folder.shown
    if result.optimum is None:
        print(f"no successful iterate: {result.status}", file=sys.stderr)
    elif not args.quiet:
        print(
            "best: "
            + ", ".join(f"{k}={v:.4g}" for k, v in result.optimum.items())
            + f"  J = {result.objective[result.best]:.5g} (iteration {result.best + 1})"
        )
    if result.status != "ok":
        print(f"error: {result.status}", file=sys.stderr)
    if not args.quiet:
        print(f"wrote {out}/result.json, {out}/{figure} (objective history)")
    return 0 if result.status == "ok" else 1


def _check_tolerance_flags(args) -> None:
    """--derivative-change and --no-step-tolerance-check: pathwise gradients only, not both."""
    given = [flag for flag, value in (("--derivative-change", args.derivative_change is not None),
             ("--no-step-tolerance-check", args.no_step_tolerance_check)) if value]  # fmt: skip
    if len(given) == 2:
        raise ValueError("--derivative-change and --no-step-tolerance-check exclude each other")
    if given and (args.gradient != "pathwise" or args.robust):
        raise ValueError(f"{given[0]} is for --gradient pathwise (without --robust)")


def _tolerance_search(args, problem, pathwise) -> dict:
    """`optimize`'s step-control keywords: a pathwise gradient runs at the tolerance at which
    it is converged at the start (`fit.converged_tolerance`, as `jaxdeploy gradcheck`), the
    control's tolerances data of the one compiled gradient program."""
    from ..fit import DERIVATIVE_CHANGE

    if not pathwise:
        return {}
    fraction = None if args.no_step_tolerance_check else args.derivative_change
    if fraction is None and not args.no_step_tolerance_check:
        fraction = DERIVATIVE_CHANGE

    def say(message):
        if not args.quiet:
            print(f"step tolerance: {message}", file=sys.stderr, flush=True)

    return {"control": problem.step_control, "derivative_change": fraction, "progress": say}


def _plot(result, scene, out):
    """The objective and each design parameter against the iteration, best iterate marked."""
    import os

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..io import atomic_savefig

    names = result.names
    iterations = range(1, len(result.x) + 1)
    fig, axes = plt.subplots(1 + len(names), 1, figsize=(6, 2.0 * (1 + len(names))), sharex=True)
    axes[0].plot(iterations, result.objective, "o-")
    axes[0].set_ylabel("objective J [-]")
    best = result.best
    if best is not None:
        axes[0].plot([best + 1], [result.objective[best]], "r*", ms=12, label="best")
        axes[0].legend(fontsize=8)
    for ax, name in zip(axes[1:], names, strict=True):
        ax.plot(iterations, [x[name] for x in result.x], "o-")
        unit = scene.params[name].unit if name in scene.params else ""
        ax.set_ylabel(f"{name} [{unit or '-'}]", fontsize=8)
    axes[-1].set_xlabel("iteration")
    fig.tight_layout()
    path = os.path.join(out, "history.png")
    atomic_savefig(fig, path, dpi=110)
    plt.close(fig)
    return path
