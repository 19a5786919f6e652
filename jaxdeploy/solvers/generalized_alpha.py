"""Generalized-α for index-3 multibody DAEs, as a diffrax solver.

Chung & Hulbert (1993) parameters from the spectral radius at infinity ρ∞, in the
Arnold–Brüls convention, which weights the **old** level (LITERATURE §2.1–2.3):

    (1 − α_m) a_{n+1} + α_m a_n = (1 − α_f) q̈_{n+1} + α_f q̈_n
    q_{n+1} = q_n + h q̇_n + h² (½ − β) a_n + h² β a_{n+1}
    q̇_{n+1} = q̇_n + h (1 − γ) a_n + h γ a_{n+1}
    α_m = (2ρ∞ − 1)/(ρ∞ + 1),  α_f = ρ∞/(ρ∞ + 1),  γ = ½ + α_f − α_m,  β = ¼ (γ + ½)²

(PETSc's TSALPHA2 and OpenSees use the complements 1 − α.) Each step solves, at t_{n+1},

    M q̈ + Φ_qᵀ λ = Q(q, q̇, t),    Φ(q, t) = 0

by Newton's method in the correction `u = q_{n+1} − q̂` to the predicted position and the scaled
multiplier `μ = λ/β'`, `β' = (1 − α_m)/(h² β (1 − α_f))`, `γ' = γ/(h β)`:

    r(u, μ) = [ M u + Φ_q(q)ᵀ μ − Q(q, q̂̇ + γ' u, t)/β' ;  Φ(q, t) ],   q = q̂ + u,  q̈ = β' u

This is Arnold & Brüls' Algorithm 1 with both the dynamic rows divided by β' and λ rescaled, so
the iteration matrix `[[M + (K_t + γ' C_t)/β', Φ_qᵀ], [Φ_q, 0]]` stays O(1) as h → 0 (Bottasso,
Bauchau & Cardona 2007 scaling; LITERATURE §2.4). The Newton matrix comes from JAX derivatives;
the converged solve is differentiated by the implicit-function theorem (`lax.custom_root`),
never by unrolling the iterations.

Local error estimate (Zienkiewicz & Xie 1991, for Newmark-type position updates):
`e_q ≈ h² (β − 1/6)(q̈_{n+1} − q̈_n)`. It is an estimate of the position error only.

References:
- J. Chung, G. M. Hulbert, *J. Appl. Mech.* 60 (1993) 371, doi:10.1115/1.2900803.
- M. Arnold, O. Brüls, *Multibody Syst. Dyn.* 18 (2007) 185, doi:10.1007/s11044-007-9084-0.
- O. C. Zienkiewicz, Y. M. Xie, *Earthq. Eng. Struct. Dyn.* 20 (1991) 871.
"""

from __future__ import annotations

from typing import ClassVar, NamedTuple

import diffrax as dfx
import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp

from .term import MechanismState, MechanismTerm


class AlphaCoefficients(NamedTuple):
    alpha_m: float
    alpha_f: float
    gamma: float
    beta: float


def chung_hulbert(rho_inf: float) -> AlphaCoefficients:
    """Chung–Hulbert coefficients for spectral radius at infinity `rho_inf` ∈ [0, 1], in the
    Arnold–Brüls convention (old level weighted): e.g. ρ∞ = 0.8 gives α_m = 1/3, α_f = 4/9,
    γ = 11/18, β = 0.3086."""
    if not 0.0 <= rho_inf <= 1.0:
        raise ValueError(f"rho_inf = {rho_inf!r} is invalid: it must be in [0, 1]")
    alpha_m = (2.0 * rho_inf - 1.0) / (rho_inf + 1.0)
    alpha_f = rho_inf / (rho_inf + 1.0)
    gamma = 0.5 + alpha_f - alpha_m
    beta = 0.25 * (gamma + 0.5) ** 2
    return AlphaCoefficients(alpha_m, alpha_f, gamma, beta)


class GeneralizedAlphaState(NamedTuple):
    """Solver state carried between steps: the algorithmic acceleration `a_n` and counters."""

    a: jax.Array
    newton_iterations: jax.Array


def _flat_solve(g, y):
    """Solve the linear system `g(x) = y` by materialising g's matrix (small systems)."""
    flat, unravel = jax.flatten_util.ravel_pytree(y)
    matrix = jax.jacfwd(lambda x: jax.flatten_util.ravel_pytree(g(unravel(x)))[0])(flat)
    return unravel(jnp.linalg.solve(matrix, flat))


def _mechanism_of(terms):
    # diffeqsolve wraps terms (e.g. in a WrapTerm that handles the direction of time).
    while not isinstance(terms, MechanismTerm):
        terms = terms.term
    return terms.mechanism


class GeneralizedAlpha(dfx.AbstractAdaptiveSolver):
    """Index-3 generalized-α (Arnold & Brüls 2007) for a `MechanismTerm`.

    **Arguments:**
    - `rho_inf`: spectral radius at infinity ρ∞ ∈ [0, 1]; < 1 damps the parasitic index-3
      modes (LITERATURE §2.5). Default 0.8.
    - `newton_atol`, `newton_rtol`: a Newton iteration has converged when every position
      correction `|Δu_i| ≤ atol + rtol |q_i|` [m or rad].
    - `newton_max_iterations`: iterations before the step is declared failed (the step-size
      controller then rejects it; with constant steps the solve stops with
      `nonlinear_divergence` at that time).

    Works with `diffrax.ConstantStepSize` (fixed step) and `diffrax.PIDController` (adaptive,
    on the Zienkiewicz–Xie position error estimate).
    """

    rho_inf: float = eqx.field(static=True, default=0.8)
    newton_atol: float = eqx.field(static=True, default=1e-12)
    newton_rtol: float = eqx.field(static=True, default=1e-10)
    newton_max_iterations: int = eqx.field(static=True, default=12)

    term_structure: ClassVar = MechanismTerm
    interpolation_cls: ClassVar = dfx.ThirdOrderHermitePolynomialInterpolation

    def order(self, terms):
        return 2

    def error_order(self, terms):
        # The position estimate is O(h³) locally.
        return 3

    def init(self, terms, t0, t1, y0: MechanismState, args):
        return GeneralizedAlphaState(a=y0.qdd, newton_iterations=jnp.array(0))

    def func(self, terms, t0, y0, args):
        return terms.vf(t0, y0, args)

    def step(self, terms, t0, t1, y0: MechanismState, args, solver_state, made_jump):
        mech = _mechanism_of(terms)
        cf = chung_hulbert(self.rho_inf)
        h = t1 - t0
        q0, v0, qdd0 = y0.q, y0.v, y0.qdd
        # After a declared discontinuity the algorithmic acceleration restarts from q̈.
        a0 = jnp.where(made_jump, qdd0, solver_state.a)
        memory = mech.memory_for_step(y0.memory, q0, v0)

        a_pred = (cf.alpha_f * qdd0 - cf.alpha_m * a0) / (1.0 - cf.alpha_m)
        q_hat = q0 + h * v0 + h**2 * (0.5 - cf.beta) * a0 + h**2 * cf.beta * a_pred
        v_hat = v0 + h * (1.0 - cf.gamma) * a0 + h * cf.gamma * a_pred
        beta_p = (1.0 - cf.alpha_m) / (h**2 * cf.beta * (1.0 - cf.alpha_f))
        gamma_p = cf.gamma / (h * cf.beta)
        mass = mech.mass_diagonal()

        def residual(z):
            u, mu = z
            q = q_hat + u
            v = v_hat + gamma_p * u
            forces = mech.generalized_forces(q, v, t1, memory)
            dynamic = mass * u - forces / beta_p
            if mech.n_constraints:
                dynamic = dynamic + mech.constraint_jacobian(q, t1).T @ mu
            return dynamic, mech.constraints(q, t1)

        def newton(f, z0):
            def cond(carry):
                _, it, converged, ok = carry
                return (~converged) & ok & (it < self.newton_max_iterations)

            def body(carry):
                z, it, _, _ = carry
                dz = _flat_solve(lambda x: jax.jvp(f, (z,), (x,))[1], f(z))
                z = jax.tree_util.tree_map(lambda a, b: a - b, z, dz)
                du = dz[0]
                # Relative to the larger of predictor and iterate: when the correction cancels
                # the predictor (large h ω), roundoff in u is ε|q̂|, not ε|q|.
                magnitude = jnp.maximum(jnp.abs(q_hat), jnp.abs(q_hat + z[0]))
                scale = self.newton_atol + self.newton_rtol * magnitude
                converged = jnp.all(jnp.abs(du) <= scale)
                ok = jnp.all(jnp.isfinite(du))
                return z, it + 1, converged, ok

            init = (z0, jnp.array(0), jnp.array(False), jnp.array(True))
            z, it, converged, ok = jax.lax.while_loop(cond, body, init)
            # Auxiliary outputs as floats: custom_root's JVP rule mishandles int/bool aux.
            return z, (it.astype(float), (converged & ok).astype(float))

        z0 = (jnp.zeros_like(q0), y0.lam / beta_p)
        (u, mu), aux = jax.lax.custom_root(residual, z0, newton, _flat_solve, has_aux=True)
        iterations = jax.lax.stop_gradient(aux[0]).astype(int)
        converged = jax.lax.stop_gradient(aux[1]) > 0.5

        q1 = q_hat + u
        v1 = v_hat + gamma_p * u
        qdd1 = beta_p * u
        lam1 = beta_p * mu
        a1 = a_pred + (1.0 - cf.alpha_f) / (1.0 - cf.alpha_m) * qdd1
        memory1 = mech.memory_after_step(memory, q1, v1, h)
        y1 = MechanismState(q1, v1, qdd1, lam1, memory1)

        # Error estimate under stop_gradient: step-size control must not be differentiated.
        err_q = jax.lax.stop_gradient(h**2 * (cf.beta - 1.0 / 6.0) * (qdd1 - qdd0))
        err_q = jnp.where(converged, err_q, jnp.inf)
        y_error = MechanismState(
            q=err_q,
            v=jnp.zeros_like(v1),
            qdd=jnp.zeros_like(qdd1),
            lam=jnp.zeros_like(lam1),
            memory=jax.tree_util.tree_map(jnp.zeros_like, memory1),
        )

        def slopes(y):
            # Hermite data: exact derivatives for q (q̇) and q̇ (q̈); secants for the rest,
            # which makes their interpolation linear.
            return (y.v * h, y.qdd * h)

        kq0, kv0 = slopes(y0)
        kq1, kv1 = slopes(y1)
        secant = jax.tree_util.tree_map(
            lambda b, a: b - a, (qdd1, lam1, memory1), (y0.qdd, y0.lam, y0.memory)
        )
        k0 = MechanismState(kq0, kv0, *secant)
        k1 = MechanismState(kq1, kv1, *secant)
        dense_info = dict(y0=y0, y1=y1, k0=k0, k1=k1)
        result = dfx.RESULTS.where(
            converged, dfx.RESULTS.successful, dfx.RESULTS.nonlinear_divergence
        )
        state1 = GeneralizedAlphaState(
            a=a1, newton_iterations=solver_state.newton_iterations + iterations
        )
        return y1, y_error, dense_info, state1, result
