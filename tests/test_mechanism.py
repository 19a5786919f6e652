"""Mechanism building blocks: validation, assembly, memory (latch), the drive's closed form."""

import jax.numpy as jnp
import numpy as np
import pytest

from jaxdeploy.mechanism import (
    AssemblyError,
    Body,
    CoilSpringDrive,
    Latch,
    Mechanism,
    Revolute,
    RevoluteClearance,
    consistent_motion,
    consistent_state,
)
from jaxdeploy.scenes import SliderCrank, ideal_slider_kinematics
from jaxdeploy.simulation import simulate


def test_body_rejects_bad_mass_with_a_clear_message():
    with pytest.raises(ValueError, match=r"panel\.mass = -1.0 kg is invalid.*\(0, inf\]"):
        Body("panel", mass=-1.0, inertia=1.0)


def test_unknown_body_and_point_are_named():
    rod = Body("rod", 1.0, 0.1, {"end": (0.5, 0.0)})
    with pytest.raises(ValueError, match="unknown body 'crank'"):
        Mechanism([rod], [Revolute("ground", "O", "crank", "end")], {"O": (0, 0)})
    with pytest.raises(KeyError, match="no point 'tip'"):
        Mechanism([rod], [Revolute("ground", "O", "rod", "tip")], {"O": (0, 0)})


def test_clearance_joint_rejects_nonpositive_clearance():
    from jaxdeploy import contact

    law = contact.Undamped(contact.HertzElastic(1e10))
    with pytest.raises(ValueError, match="clearance"):
        RevoluteClearance(
            "ground", "O", "rod", "end", clearance=0.0, journal_radius=5e-3, normal=law
        )


def _four_bar(ground_span):
    links = [
        Body("crank", 1.0, 0.1, {"a": (-0.5, 0.0), "b": (0.5, 0.0)}),
        Body("coupler", 1.0, 0.1, {"a": (-1.0, 0.0), "b": (1.0, 0.0)}),
        Body("rocker", 1.0, 0.1, {"a": (-0.75, 0.0), "b": (0.75, 0.0)}),
    ]
    joints = [
        Revolute("ground", "A", "crank", "a"),
        Revolute("crank", "b", "coupler", "a"),
        Revolute("coupler", "b", "rocker", "b"),
        Revolute("ground", "D", "rocker", "a"),
    ]
    return Mechanism(links, joints, {"A": (0.0, 0.0), "D": (ground_span, 0.0)})


def test_four_bar_assembles_and_has_one_dof():
    mech = _four_bar(2.0)
    assert mech.degrees_of_freedom == 1
    guess = jnp.array([0.0, 0.5, np.pi / 2, 1.0, 1.2, 0.0, 2.0, 0.6, np.pi / 2])
    state = consistent_state(mech, guess, fixed=(2,))
    assert float(jnp.max(jnp.abs(mech.constraints(state.q, 0.0)))) < 1e-12
    assert float(state.q[2]) == pytest.approx(np.pi / 2)


def test_unassemblable_pose_is_reported():
    mech = _four_bar(10.0)  # links 1 + 2 + 1.5 cannot reach 10 m
    guess = jnp.array([0.0, 0.5, np.pi / 2, 1.0, 1.2, 0.0, 2.0, 0.6, np.pi / 2])
    with pytest.raises(AssemblyError, match="could not assemble"):
        consistent_state(mech, guess, fixed=(2,))


def test_consistent_motion_is_consistent_states_positions_and_velocities():
    """Bit for bit, on a driven mechanism (velocities not zero: the crank turns), and it
    refuses a pose that cannot close as `consistent_state` does."""
    scene = SliderCrank()
    params = scene.resolve_params({})
    ideal = scene.build(params).idealized()
    guess = jnp.array([0.02, 0.001, 0.05, 0.09, 0.0, 0.0, 0.16, 0.0, 0.0])
    state = consistent_state(ideal, guess)
    q, v = consistent_motion(ideal, guess)
    assert np.asarray(q).tobytes() == np.asarray(state.q).tobytes()
    assert np.asarray(v).tobytes() == np.asarray(state.v).tobytes()
    assert float(jnp.max(jnp.abs(v))) > 1.0
    far = _four_bar(10.0)
    bad = jnp.array([0.0, 0.5, np.pi / 2, 1.0, 1.2, 0.0, 2.0, 0.6, np.pi / 2])
    with pytest.raises(AssemblyError, match="could not assemble"):
        consistent_motion(far, bad, fixed=(2,))


def test_redundant_constraints_are_reported():
    rod = Body("rod", 1.0, 0.1, {"end": (-0.5, 0.0)})
    joints = [Revolute("ground", "O", "rod", "end"), Revolute("ground", "O", "rod", "end")]
    mech = Mechanism([rod], joints, {"O": (0.0, 0.0)})
    with pytest.raises(AssemblyError, match="rank deficient"):
        consistent_state(mech, jnp.array([0.5, 0.0, 0.0]))


def test_spring_drive_lock_time_and_latch_engagement():
    """A panel on an ideal hinge, driven by a linear coil spring from rest at θ_s: it reaches
    the lock angle at t = arccos((θ0 − θ_L)/(θ0 − θ_s))/ω, ω = sqrt(k/I) (θ is harmonic
    about θ0); the latch then
    engages and holds it there."""
    inertia_about_hinge = 0.5 * 1.0**2 / 3.0  # 0.5 kg, 1 m plate about its edge
    k, theta0, theta_s, theta_lock = 2.0, np.pi, np.pi / 4, np.pi / 2
    panel = Body("panel", 0.5, 0.5 / 12.0, {"hinge": (-0.5, 0.0)})
    mech = Mechanism(
        [panel],
        [
            Revolute("ground", "O", "panel", "hinge"),
            CoilSpringDrive("ground", "panel", stiffness=k, free_angle=theta0),
            Latch("ground", "panel", lock_angle=theta_lock, stiffness=500.0, damping=2.0),
        ],
        {"O": (0.0, 0.0)},
    )
    guess = jnp.array([0.5 * np.cos(theta_s), 0.5 * np.sin(theta_s), theta_s])
    s0 = consistent_state(mech, guess, fixed=(2,))
    omega = np.sqrt(k / inertia_about_hinge)
    t_lock = np.arccos((theta0 - theta_lock) / (theta0 - theta_s)) / omega
    ts = np.linspace(0.0, 3.0 * t_lock, 3001)
    tr = simulate(mech, s0, ts[-1], ts=ts, dt=t_lock / 2000)
    assert tr.ok
    theta = np.asarray(tr.q[:, 2])
    crossing = np.flatnonzero(theta >= theta_lock)[0]
    np.testing.assert_allclose(ts[crossing], t_lock, rtol=2e-3)
    engaged = np.asarray(tr.memory[2]["engaged"])
    assert engaged[crossing - 2] == 0.0 and engaged[-1] == 1.0
    # Held: the spring-damper latch keeps the panel near 90° (small overshoot, decaying).
    late = theta[ts > 2.0 * t_lock]
    assert np.max(np.abs(late - theta_lock)) < 0.05


def test_clearance_mechanism_converges_to_ideal_as_clearance_shrinks():
    ideal_scene = SliderCrank(ideal=True)
    params = ideal_scene.resolve_params()
    period = 2 * np.pi / params["crank_speed"]
    ts = np.linspace(0.0, period, 361)
    ideal = ideal_scene.build(params)
    x_ideal = np.asarray(
        simulate(ideal, ideal_scene.initial_state(params, ideal), period, ts=ts, dt=period / 720).q[
            :, 6
        ]
    )
    scene = SliderCrank()
    deviations = []
    for c in [2e-4, 2e-5]:
        # An array, not a float: the clearance is then data of one compiled run, not a
        # constant compiled into each.
        p = scene.resolve_params({"clearance": jnp.asarray(c)})
        mech = scene.build(p)
        tr = simulate(
            mech, scene.initial_state(p, mech), period, ts=ts, control=scene.default_control
        )
        assert tr.ok, tr.status()
        deviations.append(np.max(np.abs(np.asarray(tr.q[:, 6]) - x_ideal)))
    # The slider can deviate from the ideal by at most about the clearance plus contact
    # deformation; it must shrink with c.
    assert deviations[1] < 0.3 * deviations[0]
    assert deviations[1] < 3 * 2e-5


def test_ideal_slider_kinematics_are_derivatives_of_the_position():
    """v = dx/dt and a = dv/dt for the closed form, by complex-step differentiation (exact to
    round-off, no step-size trade-off), for r = 0.05 m, l = 0.12 m, 5000 rpm; a also takes its
    dead-centre values −rω²(1 + λ) and rω²(1 − λ)."""
    r, ell, w = 0.05, 0.12, 5000.0 * 2.0 * np.pi / 60.0
    ts = np.linspace(0.0, 2.0 * np.pi / w, 37)
    _, v, a = ideal_slider_kinematics(r, ell, w, ts)
    step = 1e-30  # [s]
    x_c, v_c, _ = ideal_slider_kinematics(r, ell, w, ts + 1j * step)
    np.testing.assert_allclose(v, x_c.imag / step, rtol=1e-12, atol=1e-12 * r * w)
    np.testing.assert_allclose(a, v_c.imag / step, rtol=1e-12, atol=1e-12 * r * w**2)
    lam = r / ell
    np.testing.assert_allclose(a[0], -r * w**2 * (1.0 + lam), rtol=1e-13)
    np.testing.assert_allclose(a[18], r * w**2 * (1.0 - lam), rtol=1e-12)
