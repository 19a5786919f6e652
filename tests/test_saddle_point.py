"""The saddle-point solves behind the index-1 accelerations and the projection: the range-space
(Schur complement) and LU solutions satisfy the system and agree; the least-change correction
is the mass-weighted minimum-norm solution; both accelerations agree on deploy_array."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxdeploy.mechanism.saddle_point import (
    kkt_lu_solution,
    least_change_correction,
    range_space_solution,
)
from jaxdeploy.scenes import DeployArray


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
