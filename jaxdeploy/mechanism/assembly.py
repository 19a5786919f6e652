"""Consistent initial conditions for the index-3 equations.

1. Positions: the pose nearest to a guess that satisfies the constraints,
   `min ½|q − q_g|²  s.t.  Φ(q, t) = 0  (and q_i = q_g,i for chosen i)`, by Gauss–Newton
   (minimum-norm corrections `Δq = −Φ_q⁺ Φ`). Differentiable through the implicit-function
   theorem on its KKT system, so gradients flow from parameters to the initial pose.
2. Velocities: the mass-weighted projection of a guess onto `Φ_q q̇ = −Φ_t` — the velocity a
   constraint impulse would leave (Haug 1989, §6.3).
3. Accelerations and multipliers from the index-1 system `[[M, Φ_qᵀ], [Φ_q, 0]]`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp
import numpy as np

from .. import _program_cache
from .._collector import deferring_full_collections
from .._validation import is_concrete
from .saddle_point import least_change_correction
from .system import Mechanism


class AssemblyError(ValueError):
    """The initial guess cannot be assembled, or the constraints are redundant/singular."""


class ConsistentState(NamedTuple):
    """A state that satisfies the position, velocity and acceleration constraints."""

    q: jax.Array
    v: jax.Array
    qdd: jax.Array
    lam: jax.Array
    memory: tuple


def _augmented_constraints(mechanism: Mechanism, q_guess, t, fixed: tuple[int, ...]):
    idx = jnp.asarray(fixed, dtype=int)

    def phi(q):
        rows = mechanism.constraints(q, t)
        if fixed:
            rows = jnp.concatenate([rows, q[idx] - q_guess[idx]])
        return rows

    return phi


def assemble_positions(
    mechanism: Mechanism,
    q_guess,
    t=0.0,
    fixed: Sequence[int] = (),
    tol: float = 1e-13,
    max_iter: int = 60,
):
    """Pose nearest to `q_guess` with `Φ(q, t) = 0`; coordinates in `fixed` keep their guesses.

    **Returns:** `(q, residual_norm, iterations)`; check `residual_norm` (or use
    `consistent_state`, which raises `AssemblyError`).
    """
    q_guess = jnp.asarray(q_guess, dtype=float)
    fixed = tuple(int(i) for i in fixed)
    phi = _augmented_constraints(mechanism, q_guess, t, fixed)

    def kkt(z):
        q, mu = z
        return (q - q_guess + jax.jacfwd(phi)(q).T @ mu, phi(q))

    def newton(_, z0):
        def cond(state):
            _, res, it = state
            return (res > tol) & (it < max_iter)

        def body(state):
            q, _, it = state
            jac = jax.jacfwd(phi)(q)
            step = jnp.linalg.lstsq(jac, phi(q))[0]
            q = q - step
            res = jnp.max(jnp.abs(phi(q)), initial=0.0)
            return q, res, it + 1

        q0 = z0[0]
        q, res, it = jax.lax.while_loop(cond, body, (q0, jnp.max(jnp.abs(phi(q0)), initial=0.0), 0))
        jac = jax.jacfwd(phi)(q)
        mu = jnp.linalg.lstsq(jac.T, q_guess - q)[0]
        return (q, mu), (res, jnp.asarray(it, dtype=float))

    def tangent_solve(g, y):
        flat, unravel = jax.flatten_util.ravel_pytree(y)
        jac = jax.jacfwd(lambda x: jax.flatten_util.ravel_pytree(g(unravel(x)))[0])(flat)
        return unravel(jnp.linalg.solve(jac, flat))

    n_rows = mechanism.n_constraints + len(fixed)
    if n_rows == 0:
        return q_guess, jnp.zeros(()), 0
    z0 = (q_guess, jnp.zeros(n_rows, dtype=q_guess.dtype))
    (q, _), (res, it) = jax.lax.custom_root(kkt, z0, newton, tangent_solve, has_aux=True)
    return q, res, it


def project_velocities(mechanism: Mechanism, q, v_guess, t=0.0, fixed: Sequence[int] = ()):
    """Mass-weighted projection of `v_guess` onto `Φ_q v = −Φ_t` (plus `v_i = v_guess,i`, i ∈
    `fixed`): `v = v_g − M⁻¹ Jᵀ (J M⁻¹ Jᵀ)⁻¹ (J v_g − b)`."""
    v_guess = jnp.asarray(v_guess, dtype=float)
    jac = mechanism.constraint_jacobian(q, t)
    rhs = mechanism.constraint_velocity_rhs(q, t)
    if fixed:
        idx = jnp.asarray(tuple(fixed), dtype=int)
        jac = jnp.concatenate([jac, jnp.eye(q.shape[0])[idx]])
        rhs = jnp.concatenate([rhs, v_guess[idx]])
    if jac.shape[0] == 0:
        return v_guess
    mass_inverse = 1.0 / mechanism.mass_diagonal()
    return v_guess - least_change_correction(mass_inverse, jac, jac @ v_guess - rhs)


def _worst_element(mechanism: Mechanism, q, t) -> str:
    """Which constraint is violated most at `q` (for the error message)."""
    kin = mechanism.kinematics(q)
    worst, where = -1.0, "no constraint is violated"
    for index, element in enumerate(mechanism.elements):
        if not element.n_constraints:
            continue
        violation = float(np.max(np.abs(np.asarray(element.constraint(kin, t)))))
        if not violation <= worst:  # NaN counts as worst
            ends = ", ".join(element.bodies())
            worst = violation if np.isfinite(violation) else np.inf
            where = (
                f"largest violation {violation:.3g} in element {index} "
                f"({type(element).__name__} between {ends})"
            )
    return where


def _singular_value_range(mechanism: Mechanism, q, t):
    """Largest and smallest singular values of Φ_q. Diagnostics only: no derivatives flow
    through them."""
    jac = jax.lax.stop_gradient(mechanism.constraint_jacobian(q, t))
    if jac.shape[0] == 0:
        return jnp.ones(()), jnp.ones(())
    sv = jnp.linalg.svd(jac, compute_uv=False)
    return sv[0], sv[-1]


def _check_rank(sv_max, sv_min, shape, what: str):
    scale = max(1.0, float(sv_max))
    if float(sv_min) < 1e-9 * scale:
        raise AssemblyError(
            f"{what}: the constraint Jacobian Φ_q ({shape[0]}×{shape[1]}) is rank "
            f"deficient at this pose (smallest singular value {float(sv_min):.3g}); the "
            "constraints are redundant or the pose is singular (e.g. a dead-centre position)."
        )


@eqx.filter_jit
@deferring_full_collections
def _motion_core(mechanism, q_guess, v_guess, t, fixed, fixed_velocities, tol):
    """The positions and velocities of `_consistent_core` alone, as one compiled program."""
    q, res, it = assemble_positions(mechanism, q_guess, t, fixed, tol)
    v = project_velocities(mechanism, q, v_guess, t, fixed_velocities)
    return (q, v), (res, it)


@eqx.filter_jit
@deferring_full_collections
def _consistent_core(mechanism, q_guess, v_guess, t, fixed, fixed_velocities, tol):
    """Everything of `consistent_state` as one compiled program (op-by-op dispatch of the
    Gauss–Newton loop and the Jacobians would cost seconds of small compilations)."""
    q, res, it = assemble_positions(mechanism, q_guess, t, fixed, tol)
    sv_max, sv_min = _singular_value_range(mechanism, q, t)
    v = project_velocities(mechanism, q, v_guess, t, fixed_velocities)
    memory = mechanism.init_memory(q, v)
    qdd, lam = mechanism.accelerations(q, v, t, memory)
    return ConsistentState(q, v, qdd, lam, memory), (res, it, sv_max, sv_min)


def consistent_state(
    mechanism: Mechanism,
    q_guess,
    v_guess=None,
    t=0.0,
    fixed: Sequence[int] = (),
    fixed_velocities: Sequence[int] = (),
    tol: float = 1e-13,
) -> ConsistentState:
    """Consistent `(q, q̇, q̈, λ, memory)` at time `t` from approximate guesses.

    **Arguments:**
    - `mechanism`: the mechanism.
    - `q_guess`: approximate coordinates (n,).
    - `v_guess`: approximate velocities (default zero).
    - `fixed`: coordinate indices kept at their guessed values while assembling (e.g. the
      input angle that selects a pose of a 1-DOF mechanism).
    - `fixed_velocities`: velocity indices kept at their guessed values.

    **Raises:** `AssemblyError` (with the residual) if the pose cannot be assembled or the
    constraints are redundant. Checks are skipped under `jit`/`vmap` (traced inputs).
    """
    q_guess, v_guess = _guesses(mechanism, q_guess, v_guess)
    # Through the command line's program cache (a plain call unless it is enabled).
    state, (res, it, sv_max, sv_min) = _program_cache.call(
        _consistent_core, mechanism, q_guess, v_guess, t, tuple(fixed), tuple(fixed_velocities), tol
    )
    if is_concrete((state.q, res)):
        _check_assembled(mechanism, state.q, t, res, it, tol)
        shape = (mechanism.n_constraints, mechanism.n_coordinates)
        if shape[0] > 0:
            _check_rank(sv_max, sv_min, shape, "initial pose")
    return state


def consistent_motion(
    mechanism: Mechanism,
    q_guess,
    v_guess=None,
    t=0.0,
    fixed: Sequence[int] = (),
    fixed_velocities: Sequence[int] = (),
    tol: float = 1e-13,
):
    """`(q, q̇)` of `consistent_state` alone: the pose assembled and the velocities projected
    (same arguments), without the rank check, the memory, q̈ and λ, in a program about half
    the size (slider_crank's ideal mechanism: 0.36 → 0.16 CPU-s of XLA compile, 0.41 → 0.20
    of tracing and lowering; deploy_array's 0.78 → 0.39 and 0.85 → 0.59).

    For a pose that is only a step towards the state a run starts from: a clearance
    mechanism's scene assembles its ideal counterpart (journals centred), then completes the
    state of the mechanism itself with `consistent_state`, which checks its rank.

    **Raises:** `AssemblyError` if the pose cannot be assembled (not under `jit`/`vmap`).
    """
    q_guess, v_guess = _guesses(mechanism, q_guess, v_guess)
    (q, v), (res, it) = _program_cache.call(
        _motion_core, mechanism, q_guess, v_guess, t, tuple(fixed), tuple(fixed_velocities), tol
    )
    if is_concrete((q, res)):
        _check_assembled(mechanism, q, t, res, it, tol)
    return q, v


def _guesses(mechanism: Mechanism, q_guess, v_guess):
    """`(q_guess, v_guess)` as float arrays (v default zero); a `ValueError` for a q of the
    wrong shape."""
    q_guess = jnp.asarray(q_guess, dtype=float)
    if q_guess.shape != (mechanism.n_coordinates,):
        raise ValueError(
            f"q_guess has shape {q_guess.shape}; this mechanism has "
            f"{mechanism.n_coordinates} coordinates (3 per body)"
        )
    v_guess = jnp.zeros_like(q_guess) if v_guess is None else jnp.asarray(v_guess, dtype=float)
    return q_guess, v_guess


def _check_assembled(mechanism: Mechanism, q, t, res, it, tol) -> None:
    """`AssemblyError` when the Gauss–Newton residual `res` is not within the tolerance."""
    if not np.isfinite(float(res)) or float(res) > 1e3 * tol:
        raise AssemblyError(
            f"could not assemble the initial pose: constraint residual {float(res):.3g} "
            f"after {int(it)} Gauss–Newton iterations (tolerance {tol:g}); "
            f"{_worst_element(mechanism, q, t)}. The guess is too far from a feasible "
            "pose or the geometry cannot close."
        )
