"""`jaxdeploy sweep --scene S --grid NAME=v1,v2,... --out DIR [--resume] [--policy P]`: run the
Cartesian product of parameter values, each case alone on every core (a small sweep) or as
batched chunks sharded over all devices, written chunk by chunk, resumable (see
`jaxdeploy.sweep`); then every finished case's features (summary quantities, objective
terms) as features.csv/features.json and overview.png."""

from __future__ import annotations

import os
import sys

from ._args import (
    EXIT_FAILED,
    EXIT_IMPLAUSIBLE,
    EXIT_OK,
    OBJECTIVE_PRESETS,
    SCENE_OPTION_HELP,
    SET_HELP,
    SWEEP_AUTO_EACH_CASES_PER_CORE,
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
HELP = "parameter sweep: case by case or vmapped and sharded, chunked, resumable"


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
        help="how the cases run: each (every case alone, as `jaxdeploy simulate` runs it, "
        "on every core; its compiled programs are kept), all (one vmap per device) or "
        "groups:G (vmapped groups of G one after another); default auto: each for at most "
        f"{SWEEP_AUTO_EACH_CASES_PER_CORE} cases per core, else all (a resumed sweep: as it "
        "was started); "
        "recorded in the manifest",
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
    parser.add_argument(
        "--long-run",
        action="store_true",
        help="accept a sweep estimated to run longer than 15 min (as `simulate --long-run`; "
        "default: such a sweep is refused with its estimate)",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument(
        "--distributed", action="store_true", help="call jax.distributed.initialize() first"
    )
    parser.add_argument(
        "--devices",
        type=integer_at_least("--devices", 1),
        default=None,
        help="CPU devices each chunk is sharded over, one core each, ≥ 1 (default: one per "
        "core this process may use; a resumed sweep: as many as it was started with); not "
        "with --distributed, whose devices are the cluster's",
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
            return _distinct(name, np.geomspace(low, high, n).tolist())
        return _distinct(name, np.linspace(low, high, n).tolist())
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise bad("a value is not a number") from None
    if not values:
        raise bad("no values")
    if not all(math.isfinite(v) for v in values):
        raise bad("values must be finite")
    return _distinct(name, values)


def _distinct(name: str, values: list[float]) -> list[float]:
    """`values`, refused (`ValueError`) when one appears twice: the same case would run twice
    (and a range LOW:HIGH:N with LOW = HIGH and N > 1 is such a repetition too)."""
    seen = set()
    for v in values:
        if v in seen:
            raise ValueError(
                f"--grid {name}: the value {v:g} is given twice; the same case would run twice"
            )
        seen.add(v)
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
    """validate → plan (the folder's lock, estimates) → run → write; every refusal (exit 2)
    comes before anything is written, and before anything is compiled but the one that needs
    the compiled sweep: its run length, probed by the sweep's own program before the first
    chunk (`_length_probe`). The ideal reference of an --objective is a simulation: it comes
    after the checks."""
    import jax

    refusal = _host_devices(args)
    if refusal is not None:
        return refuse(refusal)
    if args.distributed:
        try:
            jax.distributed.initialize(**_distributed_from_environment())
        except ValueError as err:
            return refuse(f"--distributed: {err}")
    lock, refusal = None, None
    try:
        plan = _validate(args)
        # Before the mechanism is built for the estimates: a held folder is refused at once.
        lock = _claim(plan.out)
        _plan_resources(args, plan)
    except (ValueError, FileExistsError) as err:
        refusal = str(err)
    refusal = _agree(refusal)
    if refusal is not None:
        if lock is not None:
            lock.close()
        return refuse(refusal)
    with lock:
        try:
            manifest = _run(args, plan)
        except (ValueError, FileExistsError) as err:
            return refuse(str(err))
        except RuntimeError as err:  # the objective's ideal reference run failed
            print(f"error: {err}", file=sys.stderr)
            return EXIT_FAILED
        return _write(args, plan, manifest)


def _host_devices(args) -> str | None:
    """Split the CPU into `--devices` JAX devices (`_devices.split_host`: default one per
    usable core; for --resume, the count the sweep in --out was started with), so that each
    chunk's shards run side by side (what that gains: docs/performance.md, "Whole processes",
    by `make bench`). With --distributed the devices are the cluster's."""
    from ._devices import split_host

    if args.distributed:
        return "--devices does not apply with --distributed" if args.devices else None
    resumed = _resumed_devices(args.out) if args.resume and args.devices is None else None
    if resumed is None and args.devices is None and _runs_each_case_alone(args):
        # One device: a process of several never keeps a compiled program in the program
        # cache (`_program_cache._executable`); the cases use every core as threads.
        resumed = 1
    return split_host(args.devices, resumed)


def _runs_each_case_alone(args) -> bool:
    """Whether a new sweep of these arguments runs by the policy `each`
    (`jaxdeploy.sweep.resolve_policy`; False for a malformed --policy or --grid, which
    `_validate` refuses)."""
    from ..sweep import DEFAULT_POLICY, parse_policy, resolve_policy

    try:
        policy = parse_policy(DEFAULT_POLICY if args.policy is None else args.policy)
        grid = parse_grid(args.grid)
    except ValueError:
        return False
    n_cases = 1
    for values in grid.values():
        n_cases *= len(values)
    return resolve_policy(policy, n_cases)["kind"] == "each"


def _resumed_devices(out: str | None) -> int | None:
    """How many devices the sweep in `out` was started with (its manifest), or None: a
    resumed sweep keeps its chunks' composition per device, so that its later chunks are
    computed as its earlier ones were (a vmapped case's last bits depend on its batch)."""
    import json

    from ..sweep import MANIFEST

    try:
        with open(os.path.join(out, MANIFEST)) as f:
            devices = json.load(f).get("devices")
    except (OSError, TypeError, ValueError, AttributeError):
        return None  # no readable manifest: --resume's own checks say so
    return len(devices) if isinstance(devices, list) and devices else None


def _claim(out: str):
    """The output folder's lock (`FolderLock`), taken by process 0 only: it alone writes the
    sweep (`jaxdeploy.sweep`), and the other processes of a `--distributed` run share its
    folder (taken by each, the second process was refused 'in use by another run', the
    first then waited for it in vain). Elsewhere a lock that holds nothing."""
    import jax

    from .._output_folder import FolderLock

    if jax.process_index() == 0:
        return FolderLock(out).claim()
    return _NoLock()


class _NoLock:
    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        pass


def _agree(refusal: str | None) -> str | None:
    """One verdict for all processes of a `--distributed` run (one collective): a process
    that refuses alone would leave the others waiting for it inside the first chunk's program
    until the coordination service times out. Returns this process's own refusal, or for a
    process that had none while another refused, a line naming the one that did."""
    import jax

    if jax.process_count() == 1:
        return refusal
    import numpy as np
    from jax.experimental import multihost_utils

    refused = np.asarray(multihost_utils.process_allgather(np.int32(refusal is not None)))
    if refusal is None and refused.any():
        ids = ", ".join(str(i) for i in np.flatnonzero(refused))
        refusal = f"process {ids} of this --distributed run refused (its message says why)"
    return refusal


class _Plan:
    """What the command line asks for, checked: scene, fixed parameters, step control, grid,
    policy, objective, end time and output folder."""

    def __init__(self, **fields):
        self.__dict__.update(fields)


def _validate(args) -> _Plan:
    """The sweep of the command line; a bad argument raises `ValueError` naming it."""
    from ..sweep import DEFAULT_CHUNK_SIZE, DEFAULT_POLICY, grid_cases, parse_policy

    if args.resume and args.out is None:
        raise ValueError("--resume continues the sweep in --out: give --out")
    if args.resume and not os.path.isfile(os.path.join(args.out, "manifest.json")):
        raise ValueError(
            f"--resume: {args.out!r} holds no sweep to continue (no manifest.json: it does not "
            "exist, or its sweep stopped before finishing a chunk); leave out --resume to start it"
        )
    scene = scene_of(args.scene, args)
    fixed, _, control = scene_settings(scene, args)
    grid = parse_grid(args.grid, fixed)
    cases = grid_cases(grid)
    for row in zip(*cases.values(), strict=True):  # names and ranges of every case (cheap)
        scene.resolve_params({**fixed, **dict(zip(cases, row, strict=True))})
    check_used(scene, grid, "--grid")
    policy = DEFAULT_POLICY if args.policy is None else args.policy
    parse_policy(policy)
    objective = None
    if args.objective:
        from ..objectives import parse_objective

        objective = parse_objective(args.objective)
    t_end = scene.default_t_end if args.t_end is None else args.t_end
    if args.out is not None and not args.resume:
        _check_fresh(args.out)
    from ..io import default_output_dir

    return _Plan(
        scene=scene,
        fixed=fixed,
        control=control,
        grid=grid,
        n_cases=len(next(iter(cases.values()))),
        policy=policy,
        objective=objective,
        t_end=t_end,
        chunk_size=DEFAULT_CHUNK_SIZE if args.chunk_size is None else args.chunk_size,
        out=args.out or default_output_dir("sweep", scene.name),
    )


def _check_fresh(out: str) -> None:
    """Refuse (`ValueError`) a folder a new sweep cannot start in: one holding a sweep (it
    needs --resume), one holding anything else, a file in the way, a read-only place."""
    from ..io import check_output_dir

    if os.path.isfile(os.path.join(out, "manifest.json")):
        raise ValueError(
            f"{out!r} already holds a sweep; pass --resume to continue it or choose another --out"
        )
    if os.path.isdir(out) and os.listdir(out):
        raise ValueError(
            f"output folder {out!r} is not empty and holds no sweep manifest; choose another --out"
        )
    try:
        check_output_dir(out, overwrite=False)
    except FileExistsError as err:
        raise ValueError(str(err)) from None


def _plan_resources(args, plan) -> None:
    """Refuse (`ValueError`) a sweep whose step tolerances cannot resolve its clearances, whose
    chunks or collected trajectories would not fit in memory, or that is estimated to run
    longer than `simulate.LONG_RUN_S` without --long-run."""
    from . import _plan

    scene, grid = plan.scene, plan.grid
    _check_duration(args, plan)
    first = {k: v[0] for k, v in grid.items()}
    # The smallest and largest value of each swept name (the others at their first): the
    # tolerances must resolve the clearances of both ends (building compiles nothing).
    for name, values in grid.items():
        for value in {min(values), max(values)}:
            params = scene.resolve_params({**plan.fixed, **first, name: value})
            mechanism = scene.build(params)
            _plan.check_tolerances(mechanism, plan.control)
    chunk = min(plan.chunk_size, plan.n_cases)
    collected = plan.n_cases if not args.no_trajectories else 0
    from ..mechanism import balance_metered

    # A chunk's cases run with their energy meter (`_run`), whose memory holds copies of q.
    metered = balance_metered(mechanism) or mechanism
    _plan.check_memory(
        _plan.saved_state_bytes(metered, args.n_save, runs=chunk)
        + _plan.saved_state_bytes(mechanism, args.n_save, runs=collected),
        f"--n-save = {args.n_save} saved states of {chunk} cases per chunk"
        + ("" if not collected else f" and the trajectories of all {collected} cases"),
        "lower --n-save or --chunk-size, or pass --no-trajectories",
    )


def _check_duration(args, plan) -> None:
    """Refuse (`ValueError`) a sweep estimated to run longer than `simulate.LONG_RUN_S`
    without --long-run: `simulate`'s rate per simulated second of the scene, times the
    cases, over the devices (an upper estimate: a vmapped chunk costs less per case)."""
    from ._plan import duration_text
    from .simulate import INTEGRATE_S_PER_SIMULATED_S, LONG_RUN_S

    scene = plan.scene
    rate = INTEGRATE_S_PER_SIMULATED_S.get(scene.name)
    if rate is not None and not args.long_run:
        import jax

        estimate = rate * plan.t_end * plan.n_cases / jax.device_count()
        if estimate > LONG_RUN_S:
            raise ValueError(
                f"{plan.n_cases} cases of {scene.name} to --t-end = {plan.t_end:g} s would run "
                f"for about {duration_text(estimate)} (~{rate:g} s per simulated second and case "
                f"on one core, {jax.device_count()} device(s)); pass --long-run to start it anyway"
            )


def _length_probe(args, plan, summarize):
    """The sweep's `probe` (`jaxdeploy.sweep.sweep`): its run length measured as `simulate`
    measures its own (`_run_length.estimate`), by the sweep's compiled program over growing
    first parts of the horizon of the first chunk still to run, before that chunk runs; the
    whole is that chunk's estimate times the chunks to run (each chunk runs as many steps
    as its slowest case, and its cases run side by side). Refuses (`ValueError`, nothing
    written) a sweep estimated past `simulate.LONG_RUN_S` without --long-run; says the
    estimate of one past `simulate.PROGRESS_BAR_S`. Each case's summary (`summarize`, host
    work after its chunk: the analysis, the plausibility checks) is timed on the last
    prefix's first case and added per case: for a cheap scene it is most of a case's cost
    (10,000 pendulum cases to 0.2 s: 0.5 s of integration and ~5 s of summaries per chunk
    of 64, load ~15).

    Like simulate's, an extrapolation, not a bound: the other chunks' cases may step more or
    less than the first chunk's. Compiling is not counted (the program is the sweep's own:
    it compiles once, for the probe)."""
    import threading
    import time

    from . import _run_length
    from ._phases import Phases, compile_seconds
    from ._plan import duration_text
    from .simulate import LONG_RUN_S, PROGRESS_BAR_S

    phases = Phases(quiet=args.quiet)

    def timed(work):
        """`(seconds, result)` of `work()`, compiling not counted."""
        start = time.time()
        result = work()
        end = time.time()
        seconds = end - start - compile_seconds(start, end, threading.get_ident())
        return _agreed(max(seconds, 0.0)), result

    def probe(run_to, chunks: int, cases: int) -> None:
        last = []

        def prefix(t):
            seconds, (steps, ok, case) = timed(lambda: run_to(t))
            last[:] = [case]
            return _run_length.Prefix(t, seconds, steps, ok)

        label = "probe: the first chunk over the first parts of its horizon, for the sweep's length"
        with phases.phase("probe", label, split_compile=True):
            length = _run_length.estimate(prefix, plan.t_end, short_s=PROGRESS_BAR_S / chunks)
            if length is None:  # every case of the chunk failed: the sweep says why
                return
            # Its second summary: the first one compiles and makes what cases share (the
            # ideal-joint reference of deploy_array).
            summarize(*last[0])
            per_case, _ = timed(lambda: summarize(*last[0]))
        seconds = length.seconds * chunks + per_case * cases
        if seconds <= PROGRESS_BAR_S:
            return
        account = (
            f"{cases} cases of {plan.scene.name} to --t-end = {plan.t_end:g} s would run for "
            f"about {duration_text(seconds)}: {chunks} chunk(s) each as long as the first (its "
            f"slowest case: {length.account()}) and {duration_text(per_case)} per case for its "
            "summary"
        )
        if seconds > LONG_RUN_S and not args.long_run:
            raise ValueError(f"{account}; pass --long-run to start it anyway")
        phases.say(f"sweep: {account}")

    return probe


def _agreed(seconds: float) -> float:
    """Process 0's `seconds` in every process of a `--distributed` run: each decides from
    the same times, so all run the same prefixes and reach the same verdict."""
    import jax

    if jax.process_count() == 1:
        return seconds
    import numpy as np
    from jax.experimental import multihost_utils

    return float(multihost_utils.broadcast_one_to_all(np.float64(seconds)))


def _summarizer(plan):
    """`summarize(params, trajectory)` of each case: what `jaxdeploy simulate` would report
    for it (docs/results.md), with the same plausibility verdict in its status; a failed case
    keeps its status and steps (null for the rest)."""
    import numpy as np

    from ..analysis import analysis_class
    from ..analysis.plausibility import case_energy, plausibility_checks, verdict
    from ..batch import reference_run
    from . import _reference_cache
    from ._results import run_quantities

    scene = plan.scene
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
        # The case ran with its energy meter where its mechanism allows one (`_run`).
        mechanism = scene.build(params)
        energy, trajectory = case_energy(mechanism, trajectory)
        quantities = run_quantities(trajectory)
        if not trajectory.ok:
            # States past the failure are NaN and extremes may be those of a diverging
            # force: nothing more to report than the status and the steps.
            return {**quantities, "energy_balance": None}
        reference = reference_for(params, trajectory)
        analysis = analysis_type(scene, params, mechanism, trajectory, reference)
        quantities.update(analysis.summary())
        check = energy()
        quantities["status"] = verdict(
            trajectory, plausibility_checks(mechanism, trajectory, check)
        )
        quantities["energy_balance"] = check.value
        return quantities

    return summarize


def _run(args, plan) -> dict:
    """Run (or resume) the sweep; returns its manifest."""
    from ..sweep import sweep

    summarize = _summarizer(plan)
    evaluate, features = None, None
    if plan.objective is not None:
        from ..optimize import DesignProblem

        problem = DesignProblem(
            plan.scene,
            plan.objective,
            plan.t_end,
            n_save=args.n_save,
            fixed=plan.fixed,
            control=plan.control,
        )

        def evaluate(params, trajectory):
            dep, _ = problem.deployment({k: params[k] for k in plan.grid}, trajectory)
            return {"objective": plan.objective(dep), **plan.objective.parts(dep)}

        features = ",".join(args.objective)
    return sweep(
        plan.scene,
        plan.grid,
        plan.out,
        t_end=plan.t_end,
        n_save=args.n_save,
        fixed=plan.fixed,
        control=plan.control,
        chunk_size=plan.chunk_size,
        policy=plan.policy,
        resume=args.resume,
        evaluate=evaluate,
        features=features,
        summarize=summarize,
        save_trajectories=not args.no_trajectories,
        progress=not args.quiet,
        energy_meter=True,
        probe=_length_probe(args, plan, summarize),
    )


def _write(args, plan, manifest) -> int:
    """features.csv/json and overview.png of the finished cases; the report and exit code."""
    import jax

    out = plan.out
    failed = sum(c["failed"] for c in manifest["chunks"])
    done = sum(c["stop"] - c["start"] for c in manifest["chunks"])
    written = [os.path.join(out, "manifest.json")]
    not_ok = 0
    if jax.process_index() == 0 and done:
        from ..sweep import load_sweep
        from ._sweep_outputs import plot_overview, write_features

        data = load_sweep(out)
        written += write_features(out, plan.scene, data, list(plan.grid))
        figure, not_ok = plot_overview(out, plan.scene, data, list(plan.grid), plan.grid)
        written += [] if figure is None else [figure]
    implausible = max(not_ok - failed, 0)
    if not args.quiet:
        print(
            f"sweep: {done}/{manifest['n_cases']} cases in {len(manifest['chunks'])} chunks, "
            f"{failed} failed, {implausible} implausible (features.csv says why; left out of "
            "overview.png); wrote " + ", ".join(written)
        )
    if failed or done != manifest["n_cases"]:
        return EXIT_FAILED
    return EXIT_IMPLAUSIBLE if implausible else EXIT_OK
