"""`jaxdeploy optimize --scene deploy_array --objective SPEC --out DIR`: choose parameters
(default: per-panel hinge roughness and clearance) within machinable bounds by gradient steps
(optax), writing the optimum, the objective history and plots (see `jaxdeploy.optimize`)."""

from __future__ import annotations

import sys

from . import SOLVER_HELP, solver_control

NAME = "optimize"
HELP = "choose Ra, clearance (or any parameter) by gradients on a deployment objective"
DEFAULT_PARAMS = ("panel1_ra", "panel2_ra", "panel1_clearance", "panel2_clearance")


def add_arguments(parser) -> None:
    parser.add_argument("--scene", default="deploy_array", help="scene (needs panel channels)")
    parser.add_argument(
        "--objective",
        action="append",
        default=[],
        metavar="PANEL:FEATURE=WEIGHT",
        help="objective terms or a preset (paper, paper_reproducible, quiet, fast_decay); "
        "repeatable",
    )
    parser.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="NAME[=LOW:HIGH]",
        help="design parameter and bounds (SI); *_ra, *_clearance default to the machinable "
        "range. Default: " + ", ".join(DEFAULT_PARAMS),
    )
    parser.add_argument("--start", action="append", default=[], metavar="NAME=VALUE")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE")
    parser.add_argument("--t-end", type=float, default=0.75, help="horizon [s] (default 0.75)")
    parser.add_argument("--n-save", type=int, default=1501, help="saved states")
    parser.add_argument("--steps", type=int, default=12, help="gradient evaluations")
    parser.add_argument("--learning-rate", type=float, default=0.25, help="Adam step (in u)")
    parser.add_argument(
        "--gradient",
        choices=("smoothed", "pathwise"),
        default="smoothed",
        help="smoothed: Stein estimate on a Gaussian smoothing (robust to chatter); "
        "pathwise: forward-mode AD through the solver",
    )
    # deploy_array's objectives are rough below about half a unit of ln Ra (contact events
    # shift with the design): smoothing at s = 0.1 follows that roughness, at 0.5 the trend
    # (docs/design.md, "Gradient-based optimum").
    parser.add_argument("--smoothing", type=float, default=0.5, help="s in ln x (smoothed)")
    parser.add_argument("--pairs", type=int, default=4, help="antithetic pairs per step")
    parser.add_argument(
        "--robust",
        action="store_true",
        help="minimise E[J] under manufacturing scatter (--tol-ra, --tol-clearance)",
    )
    parser.add_argument("--tol-ra", type=float, default=0.25, help="Ra log-normal s")
    parser.add_argument("--tol-clearance", type=float, default=5e-6, help="clearance σ [m]")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", required=True, help="output folder")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing result")
    parser.add_argument("--solver", default=None, metavar="NAME", help=SOLVER_HELP)
    parser.add_argument("--quiet", action="store_true", help="no progress lines")


def _parse_params(items, scene, machinable):
    names = {}
    for item in items or DEFAULT_PARAMS:
        name, sep, text = item.partition("=")
        name = name.strip()
        if name not in scene.params:
            raise ValueError(
                f"unknown parameter {name!r} for scene {scene.name!r}; valid: "
                + ", ".join(sorted(scene.params))
            )
        if sep:
            try:
                low, high = (float(v) for v in text.split(":"))
            except ValueError:
                raise ValueError(f"--param {item!r}: expected NAME=LOW:HIGH") from None
            names[name] = (low, high)
        else:
            names[name] = machinable(scene, [name])[name]
    return names


def run(args) -> int:
    import math
    import time

    import diffrax as dfx

    from ..io import atomic_write_json, check_output_dir, prepare_output_dir, run_metadata
    from ..objectives import parse_objective
    from ..optimize import (
        BatchObjective,
        Box,
        DesignProblem,
        Scatter,
        machinable_bounds,
        optimize,
    )
    from ..scenes import SCENES, get_scene
    from .simulate import parse_assignments

    if args.scene not in SCENES:
        print(f"error: unknown scene {args.scene!r}; valid: {', '.join(SCENES)}", file=sys.stderr)
        return 2
    scene = get_scene(args.scene)
    try:
        objective = parse_objective(args.objective or ["paper"])
        bounds = _parse_params(args.param, scene, machinable_bounds)
        Box(bounds)
        fixed = parse_assignments(args.set)
        start = parse_assignments(args.start)
        for name in start:
            if name not in bounds:
                raise ValueError(f"--start {name}: not a design parameter ({', '.join(bounds)})")
        defaults = scene.resolve_params(fixed)
        x0 = {}
        for name, (lo, hi) in bounds.items():
            value = start.get(name, defaults[name])
            if not lo < value < hi:  # the default outside the box: start at its log-centre
                value = math.sqrt(lo * hi) if lo > 0 else 0.5 * (lo + hi)
            x0[name] = value
        control = solver_control(scene, args.solver)
        if args.steps < 1:
            raise ValueError(f"--steps = {args.steps}: must be ≥ 1")
        if not args.t_end > 0:
            raise ValueError(f"--t-end = {args.t_end}: must be > 0 (s)")
        check_output_dir(args.out, args.overwrite)  # refuse before any work
    except (ValueError, FileExistsError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2

    began = time.perf_counter()
    pathwise = args.gradient == "pathwise" and not args.robust
    problem = DesignProblem(
        scene,
        objective,
        args.t_end,
        n_save=args.n_save,
        fixed=fixed,
        control=control,
        adjoint=dfx.ForwardMode() if pathwise else None,
    )
    smoothing = None
    if args.robust:
        ra = {n: args.tol_ra for n in scene.params if n.endswith("_ra")}
        cl = {n: args.tol_clearance for n in scene.params if n.endswith("_clearance")}
        nominal = {n: problem.fixed[n] for n in (*ra, *cl) if n not in bounds}
        smoothing = Scatter(ra, cl, pairs=args.pairs, seed=args.seed, nominal=nominal)
    elif not pathwise:
        smoothing = Scatter(
            relative={n: args.smoothing for n, (lo, _) in bounds.items() if lo > 0},
            absolute={n: args.smoothing * (hi - lo) for n, (lo, hi) in bounds.items() if lo <= 0},
            pairs=args.pairs,
            seed=args.seed,
        )
    loss = problem.evaluate if smoothing is None else BatchObjective(problem)

    def progress(i, result):
        if args.quiet:
            return
        x = ", ".join(f"{k}={v:.4g}" for k, v in result.x[-1].items())
        print(
            f"[{i + 1}/{args.steps}] J = {result.objective[-1]:.5g}  {x}  "
            f"({result.wall_time[-1]:.1f} s)",
            file=sys.stderr,
            flush=True,
        )

    try:
        result = optimize(
            loss,
            x0,
            bounds,
            steps=args.steps,
            learning_rate=args.learning_rate,
            smoothing=smoothing,
            callback=progress,
        )
        status = "ok"
    except RuntimeError as err:
        print(f"error: {err}", file=sys.stderr)
        return 1
    record = {
        "scene": args.scene,
        "objective": [f"{t.label}={t.weight}" for t in objective.terms],
        "gradient": "pathwise" if pathwise else ("robust" if args.robust else "smoothed"),
        "bounds": bounds,
        "start": x0,
        "t_end": args.t_end,
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
        },
        "params": problem.fixed,
        "ideal_lock_time": problem.lock_time,
        "status": status,
        "wall_time_s": time.perf_counter() - began,
        **result.to_json(),
        "versions": run_metadata(),
    }
    prepare_output_dir(args.out, args.overwrite)
    atomic_write_json(f"{args.out}/result.json", record)
    figure = _plot(result, args.out)
    print(
        "optimum: "
        + ", ".join(f"{k}={v:.4g}" for k, v in result.optimum.items())
        + f"  J = {result.objective[result.best]:.5g}"
    )
    print(f"wrote {args.out}/result.json, {figure}")
    return 0


def _plot(result, out):
    import os

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..io import atomic_savefig

    names = result.names
    fig, axes = plt.subplots(1 + len(names), 1, figsize=(6, 2.0 * (1 + len(names))), sharex=True)
    axes[0].plot(result.objective, "o-")
    axes[0].set_ylabel("J")
    for ax, name in zip(axes[1:], names, strict=True):
        ax.plot([x[name] for x in result.x], "o-")
        ax.set_ylabel(name, fontsize=8)
    axes[-1].set_xlabel("iteration")
    fig.tight_layout()
    path = os.path.join(out, "history.png")
    atomic_savefig(fig, path, dpi=110)
    plt.close(fig)
    return path
