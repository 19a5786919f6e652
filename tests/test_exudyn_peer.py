"""The Exudyn peer (`benchmarks.exudyn_peer`): the same slider-crank as jaxdeploy's,
checked against closed-form kinematics (ideal) and against the independent event-based numpy
model (clearance). Skipped when exudyn (the `bench` extra) is not installed."""

import math

import jax
import numpy as np
import pytest

pytest.importorskip("exudyn")

from benchmarks.exudyn_peer import ExudynSliderCrank  # noqa: E402
from benchmarks.peers import SliderCrankNumpy  # noqa: E402
from benchmarks.reference import eccentricities  # noqa: E402
from jaxdeploy.scenes import SliderCrank  # noqa: E402
from jaxdeploy.scenes.slider_crank import ideal_slider_kinematics  # noqa: E402

T_IMPACT = 0.6e-3  # through the first impact (onset ≈ 0.23 ms, separation < 0.33 ms)


def _setup(ideal):
    scene = SliderCrank(ideal=ideal)
    params = scene.resolve_params()
    mech = scene.build(params)
    s0 = scene.initial_state(params, mech)
    return scene, params, mech, s0


def test_ideal_matches_closed_form_and_jaxdeploy_constraints():
    scene, p, mech, s0 = _setup(ideal=True)
    model = ExudynSliderCrank(p, s0.q, s0.v, ideal=True)
    t_rev = 2 * math.pi / p["crank_speed"]  # one revolution, 0.012 s
    ts = np.linspace(0.0, t_rev, 121)
    errors = []
    for h in (1e-5, 5e-6):
        run = model.solve(h, t_rev, ts)
        assert run.ok and run.steps == round(t_rev / h) and run.rejected == 0, run.message
        x, v, _ = ideal_slider_kinematics(p["crank_length"], p["rod_length"], p["crank_speed"], ts)
        # The mechanism is kinematically driven: positions follow from the constraints alone
        # (solved by Newton far below 1 nm), whatever the step.
        assert np.max(np.abs(run.q[:, 6] - x)) < 1e-9
        # jaxdeploy's own constraint functions vanish on Exudyn's states: the same mechanism.
        residual = np.asarray(jax.jit(jax.vmap(mech.constraints))(run.q, ts))
        assert np.max(np.abs(residual)) < 1e-9
        errors.append(np.max(np.abs(run.v[:, 6] - v)) / (p["crank_length"] * p["crank_speed"]))
    # Velocities of index-3 generalized-α are second-order accurate: the error falls by about
    # 4 per halving of h (at least 2^1.8), and is small against the crank-pin speed r ω.
    assert errors[1] < 1e-3, errors
    assert errors[0] / errors[1] > 2**1.8, errors


@pytest.fixture(scope="module")
def clearance_peer():
    """The event-based numpy model (classical rule, v⁻ at the located onset; tested against
    the reference in test_reference.py) through the first impact, at 61 output times."""
    _, p, mech, s0 = _setup(ideal=False)
    ts = np.linspace(0.0, T_IMPACT, 61)
    model = SliderCrankNumpy(p)
    peer = model.solve(s0, T_IMPACT, ts, "DOP853", 1e-12, 1e-14)
    assert peer.ok
    return p, mech, s0, ts, peer


@pytest.mark.parametrize("force_function", ["python", "symbolic"])
def test_clearance_matches_event_model_through_first_impact(clearance_peer, force_function):
    p, mech, s0, ts, peer = clearance_peer
    model = ExudynSliderCrank(p, s0.q, s0.v, force_function=force_function)
    e_ref = eccentricities(mech, peer.ys[:, :9])
    errors = {}
    for h in (1e-6, 5e-7):
        run = model.solve(h, T_IMPACT, ts)
        assert run.ok, run.message
        errors[h] = np.max(np.linalg.norm(eccentricities(mech, run.q) - e_ref, axis=-1))
        # One contact, whose v⁻ is the approach speed at the onset the event model located.
        assert len(model.contact_history) == 1
        assert [kind for _, kind, _ in peer.events] == ["onset", "separation"]
        v_onset = peer.events[0][2]
        assert abs(model.contact_history[0][1] - v_onset) < 1e-3 * v_onset
    # Second order through the impact (the onset's δ̇ from the step's Hermite interpolant; a
    # step-end v⁻ would be first order), and at h = 0.5 µs within 2e-4 c of the independent
    # model.
    assert errors[1e-6] / errors[5e-7] > 2**1.8, errors
    assert errors[5e-7] < 2e-4, errors


def test_force_law_matches_jaxdeploy_contact_law():
    """K, χ and the force at a few (δ, δ̇, v⁻) equal jaxdeploy's LankaraniNikravesh law."""
    import jax.numpy as jnp

    _, p, mech, s0 = _setup(ideal=False)
    model = ExudynSliderCrank(p, s0.q, s0.v)
    (index,) = [i for i, el in enumerate(mech.elements) if hasattr(el, "normal")]
    law = mech.elements[index].normal
    for delta, rate, v_minus in [(1e-6, 0.5, 0.7), (3e-6, -0.2, 0.7), (2e-6, 0.9, 0.3)]:
        model.memory = {"impact_velocity": v_minus, "in_contact": True}
        ours = float(law.force(jnp.array(delta), jnp.array(rate), v_minus))
        assert model.normal_force(delta, rate) == pytest.approx(ours, rel=1e-12)
    assert model.normal_force(-1e-6, 1.0) == 0.0


def test_invalid_inputs_are_refused():
    _, p, mech, s0 = _setup(ideal=False)
    with pytest.raises(ValueError, match="friction_coefficient"):
        ExudynSliderCrank({**p, "friction_coefficient": 0.1}, s0.q, s0.v)
    with pytest.raises(ValueError, match="force_function"):
        ExudynSliderCrank(p, s0.q, s0.v, force_function="cython")
    with pytest.raises(ValueError, match="rho_inf"):
        ExudynSliderCrank(p, s0.q, s0.v, rho_inf=1.5)
    model = ExudynSliderCrank(p, s0.q, s0.v)
    with pytest.raises(ValueError, match="divide"):
        model.solve(3e-6, 1e-4)


@pytest.mark.slow
def test_exudyn_and_jaxdeploy_generalized_alpha_agree_step_for_step(clearance_peer):
    """Both are index-3 generalized-α with Chung–Hulbert coefficients (ρ∞ = 0.8) on the same
    mechanism, contact law and v⁻ update: at the same fixed step their trajectories through
    the first impact agree far more closely than either agrees with the exact solution (what
    remains is each code's Newton tolerance and constraint formulation)."""
    from jaxdeploy.simulation import simulate

    p, mech, s0, ts, peer = clearance_peer
    h = 1e-6
    run = ExudynSliderCrank(p, s0.q, s0.v).solve(h, T_IMPACT, ts)
    ours = simulate(mech, s0, T_IMPACT, ts=ts, dt=h)
    e_exudyn = eccentricities(mech, run.q)
    e_ours = eccentricities(mech, np.asarray(ours.q))
    e_ref = eccentricities(mech, peer.ys[:, :9])
    between = np.max(np.linalg.norm(e_exudyn - e_ours, axis=-1))
    to_exact = np.max(np.linalg.norm(e_ours - e_ref, axis=-1))
    assert to_exact > 1e-5  # the discretisation error is resolved at this step
    assert between < 1e-3 * to_exact, (between, to_exact)
