"""Generalized-α for index-3 multibody DAEs, as a diffrax solver.

Chung & Hulbert (1993) parameters from the spectral radius at infinity ρ∞, in the
Arnold–Brüls convention, which weights the **old** level (Arnold & Brüls, *Multibody Syst.
Dyn.* 18 (2007) 185):

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
Bauchau & Cardona, *SIAM J. Sci. Comput.* 29 (2007) 397, recalled, unverified). The iteration
matrix comes from JAX forward-mode derivatives, compressed along the mechanism's sparsity
(`StepSystem`); by default it is factorised once and reused across iterations and steps until
convergence slows (modified Newton, see `GeneralizedAlpha`). The
converged solve is differentiated by the implicit-function theorem (`lax.custom_root`) with the
exact Jacobian, never by unrolling the iterations.

Local error estimate, positions and velocities (`local_error_estimate`): the leading Taylor
terms of one step, `e_q = C_q h³ q⃛`, `e_v = C_v h³ q⁗` (`error_constants`; C_q generalises
Zienkiewicz & Xie's (1991) Newmark constant to α_m ≠ α_f), with q⃛ and q⁗ from divided
differences of the index-1 accelerations at the last three step ends.

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

from .._tracing import traced_once
from ..mechanism.saddle_point import least_change_correction
from ..mechanism.sparsity import compressed_jacobian
from .term import MechanismState, MechanismTerm, accelerations_at, mechanism_of


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
    """Solver state carried between steps: the algorithmic acceleration `a_n`, counters,
    (modified Newton) the factorisation of the last iteration matrix (`_factor`) with a flag
    saying whether it has been formed yet, and the previous step's accelerations,
    multipliers and length (`qdd_prev`, `lam_prev`, `step_prev`; 0 before the first step),
    from which Newton's initial guess is extrapolated, and the index-1 accelerations at the
    start of this step and of the previous one (`accel_now`, `accel_prev`), from which the
    local error is estimated (`local_error_estimate`).

    Build it with `GeneralizedAlphaState.of`; the vectors and scalars other than `a` and the
    factorisation are stored packed in one float vector (`history`) and read through the
    properties of the same names: XLA's CPU backend updates (and, for a rejected step,
    selects) each array of diffrax's loop state with its own kernel, so eleven arrays cost
    about eleven kernels per step where four cost four."""

    a: jax.Array
    history: jax.Array
    iteration_factors: jax.Array
    iteration_permutation: jax.Array

    @classmethod
    def of(
        cls,
        *,
        a,
        newton_iterations,
        jacobian_evaluations,
        iteration_factors,
        iteration_permutation,
        iteration_factors_valid,
        qdd_prev,
        lam_prev,
        step_prev,
        accel_now,
        accel_prev,
    ):
        dtype = a.dtype
        scalars = [step_prev, newton_iterations, jacobian_evaluations, iteration_factors_valid]
        history = jnp.concatenate(
            [qdd_prev, accel_now, accel_prev, lam_prev]
            + [jnp.reshape(jnp.asarray(x, dtype=dtype), (1,)) for x in scalars]
        )
        return cls(a, history, iteration_factors, iteration_permutation)

    def _part(self, k, length=None):
        """Part k of `history`: the vectors qdd_prev, accel_now, accel_prev (n each), lam_prev
        (m), then the scalars."""
        n = self.a.shape[-1]
        m = self.iteration_factors.shape[-1] - n
        start = n * min(k, 3) + m * (k > 3) + max(k - 4, 0)
        if length is None:
            return self.history[..., start]
        return self.history[..., start : start + length]

    @property
    def qdd_prev(self):
        return self._part(0, self.a.shape[-1])

    @property
    def accel_now(self):
        return self._part(1, self.a.shape[-1])

    @property
    def accel_prev(self):
        return self._part(2, self.a.shape[-1])

    @property
    def lam_prev(self):
        return self._part(3, self.iteration_factors.shape[-1] - self.a.shape[-1])

    @property
    def step_prev(self):
        return self._part(4)

    @property
    def newton_iterations(self):
        return self._part(5).astype(int)

    @property
    def jacobian_evaluations(self):
        return self._part(6).astype(int)

    @property
    def iteration_factors_valid(self):
        return self._part(7) != 0.0


def error_constants(cf: AlphaCoefficients) -> tuple[float, float]:
    """Leading local-error constants `(C_q, C_v)` of generalized-α: one step from an exact
    state leaves `q₁ − q(t₁) = C_q h³ q⃛ + O(h⁴)` and `q̇₁ − q̇(t₁) = C_v h³ q⁗ + O(h⁴)`.

    Taylor expansion of the scheme in the module docstring. On a smooth solution the
    algorithmic acceleration lags the true one by Δ = α_m − α_f steps,
    `a_n = q̈_n + Δ h q⃛_n + D h² q⁗_n + O(h³)` with `D = Δ (2α_m − 1)/2` (substitute into
    `(1 − α_m) a_{n+1} + α_m a_n = (1 − α_f) q̈_{n+1} + α_f q̈_n` and match powers of h).
    Putting a_n, a_{n+1} into the position and velocity updates and subtracting the exact
    Taylor series, with γ = ½ − Δ (second order):

        C_q = β + Δ/2 − 1/6,        C_v = D + γ (½ + Δ) − 1/6 = D − Δ² + 1/12.

    For Newmark's average acceleration (ρ∞ = 1: Δ = 0, β = ¼) these are 1/12 and 1/12, the
    trapezoidal rule's constants; C_q = β − 1/6 for any Newmark scheme (Δ = 0) is Zienkiewicz
    & Xie's (1991) constant. `tests/test_generalized_alpha.py` checks both against the exact
    one-step error of an oscillator.
    """
    delta = cf.alpha_m - cf.alpha_f
    lag2 = delta * (2.0 * cf.alpha_m - 1.0) / 2.0
    return cf.beta + delta / 2.0 - 1.0 / 6.0, lag2 - delta**2 + 1.0 / 12.0


def local_error_estimate(cf, h, h_prev, qdd_prev, qdd0, qdd1, history):
    """Estimates `(e_q, e_v)` of the local position and velocity errors of a step of length
    `h` from t₀ to t₁ (`error_constants`), from the accelerations q̈ at t₋₁ = t₀ − h_prev,
    t₀ and t₁:

        e_q = C_q h² (q̈₁ − q̈₀)                          ≈ C_q h³ q⃛
        e_v = C_v h³ · 2 [(q̈₁ − q̈₀)/h − (q̈₀ − q̈₋₁)/h_prev] / (h + h_prev)   ≈ C_v h³ q⁗

    (divided differences; exact for cubic q̈ on any step ratio). The position estimate alone
    (Zienkiewicz–Xie) lets a step straddle most of a contact: the impact's velocity change
    is then integrated coarsely while q stays within tolerance, and the error shows up later
    as a wrong rebound (deploy_array: 0.4 c in eccentricity at rtol 1e-7). Without a
    previous step (`history` false: the first step, or after a declared jump) q⁗ is not
    available and `e_v = C_v h (q̈₁ − q̈₀)` stands in: one order larger, so the step after a
    restart starts small, as an error estimate of a restart should (PETSc's TSALPHA2 restarts
    with a lower-order estimate for the same reason).
    """
    c_q, c_v = error_constants(cf)
    e_q = c_q * h**2 * (qdd1 - qdd0)
    safe_prev = jnp.where(history, h_prev, 1.0)
    fourth = 2.0 * ((qdd1 - qdd0) / h - (qdd0 - qdd_prev) / safe_prev) / (h + safe_prev)
    e_v = jnp.where(history, c_v * h**3 * fourth, c_v * h * (qdd1 - qdd0))
    return e_q, e_v


def _flat_solve(g, y):
    """Solve the linear system `g(x) = y` by materialising g's matrix (small systems)."""
    flat, unravel = jax.flatten_util.ravel_pytree(y)
    matrix = jax.jacfwd(lambda x: jax.flatten_util.ravel_pytree(g(unravel(x)))[0])(flat)
    return unravel(jnp.linalg.solve(matrix, flat))


# Up to this size the iteration matrix is stored as its explicit inverse (one matrix–vector
# product per Newton iteration); above it as LU factors (two triangular solves per iteration).
# Measured on this CPU (XLA, LAPACK): for 18 × 18 the inverse costs ~10 µs once and 0.3 µs per
# product against ~1.6 µs per pair of triangular solves; for 37 × 37 an explicit inverse costs
# over 1 ms (XLA's triangular solve with many right-hand sides), LU ~9 µs and a solve ~3 µs.
_INVERSE_MAX_SIZE = 24


def _factor(matrix):
    """`(factors, permutation)` of the iteration matrix for `_apply_factor`."""
    size = matrix.shape[0]
    if size <= _INVERSE_MAX_SIZE:
        return jnp.linalg.inv(matrix), jnp.arange(size, dtype=jnp.int32)
    lu, _, permutation = jax.lax.linalg.lu(matrix)
    return lu, permutation.astype(jnp.int32)


def _apply_factor(factors, permutation, rhs):
    """`A⁻¹ rhs` from `_factor(A)`."""
    if factors.shape[0] <= _INVERSE_MAX_SIZE:
        return factors @ rhs
    y = jax.lax.linalg.triangular_solve(
        factors, rhs[permutation][:, None], left_side=True, lower=True, unit_diagonal=True
    )
    return jax.lax.linalg.triangular_solve(factors, y, left_side=True, lower=False)[:, 0]


# Slots of the Newton loop's packed scalars (`GeneralizedAlpha.step`).
_IT, _SINCE, _NORM, _CONVERGED, _REFRESH, _OK, _EVALUATIONS = range(7)
_N_SCALARS = 7


def _run_if(pred, fn, operand):
    """`fn(operand)` where `pred`, else `operand`, evaluating `fn` only when needed.

    A `while_loop` that runs at most once rather than a `lax.cond`: under `vmap` a `cond` with a
    batched predicate becomes a `select` that evaluates `fn` for every case at every call,
    whereas a batched `while_loop` runs its body only while *some* case needs it (and keeps
    the others' values). Not differentiable: used only inside the Newton solve, whose
    derivative comes from the implicit-function theorem.
    """

    def body(carry):
        _, x = carry
        return jnp.zeros_like(pred), fn(x)

    return jax.lax.while_loop(lambda carry: carry[0], body, (pred, operand))[1]


class StepSystem(NamedTuple):
    """The nonlinear system of one step, in the correction `u` and scaled multipliers `μ`:

        r(u, μ) = [ M u + Φ_q(q)ᵀ μ − Q(q, q̂̇ + γ' u, t)/β' ;  Φ(q, t) ],   q = q̂ + u

    (module docstring), and its iteration matrix ∂r/∂(u, μ)."""

    mechanism: object
    q_hat: jax.Array
    v_hat: jax.Array
    gamma_p: jax.Array
    beta_p: jax.Array
    t: jax.Array
    memory: object

    def _constraint_terms(self, u, mu):
        """`[Φ_q(q)ᵀ μ; Φ(q)]` at `q = q̂ + u`."""
        mech, q = self.mechanism, self.q_hat + u
        if not mech.n_constraints:
            return jnp.zeros_like(u)
        return jnp.concatenate(
            [mech.constraint_jacobian_transpose_product(q, self.t, mu), mech.constraints(q, self.t)]
        )

    def _scaled_forces(self, u):
        """`Q(q̂ + u, q̂̇ + γ' u, t)/β'`."""
        q, v = self.q_hat + u, self.v_hat + self.gamma_p * u
        return self.mechanism.generalized_forces(q, v, self.t, self.memory) / self.beta_p

    @traced_once
    def residual(self, z):
        u, mu = z
        mech = self.mechanism
        dynamic = mech.mass_diagonal() * u - self._scaled_forces(u)
        if mech.n_constraints:
            dynamic = dynamic + mech.constraint_jacobian_transpose_product(
                self.q_hat + u, self.t, mu
            )
        return dynamic, mech.constraints(self.q_hat + u, self.t)

    @traced_once
    def iteration_matrix(self, x):
        """∂r/∂(u, μ) at the flat iterate `x = (u, μ)`:

            [[M + (Φ_qᵀ μ)_q − Q_u/β',  Φ_qᵀ], [Φ_q, 0]],   Q_u = K + γ' C

        The u columns come from compressed forward-mode derivatives
        (`jaxdeploy.mechanism.sparsity`) along the mechanism's static sparsity
        (`Mechanism.jacobian_patterns`), separately for the constraint terms (kinematics only)
        and the forces (where the contact laws are, and only the bodies of force elements
        need a direction); the μ columns are [Φ_qᵀ; 0], read off the constraint rows (r is
        linear in μ). Equal to the dense Jacobian of `residual` (tested)."""
        mech = self.mechanism
        n = self.q_hat.shape[0]
        u, mu = x[:n], x[n:]
        constraint_pattern, force_pattern = mech.jacobian_patterns()
        forces_u = compressed_jacobian(self._scaled_forces, u, force_pattern)
        dynamic_u = jnp.diag(mech.mass_diagonal()) - forces_u
        if not mech.n_constraints:
            return dynamic_u
        terms_u = compressed_jacobian(
            lambda w: self._constraint_terms(w, mu), u, constraint_pattern
        )
        phi_q = terms_u[n:]
        m = phi_q.shape[0]
        return jnp.concatenate(
            [
                jnp.concatenate([dynamic_u + terms_u[:n], phi_q.T], axis=1),
                jnp.concatenate([phi_q, jnp.zeros((m, m), dtype=x.dtype)], axis=1),
            ]
        )


class GeneralizedAlphaInterpolation(dfx.AbstractLocalInterpolation):
    """Dense output of a generalized-α step: positions and velocities by the cubic Hermite
    interpolant of the step's ends (slopes q̇ and q̈ there), memory linear, and the
    accelerations and multipliers evaluated from the interpolated state with the step's
    memory (`accelerations_at`: index-1, so they satisfy the acceleration constraint, which
    the step's own q̈ = β' u does not, and carry none of its Newton error amplified by β'
    ~ 1/h²). At a saved step end they therefore differ from the solver's q̈ by that error."""

    t0: float
    t1: float
    hermite: dfx.ThirdOrderHermitePolynomialInterpolation
    mechanism: object
    memory: tuple

    def __init__(self, *, t0, t1, y0, y1, k0, k1, mechanism, memory):
        self.t0, self.t1 = t0, t1
        self.hermite = dfx.ThirdOrderHermitePolynomialInterpolation(
            t0=t0, t1=t1, y0=y0, y1=y1, k0=k0, k1=k1
        )
        self.mechanism, self.memory = mechanism, memory

    def evaluate(self, t0, t1=None, left=True):
        if t1 is not None:
            return jax.tree.map(lambda b, a: b - a, self.evaluate(t1), self.evaluate(t0))
        y = self.hermite.evaluate(t0)
        qdd, lam = accelerations_at(self.mechanism, y.q, y.v, t0, self.memory)
        return MechanismState(y.q, y.v, qdd, lam, y.memory)

    def motion(self, t):
        """`(q, q̇, memory)` at `t`, as `evaluate` gives them, without the acceleration
        solve (what `TrackExtremes` samples)."""
        y = self.hermite.evaluate(t)
        return y.q, y.v, y.memory

    def acceleration_inputs(self, t):
        """`(q, q̇, memory, step_memory)` at `t`: `motion` and the memory `evaluate` solves
        q̈ and λ with (the step's), for a caller that solves them later."""
        y = self.hermite.evaluate(t)
        return y.q, y.v, y.memory, self.memory


class GeneralizedAlpha(dfx.AbstractAdaptiveSolver):
    """Index-3 generalized-α (Arnold & Brüls 2007) for a `MechanismTerm`.

    **Arguments:**
    - `rho_inf`: spectral radius at infinity ρ∞ ∈ [0, 1]; < 1 damps the parasitic index-3
      modes (Arnold & Brüls 2007; docs/verification.md, λ start-up transient). Default 0.8.
    - `newton_atol`, `newton_rtol`: a Newton iteration has converged when every position
      correction `|Δu_i| ≤ atol + rtol |q_i|` [m or rad] (the scaled multipliers likewise, in
      units of the mean mass times that bound).
    - `newton_max_iterations`: iterations before the step is declared failed (the step-size
      controller then rejects it; with constant steps the solve stops with
      `nonlinear_divergence` at that time).
    - `newton`: `"modified"` (default) or `"full"`. Modified Newton keeps the factorised
      iteration matrix across iterations *and steps* and forms it again (at the current
      iterate) only when the iteration converges slowly or diverges: the contraction rate
      θ = ‖Δu_k‖/‖Δu_{k−1}‖ exceeds `refresh_rate`, or `refresh_after` iterations with the
      same matrix have not converged (the simplified Newton of implicit integrators; Hairer &
      Wanner, *Solving ODEs II*, §IV.8; Exudyn's "modified Newton"). `"full"` forms it at every
      iteration (Newton's method proper; the reference the tests compare against).
    - `refresh_rate`, `refresh_after`: the refresh rule above (modified Newton only).
    - `newton_safety`: with a reused matrix convergence is linear, so a step is accepted only
      once a rate θ has been measured and the estimated remaining error `θ/(1 − θ) ‖Δ‖` is
      within `newton_safety` times the tolerance. Newton proper ends its quadratic
      convergence far below the tolerance; the default 1e-6 makes modified Newton's result
      agree with it to round-off level (with 1e-4 the per-step differences, summed over
      3500 steps of h = 1e-7, cost the fixed-step convergence test through an impact its
      second order).
    - `estimate_error`: compute the local error estimate (an index-1 acceleration solve per
      step). `simulate` turns it off for fixed steps, where nothing reads it.
    - `project_velocities`: after each step, replace q̇_{n+1} by its mass-weighted projection onto
      the velocity constraints `Φ_q q̇ + Φ_t = 0`. `None` (default): with the error estimate
      (adaptive steps; `simulate` turns it off for fixed steps), i.e. where the step size reacts to
      the velocities' noise; `False` is the plain index-3 scheme of Arnold & Brüls 2007 at every
      step, and what fixed-step runs integrate by default (their step ends' q̈ = β' u then stay
      close to the index-1 accelerations of the saved state, which the projected velocities move by
      the O(h²) velocity-constraint error). Why: the index-3 step enforces Φ(q) = 0 only, to
      round-off ε|q| (the positions cannot be represented better), and takes `q̇_{n+1} = q̂̇ + γ' u`
      with γ' = γ/(hβ) ~ 2/h, so the velocities carry a constraint violation ~ 2ε|q|/h that grows as
      the step shrinks — the ε/h round-off amplification of index-3 formulations (Hairer, Lubich &
      Roche, *The Numerical Solution of Differential-Algebraic Systems by Runge–Kutta Methods*, LNM
      1409, 1989; Hairer & Wanner, *Solving ODEs II*, §VII.3). Measured on slider_crank at rtol
      1e-10, atol 1e-13: 1e-7 m/s at h = 3e-10 s, which a contact's damping (c/m ~ 1e5 1/s) turns
      into 0.05 m/s² of step-to-step noise in the accelerations the error estimate differences; near
      the slider's dead centre (|q̇| → 0, so the velocity tolerance is atol) that noise exceeded the
      tolerance at every step size and the run stalled at t = 12.02 ms. The projection (one linear
      solve with the step's own Φ_q) removes the violation to round-off of q̇, and with it the O(h²)
      drift of the hidden constraint; the positions, the algorithmic acceleration and the
      multipliers are unchanged, so the scheme keeps its order (tested). On the Andrews squeezer at
      rtol 1e-10 with ρ∞ = 1 the plain scheme stalled at t = 0.0286 s (400k steps); projected it
      needs 28.7k steps. This is the velocity stage of the projections of Bayo & Ledesma (*Nonlinear
      Dyn.* 9 (1996) 113) applied after the index-3 solve.

    The iteration matrix `[[M + (K + γ' C)/β' + (Φ_qᵀ μ)_q, Φ_qᵀ], [Φ_q, 0]]` is formed by
    `StepSystem.iteration_matrix`: compressed forward-mode derivatives of the constraint terms
    and of the forces along the mechanism's static sparsity; the μ columns `[Φ_qᵀ; 0]` are
    read off the constraint rows. Whichever `newton` is used, the
    converged solve is differentiated by the implicit-function theorem with the exact
    Jacobian (`lax.custom_root`), so derivatives do not depend on the iteration.

    Works with `diffrax.ConstantStepSize` (fixed step) and `diffrax.PIDController` (adaptive,
    on the position and velocity error estimate of `local_error_estimate`).
    """

    rho_inf: float = eqx.field(static=True, default=0.8)
    newton_atol: float = eqx.field(static=True, default=1e-12)
    newton_rtol: float = eqx.field(static=True, default=1e-10)
    newton_max_iterations: int = eqx.field(static=True, default=12)
    newton: str = eqx.field(static=True, default="modified")
    refresh_rate: float = eqx.field(static=True, default=0.2)
    refresh_after: int = eqx.field(static=True, default=5)
    newton_safety: float = eqx.field(static=True, default=1e-6)
    estimate_error: bool = eqx.field(static=True, default=True)
    project_velocities: bool | None = eqx.field(static=True, default=None)

    term_structure: ClassVar = MechanismTerm
    interpolation_cls: ClassVar = GeneralizedAlphaInterpolation

    def __check_init__(self):
        if self.newton not in ("modified", "full"):
            raise ValueError(f"newton = {self.newton!r} is invalid: use 'modified' or 'full'")
        if not 0.0 < self.refresh_rate < 1.0:
            raise ValueError(
                f"refresh_rate = {self.refresh_rate!r} is invalid: it must be in (0, 1)"
            )
        if self.refresh_after < 1:
            raise ValueError(f"refresh_after = {self.refresh_after!r} is invalid: it must be ≥ 1")
        if self.newton_max_iterations < 1:
            raise ValueError(
                f"newton_max_iterations = {self.newton_max_iterations!r} is invalid: it must be ≥ 1"
            )

    def order(self, terms):
        return 2

    def error_order(self, terms):
        # Both estimates are O(h³) locally.
        return 3

    def init(self, terms, t0, t1, y0: MechanismState, args):
        if mechanism_of(terms).has_internal_state:
            # Its second-order scheme has no stage for a first-order state ż = f(q, q̇, z).
            raise ValueError(
                "solver='generalized_alpha' cannot integrate elements with continuous internal "
                "states (e.g. LuGre friction's bristle deflection); use an index-1 solver, "
                "e.g. solver='tsit5' or solver='kvaerno5'"
            )
        size = y0.q.shape[0] + y0.lam.shape[0]
        return GeneralizedAlphaState.of(
            a=y0.qdd,
            newton_iterations=jnp.array(0),
            jacobian_evaluations=jnp.array(0),
            iteration_factors=jnp.zeros((size, size), dtype=y0.q.dtype),
            iteration_permutation=jnp.arange(size, dtype=jnp.int32),
            iteration_factors_valid=jnp.array(False),
            qdd_prev=y0.qdd,
            lam_prev=y0.lam,
            step_prev=jnp.zeros((), dtype=y0.q.dtype),
            accel_now=y0.qdd,
            accel_prev=y0.qdd,
        )

    def func(self, terms, t0, y0, args):
        return terms.vf(t0, y0, args)

    def step(self, terms, t0, t1, y0: MechanismState, args, solver_state, made_jump):
        mech = mechanism_of(terms)
        cf = chung_hulbert(self.rho_inf)
        h = t1 - t0
        q0, v0, qdd0 = y0.q, y0.v, y0.qdd
        n = q0.shape[0]
        # After a declared discontinuity the algorithmic acceleration restarts from q̈.
        a0 = jnp.where(made_jump, qdd0, solver_state.a)
        memory = mech.memory_for_step(y0.memory, q0, v0)

        a_pred = (cf.alpha_f * qdd0 - cf.alpha_m * a0) / (1.0 - cf.alpha_m)
        q_hat = q0 + h * v0 + h**2 * (0.5 - cf.beta) * a0 + h**2 * cf.beta * a_pred
        v_hat = v0 + h * (1.0 - cf.gamma) * a0 + h * cf.gamma * a_pred
        beta_p = (1.0 - cf.alpha_m) / (h**2 * cf.beta * (1.0 - cf.alpha_f))
        gamma_p = cf.gamma / (h * cf.beta)
        mass_unit = jnp.mean(mech.mass_diagonal())

        step_system = StepSystem(mech, q_hat, v_hat, gamma_p, beta_p, t1, memory)
        residual = step_system.residual
        iteration_matrix = step_system.iteration_matrix

        full = self.newton == "full"
        factors_prev = jax.lax.stop_gradient(
            (solver_state.iteration_factors, solver_state.iteration_permutation)
        )
        valid_prev = solver_state.iteration_factors_valid

        def newton(f, z0):
            x0, unravel = jax.flatten_util.ravel_pytree(z0)

            def f_flat(x):
                return jax.flatten_util.ravel_pytree(f(unravel(x)))[0]

            # The loop's scalars travel packed in one float vector (`_IT`, `_SINCE`, …): XLA's
            # CPU backend runs each loop-carried array as its own kernel and copy, so seven
            # scalars cost seven kernels per iteration where one vector costs one.
            def cond(c):
                s = c[2]
                return (
                    (s[_CONVERGED] == 0.0) & (s[_OK] != 0.0) & (s[_IT] < self.newton_max_iterations)
                )

            def body(c):
                x, factors, s = c
                fresh = s[_REFRESH] != 0.0  # the matrix is formed at this very iterate
                factors = _run_if(fresh, lambda _: _factor(iteration_matrix(x)), factors)
                since = jnp.where(fresh, 0.0, s[_SINCE])
                dx = _apply_factor(*factors, f_flat(x))
                x1 = x - dx
                # Relative to the larger of predictor and iterate: when the correction cancels
                # the predictor (large h ω), roundoff in u is ε|q̂|, not ε|q|.
                magnitude = jnp.maximum(jnp.abs(q_hat), jnp.abs(q_hat + x1[:n]))
                # The scaled multipliers μ = λ/β' (units of M u) are measured in the same
                # tolerance, converted by the mean mass: with a reused matrix the positions can
                # look converged while μ (the reactions) is not, and an unconverged μ leaves
                # the dynamic equations unsatisfied.
                scale = jnp.concatenate(
                    [
                        self.newton_atol + self.newton_rtol * magnitude,
                        mass_unit * self.newton_atol
                        + self.newton_rtol * jnp.maximum(jnp.abs(x[n:]), jnp.abs(x1[n:])),
                    ]
                )
                norm = jnp.max(jnp.abs(dx) / scale, initial=0.0)
                finite = jnp.all(jnp.isfinite(dx))
                # Contraction rate, measured once the same matrix has served two iterations.
                theta = jnp.where(since > 0, norm / s[_NORM], 0.0)
                eta = theta / (1.0 - theta)
                # Newton proper (fresh matrix) converges quadratically: a correction within
                # tolerance leaves an error far below it. With a reused matrix the remaining
                # error is about θ/(1 − θ) times the correction, so a rate must have been
                # measured (two iterations with that matrix) before accepting.
                converged = finite & jnp.where(
                    fresh,
                    norm <= 1.0,
                    (since > 0)
                    & (theta < 1.0)
                    & (norm <= 1.0)
                    & (eta * norm <= self.newton_safety),
                )
                # A stale matrix that diverges has its correction rejected; Newton proper
                # (fresh matrix) keeps its step, as Newton's method does.
                keep = finite & ((theta < 1.0) | fresh)
                refresh = ~converged & (
                    full | ~finite | (theta > self.refresh_rate) | (since + 1 >= self.refresh_after)
                )
                packed = [None] * _N_SCALARS
                packed[_IT] = s[_IT] + 1.0
                packed[_SINCE] = since + 1.0
                packed[_NORM] = norm
                packed[_CONVERGED] = converged
                packed[_REFRESH] = refresh
                packed[_OK] = finite | ~fresh
                packed[_EVALUATIONS] = s[_EVALUATIONS] + fresh
                packed = jnp.stack([jnp.asarray(v, dtype=x0.dtype) for v in packed])
                return jnp.where(keep, x1, x), factors, packed

            scalars = [0.0] * _N_SCALARS
            scalars[_NORM] = jnp.inf
            scalars[_REFRESH] = jnp.asarray(full) | ~valid_prev
            scalars[_OK] = 1.0
            init = (
                x0,
                factors_prev,
                jnp.stack([jnp.asarray(v, dtype=x0.dtype) for v in scalars]),
            )
            x_end, factors_end, s = jax.lax.while_loop(cond, body, init)
            c = dict(
                x=x_end,
                factors=factors_end,
                it=s[_IT].astype(int),
                converged=s[_CONVERGED] != 0.0,
                ok=s[_OK] != 0.0,
                evaluations=s[_EVALUATIONS].astype(int),
            )
            # Auxiliary outputs as floats: custom_root's JVP rule mishandles int/bool aux.
            aux = (
                c["it"].astype(x0.dtype),
                (c["converged"] & c["ok"]).astype(x0.dtype),
                c["evaluations"].astype(x0.dtype),
                c["factors"][0],
                c["factors"][1].astype(x0.dtype),
            )
            # Newton's method proper met non-finite values (a NaN or overflowing force): the
            # step has no solution to offer, and its last finite iterate would pass for one.
            # NaN makes the failure visible to the step-size control (`simulate` stops a run
            # whose steps cannot avoid it, with the time reached).
            return unravel(jnp.where(c["ok"], c["x"], jnp.nan)), aux

        # Initial guess: q̈_{n+1} and λ_{n+1} extrapolated linearly from the last two steps
        # (u = q̈_{n+1}/β', μ = λ_{n+1}/β'); constant after a jump or before the first step.
        # Only Newton's starting point changes, not the equations it solves.
        ratio = jnp.where(
            made_jump | (solver_state.step_prev <= 0.0),
            0.0,
            jnp.minimum(
                h / jnp.where(solver_state.step_prev > 0.0, solver_state.step_prev, 1.0), 2.0
            ),
        )
        qdd_guess = qdd0 + ratio * (qdd0 - solver_state.qdd_prev)
        lam_guess = y0.lam + ratio * (y0.lam - solver_state.lam_prev)
        z0 = jax.lax.stop_gradient((qdd_guess / beta_p, lam_guess / beta_p))
        (u, mu), aux = jax.lax.custom_root(residual, z0, newton, _flat_solve, has_aux=True)
        iterations = jax.lax.stop_gradient(aux[0]).astype(int)
        converged = jax.lax.stop_gradient(aux[1]) > 0.5
        evaluations = jax.lax.stop_gradient(aux[2]).astype(int)
        factors1 = jax.lax.stop_gradient(aux[3])
        permutation1 = jax.lax.stop_gradient(aux[4]).astype(jnp.int32)
        # Any matrix that has been formed is kept, whether or not this step converged.
        valid1 = valid_prev | (evaluations > 0)

        q1 = q_hat + u
        v1 = v_hat + gamma_p * u
        project = (
            self.estimate_error if self.project_velocities is None else self.project_velocities
        )
        if project and mech.n_constraints:
            # Round-off of Φ(q₁) = 0, amplified by γ' ~ 2/h, out of q̇₁ (class docstring).
            jac = mech.constraint_jacobian(q1, t1)
            violation = jac @ v1 - mech.constraint_velocity_rhs(q1, t1)
            v1 = v1 - least_change_correction(1.0 / mech.mass_diagonal(), jac, violation)
        qdd1 = beta_p * u
        lam1 = beta_p * mu
        a1 = a_pred + (1.0 - cf.alpha_f) / (1.0 - cf.alpha_m) * qdd1
        memory1 = mech.memory_after_step(memory, q1, v1, h)
        y1 = MechanismState(q1, v1, qdd1, lam1, memory1)

        # Error estimate under stop_gradient: step-size control must not be differentiated.
        # It differences accelerations, so it takes them from the index-1 equations of motion
        # at the new state, not from the step's q̈₁ = β' u: β' ~ 1/h², so Newton's and
        # round-off's error in u (ε|q| at best) becomes ~ε|q|/h² in q̈₁, which at small steps
        # swamps the velocity estimate and drives h to zero (measured on deploy_array).
        history = (~made_jump) & (solver_state.step_prev > 0.0)
        accel0 = jnp.where(made_jump, qdd0, solver_state.accel_now)
        if self.estimate_error:
            accel1, _ = mech.accelerations(*jax.lax.stop_gradient((q1, v1, t1, memory)))
            err_q, err_v = jax.lax.stop_gradient(
                local_error_estimate(
                    cf, h, solver_state.step_prev, solver_state.accel_prev, accel0, accel1, history
                )
            )
        else:
            # Fixed steps read no error: skip the index-1 solve (it is carried in the state,
            # so the compiler could not drop it).
            accel1, err_q, err_v = accel0, jnp.zeros_like(q1), jnp.zeros_like(v1)
        err_q = jnp.where(converged, err_q, jnp.inf)
        err_v = jnp.where(converged, err_v, jnp.inf)
        y_error = MechanismState(
            q=err_q,
            v=err_v,
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
        dense_info = dict(y0=y0, y1=y1, k0=k0, k1=k1, mechanism=mech, memory=memory)
        result = dfx.RESULTS.where(
            converged, dfx.RESULTS.successful, dfx.RESULTS.nonlinear_divergence
        )
        state1 = GeneralizedAlphaState.of(
            a=a1,
            newton_iterations=solver_state.newton_iterations + iterations,
            jacobian_evaluations=solver_state.jacobian_evaluations + evaluations,
            iteration_factors=factors1,
            iteration_permutation=permutation1,
            iteration_factors_valid=valid1,
            qdd_prev=qdd0,
            lam_prev=y0.lam,
            step_prev=h,
            accel_now=accel1,
            accel_prev=accel0,
        )
        return y1, y_error, dense_info, state1, result
