"""The preloaded latch (`PreloadedLatch`) and deploy_array's `latch` option.

The static checks solve the equilibrium of a latched panel with a clearance hinge by hand
(Hertz closed form, a scalar moment balance by scipy) and require the package's generalized
forces to vanish there; the slow one runs deploy_array through its lock with both latch models.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import brentq

from jaxdeploy import contact
from jaxdeploy.mechanism import (
    Body,
    Latch,
    Mechanism,
    PreloadedLatch,
    RevoluteClearance,
)
from jaxdeploy.scenes import DeployArray, get_scene
from jaxdeploy.scenes.deploy_array import GEOMETRY, LATCH_ROLLER_RADIUS
from jaxdeploy.simulation import simulate

K_HERTZ = 1e10  # N/m^1.5
CLEARANCE = 5e-5  # m
K_LATCH = 2e4  # N m/rad
PIN = np.array([-0.3, 0.0])  # the hinge pin on the panel, body frame [m]


def _panel(preload, phi, arm, stiffness=K_LATCH):
    """A 0.6 m panel whose pin sits in a bearing at the ground's origin (Hertz, undamped),
    latched at θ = 0 with a preload F along u(φ) whose line of action passes `arm` beside the
    pin."""
    u = np.array([np.cos(phi), np.sin(phi)])
    point = PIN - 0.02 * u + arm * np.array([-u[1], u[0]])
    panel = Body("panel", 1.2, 0.036, {"pin": tuple(PIN), "tip": (0.3, 0.0)})
    elements = [
        RevoluteClearance(
            "ground",
            "O",
            "panel",
            "pin",
            clearance=CLEARANCE,
            journal_radius=5e-3,
            normal=contact.Undamped(contact.HertzElastic(K_HERTZ)),
        ),
        PreloadedLatch(
            "ground",
            "panel",
            lock_angle=0.0,
            stiffness=stiffness,
            preload=preload,
            preload_body="panel",
            preload_point=tuple(point),
            preload_angle=phi,
        ),
    ]
    return Mechanism([panel], elements, {"O": (0.0, 0.0)}), u, point


def _pose(theta, pin_world):
    """q of the panel with its pin at `pin_world` and angle θ."""
    c, s = np.cos(theta), np.sin(theta)
    centre = pin_world - np.array([c * PIN[0] - s * PIN[1], s * PIN[0] + c * PIN[1]])
    return jnp.array([centre[0], centre[1], theta])


@pytest.mark.parametrize(("phi", "arm"), [(np.pi, 0.0), (2.0, 0.004), (-0.7, -0.01)])
def test_preload_seats_the_journal_in_the_hand_solved_equilibrium(phi, arm):
    """Equilibrium by hand: the net force F u is taken by the bearing, so the journal sits
    along u at |e| = c + (F/K)^(2/3) (Hertz); the moment of F about the pin, (A(θ) s) × F u,
    is taken by the lock torque k_L θ. The package's Q must vanish there, and the joint must
    carry F."""
    force = 80.0
    mech, u, point = _panel(force, phi, arm)
    pin_world = (CLEARANCE + (force / K_HERTZ) ** (2.0 / 3.0)) * u
    arm_body = point - PIN

    def moment_balance(theta):
        c, s = np.cos(theta), np.sin(theta)
        lever = np.array([c * arm_body[0] - s * arm_body[1], s * arm_body[0] + c * arm_body[1]])
        return -K_LATCH * theta + force * (lever[0] * u[1] - lever[1] * u[0])

    theta = brentq(moment_balance, -0.1, 0.1, xtol=1e-15)
    # e beside the pin, moment −F e about +z (the sign convention of deploy_array's arm).
    assert theta == pytest.approx(-force * arm / K_LATCH, rel=1e-3, abs=1e-12)
    q = _pose(theta, pin_world)
    memory = mech.init_memory(q, jnp.zeros(3))
    assert float(memory[1]["engaged"]) == (1.0 if theta >= 0 else 0.0)
    memory = (memory[0], {"engaged": jnp.asarray(1.0), "anchor": memory[1]["anchor"]})
    residual = np.asarray(mech.generalized_forces(q, jnp.zeros(3), 0.0, memory))
    # Scale: the preload [N] and its moment at the pin's 0.3 m lever [N m].
    assert np.all(np.abs(residual[:2]) < 1e-6 * force)
    assert abs(residual[2]) < 1e-6 * force * 0.3
    fn, _, _ = mech.elements[0].contact_forces(mech.kinematics(q), memory[0])
    assert float(fn) == pytest.approx(force, rel=1e-9)


def test_angle_only_latch_leaves_the_journal_unloaded():
    """The same pose with `Latch`: nothing presses the journal, so the centred journal is in
    equilibrium (the lock torque alone)."""
    panel = Body("panel", 1.2, 0.036, {"pin": tuple(PIN)})
    latch = Latch("ground", "panel", lock_angle=0.0, stiffness=K_LATCH)
    joint = RevoluteClearance(
        "ground",
        "O",
        "panel",
        "pin",
        clearance=CLEARANCE,
        journal_radius=5e-3,
        normal=contact.Undamped(contact.HertzElastic(K_HERTZ)),
    )
    mech = Mechanism([panel], [joint, latch], {"O": (0.0, 0.0)})
    q = _pose(0.0, np.zeros(2))
    memory = (None, {"engaged": jnp.asarray(1.0)})
    np.testing.assert_allclose(mech.generalized_forces(q, jnp.zeros(3), 0.0, memory), 0, atol=1e-9)


def test_engagement_sets_the_anchor_once_and_nothing_acts_before():
    mech, u, point = _panel(50.0, 0.5, 0.003)
    latch = mech.elements[1]
    before = _pose(-0.01, np.zeros(2))
    memory = mech.init_memory(before, jnp.zeros(3))
    assert float(memory[1]["engaged"]) == 0.0
    kin = mech.kinematics(before)
    assert all(
        not np.any(np.asarray(w.force)) and not np.any(np.asarray(w.torque or 0.0))
        for w in latch.wrenches(kin, 0.0, memory[1])
    )
    past = _pose(0.002, np.array([1e-6, -2e-6]))
    after = latch.memory_after_step(memory[1], mech.kinematics(past), 1e-3)
    assert float(after["engaged"]) == 1.0
    p_world = np.asarray(mech.kinematics(past).position("panel", tuple(point)))
    np.testing.assert_allclose(after["anchor"], p_world, atol=1e-15)  # ground frame = world
    later = latch.memory_after_step(after, mech.kinematics(_pose(-0.003, np.zeros(2))), 1e-3)
    assert float(later["engaged"]) == 1.0  # for good
    np.testing.assert_array_equal(later["anchor"], after["anchor"])


def _two_moving_bodies():
    """A preloaded latch between two free bodies (lock angle 0.1 rad, 40 N m/rad, a 30 N
    preload on body b's roller): `(mechanism, latch)`."""
    a = Body("a", 2.0, 0.1, {"hole": (0.3, 0.0)})
    b = Body("b", 1.0, 0.05, {"pin": (-0.2, 0.0)})
    latch = PreloadedLatch(
        "a",
        "b",
        lock_angle=0.1,
        stiffness=40.0,
        preload=30.0,
        preload_body="b",
        preload_point=(-0.17, 0.01),
        preload_angle=2.5,
    )
    return Mechanism([a, b], [latch]), latch


def test_potential_is_the_conservative_force_with_a_moving_roller_body():
    """`Q = −∇V` for an engaged latch between two moving bodies (damping 0), at the pose where
    it engaged (the roller carrier moving: exact where P is at its anchor)."""
    mech, latch = _two_moving_bodies()
    q = jnp.array([0.1, 0.2, 0.3, 0.5, 0.4, 0.45])
    memory = mech.init_memory(q, jnp.zeros(6))
    memory = ({"engaged": jnp.asarray(1.0), "anchor": memory[0]["anchor"]},)
    forces = mech.generalized_forces(q, jnp.zeros(6), 0.0, memory)
    grad_v = jax.grad(lambda x: mech.potential_energy(x, memory))(q)
    np.testing.assert_allclose(np.asarray(forces), -np.asarray(grad_v), rtol=1e-10, atol=1e-10)
    # The preload is an internal force pair: no net force on the two bodies.
    assert float(jnp.abs(forces[0] + forces[3])) < 1e-12
    assert float(jnp.abs(forces[1] + forces[4])) < 1e-12


def test_the_preload_stores_no_energy_before_its_anchor_is_set():
    """Inside the step that engages the latch (past the stop, memory not yet engaged) the
    preload's potential is 0, not −f·(r_P − the run's initial anchor): an energy meter booked
    that difference as energy put in at the engagement (−2.7 J of deploy_array's 4.2 J), the
    whole residual of its balance. After the engagement it is measured from the new anchor."""
    mech, latch = _two_moving_bodies()
    start = jnp.array([0.1, 0.2, 0.3, 0.5, 0.4, 0.35])  # α = 0.05: before the stop
    (memory,) = mech.init_memory(start, jnp.zeros(6))
    assert float(memory["engaged"]) == 0.0
    past = jnp.array([0.1, 0.2, 0.3, 0.8, 0.1, 0.45])  # α = 0.15, P moved ~0.4 m away
    kin = mech.kinematics(past)
    elastic = 0.5 * 40.0 * (0.15 - 0.1) ** 2
    assert float(latch.potential_energy(kin, memory)) == pytest.approx(elastic, rel=1e-12)
    engaged = latch.memory_after_step(memory, kin, 1e-3)
    assert float(engaged["engaged"]) == 1.0
    assert float(latch.potential_energy(kin, engaged)) == pytest.approx(elastic, rel=1e-12)


def test_bad_latch_arguments_are_named():
    with pytest.raises(ValueError, match=r"PreloadedLatch\.preload = -1\.0 N is invalid"):
        _panel(-1.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="preload_body = 'rod' is invalid; valid: 'ground'"):
        PreloadedLatch(
            "ground",
            "panel",
            lock_angle=0.0,
            stiffness=1.0,
            preload=1.0,
            preload_body="rod",
            preload_point=(0.0, 0.0),
            preload_angle=0.0,
        )
    with pytest.raises(
        ValueError, match="latch = 'stiff' is invalid; valid: preloaded, angle_only"
    ):
        DeployArray(latch="stiff")


def test_deploy_array_latch_option_and_its_parameters():
    preloaded, angle_only = DeployArray(), get_scene("deploy_array", latch="angle_only")
    assert preloaded.options["latch"] == "preloaded"  # the default (docs/deploy_array.md)
    assert angle_only.options["latch"] == "angle_only"
    latch_preload_params = {
        "latch_preload",
        "latch_preload_angle",
        "latch_preload_arm",
        "panel_latch_preload",
    }
    # Other options (e.g. friction_roughness) may ignore their own parameters; the latch's are
    # used by the preloaded latch and ignored by the angle-only one, with the option named.
    assert not latch_preload_params & set(preloaded.ignored_params())
    angle_only_ignored = angle_only.ignored_params()
    assert latch_preload_params <= set(angle_only_ignored)
    assert {angle_only_ignored[name] for name in latch_preload_params} == {"latch=preloaded"}
    with pytest.raises(ValueError, match=r"latch_preload_arm.*\[-0\.02, 0\.02\] m"):
        preloaded.resolve_params({"latch_preload_arm": 0.05})
    mech = angle_only.build(angle_only.resolve_params())
    assert type(mech.elements[-1]) is Latch
    assert not any(isinstance(e, PreloadedLatch) for e in mech.elements)


def test_deploy_array_preload_acts_where_the_docs_say():
    """At the deployed pose (α = 90°): the root latch's force on panel 1 is F_p along u(φ),
    its point at the roller radius r_L (and e beside the line through the hinge axis), and its
    moment about the hinge J1 is F_p e in the deploying sense (−z on panel 1: α = π/2 − θ₁);
    the panel latch presses J7 through its axis."""
    scene = DeployArray()
    force, phi, arm = 120.0, 2.8, 0.006
    params = scene.resolve_params(
        {"latch_preload": force, "latch_preload_angle": phi, "latch_preload_arm": arm}
    )
    mech = scene.build(params)
    root, panel = mech.elements[-1], mech.elements[-2]
    assert isinstance(root, PreloadedLatch) and isinstance(panel, PreloadedLatch)
    q = jnp.asarray(GEOMETRY["deployed_state"]["q"], dtype=float)
    kin = mech.kinematics(q)
    engaged = {"engaged": jnp.asarray(1.0), "anchor": jnp.zeros(2)}
    torques, forces = [], []
    for w in root.wrenches(kin, 0.0, engaged):
        if w.body == "ground":  # the reactions (the mechanism drops them)
            continue
        assert w.body == "panel1"
        if w.force is not None:
            forces.append((np.asarray(w.force), np.asarray(w.point)))
        if w.torque is not None:
            torques.append(float(w.torque))
    ((f, p),) = forces
    np.testing.assert_allclose(f, force * np.array([np.cos(phi), np.sin(phi)]), rtol=1e-12)
    hinge = np.asarray(kin.position("panel1", "root"))
    lever = p - hinge
    assert np.hypot(*lever) == pytest.approx(np.hypot(LATCH_ROLLER_RADIUS, arm), rel=1e-9)
    assert lever[0] * f[1] - lever[1] * f[0] == pytest.approx(-force * arm, rel=1e-9)
    assert abs(sum(torques)) < 1e-6  # the lock torque vanishes at α = 90°
    j7 = np.asarray(kin.position("panel2", "root"))
    ((f7, p7),) = [
        (np.asarray(w.force), np.asarray(w.point))
        for w in panel.wrenches(kin, 0.0, engaged)
        if w.body == "panel2" and w.force is not None
    ]
    # Through the axis: no moment, up to the deployed pose's rounding (1.7e-11 m).
    assert abs((p7 - j7)[0] * f7[1] - (p7 - j7)[1] * f7[0]) < 1e-9 * 100.0 * LATCH_ROLLER_RADIUS
    assert np.linalg.norm(f7) == pytest.approx(params["panel_latch_preload"], rel=1e-12)


@pytest.mark.slow
def test_preloaded_latch_keeps_the_hinges_seated_after_the_lock():
    """deploy_array over 0.8 s (lock at 0.54 s): with the preloaded latch both clearance
    hinges carry at least half their preload from 0.15 s after the lock (the latch-up
    oscillation's hinge reactions, ~2 kN at the lock, have decayed to ~20 N by then: ideal-joint
    run); with the angle-only latch the journals float
    (their contact force falls to ~0 in the same window)."""
    seated = {}
    for latch in ("preloaded", "angle_only"):
        scene = DeployArray(latch=latch)
        params = scene.resolve_params()
        mech = scene.build(params)
        tr = simulate(
            mech, scene.initial_state(params, mech), 0.8, n_save=801, **scene.default_control
        )
        assert tr.ok, tr.status()
        ch = scene.channels(mech, tr)
        window = np.asarray(tr.ts) > 0.54 + 0.15
        seated[latch] = {
            owner: float(np.min(np.asarray(ch[f"{owner}_normal_force"])[window]))
            for owner in ("panel1", "panel2")
        }
    assert seated["preloaded"]["panel1"] > 0.5 * 100.0
    assert seated["preloaded"]["panel2"] > 0.5 * 100.0
    assert seated["angle_only"]["panel1"] < 1.0 and seated["angle_only"]["panel2"] < 1.0
