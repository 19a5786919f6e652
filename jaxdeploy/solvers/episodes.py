"""Contact episodes of the clearance joints, logged over every accepted step of a run.

An episode of a clearance joint runs from the onset of a contact (the journal's surface
reaches the bearing's: δ rises through the elastic law's onset, 0 for Hertz) to its separation.
Per episode the log keeps

* `onset_time` [s] and `impact_velocity` v⁻ [m/s]: where the joint's memory located the onset
  inside the step (`RevoluteClearance`'s `event_fraction`, on the step's interpolant of the
  eccentricity) and the v⁻ it latched there; with adaptive steps and event location the step
  itself ends just past the onset (`LocateEvents`), so both are as accurate as the state;
* `separation_time` [s] (NaN while the contact lasts at the end of the run), located likewise;
* `peak_force` [N] and `peak_force_time` [s]: the largest net normal force of the episode,
  maximised over each step's dense output (`step_maxima`), not sampled at step ends;
* `peak_penetration` [m]: the largest δ = |e| − c, maximised the same way;
* `impulse` [N s]: ∫ F_N dt over the episode, Simpson's rule on each step's dense output.

The log is part of the solver's state (`TrackExtremes` folds it), so a rejected step changes
nothing and the result does not depend on the output times. Episodes are numbered per joint in
the order they begin; the first `capacity` of each joint are kept (`count` says how many there
were). A contact that begins and ends inside one step is not seen: with event location a step
ends at every onset, with fixed steps such a graze is lost (as in any step-end test).

`step_maxima` is the refinement by itself — the largest value of each component of a function
of time on one step, located on samples and refined by successive parabolic interpolation (no
derivatives of the interpolant; `step_maximum` for a scalar function) — written as
a pure JAX function of the step's interpolant, so that gradients of a peak can reuse it: the
location is gradient-stopped and the value differentiates by the envelope theorem (at an
interior maximum df/dt = 0, so the peak's derivative with respect to a parameter is ∂f/∂θ at
the peak's time; Milgrom & Segal, *Econometrica* 70 (2002) 583).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from .._tracing import traced_once
from ..mechanism import RevoluteClearance

DEFAULT_CAPACITY = 128  # episodes kept per clearance joint
SAMPLES = 8  # equal intervals of a step sampled to bracket its maximum (Simpson needs even)
# Successive parabolic interpolation steps from the best sample (`step_maxima`). A Gaussian
# peak of width w (in step lengths) plus a slope, against 40 steps: w = 0.1 converged to
# round-off after 5 steps, w = 0.045 (narrower than the samples' spacing, 1/8) to 2.5e-10
# relative after 6 and to round-off after 7. deploy_array's 36 episode peaks (force,
# penetration) were within 5.6e-11 and 2.4e-10 of 12 steps' already with 4, slider_crank's
# within 1e-12 (Newton's method, which this replaced, was within 7e-11 and 1.3e-9). Each step
# costs a little warm time (slider_crank: 4 steps 0.046-0.048 s, 8 steps 0.048-0.065 s).
PARABOLIC = 6

FIELDS = (
    "onset_time",
    "impact_velocity",
    "separation_time",
    "peak_force",
    "peak_force_time",
    "peak_penetration",
    "impulse",
)
UNITS = {
    "onset_time": "s",
    "impact_velocity": "m/s",
    "separation_time": "s",
    "peak_force": "N",
    "peak_force_time": "s",
    "peak_penetration": "m",
    "impulse": "N s",
}


class EpisodeLog(NamedTuple):
    """Per clearance joint (first axis, the order of `mechanism.find(RevoluteClearance)`):
    `count` (k,) episodes begun so far, and each of `FIELDS` as a (k, capacity) array (NaN in
    slots not reached); `force_max`, `penetration_max` (k,): the refined peaks over every
    contact step of the run, whatever the capacity (what `Trajectory.extremes` reports)."""

    count: jax.Array
    onset_time: jax.Array
    impact_velocity: jax.Array
    separation_time: jax.Array
    peak_force: jax.Array
    peak_force_time: jax.Array
    peak_penetration: jax.Array
    impulse: jax.Array
    force_max: jax.Array
    penetration_max: jax.Array


def _vertex(p, fp):
    """The abscissa of the vertex of the parabola through (p[:, i], fp[:, i]), i = 0, 1, 2, of
    each row, and whether there is one (Press et al., *Numerical Recipes in C*, 2nd ed. (1992),
    eq. 10.2.1): x = b − ½ [(b−a)²(f_b−f_c) − (b−c)²(f_b−f_a)] / [(b−a)(f_b−f_c) −
    (b−c)(f_b−f_a)]."""
    a, b, c = p[:, 0], p[:, 1], p[:, 2]
    fa, fb, fc = fp[:, 0], fp[:, 1], fp[:, 2]
    numerator = (b - a) ** 2 * (fb - fc) - (b - c) ** 2 * (fb - fa)
    denominator = (b - a) * (fb - fc) - (b - c) * (fb - fa)
    exists = denominator != 0
    return b - 0.5 * numerator / jnp.where(exists, denominator, 1.0), exists


def _best_triple(p, fp, x, fx):
    """Per row, of the increasing triple `p` and a fourth point `x` (not one of them), the
    three consecutive points around the highest value, by comparisons and static slices (no
    sort, no dynamic slice: elementwise work XLA fuses)."""
    position = jnp.sum(x[:, None] > p, axis=1)  # where x goes among the three

    def sorted_column(i):  # column i of the four points in increasing order
        if i == 0:
            return jnp.where(position == 0, x, p[:, 0]), jnp.where(position == 0, fx, fp[:, 0])
        if i == 3:
            return jnp.where(position == 3, x, p[:, 2]), jnp.where(position == 3, fx, fp[:, 2])
        below, at = position < i, position == i
        return (
            jnp.where(below, p[:, i - 1], jnp.where(at, x, p[:, i])),
            jnp.where(below, fp[:, i - 1], jnp.where(at, fx, fp[:, i])),
        )

    columns = [sorted_column(i) for i in range(4)]
    p4 = jnp.stack([c[0] for c in columns], axis=1)
    f4 = jnp.stack([c[1] for c in columns], axis=1)
    # The best of the four is at 0 or 1: keep points 0-2; at 2 or 3: points 1-3.
    upper = jnp.maximum(f4[:, 2], f4[:, 3]) > jnp.maximum(f4[:, 0], f4[:, 1])
    return (
        jnp.where(upper[:, None], p4[:, 1:], p4[:, :3]),
        jnp.where(upper[:, None], f4[:, 1:], f4[:, :3]),
    )


def step_maxima(f, t0, t1, samples: int = SAMPLES, iterations: int = PARABOLIC):
    """`(t*, f(t*), values)`: the largest value of each component of `f(t)` (shape (m,)) on
    [t0, t1], with t* (m,) where it is reached.

    `f` is evaluated at `samples` + 1 equally spaced times (`values`, (samples + 1, m), the
    ends included). Each component is then refined by `iterations` steps of successive
    parabolic interpolation (Press et al., *Numerical Recipes in C*, 2nd ed. (1992), §10.2):
    from the best sample and its two neighbours (the two nearest inside the interval when it
    is an end), the vertex of the parabola through the three points, kept only inside the
    samples around the best one, joins them and the best three consecutive points of the four
    go on (`_refined`; skipped, bit for bit, where the first vertex is of no use). The m
    refinements evaluate `f` together (one batched call per iteration), so the
    function is traced once for all of them. No derivative of `f` is taken: Newton's method on
    f′ = 0 needed second derivatives by nested forward mode, 28 % of deploy_array's compiled
    program (issue 32). The result is never worse than the best sample (at a kink, e.g. a
    contact's onset or the `max(0, ·)` of a damped law, it keeps the sample). `t*` is
    gradient-stopped; `f(t*)` differentiates with respect to whatever `f` closes over by the
    envelope theorem (module docstring). Pure JAX: jits, vmaps and differentiates.
    """
    grid = jnp.linspace(0.0, 1.0, samples + 1)
    times = jax.lax.stop_gradient(t0 + (t1 - t0) * grid)
    values = jax.vmap(f)(times)
    sampled = jax.lax.stop_gradient(values)
    m = values.shape[1]
    component = jnp.arange(m)

    def f_each(t):  # component i of f at t[i], one batched evaluation
        # (f at every t[j] and its diagonal ran 1.4x slower in deploy_array's warm run)
        return jax.vmap(lambda ti, i: f(ti)[i])(t, component)

    k = jnp.argmax(sampled, axis=0)
    lo, hi = times[jnp.maximum(k - 1, 0)], times[jnp.minimum(k + 1, samples)]
    middle = jnp.clip(k, 1, samples - 1)
    around = middle[:, None] + jnp.arange(-1, 2)[None, :]
    points, heights = times[around], jnp.take_along_axis(sampled.T, around, axis=1)
    points, heights = _refined(f_each, points, heights, lo, hi, iterations)
    j = jnp.argmax(heights, axis=1)
    best_refined = jnp.take_along_axis(heights, j[:, None], axis=1)[:, 0]
    best_sample = sampled[k, component]
    better = best_refined > best_sample
    t_star = jax.lax.stop_gradient(
        jnp.where(better, jnp.take_along_axis(points, j[:, None], axis=1)[:, 0], times[k])
    )
    # f(t*), evaluated again so that it carries the derivative (the envelope theorem): the
    # refinement's values were gradient-stopped, and a sample's is kept as computed.
    return t_star, jnp.where(better, f_each(t_star), values[k, component]), values


def _refined(f_each, points, heights, lo, hi, iterations: int, skip_idle: bool = True):
    """`(points, heights)` after `iterations` steps of successive parabolic interpolation
    (`step_maxima`), each row's vertex kept only inside (lo, hi) and off its points.

    A step whose vertex no row can use changes nothing, and so does every step after it (the
    same points propose the same vertex). With `skip_idle`, a `lax.cond` on the first step's
    vertices therefore skips the steps without evaluating `f_each`: bit for bit the same
    result. That is the usual case over a contact step whose force rises or falls through it:
    the best sample is an end of the step and the parabola's vertex lies outside its bracket.
    deploy_array at its defaults (2 s, one core, warm): 2.70 s with every contact step
    refined, 2.29 s with idle steps skipped, 2.03 s with no refinement at all. Under `vmap`
    the `cond` becomes a select, and the steps run as before.
    """

    def proposal(points, heights):
        x, exists = _vertex(points, heights)
        usable = exists & (x > lo) & (x < hi) & jnp.all(x[:, None] != points, axis=1)
        return jnp.where(usable, x, points[:, 1]), usable

    def parabolic_step(_, state):
        points, heights = state
        x, usable = proposal(points, heights)
        fx = jnp.where(usable, jax.lax.stop_gradient(f_each(x)), -jnp.inf)
        new_points, new_heights = _best_triple(points, heights, x, fx)
        return (
            jnp.where(usable[:, None], new_points, points),
            jnp.where(usable[:, None], new_heights, heights),
        )

    def steps():
        return jax.lax.fori_loop(0, iterations, parabolic_step, (points, heights))

    if not skip_idle:
        return steps()
    _, usable = proposal(points, heights)
    return jax.lax.cond(jnp.any(usable), steps, lambda: (points, heights))


def step_maximum(f, t0, t1, samples: int = SAMPLES, iterations: int = PARABOLIC):
    """`(t*, f(t*), values)` of a scalar function `f(t)` on [t0, t1]: `step_maxima` of one
    component (values (samples + 1,))."""
    t_star, peak, values = step_maxima(lambda t: f(t)[None], t0, t1, samples, iterations)
    return t_star[0], peak[0], values[:, 0]


def simpson(values, t0, t1):
    """∫ f dt over [t0, t1] from f at an even number of equal intervals (Simpson's rule)."""
    n = values.shape[0] - 1
    weights = jnp.ones(n + 1).at[1:-1:2].set(4.0).at[2:-1:2].set(2.0)
    return (t1 - t0) / (3.0 * n) * jnp.dot(weights, values)


def _joint_state(mechanism, index, memory):
    """`(in_contact, event_fraction, impact_velocity)` of joint `index` from its memory, or
    None for a joint whose law keeps no v⁻ memory."""
    m = memory[index]
    if not isinstance(m, dict) or "in_contact" not in m:
        return None
    return m["in_contact"] > 0.5, m["event_fraction"], m["impact_velocity"]


@traced_once
def _contact_at(mechanism, index, q, v, step_memory):
    """[F_N, δ] of joint `index` at `(q, q̇)` with the step's memory of the joint (traced
    once per program: a step evaluates it at its samples, in the refinement of
    `step_maxima` and at the peaks)."""
    joint = mechanism.elements[index]
    kin = mechanism.kinematics(q, v)
    fn, _, geometry = joint.contact_forces(kin, step_memory)
    return jnp.stack([fn, geometry.penetration])


def _penetration_state(mechanism, index, q, v):
    joint = mechanism.elements[index]
    g = joint.geometry(mechanism.kinematics(q, v))
    return g.penetration > _onset(joint), g.penetration, g.penetration_rate


def _onset(joint):
    """The penetration at which the joint's elastic law starts to push (0 for Hertz)."""
    return joint.normal.elastic.onset_penetration()


def init_log(mechanism, t0, y0, capacity: int = DEFAULT_CAPACITY) -> EpisodeLog | None:
    """The log at the start of a run (a joint already in contact opens its first episode at
    `t0`); None for a mechanism without clearance joints."""
    joints = mechanism.find(RevoluteClearance)
    if not joints:
        return None
    k = len(joints)
    nan = jnp.full((k, capacity), jnp.nan, dtype=y0.q.dtype)
    log = EpisodeLog(
        jnp.zeros((k,), dtype=jnp.int32),
        *([nan] * len(FIELDS)),
        jnp.full((k,), -jnp.inf, dtype=y0.q.dtype),
        jnp.full((k,), -jnp.inf, dtype=y0.q.dtype),
    )
    for row, index in enumerate(joints):
        state = _joint_state(mechanism, index, y0.memory)
        if state is None:
            now_in, _, rate = _penetration_state(mechanism, index, y0.q, y0.v)
            v_minus = jnp.maximum(rate, 0.0)
        else:
            now_in, _, v_minus = state
        log = _begin(log, row, now_in, t0, v_minus, capacity)
    return log


def _begin(log, row, began, time, v_minus, capacity):
    slot = jnp.minimum(log.count[row], capacity - 1)
    writable = began & (log.count[row] < capacity)

    def put(field, value):
        old = getattr(log, field)
        return old.at[row, slot].set(jnp.where(writable, value, old[row, slot]))

    log = log._replace(
        onset_time=put("onset_time", time),
        impact_velocity=put("impact_velocity", v_minus),
        peak_force=put("peak_force", 0.0),
        peak_penetration=put("peak_penetration", -jnp.inf),
        impulse=put("impulse", 0.0),
    )
    return log._replace(count=log.count.at[row].add(began.astype(log.count.dtype)))


def log_step(log, mechanism, t0, t1, y0, y1, motion, capacity: int = DEFAULT_CAPACITY):
    """The log after an accepted step from `(t0, y0)` to `(t1, y1)`; `motion(t)` gives the
    step's dense output `(q, q̇, memory)` at `t`."""
    if log is None:
        return None
    h = t1 - t0
    for row, index in enumerate(mechanism.find(RevoluteClearance)):
        joint = mechanism.elements[index]
        before = _joint_state(mechanism, index, y0.memory)
        if before is not None:
            was_in = before[0]
            now_in, fraction, v_minus = _joint_state(mechanism, index, y1.memory)
            fraction = jnp.clip(fraction, 0.0, 1.0)
            step_memory = joint.memory_for_step(y0.memory[index], mechanism.kinematics(y0.q, y0.v))
        else:
            # A law without v⁻ memory: in contact by δ at the step's ends, the crossing
            # interpolated linearly (not located).
            was_in, d0, r0 = _penetration_state(mechanism, index, y0.q, y0.v)
            now_in, d1, r1 = _penetration_state(mechanism, index, y1.q, y1.v)
            level = _onset(joint)
            fraction = jnp.clip((level - d0) / jnp.where(d1 != d0, d1 - d0, 1.0), 0.0, 1.0)
            v_minus = jnp.maximum(r0 + fraction * (r1 - r0), 0.0)
            step_memory = y0.memory[index]
        began, ended = (~was_in) & now_in, was_in & (~now_in)
        log = _begin(log, row, began, t0 + fraction * h, v_minus, capacity)
        slot = jnp.clip(log.count[row] - 1, 0, capacity - 1)
        open_ = (log.count[row] > 0) & (log.count[row] <= capacity)
        in_step = was_in | now_in
        touched = in_step & open_

        def peaks(joint_index=index, memory=step_memory):
            def contact(t):  # [F_N, δ]: both maximised together, the contact traced once
                q, v, _ = motion(t)
                return _contact_at(mechanism, joint_index, q, v, memory)

            t_star, peak, values = step_maxima(contact, t0, t1)
            return t_star[0], peak[0], peak[1], simpson(values[:, 0], t0, t1)

        def nothing():
            zero = jnp.zeros((), dtype=y0.q.dtype)
            return t0 + zero, zero, jnp.full((), -jnp.inf, dtype=zero.dtype), zero

        t_force, f_max, d_max, impulse = jax.lax.cond(in_step, peaks, nothing)
        row_force = log.peak_force[row, slot]
        higher = touched & (f_max > row_force)
        log = log._replace(
            peak_force=log.peak_force.at[row, slot].set(jnp.where(higher, f_max, row_force)),
            peak_force_time=log.peak_force_time.at[row, slot].set(
                jnp.where(higher, t_force, log.peak_force_time[row, slot])
            ),
            peak_penetration=log.peak_penetration.at[row, slot].set(
                jnp.where(
                    touched,
                    jnp.maximum(log.peak_penetration[row, slot], d_max),
                    log.peak_penetration[row, slot],
                )
            ),
            impulse=log.impulse.at[row, slot].add(jnp.where(touched, impulse, 0.0)),
            force_max=log.force_max.at[row].max(jnp.where(in_step, f_max, -jnp.inf)),
            penetration_max=log.penetration_max.at[row].max(jnp.where(in_step, d_max, -jnp.inf)),
            separation_time=log.separation_time.at[row, slot].set(
                jnp.where(ended & open_, t0 + fraction * h, log.separation_time[row, slot])
            ),
        )
    return log


def episode_outputs(log: EpisodeLog | None, names) -> dict:
    """Differentiable per-episode outputs of a run's log, for losses and objectives
    (`Scene.outputs`): per clearance joint (row of the log, named by `names`, "" for no
    prefix) `{name}_onset_times`, `{name}_impact_velocities`, `{name}_peak_forces` and
    `{name}_peak_penetrations` — arrays over the first `capacity` episodes, NaN where the run
    had fewer — and the run's extremes `{name}_peak_force` [N] and `{name}_peak_penetration`
    [m] over every contact step (NaN: no contact). Onset times carry the implicit-function
    derivative of their location, peaks the envelope theorem's (module docstring)."""
    if log is None:
        return {}
    out = {}
    for row, name in enumerate(names):
        prefix = f"{name}_" if name else ""

        def finite(x):
            return jnp.where(jnp.isfinite(x), x, jnp.nan)

        out[f"{prefix}onset_times"] = log.onset_time[row]
        out[f"{prefix}impact_velocities"] = log.impact_velocity[row]
        out[f"{prefix}peak_forces"] = log.peak_force[row]
        out[f"{prefix}peak_penetrations"] = finite(log.peak_penetration[row])
        out[f"{prefix}peak_force"] = finite(log.force_max[row])
        out[f"{prefix}peak_penetration"] = finite(log.penetration_max[row])
    return out
