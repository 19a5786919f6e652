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
  less from vectorisation than these elementwise operations and one small Cholesky
  (`make bench` measures the step's linear-algebra ceiling: docs/performance.md).
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

import jax.numpy as jnp
import jax.scipy.linalg as jsl


def schur_factor(mass_inverse, jacobian):
    """Cholesky factor of `S = J M⁻¹ Jᵀ` (eq. 2), for `schur_solve`."""
    schur = (jacobian * mass_inverse) @ jacobian.T
    return jsl.cho_factor(schur, lower=True)


def schur_solve(factor, rhs):
    """`S⁻¹ rhs` with the factor from `schur_factor`."""
    return jsl.cho_solve(factor, rhs)


def range_space_solution(mass_inverse, jacobian, forces, rhs):
    """`(x, λ)` solving eq. (1) with `f = forces`, `g = rhs` by eq. (2): e.g. `(q̈, λ)` of
    `M q̈ + Jᵀ λ = Q`, `J q̈ = γ`."""
    factor = schur_factor(mass_inverse, jacobian)
    lam = schur_solve(factor, jacobian @ (mass_inverse * forces) - rhs)
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
    lam = schur_solve(schur_factor(mass_inverse, jacobian), residual)
    return mass_inverse * (jacobian.T @ lam)
