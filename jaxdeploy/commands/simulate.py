"""`jaxdeploy simulate [SCENE] [--set NAME=VALUE ...] [--t-end T] [--out DIR]`: run a scene and
write its trajectory, plots and summary."""

from __future__ import annotations

import json
import os
import sys
import time

from . import SCENE_OPTION_HELP, SOLVER_HELP, parse_pairs, solver_control

NAME = "simulate"
HELP = "run a scene and write trajectory, plots, summary"
DEFAULT_SCENE = "deploy_array"


def add_arguments(parser) -> None:
    parser.add_argument("scene", nargs="?", help=f"scene name (default {DEFAULT_SCENE})")
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="scene parameter in SI units (repeatable); unknown names list the valid ones",
    )
    parser.add_argument(
        "--scene-option", action="append", default=[], metavar="KEY=VALUE", help=SCENE_OPTION_HELP
    )
    parser.add_argument("--t-end", type=float, default=None, help="end time [s]")
    parser.add_argument("--out", default=None, help="output folder (default results/SCENE)")
    parser.add_argument("--n-save", type=int, default=2001, help="number of saved states")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing result")
    parser.add_argument("--solver", default=None, metavar="NAME", help=SOLVER_HELP)
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def parse_assignments(items: list[str]) -> dict[str, float]:
    out = {}
    for item in items:
        if "=" not in item:
            raise SystemExit(f"error: --set expects NAME=VALUE, got {item!r}")
        name, value = item.split("=", 1)
        try:
            out[name.strip()] = float(value)
        except ValueError:
            raise SystemExit(f"error: --set {name}: {value!r} is not a number (SI units)") from None
    return out


def _refuse(message: str) -> int:
    print(f"error: {message}", file=sys.stderr)
    return 2


def run(args) -> int:
    import math

    from ..io import (
        atomic_write_json,
        atomic_write_npz,
        check_output_dir,
        prepare_output_dir,
        run_metadata,
    )
    from ..mechanism import AssemblyError
    from ..scenes import SCENES, get_scene
    from ..simulation import simulate

    # Every refusal happens here, before the output folder is created and before the solver
    # is compiled: a bad run leaves nothing behind.
    scene_name = args.scene or DEFAULT_SCENE
    if scene_name not in SCENES:
        return _refuse(f"unknown scene {scene_name!r}; valid: {', '.join(sorted(SCENES))}")
    try:
        scene = get_scene(scene_name, **parse_pairs(args.scene_option, "--scene-option"))
    except ValueError as err:
        return _refuse(f"--scene-option: {err}")
    try:
        params = scene.resolve_params(parse_assignments(args.set))
    except ValueError as err:
        return _refuse(str(err))
    t_end = scene.default_t_end if args.t_end is None else args.t_end
    if not (math.isfinite(t_end) and t_end > 0):
        return _refuse(f"--t-end = {t_end} is invalid: it must be finite and in (0, inf) s")
    if args.n_save < 2:
        return _refuse(f"--n-save = {args.n_save} is invalid: it must be an integer >= 2")
    try:
        control = solver_control(scene, args.solver)
    except ValueError as err:
        return _refuse(str(err))
    out = args.out or f"results/{scene_name}"
    try:
        check_output_dir(out, args.overwrite)
    except FileExistsError as err:
        return _refuse(str(err))
    try:
        mechanism = scene.build(params)
        initial = scene.initial_state(params, mechanism)
    except (ValueError, AssemblyError) as err:
        return _refuse(f"scene {scene_name!r} with these parameters: {err}")
    prepare_output_dir(out, args.overwrite)
    # summary.json is written last and marks a complete result; drop the old one first so a
    # rerun that dies half-way cannot pass for a complete result.
    stale_marker = os.path.join(out, "summary.json")
    if os.path.exists(stale_marker):
        os.unlink(stale_marker)

    start = time.perf_counter()
    trajectory = simulate(
        mechanism,
        initial,
        t_end,
        n_save=args.n_save,
        progress=not args.quiet and sys.stderr.isatty(),
        **control,
    )
    trajectory.q.block_until_ready()
    wall = time.perf_counter() - start

    summary = {
        "scene": scene_name,
        "t_end": t_end,
        "status": trajectory.status(),
        "n_steps": int(trajectory.stats["num_accepted_steps"]),
        "n_rejected": int(trajectory.stats["num_rejected_steps"]),
        # Newton iterations exist only for generalized-α; null for the explicit diffrax path.
        "n_newton_iterations": (
            int(trajectory.stats["num_newton_iterations"])
            if "num_newton_iterations" in trajectory.stats
            else None
        ),
        "wall_time_s": wall,
        "wall_time_includes": "compilation and run",
    }
    summary.update(scene.summary(params, mechanism, trajectory))
    summary["params"] = params
    summary["scene_options"] = scene.options
    # simulate draws no random numbers: the run is reproducible from params and versions.
    summary["seed"] = None
    summary["step_control"] = control
    summary["versions"] = run_metadata()
    atomic_write_npz(
        f"{out}/trajectory.npz",
        t=trajectory.ts,
        q=trajectory.q,
        v=trajectory.v,
        qdd=trajectory.qdd,
        lam=trajectory.lam,
    )
    figures = scene.plot(params, mechanism, trajectory, out)
    atomic_write_json(f"{out}/summary.json", summary)
    shown = {
        k: v
        for k, v in summary.items()
        if k not in ("params", "scene_options", "versions", "step_control")
    }
    print(json.dumps(shown, indent=2, default=float))
    print(f"wrote {out}/summary.json, {out}/trajectory.npz" + "".join(f", {f}" for f in figures))
    return 0 if trajectory.ok else 1
