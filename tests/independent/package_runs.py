"""Runs of the *package* in the form the references are compared in (used by the tests and by
`experiments/independent_references.py`). Unlike the references next to it, this module
imports jaxdeploy: it is the measuring side, not the reference side."""

from __future__ import annotations

import math

import numpy as np

from jaxdeploy.scenes import Impact, SliderCrank
from jaxdeploy.simulation import simulate

from .crossings import level_crossings

TWO_REVOLUTIONS = 2.0 * 2.0 * math.pi / (5000.0 * 2.0 * math.pi / 60.0)  # [s]
STEP = 1e-6  # [s], the saved grid: slider_crank's contacts last ≥ 40 µs, ≥ 12 µs apart

# The impact scene's defaults (m = 1 kg, v0 = 1 m/s, K = 1e10 N/m^1.5, c = 0.1 mm) with a
# roughness σ = 10 µm: δ_max moves by 0.6 % and the contact time at δ = 0 by 0.1 % from Hertz.
IMPACT = {"mass": 1.0, "speed": 1.0, "stiffness": 1e10, "clearance": 1e-4, "sigma": 1e-5}
IMPACT_T_END = 6e-4  # [s]
IMPACT_TS = np.linspace(0.0, IMPACT_T_END, 601)


def slider_crank_scene(mu, rule="onset"):
    """The scene and its parameters for friction μ (tanh law, v_s = 1 mm/s when μ > 0)."""
    scene = SliderCrank(impact_velocity_rule=rule, friction_shape="tanh")
    overrides = {"friction_coefficient": mu, "friction_slip_velocity": 1e-3} if mu else {}
    return scene, scene.resolve_params(overrides)


def slider_crank_run(mu, t_end, rule="onset", **control):
    """`(ts, x_s, onsets, run)` on the 1 µs grid; onsets are where δ = |e| − c rises through 0,
    located on the cubic Hermite interpolant of the saved δ, δ̇ (e from the saved coordinates:
    journal = rod centre + (l/2)(cos θ, sin θ), bearing = slider centre)."""
    scene, params = slider_crank_scene(mu, rule)
    mech = scene.build(params)
    ts = np.linspace(0.0, t_end, int(round(t_end / STEP)) + 1)
    run = simulate(mech, scene.initial_state(params, mech), t_end, ts=ts, **control)
    if not run.ok:
        raise RuntimeError(f"slider_crank μ = {mu}, {control}: {run.status()}")
    q, v = np.asarray(run.q), np.asarray(run.v)
    half = 0.5 * params["rod_length"]
    arm = half * np.stack([np.cos(q[:, 5]), np.sin(q[:, 5])], axis=1)
    arm_rate = v[:, 5:6] * np.stack([-arm[:, 1], arm[:, 0]], axis=1)
    e = q[:, 3:5] + arm - q[:, 6:8]
    e_rate = v[:, 3:5] + arm_rate - v[:, 6:8]
    norm = np.linalg.norm(e, axis=1)
    delta = norm - params["clearance"]
    delta_rate = np.sum(e * e_rate, axis=1) / np.maximum(norm, 1e-300)
    onsets = level_crossings(ts, delta, delta_rate, 0.0, direction=1)
    return ts, q[:, 6], onsets, run


def impact_run(damping, **control):
    """`(x, ẋ)` of the journal on `IMPACT_TS`, the impact scene with the rough law."""
    scene = Impact(damping=damping)
    params = scene.resolve_params({"sigma": IMPACT["sigma"]})
    mech = scene.build(params)
    run = simulate(mech, scene.initial_state(params, mech), IMPACT_T_END, ts=IMPACT_TS, **control)
    if not run.ok:
        raise RuntimeError(f"impact {damping}, {control}: {run.status()}")
    return np.asarray(run.q)[:, 0], np.asarray(run.v)[:, 0]


def return_to_centre(x, v):
    """`(t, |ẋ|)` when the journal is back at the bearing's centre (the rebound speed)."""
    (t_back,) = level_crossings(IMPACT_TS[1:], x[1:], v[1:], 0.0)
    return t_back, abs(float(np.interp(t_back, IMPACT_TS, v)))
