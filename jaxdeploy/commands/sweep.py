"""`jaxdeploy sweep --scene S --grid NAME=v1,v2,... --out DIR [--resume] [--policy P]`: run the
Cartesian product of parameter values as batched chunks sharded over all devices, written
chunk by chunk, resumable (see `jaxdeploy.sweep`); then every finished case's features
(summary quantities, objective terms) as features.csv/features.json and overview.png."""

from __future__ import annotations

import os
import sys

from ._args import (
    OBJECTIVE_PRESETS,
    SCENE_OPTION_HELP,
    SET_HELP,
    SWEEP_CHUNK_SIZE,
    add_step_control,
    check_used,
    integer_at_least,
    positive,
    refuse,
    scene_of,
    scene_settings,
)

NAME = "sweep"
HELP = "parameter sweep: vmapped, sharded, chunked, resumable"


def add_arguments(parser) -> None:
    parser.add_argument("--scene", default="deploy_array", help="scene name (default deploy_array)")
    parser.add_argument(
        "--grid",
        action="append",
        default=[],
        metavar="NAME=VALUES",
        help="a swept parameter (repeatable, each NAME once): v1,v2,... or LOW:HIGH:N (linear) "
        "or LOW:HIGH:N:log (geometric), SI units; default: none (one case)",
    )
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help=SET_HELP)
    parser.add_argument(
        "--scene-option", action="append", default=[], metavar="KEY=VALUE", help=SCENE_OPTION_HELP
    )
    parser.add_argument(
        "--out",
        default=None,
        help="output folder (default results/sweep/SCENE-DATE-TIME; --resume needs it)",
    )
    parser.add_argument("--resume", action="store_true", help="continue the sweep in --out")
    parser.add_argument(
        "--t-end",
        type=positive("--t-end", "s"),
        default=None,
        help="end time [s], > 0; default: the scene's (`jaxdeploy scenes SCENE`)",
    )
    parser.add_argument(
        "--n-save",
        type=integer_at_least("--n-save", 2),
        default=201,
        help="saved states per case, ≥ 2 (default 201)",
    )
    parser.add_argument(
        "--chunk-size",
        type=integer_at_least("--chunk-size", 1),
        default=None,
        help="cases per compiled run (memory, resume granularity), ≥ 1 (default "
        f"{SWEEP_CHUNK_SIZE})",
    )
    parser.add_argument(
        "--policy",
        default=None,
        metavar="POLICY",
        help="how each device batches its cases: all (one vmap, the default) or groups:G "
        "(vmapped groups of G one after another); recorded in the manifest",
    )
    parser.add_argument(
        "--objective",
        action="append",
        default=[],
        metavar="PANEL:FEATURE=WEIGHT",
        help="design objective terms PANEL:FEATURE=WEIGHT or a preset ("
        + ", ".join(OBJECTIVE_PRESETS)
        + "), stored per case (deploy_array; repeatable); default: none",
    )
    parser.add_argument("--no-trajectories", action="store_true", help="store no q, v")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument(
        "--distributed", action="store_true", help="call jax.distributed.initialize() first"
    )
    add_step_control(parser)


GRID_FORMS = "v1,v2,... or LOW:HIGH:N or LOW:HIGH:N:log"


def parse_values(name: str, text: str) -> list[float]:
    """`v1,v2,...`, `LOW:HIGH:N` or `LOW:HIGH:N:log` as a list of finite numbers; anything
    else raises `ValueError` naming `--grid NAME` and the valid forms."""
    import math

    import numpy as np

    def bad(reason):
        return ValueError(f"--grid {name}={text!r}: {reason}; expected {GRID_FORMS}")

    if ":" in text:
        parts = text.split(":")
        if len(parts) not in (3, 4) or (len(parts) == 4 and parts[3] != "log"):
            raise bad("malformed range")
        try:
            low, high, n = float(parts[0]), float(parts[1]), int(parts[2])
        except ValueError:
            raise bad("LOW and HIGH must be numbers, N an integer") from None
        if not (math.isfinite(low) and math.isfinite(high)):
            raise bad("LOW and HIGH must be finite")
        if n < 1:
            raise bad(f"N = {n} must be ≥ 1")
        if len(parts) == 4:
            if not (low > 0 and high > 0):
                raise bad("a log grid needs LOW, HIGH > 0")
            return np.geomspace(low, high, n).tolist()
        return np.linspace(low, high, n).tolist()
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise bad("a value is not a number") from None
    if not values:
        raise bad("no values")
    if not all(math.isfinite(v) for v in values):
        raise bad("values must be finite")
    return values


def parse_grid(items: list[str], fixed=()) -> dict[str, list[float]]:
    """`--grid` items as `{name: values}`; a malformed item, a NAME given twice or also fixed
    by `--set` (names in `fixed`) raises `ValueError`."""
    grid = {}
    for item in items:
        name, sep, text = item.partition("=")
        name = name.strip()
        if not sep or not name:
            raise ValueError(f"--grid expects NAME=VALUES, got {item!r}")
        if name in grid:
            raise ValueError(
                f"--grid {name} is given twice; give all its values in one --grid {name}=v1,v2,..."
            )
        if name in fixed:
            raise ValueError(f"{name} is both swept (--grid) and fixed (--set); give one")
        grid[name] = parse_values(name, text)
    if not grid:
        raise ValueError("give at least one --grid NAME=VALUES")
    return grid


def _distributed_from_environment() -> dict:
    """`jax.distributed.initialize` arguments from `JAX_NUM_PROCESSES` and `JAX_PROCESS_ID`
    when set (JAX itself reads only `JAX_COORDINATOR_ADDRESS` from the environment); unset,
    JAX's cluster auto-detection (SLURM, Open MPI, …) supplies them."""
    options = {}
    for key, name in (("num_processes", "JAX_NUM_PROCESSES"), ("process_id", "JAX_PROCESS_ID")):
        text = os.environ.get(name)
        if text is not None:
            try:
                options[key] = int(text)
            except ValueError:
                raise ValueError(f"{name} = {text!r} is invalid: it must be an integer") from None
    return options


def run(args) -> int:
    import jax

    if args.distributed:
        try:
            jax.distributed.initialize(**_distributed_from_environment())
        except ValueError as err:
            return refuse(f"--distributed: {err}")

    import numpy as np

    from ..analysis import analysis_class
    from ..batch import reference_run
    from ..io import default_output_dir
    from ..sweep import DEFAULT_CHUNK_SIZE, DEFAULT_POLICY, grid_cases, parse_policy, sweep
    from . import _reference_cache
    from ._results import run_quantities

    # Every refusal happens before anything is written or compiled (the ideal reference of an
    # --objective is a simulation: it comes after the checks).
    if args.resume and args.out is None:
        return refuse("--resume continues the sweep in --out: give --out")
    try:
        scene = scene_of(args.scene, args)
        fixed, _, control = scene_settings(scene, args)
        grid = parse_grid(args.grid, fixed)
        cases = grid_cases(grid)
        rows = zip(*cases.values(), strict=True)
        for row in rows:  # names and ranges of every case (cheap: no simulation)
            scene.resolve_params({**fixed, **dict(zip(cases, row, strict=True))})
        check_used(scene, grid, "--grid")
        policy = DEFAULT_POLICY if args.policy is None else args.policy
        parse_policy(policy)
        objective = None
        if args.objective:
            from ..objectives import parse_objective

            objective = parse_objective(args.objective)
    except ValueError as err:
        return refuse(str(err))
    t_end = scene.default_t_end if args.t_end is None else args.t_end
    out = args.out or default_output_dir("sweep", scene.name)
    evaluate, features = None, None

    analysis_type = analysis_class(scene)
    with_reference = analysis_type.uses_reference and scene.ideal_counterpart() is not None

    def reference_for(params, trajectory):
        # The ideal-joint reference (`_reference_cache`): one per set of the parameters the
        # ideal mechanism uses, so a sweep over the hinges' contact shares one.
        if not with_reference:
            return None
        ts = np.asarray(trajectory.ts)
        run, _ = _reference_cache.reference(
            scene, params, ts, lambda: reference_run(scene, params, ts)
        )
        return run

    def summarize(params, trajectory):
        # What `jaxdeploy simulate` would report for this case (docs/results.md).
        quantities = run_quantities(trajectory)
        try:
            reference = reference_for(params, trajectory)
            mechanism = scene.build(params)
            analysis = analysis_type(scene, params, mechanism, trajectory, reference)
            quantities.update(analysis.summary())
        except Exception:
            # A failed case's states past the failure may be NaN and leave nothing to
            # summarize: it keeps its status and steps (and null for the rest). A successful
            # case whose summary fails is a bug: raise it.
            if trajectory.ok:
                raise
        return quantities

    try:
        if objective is not None:
            from ..optimize import DesignProblem

            problem = DesignProblem(
                scene, objective, t_end, n_save=args.n_save, fixed=fixed, control=control
            )

            def evaluate(params, trajectory):
                dep, _ = problem.deployment({k: params[k] for k in grid}, trajectory)
                return {"objective": objective(dep), **objective.parts(dep)}

            features = ",".join(args.objective)
        manifest = sweep(
            scene,
            grid,
            out,
            t_end=t_end,
            n_save=args.n_save,
            fixed=fixed,
            control=control,
            chunk_size=DEFAULT_CHUNK_SIZE if args.chunk_size is None else args.chunk_size,
            policy=policy,
            resume=args.resume,
            evaluate=evaluate,
            features=features,
            summarize=summarize,
            save_trajectories=not args.no_trajectories,
            progress=not args.quiet,
        )
    except (ValueError, FileExistsError) as err:
        return refuse(str(err))
    except RuntimeError as err:  # the objective's ideal reference run failed
        print(f"error: {err}", file=sys.stderr)
        return 1
    failed = sum(c["failed"] for c in manifest["chunks"])
    done = sum(c["stop"] - c["start"] for c in manifest["chunks"])
    written = [os.path.join(out, "manifest.json")]
    if jax.process_index() == 0 and done:
        from ..sweep import load_sweep
        from ._sweep_outputs import plot_overview, write_features

        data = load_sweep(out)
        written += write_features(out, scene, data, list(grid))
        figure = plot_overview(out, scene, data, list(grid), grid)
        written += [] if figure is None else [figure]
    if not args.quiet:
        print(
            f"sweep: {done}/{manifest['n_cases']} cases in {len(manifest['chunks'])} chunks, "
            f"{failed} failed; wrote " + ", ".join(written)
        )
    return 0 if failed == 0 and done == manifest["n_cases"] else 1
