"""`jaxdeploy fit DATA --scene S --params NAME[=guess[:low:high]] ... --out DIR`: fit scene
parameters to measured channels; write estimates with standard errors and correlations, the
adequacy verdict (does the model explain the data?), the loss history and plots.

Exit status (docs/identification.md):

* 0 — the optimiser converged and the model explains the data (χ²/dof consistent with the
  stated noise, white residuals);
* 1 — the fit could not run (the model cannot be simulated at the start points);
* 2 — refused input (bad data file, parameter, option or output folder);
* 3 — the model does NOT explain the data (χ²/dof far above 1 or residuals not white): the
  estimates and their standard errors are not to be trusted, whether or not it converged;
* 4 — the model explains the data but the optimiser stopped before its criterion was met in
  the last stage (e.g. --max-iterations reached): the estimates may still move;
* 5 — the model explains the data but is not reproducible at the noise level at the estimate
  (the tolerance check: a 10x tighter model tolerance changes it by more than one noise level
  RMS or would move an estimate by more than one standard error): the fit may have matched
  the model's integration error. With the default tolerance (no --rtol, --dt) a failed check
  is first answered by refitting from the estimate at 10x tighter tolerances until a check
  passes (`jaxdeploy.fit.refit_until_reproducible`, the checks down to rtol 1e-12); exit 5
  when none does. A tolerance the user gave is checked, not changed.
"""

from __future__ import annotations

import sys

from ._args import (
    RTOL_FLOOR,
    SCENE_OPTION_HELP,
    SET_HELP,
    add_step_control,
    integer_at_least,
    parse_pairs,
    positive,
    scene_of,
    scene_settings,
)

NAME = "fit"
EXIT_OK, EXIT_FAILED, EXIT_REFUSED, EXIT_INADEQUATE, EXIT_NOT_CONVERGED = 0, 1, 2, 3, 4
EXIT_NOT_REPRODUCIBLE = 5
HELP = "fit scene parameters to measured channels (CSV/npz), with uncertainties"


def add_arguments(parser) -> None:
    parser.add_argument("data", help="measurements: .csv or .npz (time column t + channels)")
    parser.add_argument("--scene", required=True, help="scene name, e.g. deploy_array (required)")
    parser.add_argument(
        "--params",
        nargs="+",
        action="extend",
        required=True,
        metavar="NAME[=guess[:low:high]]",
        help="parameters to fit (SI units); default guess: scene default, bounds guess/10..x10",
    )
    parser.add_argument(
        "--out", default=None, help="output folder (default results/fit/SCENE-DATE-TIME)"
    )
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help=SET_HELP)
    parser.add_argument(
        "--scene-option",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help=SCENE_OPTION_HELP,
    )
    parser.add_argument(
        "--channels",
        default=None,
        help="comma-separated channels to fit (default: all in the file)",
    )
    parser.add_argument(
        "--noise",
        action="append",
        default=[],
        metavar="[CHANNEL=]SIGMA",
        help="noise level (one standard deviation, in the channel's unit); overrides the "
        "file's; default: the file's",
    )
    parser.add_argument(
        "--loss",
        choices=("trajectory", "block", "smooth"),
        default="trajectory",
        help="pointwise residuals, block means (a low-pass feature) or Gaussian-smoothed "
        "channels (--width); default trajectory",
    )
    parser.add_argument(
        "--block",
        type=positive("--block", "s"),
        default=None,
        help="block duration [s], > 0 (needed by --loss block; default: none)",
    )
    parser.add_argument(
        "--width",
        type=positive("--width", "s"),
        default=None,
        help="smoothing width [s], > 0 (needed by --loss smooth; default: none)",
    )
    parser.add_argument(
        "--widths",
        default=None,
        metavar="W1,W2,...",
        help="continuation in resolution: fit the channels smoothed over W1 s, then W2, ... "
        "(decreasing), then with --loss (trajectory or block; the uncertainties come from it); "
        "default: none",
    )
    parser.add_argument(
        "--window",
        action="append",
        default=[],
        metavar="T0:T1",
        help="fit only samples in [T0, T1] s (repeatable); default: every sample",
    )
    parser.add_argument(
        "--horizons",
        default="auto",
        metavar="T1,T2,...|auto|none",
        help="continuation: fit up to T1, then T2, ... (each from the last); auto (default): "
        "through the 4th, 8th, 16th, ... impact of the model at the start, then the whole "
        "record (none without impacts, or with --window or --widths)",
    )
    parser.add_argument(
        "--max-iterations",
        type=integer_at_least("--max-iterations", 1),
        default=30,
        help="Levenberg–Marquardt trial steps per stage, ≥ 1 (default 30)",
    )
    parser.add_argument(
        "--starts",
        type=integer_at_least("--starts", 0),
        default=0,
        metavar="N",
        help="global first stage: simulate N Latin-hypercube points within the bounds (one "
        "batch) and start from the best (default 0: start from the guess)",
    )
    parser.add_argument(
        "--seed", type=int, default=0, help="seed of the --starts sample (default 0)"
    )
    parser.add_argument("--overwrite", action="store_true", help="replace an existing result")
    parser.add_argument("--quiet", action="store_true", help="no progress lines")
    add_step_control(
        parser,
        unset="The fit chooses the model's tolerance itself (jaxdeploy.fit.choose_tolerance): "
        "from the scene's default step control it tightens rtol until the model's error at the "
        f"start is below the noise (not below rtol {RTOL_FLOOR:g}), measures it again at each "
        "horizon's estimate and tightens before the next horizon where it has grown, then checks "
        "the estimate at a 10x tighter rtol and refits there when it moves (exit 5 if no check "
        "passes down to "
        "rtol 1e-12). A --rtol or --dt given is used as given and only checked. The solver and "
        "the other unset values keep the scene's default (`jaxdeploy scenes SCENE`).",
        default="chosen by the fit (see above)",
    )


def _fail(message: str, code: int = EXIT_REFUSED) -> int:
    print(f"error: {message}", file=sys.stderr)
    return code


def _noise(items, names) -> dict:
    """`--noise [CHANNEL=]SIGMA` items as `{channel: σ}`; a bare SIGMA applies to every
    channel. A malformed item or σ ≤ 0 raises `ValueError` naming the flag."""
    import math

    noise = {}
    for item in items:
        key, sep, value = item.rpartition("=")
        try:
            sigma = float(value)
        except ValueError:
            raise ValueError(
                f"--noise {item!r}: expected [CHANNEL=]SIGMA, SIGMA a number"
            ) from None
        if not (math.isfinite(sigma) and sigma > 0):
            raise ValueError(
                f"--noise {item!r}: SIGMA = {value} is invalid: it must be in (0, inf)"
            )
        if sep:
            noise[key.strip()] = sigma
        else:
            noise.update(dict.fromkeys(names, sigma))
    return noise


def _windows(items):
    import math

    out = []
    for item in items:
        parts = item.split(":")
        try:
            t0, t1 = (float(p) for p in parts)
        except ValueError:
            raise ValueError(f"--window {item!r}: expected T0:T1 in seconds") from None
        if not (math.isfinite(t0) and math.isfinite(t1) and t0 < t1):
            raise ValueError(f"--window {item!r}: T0 and T1 must be finite with T0 < T1")
        out.append((t0, t1))
    return tuple(out) or None


def _float_list(option: str, text: str, expected: str) -> list[float]:
    """Comma-separated numbers of a command-line option, or an error naming it."""
    try:
        return [float(x) for x in text.split(",")]
    except ValueError:
        raise ValueError(f"{option} {text!r}: expected {expected}") from None


def _stages(args, data):
    from ..fit import ResidualSpec

    windows = _windows(args.window)
    t = data.t
    for t0, t1 in windows or ():
        if not ((t >= t0) & (t <= t1)).any():
            raise ValueError(
                f"--window {t0:g}:{t1:g}: no data sample lies in it; the data cover "
                f"[{float(t[0]):g}, {float(t[-1]):g}] s"
            )
    block = args.block if args.loss == "block" else None
    width = args.width if args.loss == "smooth" else None
    widths = []
    if args.widths:
        widths = _float_list("--widths", args.widths, "widths in s, e.g. 0.004,0.001")
        if args.loss == "smooth":
            raise ValueError(
                "--widths ends with a stage of independent residuals: give --loss trajectory "
                "or --loss block with it"
            )
        if not all(w > 0 for w in widths) or any(
            b >= a for a, b in zip(widths, widths[1:], strict=False)
        ):
            raise ValueError(f"--widths {args.widths!r}: widths must be > 0 and decrease")

    def stages_up_to(wins):
        out = [ResidualSpec("smooth", wins, width=w) for w in widths]
        return out + [ResidualSpec(args.loss, wins, block, width)]

    if args.horizons in ("auto", "none", None):
        return stages_up_to(windows)
    if isinstance(args.horizons, list):
        horizons = args.horizons
    else:
        horizons = _float_list("--horizons", args.horizons, "times in s, e.g. 0.05,0.2")
    increasing = all(b > a for a, b in zip(horizons, horizons[1:], strict=False))
    if not increasing or horizons[0] <= data.t[0]:
        raise ValueError(f"--horizons {args.horizons!r}: times must increase and exceed t[0]")
    stages = []
    base = windows or ((float(data.t[0]), float(data.t[-1])),)
    for h in horizons:
        clipped = tuple((a, min(b, h)) for a, b in base if a < h)
        stages += stages_up_to(clipped)
    return stages


def _progress(names):
    def show(entry):
        mark = "accepted" if entry["accepted"] else "rejected"
        values = " ".join(f"{n}={entry['params'][n]:.6g}" for n in names)
        print(
            f"  stage {entry['stage']} eval {entry['iteration']:3d}  cost {entry['cost']:.6g}"
            f"  {mark:8s}  {values}",
            file=sys.stderr,
            flush=True,
        )

    return show


def _replanner(args, job):
    """`fit`'s `replan` for the default continuation: after each stage, the horizons from the
    contact onsets of the run at its estimate (`impact_horizons`), those beyond the stage
    just fitted. The start point's run bounces otherwise than the data (on the 12 ms friction
    record 13 impacts where the data have 25), so horizons counted from it put far more
    impacts into a stage than `FIRST_IMPACTS`·2^k; each replan is recorded in
    `schedule.replanned_horizons`."""
    import copy

    from ..fit import Comparison, impact_horizons, onset_times, run_channels

    full = Comparison(job.data, job.stages[-1])
    t0 = float(job.data.t[0])
    job.schedule["replanned_horizons"] = []

    def replan(done, estimate, control):
        end = max(b for _, b in done.windows) if done.windows else full.t_end
        _, trajectory = run_channels(job.scene, {**job.fixed, **estimate}, full.ts, full.names,
                                     control)  # fmt: skip
        if trajectory is None:
            return None
        onsets = onset_times(trajectory)
        horizons = [h for h in impact_horizons(onsets, full.t_end, t0) if h > end * (1 + 1e-9)]
        if not horizons:
            return None
        job.schedule["replanned_horizons"].append(
            {"after": end, "estimate": estimate, "onsets": len(onsets), "horizons": horizons}
        )
        if not args.quiet:
            print(f"horizons from the {len(onsets)} impacts at the estimate: "
                  f"{', '.join(f'{h:.3g}' for h in horizons)} s", file=sys.stderr)  # fmt: skip
        replanned = copy.copy(args)
        replanned.horizons = horizons
        return _stages(replanned, job.data)

    return replan


def _announce_tolerance(stage: int, record: dict) -> None:
    """The console line of a stage's tolerance check at the estimate (`fit(model_error=...)`)."""
    changes = ", ".join(
        f"{st['rtol']:g} -> {st['rtol_check']:g}: {st['rms_difference_over_sigma']:.2g}"
        for st in record["steps"]
    )
    verdict = "" if record["met"] else " (NOT within the limit)"
    print(
        f"stage {stage}: model error at the estimate in noise levels RMS, rtol "
        f"[{changes or record.get('note')}] (limit {record['limit']:g}): "
        f"rtol {record['chosen_rtol']:g}{verdict}",
        file=sys.stderr,
    )


def _tolerance_line(tol) -> str:
    """One line of a `tolerance_check` record."""
    if "estimate_change_in_standard_errors" not in (tol or {}):
        return f"tolerance check at rtol {tol.get('rtol')}: {tol.get('note', 'not run')}"
    moves = ", ".join(f"{n} {v:+.2g}" for n, v in tol["estimate_change_in_standard_errors"].items())
    jacobian = ""
    if "jacobian_change" in tol:
        jacobian = (
            f"; the Jacobian changes by {tol['jacobian_change']:.2g} (limit "
            f"{tol['jacobian_limit']:g}), the standard errors by {tol['standard_error_change']:.2g}"
        )
    return (
        f"tolerance check (rtol {tol['rtol']:g} -> {tol['rtol_check']:g}): model moves "
        f"{tol['rms_model_change_over_sigma']:.2g} noise levels RMS; a refit would move "
        f"the estimates by [{moves}] standard errors{jacobian}"
    )


def run(args) -> int:
    """validate → plan (the output folder's lock) → schedule (model tolerance, horizons) →
    fit (and the refits the tolerance check asks for) → write → report. Every refusal comes
    before the folder is taken and before anything is compiled."""
    from ..fit import MeasurementError
    from . import _plan

    try:
        job = _validate(args)
    except (MeasurementError, ValueError) as err:
        return _fail(str(err))
    try:
        folder = _plan.claim_output(job.out, args.overwrite)
    except FileExistsError as err:
        return _fail(str(err))
    with folder:
        try:
            _schedule(args, job)
            result, refits, wall = _fit(args, job)
        except ValueError as err:
            return _fail(str(err))
        except RuntimeError as err:
            return _fail(str(err), EXIT_FAILED)
        finally:
            if job.ahead is not None:
                job.ahead.join()
        report, figures = _write(args, job, result, wall, folder)
        folder.commit()
    return _report(args, job, result, refits, report, figures)


class _Job:
    """A fit of the command line, checked: scene, data, fixed parameters, step control, the
    parameters to fit, the residual stages, the output folder; `schedule` records what the
    command chose on its own (tolerance, horizons)."""

    def __init__(self, **fields):
        self.schedule = {}
        self.ahead = None  # the fit's program made in a second thread (`_model_ahead`)
        self.__dict__.update(fields)

    @property
    def names(self) -> list[str]:
        return [p.name for p in self.params]


def _validate(args) -> _Job:
    """The fit of the command line; a bad argument raises `ValueError` or
    `MeasurementError` naming it."""
    from ..fit import load_measurements, make_parameters
    from ..io import check_output_dir, default_output_dir

    scene = scene_of(args.scene, args)
    data = load_measurements(args.data)
    if args.channels:
        data = data.select([c.strip() for c in args.channels.split(",") if c.strip()])
    if args.noise:
        data = data.with_noise(_noise(args.noise, data.names))
    _, fixed, control = scene_settings(scene, args)
    params = make_parameters(scene, args.params, fixed)
    stages = _stages(args, data)
    _plan_fit(scene, {**fixed, **{p.name: p.guess for p in params}}, control, data)
    out = args.out or default_output_dir("fit", scene.name)
    try:
        check_output_dir(out, args.overwrite)
    except FileExistsError as err:
        raise ValueError(str(err)) from None
    return _Job(
        scene=scene,
        data=data,
        fixed=fixed,
        control=control,
        params=params,
        stages=stages,
        out=out,
        # The default continuation applies where the user chose none (no windows, widths).
        auto_tolerance=args.dt is None and args.rtol is None,
        auto_horizons=args.horizons == "auto" and not args.window and not args.widths,
    )


def _plan_fit(scene, params, control, data) -> None:
    from . import _plan

    _plan.check_derivative_run(
        scene,
        params,
        control,
        len(data.t),
        f"the {len(data.t)} data times of {scene.name} (a run's states at each, its "
        "sensitivities and residuals)",
        "thin the data (fewer rows)",
    )


def _schedule(args, job) -> None:
    """The model tolerance (`choose_tolerance`, when the user gave none) and the horizons of
    the continuation (`impact_horizons`, from the impacts of the start point's run)."""
    from ..fit import (
        Comparison,
        choose_tolerance,
        first_tolerance,
        impact_horizons,
        onset_times,
        run_channels,
    )

    if not (job.auto_tolerance or job.auto_horizons):
        return
    full = Comparison(job.data, job.stages[-1])
    start = {**job.fixed, **{p.name: p.guess for p in job.params}}
    chooses = job.auto_tolerance and full.noise_known
    first = first_tolerance(job.scene, full, job.control) if chooses else None
    job.ahead = _model_ahead(job, first)
    job.ahead.wait_traced()
    if not args.quiet:
        print("measuring the model's error at the start point...", file=sys.stderr)
    if chooses:
        job.control, record = choose_tolerance(job.scene, start, full, job.control)
    else:
        record = {}
        record["trajectory"] = run_channels(job.scene, start, full.ts, full.names, job.control)[1]
    trajectory = record.pop("trajectory", None)
    job.schedule["tolerance"] = record
    if job.auto_horizons and trajectory is not None:
        onsets = onset_times(trajectory)
        horizons = impact_horizons(onsets, full.t_end, float(job.data.t[0]))
        job.schedule["horizons"] = horizons
        job.schedule["onsets_at_start"] = len(onsets)
        if horizons:
            args.horizons = horizons
            job.stages = _stages(args, job.data)
    if not args.quiet:
        print(
            f"model tolerance: rtol {job.control.rtol}, atol {job.control.atol}; "
            f"horizons: {job.schedule.get('horizons') or 'whole record'}",
            file=sys.stderr,
        )


def _model_ahead(job, control):
    """The fit's Jacobian program (`fit.prepare_fit`) made in a second thread (`_ahead.Ahead`)
    while the main thread measures the model's error at the start point (`_schedule`): from
    an empty cache the Jacobian's trace and XLA compile (slider_crank over 4 ms, the README's
    fit: ~8 s and ~11 s) were the fit's first step, after the schedule's runs (the start run's
    program, ~5 s); now the schedule's runs happen while XLA compiles the Jacobian.

    The program's structure is that of the tolerance the schedule starts from
    (`fit.first_tolerance`; every tolerance it goes on to keeps the method). Nothing is made
    when the program cache is off. `control` None: the command's own control (no tolerance
    to choose)."""
    from ..fit import prepare_fit
    from ._ahead import Ahead

    control = job.control if control is None else control

    def make(on_traced):
        prepare_fit(job.scene, job.data, job.params, fixed=job.fixed, residuals=job.stages,
                    control=control, on_traced=on_traced)  # fmt: skip

    return Ahead("fit-model-ahead", make)


def _fit(args, job):
    """`(result, refits, wall)`: the fit, refitted at tighter tolerances when the default
    tolerance fails the check at the estimate (`refit_until_reproducible`)."""
    import time

    from ..fit import MODEL_ERROR, fit, refit_until_reproducible, tolerance_check

    names = job.names
    if not args.quiet:
        print(
            f"fitting {', '.join(names)} of {job.scene.name} to {', '.join(job.data.names)} "
            f"({job.data.t.size} samples); compiling the model first...",
            file=sys.stderr,
            flush=True,
        )
    start_time = time.perf_counter()
    result = fit(
        job.scene,
        job.data,
        job.params,
        fixed=job.fixed,
        residuals=job.stages,
        control=job.control,
        max_iterations=args.max_iterations,
        starts=args.starts,
        seed=args.seed,
        callback=None if args.quiet else _progress(names),
        # The tolerance chosen at the start point is measured again at each horizon's
        # estimate before the next horizon (`jaxdeploy.fit.tolerance_at_estimate`: why).
        model_error=MODEL_ERROR if job.auto_tolerance else None,
        on_tolerance=None if args.quiet else _announce_tolerance,
        replan=_replanner(args, job) if job.schedule.get("horizons") else None,
    )
    job.control = result.control
    tolerance_check(result, job.scene, job.fixed, job.control)
    refits = []
    if job.auto_tolerance and False in (result.reproducible, result.derivatives_converged):
        # The default tolerance was chosen at the start point; at the estimate it is not
        # tight enough (for the model or for its Jacobian, which gives the standard errors):
        # refit from the estimate at 10x tighter until the check passes.
        if not args.quiet:
            print(_tolerance_line(result.tolerance), file=sys.stderr)
        job.schedule["tolerance_check_before_refits"] = result.tolerance

        def announce(record):
            if not args.quiet:
                values = " ".join(f"{n}={v:.6g}" for n, v in record["estimates"].items())
                print(f"refit at rtol {record['rtol']:g}: {values}; chi2/dof "
                      f"{record['reduced_chi2']:.3g}; {_tolerance_line(record['tolerance'])}",
                      file=sys.stderr)  # fmt: skip

        try:
            result, job.control, refits = refit_until_reproducible(
                result, job.scene, job.data, fixed=job.fixed, control=job.control,
                max_iterations=args.max_iterations,
                callback=None if args.quiet else _progress(names), on_stage=announce,
            )  # fmt: skip
        except RuntimeError as err:
            raise RuntimeError(f"refit at a tighter tolerance: {err}") from None
        job.schedule["tolerance_refits"] = refits
    return result, refits, time.perf_counter() - start_time


def _write(args, job, result, wall, folder):
    """fit.json, history.csv, fit.npz and the figures into the staging `folder`; returns
    `(report, figure names)`."""
    import os

    from ..fit import plot_fit
    from ..io import atomic_write_bytes, atomic_write_json, atomic_write_npz, run_metadata

    names = job.names
    report = result.report()
    report.update(
        scene=job.scene.name,
        scene_options=parse_pairs(args.scene_option, "--scene-option"),
        data=args.data,
        channels=list(job.data.names),
        noise_levels=result.comparison.sigma,
        step_control=job.control.to_json(),
        params={**job.fixed, **result.estimates},
        seed=args.seed if args.starts else None,
        randomness=(
            f"--starts {args.starts}: Latin-hypercube start points drawn with --seed {args.seed}"
            if args.starts
            else "none: Levenberg–Marquardt is deterministic from the initial guess"
        ),
        command=sys.argv,
        wall_time_s=wall,
        schedule=job.schedule,
        versions=run_metadata(),
    )
    rows = ["stage,evaluation,cost,accepted,step," + ",".join(names)]
    for h in result.history:
        rows.append(
            f"{h['stage']},{h['iteration']},{h['cost']!r},{int(h['accepted'])},{h['step']!r},"
            + ",".join(repr(h["params"][n]) for n in names)
        )
    atomic_write_bytes(folder.file("history.csv"), ("\n".join(rows) + "\n").encode())
    cmp_ = result.comparison
    first = result.comparison_initial
    arrays = {"t": cmp_.times, "t_initial": first.times}
    for n in cmp_.names:
        arrays[f"data_{n}"] = cmp_.data_features[n]
        arrays[f"initial_{n}"] = first.features_np(result.model_initial[n])
        arrays[f"fitted_{n}"] = cmp_.features_np(result.model_final[n])
    atomic_write_npz(folder.file("fit.npz"), **arrays)
    figures = [os.path.basename(f) for f in plot_fit(result, folder.staging)]
    atomic_write_json(folder.file("fit.json"), report)
    return report, figures


def _report(args, job, result, refits, report, figures) -> int:
    """Print the estimates and verdicts (nothing with --quiet); return the exit code."""
    names, out = job.names, job.out
    say = print if not args.quiet else (lambda *args, **kwargs: None)
    width = max(len(n) for n in names)
    say(
        f"{'parameter':<{width}}  {'estimate':>12}  {'std. error':>11}  {'rel.':>7}"
        f"  {'x sqrt(chi2/dof)':>16}"
    )
    for n in names:
        rel = result.relative_errors()[n]
        say(
            f"{n:<{width}}  {result.estimates[n]:12.6g}  {result.standard_errors[n]:11.3g}"
            f"  {rel:7.2%}  {result.standard_errors_inflated[n]:16.3g}"
        )
    say(
        f"chi2/dof = {result.reduced_chi2:.3g} ({result.n_residuals} residuals, noise "
        f"{report['noise']}); {result.iterations} LM trial steps; {result.message}"
    )
    for flag in result.flags():
        say(f"warning: {flag}")
    for record in refits:
        say(f"tolerance refit at rtol {record['rtol']:g} (the check at the previous rtol failed)")
    if "estimate_change_in_standard_errors" in (result.tolerance or {}):
        say(_tolerance_line(result.tolerance))
    say(f"wrote {out}/fit.json, history.csv, fit.npz, " + ", ".join(figures))
    say(f"converged: {'yes' if result.converged else 'NO'} ({result.message})")
    if result.reproducible is False:
        say(
            "reproducible: NO -- at a 10x tighter tolerance the model at the estimate changes "
            "by more than the noise; the fit may have matched its integration error"
        )
    if result.adequate:
        say("adequate: yes (chi2/dof consistent with the stated noise, white residuals)")
        if result.reproducible is False:
            return EXIT_NOT_REPRODUCIBLE
        return EXIT_OK if result.converged else EXIT_NOT_CONVERGED
    say(
        "adequate: NO -- the model does not explain the data; the estimates may be biased "
        "far beyond their standard errors (see residuals.png, residual_autocorrelation.png)"
    )
    return EXIT_INADEQUATE
