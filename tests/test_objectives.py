"""Objectives on synthetic deviations with known answers (decay rate, frequency, amplitude,
settling time), their gradients against central differences, and composition/parsing."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxdeploy import objectives as ob

TS = np.linspace(0.0, 1.0, 2001)  # 0.5 ms, as the design study saves
LOCK = 0.3


def _deployment(decay=12.0, freq=100.0, amp=1e-3, offset=2e-4, force=None):
    """Panel 1's tip x deviation: `offset` before the lock, amp e^{−λ(t − t_L)} sin(2π f t)
    after; tip y deviation zero. Acceleration channels carry the same signal, velocity
    channels its integral (so the interval-mean acceleration is this signal again)."""
    t = jnp.asarray(TS)
    after = t > LOCK
    ringing = amp * jnp.exp(-decay * (t - LOCK)) * jnp.sin(2 * jnp.pi * freq * t)
    e = jnp.where(after, ringing, offset)
    zero = jnp.zeros_like(t)
    w = 2 * jnp.pi * freq
    # ∫ A e^{−λs} sin(ω t) dt with s = t − t_L, from t_L on (0 before).
    integral = (
        amp
        * (
            jnp.exp(-decay * (t - LOCK)) * (-decay * jnp.sin(w * t) - w * jnp.cos(w * t))
            - (-decay * jnp.sin(w * LOCK) - w * jnp.cos(w * LOCK))
        )
        / (decay**2 + w**2)
    )
    channels = {
        "panel1_tip_vx": jnp.where(after, integral, 0.0),
        "panel1_tip_vy": zero,
        "alpha": zero,
        "panel1_tip_x": e,
        "panel1_tip_y": zero,
        "panel1_tip_ax": e,
        "panel1_tip_ay": zero,
    }
    if force is not None:
        channels["panel1_normal_force"] = force
    return ob.Deployment(TS, LOCK, channels, None)


def test_decay_rate_frequency_and_deployment_deviation_recover_known_values():
    dep = _deployment(decay=12.0, freq=100.0)
    # 20 ms windows hold two periods: r_k = A e^{−λ t_k} × const, so the fit is exact up to
    # the envelope's curvature within a window (O((λw)²) = O(0.06)) — checked to 1 %.
    assert float(ob.decay_rate(dep, "panel1", "displacement")) == pytest.approx(12.0, rel=1e-2)
    # The spectral peak of a decaying 100 Hz sine (Welch, 0.1 s segments: bins 10 Hz apart,
    # the soft argmax weighs the bins around the peak symmetrically).
    f = float(ob.dominant_frequency(dep, "panel1", "displacement"))
    assert f == pytest.approx(100.0, abs=1.5)
    # Acceleration: interval means from the tip velocities, the same sine.
    f = float(ob.dominant_frequency(dep, "panel1", "acceleration"))
    assert f == pytest.approx(100.0, abs=1.5)
    assert float(ob.deployment_deviation(dep, "panel1")) == pytest.approx(2e-4, rel=1e-12)
    # log_decay is the fitted log-ratio over the span of window centres.
    t, _ = ob.window_rms(dep, "panel1", "displacement")
    assert float(ob.log_decay(dep, "panel1", "displacement")) == pytest.approx(
        -12.0 * (t[-1] - t[0]), rel=1e-2
    )


def test_window_rms_of_a_sine_and_smoothed_peak_bounds():
    dep = _deployment(decay=0.0, amp=2e-3)
    _, r = ob.window_rms(dep, "panel1", "displacement")
    np.testing.assert_allclose(r, 2e-3 / math.sqrt(2), rtol=1e-3)  # RMS of A sin = A/√2
    decaying = _deployment(decay=12.0)
    _, r = ob.window_rms(decaying, "panel1", "displacement")
    peak = [float(ob.peak_vibration(decaying, "panel1", power=p)) for p in (1.0, 8.0, 200.0)]
    assert peak[0] == pytest.approx(float(r.mean()), rel=1e-12)  # p = 1: the mean
    assert peak[0] < peak[1] < peak[2] <= float(r.max())
    assert peak[2] == pytest.approx(float(r.max()), rel=0.02)  # p → ∞: the maximum


def test_settling_time_of_an_exponential_envelope():
    """Envelope r(t) = r0 e^{−λ(t − t_L)}: time above ε is ln(r0/ε)/λ (within a window)."""
    dep = _deployment(decay=10.0, amp=1e-3)
    r0 = 1e-3 / math.sqrt(2)
    eps = r0 * math.exp(-3.0)
    expected = 3.0 / 10.0 - 0.005  # windows start at t_L + δ, δ = 5 ms
    got = float(ob.settling_time(dep, "panel1", "displacement", threshold=eps, sharpness=0.05))
    assert got == pytest.approx(expected, abs=0.02)
    with pytest.raises(ValueError, match="threshold"):
        ob.settling_time(dep, "panel1", "displacement", threshold=0.0)


def test_peak_contact_force_smoothed_max():
    force = jnp.where(jnp.asarray(TS) > 0.5, 100.0, 1.0)
    dep = _deployment(force=force)
    value = float(ob.peak_contact_force(dep, "panel1", power=8.0))
    frac = np.mean(TS > 0.5)
    assert value == pytest.approx((frac * 100.0**8 + (1 - frac) * 1.0) ** (1 / 8), rel=1e-9)
    with pytest.raises(ValueError, match="owns no clearance joint"):
        ob.peak_contact_force(_deployment(), "panel1")


@pytest.mark.parametrize(
    "feature, kwargs",
    [
        (ob.decay_rate, {"signal": "displacement"}),
        (ob.log_decay, {"signal": "displacement"}),
        (ob.dominant_frequency, {"signal": "displacement"}),
        (ob.dominant_frequency, {"signal": "acceleration"}),
        (ob.peak_vibration, {"signal": "displacement"}),
        (ob.settling_time, {"signal": "displacement", "threshold": 1e-4}),
        (ob.deployment_deviation, {}),
    ],
)
def test_feature_gradients_match_central_differences(feature, kwargs):
    """d feature / d (λ, f, A, offset) by AD against central differences."""

    def value(theta):
        dep = _deployment(decay=theta[0], freq=theta[1], amp=theta[2], offset=theta[3])
        return feature(dep, "panel1", **kwargs)

    theta = jnp.array([12.0, 97.3, 1e-3, 2e-4])
    ad = np.asarray(jax.grad(value)(theta))
    scale = abs(float(value(theta)))
    # small steps: the window ripple makes d²/df² large (phase 2πft, t ~ 1 s)
    for i, h in enumerate(1e-7 * np.asarray(theta)):
        e = np.zeros(4)
        e[i] = h
        fd = (float(value(theta + e)) - float(value(theta - e))) / (2 * h)
        roundoff = 1e-13 * scale / h  # FD's own rounding error (~100 ulp of the value)
        assert ad[i] == pytest.approx(fd, rel=1e-5, abs=roundoff)


def test_objective_composition_and_parsing():
    dep = _deployment()
    objective = ob.parse_objective(["panel1:peak_vibration=2", "panel1:log_decay=-0.5"])
    expected = 2 * math.log(float(ob.peak_vibration(dep, "panel1"))) - 0.5 * float(
        ob.log_decay(dep, "panel1")
    )
    assert float(objective(dep)) == pytest.approx(expected, rel=1e-12)
    assert set(objective.parts(dep)) == {"panel1:peak_vibration", "panel1:log_decay"}
    assert len(ob.parse_objective("paper").terms) == 4
    # The reproducible reading: its parts are distinct, and its J is their log sum.
    reproducible = ob.parse_objective("paper_reproducible")
    both = {**dep.channels}
    both.update({k.replace("panel1", "panel2"): v for k, v in dep.channels.items()})
    both_panels = ob.Deployment(dep.ts, dep.lock_time, both, None)
    parts = reproducible.parts(both_panels)
    assert len(parts) == len(reproducible.terms) == 3
    assert float(reproducible(both_panels)) == pytest.approx(
        sum(math.log(float(v)) for v in parts.values()), rel=1e-12
    )
    with pytest.raises(ValueError, match="unknown"):
        ob.parse_objective("panel1:loudness=1")
    with pytest.raises(ValueError, match="PANEL:FEATURE=WEIGHT"):
        ob.parse_objective("loud")
    with pytest.raises(ValueError, match="not a number"):
        ob.parse_objective("panel1:log_decay=abc")
    with pytest.raises(ValueError, match="signal"):
        ob.peak_vibration(dep, "panel1", signal="jerk")
    with pytest.raises(ValueError, match="fewer than 2 whole windows"):
        ob.decay_rate(dep, "panel1", window=0.5)
