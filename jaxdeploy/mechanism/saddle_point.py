"""Linear systems with a diagonal mass matrix and constraint rows (saddle-point systems).

The index-1 equations of motion and the projection onto the constraint manifold both solve

    [[M, Jᵀ], [J, 0]] [x; λ] = [f; g]                                               (1)

with `M` diagonal and positive (masses and inertias, `Mechanism.mass_diagonal`) and `J` the
m × n constraint Jacobian of full row rank. Two ways, same solution in exact arithmetic:

* **Range space** (`range_space_solution`): eliminating `x = M⁻¹ (f − Jᵀ λ)` leaves

      S λ = J M⁻¹ f − g,      S = J M⁻¹ Jᵀ   (m × m, symmetric positive definite)      (2)

  (the Schur-complement or range-space method: Nocedal & Wright, *Numerical Optimization*,
  2nd ed., 2006, §16.2), factorised by Cholesky. `S` is m × m instead of (n + m)², needs no
  pivoting, and the elimination with a diagonal `M` is an elementwise scaling. On XLA's CPU
  backend, where a mechanism's step is many small operations, the batched LU of (1) gains
  less from vectorisation than these elementwise operations and one small Cholesky, itself
  written as array operations up to m = `UNROLLED_MAX_SIZE` (`unrolled_cholesky`; `make
  bench` measures the step's linear-algebra ceiling: docs/performance.md).
  Conditioning: κ(S) ≤ κ(J)² · max(M)/min(M).
* **LU of (1)** (`kkt_lu_solution`, partial pivoting). A coordinate that the constraints
  alone fix (a slider's lateral position) gets its acceleration from its constraint row, so
  it comes out exactly as that row says (0), where the range space gets it as the difference
  `f_i − (Jᵀλ)_i` of two large numbers: round-off of ~1e-16 |f|. Implicit Runge–Kutta
  stages need this: their Newton iteration (optimistix `Chord`) tests convergence on the
  stage derivatives with the state's `atol`, and on slider_crank (atol 1e-12, forces ~1e5 N)
  that round-off alone kept Kvaerno5's iteration from converging at the first impact.

A rank-deficient `J` (redundant constraints, a singular pose) makes both singular: the
results then hold NaN or inf, which the integrators report as a failed step.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl

UNROLLED_MAX_SIZE = 8
"""Largest Schur complement (m × m) factorised by `unrolled_cholesky` rather than LAPACK's
`potrf` (`jax.scipy.linalg.cho_factor`); chosen at trace time from the static size. 8 keeps
slider_crank (m = 7) unrolled, where a 256-case vmap gains from it, and gives deploy_array
(m = 16) LAPACK's: unrolled, its simulate program grew from 16 932 to 44 413 XLA operations
and its XLA compile from 10.5 to 16.3 CPU-s (one core, measured by switching this constant),
a cost every cold `jaxdeploy simulate` pays while only a vmap gains. Read when
a program is traced: programs already traced (jit's caches, the mechanism's `traced_once`
functions) keep the factor they were traced with until `jax.clear_caches()`."""


def unrolled_cholesky(a):
    """Lower Cholesky factor `L` (`L Lᵀ = a`) of a symmetric positive definite m × m matrix
    (static m; leading axes are batch axes), by the outer-product (right-looking) form of
    the algorithm (Golub & Van Loan, *Matrix Computations*, 4th ed., 2013, §4.2) written as
    m steps of array operations:

        l_k = a⁽ᵏ⁾[k:, k] / √a⁽ᵏ⁾[k, k],
        a⁽ᵏ⁺¹⁾[k+1:, k+1:] = a⁽ᵏ⁾[k+1:, k+1:] − l_k[1:] l_k[1:]ᵀ

    Every ordering of Cholesky's operations (this one, LAPACK's dot-product `potf2`) has the
    same backward error bound, `L Lᵀ = a + E`, `|E| ≤ γ_{m+1} |L| |Lᵀ|` (Higham, *Accuracy
    and Stability of Numerical Algorithms*, 2nd ed., 2002, ch. 10); tests/test_saddle_point.py
    checks it and the solve's backward error at condition numbers up to 1e14.

    Why written out. XLA's CPU backend runs `cholesky` and `triangular_solve` as LAPACK
    calls, one per matrix: under `vmap` a batch of 7 × 7 Schur complements is a loop of tiny
    `potrf`/`trsm` calls plus the transposes into and out of their column-major layout. Here
    each of the m steps is one elementwise operation over the whole batch, which XLA fuses and
    vectorises across cases. Measured (slider_crank, 4 ms, Tsit5, CPU time on one pinned core,
    load 8, A/B alternated): a 256-case vmap 0.0168 and 0.0192 s per simulation with LAPACK's
    factor, 0.0140 s with this one; one at a time 0.0168–0.0184 s either way (within the
    noise); the bench's step ceiling: `benchmarks/targets.py`, `step_solves_ceiling`.
    Plain `jax.numpy`: differentiable in both modes. Not positive definite (a rank-deficient
    J): NaN, as LAPACK's factor gives.
    """
    m = a.shape[-1]
    columns = []
    for k in range(m):
        pivot = jnp.sqrt(a[..., 0, 0])
        column = a[..., :, 0] / pivot[..., None]
        columns.append(jnp.concatenate([jnp.zeros((*a.shape[:-2], k), a.dtype), column], -1))
        tail = column[..., 1:]
        a = a[..., 1:, 1:] - tail[..., :, None] * tail[..., None, :]
    return jnp.stack(columns, axis=-1)


def unrolled_cholesky_solve(factor, rhs):
    """`(L Lᵀ)⁻¹ rhs` for `L = unrolled_cholesky(a)` and a vector `rhs` (leading axes batch):
    forward substitution `L y = rhs` column by column, then back substitution `Lᵀ x = y`, each
    m steps of array operations over the batch (`unrolled_cholesky`: why)."""
    m = factor.shape[-1]
    y = []
    b = rhs
    for k in range(m):
        y_k = b[..., 0] / factor[..., k, k]
        y.append(y_k)
        b = b[..., 1:] - factor[..., k + 1 :, k] * y_k[..., None]
    x = [None] * m
    for k in reversed(range(m)):
        dot = sum((factor[..., i, k] * x[i] for i in range(k + 1, m)), jnp.zeros_like(y[k]))
        x[k] = (y[k] - dot) / factor[..., k, k]
    return jnp.stack(x, axis=-1)


def schur_factor(mass_inverse, jacobian):
    """Cholesky factor of `S = J M⁻¹ Jᵀ` (eq. 2), for `schur_solve`: `unrolled_cholesky` for
    m ≤ `UNROLLED_MAX_SIZE`, LAPACK's (`jax.scipy.linalg.cho_factor`) above."""
    schur = (jacobian * mass_inverse) @ jacobian.T
    if schur.shape[-1] <= UNROLLED_MAX_SIZE:
        return unrolled_cholesky(schur)
    return jsl.cho_factor(schur, lower=True)


def schur_solve(factor, rhs):
    """`S⁻¹ rhs` with the factor from `schur_factor`."""
    if isinstance(factor, tuple):
        return jsl.cho_solve(factor, rhs)
    return unrolled_cholesky_solve(factor, rhs)


def schur_system_solve(mass_inverse, jacobian, rhs):
    """`S⁻¹ rhs` with `S = J M⁻¹ Jᵀ` (eq. 2), factorised by `schur_factor`, and differentiated
    implicitly: the tangent of `λ = S⁻¹ r` is

        λ̇ = S⁻¹ (ṙ − Ṡ λ),    Ṡ λ = J̇ M⁻¹ Jᵀ λ + J (M⁻¹)˙ Jᵀ λ + J M⁻¹ J̇ᵀ λ           (3)

    (differentiate `S λ = r`), one more solve with the same factor per direction
    (`jax.lax.custom_linear_solve`, `symmetric=True`: reverse mode solves with `S` again).
    Differentiating the factorisation instead costs, per direction, the tangent of the
    Cholesky factor `L̇ = L Φ(L⁻¹ Ṡ L⁻ᵀ)`: two triangular solves with m × m right-hand sides
    (Murray, "Differentiation of the Cholesky decomposition", arXiv:1602.07527, 2016, eq.
    (9)), or, unrolled (`unrolled_cholesky`), the tangent of every one of its operations.
    The values are those of `schur_solve(schur_factor(...), rhs)`: the primal computation is
    that one (the factor is built from the primal `M⁻¹` and `J`, whose tangents enter through
    `Ṡ λ` alone)."""
    factor = schur_factor(jax.lax.stop_gradient(mass_inverse), jax.lax.stop_gradient(jacobian))

    def schur_times(lam):
        return jacobian @ (mass_inverse * (jacobian.T @ lam))

    return jax.lax.custom_linear_solve(
        schur_times, rhs, lambda _, b: schur_solve(factor, b), symmetric=True
    )


def range_space_solution(mass_inverse, jacobian, forces, rhs):
    """`(x, λ)` solving eq. (1) with `f = forces`, `g = rhs` by eq. (2): e.g. `(q̈, λ)` of
    `M q̈ + Jᵀ λ = Q`, `J q̈ = γ`. Differentiated implicitly (`schur_system_solve`)."""
    lam = schur_system_solve(mass_inverse, jacobian, jacobian @ (mass_inverse * forces) - rhs)
    return mass_inverse * (forces - jacobian.T @ lam), lam


def kkt_lu_solution(mass_inverse, jacobian, forces, rhs):
    """`(x, λ)` solving eq. (1) by an LU factorisation of the whole (n + m)² matrix."""
    n, m = jacobian.shape[1], jacobian.shape[0]
    zeros = jnp.zeros((m, m), dtype=jacobian.dtype)
    kkt = jnp.block([[jnp.diag(1.0 / mass_inverse), jacobian.T], [jacobian, zeros]])
    solution = jnp.linalg.solve(kkt, jnp.concatenate([forces, rhs]))
    return solution[:n], solution[n:]


SOLUTIONS = {"range_space": range_space_solution, "kkt_lu": kkt_lu_solution}


def least_change_correction(mass_inverse, jacobian, residual):
    """The mass-weighted smallest `Δ` with `J Δ = residual`: `Δ = M⁻¹ Jᵀ S⁻¹ residual`
    (eq. 1 with `f = 0`, `g = −residual`, up to sign). Subtracting it from a state whose
    constraint residual is `residual` removes that residual to first order."""
    lam = schur_system_solve(mass_inverse, jacobian, residual)
    return mass_inverse * (jacobian.T @ lam)
