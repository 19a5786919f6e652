"""The index-1 ODE path (diffrax solvers with coordinate projection and step-wise memory):
selection by name, agreement with an independent numpy/scipy model and with generalized-α,
constraint satisfaction, derivatives against finite differences."""

import diffrax as dfx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from benchmarks.peers import SliderCrankNumpy
from benchmarks.reference import eccentricities
from jaxdeploy.scenes import Impact, Pendulum, SliderCrank
from jaxdeploy.simulation import simulate
from jaxdeploy.solvers import SOLVER_NAMES, solver_by_name

# First contact of the Flores slider-crank starts at t ≈ 0.23 ms and ends before 0.33 ms.
WINDOW = 0.35e-3


@pytest.fixture(scope="module")
def slider_crank():
    # The tests below check the running-max rule's peak events; the numpy model is given the
    # same rule (its default is the classical onset rule).
    scene = SliderCrank(impact_velocity_rule="running_max")
    params = scene.resolve_params()
    mech = scene.build(params)
    return params, mech, scene.initial_state(params, mech)


def test_unknown_solver_name_is_refused_with_the_valid_names():
    with pytest.raises(ValueError, match="kvaerno5"):
        solver_by_name("kvaerno7")
    assert "generalized_alpha" in SOLVER_NAMES and "kvaerno3" in SOLVER_NAMES


def test_kvaerno5_matches_independent_numpy_model_through_first_impact(slider_crank):
    """Against a separately written numpy model (hand-derived Jacobian and δ̈, v⁻ kept exactly
    by onset and peak events) solved by scipy DOP853 at 1e-11: the eccentricity and the
    recorded impact velocity agree, so the memory update after accepted steps (onset
    interpolated, running maximum at step ends) reproduces the continuous model."""
    params, mech, s0 = slider_crank
    ts = np.linspace(0.0, WINDOW, 36)
    tr = simulate(mech, s0, WINDOW, ts=ts, solver="kvaerno5", rtol=1e-9, atol=1e-12)
    assert tr.ok, tr.status()
    model = SliderCrankNumpy(params, "running_max")
    peer = model.solve(s0, WINDOW, ts, "DOP853", 1e-11, 1e-13)
    # The first impact: onset, then the approach keeps speeding up (the rod drives the journal
    # in) until its peak, which sets v⁻.
    kinds = [kind for _, kind, _ in peer.events]
    assert peer.ok and kinds == ["onset", "peak", "separation"], peer.events
    ecc = eccentricities(mech, tr.q)
    ecc_peer = eccentricities(mech, peer.ys[:, :9])
    err = np.max(np.linalg.norm(ecc - ecc_peer, axis=-1))
    assert err < 1e-5, err  # relative to the clearance c = 0.5 mm, i.e. 5 nm
    in_contact = np.asarray(tr.memory[4]["in_contact"]) > 0.5
    v_minus = np.asarray(tr.memory[4]["impact_velocity"])[in_contact][-1]
    onset_speed, peak_speed = peer.events[0][2], peer.events[1][2]
    assert peak_speed > onset_speed * (1 + 1e-3)  # the running maximum matters here
    # The peak falls between step ends; the step's Hermite interpolant of δ finds it (taking
    # the largest δ̇ at step ends instead would be ~1e-5 low here).
    np.testing.assert_allclose(v_minus, peak_speed, rtol=1e-6)


def test_fixed_step_generalized_alpha_converges_at_second_order_through_first_impact(
    slider_crank,
):
    """v⁻ is a continuous-time quantity (onset interpolated inside the step, running maximum),
    so fixed-step generalized-α keeps its second order through an impact: against the exact
    event-based numpy model the eccentricity error falls 4× per halving of h."""
    params, mech, s0 = slider_crank
    ts = np.linspace(0.0, WINDOW, 36)
    model = SliderCrankNumpy(params, "running_max")
    peer = model.solve(s0, WINDOW, ts, "DOP853", 1e-12, 1e-14)
    assert peer.ok
    errors = []
    for h in (4e-7, 2e-7, 1e-7):
        ga = simulate(mech, s0, WINDOW, ts=ts, dt=h)
        assert ga.ok, ga.status()
        diff = eccentricities(mech, ga.q) - eccentricities(mech, peer.ys[:, :9])
        errors.append(np.max(np.linalg.norm(diff, axis=-1)))
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(orders > 1.8), (errors, orders)


def test_kvaerno5_and_generalized_alpha_converge_to_each_other(slider_crank):
    """Two different discretisations (index-1 ESDIRK + projection; index-3 generalized-α) of
    the same mechanism through the first impact: the difference shrinks with h and is small
    at h = 1e-7 s."""
    params, mech, s0 = slider_crank
    ts = np.linspace(0.0, WINDOW, 36)
    k5 = simulate(mech, s0, WINDOW, ts=ts, solver="kvaerno5", rtol=1e-9, atol=1e-12)
    assert k5.ok
    errors = []
    for h in (2e-7, 1e-7):
        ga = simulate(mech, s0, WINDOW, ts=ts, dt=h)
        assert ga.ok
        diff = eccentricities(mech, k5.q) - eccentricities(mech, ga.q)
        errors.append(np.max(np.linalg.norm(diff, axis=-1)))
    assert errors[1] < errors[0], errors
    assert errors[1] < 3e-5, errors  # relative to c: 15 nm


@pytest.mark.parametrize("name", ["kvaerno3", "tsit5"])
def test_projection_keeps_constraints_and_pendulum_matches_dop853(name):
    scene = Pendulum()
    params = scene.resolve_params()
    mech = scene.build(params)
    s0 = scene.initial_state(params, mech)
    ts = np.linspace(0.0, 1.0, 11)
    # Steps land on the saved times, so every saved state is a projected step end point.
    tr = simulate(mech, s0, 1.0, solver=name, rtol=1e-8, atol=1e-10, ts=ts, step_ts=ts)
    assert tr.ok
    drift = max(float(jnp.max(jnp.abs(mech.constraints(q, 0.0)))) for q in tr.q)
    assert drift < 1e-12, drift

    def rhs(t, y):  # independent: the pendulum's angle ODE (uniform rod, pivot at one end)
        return [y[1], -(9.81 / 2) * np.cos(y[0]) / (1.0 / 3)]

    ref = solve_ivp(rhs, (0, 1.0), [0.0, 0.0], method="DOP853", rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(float(tr.q[-1, 2]), ref.y[0, -1], atol=1e-6)


def _damped_impact_final_x(restitution, **simulate_options):
    """Journal position 0.2 ms after a damped impact (fixed steps of 0.5 µs)."""
    scene = Impact(damping="lankarani_nikravesh")
    params = scene.resolve_params({"impact_speed": 0.5, "clearance": 2e-5})
    params = dict(params, restitution=restitution)
    mech = scene.build(params)
    s0 = scene.initial_state(params, mech)
    return simulate(mech, s0, 2e-4, dt=5e-7, n_save=2, **simulate_options).q[-1, 0]


def _central_difference(fn, x, relative_step=1e-4):
    step = relative_step * x
    return (fn(x + step) - fn(x - step)) / (2 * step)


@pytest.mark.slow  # 24 s of the default suite at 844cb65 (2 cores): kept out of it
def test_gradient_through_kvaerno_path_matches_finite_differences():
    """d(position after a damped impact)/d(restitution), reverse mode through Kvaerno3 steps
    (root finds differentiated implicitly) and the memory update, against central
    differences."""
    # One compiled program gives the values for the differences and the gradient.
    value_and_grad = jax.jit(
        jax.value_and_grad(lambda r: _damped_impact_final_x(r, solver="kvaerno3"))
    )
    _, grad = value_and_grad(jnp.asarray(0.7))
    fd = _central_difference(lambda r: value_and_grad(r)[0], 0.7)
    assert np.isfinite(float(grad))
    np.testing.assert_allclose(float(grad), float(fd), rtol=1e-4)


@pytest.mark.parametrize("adjoint", [dfx.ForwardMode(), dfx.DirectAdjoint()])
def test_forward_mode_through_an_explicit_runge_kutta_path_matches_finite_differences(adjoint):
    """Forward mode through Tsit5 inside `MechanismODESolver`: its stage loop must not be
    diffrax's checkpointed (custom_vjp) loop, which jvp cannot enter — diffrax switches it
    only for a bare Runge–Kutta solver, `simulate` for ours. Against central differences."""

    def final_x(restitution):
        return _damped_impact_final_x(restitution, solver="tsit5", adjoint=adjoint)

    _, tangent = jax.jit(lambda r: jax.jvp(final_x, (r,), (jnp.ones(()),)))(jnp.asarray(0.7))
    fd = _central_difference(jax.jit(final_x), 0.7)
    assert abs(float(fd)) > 0  # restitution moves the journal after the impact
    np.testing.assert_allclose(float(tangent), float(fd), rtol=1e-4)


def test_adaptive_steps_end_on_the_events_that_set_v_minus(slider_crank):
    """`simulate(..., locate_events=True)` (the default): a step inside which the contact
    begins, inside which δ̇ peaks above v⁻, or inside which the contact ends (v⁻ resets), is
    redone to end just past that event (`jaxdeploy.solvers.LocateEvents`). Against the
    event-exact numpy model: a step ends within 5 ns of all three events of the first contact
    (a contact lasts 53 µs; without location the peak fell 43 ns from the nearest step end
    with Dopri8 at this tolerance), and v⁻ equals the peak speed."""
    params, mech, s0 = slider_crank
    ts = np.linspace(0.0, WINDOW, 36)
    tr = simulate(
        mech, s0, WINDOW, ts=ts, solver="dopri8", rtol=1e-10, atol=1e-13, replay_steps=True
    )
    assert tr.ok, tr.status()
    peer = SliderCrankNumpy(params, "running_max").solve(s0, WINDOW, ts, "DOP853", 1e-12, 1e-14)
    (onset, _, _), (peak, _, peak_speed), (separation, kind, _) = peer.events[:3]
    assert kind == "separation"
    ends = np.asarray(tr.step_times)
    ends = ends[np.isfinite(ends)]
    for event in (onset, peak, separation):
        assert np.min(np.abs(ends - event)) < 5e-9, (event, ends[np.abs(ends - event) < 1e-7])
    in_contact = np.asarray(tr.memory[4]["in_contact"]) > 0.5
    v_minus = np.asarray(tr.memory[4]["impact_velocity"])[in_contact][-1]
    np.testing.assert_allclose(v_minus, peak_speed, rtol=1e-8)


def test_dense_output_is_the_inner_solvers_interpolant():
    """Outputs between steps come from the inner solver's own interpolant (Dopri8: 7th order),
    not a cubic Hermite: on the ideal slider-crank (kinematically driven, so positions are
    known in closed form) the slider position at 241 times over a revolution, 39 steps, is
    within 1e-9 m (the cubic Hermite of the same steps was 1e-6 m off)."""
    from jaxdeploy.scenes.slider_crank import ideal_slider_kinematics

    scene = SliderCrank(ideal=True)
    params = scene.resolve_params()
    mech = scene.build(params)
    s0 = scene.initial_state(params, mech)
    t_rev = 2 * np.pi / params["crank_speed"]
    ts = np.linspace(0.0, t_rev, 241)
    tr = simulate(mech, s0, t_rev, ts=ts, solver="dopri8", rtol=1e-10, atol=1e-13)
    assert tr.ok
    assert int(tr.stats["num_accepted_steps"]) < 60  # long steps: the interpolant matters
    x, v, _ = ideal_slider_kinematics(
        params["crank_length"], params["rod_length"], params["crank_speed"], ts
    )
    assert np.max(np.abs(np.asarray(tr.q[:, 6]) - x)) < 1e-9
    assert np.max(np.abs(np.asarray(tr.v[:, 6]) - v)) < 1e-6


def test_saving_fewer_outputs_leaves_the_kept_ones_bit_identical():
    """`outputs="state"` drops the saved q̈ and λ (an acceleration solve per saved time),
    `"motion"` the memory too, and nothing else: positions, velocities, memory, steps and
    extremes are the same bits, through a damped impact with its onset located."""
    scene = Impact(damping="lankarani_nikravesh")
    params = scene.resolve_params({"impact_speed": 0.5, "clearance": 2e-5})
    mech = scene.build(params)
    s0 = scene.initial_state(params, mech)
    ts = np.linspace(0.0, 2e-4, 401)
    full, state, motion = [
        simulate(mech, s0, 2e-4, solver="tsit5", rtol=1e-7, atol=1e-10, ts=ts, outputs=kept)
        for kept in ("all", "state", "motion")
    ]
    assert full.ok and state.ok and motion.ok and int(full.stats["num_rejected_steps"]) > 0
    assert state.qdd is None and state.lam is None and full.qdd.shape == full.q.shape
    assert motion.qdd is None and motion.memory is None

    def kept(tr, memory=True):
        return jax.tree.leaves((tr.ts, tr.q, tr.v, tr.memory if memory else None, tr.stats,
                                tr.extremes, tr.t_reached))  # fmt: skip

    for other, memory in ((state, True), (motion, False)):
        for a, b in zip(kept(full, memory), kept(other, memory), strict=True):
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    with pytest.raises(ValueError, match="outputs = 'no' is invalid"):
        simulate(mech, s0, 2e-4, solver="tsit5", rtol=1e-7, ts=ts, outputs="no")
    with pytest.raises(ValueError, match="batch_saved_accelerations = 'yes' is invalid"):
        simulate(mech, s0, 2e-4, solver="tsit5", rtol=1e-7, ts=ts,
                 batch_saved_accelerations="yes")  # fmt: skip
