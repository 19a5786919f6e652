"""LuGre friction inside the clearance joint (`contact.LuGreContactFriction` in
`mechanism.RevoluteClearance`): the bristle deflections are the joint's internal state and
the normal force is the contact force (issue 24, item 1).

References share no code with the package: closed forms of the static and steady states,
`contact.LuGreFriction` (the constant-normal-force law) for the force-normalised form, and
scipy integrating the bristle ODE for the Coulomb limit. The mechanism: a journal (disc) in a
fixed bore, pressed down by a constant force W and loaded by a constant torque τ."""

import diffrax as dfx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from jaxdeploy import contact
from jaxdeploy.mechanism import (
    AppliedForce,
    AppliedTorque,
    Body,
    Mechanism,
    RevoluteClearance,
    consistent_state,
)
from jaxdeploy.simulation import simulate

R, C, W = 5e-3, 50e-6, 100.0  # journal radius [m], clearance [m], load [N]
MASS, INERTIA = 1.0, 1.25e-5  # kg, kg m²
# A soft bore (steel's Hertz stiffness / 100) keeps the explicit steps of a resting contact
# long; nothing below depends on the stiffness.
K = float(contact.journal_bearing_stiffness(R, C, 207e9, 0.3, 207e9, 0.3)) / 100
MU = 0.05
LAW = contact.LuGreContactFriction()  # μ_C 0.05, μ_S 0.075, σ0 5e3 1/m, σ1 15.8 s/m


def _mechanism(friction, torque, load=W):
    joint = RevoluteClearance(
        "ground", "B", "disc", "c", clearance=C, journal_radius=R,
        normal=contact.Flores(contact.HertzElastic(K), 0.5), friction=friction,
    )  # fmt: skip
    elements = [joint, AppliedForce("disc", "c", (0.0, -load)), AppliedTorque("disc", torque)]
    mech = Mechanism([Body("disc", MASS, INERTIA, {"c": (0.0, 0.0)})], elements, {"B": (0.0, 0)})
    # The journal resting on the bottom of the bore with the static Hertz penetration.
    delta = (load / K) ** (2.0 / 3.0)
    return mech, consistent_state(mech, jnp.array([0.0, -C - delta, 0.0]))


def _run(friction, torque, t_end, n_save=21, **options):
    mech, state = _mechanism(friction, torque)
    options = {"rtol": 1e-7, "atol": 1e-10, "solver": "tsit5", **options}
    tr = simulate(mech, state, t_end, n_save=n_save, **options)
    assert tr.ok, tr.status()
    return tr


def test_force_normalised_law_is_lugre_at_a_constant_normal_force():
    """F_N (σ0 z + σ1 ż + σ2 v) with ż = v − σ0|v|z/g(v) is `LuGreFriction` with σ0 F_N,
    σ1 F_N, σ2 F_N and the levels μ F_N, for any fixed F_N; and z's rate does not depend on
    F_N (no 1/F_N when a contact opens)."""
    law = contact.LuGreContactFriction(0.05, 0.08, 2e-3, 4e3, 12.0, 0.3)
    for fn in (1.0, 250.0):
        ref = contact.LuGreFriction(0.05, 0.08, 2e-3, 4e3 * fn, 12.0 * fn, 0.3 * fn)
        for v, z in ((-3e-3, 1e-6), (1e-3, -4e-6), (0.2, 1.2e-5), (0.0, 3e-6)):
            assert float(law.force(v, z, fn)) == pytest.approx(float(ref.force(v, z, fn)), 1e-13)
            assert float(law.rate(v, z)) == pytest.approx(float(ref.rate(v, z, fn)), rel=1e-13)
            assert float(law.steady_force(v, fn)) == pytest.approx(
                float(ref.steady_force(v, fn)), rel=1e-13, abs=1e-300
            )
    assert float(law.force(0.1, 1e-5, 0.0)) == 0.0  # no contact, no friction


def test_approaches_coulomb_as_the_bristles_stiffen():
    """Sliding speed v = V sin(2π f t) through two reversals, μ_S = μ_C (no Stribeck): the
    bristle ODE (scipy, Radau) and the law's μ(v, z) tend to Coulomb's μ_C sgn v. The mean
    |μ − μ_C sgn v| over a period falls as σ0^(−1/2) (the presliding distance g/σ0 is
    covered near a reversal in a time ∝ σ0^(−1/2)), with σ1 = 0 and with σ1 ∝ √σ0
    (critical damping of a fixed mass, as in the example of Canudas de Wit et al. 1995)."""
    speed, freq = 0.01, 5.0

    def distance(sigma0, sigma1):
        law = contact.LuGreContactFriction(MU, MU, 1e-3, sigma0, sigma1)

        def ode(t, z):  # the 1995 bristle equation with g = μ_C, written here
            v = speed * np.sin(2 * np.pi * freq * t)
            return v - sigma0 * np.abs(v) * z / MU

        ts = np.linspace(0.0, 1.0 / freq, 4001)
        sol = solve_ivp(ode, (0, ts[-1]), [0.0], t_eval=ts, method="Radau", rtol=1e-9,
                        atol=1e-14, max_step=2e-4, vectorized=True)  # fmt: skip
        v, z = speed * np.sin(2 * np.pi * freq * ts), sol.y[0]
        np.testing.assert_allclose(np.asarray(law.rate(v, z)), ode(ts, z), rtol=1e-12, atol=1e-15)
        mu = np.asarray(law.coefficient(v, z))
        return np.trapezoid(np.abs(mu - MU * np.sign(v)), ts) * freq

    for sigma1_of in (lambda s: 0.0, lambda s: 15.8 * np.sqrt(s / 5e3)):
        errors = [distance(s, sigma1_of(s)) for s in (5e3, 5e4, 5e5)]
        ratios = np.array(errors[:-1]) / np.array(errors[1:])
        # order 1/2: a factor √10 ≈ 3.16 per decade of σ0
        np.testing.assert_allclose(ratios, np.sqrt(10.0), rtol=0.15)
        assert errors[-1] < 0.02 * MU  # 1 % of μ at σ0 = 5e5 /m


@pytest.mark.slow
def test_sticks_in_the_clearance_joint_where_coulomb_creeps():
    """τ = μ_C W R / 2, below the static level: the regularised Coulomb law balances it at the
    sliding speed v = v_s/√3 (μ s(v) = μ/2) and the disc creeps at ≈ v/R for as long as the
    load lasts; with LuGre it rolls a little up the bore and stops. At rest the bristles carry the
    tangential load, F_N σ0 z = F_T, with F_T = τ/R (moment balance about the centre) and
    F_N = W cos φ (φ the journal's angle from the bottom of the bore; static balance, so the
    ringing of the rolling mode is averaged out)."""
    torque = 0.5 * MU * W * R
    lugre = _run(LAW, torque, 0.1, n_save=201)
    coulomb = _run(contact.SmoothCoulomb(MU, slip_velocity=1e-3), torque, 0.1, n_save=201)
    ts = np.asarray(lugre.ts)
    late = ts >= 0.05
    creep = np.polyfit(ts[late], np.asarray(coulomb.q[late, 2]), 1)[0]
    # (the journal's rolling up the bore is still settling: within 10 %)
    assert creep == pytest.approx(1e-3 / np.sqrt(3.0) / R, rel=0.1)
    theta = np.asarray(lugre.q[:, 2])
    # Stuck: the rolling mode rings (±1e-5 rad) about a fixed angle, which does not drift.
    drift = theta[(ts >= 0.075)].mean() - theta[late & (ts < 0.075)].mean()
    assert abs(drift) < 1e-2 * creep * 0.025
    e = np.asarray(lugre.q[late, :2])
    cos_phi = -e[:, 1] / np.linalg.norm(e, axis=1)
    z = np.asarray(lugre.memory[0]["internal"]["bristle"])[late, 0]
    carried = float(LAW.bristle_stiffness) * np.abs(z) * W * cos_phi
    # Averaged over the late window (not a whole number of the ringing mode's periods, which
    # move the instantaneous value by ~3e-4).
    assert carried.mean() == pytest.approx(torque / R, rel=1e-3)


@pytest.mark.slow
def test_gradients_match_central_differences():
    """d θ(end) / d(μ_S, σ0, σ1) of the stuck disc, forward mode through the integration
    against central differences of separate runs."""

    def angle(p):
        law = contact.LuGreContactFriction(MU, p[0], 1e-3, p[1], p[2])
        mech, state = _mechanism(law, 0.5 * MU * W * R)
        tr = simulate(mech, state, 0.02, n_save=2, rtol=1e-10, atol=1e-13, solver="tsit5",
                      adjoint=dfx.ForwardMode())  # fmt: skip
        return tr.q[-1, 2]

    x = jnp.array([0.075, 5e3, 15.8])
    run = jax.jit(angle)
    grad = np.asarray(jax.jit(jax.jacfwd(angle))(x))
    for k in range(3):
        step = 1e-4 * float(x[k])
        dx = jnp.zeros(3).at[k].set(step)
        fd = (float(run(x + dx)) - float(run(x - dx))) / (2 * step)
        assert grad[k] == pytest.approx(fd, rel=1e-4), k
        assert grad[k] != 0.0


def test_bad_parameters_are_named():
    with pytest.raises(ValueError, match="mu_static = 0.01 is invalid: it must be ≥ mu_coulomb"):
        contact.LuGreContactFriction(mu_static=0.01)
    with pytest.raises(ValueError, match="mu_coulomb = 0.0 is invalid"):
        contact.LuGreContactFriction(mu_coulomb=0.0, mu_static=0.0)
    with pytest.raises(ValueError, match=r"bristle_stiffness.*1/m"):
        contact.LuGreContactFriction(bristle_stiffness=-1.0)


def test_deploy_array_friction_law_option_builds_lugre_hinges():
    """`DeployArray(friction_law="lugre")`: each clearance joint's friction is the LuGre law
    with the hinge's μ as μ_C and the named parameters; the Coulomb default is unchanged and
    ignores them (and LuGre ignores the Coulomb law's slip velocity)."""
    from jaxdeploy.scenes import DeployArray

    overrides = {"friction_static_ratio": 1.2, "stribeck_velocity": 2e-3,
                 "bristle_stiffness": 1e4, "bristle_damping": 30.0}  # fmt: skip
    scene = DeployArray(friction_law="lugre", friction_roughness="ploughing")
    mech = scene.build(scene.resolve_params({"panel1_ra": 0.8e-6, **overrides}))
    joints = [e for e in mech.elements if isinstance(e, RevoluteClearance)]
    assert len(joints) == 2 and all(j.has_internal_state for j in joints)
    mu = float(contact.PloughingFriction(0.01, 0.8e-3)(0.8e-6))
    law = joints[0].friction
    assert isinstance(law, contact.LuGreContactFriction)
    assert (float(law.mu_coulomb), float(law.mu_static)) == pytest.approx((mu, 1.2 * mu), 1e-15)
    assert float(law.bristle_stiffness) == 1e4 and float(law.bristle_damping) == 30.0
    assert float(law.stribeck_velocity) == 2e-3
    assert scene.ignored_params()["friction_slip_velocity"] == "friction_law=coulomb"
    default = DeployArray()
    assert {default.ignored_params()[k] for k in overrides} == {"friction_law=lugre"}
    assert all(
        isinstance(e.friction, contact.SmoothCoulomb) and not e.has_internal_state
        for e in default.build(default.resolve_params()).elements
        if isinstance(e, RevoluteClearance)
    )
    with pytest.raises(ValueError, match="friction_law = 'dahl' is invalid; valid: coulomb"):
        DeployArray(friction_law="dahl")
