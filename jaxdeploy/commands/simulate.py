"""`jaxdeploy simulate [SCENE] [--set NAME=VALUE ...] [--t-end T] [--out DIR]`: run a scene and
write its trajectory, plots and summary."""

from __future__ import annotations

import functools
import math
import os
import sys
import threading
import time
import warnings
from typing import NamedTuple

import numpy as np

from ._args import (
    EXIT_FAILED,
    EXIT_IMPLAUSIBLE,
    EXIT_OK,
    SCENE_OPTION_HELP,
    SET_HELP,
    add_step_control,
    integer_at_least,
    positive,
    refuse,
    scene_of,
    scene_settings,
)

NAME = "simulate"
HELP = "run a scene and write trajectory, plots, summary"
DEFAULT_SCENE = "deploy_array"

# Wall time of the integration per simulated second with each scene's default step control
# [s/s]: `phases.integrate_s` / `t_end_s` of `jaxdeploy simulate SCENE` (default parameters)
# on the 2-core reference machine while it was shared (load average ~9, so these are upper
# values; docs/performance.md times the whole command quietly). Only the order
# of magnitude matters: it sizes the estimate that stops a run of hours started by a
# mistyped --t-end before anything is built. It cannot see what a parameter or a tolerance
# does to the steps: the probe (`_run_length`) measures the run itself once it is compiled.
INTEGRATE_S_PER_SIMULATED_S = {
    "deploy_array": 5.6,  # 11.2 s for 2 s
    "slider_crank": 21.0,  # 0.5 s for 0.024 s
    "impact": 330.0,  # 0.2 s for 6e-4 s
    "pendulum": 0.3,  # 0.3 s for 1 s
}
# A run estimated to integrate longer than this needs --long-run [s].
LONG_RUN_S = 900.0
# A run the probe estimates to integrate longer than this says so and shows diffrax's
# progress bar on a terminal [s]. Shorter runs go without: the bar is a host callback, which
# keeps the program out of the program cache (jaxdeploy/_program_cache.py), and tracing
# would cost more than the bar tells.
PROGRESS_BAR_S = 30.0


def add_arguments(parser) -> None:
    parser.add_argument(
        "scene",
        nargs="?",
        help=f"scene name (default {DEFAULT_SCENE}); `jaxdeploy scenes` lists them",
    )
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help=SET_HELP)
    parser.add_argument(
        "--scene-option", action="append", default=[], metavar="KEY=VALUE", help=SCENE_OPTION_HELP
    )
    parser.add_argument(
        "--t-end",
        type=positive("--t-end", "s"),
        default=None,
        help="end time [s], > 0; default: the scene's (`jaxdeploy scenes SCENE`)",
    )
    parser.add_argument(
        "--out",
        default=None,
        help="output folder (default results/simulate/SCENE-DATE-TIME, a new one every run)",
    )
    parser.add_argument(
        "--n-save",
        type=integer_at_least("--n-save", 2),
        default=2001,
        help="number of saved states, equally spaced over [0, t_end], ≥ 2 (default 2001)",
    )
    parser.add_argument("--overwrite", action="store_true", help="replace an existing result")
    parser.add_argument(
        "--long-run",
        action="store_true",
        help=f"accept a run estimated to integrate longer than {LONG_RUN_S / 60:.0f} min",
    )
    parser.add_argument(
        "--quiet", action="store_true", help="print nothing but errors (no phases, no progress)"
    )
    parser.add_argument(
        "--no-reference",
        action="store_true",
        help="skip the ideal-joint reference run (deploy_array): no deviations from the ideal "
        "mechanism in the summary and plots, one simulation fewer",
    )
    add_step_control(parser)


def run_length_problem(scene, control, t_end: float, long_run: bool) -> str | None:
    """Why a run of `scene` to `t_end` should not start, or None: it needs more steps than
    `control.max_steps` allows (at least t_end/dt_max adaptive or t_end/dt fixed, so it
    would fail), or its estimated integration time exceeds `LONG_RUN_S` without `long_run`."""
    if control.adaptive:
        bound = control.dt_max
        what = f"t_end/dt_max = {t_end:g}/{bound:g}" if bound is not None else None
    else:
        bound = control.dt
        what = f"t_end/dt = {t_end:g}/{bound:g}"
    if bound is not None and is_number(bound):
        steps = t_end / float(bound)
        if steps > control.max_steps:
            return (
                f"--t-end = {t_end:g} s cannot finish: it needs at least {what} = {steps:.3g} "
                f"steps, more than the {control.max_steps} a run may take; shorten --t-end or "
                "lengthen --dt-max/--dt"
            )
    rate = INTEGRATE_S_PER_SIMULATED_S.get(scene.name)
    if rate is not None and not long_run:
        estimate = rate * t_end
        if estimate > LONG_RUN_S:
            return (
                f"--t-end = {t_end:g} s would integrate for about {_duration(estimate)} "
                f"(~{rate:g} s per simulated second with {scene.name}'s default step control "
                "on one core); pass --long-run to start it anyway"
            )
    return None


def is_number(value) -> bool:
    return isinstance(value, int | float) and math.isfinite(value)


def _duration(seconds: float) -> str:
    from ._plan import duration_text

    return duration_text(seconds)


def run(args) -> int:
    """validate → take the output folder → build → plan → run and write. Every refusal
    (exit 2) comes before the run is compiled, and those of the command line and of a folder
    held by another run before any work; a refusal releases the folder as it was: a bad run
    leaves nothing behind."""
    _read_ahead(args)
    # Started first, by the scene's name (`_figures`): matplotlib's import in the figure
    # process then overlaps the imports of the scenes here, not only the build and the run.
    drawing = _figures_ahead(args.scene or DEFAULT_SCENE)
    try:
        return _validate_and_run(args, drawing)
    finally:
        drawing.close()  # a refused run's process ends without drawing


def _validate_and_run(args, drawing) -> int:
    from . import _plan

    try:
        scene, params, control, t_end = _validate(args)
    except ValueError as err:
        return refuse(str(err))
    try:
        # Taken before the build, as every command takes it: a second run into a held folder
        # is refused at once, not after its build and its program's compile.
        folder = _plan.claim_output(args.out or _default_out(args), args.overwrite)
    except FileExistsError as err:
        return refuse(str(err))
    with folder:
        _figures_of(scene, drawing)
        return _build_and_run(args, scene, params, control, t_end, folder, drawing)


def _read_ahead(args) -> None:
    """Start reading the compiled programs the last run of these settings ran (`_read_ahead`),
    before the imports and the build: the settings that choose the programs name the hint
    (`--set` values and times are the programs' data; the solver, the tolerance that
    `--solver auto` goes by, fixed steps, the saved times' count and the reference are not)."""
    from .. import _read_ahead

    chosen = [args.scene or DEFAULT_SCENE, sorted(args.scene_option), args.n_save, args.solver,
              args.rtol, args.dt is not None, args.no_reference]  # fmt: skip
    _read_ahead.start("jaxdeploy simulate " + repr(chosen))


def _figures_ahead(scene_name: str):
    """The run's figure process (`_figures.FigureProcess`), started now when figures.py has a
    drawing of that name: a scene's analysis names its figures after the scene
    (`_figures_of` checks it once the scene is known)."""
    from ._figures import FigureProcess, drawing_names

    drawing = FigureProcess()
    if scene_name in drawing_names():
        drawing.start()
    return drawing


def _figures_of(scene, drawing) -> None:
    """The figure process as `scene`'s analysis needs it: started when it draws figures (if
    `_figures_ahead` did not), ended when it draws none."""
    from ..analysis import analysis_class

    if analysis_class(scene).figures is not None:
        drawing.start()
    else:
        drawing.close()


def _build_and_run(args, scene, params, control, t_end, folder, drawing) -> int:
    """build (the run's program compiled beside it: `_ahead`) → plan → probe → run and
    write, the figures drawn by `drawing`."""
    from ._ahead import CompileAhead
    from ._phases import Phases

    phases = Phases(quiet=args.quiet)
    # The run's program, compiled beside the assembly once the mechanism is built; joined on
    # every way out (a process that ends while XLA compiles in a thread aborts).
    ahead = CompileAhead(t_end, args.n_save, control)
    try:
        return _build_then_run(args, scene, params, control, t_end, folder, drawing, phases, ahead)
    finally:
        ahead.wait()


def _build_then_run(args, scene, params, control, t_end, folder, drawing, phases, ahead) -> int:
    from ..mechanism import AssemblyError

    try:
        with phases.phase(
            "build", f"{scene.name}: build the mechanism, assemble the initial state"
        ):
            mechanism, initial = _build(args, scene, params, control, phases, ahead)
    except _Refused as refused:
        return refuse(str(refused))  # the folder is released as it was
    except (ValueError, AssemblyError) as err:
        return refuse(f"scene {scene.name!r} with these parameters: {err}")
    beside = _reference_beside(args, scene, params, t_end, phases)
    run = _metered(mechanism, initial)
    if beside is not None and ahead.started:
        # The run's program is traced or being compiled beside: the reference's trace
        # can take its turn now, while XLA compiles (as it does after the run's trace).
        beside.start()
    # What the run still waits for of its program compiled ahead is its compile.
    phases.add("compile_s", ahead.wait())
    if ahead.seconds:
        phases.add("compile_ahead_s", ahead.seconds)
    try:
        length = _probe(args, scene, params, control, t_end, run, phases, beside)
    except _Refused as refused:
        return refuse(str(refused))
    return _simulate(
        args, scene, params, control, t_end, mechanism, run, folder, phases, drawing,
        beside, length,
    )  # fmt: skip


class _Metered(NamedTuple):
    """The run as it integrates: `mechanism` with its energy meter where it allows one
    (`balance_metered`: a plausibility check; the meter does not change how it steps), from
    `initial`; `metered` the metered mechanism, or None."""

    mechanism: object
    initial: object
    metered: object


def _metered(mechanism, initial) -> _Metered:
    from .. import _program_cache
    from ..mechanism import balance_metered

    metered = balance_metered(mechanism)
    if metered is None:
        return _Metered(mechanism, initial, None)
    # One compiled program, which a warm run reads back from the program cache, instead of
    # ~130 operations run one by one, each traced, lowered and dispatched on its own: 0.9 s of
    # a warm deploy_array run (cProfile). Compiled, the meters' initial values differ from
    # the operation-by-operation ones by at most one rounding (5.6e-17 for deploy_array);
    # they do not enter the steps.
    return _Metered(metered, _program_cache.call(_metered_state(), metered, initial), metered)


@functools.cache
def _metered_state():
    """`balance_metered_state` as an `equinox.filter_jit` program (what
    `_program_cache.call` takes); built on first use, so that importing this module does not
    import JAX."""
    import equinox as eqx

    from ..mechanism import balance_metered_state

    return eqx.filter_jit(balance_metered_state)


def _reference_beside(args, scene, params, t_end, phases):
    """The ideal-joint reference made beside the run (`_ReferenceBeside`), or None when the
    analysis uses none or --no-reference."""
    import jax.numpy as jnp

    from ..analysis import analysis_class

    if (
        analysis_class(scene).uses_reference
        and scene.ideal_counterpart() is not None
        and not args.no_reference
    ):
        # The saved times `simulate` makes for n_save (t0 = 0), checked against the run's own
        # in `result`.
        return _ReferenceBeside(scene, params, jnp.linspace(0.0, t_end, args.n_save), phases)
    return None


def _measured_by_table(scene, params, control) -> bool:
    """Whether the scene's rate (`INTEGRATE_S_PER_SIMULATED_S`) was measured for this run:
    the scene's default parameters, options and step control, so that only --t-end differs,
    which the rate scales. Such a run is not probed: the probe's calls (each saves its
    states) cost a default slider_crank 0.5 s beside its 1.3 s of integration (load ~10)."""
    return (
        scene.name in INTEGRATE_S_PER_SIMULATED_S
        and params == scene.resolve_params({})
        and scene.options == type(scene)().options
        and control == scene.default_control
    )


def _probe(args, scene, params, control, t_end, run, phases, beside):
    """The run's estimated integration time (`_run_length.estimate`, a `RunLength`, or None
    when the probe failed, the run will say why, or was not needed: `_measured_by_table`),
    measured by the run's own program over the
    first parts of its horizon (it compiles the program the run then reuses; the reference
    beside starts once it is traced, as it would for the run). Refuses (`_Refused`) a run
    estimated past `LONG_RUN_S` without --long-run; says the estimate of a run past
    `PROGRESS_BAR_S`."""
    from .. import _program_cache
    from ..simulation import simulate
    from ..solvers import SolverChoiceWarning
    from ..solvers.step_control import scene_default_choice
    from . import _run_length
    from ._phases import compile_seconds
    from ._plan import duration_text

    def prefix(t):
        start = time.time()
        with warnings.catch_warnings():
            # A step control measured to be less accurate is said once, by the run.
            warnings.simplefilter("ignore", SolverChoiceWarning)
            trajectory = simulate(
                run.mechanism, run.initial, t, n_save=args.n_save, control=control
            )
        stats = trajectory.stats
        steps = int(stats["num_steps"]) + int(stats["num_rejected_steps"])
        ok = bool(trajectory.ok)
        end = time.time()
        # Its first call compiles (or reads back) the program: not part of a run's length.
        seconds = end - start - compile_seconds(start, end, threading.get_ident())
        return _run_length.Prefix(t, max(seconds, 0.0), steps, ok)

    if _measured_by_table(scene, params, control):
        return None
    label = "probe: the run over the first parts of its horizon, for its length"
    with (
        phases.phase("probe", label, split_compile=True),
        _program_cache.when_traced(None if beside is None else beside.start),
        scene_default_choice(control, scene.default_control),
    ):
        length = _run_length.estimate(prefix, t_end, short_s=PROGRESS_BAR_S)
    if length is None or length.seconds <= PROGRESS_BAR_S:
        return length
    account = (
        f"{scene.name} to --t-end = {t_end:g} s would integrate for about "
        f"{duration_text(length.seconds)}: {length.account()}"
    )
    if length.seconds > LONG_RUN_S and not args.long_run:
        raise _Refused(f"{account}; pass --long-run to start it anyway")
    phases.say(f"probe: {account}")
    return length


class _Refused(ValueError):
    """A refusal of the plan (its message is the whole line)."""


def _build(args, scene, params, control, phases, ahead):
    """`(mechanism, initial_state)` of the run: read back from the scene cache when an
    earlier run built the same scene with the same parameters (`_scene_cache`), else built,
    planned (before the assembly compiles its Newton iteration) and assembled, the run's
    program compiled `ahead` meanwhile. The plan is checked on a cached mechanism too: it
    depends on the command's other flags."""
    from ..mechanism import balance_metered
    from . import _plan, _scene_cache

    def assemble(mechanism):
        # Kept with the mechanism: finding it traces the memory's initialisation.
        facts = {"memory_floats": _plan.memory_floats(balance_metered(mechanism) or mechanism)}
        try:
            _plan_run(args, scene, mechanism, control, facts["memory_floats"])
        except ValueError as err:
            raise _Refused(str(err)) from None
        ahead.start(balance_metered(mechanism) or mechanism)  # the mechanism that runs
        # The assembly traces once the run's program is in XLA's compile (`_ahead`).
        ahead.wait_traced()
        return scene.initial_state(params, mechanism), facts

    mechanism, initial, facts, source = _scene_cache.built(
        scene, params, lambda: scene.build(params), assemble
    )
    if source == "cache":
        try:
            _plan_run(args, scene, mechanism, control, facts["memory_floats"])
        except ValueError as err:
            raise _Refused(str(err)) from None
        phases.say("  the mechanism and its initial state from the scene cache")
    return mechanism, initial


def _validate(args):
    """`(scene, params, control, t_end)` of the command line; a bad one raises `ValueError`."""
    scene = scene_of(args.scene or DEFAULT_SCENE, args)
    _, params, control = scene_settings(scene, args)
    t_end = scene.default_t_end if args.t_end is None else args.t_end
    problem = run_length_problem(scene, control, t_end, args.long_run)
    if problem is not None:
        raise ValueError(problem)
    from ..io import check_output_dir

    if args.out is not None:
        try:
            check_output_dir(args.out, args.overwrite)
        except FileExistsError as err:
            raise ValueError(str(err)) from None
    return scene, params, control, t_end


def _default_out(args) -> str:
    from ..io import default_output_dir

    return default_output_dir("simulate", args.scene or DEFAULT_SCENE)


def _plan_run(args, scene, mechanism, control, memory_floats) -> None:
    """Refuse (`ValueError`) what the built mechanism shows cannot work: tolerances too loose
    for its clearances, outputs too large for the memory (`memory_floats`: numbers in a
    saved state's memory of the mechanism that runs, with its meter: `_plan.memory_floats`)."""
    from ..mechanism import balance_metered
    from . import _plan

    _plan.check_tolerances(mechanism, control)
    with_reference = not args.no_reference and scene.ideal_counterpart() is not None
    run = balance_metered(mechanism) or mechanism  # the mechanism that runs, with its meter
    _plan.check_memory(
        _plan.saved_state_bytes(
            run, args.n_save, runs=2 if with_reference else 1, memory=memory_floats
        ),
        f"--n-save = {args.n_save} saved states of {scene.name}",
        "lower --n-save",
    )


def _reference(scene, params, ts, phases):
    """The ideal-joint reference run at the saved times `ts` (`batch.reference_run`), read
    from the reference cache when it holds it (`_reference_cache`)."""
    from ..batch import reference_run
    from . import _reference_cache

    ts = np.asarray(ts)

    def compute():
        label = "reference: the ideal-joint mechanism at the same saved times"
        with phases.phase(
            "reference", label, split_compile=True, compile_key="reference_compile_s"
        ):
            run = reference_run(scene, params, ts)
            run.q.block_until_ready()
        return run

    reference, source = _reference_cache.reference(scene, params, ts, compute)
    if source != "computed":
        phases.say("reference: the ideal-joint mechanism, from the reference cache")
    return reference


class _ReferenceBeside:
    """The reference run made in a second thread beside the run, at the saved times the run
    will have (`expected_ts`): its tracing starts once the run's own tracing is done
    (`start`, from `_program_cache.when_traced`), so that it overlaps the run's compile and
    integration, which leave Python's GIL free (on two cores the reference then costs little
    wall time; before, it came after the run). `result(ts)` is the reference at the run's
    actual saved times `ts`: the one made beside when they are `expected_ts` (always, unless
    the run failed and its unreached saves are not times), else one made now at `ts`, as
    the command did before; an error of the one made beside is raised only when it is used."""

    def __init__(self, scene, params, expected_ts, phases):
        self.scene, self.params, self.phases = scene, params, phases
        self.expected_ts = np.asarray(expected_ts)
        self._thread = None
        self._outcome = None

    def start(self) -> None:
        if self._thread is None:
            self._thread = threading.Thread(target=self._make, name="reference", daemon=True)
            self._thread.start()

    def _make(self) -> None:
        try:
            run = _reference(self.scene, self.params, self.expected_ts, self.phases)
            self._outcome = (run, None)
        except BaseException as err:  # noqa: BLE001 - re-raised in the caller's thread
            self._outcome = (None, err)

    def result(self, ts):
        self.start()
        self._thread.join()
        ts = np.asarray(ts)
        if not np.array_equal(ts, self.expected_ts):
            return _reference(self.scene, self.params, ts, self.phases)
        run, err = self._outcome
        if err is not None:
            raise err
        return run


def _while_running(mechanism, trajectory) -> dict:
    """Work that needs the run's arrays' shapes but not their values, done while the run is
    under way: the programs of the contact histories the analysis evaluates (read back or
    traced and compiled now, run again on the result later) and the run's metadata (its git
    query is a subprocess; matplotlib's import is the figure process's). **Returns:**
    `run_metadata()`."""
    from ..analysis import clearance_joint_history
    from ..io import run_metadata
    from ..mechanism import RevoluteClearance

    if mechanism.find(RevoluteClearance):
        clearance_joint_history(mechanism, trajectory)
    return run_metadata()


def _simulate(
    args, scene, params, control, t_end, mechanism, run, folder, phases, drawing, beside, length
) -> int:
    from .. import _program_cache
    from ..analysis import analysis_class, episodes_csv
    from ..analysis.plausibility import plausibility_checks, verdict
    from ..io import atomic_write_bytes, atomic_write_json, atomic_write_npz, strict_json
    from ..mechanism import RevoluteClearance
    from ..simulation import simulate
    from ..solvers.step_control import scene_default_choice
    from ._results import failed_run_summary, run_quantities, units_of

    analysis_type = analysis_class(scene)
    label = f"integrate to t_end = {t_end:g} s ({control.solver_name()})"
    with phases.phase("integrate", label, split_compile=True):
        with (
            _program_cache.when_traced(None if beside is None else beside.start),
            scene_default_choice(control, scene.default_control),
        ):
            trajectory = simulate(
                run.mechanism,
                run.initial,
                t_end,
                n_save=args.n_save,
                # diffrax's bar shows the simulated time as a percentage of t_end.
                progress=not args.quiet
                and sys.stderr.isatty()
                and _estimated_seconds(scene, t_end, length) > PROGRESS_BAR_S,
                control=control,
            )
        if beside is not None:
            beside.start()  # if the program cache did not (off, or the run not cacheable)
        energy, trajectory = _energy_of(mechanism, run.metered, trajectory)
        # JAX has dispatched the run and returned: meanwhile, what does not need its result.
        versions = _while_running(mechanism, trajectory)
        trajectory.q.block_until_ready()

    summary = {
        "scene": scene.name,
        "t_end_s": t_end,
        **run_quantities(trajectory),
    }
    reference = None
    if beside is not None:
        waited = time.time()
        reference = beside.result(trajectory.ts)
        phases.add("reference_wait_s", time.time() - waited)
    analysis = analysis_type(scene, params, mechanism, trajectory, reference)
    with phases.phase("outputs", "outputs: summary quantities, plausibility, trajectory.npz"):
        if analysis.figures is not None:
            # Drawn in the figure process while this one writes the other files.
            drawing.send(analysis.figures, analysis.plot_data(), folder.staging)
        quantities = analysis.summary()
        checks = plausibility_checks(mechanism, trajectory, energy()) if trajectory.ok else []
        summary["status"] = verdict(trajectory, checks)
        # A failed run's quantities past its failure are not numbers to report (NaN states,
        # an extreme of a diverging force): null, with the status saying why.
        summary.update(quantities if trajectory.ok else failed_run_summary(quantities))
        summary["plausibility"] = [{"check": c.name, **c.to_json()} for c in checks]
        atomic_write_npz(
            folder.file("trajectory.npz"),
            t=trajectory.ts,
            q=trajectory.q,
            v=trajectory.v,
            qdd=trajectory.qdd,
            lam=trajectory.lam,
        )
        written = ["summary.json", "trajectory.npz"]
        if mechanism.find(RevoluteClearance):
            # One row per contact episode of each clearance joint, units in the header.
            text = episodes_csv(mechanism, trajectory)
            atomic_write_bytes(folder.file("episodes.csv"), text.encode())
            written.append("episodes.csv")
    with phases.phase("plots", "plots: waiting for the figures"):
        figures = [os.path.basename(f) for f in drawing.files()]
    summary["phases"] = dict(phases.durations)
    summary["wall_time_s"] = phases.total()
    summary["units"] = units_of(summary)
    summary["params"] = params
    summary["scene_options"] = scene.options
    # simulate draws no random numbers: the run is reproducible from params and versions.
    summary["seed"] = None
    summary["step_control"] = control.to_json()
    summary["versions"] = versions
    atomic_write_json(folder.file("summary.json"), summary)
    folder.commit()
    out = folder.shown
    if not args.quiet:
        shown = {
            k: v
            for k, v in summary.items()
            if k not in ("params", "scene_options", "versions", "step_control", "plausibility")
        }
        print(strict_json(shown, indent=2))
        print(
            "wrote "
            + ", ".join(f"{out}/{name}" for name in written)
            + "".join(f", {out}/{f}" for f in figures)
        )
    return _verdict_exit(summary["status"], trajectory)


def _estimated_seconds(scene, t_end, length) -> float:
    """The run's integration time [s]: the probe's estimate, else the scene's rate's."""
    if length is not None:
        return length.seconds
    return INTEGRATE_S_PER_SIMULATED_S.get(scene.name, math.inf) * t_end


def _energy_of(mechanism, metered, trajectory):
    """`(energy, trajectory)`: `energy()` the run's `plausibility.energy_check` (None when it
    could not be metered: the check says why), and the run as one of `mechanism`, without
    the meter's memory."""
    from ..analysis.plausibility import energy_check
    from ..mechanism import metered_balance, unmetered_because, without_balance_meter

    if metered is None:
        return lambda: energy_check(None, unmetered_because(mechanism)), trajectory
    # Dispatched now, while the run is still under way (JAX returns before it finishes): the
    # balance's program is traced and compiled (cold: 0.7 s for deploy_array) beside the run
    # instead of after it, and runs on the run's arrays when they are ready.
    balance = metered_balance(metered, trajectory.q, trajectory.v, trajectory.memory)
    return lambda: energy_check(balance), without_balance_meter(trajectory)


def _verdict_exit(status: str, trajectory) -> int:
    """Exit code of a finished run: 0 ok, `EXIT_FAILED` when the solver failed,
    `EXIT_IMPLAUSIBLE` when a plausibility check failed (the status names it)."""
    if status == "ok":
        return EXIT_OK
    print(f"error: the run {status}", file=sys.stderr)
    return EXIT_FAILED if not trajectory.ok else EXIT_IMPLAUSIBLE
