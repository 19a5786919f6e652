"""Generalized-α: the α convention, convergence order, accuracy against closed forms,
derivatives through the solver."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from jaxdeploy.mechanism import Body, Mechanism, Spring, consistent_state
from jaxdeploy.scenes import Impact, Pendulum, SliderCrank, ideal_slider_kinematics
from jaxdeploy.simulation import simulate
from jaxdeploy.solvers import GeneralizedAlpha, MechanismState, MechanismTerm, chung_hulbert


@pytest.mark.parametrize(
    "rho, expected",
    [
        # Chung & Hulbert (1993) formulas in the Arnold–Brüls convention (old level weighted).
        (0.8, (1 / 3, 4 / 9, 11 / 18, 0.25 * (11 / 18 + 0.5) ** 2)),
        (0.5, (0.0, 1 / 3, 5 / 6, 4 / 9)),
        (1.0, (0.5, 0.5, 0.5, 0.25)),
    ],
)
def test_chung_hulbert_coefficients(rho, expected):
    np.testing.assert_allclose(chung_hulbert(rho), expected, rtol=1e-12)


def _oscillator(omega):
    body = Body("mass", 1.0, 1.0, {"c": (0.0, 0.0)})
    spring = Spring("ground", "O", "mass", "c", stiffness=omega**2, rest_length=0.0)
    return Mechanism([body], [spring], ground_points={"O": (0.0, 0.0)})


@pytest.mark.parametrize("rho", [0.0, 0.5, 0.8, 1.0])
def test_spectral_radius_at_infinity_is_rho_inf(rho):
    """Pins the convention: the one-step map of x'' = −ω²x has spectral radius ρ∞ as hω → ∞.
    (With the complementary PETSc/OpenSees convention the radius would differ.)"""
    mech = _oscillator(omega=1e4)
    solver = GeneralizedAlpha(rho_inf=rho)
    term = MechanismTerm(mech)
    h = 100.0  # hω = 1e6

    def one_step(z):
        x, v, qdd, a = z
        q = jnp.array([x, 0.0, 0.0])
        y = MechanismState(
            q, v * jnp.array([1.0, 0, 0]), qdd * jnp.array([1.0, 0, 0]), jnp.zeros(0), (None,)
        )
        state = solver.init(term, 0.0, h, y, None)._replace(a=a * jnp.array([1.0, 0, 0]))
        y1, *_, state1, _ = solver.step(term, 0.0, h, y, None, state, False)
        return jnp.stack([y1.q[0], y1.v[0], y1.qdd[0], state1.a[0]])

    jac = jax.jacfwd(one_step)(jnp.array([1e-3, 0.0, -1e5, -1e5]))
    radius = np.max(np.abs(np.linalg.eigvals(np.asarray(jac))))
    np.testing.assert_allclose(radius, rho, atol=2e-3)


@pytest.mark.parametrize("rho", [0.5, 0.8, 1.0])
def test_local_error_estimate_matches_the_exact_one_step_error(rho):
    """The step's error estimate (`y_error`: position and velocity) against the exact local
    error of x'' = −x: after steps of h up to t = 0.6 (so the algorithmic acceleration
    carries its own history), one more step from (x_n, v_n) is compared with the closed-form
    solution from the same state, x(h) = x_n cos h + v_n sin h. The estimate must agree to
    O(h) relative (the next Taylor term), i.e. the ratio error must shrink as h halves. Both
    estimates are O(h³); a wrong constant (e.g. Zienkiewicz–Xie's β − 1/6 for ρ∞ < 1) fails
    this."""
    mech = _oscillator(omega=1.0)
    solver = GeneralizedAlpha(rho_inf=rho)
    term = MechanismTerm(mech)
    step = eqx.filter_jit(solver.step)

    def ratios(h):
        unit = jnp.array([1.0, 0.0, 0.0])
        y = MechanismState(unit, 0.0 * unit, -unit, jnp.zeros(0), (None,))
        state = solver.init(term, 0.0, h, y, None)
        h = jnp.asarray(h)
        t = jnp.asarray(0.0)
        for _ in range(round(0.6 / float(h))):
            y, y_error, _, state, _ = step(term, t, t + h, y, None, state, jnp.array(False))
            t += h
        y1, y_error, _, _, _ = step(term, t, t + h, y, None, state, jnp.array(False))
        h = float(h)
        x, v = float(y.q[0]), float(y.v[0])
        exact_q = x * np.cos(h) + v * np.sin(h)
        exact_v = -x * np.sin(h) + v * np.cos(h)
        return (
            float(y_error.q[0]) / (float(y1.q[0]) - exact_q),
            float(y_error.v[0]) / (float(y1.v[0]) - exact_v),
        )

    coarse, fine = np.array(ratios(2e-2)), np.array(ratios(1e-2))
    assert np.all(np.abs(fine - 1.0) < 0.05), fine
    assert np.all(np.abs(fine - 1.0) < 0.7 * np.abs(coarse - 1.0) + 1e-3), (coarse, fine)


def _pendulum_reference(t_end, gravity=9.81, length=1.0):
    # Independent: the pendulum's angle ODE, θ'' = −(m g L/2) cos θ / (m L²/3), by DOP853.
    def rhs(t, y):
        return [y[1], -(gravity * length / 2) * np.cos(y[0]) / (length**2 / 3)]

    sol = solve_ivp(rhs, (0, t_end), [0.0, 0.0], method="DOP853", rtol=1e-13, atol=1e-13)
    return sol.y[0, -1]


@pytest.mark.parametrize("project", [None, True])
def test_pendulum_second_order_and_bounded_drift(project):
    """Fixed steps: second order, with the default (no velocity projection on fixed steps)
    and with the projection forced on."""
    scene = Pendulum()
    params = scene.resolve_params()
    mech = scene.build(params)
    s0 = scene.initial_state(params, mech)
    theta_ref = _pendulum_reference(1.0)
    steps = np.array([4e-3, 2e-3, 1e-3])
    errors, drift = [], []
    for h in steps:
        solver = None if project is None else GeneralizedAlpha(project_velocities=True)
        tr = simulate(mech, s0, 1.0, dt=h, n_save=11, solver=solver)
        assert tr.ok
        errors.append(abs(float(tr.q[-1, 2]) - theta_ref))
        drift.append(max(float(jnp.max(jnp.abs(mech.constraints(q, 0.0)))) for q in tr.q))
    order = np.polyfit(np.log(steps), np.log(errors), 1)[0]
    assert 1.8 < order < 2.2, (order, errors)
    # Index-3: the constraints hold to the Newton tolerance at every step, whatever h.
    assert max(drift) < 1e-9


@pytest.mark.parametrize("h", [1e-6, 1e-9, 1e-11])
def test_velocity_projection_removes_the_index3_roundoff(h):
    """One step of length h from a consistent pendulum state: the plain index-3 step leaves
    the velocity constraint violated by round-off of Φ(q) = 0 amplified by γ' ~ 2/h (it grows
    as h shrinks); with `project_velocities` (the default with the error estimate, i.e. on
    adaptive steps) the violation is round-off of q̇,
    and the velocities differ from the plain step's by no more than that violation."""
    scene = Pendulum()
    params = scene.resolve_params()
    mech = scene.build(params)
    s0 = scene.initial_state(params, mech)
    y0 = MechanismState(s0.q, s0.v, s0.qdd, s0.lam, s0.memory)
    term = MechanismTerm(mech)
    t0 = 0.37

    def step(solver):
        state = solver.init(term, t0, t0 + h, y0, None)
        y1 = solver.step(term, t0, t0 + h, y0, None, state, False)[0]
        jac = mech.constraint_jacobian(y1.q, t0 + h)
        violation = jac @ y1.v - mech.constraint_velocity_rhs(y1.q, t0 + h)
        return y1, float(jnp.max(jnp.abs(violation)))

    plain, plain_violation = step(GeneralizedAlpha(project_velocities=False))
    projected, violation = step(GeneralizedAlpha())
    speed = float(jnp.max(jnp.abs(y0.v))) + 1.0
    assert violation < 1e-14 * speed, violation
    np.testing.assert_array_equal(projected.q, plain.q)
    np.testing.assert_allclose(projected.v, plain.v, rtol=0, atol=10 * plain_violation + 1e-15)
    if h <= 1e-9:
        # Round-off ε|q| of the positions, times γ' ~ 2/h: far above ε|q̇|.
        assert plain_violation > 100 * violation, (plain_violation, violation)


def test_hertz_impact_closed_form():
    scene = Impact(damping="none")
    params = scene.resolve_params({"mass": 0.5, "impact_speed": 0.8, "stiffness": 2e10})
    mech = scene.build(params)
    s0 = scene.initial_state(params, mech)
    from jaxdeploy.scenes import hertz_impact_closed_form

    d_max, f_max, t_c = hertz_impact_closed_form(0.5, 2e10, 0.8)
    t_hit = scene.time_of_first_touch(params)
    ts = np.linspace(t_hit - 0.1 * t_c, t_hit + 1.2 * t_c, 3001)
    tr = simulate(mech, s0, ts[-1], ts=ts, rtol=1e-9, atol=1e-15, dt_max=t_c / 300)
    assert tr.ok
    pen = np.asarray(tr.q[:, 0]) - params["clearance"]
    np.testing.assert_allclose(pen.max(), d_max, rtol=1e-3)
    np.testing.assert_allclose(2e10 * pen.max() ** 1.5, f_max, rtol=1e-3)
    # Contact start and end by linear interpolation of the penetration's zero crossings.
    idx = np.flatnonzero(np.diff(np.sign(pen)) != 0)
    crossings = [ts[i] - pen[i] * (ts[i + 1] - ts[i]) / (pen[i + 1] - pen[i]) for i in idx]
    assert len(crossings) == 2
    np.testing.assert_allclose(crossings[1] - crossings[0], t_c, rtol=1e-3)
    # Undamped: the rebound speed equals the approach speed.
    np.testing.assert_allclose(-float(tr.v[-1, 0]), 0.8, rtol=1e-4)


def test_impact_energy_error_shrinks_with_step():
    scene = Impact(damping="none")
    params = scene.resolve_params()
    mech = scene.build(params)
    s0 = scene.initial_state(params, mech)
    errors = []
    for h in [2e-6, 1e-6, 5e-7]:
        tr = simulate(mech, s0, 6e-4, dt=h, n_save=2)  # contact ends at ~4.2e-4 s
        e0, e1 = (float(mech.kinetic_energy(v)) for v in tr.v)
        errors.append(abs(e1 / e0 - 1.0))
    assert errors[0] > errors[1] > errors[2]
    assert errors[-1] < 1e-3


def test_ideal_slider_crank_acceleration_extremes():
    scene = SliderCrank(ideal=True)
    params = scene.resolve_params()
    mech = scene.build(params)
    s0 = scene.initial_state(params, mech)
    period = 2 * np.pi / params["crank_speed"]
    ts = np.linspace(period, 2 * period, 1441)
    tr = simulate(mech, s0, 2 * period, ts=ts, dt=period / 1440)
    assert tr.ok
    _, _, a_ideal = ideal_slider_kinematics(
        params["crank_length"], params["rod_length"], params["crank_speed"], ts
    )
    acc = np.asarray(tr.qdd[:, 6])
    np.testing.assert_allclose(acc.min(), a_ideal.min(), rtol=1e-3)
    np.testing.assert_allclose(acc.max(), a_ideal.max(), rtol=1e-3)


# Slow: the default suite checks a superset in tests/test_gradients.py
# (test_impact_forward_and_reverse_mode_match_central_differences: the same damped impact —
# Lankarani–Nikravesh, 0.5 m/s, c = 20 µm —, fixed-step generalized-α, reverse mode against
# central differences at 1e-4, w.r.t. c_e and K and also c and σ, forward mode too).
@pytest.mark.slow
def test_gradient_through_solver_matches_finite_differences():
    """d(position after a damped impact)/d(restitution, stiffness), reverse mode through the
    generalized-α steps (implicit-function-theorem Newton), against central differences."""
    scene = Impact(damping="lankarani_nikravesh")
    base = scene.resolve_params({"impact_speed": 0.5, "clearance": 2e-5})
    t_end = 2e-4

    def final_x(restitution, stiffness):
        params = dict(base, restitution=restitution, stiffness=stiffness)
        mech = scene.build(params)
        s0 = scene.initial_state(params, mech)
        tr = simulate(mech, s0, t_end, dt=2e-7, n_save=2)
        return tr.q[-1, 0]

    # One compiled program gives the gradient and the values for the differences (run op by
    # op, `jax.grad` and the plain runs compiled separately and dispatched every operation).
    value_and_grad = jax.jit(jax.value_and_grad(final_x, argnums=(0, 1)))
    args = (jnp.asarray(0.7), jnp.asarray(1e10))
    _, grads = value_and_grad(*args)
    for i, rel in enumerate([1e-4, 1e-4]):
        step = rel * float(args[i])
        plus = list(args)
        minus = list(args)
        plus[i] = args[i] + step
        minus[i] = args[i] - step
        fd = (value_and_grad(*plus)[0] - value_and_grad(*minus)[0]) / (2 * step)
        assert np.isfinite(float(grads[i]))
        np.testing.assert_allclose(float(grads[i]), float(fd), rtol=1e-4)


def test_newton_failure_is_reported_with_time_and_reason_not_nan():
    mech = _oscillator(omega=1e4)
    s0 = consistent_state(mech, jnp.array([1.0, 0.0, 0.0]))
    ok = simulate(mech, s0, 5.0, dt=1.0, n_save=6, solver=GeneralizedAlpha(rho_inf=0.6))
    assert ok.ok and ok.status() == "ok"
    starved = GeneralizedAlpha(rho_inf=0.6, newton_max_iterations=1)
    failed = simulate(mech, s0, 5.0, dt=1.0, n_save=6, solver=starved)
    assert not failed.ok
    assert failed.status().startswith("failed after t = ")
    assert "Nonlinear solve diverged" in failed.status()


def test_modified_newton_matches_newton_within_the_newton_tolerance():
    """Modified Newton (factorised iteration matrix reused across iterations and steps) and
    Newton proper solve the same step equations: on the ideal slider-crank (2 revolutions,
    2400 steps) the trajectories agree to within one Newton tolerance, atol + rtol |q|, with
    far fewer matrix evaluations than steps (the point of the reuse)."""
    scene = SliderCrank(ideal=True)
    p = scene.resolve_params()
    mech = scene.build(p)
    s0 = scene.initial_state(p, mech)
    runs = {
        mode: simulate(
            mech, s0, scene.default_t_end, dt=1e-5, n_save=41, solver=GeneralizedAlpha(newton=mode)
        )
        for mode in ("full", "modified")
    }
    assert all(run.ok for run in runs.values())
    full, modified = runs["full"], runs["modified"]
    solver = GeneralizedAlpha()
    tolerance = solver.newton_atol + solver.newton_rtol * np.abs(np.asarray(full.q))
    assert np.all(np.abs(np.asarray(modified.q - full.q)) <= tolerance)
    steps = int(modified.stats["num_accepted_steps"])
    assert int(full.stats["num_jacobian_evaluations"]) >= steps  # one per iteration
    assert int(modified.stats["num_jacobian_evaluations"]) < 0.25 * steps


def test_modified_newton_error_is_negligible_against_the_step_error():
    """Independent criterion on the clearance slider-crank through its first impact (fixed
    h = 1e-6, 0.4 ms; first contact at 0.23 ms): the journal eccentricity of modified Newton
    differs from Newton proper's by less than 1 % of the time-discretisation error, estimated
    by Newton proper's step-halving difference |e(h) − e(h/2)|."""
    from benchmarks.reference import eccentricities

    scene = SliderCrank()
    p = scene.resolve_params()
    mech = scene.build(p)
    s0 = scene.initial_state(p, mech)
    ts = jnp.linspace(0.0, 4e-4, 41)

    def ecc(mode, dt):
        run = simulate(mech, s0, 4e-4, dt=dt, ts=ts, solver=GeneralizedAlpha(newton=mode))
        assert run.ok
        return eccentricities(mech, run.q)[:, 0]

    full, half = ecc("full", 1e-6), ecc("full", 5e-7)
    modified = ecc("modified", 1e-6)
    step_error = np.max(np.linalg.norm(full - half, axis=-1))
    assert step_error > 0
    assert np.max(np.linalg.norm(modified - full, axis=-1)) < 0.01 * step_error
