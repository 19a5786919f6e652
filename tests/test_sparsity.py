"""Compressed (column-coloured) forward-mode Jacobians, and the generalized-α iteration matrix
built from them, against dense autodiff."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxdeploy.mechanism import (
    AppliedForce,
    Body,
    Gravity,
    Mechanism,
    Prismatic,
    Revolute,
    RevoluteClearance,
    Spring,
    Weld,
    consistent_state,
    metered,
)
from jaxdeploy.mechanism.sparsity import column_groups, compressed_jacobian
from jaxdeploy.scenes import DeployArray, Pendulum, SliderCrank
from jaxdeploy.solvers.generalized_alpha import StepSystem


def _random_pattern(rng, rows, cols, density):
    pattern = rng.random((rows, cols)) < density
    pattern[:, rng.integers(cols)] = False  # a structurally zero column
    return pattern


@pytest.mark.parametrize("seed", range(5))
def test_column_groups_share_no_row_and_cover_every_nonzero_column(seed):
    rng = np.random.default_rng(seed)
    pattern = _random_pattern(rng, 30, 20, 0.15)
    groups = column_groups(pattern)
    members = sorted(c for g in groups for c in g)
    assert members == [c for c in range(20) if pattern[:, c].any()]
    for g in groups:
        assert np.all(pattern[:, g].sum(axis=1) <= 1)
    assert len(groups) < 20  # a sparse pattern needs fewer directions than columns


@pytest.mark.parametrize("seed", range(3))
def test_compressed_jacobian_equals_dense_jacobian(seed):
    rng = np.random.default_rng(seed)
    pattern = _random_pattern(rng, 25, 18, 0.2)
    weights = jnp.asarray(rng.standard_normal(pattern.shape) * pattern)

    def fn(x):  # row i depends on x_j exactly where pattern[i, j]
        return jnp.sum(weights * jnp.sin(x * weights + x**2), axis=1) + jnp.prod(
            jnp.where(pattern, 1.0 + 0.1 * x**3, 1.0), axis=1
        )

    x = jnp.asarray(rng.standard_normal(18))
    dense = jax.jacfwd(fn)(x)
    assert np.all(np.asarray(dense)[~pattern] == 0.0)
    np.testing.assert_allclose(compressed_jacobian(fn, x, pattern), dense, rtol=1e-14, atol=1e-15)


def _mixed_mechanism():
    """Every joint and force type the structure must describe, gravity included."""
    bodies = [
        Body("a", 1.0, 0.1, {"p": (0.5, 0.0), "m": (-0.5, 0.0)}),
        Body("b", 2.0, 0.2, {"p": (0.3, 0.1)}),
        Body("c", 0.5, 0.05, {"p": (0.0, 0.2)}),
        Body("d", 0.7, 0.03),
    ]
    elements = [
        Revolute("ground", (0.0, 0.0), "a", "m"),
        Revolute("a", "p", "b", (-0.3, 0.0)),
        Prismatic("ground", (0.0, 0.0), "c", (0.0, 0.0), axis=(1.0, 0.2)),
        Weld("b", "p", "d", (0.0, 0.0)),
        Spring("b", "p", "c", "p", stiffness=300.0, rest_length=0.2, damping=2.0),
        AppliedForce("d", (0.1, 0.0), (0.0, 3.0)),
        Gravity(),
    ]
    mech = Mechanism(bodies, elements)
    q0 = jnp.array([0.5, 0.0, 0.0, 1.3, 0.0, 0.0, 0.6, 0.1, 0.0, 1.6, 0.1, 0.0])
    return mech, consistent_state(mech, q0)


def _cases():
    out = {}
    for name, scene in {
        "deploy_array": DeployArray(),
        "slider_crank clearance": SliderCrank(),
        "slider_crank ideal": SliderCrank(ideal=True),
        "pendulum": Pendulum(),
    }.items():
        params = scene.resolve_params()
        mech = scene.build(params)
        out[name] = (mech, scene.initial_state(params, mech))
    mech, state = out["slider_crank clearance"]
    wrapped = metered(mech)  # force elements wrapped in energy meters: same structure
    memory = wrapped.init_memory(state.q, state.v)
    out["slider_crank metered"] = (wrapped, state._replace(memory=memory))
    out["mixed joints and forces"] = _mixed_mechanism()
    return out


@pytest.mark.parametrize("name", list(_cases()))
def test_iteration_matrix_equals_dense_jacobian_of_the_residual(name):
    """The structured iteration matrix (compressed derivatives of constraint terms and forces,
    closed-form contact stiffness, μ columns read off Φ_q) equals autodiff of the whole
    residual in (u, μ), at states pushed into contact (u of the size of the clearances)."""
    mech, state = _cases()[name]
    n, m = state.q.shape[0], state.lam.shape[0]
    memory = mech.memory_for_step(state.memory, state.q, state.v)
    h = 1e-4
    system = StepSystem(mech, state.q, state.v, 0.6 / h, 1.2 / h**2, jnp.asarray(0.01), memory)

    def flat_residual(x):
        dynamic, constraint = system.residual((x[:n], x[n:]))
        return jnp.concatenate([dynamic, constraint])

    clearance = mech.find(RevoluteClearance)
    structured_matrix = jax.jit(system.iteration_matrix)
    dense_matrix = jax.jit(jax.jacfwd(flat_residual))
    rng = np.random.default_rng(1)
    largest_contact = 0.0
    for scale in (1e-5, 1e-4, 1e-3, 1e-3, 1e-3):
        x = jnp.concatenate(
            [scale * jnp.asarray(rng.standard_normal(n)), jnp.asarray(rng.standard_normal(m))]
        )
        dense = dense_matrix(x)
        big = float(jnp.max(jnp.abs(dense)))
        np.testing.assert_allclose(structured_matrix(x), dense, rtol=1e-11, atol=1e-14 * big)
        u = x[:n]
        kin = mech.kinematics(state.q + u, state.v + system.gamma_p * u)
        for i in clearance:
            normal = mech.elements[i].contact_forces(kin, memory[i])[0]
            largest_contact = max(largest_contact, abs(float(normal)))
    if clearance:
        assert largest_contact > 1.0  # [N]: the contact law's derivative was exercised


@pytest.mark.parametrize("name", list(_cases()))
def test_constraint_jacobian_equals_dense_jacobian(name):
    """`Mechanism.constraint_jacobian` (compressed along `constraint_pattern`) equals dense
    forward-mode differentiation of Φ, away from the assembled pose too."""
    mech, state = _cases()[name]
    if not mech.n_constraints:
        pytest.skip("no constraints")
    rng = np.random.default_rng(2)
    q = state.q + 0.1 * jnp.asarray(rng.standard_normal(state.q.shape))
    dense = jax.jacfwd(mech.constraints)(q, 0.3)
    np.testing.assert_allclose(mech.constraint_jacobian(q, 0.3), dense, rtol=1e-13, atol=1e-15)
