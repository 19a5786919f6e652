"""`jaxdeploy sweep --scene S --grid NAME=v1,v2,... --out DIR [--resume] [--policy P]`: run the
Cartesian product of parameter values as batched chunks sharded over all devices, written
chunk by chunk, resumable (see `jaxdeploy.sweep`)."""

from __future__ import annotations

import sys

from . import SOLVER_HELP, solver_control

NAME = "sweep"
HELP = "parameter sweep: vmapped, sharded, chunked, resumable"


def add_arguments(parser) -> None:
    parser.add_argument("--scene", default="deploy_array", help="scene name")
    parser.add_argument(
        "--grid",
        action="append",
        default=[],
        metavar="NAME=VALUES",
        help="values: v1,v2,... or LOW:HIGH:N (linear) or LOW:HIGH:N:log (geometric), SI units",
    )
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE")
    parser.add_argument("--out", required=True, help="output folder")
    parser.add_argument("--resume", action="store_true", help="continue the sweep in --out")
    parser.add_argument("--t-end", type=float, default=None, help="end time [s]")
    parser.add_argument("--n-save", type=int, default=201, help="saved states per case")
    parser.add_argument(
        "--chunk-size",
        type=int,
        default=None,
        help="cases per compiled run (memory, resume granularity); default "
        "jaxdeploy.sweep.DEFAULT_CHUNK_SIZE",
    )
    parser.add_argument(
        "--policy",
        default=None,
        metavar="POLICY",
        help="how each device batches its cases: lanes:L[:K] (L lanes refilled every K steps, "
        "the default lanes:8), groups:G (vmapped groups of G) or all (one vmap); recorded in "
        "the manifest (docs/batch_throughput.md)",
    )
    parser.add_argument(
        "--objective",
        action="append",
        default=[],
        metavar="PANEL:FEATURE=WEIGHT",
        help="design objective terms or a preset, stored per case (deploy_array)",
    )
    parser.add_argument("--no-trajectories", action="store_true", help="store no q, v")
    parser.add_argument("--solver", default=None, metavar="NAME", help=SOLVER_HELP)
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument(
        "--distributed", action="store_true", help="call jax.distributed.initialize() first"
    )


def parse_values(name: str, text: str) -> list[float]:
    """`v1,v2,...`, `LOW:HIGH:N` or `LOW:HIGH:N:log`."""
    import numpy as np

    try:
        if ":" in text:
            parts = text.split(":")
            if len(parts) not in (3, 4) or (len(parts) == 4 and parts[3] != "log"):
                raise ValueError
            low, high, n = float(parts[0]), float(parts[1]), int(parts[2])
            if n < 1:
                raise ValueError
            if len(parts) == 4:
                if not (low > 0 and high > 0):
                    raise SystemExit(f"error: --grid {name}: a log grid needs LOW, HIGH > 0")
                return np.geomspace(low, high, n).tolist()
            return np.linspace(low, high, n).tolist()
        return [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise SystemExit(
            f"error: --grid {name}={text!r}: expected v1,v2,... or LOW:HIGH:N[:log]"
        ) from None


def parse_grid(items: list[str]) -> dict[str, list[float]]:
    grid = {}
    for item in items:
        if "=" not in item:
            raise SystemExit(f"error: --grid expects NAME=VALUES, got {item!r}")
        name, text = item.split("=", 1)
        grid[name.strip()] = parse_values(name.strip(), text)
    if not grid:
        raise SystemExit("error: give at least one --grid NAME=VALUES")
    return grid


def run(args) -> int:
    import jax

    if args.distributed:
        jax.distributed.initialize()

    from ..scenes import SCENES, get_scene
    from ..sweep import DEFAULT_CHUNK_SIZE, DEFAULT_POLICY, sweep
    from .simulate import parse_assignments

    if args.scene not in SCENES:
        print(
            f"error: unknown scene {args.scene!r}; valid: {', '.join(sorted(SCENES))}",
            file=sys.stderr,
        )
        return 2
    scene = get_scene(args.scene)
    grid = parse_grid(args.grid)
    fixed = parse_assignments(args.set)
    t_end = scene.default_t_end if args.t_end is None else args.t_end
    evaluate, features = None, None
    try:
        control = solver_control(scene, args.solver)
        if args.objective:
            from ..objectives import parse_objective
            from ..optimize import DesignProblem

            objective = parse_objective(args.objective)
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
            args.out,
            t_end=t_end,
            n_save=args.n_save,
            fixed=fixed,
            control=control,
            chunk_size=DEFAULT_CHUNK_SIZE if args.chunk_size is None else args.chunk_size,
            policy=DEFAULT_POLICY if args.policy is None else args.policy,
            resume=args.resume,
            evaluate=evaluate,
            features=features,
            save_trajectories=not args.no_trajectories,
            progress=not args.quiet,
        )
    except (ValueError, FileExistsError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    failed = sum(c["failed"] for c in manifest["chunks"])
    done = sum(c["stop"] - c["start"] for c in manifest["chunks"])
    print(
        f"sweep: {done}/{manifest['n_cases']} cases in {len(manifest['chunks'])} chunks, "
        f"{failed} failed; wrote {args.out}/manifest.json"
    )
    return 0 if failed == 0 and done == manifest["n_cases"] else 1
