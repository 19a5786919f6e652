"""Command line: `jaxdeploy simulate [SCENE] [--set NAME=VALUE ...] [--t-end T] [--out DIR]`."""

from __future__ import annotations

import argparse
import json
import sys
import time

DEFAULT_SCENE = "deploy_array"


def _parse_assignments(items: list[str]) -> dict[str, float]:
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


def _simulate(args) -> int:
    from .io import atomic_write_json, atomic_write_npz, prepare_output_dir, run_metadata
    from .scenes import SCENES, get_scene
    from .simulation import simulate

    scene_name = args.scene or DEFAULT_SCENE
    if scene_name not in SCENES:
        print(
            f"error: unknown scene {scene_name!r}; valid: {', '.join(sorted(SCENES))}",
            file=sys.stderr,
        )
        return 2
    scene = get_scene(scene_name)
    try:
        params = scene.resolve_params(_parse_assignments(args.set))
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    out = args.out or f"results/{scene_name}"
    try:
        prepare_output_dir(out, args.overwrite)
    except FileExistsError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    t_end = scene.default_t_end if args.t_end is None else args.t_end
    if not t_end > 0:
        print(f"error: --t-end = {t_end} is invalid: it must be > 0 (s)", file=sys.stderr)
        return 2

    mechanism = scene.build(params)
    initial = scene.initial_state(params, mechanism)
    control = dict(scene.default_control)
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
        "n_newton_iterations": int(trajectory.stats.get("num_newton_iterations", -1)),
        "wall_time_s": wall,
        "wall_time_includes": "compilation and run",
    }
    summary.update(scene.summary(params, mechanism, trajectory))
    summary["params"] = params
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
    shown = {k: v for k, v in summary.items() if k not in ("params", "versions", "step_control")}
    print(json.dumps(shown, indent=2, default=float))
    print(f"wrote {out}/summary.json, {out}/trajectory.npz" + "".join(f", {f}" for f in figures))
    return 0 if trajectory.ok else 1


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="jaxdeploy", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    sim = sub.add_parser("simulate", help="run a scene and write trajectory, plots, summary")
    sim.add_argument("scene", nargs="?", help=f"scene name (default {DEFAULT_SCENE})")
    sim.add_argument("--set", action="append", default=[], metavar="NAME=VALUE")
    sim.add_argument("--t-end", type=float, default=None, help="end time [s]")
    sim.add_argument("--out", default=None, help="output folder (default results/SCENE)")
    sim.add_argument("--n-save", type=int, default=2001, help="number of saved states")
    sim.add_argument("--overwrite", action="store_true", help="replace an existing result")
    sim.add_argument("--quiet", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    if args.command == "simulate":
        return _simulate(args)
    return 2


if __name__ == "__main__":
    sys.exit(main())
