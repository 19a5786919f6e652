"""LuGre hinge friction (`contact.LuGreFriction`, `mechanism.HingeFriction`): a friction law
with a state that is integrated with the mechanism (issue 24, item 1).

References used here share no code with the package: the law's steady state and its
quasi-static presliding displacement in closed form, and scipy integrating the bristle ODE.
A disc on a hinge (pin radius r, normal load F_N) is loaded by a torque ramp τ(t)."""

from typing import ClassVar

import diffrax as dfx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from jaxdeploy import contact
from jaxdeploy.mechanism import (
    AbstractElement,
    Body,
    EnergyMeter,
    HingeFriction,
    Mechanism,
    Revolute,
    Wrench,
    consistent_state,
)
from jaxdeploy.mechanism._fields import param
from jaxdeploy.simulation import simulate

F_N = 100.0  # N
RADIUS = 5e-3  # m
INERTIA = 1e-4  # kg m²
LAW = contact.LuGreFriction()  # literature defaults: μ_C 0.05, μ_S 0.075, σ0 1e5 N/m, ...
STATIC_TORQUE = float(LAW.mu_static) * F_N * RADIUS  # 0.0375 N m


class TorqueRamp(AbstractElement):
    """τ(t) = τ_max S(t/T), S(s) = s² (3 − 2s) on [0, 1] and 1 after, on the disc (a test load
    that starts and stops without a jump in τ̇: a kink would ring the bristle mode, the pin
    would move back and forth, and the presliding path would no longer be the monotone one
    of the closed form)."""

    peak: float = param()
    ramp_time: float = param()
    has_memory: ClassVar[bool] = False

    def torque(self, t):
        s = jnp.clip(t / self.ramp_time, 0.0, 1.0)
        return self.peak * s * s * (3.0 - 2.0 * s)

    def wrenches(self, kin, t, memory):
        return [Wrench("disc", torque=self.torque(t))]

    def bodies(self):
        return ("disc",)


def _disc(law, peak, ramp_time=1.0, omega0=0.0):
    disc = Body("disc", 0.5, INERTIA, {"c": (0.0, 0.0)})
    elements = [
        Revolute("ground", "O", "disc", "c"),
        HingeFriction("ground", "disc", law, normal_force=F_N, radius=RADIUS),
        TorqueRamp(peak, ramp_time),
    ]
    mech = Mechanism([disc], elements, {"O": (0.0, 0.0)})
    state = consistent_state(mech, jnp.zeros(3), jnp.array([0.0, 0.0, omega0]))
    return mech, state


def _run(mech, state, t_end, n_save=201, **control):
    options = {"rtol": 1e-8, "atol": 1e-11, "solver": "kvaerno5", **control}
    tr = simulate(mech, state, t_end, n_save=n_save, **options)
    assert tr.ok, tr.status()
    return tr


def _presliding(force, level, stiffness):
    """Quasi-static presliding displacement under a tangential force F < g at v → 0⁺:
    dz/dx = 1 − σ0 z / g, so z = (g/σ0)(1 − e^{−σ0 x/g}) and x = −(g/σ0) ln(1 − F/g)."""
    return -(level / stiffness) * np.log(1.0 - force / level)


def test_steady_sliding_is_coulomb_plus_stribeck_plus_viscous():
    """The bristle ODE at constant speed, integrated by scipy, settles at
    F = g(v) sgn v + σ2 v, g(v) = F_N (μ_C + (μ_S − μ_C) e^{−(v/v_S)²}); speeds around v_S,
    where the Stribeck term is a third of the Coulomb level, and far above it."""
    mu_c, mu_s, v_s = 0.05, 0.075, 1e-3
    sigma0, sigma1, sigma2 = 1e5, 316.22776601683796, 0.4
    for v in (-3e-3, -1e-3, 5e-4, 1e-3, 2e-3, 0.05):
        g = F_N * (mu_c + (mu_s - mu_c) * np.exp(-((v / v_s) ** 2)))

        def rate(t, z, v=v, g=g):
            return [v - sigma0 * abs(v) * z[0] / g]

        # z relaxes at σ0 |v| / g ≥ 8 /s here: 10 s are e^-80.
        sol = solve_ivp(rate, (0, 10.0), [0.0], rtol=1e-12, atol=1e-16)
        z = sol.y[0, -1]
        zdot = v - sigma0 * abs(v) * z / g
        expected = sigma0 * z + sigma1 * zdot + sigma2 * v
        assert float(LAW.force(v, z, F_N)) == pytest.approx(expected, rel=1e-12)
        assert float(LAW.steady_force(v, F_N)) == pytest.approx(expected, rel=1e-9)
        assert expected == pytest.approx(np.sign(v) * g + sigma2 * v, rel=1e-9)


def test_sticks_below_the_static_level_without_creep():
    """Ramp to 0.6 τ_S in 4 s (slow enough to be quasi-static: the pin slides at < 0.03 v_S,
    where the Stribeck level is within 1e-3 of μ_S F_N), then hold for 2 s: the disc turns by
    the quasi-static presliding displacement and then stops — no creep while the load is
    held (a regularised Coulomb law would slide at ~v_s τ/τ_C here)."""
    mech, state = _disc(LAW, 0.6 * STATIC_TORQUE, ramp_time=4.0)
    tr = _run(mech, state, 6.0, n_save=601)
    theta = np.asarray(tr.q[:, 2])
    ts = np.asarray(tr.ts)
    x = _presliding(0.6 * STATIC_TORQUE / RADIUS, float(LAW.mu_static) * F_N, 1e5) / RADIUS
    held = ts >= 4.5
    np.testing.assert_allclose(theta[held], x, rtol=2e-3)
    assert np.ptp(theta[held]) < 1e-6 * x  # no creep
    bristle = np.asarray(tr.memory[1]["internal"]["bristle"])
    # Stuck: the bristles carry the load, σ0 z = F.
    assert bristle[-1] * 1e5 == pytest.approx(0.6 * STATIC_TORQUE / RADIUS, rel=1e-6)


@pytest.mark.slow
def test_breaks_away_at_the_static_level():
    """A slow ramp to 1.2 τ_S (quasi-static: with v_S = 0.1 m/s the Stribeck drop stays below
    1e-3 until the pin slides): up to 0.98 τ_S the disc has turned no more than the presliding
    displacement there, x(0.98 F_S); by 1.1 τ_S it slides (more than five times that; the
    ramp, ~0.5 τ_S/s there, carries the load past τ_S while the slip builds up)."""
    law = contact.LuGreFriction(stribeck_velocity=0.1)
    ramp = TorqueRamp(1.2 * STATIC_TORQUE, 2.4)
    mech, state = _disc(law, 1.2 * STATIC_TORQUE, ramp_time=2.4)
    tr = _run(mech, state, 2.4, n_save=2401)
    ts, theta = np.asarray(tr.ts), np.asarray(tr.q[:, 2])
    torque = np.asarray(ramp.torque(ts)) / STATIC_TORQUE
    bound = _presliding(0.98 * STATIC_TORQUE / RADIUS, float(LAW.mu_static) * F_N, 1e5) / RADIUS
    assert theta[torque <= 0.98].max() < 1.02 * bound
    assert theta[np.flatnonzero(torque >= 1.1)[0]] > 5 * bound


@pytest.mark.slow
def test_sliding_settles_at_the_steady_speed():
    """Spun at 20 rad/s under a constant torque τ between the Coulomb and static levels (with a
    viscous σ2 = 40 N s/m, so that it settles within the run): ω → v/r with
    τ/r = g(v) + σ2 v (the closed form of the steady state, solved here by bisection)."""
    law = contact.LuGreFriction(viscous=40.0)
    torque = 1.2 * float(law.mu_coulomb) * F_N * RADIUS
    mech, state = _disc(law, torque, ramp_time=1e-9, omega0=20.0)
    tr = _run(mech, state, 1.5)
    lo, hi = 1e-4, 1.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        excess = float(law.steady_force(mid, F_N)) - torque / RADIUS
        lo, hi = (lo, mid) if excess > 0 else (mid, hi)
    assert float(tr.v[-1, 2]) * RADIUS == pytest.approx(lo, rel=1e-6)


@pytest.mark.slow
def test_gradients_match_central_differences():
    """d θ(end) / d(μ_S, σ0, F_N) through the integration (forward mode) against central
    differences of separate runs, in the stuck regime."""

    def angle(p):
        law = contact.LuGreFriction(mu_static=p[0], bristle_stiffness=p[1])
        disc = Body("disc", 0.5, INERTIA, {"c": (0.0, 0.0)})
        elements = [
            Revolute("ground", "O", "disc", "c"),
            HingeFriction("ground", "disc", law, normal_force=p[2], radius=RADIUS),
            TorqueRamp(0.6 * STATIC_TORQUE, 0.5),
        ]
        mech = Mechanism([disc], elements, {"O": (0.0, 0.0)})
        state = consistent_state(mech, jnp.zeros(3))
        tr = simulate(
            mech,
            state,
            0.8,
            n_save=2,
            rtol=1e-10,
            atol=1e-13,
            solver="kvaerno5",
            adjoint=dfx.ForwardMode(),
        )
        return tr.q[-1, 2]

    x = jnp.array([0.075, 1e5, F_N])
    grad = np.asarray(jax.jacfwd(angle)(x))
    for k in range(3):
        step = 1e-4 * float(x[k])
        dx = jnp.zeros(3).at[k].set(step)
        fd = (float(angle(x + dx)) - float(angle(x - dx))) / (2 * step)
        assert grad[k] == pytest.approx(fd, rel=1e-4), k
        assert grad[k] != 0.0


def test_generalized_alpha_refuses_internal_states():
    mech, state = _disc(LAW, 0.01)
    with pytest.raises(ValueError, match="generalized_alpha.*internal states.*tsit5"):
        simulate(mech, state, 0.01, dt=1e-3, solver="generalized_alpha")


def test_bad_lugre_parameters_are_named():
    with pytest.raises(ValueError, match="mu_static = 0.01 is invalid: it must be ≥ mu_coulomb"):
        contact.LuGreFriction(mu_static=0.01)
    with pytest.raises(ValueError, match="bristle_stiffness"):
        contact.LuGreFriction(bristle_stiffness=0.0)
    with pytest.raises(ValueError, match=r"HingeFriction\.normal_force"):
        HingeFriction("ground", "disc", LAW, normal_force=0.0, radius=RADIUS)
    with pytest.raises(ValueError, match="EnergyMeter cannot meter HingeFriction"):
        EnergyMeter(HingeFriction("ground", "disc", LAW, normal_force=1.0, radius=RADIUS))
