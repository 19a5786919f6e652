"""The saddle-point solves behind the index-1 accelerations and the projection: the range-space
(Schur complement) and LU solutions satisfy the system and agree; the least-change correction
is the mass-weighted minimum-norm solution; both accelerations agree on deploy_array; the
unrolled Cholesky solve is backward stable on well- and ill-conditioned matrices, agrees with
LAPACK's, vmaps case by case and differentiates as `jnp.linalg.solve` does."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxdeploy.mechanism import saddle_point
from jaxdeploy.mechanism.saddle_point import (
    kkt_lu_solution,
    least_change_correction,
    range_space_solution,
    unrolled_cholesky,
    unrolled_cholesky_solve,
)
from jaxdeploy.scenes import DeployArray, SliderCrank
from jaxdeploy.simulation import simulate


@pytest.fixture
def system():
    rng = np.random.default_rng(3)
    n, m = 9, 5
    mass = rng.uniform(1e-3, 2.0, n)  # masses and inertias over three orders
    jac = rng.normal(size=(m, n))
    return 1.0 / jnp.asarray(mass), jnp.asarray(jac), rng.normal(size=n), rng.normal(size=m)


@pytest.mark.parametrize("solve", [range_space_solution, kkt_lu_solution])
def test_solution_satisfies_the_saddle_point_system(system, solve):
    mass_inverse, jac, f, g = system
    x, lam = solve(mass_inverse, jac, jnp.asarray(f), jnp.asarray(g))
    np.testing.assert_allclose(x / mass_inverse + jac.T @ lam, f, atol=1e-12)
    np.testing.assert_allclose(jac @ x, g, atol=1e-12)


def test_least_change_correction_is_the_mass_weighted_minimum_norm_solution(system):
    mass_inverse, jac, _, g = system
    delta = least_change_correction(mass_inverse, jac, jnp.asarray(g))
    np.testing.assert_allclose(jac @ delta, g, atol=1e-12)
    # Any other solution delta + z (J z = 0) has a larger M-norm: delta is M-orthogonal to
    # the null space of J.
    null_space = np.linalg.svd(np.asarray(jac))[2][jac.shape[0] :]
    np.testing.assert_allclose(null_space @ (delta / mass_inverse), 0.0, atol=1e-12)


def test_deploy_array_accelerations_agree_between_solves():
    scene = DeployArray()
    params = scene.resolve_params()
    mech = scene.build(params)
    s0 = scene.initial_state(params, mech)
    memory = mech.memory_for_step(s0.memory, s0.q, s0.v)
    v = jnp.asarray(np.random.default_rng(0).normal(size=s0.v.shape))  # a generic velocity
    results = {
        solve: jax.jit(lambda q, v, solve=solve: mech.accelerations(q, v, 0.0, memory, 0.0, solve))(
            s0.q, v
        )
        for solve in ("range_space", "kkt_lu")
    }
    (a1, l1), (a2, l2) = results.values()
    np.testing.assert_allclose(a1, a2, rtol=1e-10, atol=1e-10 * float(jnp.max(jnp.abs(a2))))
    np.testing.assert_allclose(l1, l2, rtol=1e-10, atol=1e-10 * float(jnp.max(jnp.abs(l2))))
    with pytest.raises(ValueError, match="linear_solve.*range_space"):
        mech.accelerations(s0.q, v, 0.0, memory, 0.0, "cholesky")


def _spd(m, condition, seed):
    """A symmetric positive definite m × m matrix with 2-norm condition number `condition`."""
    rng = np.random.default_rng(seed)
    u, _ = np.linalg.qr(rng.normal(size=(m, m)))
    a = (u * np.logspace(0, np.log10(condition), m)) @ u.T
    return 0.5 * (a + a.T), rng.normal(size=m)


@pytest.mark.parametrize("m", [1, 2, 7, 16])
@pytest.mark.parametrize("condition", [1e1, 1e8, 1e14])
def test_unrolled_cholesky_solve_is_backward_stable_and_agrees_with_lapack(m, condition):
    a, b = _spd(m, condition, seed=m)
    factor = jax.jit(unrolled_cholesky)(jnp.asarray(a))
    x = np.asarray(jax.jit(unrolled_cholesky_solve)(factor, jnp.asarray(b)))
    eps = np.finfo(float).eps
    # Backward errors (normwise) at round-off level, whatever the conditioning: of the solve
    # (Rigal–Gaches) and of the factor, L Lᵀ = a + E with ‖E‖ = O(m ε ‖a‖).
    backward = np.linalg.norm(a @ x - b) / (np.linalg.norm(a, 2) * np.linalg.norm(x))
    assert backward < 10 * m * eps
    lower = np.asarray(factor)
    assert np.all(np.triu(lower, 1) == 0.0)
    assert np.linalg.norm(lower @ lower.T - a, 2) < 10 * m * eps * np.linalg.norm(a, 2)
    # Forward error against LAPACK's LU solve: both within κ ε of the exact solution.
    lapack = np.asarray(jnp.linalg.solve(jnp.asarray(a), jnp.asarray(b)))
    assert np.linalg.norm(x - lapack) <= 10 * m * condition * eps * np.linalg.norm(lapack)


def test_unrolled_cholesky_vmaps_case_by_case_and_differentiates_as_the_lapack_solve():
    a, b = _spd(7, 1e4, seed=1)
    batch = jnp.stack([jnp.asarray(a) * s for s in (1.0, 2.0, 0.5)])

    @jax.jit
    def solve(a, b):
        return unrolled_cholesky_solve(unrolled_cholesky(a), b)

    batched = jax.vmap(solve, in_axes=(0, None))(batch, jnp.asarray(b))
    for k in range(3):
        np.testing.assert_array_equal(batched[k], solve(batch[k], jnp.asarray(b)))

    def loss(a, b, solve):
        return jnp.sum(jnp.sin(solve(a, b)))

    mine = jax.grad(loss, argnums=(0, 1))(jnp.asarray(a), jnp.asarray(b), solve)
    lapack = jax.grad(loss, argnums=(0, 1))(jnp.asarray(a), jnp.asarray(b), jnp.linalg.solve)
    # d/da of a solve is −x ⊗ (a⁻ᵀ g): symmetric inputs perturbed only symmetrically by the
    # Cholesky path (it reads the lower triangle), so compare symmetrised gradients.
    sym = lambda g: 0.5 * (g + g.T)  # noqa: E731
    np.testing.assert_allclose(sym(mine[0]), sym(lapack[0]), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(mine[1], lapack[1], rtol=1e-10)
    forward = jax.jacfwd(solve, argnums=1)(jnp.asarray(a), jnp.asarray(b))
    np.testing.assert_allclose(forward, np.linalg.inv(a), rtol=1e-9, atol=1e-12)


def test_unrolled_cholesky_of_a_singular_matrix_is_not_finite():
    jac = jnp.asarray([[1.0, 0.0, 0.0], [2.0, 0.0, 0.0]])  # rank 1: S singular
    factor = jax.jit(unrolled_cholesky)(jac @ jac.T)
    solution = jax.jit(unrolled_cholesky_solve)(factor, jnp.ones(2))
    assert not np.all(np.isfinite(np.asarray(solution)))


@pytest.fixture
def unrolled_max_size(monkeypatch):
    """Set `saddle_point.UNROLLED_MAX_SIZE` for a test. Traced programs are cached (jit, and
    the mechanism's `traced_once` functions) with the factor they were traced with: the
    caches are cleared on each change and after the test."""

    def set_size(size):
        monkeypatch.setattr(saddle_point, "UNROLLED_MAX_SIZE", size)
        jax.clear_caches()

    yield set_size
    monkeypatch.undo()
    jax.clear_caches()


def test_schur_solve_is_the_same_above_and_below_the_unrolled_size(unrolled_max_size):
    rng = np.random.default_rng(5)
    n, m = 30, 20
    mass_inverse = 1.0 / jnp.asarray(rng.uniform(1e-3, 2.0, n))
    jac, g = jnp.asarray(rng.normal(size=(m, n))), jnp.asarray(rng.normal(size=m))
    assert m > saddle_point.UNROLLED_MAX_SIZE  # LAPACK's factor
    lapack = jax.jit(least_change_correction)(mass_inverse, jac, g)
    unrolled_max_size(m)
    assert not isinstance(jax.eval_shape(saddle_point.schur_factor, mass_inverse, jac), tuple)
    unrolled = jax.jit(least_change_correction)(mass_inverse, jac, g)
    np.testing.assert_allclose(unrolled, lapack, rtol=1e-11, atol=1e-13)


@pytest.mark.slow
def test_slider_crank_trajectory_is_the_same_with_either_schur_factor(unrolled_max_size):
    """The whole run (Tsit5, fixed steps over the first millisecond; the accelerations, the
    projection and the saved states all solve with S) with the unrolled factor and with
    LAPACK's agrees to round-off."""
    scene = SliderCrank()
    params = scene.resolve_params()

    def run():
        mech = scene.build(params)
        initial = scene.initial_state(params, mech)
        return simulate(mech, initial, 1e-3, solver="tsit5", dt=2e-6, n_save=51)

    unrolled = run()
    unrolled_max_size(0)
    lapack = run()
    assert unrolled.ok and lapack.ok
    assert np.any(np.asarray(unrolled.lam) != np.asarray(lapack.lam))  # two different programs
    for name in ("q", "v", "qdd", "lam"):
        a, b = np.asarray(getattr(unrolled, name)), np.asarray(getattr(lapack, name))
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-9 * np.max(np.abs(b)), err_msg=name)
