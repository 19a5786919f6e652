"""`jaxdeploy bench work-precision [SCENE] --out DIR [--quick]`: error against run time of every
solver configuration and of the peers, against a converged reference (CSV, markdown, PNG)."""

from __future__ import annotations

import sys

from ._args import integer_at_least, positive

NAME = "bench"
HELP = "benchmarks: work-precision (error against wall time) of solvers and peers"
SCENES = ("slider_crank", "deploy_array")
# Some configurations would take hours on deploy_array (Kvaerno5: ~0.24 s per step, ~10 000
# steps), so each runs in a worker stopped at this many seconds.
DEFAULT_BUDGET_S = {"deploy_array": 900.0}


def add_arguments(parser) -> None:
    sub = parser.add_subparsers(dest="benchmark", required=True)
    wp = sub.add_parser("work-precision", help="error against wall time, all configurations")
    wp.add_argument("scene", nargs="?", default="slider_crank", help=f"one of {SCENES}")
    wp.add_argument("--out", default=None, help="output folder (default results/bench_SCENE)")
    wp.add_argument("--quick", action="store_true", help="short horizon, few configurations")
    wp.add_argument(
        "--repeats",
        type=integer_at_least("--repeats", 1),
        default=3,
        help="timed runs per configuration, ≥ 1",
    )
    wp.add_argument(
        "--t-end",
        type=positive("--t-end", "s"),
        default=None,
        help="horizon [s], > 0 (default: scene's)",
    )
    wp.add_argument(
        "--budget",
        type=positive("--budget", "s"),
        default=None,
        help="wall-time limit [s] per configuration, each run in a worker process (default: "
        f"{DEFAULT_BUDGET_S} for a scene listed there, else none); one over it is reported "
        "as such and the benchmark goes on",
    )
    wp.add_argument("--overwrite", action="store_true", help="replace an existing result")
    wp.add_argument(
        "--resume",
        action="store_true",
        help="continue an interrupted run in --out: keep its reference and finished rows",
    )


def run(args) -> int:
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
    if args.resume and args.overwrite:
        print("error: --resume and --overwrite exclude each other", file=sys.stderr)
        return 2
    budget = args.budget if args.budget is not None else DEFAULT_BUDGET_S.get(args.scene)
    if budget is not None and not budget > 0:
        print(f"error: --budget = {budget} is invalid: it must be > 0 (s)", file=sys.stderr)
        return 2
    out = args.out or f"results/bench_{args.scene}"
    repeats = 1 if args.quick else args.repeats
    options = dict(quick=args.quick, repeats=repeats, t_end=args.t_end, budget_s=budget)
    try:
        reference, done = _resume(out, args.scene, options) if args.resume else (None, [])
        if not args.resume:
            prepare_output_dir(out, args.overwrite)
    except (FileExistsError, FileNotFoundError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    from ..benchmarks.exudyn_peer import exudyn_available, exudyn_version
    from ..benchmarks.report import write_report
    from ..benchmarks.work_precision import benchmark_reference, run_benchmark

    options["exudyn"] = exudyn_version() if exudyn_available() else None
    if reference is None:
        print(f"reference for {args.scene} ...", flush=True)
        reference = benchmark_reference(args.scene, quick=args.quick, t_end=args.t_end)
        reference.save(out)
        print(f"  evidence: {reference.evidence}", flush=True)

    def write(rows):  # after every configuration: an interrupted run loses at most one
        write_report(out, args.scene, reference, rows, options)

    rows = run_benchmark(
        args.scene,
        reference,
        quick=args.quick,
        repeats=repeats,
        done=done,
        on_row=write,
        log=lambda message: print(message, flush=True),
        budget_s=budget,
        reference_folder=out,
    )
    files = write_report(out, args.scene, reference, rows, options)
    print("wrote " + ", ".join(files))
    return 0


def _resume(out: str, scene: str, options: dict):
    """The reference and finished rows of an interrupted run in `out`, after checking that it
    benchmarked the same scene with the same options."""
    import json
    import os

    from ..benchmarks.reference import Reference
    from ..benchmarks.work_precision import Row

    if not Reference.exists_in(out):
        raise FileNotFoundError(f"--resume: no benchmark reference in {out!r} to continue from")
    reference = Reference.load(out)
    if reference.scene != scene:
        raise ValueError(f"--resume: {out!r} holds a {reference.scene} benchmark, not {scene}")
    meta_path = os.path.join(out, "work_precision.json")
    if not os.path.exists(meta_path):
        return reference, []  # interrupted before the first configuration finished
    with open(meta_path, encoding="utf-8") as f:
        meta = json.load(f)
    earlier = {k: meta["options"].get(k) for k in options}
    if earlier != options:
        raise ValueError(f"--resume: {out!r} was run with {earlier}, not {options}")
    return reference, [Row(**row) for row in meta["rows"]]
