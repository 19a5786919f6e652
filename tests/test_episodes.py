"""Contact episodes as an output (`Trajectory.contact_episodes`, `jaxdeploy.solvers.episodes`):
the peak refinement on a function with a known maximum, and one Hertz impact against Johnson's
closed forms (issue 31, Deliver 2)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxdeploy import StepControl, get_scene
from jaxdeploy.batch import run_scene
from jaxdeploy.solvers import step_maxima, step_maximum
from jaxdeploy.solvers.episodes import PARABOLIC, SAMPLES, _refined


def test_step_maximum_finds_an_interior_peak_and_differentiates_by_the_envelope_theorem():
    h, c, w = 2.0, 0.37, 0.01

    def peak(height, centre):
        def f(t):
            return height * jnp.exp(-((t - centre) ** 2) / w) + 0.1 * t

        t_hat, value, _ = step_maximum(f, 0.0, 1.0)
        return value, t_hat

    # f' = 0 at t* with −2 h (t* − c)/w e^{…} + 0.1 = 0: solved by bisection here.
    lo, hi = c, c + 0.1
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        slope = -2 * h * (mid - c) / w * math.exp(-((mid - c) ** 2) / w) + 0.1
        lo, hi = (mid, hi) if slope > 0 else (lo, mid)
    t_star = 0.5 * (lo + hi)
    exact = h * math.exp(-((t_star - c) ** 2) / w) + 0.1 * t_star
    value, _ = peak(h, c)
    assert abs(float(value) - exact) < 1e-13
    # 8 samples alone would miss it by ~1e-2 (spacing 1/8 on a peak of width 0.1).
    samples = step_maximum(lambda t: h * jnp.exp(-((t - c) ** 2) / w) + 0.1 * t, 0.0, 1.0)[2]
    assert exact - float(jnp.max(samples)) > 1e-3
    # The location, from values alone: near t* f = f* − ½|f''| δ², equal to f* in floating
    # point once ½|f''| δ² < ε f*, so no value-only search places t* closer than
    # δ = √(2 ε f*/|f''|) (Press et al., Numerical Recipes in C, 2nd ed., §10.1); f'' ≈ −2h/w here.
    curvature = 2 * h / w
    resolution = math.sqrt(2 * np.finfo(float).eps * exact / curvature)
    (d_height, d_centre), t_hat = jax.grad(peak, argnums=(0, 1), has_aux=True)(h, c)
    t_hat = float(t_hat)
    assert abs(t_hat - t_star) <= 2 * resolution
    # Envelope theorem: the derivative is ∂f/∂θ at the returned t̂ — d/dh = e^{−(t̂−c)²/w},
    # d/dc = 2h(t̂−c)/w e^{…} — to round-off; at t* d/dc = 0.1, so it is 0.1 to within
    # |∂²f/∂c∂t| |t̂ − t*| ≈ (2h/w) |t̂ − t*|.
    e = math.exp(-((t_hat - c) ** 2) / w)
    np.testing.assert_allclose(float(d_height), e, rtol=1e-13)
    np.testing.assert_allclose(float(d_centre), 2 * h * (t_hat - c) / w * e, rtol=1e-12)
    assert abs(float(d_centre) - 0.1) <= curvature * 2 * resolution


def test_step_maxima_refines_each_component_as_step_maximum_does_alone():
    def f(t):
        return jnp.stack([jnp.sin(7.0 * t), -((t - 0.81) ** 2), jnp.exp(-t)])

    t_star, peaks, values = step_maxima(f, 0.0, 1.0)
    assert values.shape == (SAMPLES + 1, 3)
    for i in range(3):
        t_i, peak_i, values_i = step_maximum(lambda t, i=i: f(t)[i], 0.0, 1.0)
        assert float(t_star[i]) == float(t_i) and float(peaks[i]) == float(peak_i)
        np.testing.assert_array_equal(values[:, i], values_i)
    # sin 7t peaks at π/14; the parabola at 0.81; e^{−t} at the interval's start (a sample).
    np.testing.assert_allclose(np.asarray(t_star[:2]), [math.pi / 14, 0.81], atol=1e-8)
    np.testing.assert_allclose(np.asarray(peaks), [1.0, 0.0, 1.0], atol=1e-15)
    assert float(t_star[2]) == 0.0


def test_skipping_idle_parabolic_steps_changes_no_bit():
    """`_refined` skips its steps when the first vertex is of no use to any row: the same
    points and heights as running every step, on rows where a vertex is usable (interior
    peaks), where none is (monotone, linear, convex, flat) and on mixed batches."""
    rng = np.random.default_rng(7)

    def rows(functions):
        def f_each(t):
            return jnp.stack([g(t[i]) for i, g in enumerate(functions)])

        samples = jnp.linspace(0.0, 1.0, SAMPLES + 1)
        values = np.stack([np.asarray(jax.vmap(g)(samples)) for g in functions], axis=1)
        k = np.argmax(values, axis=0)
        lo, hi = samples[np.maximum(k - 1, 0)], samples[np.minimum(k + 1, SAMPLES)]
        around = np.clip(k, 1, SAMPLES - 1)[:, None] + np.arange(-1, 2)[None, :]
        heights = jnp.asarray(np.take_along_axis(values.T, around, axis=1))
        return f_each, samples[around], heights, lo, hi

    families = [
        lambda c: lambda t: -((t - c) ** 2),  # a peak at c: usable when c is inside
        lambda c: lambda t: c * t,  # linear: no vertex
        lambda c: lambda t: jnp.exp(c * t),  # convex and monotone
        lambda c: lambda t: jnp.tanh(8.0 * (t - c)),  # a step: flat ends
        lambda c: lambda t: jnp.sin(9.0 * t + 10.0 * c),
    ]
    skipped = refined = 0
    for _ in range(40):
        chosen = rng.choice(len(families), size=2)
        functions = [families[i](float(rng.uniform(-0.3, 1.3))) for i in chosen]
        f_each, points, heights, lo, hi = rows(functions)
        every = _refined(f_each, points, heights, lo, hi, PARABOLIC, skip_idle=False)
        skipping = _refined(f_each, points, heights, lo, hi, PARABOLIC)
        for a, b in zip(every, skipping, strict=True):
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
        moved = not np.array_equal(np.asarray(every[0]), np.asarray(points))
        refined += moved
        skipped += not moved
    # Both branches were taken: the comparison is not vacuous.
    assert skipped > 0 and refined > 0


def test_a_run_with_idle_refinements_skipped_is_bit_for_bit_the_run_with_all(monkeypatch):
    """The skip inside a whole run: slider_crank over 4 ms (impacts and contact phases, the
    scene's default control) with `_refined` skipping idle steps and with it running every
    step: the same episode log, extremes and saved states, bit for bit."""
    import functools

    from jaxdeploy.solvers import episodes as episodes_module

    scene = get_scene("slider_crank")
    params = scene.resolve_params({})

    def run():
        jax.clear_caches()  # the monkeypatched `_refined` is read while tracing
        trajectory = run_scene(scene, params, 4e-3, n_save=41)
        return jax.tree.map(np.asarray, (trajectory.q, trajectory.episodes, trajectory.extremes))

    skipping = run()
    every = functools.partial(episodes_module._refined, skip_idle=False)
    monkeypatch.setattr(episodes_module, "_refined", every)
    all_steps = run()
    assert int(skipping[1].count.sum()) > 0  # contact episodes were logged
    for a, b in zip(jax.tree.leaves(skipping), jax.tree.leaves(all_steps), strict=True):
        np.testing.assert_array_equal(a, b)


def test_hertz_impact_episode_against_johnsons_closed_forms():
    scene = get_scene("impact")  # undamped Hertz: Johnson's closed forms hold
    params = scene.resolve_params({})
    m, v0, k = params["mass"], params["impact_speed"], params["stiffness"]
    control = StepControl("dopri8", rtol=1e-10, atol=1e-15, dt_max=1e-5)
    trajectory = run_scene(scene, params, control=control, n_save=11)
    assert trajectory.ok, trajectory.status()
    (episodes,) = trajectory.contact_episodes()
    assert len(episodes) == episodes.total == 1
    (row,) = episodes.rows()
    delta_max = (5 * m * v0**2 / (4 * k)) ** 0.4
    f_max = k * delta_max**1.5
    # Free flight across the clearance, then the onset at c/v0 with v⁻ = v0 (located).
    np.testing.assert_allclose(row["onset_time"], params["clearance"] / v0, rtol=1e-10)
    # v⁻ is δ̇ on the onset step's cubic Hermite of e (O(h⁴)): measured 5.8e-10 low.
    np.testing.assert_allclose(row["impact_velocity"], v0, rtol=2e-9)
    np.testing.assert_allclose(row["peak_penetration"], delta_max, rtol=1e-8)
    np.testing.assert_allclose(row["peak_force"], f_max, rtol=1e-8)
    # The run's extremes take the refined peak too (not a sample at step ends and midpoints).
    np.testing.assert_allclose(float(trajectory.extremes["normal_force_max"][0]), f_max, rtol=1e-8)
    np.testing.assert_allclose(
        float(trajectory.extremes["penetration_max"][0]), delta_max, rtol=1e-8
    )
    # Duration 2.9433 δ_max/v0: Johnson's constant has five digits.
    duration = row["separation_time"] - row["onset_time"]
    np.testing.assert_allclose(duration, 2.9433 * delta_max / v0, rtol=2e-5)
    # An elastic rebound reverses the momentum: ∫F dt = 2 m v0.
    np.testing.assert_allclose(row["impulse"], 2 * m * v0, rtol=1e-7)
    # The peak's time: half the contact (the undamped Hertz pulse is symmetric).
    np.testing.assert_allclose(
        row["peak_force_time"], row["onset_time"] + duration / 2, rtol=0, atol=1e-9
    )
    # The command line's episodes.csv: units in the header, one row, numbers as numbers.
    from jaxdeploy.analysis import episodes_csv

    lines = episodes_csv(scene.build(params), trajectory).splitlines()
    assert lines[0].startswith("joint,bearing,journal,episode,onset_time [s],impact_velocity [m/s]")
    assert "peak_force [N]" in lines[0] and "impulse [N s]" in lines[0]
    assert len(lines) == 2 and lines[1].startswith("0,ground,journal,0,")
    np.testing.assert_allclose(float(lines[1].split(",")[4]), row["onset_time"], rtol=0)


# ≤ 35 CPU-s: forward mode through one Dopri8 run (measured with 5 files' cheap tests: 46 CPU-s)
@pytest.mark.slow
def test_episode_outputs_differentiate_like_johnsons_closed_forms():
    """`Scene.outputs`' per-episode outputs are differentiable: on the undamped Hertz impact,
    forward mode through the run gives the derivatives of Johnson's closed forms,
    F_max = k^0.4 (5 m v0²/4)^0.6 (∂/∂k = 0.4 F/k, ∂/∂v0 = 1.2 F/v0), δ_max ∝ k^−0.4 v0^0.8,
    t_on = c/v0 (implicit-function derivative of the located onset: 1/v0, −c/v0²)."""
    from jaxdeploy import fit

    scene = get_scene("impact")
    params = scene.resolve_params({})
    k, v0, c = params["stiffness"], params["impact_speed"], params["clearance"]
    control = StepControl("dopri8", rtol=1e-10, atol=1e-15, dt_max=1e-5)

    def outputs(o):
        return jnp.stack(
            [o["peak_force"], o["peak_penetration"], o["onset_times"][0], o["peak_forces"][0]]
        )

    jac = fit.parameter_jacobian(
        scene, params, ["stiffness", "impact_speed", "clearance"], outputs, None, n_save=2,
        control=control, mode="forward",
    )  # fmt: skip
    m = params["mass"]
    f_max = k**0.4 * (5 * m * v0**2 / 4) ** 0.6
    d_max = (5 * m * v0**2 / (4 * k)) ** 0.4
    d = {name: np.asarray(value) for name, value in jac.items()}
    # Measured: k-derivatives within 2e-9, onset derivatives 6.5e-10; the v0-derivatives of
    # both peaks 1.1e-6 low, the same relative error in F and δ (so in the approach speed the
    # contact sees, not in the peak's location), hence 1e-5 for them.
    np.testing.assert_allclose(d["stiffness"][[0, 3]], 0.4 * f_max / k, rtol=1e-7)
    np.testing.assert_allclose(d["impact_speed"][[0, 3]], 1.2 * f_max / v0, rtol=1e-5)
    np.testing.assert_allclose(d["stiffness"][1], -0.4 * d_max / k, rtol=1e-7)
    np.testing.assert_allclose(d["impact_speed"][1], 0.8 * d_max / v0, rtol=1e-5)
    np.testing.assert_allclose(d["clearance"][2], 1 / v0, rtol=1e-8)
    np.testing.assert_allclose(d["impact_speed"][2], -c / v0**2, rtol=1e-8)
    # The peaks do not depend on the clearance (free flight only delays the impact): measured
    # 1.3e-6 of F/c.
    assert abs(d["clearance"][0]) < 1e-5 * f_max / c
