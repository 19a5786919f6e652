"""The clearance joint's far side (jaxdeploy/mechanism/clearance.py, docs/contact.md): with a
clearance below ~3σ the rough law acts on both sides of a centred journal, and the net force
F_N(δ) − F_N(δ') must be smooth at e = 0 (finite stiffness 2 F_e'(−c), no direction flip);
where the far side is inactive the joint is the single-contact-point model."""

import diffrax as dfx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _derivative_helpers import jacobian_and_differences

from jaxdeploy import contact
from jaxdeploy.mechanism import (
    Body,
    Mechanism,
    RevoluteClearance,
    add_clock,
    energy_balance,
    metered,
)
from jaxdeploy.mechanism.element import Wrench
from jaxdeploy.scenes import Impact
from jaxdeploy.simulation import simulate

C = 1e-6  # clearance and σ of the issue: c = σ = 1 µm, the far side well past its onset
K = float(contact.journal_bearing_stiffness(5e-3, C, 207e9, 0.3, 207e9, 0.3))


def _joint(clearance, elastic, damping="flores", friction=None):
    if damping == "flores":
        normal = contact.Flores(elastic, 0.9)
    else:
        normal = contact.Undamped(elastic)
    return RevoluteClearance(
        "ground", "B", "journal", "c", clearance=clearance, journal_radius=5e-3,
        normal=normal, friction=friction,
    )  # fmt: skip


def _mechanism(joint):
    body = Body("journal", 1.0, 1.25e-5, {"c": (0.0, 0.0)})
    return Mechanism([body], [joint], {"B": (0.0, 0.0)})


def _forces(params, q, v, v_minus=0.3):
    """Generalized forces on the journal; `params` = (c, σ) so both are differentiated."""
    clearance, sigma = params
    joint = _joint(clearance, contact.RoughElastic(K, sigma), friction=contact.SmoothCoulomb(0.3))
    mech = _mechanism(joint)
    memory = ({**mech.init_memory(q, v)[0], "impact_velocity": jnp.asarray(v_minus)},)
    return mech.generalized_forces(q, v, 0.0, memory)


# Compiled once each and reused by every case below (run op by op, each operation's first use
# compiled it: ~16 s for the first case).
_forces_jit = jax.jit(_forces)
_jacobians = {
    "forward": jax.jit(jax.jacfwd(_forces, argnums=(0, 1, 2))),
    "reverse": jax.jit(jax.jacrev(_forces, argnums=(0, 1, 2))),
}


def _central_jacobian(f, x, h):
    columns = []
    for k in range(x.size):
        dx = jnp.zeros_like(x).at[k].set(h[k] if np.ndim(h) else h)
        columns.append((f(x + dx) - f(x - dx)) / (2 * dx[k]))
    return np.stack([np.asarray(c) for c in columns], axis=-1)


def test_centred_journal_has_no_force_and_the_closed_form_stiffness():
    """At e = 0, at rest: both sides push equally (the single point pushed with F_e(−c) ≈ 57 N
    along a direction undefined at e = 0), and dQ/de = −2 F_e'(−c) I."""
    elastic = contact.RoughElastic(K, C)
    mech = _mechanism(_joint(C, elastic))
    q = jnp.zeros(3)
    memory = mech.init_memory(q, jnp.zeros(3))
    assert float(elastic.force(-C)) > 50.0  # the far side is far past its onset

    def forces(q):
        return mech.generalized_forces(q, jnp.zeros(3), 0.0, memory)

    # Compiled: op by op, each operation's first use compiles it.
    np.testing.assert_array_equal(np.asarray(jax.jit(forces)(q)), 0.0)
    jac = jax.jit(jax.jacfwd(forces))(q)
    expected = -2.0 * float(elastic.stiffness(-C))
    np.testing.assert_allclose(np.asarray(jac[:2, :2]), expected * np.eye(2), rtol=1e-9)


@pytest.mark.parametrize(
    ("offset", "velocity"),
    [
        ((0.0, 0.0), (0.05, -0.02, 3.0)),
        ((3e-9, -1e-9), (0.05, -0.02, 3.0)),
        ((2e-7, 1e-7), (0.05, -0.02, 3.0)),
        ((-6e-7, 4e-7), (0.05, -0.02, 3.0)),
    ],
    ids=["e=0", "e=3nm", "e=0.2um", "e=0.7um"],
)
def test_forces_forward_and_reverse_derivatives_match_central_differences(offset, velocity):
    """c = σ = 1 µm, moving and spinning journal, damping and friction: dQ/d(q, v, c, σ) by
    jacfwd and jacrev agree with central differences at e = 0 and near it. The position steps
    are ≤ 0.1 % of |e|: the damping and friction forces act along n and t, which turn with e
    (docs/contact.md), so they vary on the scale |e| — and on the scale ε = 1e-12 m at e = 0,
    where n = e/sqrt(e·e + ε²) shrinks to 0: there the step is ε/1000 and the derivative is
    that of the ε-regularised joint (the elastic part has the same derivative, −2 F_e'(−c) I,
    for any ε; the damping and friction parts do not have an ε → 0 limit at e = 0)."""
    q0 = jnp.array([offset[0], offset[1], 0.1])
    v0 = jnp.array(velocity)
    p0 = jnp.array([C, C])
    h_q = min(1e-10, 1e-3 * float(np.hypot(*offset))) if offset != (0.0, 0.0) else 1e-15
    fwd_all = _jacobians["forward"](p0, q0, v0)  # d/d(params, q, v)
    rev_all = _jacobians["reverse"](p0, q0, v0)
    cases = [
        (lambda q: _forces_jit(p0, q, v0), q0, np.array([h_q, h_q, 1e-6]), 1),
        (lambda v: _forces_jit(p0, q0, v), v0, np.array([1e-5, 1e-5, 1e-4]), 2),
        (lambda p: _forces_jit(p, q0, v0), p0, 1e-9 * np.array([1.0, 1.0]), 0),
    ]
    for f, x, h, arg in cases:
        fwd = np.asarray(fwd_all[arg])
        rev = np.asarray(rev_all[arg])
        fd = _central_jacobian(f, x, h)
        assert np.all(np.isfinite(fwd)) and np.all(np.isfinite(rev))
        np.testing.assert_allclose(rev, fwd, rtol=1e-10, atol=1e-12 * np.abs(fwd).max())
        np.testing.assert_allclose(fwd, fd, rtol=0, atol=1e-5 * np.abs(fd).max())


def test_the_elastic_force_is_odd_and_smooth_through_the_centre():
    """Along a line through e = 0 the net elastic force is odd, and its slope is continuous:
    the finite-difference slope on each side tends to −2 F_e'(−c)."""
    elastic = contact.RoughElastic(K, C)
    mech = _mechanism(_joint(C, elastic, damping=None))

    def fx(x):
        q = jnp.array([x, 0.3 * x, 0.0])
        return mech.generalized_forces(q, jnp.zeros(3), 0.0, (None,))[0]

    xs = np.array([1e-11, 1e-10, 1e-9])
    plus = np.array([float(fx(x)) for x in xs])
    minus = np.array([float(fx(-x)) for x in xs])
    np.testing.assert_allclose(plus, -minus, rtol=1e-6)
    slope = plus / xs
    np.testing.assert_allclose(slope, -2.0 * float(elastic.stiffness(-C)), rtol=1e-5)


class _SinglePoint(RevoluteClearance):
    """The single-contact-point joint (near side only), written from the geometry and the laws."""

    def wrenches(self, kin, t, memory):
        g = self.geometry(kin)
        # The joint's own impact-velocity rule, on the near side's rate.
        v_minus = None if memory is None else self._impact_velocity(memory, g.penetration_rate)
        fn = self.normal.force(g.penetration, g.penetration_rate, v_minus)
        ft = 0.0 if self.friction is None else self.friction.force(g.sliding_velocity, fn)
        f = -(fn * g.normal + ft * g.tangent)
        return [
            Wrench(self.journal_body, force=f, point=g.contact_point_journal),
            Wrench(self.bearing_body, force=-f, point=g.contact_point_bearing),
        ]

    def potential_energy(self, kin, memory):
        return self.normal.elastic.potential(self.geometry(kin).penetration)


def _single_point(joint):
    return _SinglePoint(
        joint.bearing_body, joint.bearing_point, joint.journal_body, joint.journal_point,
        clearance=joint.clearance, journal_radius=joint.journal_radius, normal=joint.normal,
        friction=joint.friction, impact_velocity_rule=joint.impact_velocity_rule,
    )  # fmt: skip


@pytest.mark.parametrize(
    "elastic", [contact.HertzElastic(K), contact.RoughElastic(K, 2e-7)], ids=["hertz", "c=50σ"]
)
def test_identical_to_the_single_point_model_where_the_far_side_is_inactive(elastic):
    """σ = 0 (Hertz) and c = 50σ: the far force is exactly 0 (for c = 50σ the Gaussian tail
    F_1.5(50) underflows), so the generalized forces at any state are bit-identical to the
    single-point joint's, and a whole damped, frictional impact run equal to round-off."""
    c = 1e-5
    joint = _joint(c, elastic, friction=contact.SmoothCoulomb(0.3))
    two, one = _mechanism(joint), _mechanism(_single_point(joint))
    rng = np.random.default_rng(0)
    for _ in range(20):
        q = jnp.asarray(rng.normal(size=3) * [1e-5, 1e-5, 1.0])
        v = jnp.asarray(rng.normal(size=3))
        memory = ({**two.init_memory(q, v)[0], "impact_velocity": jnp.asarray(0.5)},)
        np.testing.assert_array_equal(
            np.asarray(two.generalized_forces(q, v, 0.0, memory)),
            np.asarray(one.generalized_forces(q, v, 0.0, memory)),
        )
        # U(δ) + U(δ') with U(δ') = 0, both sides in one vectorised call: equal to round-off.
        assert float(two.potential_energy(q, memory)) == pytest.approx(
            float(one.potential_energy(q, memory)), rel=1e-15, abs=0.0
        )
    runs = []
    for mech in (two, one):
        from jaxdeploy.mechanism import consistent_state

        init = consistent_state(
            mech, jnp.zeros(3), jnp.array([1.0, 0.2, 50.0]), fixed_velocities=(0, 1, 2)
        )
        runs.append(simulate(mech, init, 6e-5, dt=2e-8, n_save=11))
    # The compiled runs add the (zero) far wrenches in another order: equal to round-off. Fixed
    # steps, because adaptive ones turn round-off in the error estimate into different (equally
    # valid) step sequences, whose results differ by far more than round-off.
    np.testing.assert_allclose(np.asarray(runs[0].q), np.asarray(runs[1].q), rtol=1e-12, atol=0)
    assert float(np.min(np.asarray(runs[0].v[:, 0]))) < 0.0  # it did impact and rebound


def _impact(damping, **overrides):
    scene = Impact(damping=damping)
    params = scene.resolve_params(
        {"clearance": C, "sigma": C, "stiffness": K, "restitution": 0.9, **overrides}
    )
    return scene, params


@pytest.mark.parametrize("damping", ["none", "flores"])
def test_impact_at_clearance_equal_to_sigma_balances_energy(damping):
    """c = σ = 1 µm, journal launched from the centre at 1 m/s, 0.5 ms (it rattles): finite,
    T + V + D = E0 to the stated tolerance (docs/robustness.md), nothing dissipated by the
    undamped law, dissipation never negative for Flores."""
    scene, params = _impact(damping)
    mech = metered(scene.build(params))
    mech, init = add_clock(mech, scene.initial_state(params, mech))
    traj = simulate(mech, init, 5e-4, rtol=1e-8, atol=1e-13, dt_max=1e-5, n_save=101)
    assert traj.ok, traj.status()
    assert np.all(np.isfinite(np.asarray(traj.q)))
    balance = energy_balance(mech, traj.q, traj.v, traj.memory)
    e0 = float(balance["kinetic"][0] + balance["potential"][0])
    assert e0 == pytest.approx(0.5 + 2 * float(contact.RoughElastic(K, C).potential(-C)), rel=1e-9)
    assert float(np.max(np.abs(np.asarray(balance["residual"])))) <= 2e-3 * e0
    dissipated = np.asarray(balance["dissipated"])
    if damping == "none":
        assert np.max(np.abs(dissipated)) <= 1e-12 * e0
    else:
        assert dissipated[-1] > 0.01 * e0 and np.min(dissipated) >= -1e-9 * e0
    assert float(np.min(np.asarray(traj.v[:, 0]))) < 0.0  # rebounds


@pytest.mark.slow
def test_run_derivatives_from_the_centre_match_central_differences():
    """c = σ = 1 µm, slow launch (1 cm/s) from e = 0: the journal sits in two-sided contact,
    then meets the near wall. Reverse mode of the replayed adaptive run is finite from e = 0
    and matches central differences over the same steps (their runs from the same compiled
    program), w.r.t. c, σ, c_e and K. (Forward and reverse mode of a replayed impact run agree
    to round-off: tests/test_gradients.py; forward mode from this start is finite: below.)"""
    scene, params = _impact("flores", impact_speed=0.01)
    wrt = ["clearance", "sigma", "restitution", "stiffness"]
    t_end = 3e-4
    ts = jnp.linspace(0.0, t_end, 7)

    def output(ch):
        return jnp.concatenate([1e3 * ch["journal_x"][1:], 1e-6 * ch["journal_ax"][1:]])

    rev, fd = jacobian_and_differences(
        scene, params, wrt, output, t_end, 1e-5, ts=ts, mode="reverse"
    )
    for name in wrt:
        scale = np.abs(fd[name]).max()
        assert scale > 0 and np.all(np.isfinite(rev[name])), name
        np.testing.assert_allclose(rev[name], fd[name], rtol=0, atol=1e-4 * scale, err_msg=name)


@pytest.mark.slow
def test_forward_mode_through_the_raw_adaptive_loop_is_finite():
    """The directional derivative of experiments/robustness.py (all parameters at once,
    `diffrax.ForwardMode`) for c = σ = 1 µm from the centre."""
    scene, params = _impact("flores", impact_speed=0.01)
    names = ["clearance", "sigma", "stiffness", "restitution", "impact_speed"]

    def f(s):
        p = {**params, **{k: params[k] * (1.0 + s) for k in names}}
        mech = scene.build(p)
        traj = simulate(
            mech, scene.initial_state(p, mech), 3e-4, rtol=1e-8, atol=1e-13, dt_max=1e-6,
            n_save=4, adjoint=dfx.ForwardMode(),
        )  # fmt: skip
        return jnp.stack([traj.q[-1, 0], traj.v[-1, 0]])

    _, tangent = jax.jvp(f, (jnp.zeros(()),), (jnp.ones(()),))
    assert np.all(np.isfinite(np.asarray(tangent))), tangent
