"""The mechanism as an ODE (index-1 form), integrated by any diffrax solver.

The index-3 equations `M q̈ + Φ_qᵀ λ = Q`, `Φ(q, t) = 0` are differentiated twice in time and
the acceleration constraint is stabilised (Baumgarte 1972; Nikravesh 1988, §13.2):

    [[M, Φ_qᵀ], [Φ_q, 0]] [q̈; λ] = [Q; γ − 2 ω_b Φ̇ − ω_b² Φ],   Φ̇ = Φ_q q̇ + Φ_t

(critically damped drift, ω_b in rad/s; ω_b = 0 is the plain index-1 ODE). The state is
`(q, q̇)`; after every accepted step the positions and velocities are projected back onto the
constraint manifold (coordinate projection; Hairer, Lubich & Wanner, *Geometric Numerical
Integration*, 2006, §IV.4; Eich 1993): the mass-weighted least-change correction

    q ← q − M⁻¹ Φ_qᵀ (Φ_q M⁻¹ Φ_qᵀ)⁻¹ Φ(q)          (Gauss–Newton, a fixed number of iterations)
    q̇ ← q̇ − M⁻¹ Φ_qᵀ (Φ_q M⁻¹ Φ_qᵀ)⁻¹ (Φ_q q̇ + Φ_t)

so drift never accumulates, whatever the inner solver. Memory elements (clearance impact
velocity v⁻, latch flag) are updated exactly as in the generalized-α solver: fixed during a
step (`Mechanism.memory_for_step`), updated after an accepted one
(`Mechanism.memory_after_step`).

Switch localisation: a memory flag that switches the model at a step boundary (a latch that
engages at the end of the step in which its angle is reached; `AbstractElement.switch_flags`)
makes the solution depend on where the boundary fell: an O(h) effect no higher-order error
estimate sees. With `resolve_switches=True` a step that flips such a flag reports the velocity
change over the step, `|q̇₁ − q̇₀|`, as its velocity error, so the step-size controller shrinks
steps at switches until that first-order effect is within tolerance too. (Clearance contact
onsets are located instead: `LocateEvents`, which `simulate` uses for adaptive runs.)
"""

from __future__ import annotations

import functools
from typing import ClassVar, NamedTuple

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx

from .._tracing import traced_once
from ..mechanism import Mechanism
from ..mechanism.saddle_point import least_change_correction
from .term import MechanismState, MechanismTerm, accelerations_at, mechanism_of


def stabilised_accelerations(
    mechanism: Mechanism, q, v, t, memory, baumgarte=0.0, linear_solve="range_space"
):
    """`(q̈, λ)` of the index-1 system with Baumgarte stabilisation (rate `baumgarte` = ω_b,
    rad/s; critically damped, α = ω_b, β = ω_b in Baumgarte's notation);
    `Mechanism.accelerations`."""
    return mechanism.accelerations(q, v, t, memory, baumgarte, linear_solve)


@traced_once
def project_onto_constraints(mechanism: Mechanism, q, v, t, iterations: int = 2):
    """Mass-weighted projection of `(q, q̇)` onto `Φ = 0`, `Φ_q q̇ + Φ_t = 0` (see module
    docstring; `saddle_point.least_change_correction`). `iterations` Gauss–Newton steps for
    positions (quadratic convergence: two take an O(tol) drift to roundoff), one linear
    projection for velocities. Differentiable (a loop of fixed length: `lax.fori_loop`
    with static bounds is a `scan`).

    The `iterations + 1` corrections are one loop whose body serves both kinds: each pass
    evaluates `Φ_q`, `Φ` and `Φ_t` at the current positions (`Φ` and `Φ_t` from one JVP in
    t) and corrects the positions with `Φ`, or, in the last pass, the velocities with
    `Φ_q q̇ + Φ_t`. Written out, the program held three copies of the Jacobian, the Schur
    factorisation and its solves, a quarter of a Tsit5 simulation's XLA program and compile
    time (slider_crank; `benchmarks/work_precision.py`, `program_parts`)."""
    if mechanism.n_constraints == 0:
        return q, v
    mass_inverse = 1.0 / mechanism.mass_diagonal()

    def correct(k, state):
        q, v = state
        jac = mechanism.constraint_jacobian(q, t)
        phi, phi_t = jax.jvp(lambda s: mechanism.constraints(q, s), (t,), (jnp.ones_like(t),))
        on_positions = k < iterations
        residual = jnp.where(on_positions, phi, jac @ v + phi_t)
        correction = least_change_correction(mass_inverse, jac, residual)
        return jnp.where(on_positions, q - correction, q), jnp.where(
            on_positions, v, v - correction
        )

    return jax.lax.fori_loop(0, iterations + 1, correct, (q, v))


class Index1Field(eqx.Module):
    """`d(q, q̇)/dt = (q̇, q̈)` with `q̈` from the stabilised index-1 system; `args` is the
    elements' memory for the step. With continuous internal states z (a mechanism whose
    elements have `has_internal_state`) the state is `(q, q̇, z)` and `ż` comes from
    `Mechanism.internal_rates`, the forces seeing the current z."""

    mechanism: Mechanism
    baumgarte: float = eqx.field(static=True, default=0.0)
    linear_solve: str = eqx.field(static=True, default="range_space")

    def __call__(self, t, y, memory):
        if len(y) == 3:
            q, v, z = y
            memory = self.mechanism.with_internal(memory, z)
        else:
            q, v = y
        qdd, _ = stabilised_accelerations(
            self.mechanism, q, v, t, memory, self.baumgarte, self.linear_solve
        )
        if len(y) == 3:
            return v, qdd, self.mechanism.internal_rates(q, v, t, memory)
        return v, qdd


class MechanismODEState(NamedTuple):
    inner: object


class MechanismInterpolation(dfx.AbstractLocalInterpolation):
    """Dense output of one `MechanismODESolver` step: positions and velocities from the inner
    solver's own interpolant (e.g. Dopri8's 7th-order one) plus the step's projection
    correction spread linearly over the step, so the output is continuous and ends at the
    projected state; accelerations and multipliers evaluated from that output state with the
    step's memory (`accelerations_at`); memory linear between the step's ends.

    Accelerations interpolated linearly between the step's ends were what the saved q̈ and λ
    were before: on slider_crank the slider's acceleration extremes were 2 % off, as the
    impacts' acceleration spikes are shorter than a step.

    A cubic Hermite interpolant of `q` (with `q̇`) has error h⁴ q⁗/384: on slider_crank, with
    the steps of 10–100 µs that an 8th-order method takes in free flight, that was ~1e-6 of the
    clearance at the output times — far above the solution's own error at tight tolerances.
    """

    t0: float
    t1: float
    inner: dfx.AbstractLocalInterpolation
    y0: MechanismState
    y1: MechanismState
    correction: tuple
    mechanism: Mechanism
    memory: tuple
    linear_solve: str = eqx.field(static=True)

    def __init__(
        self, *, t0, t1, y0, y1, inner, correction, mechanism, memory, inner_cls, linear_solve
    ):
        self.t0, self.t1 = t0, t1
        self.inner = inner_cls(t0=t0, t1=t1, **inner)
        self.y0, self.y1 = y0, y1
        self.correction = correction
        self.mechanism, self.memory = mechanism, memory
        self.linear_solve = linear_solve

    def evaluate(self, t0, t1=None, left=True):
        if t1 is not None:
            return jax.tree.map(lambda b, a: b - a, self.evaluate(t1), self.evaluate(t0))
        q, v, memory, step_memory = self._motion(t0)
        qdd, lam = accelerations_at(self.mechanism, q, v, t0, step_memory, self.linear_solve)
        return MechanismState(q, v, qdd, lam, memory)

    def motion(self, t):
        """`(q, q̇, memory)` at `t`, as `evaluate` gives them, without the acceleration
        solve (what `TrackExtremes` samples: tracing that solve only for the compiler to
        drop it cost a third of the traced program)."""
        return self._motion(t)[:3]

    def acceleration_inputs(self, t):
        """`(q, q̇, memory, step_memory)` at `t`: `motion` and the memory `evaluate` solves
        q̈ and λ with (`accelerations_at`: the step's, with the interpolated internal states
        if any), for a caller that solves them later."""
        return self._motion(t)

    def _motion(self, t):
        """`(q, q̇, memory, step_memory)`: the output state at `t` and the memory its
        accelerations see (the step's, with the interpolated internal states if any)."""
        s = (t - self.t0) / (self.t1 - self.t0)
        # Internal states (if any, the third part) are output through the memory, linear;
        # the accelerations see the inner interpolant's values of them.
        inner = self.inner.evaluate(t)
        q, v = inner[:2]
        dq, dv = self.correction

        def linear(a, b):
            return a + s * (b - a)

        q, v = q + s * dq, v + s * dv
        step_memory = self.memory
        if self.mechanism.has_internal_state:
            step_memory = self.mechanism.with_internal(step_memory, inner[2])
        memory = jax.tree.map(linear, self.y0.memory, self.y1.memory)
        return q, v, memory, step_memory


class MechanismODESolver(dfx.AbstractAdaptiveSolver):
    """Integrates a `MechanismTerm` as an index-1 ODE with a diffrax solver (e.g.
    `diffrax.Kvaerno5`), projecting onto the constraints and updating memory after each step.

    **Arguments:**
    - `solver`: the diffrax solver for `(q, q̇)`. Implicit solvers need explicit root-finder
      tolerances (e.g. `Kvaerno5(root_finder=optimistix.Chord(rtol, atol))`); see
      `ode_solver`.
    - `baumgarte`: ω_b [rad/s] ≥ 0 of the stabilisation (default 0: projection only).
    - `project`: project onto the constraint manifold after each step (default True).
    - `resolve_switches`: shrink steps at memory switches (default True; module docstring):
      steps that flip a switch flag (`Mechanism.switched`).

    Dense output is the inner solver's own interpolant for `q` and `q̇` with the projection's
    correction spread linearly over the step, `q̈` and `λ` evaluated from that state, memory
    linear (`MechanismInterpolation`).

    Continuous internal states of elements (`AbstractElement.internal_rates`, kept in the
    memory) are integrated by the inner solver with `(q, q̇)`, and their error estimate is
    part of the step's error (`state_norm`); the projection leaves them alone.
    """

    solver: dfx.AbstractSolver
    baumgarte: float = eqx.field(static=True, default=0.0)
    project: bool = eqx.field(static=True, default=True)
    resolve_switches: bool = eqx.field(static=True, default=True)

    term_structure: ClassVar = MechanismTerm

    @property
    def interpolation_cls(self):
        return functools.partial(
            MechanismInterpolation,
            inner_cls=self.solver.interpolation_cls,
            linear_solve=self.linear_solve,
        )

    @property
    def linear_solve(self) -> str:
        """How q̈ is solved for (`jaxdeploy.mechanism.saddle_point`): the cheaper range-space
        method for explicit solvers; for implicit ones the LU of the whole system, whose
        exact zeros their stage iteration needs to converge at tight `atol`."""
        if isinstance(self.solver, dfx.AbstractImplicitSolver):
            return "kkt_lu"
        return "range_space"

    def _inner_term(self, terms):
        field = Index1Field(mechanism_of(terms), self.baumgarte, self.linear_solve)
        return dfx.ODETerm(field)

    def order(self, terms):
        return self.solver.order(self._inner_term(terms))

    def error_order(self, terms):
        return self.solver.error_order(self._inner_term(terms))

    @staticmethod
    def _inner_state(mech, q, v, memory):
        if mech.has_internal_state:
            return q, v, mech.internal_vector(memory)
        return q, v

    def init(self, terms, t0, t1, y0: MechanismState, args):
        mech = mechanism_of(terms)
        y_inner = self._inner_state(mech, y0.q, y0.v, y0.memory)
        inner = self.solver.init(self._inner_term(terms), t0, t1, y_inner, y0.memory)
        return MechanismODEState(inner)

    def func(self, terms, t0, y0, args):
        return terms.vf(t0, y0, args)

    def step(self, terms, t0, t1, y0: MechanismState, args, solver_state, made_jump):
        mech = mechanism_of(terms)
        inner_term = self._inner_term(terms)
        h = t1 - t0
        memory = mech.memory_for_step(y0.memory, y0.q, y0.v)
        internal = mech.has_internal_state
        y1_inner, err, inner_dense, inner_state, result = self.solver.step(
            inner_term,
            t0,
            t1,
            self._inner_state(mech, y0.q, y0.v, memory),
            memory,
            solver_state.inner,
            made_jump,
        )
        q1_inner, v1_inner = y1_inner[:2]
        q1, v1 = q1_inner, v1_inner
        if self.project:
            q1, v1 = project_onto_constraints(mech, q1, v1, t1)
        # The internal states integrated over the step enter the memory update (which passes
        # them on) and the next step.
        stepped = mech.with_internal(memory, y1_inner[2]) if internal else memory
        memory1 = mech.memory_after_step(stepped, q1, v1, h)
        # The accelerations at the step's end with the memory the next step will use
        # (`memory_for_step` is what the next step computes first): they are the output at t1
        # and, for a first-same-as-last method (Tsit5, Kvaerno5), the next step's first
        # stage. The inner solver's own last stage cannot serve: it was taken before the
        # projection and with this step's memory. Instruments (an energy meter) have no part
        # in the accelerations: their memory for the step is the next step's business.
        memory_next = mech.memory_for_step(memory1, q1, v1, instruments=False)
        qdd1, lam1 = stabilised_accelerations(
            mech, q1, v1, t1, memory_next, self.baumgarte, self.linear_solve
        )
        if _is_first_same_as_last(inner_state):
            f1 = (v1, qdd1)
            if internal:
                f1 += (mech.internal_rates(q1, v1, t1, memory_next),)
            inner_state = (jnp.zeros_like(inner_state[0]), f1)
        y1 = MechanismState(q1, v1, qdd1, lam1, memory1)

        if err is None:
            err_q, err_v = jnp.zeros_like(q1), jnp.zeros_like(v1)
            err_z = jnp.zeros_like(y1_inner[2]) if internal else None
        else:
            err_q, err_v = err[:2]
            err_z = err[2] if internal else None
        if self.resolve_switches:
            switched = mech.switched(memory, memory1)
            err_v = jnp.where(switched, jnp.maximum(jnp.abs(err_v), jnp.abs(v1 - y0.v)), err_v)
        zeros = jax.tree_util.tree_map(jnp.zeros_like, (qdd1, lam1, memory1))
        if internal:
            # The internal states' error where `state_norm` looks for it.
            zeros = (*zeros[:2], mech.with_internal(zeros[2], err_z))
        y_error = jax.lax.stop_gradient(MechanismState(err_q, err_v, *zeros))

        dense_info = dict(
            y0=y0,
            y1=y1,
            inner=inner_dense,
            correction=(q1 - q1_inner, v1 - v1_inner),
            mechanism=mech,
            memory=memory,
        )
        return y1, y_error, dense_info, MechanismODEState(inner_state), result


def _is_first_same_as_last(inner_state) -> bool:
    """Whether a diffrax Runge–Kutta solver state carries a first-same-as-last value: the pair
    `(first_step, f0)` (`diffrax/_solver/runge_kutta.py`, `_SolverState`; `None` otherwise)."""
    return isinstance(inner_state, tuple) and len(inner_state) == 2


def state_norm(y) -> jax.Array:
    """RMS norm over the integrated variables only — positions, velocities and the elements'
    continuous internal states (`memory[i]["internal"]`) — for the step-size controller;
    other pytrees fall back to `diffrax.rms_norm`."""
    if isinstance(y, MechanismState):
        internal = [m["internal"] for m in y.memory if isinstance(m, dict) and "internal" in m]
        return optx.rms_norm((y.q, y.v, *internal))
    return optx.rms_norm(y)
