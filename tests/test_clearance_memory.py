"""The clearance joint's v⁻ memory: the step interpolant of the eccentricity e that locates
onsets, peaks and separations of δ = |e| − c (step independence through an impact is checked in
tests/test_diffrax_path.py, the whole run through the centre in tests/test_robustness.py).

References are independent of the interpolant: exact polynomial paths e(t) (which the cubic
Hermite of their end values reproduces), evaluated with numpy and solved with scipy's brentq
or in closed form."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import brentq

from jaxdeploy.mechanism._step_eccentricity import StepEccentricity

CLEARANCE = 1e-5  # m
LEVEL = -3e-6  # m: a rough law's onset, 7 µm from the centre
SMOOTHING = 1e-12  # m, RevoluteClearance's default ε
H = 1e-5  # s

# A journal 0.139 µm beside the centre, flying through it at ~0.9 m/s towards the far side and
# braking there (x is a cubic in t): the step holds the centre passage, the far-side onset and
# a peak of δ̇ after the onset (the case a Hermite of δ itself got wrong).
X = np.array([1e9, -2.7e4, -0.894, 1.39e-7])  # x(t), highest power first
Y = np.array([0.0, 0.0, 1e-3, 2e-8])


def _path(t0, x=X, y=Y, roundoff=0.0):
    """StepEccentricity over [t0, t0 + H] of the exact path, from its end values only."""

    def ends(t):
        e = jnp.array([jnp.polyval(x, t), jnp.polyval(y, t)])
        rate = jnp.array([jnp.polyval(jnp.polyder(x), t), jnp.polyval(jnp.polyder(y), t)])
        return e, rate

    return StepEccentricity(*ends(t0), *ends(t0 + H), H, CLEARANCE, SMOOTHING, roundoff)


def _exact(x=X, y=Y):
    """δ(t), δ̇(t), δ̈(t) of the exact path (numpy)."""
    dx, dy = np.polyder(x), np.polyder(y)
    ddx, ddy = np.polyder(dx), np.polyder(dy)

    def norm(t):
        return np.sqrt(np.polyval(x, t) ** 2 + np.polyval(y, t) ** 2 + SMOOTHING**2)

    def delta(t):
        return norm(t) - CLEARANCE

    def rate(t):
        return (np.polyval(x, t) * np.polyval(dx, t) + np.polyval(y, t) * np.polyval(dy, t)) / norm(
            t
        )

    def acceleration(t):
        speed2 = np.polyval(dx, t) ** 2 + np.polyval(dy, t) ** 2
        curv = np.polyval(x, t) * np.polyval(ddx, t) + np.polyval(y, t) * np.polyval(ddy, t)
        return (speed2 + curv - rate(t) ** 2) / norm(t)

    return delta, rate, acceleration


def test_separation_is_the_first_downward_crossing_of_the_exact_path():
    """A journal in contact (δ above the level) leaves it moving inwards and goes on through
    the centre: `separation` finds where δ falls through the level (the end of the contact,
    where v⁻ resets), at or just past it, to the exact path's root."""
    x = np.array([2e8, 0.0, -0.9, 8e-6])  # in contact at t = 0 (δ = −2 µm), then inwards
    y = np.array([0.0, 0.0, 0.0, 1e-7])
    delta, rate, _ = _exact(x, y)
    t_off = brentq(lambda t: delta(t) - LEVEL, 0.0, 5e-6, xtol=1e-22, rtol=1e-15)
    assert delta(0.0) > LEVEL > delta(H) and rate(t_off) < 0.0  # the case is what it claims
    s_off = float(_path(0.0, x, y).separation(LEVEL))
    np.testing.assert_allclose(s_off * H, t_off, rtol=1e-10)
    assert delta(s_off * H) <= LEVEL + 1e-15  # at or past the crossing: out of contact


@pytest.mark.parametrize("t0", [0.0, 1e-7])
def test_onset_and_peak_after_the_centre_are_those_of_the_exact_path(t0):
    delta, rate, acceleration = _exact()
    t_centre = brentq(lambda t: np.polyval(X, t), 0.0, H)
    t_on = brentq(lambda t: delta(t) - LEVEL, t_centre, t0 + H, xtol=1e-22, rtol=1e-15)
    t_peak = brentq(acceleration, t_on, t0 + H, xtol=1e-22, rtol=1e-15)
    assert t0 < t_centre < t_on < t_peak < t0 + H  # the case is what it claims
    assert rate(t0) < 0.0 < rate(t_on) < rate(t_peak)

    path = _path(t0)
    s_on = float(path.crossing(LEVEL))
    np.testing.assert_allclose(t0 + s_on * H, t_on, rtol=1e-10)
    np.testing.assert_allclose(float(path.rate(s_on)), rate(t_on), rtol=1e-10)
    s_peak, inside = path.peak(s_on)
    assert bool(inside)
    np.testing.assert_allclose(t0 + float(s_peak) * H, t_peak, rtol=1e-8)
    np.testing.assert_allclose(float(path.max_rate(s_on)), rate(t_peak), rtol=1e-12)
    # From after the peak, the maximum is at the interval's start.
    s_late = (t_peak - t0) / H + 0.05
    np.testing.assert_allclose(float(path.max_rate(s_late)), rate(t0 + s_late * H), rtol=1e-12)
    assert not bool(path.peak(s_late)[1])


def test_onset_on_a_straight_line_through_the_centre_is_the_exact_crossing_time():
    """e(t) = e₀ + v t through the centre (miss distance 10 nm): |e(t)| = c + level has the
    closed-form root t = (−e₀·v + sqrt((e₀·v)² − |v|²(|e₀|² − ρ²)))/|v|², and δ̇ = v·e/|e|
    rises monotonically after the centre, so its maximum over the contact is at the step's end."""
    e0, v = np.array([1.39e-7, 1e-8]), np.array([-0.894, 0.0])
    rho = CLEARANCE + LEVEL
    ev, vv = e0 @ v, v @ v
    t_on = (-ev + np.sqrt(ev**2 - vv * (e0 @ e0 - rho**2))) / vv
    e_on = e0 + v * t_on
    x, y = np.array([0.0, 0.0, v[0], e0[0]]), np.array([0.0, 0.0, v[1], e0[1]])
    path = _path(0.0, x, y)
    np.testing.assert_allclose(float(path.crossing(LEVEL)) * H, t_on, rtol=1e-12)
    np.testing.assert_allclose(
        float(path.rate(path.crossing(LEVEL))), v @ e_on / np.linalg.norm(e_on), rtol=1e-12
    )
    e1 = e0 + v * H
    np.testing.assert_allclose(float(path.max_rate(0.0)), v @ e1 / np.linalg.norm(e1), rtol=1e-12)
    assert not bool(path.peak(0.0)[1])


def test_onset_and_v_minus_have_the_derivatives_of_the_exact_path_and_finite_ones_at_the_centre():
    """d(t_on)/d(X₀) (the cubic coefficient) from the interpolant equals a central difference
    of the independent brentq root; from exactly e = 0 (a centred journal) gradients are finite."""
    delta, _, _ = _exact()

    def t_on_exact(b):
        x = X.copy()
        x[0] = b
        d, _, _ = _exact(x)
        return brentq(lambda t: d(t) - LEVEL, 1e-6, H, xtol=1e-22, rtol=1e-15)

    def t_on(b):
        return H * _path(0.0, jnp.array(X).at[0].set(b), Y).crossing(LEVEL)

    step = 1e6
    fd = (t_on_exact(X[0] + step) - t_on_exact(X[0] - step)) / (2 * step)
    np.testing.assert_allclose(float(jax.grad(t_on)(X[0])), fd, rtol=1e-6)

    def v_minus(e0, rate0):
        path = StepEccentricity(e0, rate0, e0 + H * rate0, rate0, H, CLEARANCE, SMOOTHING)
        return path.max_rate(path.crossing(LEVEL))

    zero, speed = jnp.zeros(2), jnp.array([0.894, 0.0])
    grads = jax.grad(v_minus, argnums=(0, 1))(zero, speed)
    assert all(np.all(np.isfinite(np.asarray(g))) for g in grads)
    np.testing.assert_allclose(float(v_minus(zero, speed)), 0.894, rtol=1e-12)
    np.testing.assert_allclose(np.asarray(grads[1]), [1.0, 0.0], atol=1e-9)


def test_a_step_too_short_to_resolve_e_adds_no_interior_peak():
    """A 4e-19 s step that landed on a requested output time (Dopri8 with `step_ts` on
    slider_crank): e₁ − e₀ = 2.8e-17 m is round-off of world positions ~0.1 m, and
    (e₁ − e₀)/h = 64 m/s once made v⁻ = 95 m/s in a 1.09 m/s contact. The interpolant must
    then not invent a rate beyond its end values."""
    d0, r0 = 1.1362057218265828e-05, 1.091997004573437
    d1, r1 = 1.1362057218293584e-05, 1.0919970045734377
    roundoff = 16 * np.finfo(float).eps * 0.2
    c = 2.5e-4
    e0, e1 = jnp.array([c + d0, 0.0]), jnp.array([c + d1, 0.0])
    path = StepEccentricity(
        e0, jnp.array([r0, 0.0]), e1, jnp.array([r1, 0.0]), 4.336808689942018e-19, c,
        SMOOTHING, roundoff,
    )  # fmt: skip
    assert float(path.max_rate(0.0)) == pytest.approx(max(r0, r1), rel=1e-15)
    # A step long enough to resolve e keeps the cubic (and its interior peak), at the same
    # round-off level.
    _, rate, acceleration = _exact()
    t_peak = brentq(acceleration, 8e-6, H, xtol=1e-22, rtol=1e-15)
    np.testing.assert_allclose(float(_path(0.0, roundoff=roundoff).max_rate(0.0)), rate(t_peak),
                               rtol=1e-12)  # fmt: skip


# --- the impact-velocity rule of RevoluteClearance, on a contact the mechanism drives in ---

DRIVEN_C = 1e-4  # m
DRIVEN_H = 1e-4  # s
# x(t) = 5e-5 + 0.5 t + 2000 t² + 1e7 t³ (m, t in s): a journal that crosses the clearance
# at ~0.6 m/s and keeps speeding up inside the step (the mechanism drives it in), as the Flores
# slider-crank's first impact does.
DRIVEN_X = np.array([1e7, 2000.0, 0.5, 5e-5])


def _driven_joint(rule):
    from jaxdeploy.contact import HertzElastic, LankaraniNikravesh
    from jaxdeploy.mechanism import Body, Mechanism, RevoluteClearance

    joint = RevoluteClearance(
        "ground",
        "B",
        "journal",
        "c",
        clearance=DRIVEN_C,
        journal_radius=5e-3,
        normal=LankaraniNikravesh(HertzElastic(1e10), 0.9),
        impact_velocity_rule=rule,
    )
    body = Body("journal", 1.0, 1e-5, {"c": (0.0, 0.0)})
    return joint, Mechanism([body], [joint], ground_points={"B": (0.0, 0.0)})


@pytest.mark.parametrize("rule", ["onset", "running_max"])
def test_impact_velocity_rule_on_a_contact_driven_in(rule):
    """`onset` keeps δ̇ at the onset (Lankarani & Nikravesh 1990), `running_max` the largest
    δ̇ since; both against the exact cubic path, solved with numpy."""
    joint, mech = _driven_joint(rule)
    dx = np.polyder(DRIVEN_X)

    def state(t):
        q = jnp.array([np.polyval(DRIVEN_X, t), 0.0, 0.0])
        v = jnp.array([np.polyval(dx, t), 0.0, 0.0])
        return mech.kinematics(q, v)

    memory = joint.init_memory(state(0.0))
    memory = joint.memory_after_step(memory, state(DRIVEN_H), DRIVEN_H)
    t_on = brentq(lambda t: np.polyval(DRIVEN_X, t) - DRIVEN_C, 0.0, DRIVEN_H, xtol=1e-16)
    expected = np.polyval(dx, t_on) if rule == "onset" else np.polyval(dx, DRIVEN_H)
    assert float(memory["in_contact"]) == 1.0
    np.testing.assert_allclose(float(memory["impact_velocity"]), expected, rtol=1e-10)
    np.testing.assert_allclose(float(memory["event_fraction"]), t_on / DRIVEN_H, rtol=1e-9)
    # In contact, the damping law sees the held v⁻ (onset) or the larger present δ̇ (running_max).
    faster = joint.geometry(state(DRIVEN_H)).penetration_rate
    seen = joint._impact_velocity(memory, jnp.stack([faster, -faster]))[0]
    assert float(seen) == pytest.approx(expected if rule == "onset" else float(faster))


def test_unknown_impact_velocity_rule_is_refused_with_the_valid_ones():
    with pytest.raises(ValueError, match="onset, running_max"):
        _driven_joint("peak")


@pytest.mark.parametrize("rule", ["onset", "running_max"])
def test_force_is_continuous_at_a_rough_contact_separation(rule):
    """A rough law pushes below its onset level; the memory's switch out of contact at a step
    end must not switch that force off (a jump at an instant that moves with the parameters:
    derivatives through the run would miss its saltation term). A journal receding through
    the level: the net normal force with the memory before and after the step that ends just
    past the separation, at the same state, is the same; and with v⁻ held the force is the
    law's F_e(δ)(1 + χ δ̇/v⁻) (computed here from the law's parts)."""
    from jaxdeploy.contact import LankaraniNikravesh, RoughElastic
    from jaxdeploy.mechanism import Body, Mechanism, RevoluteClearance

    sigma, v_minus, rate = 2e-6, 0.05, -0.04  # m, m/s, m/s (receding)
    law = LankaraniNikravesh(RoughElastic(1e10, sigma), 0.9)
    joint = RevoluteClearance("ground", "B", "journal", "c", clearance=DRIVEN_C,
                              journal_radius=5e-3, normal=law,
                              impact_velocity_rule=rule)  # fmt: skip
    mech = Mechanism([Body("journal", 1.0, 1e-5, {"c": (0.0, 0.0)})], [joint],
                     ground_points={"B": (0.0, 0.0)})  # fmt: skip
    level = float(law.elastic.onset_penetration())

    def state(delta):
        return mech.kinematics(jnp.array([DRIVEN_C + delta, 0.0, 0.0]), jnp.array([rate, 0.0, 0.0]))

    h = 1e-6  # s: the step from δ just above the level to just below it
    inside = {**joint.init_memory(state(level + 1e-9)), "in_contact": jnp.asarray(1.0),
              "impact_velocity": jnp.asarray(v_minus)}  # fmt: skip
    after = joint.memory_after_step(inside, state(level + rate * h), h)
    assert float(after["in_contact"]) == 0.0
    end = state(level + rate * h)
    before_switch = float(joint.contact_forces(end, inside)[0])
    after_switch = float(joint.contact_forces(end, after)[0])
    elastic = float(law.elastic.force(level + rate * h))
    # The tail this is about: a few % of the force one σ deeper.
    assert elastic > 0.01 * float(law.elastic.force(level + sigma))
    expected = elastic * (1 + float(law.chi()) * rate / v_minus)
    assert before_switch == pytest.approx(expected, rel=1e-9)
    assert after_switch == pytest.approx(before_switch, rel=1e-12)
    # Out of contact an approaching state sees its own δ̇, not the held v⁻ (a new contact's
    # v⁻ starts from it: continuous at the next onset).
    approaching = jnp.asarray([0.01, -0.01])
    assert float(joint._impact_velocity(after, approaching)[0]) == pytest.approx(0.01)
