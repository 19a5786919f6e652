"""Defaults a fit takes from the data: the model's step tolerance (from the noise level) and the
horizons of the continuation (from the spacing of the impacts).

**Tolerance.** The model's integration error must sit well below the measurement noise, or the
fit absorbs it into the parameters and the residuals stop being white. A local error tolerance
does not bound the global error of a run with impacts (each impact amplifies earlier errors),
so the tolerance is chosen by measurement, at the fit's start point: run the model at
rtol_k = rtol_0·10^(−k) (atol scaled alike, the method chosen at rtol_0 kept: `tighter`) and
take the loosest rtol_k whose channels differ from those at rtol_(k+1) by at most
`MODEL_ERROR` noise levels RMS over the fitted samples
(the tighter run is ~10x more accurate, so the difference estimates the looser run's error;
Hairer, Nørsett & Wanner, *Solving ODEs I*, §II.4). A model error of 0.2 σ RMS adds 0.04 to
χ²/dof. rtol_0 is the smaller of the scene's default and 1e-2 σ/RMS(y), never below
`RTOL_FLOOR` (the search's cost grows ~2x per decade; the check after the fit goes further,
`refit_until_reproducible`). The start point's model error need not be the truth's, so the
fit repeats the comparison at each stage's estimate before the next stage and tightens where
it has grown (`fit(model_error=...)`, `tolerance_at_estimate`, with `tighten`, the search
itself). After the fit `tolerance_check` repeats the
comparison at the estimate and computes the Gauss–Newton step a refit at the tighter
tolerance would take, in standard errors; where it fails, the command refits from the
estimate at 10x tighter tolerances until it passes (`refit_until_reproducible`): the start
point's model error need not be the estimate's (a start that bounces less accumulates less
integration error over the record).

**Horizons.** Each impact multiplies the sensitivity of the later motion to the parameters, so
the loss over many impacts is rugged (local minima a few per cent apart) while over a few it is
a smooth bowl tens of per cent wide (docs/identification.md). With the run at the start point
showing onsets at t_1 < t_2 < …, the fit grows its horizon through the onsets
`FIRST_IMPACTS`, 2·`FIRST_IMPACTS`, 4·`FIRST_IMPACTS`, …, then (beyond the impacts the start
run shows) by at most doubling the elapsed time, and ends on the whole record, each stage
starting from the previous estimate: the windows come from the impact spacing of this
record, not from constants. The command counts the onsets again in the run at each stage's
estimate and replaces the remaining horizons by this function's for them (`fit(replan=...)`):
the start run need not bounce like the data. A record without impacts gets one stage.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

MODEL_ERROR = 0.2  # largest model error accepted, RMS, in noise levels
RTOL_FLOOR = 1e-10
FIRST_IMPACTS = 4
MAX_DECADES = 6


def run_channels(scene, params, ts, names, control):
    from ..batch import run_scene

    traj = run_scene(scene, params, float(ts[-1]), ts=np.asarray(ts), control=control)
    if not traj.ok:
        return None, None
    channels = scene.select_channels(scene.build(params), traj, names)
    return {n: np.asarray(v) for n, v in channels.items()}, traj


def _scaled(control, factor: float):
    """`control` (a `StepControl`) with rtol and atol multiplied by `factor`."""
    atol = None if control.atol is None else control.atol * factor
    return control.replace(rtol=control.rtol * factor, atol=atol)


def tighter(control):
    """`control` (a `StepControl`) with rtol and atol 10x smaller and its method kept: an
    automatic choice (`"auto"`) is resolved at `control`'s own rtol, so the tighter run does
    not switch from Tsit5 to Dopri8 where rtol crosses `solvers.AUTO_TIGHT_RTOL`.

    Why: the comparison at rtol/10 estimates the integration error of this run, the method's
    error at this tolerance (Hairer, Nørsett & Wanner, *Solving ODEs I*, §II.4: the run at a 10x
    tighter tolerance is ~10x more accurate). The same method at rtol/10 is that estimate, and
    it needs no program of its own: the tolerances are data of the compiled programs
    (`solvers.tolerances_as_data`; the fit's `Model`, `_model_program.tolerances`), the method
    is not. Switching to Dopri8 compiled a second program of each kind the fit runs (the
    channels and their Jacobian). The README's slider_crank fit from an empty cache (2-core AMD
    EPYC, one process each): 37.3 s wall, 50.1 s user CPU with the switch; 26.4 s, 28.7 s with
    the method kept; the same estimates and verdicts (rtol 1e-8, checked at 1e-9 by Dopri8 and
    by Tsit5: the Jacobian changes by 0.008 and 0.0061, the model by 0.00013 and 0.00011 noise
    levels RMS).
    A search that moves to the tighter tolerance (`tighten`, `refit_until_reproducible`)
    keeps the method too."""
    return _scaled(control, 0.1).replace(solver=control.resolved_solver())


def model_difference(a: Mapping, b: Mapping, comparison) -> float:
    """Largest over channels of the RMS of (a − b)/σ over the fitted samples."""
    used = comparison.used
    return max(
        float(np.sqrt(np.mean(((a[n] - b[n])[used] / comparison.sigma[n]) ** 2)))
        for n in comparison.names
    )


def first_tolerance(scene, comparison, control=None):
    """The step control `choose_tolerance` starts from: rtol_0 (module docstring) and atol
    scaled alike; `control` resolved (`batch.step_control`) when it has no rtol. Every
    control the search goes on to (`tighter`) keeps its method, so the fit's programs made
    for this one (`Model.make_ready`) serve the one chosen."""
    from ..batch import step_control

    base = step_control(scene, control)
    if base.rtol is None:
        return base
    scale = max(float(np.sqrt(np.mean(comparison.data_features[n] ** 2))) for n in comparison.names)
    noise = min(comparison.sigma.values())
    rtol0 = min(base.rtol, 1e-2 * noise / scale) if scale > 0 else base.rtol
    rtol0 = max(10.0 ** math.floor(math.log10(rtol0)), RTOL_FLOOR)
    return _scaled(base, rtol0 / base.rtol)


def choose_tolerance(scene, params: Mapping, comparison, control=None):
    """`(control, record)`: the step control whose model error at `params` is at most
    `MODEL_ERROR` noise levels RMS (module docstring), and what was measured. `record` also
    holds the start run's trajectory (`"trajectory"`, not JSON) for `impact_horizons`."""
    current = first_tolerance(scene, comparison, control)
    ts, names = comparison.ts, comparison.names
    if current.rtol is None:  # fixed steps (or atol alone): no relative tolerance to choose
        y, traj = run_channels(scene, params, ts, names, current)
        return current, {"chosen_rtol": None, "met": None, "steps": [],
                         "note": "fixed step", "trajectory": traj}  # fmt: skip
    y, traj = run_channels(scene, params, ts, names, current)
    if y is None:
        raise RuntimeError(
            f"the model cannot be simulated at the start point with rtol {current.rtol:g}; "
            "change the guess, the bounds or give --rtol"
        )
    current, steps, met, (y, traj) = tighten(
        lambda c: run_channels(scene, params, ts, names, c), comparison, current, (y, traj)
    )
    return current, {"chosen_rtol": current.rtol, "met": met, "steps": steps,
                     "trajectory": traj}  # fmt: skip


def tighten(evaluate, comparison, control, first, limit: float = MODEL_ERROR):
    """`(control, steps, met, result)`: from `control` down by decades, the loosest rtol
    whose channels differ from those at rtol/10 by at most `limit` noise levels RMS over the
    fitted samples (`model_difference`; the module docstring's rule), at most `MAX_DECADES`
    tightenings and none below `RTOL_FLOOR`. `evaluate(control)` → `(channels, extra)`,
    channels None when the run failed; `first` is its value at `control`. `steps`: one
    record per comparison; `met`: whether the last one was within `limit` (False also when a
    tighter run failed or a limit stopped the search); `result`: `evaluate` at the chosen
    control."""
    current, result, steps = control, first, []
    for _ in range(MAX_DECADES):
        if current.rtol / 10.0 < RTOL_FLOOR * (1 - 1e-9):
            break
        tighter_control = tighter(current)
        result_tight = evaluate(tighter_control)
        if result_tight[0] is None:
            break
        diff = model_difference(result[0], result_tight[0], comparison)
        steps.append({"rtol": current.rtol, "rtol_check": tighter_control.rtol,
                      "rms_difference_over_sigma": diff})  # fmt: skip
        if diff <= limit:
            return current, steps, True, result
        current, result = tighter_control, result_tight
    return current, steps, False, result


def onset_times(trajectory) -> np.ndarray:
    """Contact onsets seen at the saved times (a clearance joint's `in_contact` going 0 → 1),
    all joints together, sorted [s]. Contacts shorter than the save spacing may be missed,
    which only coarsens the schedule."""
    ts = np.asarray(trajectory.ts)
    out = []
    for memory in trajectory.memory or ():
        if not isinstance(memory, Mapping) or "in_contact" not in memory:
            continue
        flag = np.asarray(memory["in_contact"]) > 0.5
        if flag.ndim != 1:
            continue
        out.extend(ts[1:][flag[1:] & ~flag[:-1]])
    return np.sort(np.asarray(out, dtype=float))


def impact_horizons(onsets, t_end: float, t_start: float = 0.0) -> list[float]:
    """Horizons through the onsets number FIRST_IMPACTS, 2·FIRST_IMPACTS, … (the midpoint to
    the next onset, so a stage ends in flight); beyond the last of them each horizon at most
    doubles the elapsed time (skipped when it would leave less than a quarter of itself to
    `t_end`); then `t_end`. [] for fewer impacts.

    The doubling covers impacts the start run does not show: a start 20 % off in c_e or c
    bounces differently, and on issue 20's 12 ms slider-crank record the start run showed
    fewer than 16 impacts where the measurements have 25, so the schedule jumped from the
    8th impact to all 25 and the last stage converged to a local minimum (χ²/dof 2.2 where
    the truth gives 1.1). The record's impact rate is assumed to stay that of the elapsed
    part, so doubling the time about doubles the impacts, as the counted stages do."""
    onsets = np.asarray(onsets, dtype=float)
    onsets = onsets[onsets < t_end]
    out = []
    n = FIRST_IMPACTS
    while n < onsets.size:
        horizon = 0.5 * (onsets[n - 1] + onsets[n])
        if not out or horizon > out[-1]:
            out.append(float(horizon))
        n *= 2
    if not out:
        return []
    # A doubled horizon that would leave less than a quarter of itself to the record's end
    # is not worth a stage of its own: the record is next.
    while t_start + 2.5 * (out[-1] - t_start) < t_end:
        target = t_start + 2.0 * (out[-1] - t_start)
        after = onsets[onsets > target]
        before = onsets[onsets <= target]
        if after.size and before.size and before[-1] > out[-1]:  # end the stage in flight
            target = 0.5 * (before[-1] + after[0])
        out.append(float(target))
    return [*out, float(t_end)]
