"""deploy_array with ideal joints against a model that shares no code with jaxdeploy.

The reference (`tests/independent/deploy_array_minimal.py`) has one coordinate, the root-hinge
angle α, solves the three loops in closed form, and integrates Lagrange's equation with scipy's
DOP853 at rtol 1e-12, the latch engagement located as an event. jaxdeploy integrates 21
absolute coordinates under 20 constraints. Issue 24 asks that the two agree on the deployment
angle history and the lock time within 1e-6 relative; the package is run at the scene's own
default step control, the one every user gets.
"""

import numpy as np
import pytest
from independent.deploy_array_minimal import DeployArrayMinimal

from jaxdeploy.scenes import DeployArray
from jaxdeploy.scenes.deploy_array import deployment_angle
from jaxdeploy.simulation import simulate

AGREEMENT = 1e-6  # relative, issue 24 item 5


@pytest.fixture(scope="module")
def reference():
    return DeployArrayMinimal()


def test_reference_conserves_energy_until_the_lock(reference):
    """The reference's own check: without the latch the spring's work is all kinetic energy,
    so α̇ at 90° has the closed form ½ I(90°) α̇² = ½ k [(α₀ − 45°)² − (α₀ − 90°)²]."""
    run = reference.simulate(t_end=0.6)
    k, a0 = reference.k, reference.alpha0
    work = 0.5 * k * ((a0 - reference.alpha_start) ** 2 - (a0 - reference.alpha_lock) ** 2)
    inertia, _ = reference.generalized_inertia(reference.alpha_lock)
    np.testing.assert_allclose(run.lock_rate, np.sqrt(2 * work / inertia), rtol=1e-10)


def lock_time(ts, alpha, lock_angle):
    """First crossing of `lock_angle`, linear between samples."""
    i = np.flatnonzero(alpha >= lock_angle)[0]
    return ts[i - 1] + (lock_angle - alpha[i - 1]) / (alpha[i] - alpha[i - 1]) * (ts[i] - ts[i - 1])


@pytest.mark.slow
def test_ideal_deploy_array_agrees_with_the_independent_model(reference):
    t_end = 1.0  # lock at 0.54 s; the latch oscillation has decayed by e⁻¹⁴ at 1 s
    # The reference models the angle-only latch; the scene's default, preloaded latch adds its
    # preload's moment after the lock (measured: 2.3e-6 relative, docs/deploy_array.md).
    scene = DeployArray(ideal=True, latch="angle_only")
    params = scene.resolve_params()
    mech = scene.build(params)
    initial = scene.initial_state(params, mech)
    ref = reference.simulate(t_end=t_end)
    # Many times over the whole run, plus a 1 µs grid around the lock to locate it (linear
    # interpolation over 1 µs is exact to ~1e-11 s at this α̈).
    around = ref.lock_time + np.linspace(-5e-5, 5e-5, 101)
    ts = np.union1d(np.linspace(0.0, t_end, 2001), around)
    tr = simulate(mech, initial, t_end, ts=ts, **scene.default_control)
    assert tr.ok, tr.status()
    alpha = np.asarray(deployment_angle(tr.q))
    alpha_ref = ref.alpha(ts)
    relative = np.abs(alpha - alpha_ref) / np.abs(alpha_ref)
    assert relative.max() < AGREEMENT, f"max relative α difference {relative.max():.2e}"
    t_lock = lock_time(ts, alpha, reference.alpha_lock)
    assert abs(t_lock - ref.lock_time) / ref.lock_time < AGREEMENT, (t_lock, ref.lock_time)
