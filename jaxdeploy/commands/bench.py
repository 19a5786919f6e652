"""`jaxdeploy bench work-precision [SCENE] --out DIR [--quick]`: error against run time of every
solver configuration and of the peers, against a converged reference (CSV, markdown, PNG)."""

from __future__ import annotations

import sys

NAME = "bench"
HELP = "benchmarks: work-precision (error against wall time) of solvers and peers"
SCENES = ("slider_crank", "deploy_array")


def add_arguments(parser) -> None:
    sub = parser.add_subparsers(dest="benchmark", required=True)
    wp = sub.add_parser("work-precision", help="error against wall time, all configurations")
    wp.add_argument("scene", nargs="?", default="slider_crank", help=f"one of {SCENES}")
    wp.add_argument("--out", default=None, help="output folder (default results/bench_SCENE)")
    wp.add_argument("--quick", action="store_true", help="short horizon, few configurations")
    wp.add_argument("--repeats", type=int, default=3, help="timed runs per configuration")
    wp.add_argument("--t-end", type=float, default=None, help="horizon [s] (default: scene's)")
    wp.add_argument("--overwrite", action="store_true", help="replace an existing result")


def run(args) -> int:
    from ..benchmarks.report import write_report
    from ..benchmarks.work_precision import run_benchmark
    from ..io import prepare_output_dir

    if args.scene not in SCENES:
        print(
            f"error: scene {args.scene!r} is invalid; valid: {', '.join(SCENES)}", file=sys.stderr
        )
        return 2
    if args.repeats < 1:
        print(f"error: --repeats = {args.repeats} is invalid: it must be >= 1", file=sys.stderr)
        return 2
    if args.t_end is not None and not args.t_end > 0:
        print(f"error: --t-end = {args.t_end} is invalid: it must be > 0 (s)", file=sys.stderr)
        return 2
    out = args.out or f"results/bench_{args.scene}"
    try:
        prepare_output_dir(out, args.overwrite)
    except FileExistsError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    repeats = 1 if args.quick else args.repeats
    reference, rows = run_benchmark(args.scene, quick=args.quick, repeats=repeats, t_end=args.t_end)
    from ..benchmarks.exudyn_peer import exudyn_available, exudyn_version

    options = dict(
        quick=args.quick,
        repeats=repeats,
        t_end=args.t_end,
        exudyn=exudyn_version() if exudyn_available() else None,
    )
    files = write_report(out, args.scene, reference, rows, options)
    print("wrote " + ", ".join(files))
    return 0
