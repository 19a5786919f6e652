"""Runs of the *package* in the form the references are compared in (used by the tests and by
`python -m independent.report`). Unlike the references next to it, this module
imports jaxdeploy: it is the measuring side, not the reference side."""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from jaxdeploy import (
    Body,
    Gravity,
    Impact,
    Mechanism,
    RevoluteClearance,
    SliderCrank,
    consistent_state,
    contact,
    simulate,
)

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


# A journal spinning in a fixed bearing under its weight, Coulomb friction (tanh) and an
# undamped Hertz wall: its equilibrium is on the wall at tan α = μ, and it spins down at
# μ W R_j cos α / J (the friction circle; tests/test_independent_contact.py derives it).
SPINNING = dict(mass=1.0, g=9.81, radius=5e-3, clearance=1e-4, stiffness=1e10, mu=0.1,
                slip=1e-3, omega0=100.0, t_end=0.05)  # fmt: skip


def spinning_journal(**control):
    """`(ts, q, v, centre, deceleration)` of the spinning journal (`SPINNING`) on 51 saved
    times: `centre` [m] the closed-form equilibrium, `deceleration` [rad/s²] the closed-form
    spin-down rate."""
    p = SPINNING
    inertia = 0.5 * p["mass"] * p["radius"] ** 2
    alpha = math.atan(p["mu"])
    normal_force = p["mass"] * p["g"] * math.cos(alpha)
    distance = p["clearance"] + (normal_force / p["stiffness"]) ** (2.0 / 3.0)
    joint = RevoluteClearance(
        "ground", "B", "journal", "c", clearance=p["clearance"], journal_radius=p["radius"],
        normal=contact.Undamped(contact.HertzElastic(p["stiffness"])),
        friction=contact.SmoothCoulomb(mu=p["mu"], slip_velocity=p["slip"], shape="tanh"),
    )  # fmt: skip
    mech = Mechanism(
        [Body("journal", p["mass"], inertia, {"c": (0.0, 0.0)})],
        [joint, Gravity((0.0, -p["g"]))],
        ground_points={"B": (0.0, 0.0)},
    )
    centre = np.array([-distance * math.sin(alpha), -distance * math.cos(alpha)])
    velocity = jnp.array([0.0, 0.0, p["omega0"]])
    state = consistent_state(mech, jnp.array([*centre, 0.0]), velocity)
    ts = np.linspace(0.0, p["t_end"], 51)
    run = simulate(mech, state, p["t_end"], ts=ts, **control)
    if not run.ok:
        raise RuntimeError(f"spinning journal, {control}: {run.status()}")
    deceleration = p["mu"] * normal_force * p["radius"] / inertia
    return ts, np.asarray(run.q), np.asarray(run.v), centre, deceleration


def slider_crank_stiffness(overrides=None) -> float:
    """The Hertz stiffness K [N/m^1.5] the slider_crank scene builds for `overrides`."""
    scene = SliderCrank()
    params = scene.resolve_params(overrides or {})
    mech = scene.build(params)
    (index,) = mech.find(RevoluteClearance)
    return float(mech.elements[index].normal.elastic.stiffness_coefficient)
