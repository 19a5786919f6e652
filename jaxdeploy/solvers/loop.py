"""The integration loop of `simulate`, written for its solvers and controllers alone.

`diffrax.diffeqsolve` is a general loop: it serves SDEs, events with root finding, dense
output, backward time, jumps, any number of `SaveAt` subs, and it traces the step three times
to decide which parts of its state are static (`diffrax/_integrate.py`, `loop`). Each of these
is compiled into every program whether the run uses it or not. For slider_crank's Tsit5
program XLA compiles 9553 operations, of which 1500 are diffrax's end-time threshold alone
(t₁ − 100 ULP, 100 chained `nextafter`), and 4351 its loop machinery (docs/performance.md,
its table of what XLA compiles). This module is the loop those runs need and nothing more:

* forward time t₀ < t₁, one `MechanismTerm`, one solver (`TrackExtremes` around a mechanism
  solver) and one step-size controller (`prepare`'s: `stop_at_non_finite` around PID,
  `LocateEvents`, `ClipStepSizeController`, `ReplaySteps` or constant steps);
* saves at given times (`ts`, each through `fn` as diffrax's `SubSaveAt(ts=..., fn=...)`) and,
  optionally, the end of every accepted step (diffrax's `SubSaveAt(steps=True)`);
* the final solver state (the extremes and contact episodes `TrackExtremes` keeps), the time
  reached, the result code and the step counts.

Its arithmetic is diffrax's, operation for operation, so that a run through it is bit for bit
the run through `diffeqsolve` (tests/test_loop.py checks that on every solver and controller
`prepare` builds). Per step (diffrax 0.7, `loop.body_fun_aux`):

    y₁, ε, dense, s₁, r = solver.step(tₙ, tₙ₊₁, yₙ, sₙ)      ε: NaN → +∞
    keep, t', t'', jump, c', r' = controller.adapt_step_size(tₙ, tₙ₊₁, yₙ, y₁, ε, cₙ)
    t' = min(t', t₁);  t'' = t₁ if keep else t' + (t₁ − t')/2   where t'' > t₁ − 100 ULP
    (y, s) = (y₁, s₁) if keep else (yₙ, sₙ);  result = first failure of r (kept steps), r'
    saved: fn(t, dense(t)) for every save time t in (tₙ, tₙ₊₁] of a kept step

What differs is only what it compiles: the threshold t₁ − 100 ULP is a loop of 100
`nextafter` (a few operations, not 1500), the step is traced once (whether the controller's
`made_jump` is static is read from the controller alone), and nothing a run does not use is
traced at all.

Measured (one process per program, compilation cache off, `benchmarks.programs.
compile_stats`; 2-core AMD EPYC, load ~1; scene defaults, every output saved), diffeqsolve →
this loop: slider_crank over 4 ms 10372 → 8664 operations, XLA's compile 3.03 → 2.71 CPU-s,
tracing and lowering 1.26 → 0.95 CPU-s; deploy_array over 0.6 s 18497 → 16889 operations,
7.44 → 6.93 and 2.64 → 2.11 CPU-s. Warm runs take the same time (the step is the cost). The
reverse-mode gradient of the bench's deploy_array loss (`benchmarks.targets.gradient`) keeps
its size, 71229 → 71150 operations (~40 CPU-s XLA, ~30 tracing): there the differentiated
step is the program.

Differentiation: `kind` chooses the while loop as diffrax's adjoints do
(`equinox.internal.while_loop`): `"checkpointed"` for reverse mode (diffrax's
`RecursiveCheckpointAdjoint`, the default; the saved arrays are the loop's buffers, written
in place), `"lax"` for forward mode (`ForwardMode`), `"bounded"` for both (`DirectAdjoint`).
`kind_for(adjoint)` maps an adjoint to its kind.

`jaxdeploy.simulation.simulate` integrates with it (`_solve`, and `_accepted_step_times` for
replayed steps); `jaxdeploy.simulation.integrate` keeps `diffeqsolve` for callers that need its
other options.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import diffrax as dfx
import equinox as eqx
import equinox.internal as eqxi
import jax
import jax.numpy as jnp

from .._tracing import batched_like, differentiated_like

__all__ = ["KINDS", "Solution", "kind_for", "solve"]

KINDS = ("lax", "checkpointed", "bounded")

# diffrax rounds a step end within 100 ULP of t₁ to t₁ (`_clip_to_end`): shorter last steps
# make its dense output numerically unstable.
_CLIP_ULPS = 100


class Solution(NamedTuple):
    """What `solve` returns.

    `ts` (N,) and `ys` (leading axis N): the save times and `fn(t, y)` at them, +inf where the
    run did not reach them (None without `ts`); `step_ts` (max_steps,): the end of every
    accepted step, padded with +inf (None unless `save_steps`); `t_reached` [s]: where the run
    ended (t₁ unless it failed); `y_final`: the state there; `result`: a `diffrax.RESULTS`;
    `stats`: `num_steps`, `num_accepted_steps`, `num_rejected_steps`, `max_steps` (diffrax's
    names); `solver_state`: the solver's final state.
    """

    ts: jax.Array | None
    ys: Any
    step_ts: jax.Array | None
    t_reached: jax.Array
    y_final: Any
    result: dfx.RESULTS
    stats: dict
    solver_state: Any


class _Carry(NamedTuple):
    y: Any
    tprev: jax.Array
    tnext: jax.Array
    made_jump: Any  # None when the controller never jumps (static False)
    solver_state: Any
    controller_state: Any
    result: dfx.RESULTS
    num_steps: jax.Array
    num_accepted: jax.Array
    num_rejected: jax.Array
    save_ts: jax.Array | None
    save_ys: Any
    save_index: jax.Array
    ts_index: jax.Array
    step_ts: jax.Array | None
    meter_state: Any


def kind_for(adjoint) -> str:
    """The while loop (`KINDS`) that differentiates as `adjoint` does in `diffeqsolve`:
    `RecursiveCheckpointAdjoint` → "checkpointed", `ForwardMode` → "lax", `DirectAdjoint` →
    "bounded". Other adjoints (backsolve, implicit) have no counterpart here."""
    if adjoint is None or isinstance(adjoint, dfx.RecursiveCheckpointAdjoint):
        return "checkpointed"
    if isinstance(adjoint, dfx.ForwardMode):
        return "lax"
    if isinstance(adjoint, dfx.DirectAdjoint):
        return "bounded"
    raise ValueError(
        f"adjoint = {adjoint!r} has no counterpart in jaxdeploy's integration loop: use "
        "RecursiveCheckpointAdjoint (reverse mode), ForwardMode or DirectAdjoint"
    )


def clip_floor(t1):
    """t₁ − 100 ULP (`_CLIP_ULPS` times `equinox.internal.prevbefore`, diffrax's threshold for
    rounding a step end to t₁), as a loop: diffrax unrolls the 100 steps into ~1500 compiled
    operations. Step decisions carry no derivative, so neither does the threshold."""
    return jax.lax.fori_loop(
        0, _CLIP_ULPS, lambda _, t: eqxi.prevbefore(t), jax.lax.stop_gradient(t1)
    )


def _clip_to_end(tprev, tnext, t1, floor, keep_step):
    """A step end past the threshold becomes t₁ (kept step) or half the way there (rejected:
    the controller's proposal was for a longer step than the one left)."""
    tclip = jnp.where(keep_step, t1, tprev + 0.5 * (t1 - tprev))
    return jnp.where(tnext > floor, tclip, tnext)


def _never_jumps(controller, term, t0, t1, y0, dt0, error_order) -> bool:
    """Whether `controller.adapt_step_size` returns `made_jump` as the Python value False
    (then the solver gets it static, and a first-same-as-last solver reuses its last stage
    without a branch). Read from the controller alone, on abstract values; diffrax instead
    traces the whole step twice more. Any doubt (an abstract evaluation that fails) carries
    `made_jump` as data, which is always correct."""

    def adapt(y0, controller_state):
        out = controller.adapt_step_size(t0, t1, y0, y0, None, y0, error_order, controller_state)
        return out[3] if isinstance(out[3], bool) else jnp.asarray(out[3])

    try:
        _, controller_state = jax.eval_shape(
            lambda: controller.init(term, t0, t1, y0, dt0, None, None, error_order)
        )
        made_jump = jax.eval_shape(adapt, y0, controller_state)
    except Exception:  # noqa: BLE001 - any failure means "not known to be static"
        return False
    return made_jump is False


def _fixed_steps(controller) -> bool:
    """Whether `controller` (through its wrappers' `controller`) takes constant steps: then
    the loop's time may be the same for every case of a vmap, and its carry stays partly
    unbatched."""
    while not isinstance(controller, dfx.ConstantStepSize) and hasattr(controller, "controller"):
        controller = controller.controller
    return isinstance(controller, dfx.ConstantStepSize)


def _promote(x):
    """diffrax's promotion of the initial state to the time dtype (`diffeqsolve`)."""
    with jax.numpy_dtype_promotion("standard"):
        dtype = jnp.result_type(x, jnp.float64 if jax.config.jax_enable_x64 else jnp.float32)
    return jnp.asarray(x, dtype=dtype)


def _identity(t, y, args):
    return y


def solve(
    term,
    solver,
    controller,
    t0,
    t1,
    dt0,
    y0,
    max_steps: int,
    *,
    ts=None,
    fn=None,
    dense_fn=None,
    save_steps: bool = False,
    kind: str = "checkpointed",
    checkpoints: int | None = None,
    progress_meter=None,
) -> Solution:
    """Integrate `term` with `solver` from `y0` at `t0` to `t1` (> t0), steps chosen by
    `controller` from a first step `dt0`, at most `max_steps` steps (module docstring).

    **Arguments:** `ts`: save times in [t0, t1], non-decreasing; `fn(t, y, args)`: what a
    saved time keeps (default: the state; `args` None); `dense_fn(t, dense)`: the same, from
    the dense output `dense` of the step the time lies in, for what needs more of the step
    than its state or less than `dense.evaluate` traces (default `fn(t, dense.evaluate(t),
    None)`; `fn` still gives the state at t₀ when t₀ = t₁, in the same structure);
    `save_steps`: also save the end of every accepted step; `kind`: the while loop (`KINDS`,
    `kind_for`); `checkpoints`: for
    `"checkpointed"`, as `RecursiveCheckpointAdjoint(checkpoints=...)`; `progress_meter`: a
    diffrax progress meter (default none).

    **Returns:** a `Solution`. Like `diffeqsolve(..., throw=False)`, it never raises on a
    failed run: the failure is its `result`.
    """
    if kind not in KINDS:
        raise ValueError(f"kind = {kind!r} is invalid: valid values are {', '.join(KINDS)}")
    if not (isinstance(max_steps, int) and max_steps > 0):
        raise ValueError(f"max_steps = {max_steps!r} is invalid: it must be an integer > 0")
    fn = _identity if fn is None else fn
    if dense_fn is None:

        def save(t, dense):
            return fn(t, dense.evaluate(t), None)

    else:
        save = dense_fn
    meter = dfx.NoProgressMeter() if progress_meter is None else progress_meter
    t0, t1 = jnp.asarray(t0, dtype=float), jnp.asarray(t1, dtype=float)
    dt0 = jnp.asarray(dt0, dtype=float)
    y0 = jax.tree.map(_promote, y0)
    controller = controller.wrap(1)
    error_order = solver.error_order(term)

    tnext, controller_state = controller.init(term, t0, t1, y0, dt0, None, solver.func, error_order)
    tnext = jnp.minimum(tnext, t1)
    solver_state = solver.init(term, t0, tnext, y0, None)
    static_jump = _never_jumps(controller, term, t0, t1, y0, dt0, error_order)

    if ts is not None:
        ts = jnp.asarray(ts, dtype=float)
        struct = eqx.filter_eval_shape(fn, t0, y0, None)
        save_ts = jnp.full(ts.shape, jnp.inf)
        save_ys = jax.tree.map(lambda s: jnp.full(ts.shape + s.shape, jnp.inf, s.dtype), struct)
    else:
        save_ts = save_ys = None
    init = _Carry(
        y=y0,
        tprev=t0,
        tnext=tnext,
        made_jump=None if static_jump else jnp.array(False),
        solver_state=solver_state,
        controller_state=controller_state,
        result=dfx.RESULTS.successful,
        num_steps=jnp.array(0),
        num_accepted=jnp.array(0),
        num_rejected=jnp.array(0),
        save_ts=save_ts,
        save_ys=save_ys,
        save_index=jnp.array(0),
        ts_index=jnp.array(0),
        step_ts=jnp.full(max_steps, jnp.inf) if save_steps else None,
        meter_state=meter.init(),
    )
    if not _fixed_steps(controller):
        # Adaptive steps: under vmap the loop's time, hence its predicate, varies by case, so
        # JAX batches the whole carry; batched from the start, it does so in one round of its
        # fixed point instead of one per part that becomes batched (`batched_like`).
        init = batched_like(init, (term, solver, controller, t0, t1, dt0, ts))
    if kind == "lax":
        # Forward mode: the parts every step makes depend on the parameters carry tangents
        # from the start, batched under jacfwd's vmap (`differentiated_like`).
        y, solver_state, save_ys = differentiated_like(
            (init.y, init.solver_state, init.save_ys), (term, solver, controller, y0)
        )
        init = init._replace(y=y, solver_state=solver_state, save_ys=save_ys)
    floor = clip_floor(t1)

    def cond(c):
        return (c.tprev < t1) & dfx.is_successful(c.result)

    def body(c):
        return _step(c, term, solver, controller, t0, t1, floor, ts, save, kind, error_order, meter)

    def buffers(c):
        # The structure alone (None fields included): equinox replaces the leaves by
        # placeholders to find the buffers, so this must not look at them.
        return c.save_ts, c.save_ys, c.step_ts

    final = eqxi.while_loop(
        cond,
        body,
        init,
        max_steps=max_steps,
        buffers=buffers,
        kind=kind,
        checkpoints=checkpoints if kind == "checkpointed" else None,
    )
    meter.close(final.meter_state)
    save_ts, save_ys = final.save_ts, final.save_ys
    if ts is not None:
        # t₀ = t₁: the loop never ran; diffrax saves the state at every save time.
        at_t0 = t0 == t1
        save_ts = jnp.where(at_t0, t0, save_ts)
        y_t0 = fn(t0, final.y, None)
        save_ys = jax.tree.map(
            lambda ys, y: jnp.where(at_t0, jnp.broadcast_to(y, ys.shape), ys), save_ys, y_t0
        )
    result = dfx.RESULTS.where(cond(final), dfx.RESULTS.max_steps_reached, final.result)
    stats = {
        "num_steps": final.num_steps,
        "num_accepted_steps": final.num_accepted,
        "num_rejected_steps": final.num_rejected,
        "max_steps": max_steps,
    }
    return Solution(
        save_ts, save_ys, final.step_ts, final.tprev, final.y, result, stats, final.solver_state
    )


def _step(c, term, solver, controller, t0, t1, floor, ts, save, kind, error_order, meter):
    """One attempted step: the solver's step, the controller's decision, the saves."""
    made_jump = False if c.made_jump is None else c.made_jump
    y, y_error, dense_info, solver_state, solver_result = solver.step(
        term, c.tprev, c.tnext, c.y, None, c.solver_state, made_jump
    )
    # A NaN error estimate rejects the step (diffrax #143): a shorter one may be finite.
    y_error = jax.tree.map(lambda x: jnp.where(jnp.isnan(x), jnp.inf, x), y_error)
    keep_step, tprev, tnext, jump, controller_state, controller_result = controller.adapt_step_size(
        c.tprev, c.tnext, c.y, y, None, y_error, error_order, c.controller_state
    )
    tprev = jnp.minimum(tprev, t1)
    tnext = _clip_to_end(tprev, tnext, t1, floor, keep_step)
    meter_state = meter.step(c.meter_state, jnp.where(t1 > t0, (tprev - t0) / (t1 - t0), 1.0))

    def keep(a, b):
        return jnp.where(keep_step, a, b)

    y = jax.tree.map(keep, y, c.y)
    solver_state = jax.tree.map(keep, solver_state, c.solver_state)
    made_jump = None if c.made_jump is None else keep(jump, c.made_jump)
    solver_result = dfx.RESULTS.where(keep_step, solver_result, dfx.RESULTS.successful)
    result = dfx.RESULTS.where(dfx.is_okay(c.result), solver_result, c.result)
    result = dfx.RESULTS.where(dfx.is_okay(result), controller_result, result)
    num_accepted = c.num_accepted + jnp.where(keep_step, 1, 0)

    save_ts, save_ys, save_index, ts_index = c.save_ts, c.save_ys, c.save_index, c.ts_index
    if ts is not None:
        dense = solver.interpolation_cls(t0=c.tprev, t1=c.tnext, **dense_info)
        save_ts, save_ys, save_index, ts_index = _save_in_step(
            keep_step, c.tnext, dense, ts, save, kind, (save_ts, save_ys, save_index, ts_index)
        )
    step_ts = c.step_ts
    if step_ts is not None:
        step_ts = eqxi.buffer_at_set(step_ts, c.num_accepted, tprev, pred=keep_step)
    return _Carry(
        y=y,
        tprev=tprev,
        tnext=tnext,
        made_jump=made_jump,
        solver_state=solver_state,
        controller_state=controller_state,
        result=result,
        num_steps=c.num_steps + 1,
        num_accepted=num_accepted,
        num_rejected=c.num_rejected + jnp.where(keep_step, 0, 1),
        save_ts=save_ts,
        save_ys=save_ys,
        save_index=save_index,
        ts_index=ts_index,
        step_ts=step_ts,
        meter_state=meter_state,
    )


def _save_in_step(keep_step, tnext, dense, ts, save, kind, saves):
    """Every save time of a kept step's interval (tₙ, tₙ₊₁] not saved yet, from its dense
    output: a loop over the save times, as diffrax's (one iteration per time saved)."""
    n = ts.shape[0]

    def cond(s):
        _, _, _, i = s
        return keep_step & (ts[jnp.minimum(i, n - 1)] <= tnext) & (i < n)

    def body(s):
        save_ts, save_ys, save_index, i = s
        t = ts[i]
        y = save(t, dense)
        save_ts = save_ts.at[save_index].set(t)
        # Over y's structure: inside a checkpointed loop each leaf of save_ys is a buffer.
        save_ys = jax.tree.map(lambda yi, ys: ys.at[save_index].set(yi), y, save_ys)
        return save_ts, save_ys, save_index + 1, i + 1

    return eqxi.while_loop(
        cond,
        body,
        saves,
        max_steps=n,
        buffers=lambda s: (s[0], s[1]),
        kind=kind,
        checkpoints=n if kind == "checkpointed" else None,
    )
