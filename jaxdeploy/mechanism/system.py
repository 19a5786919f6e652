"""A planar mechanism: bodies plus elements, and the functions the integrators need.

Equations of motion in absolute coordinates (Nikravesh 1988; Haug 1989):

    M q̈ + Φ_q(q, t)ᵀ λ = Q(q, q̇, t; memory),     Φ(q, t) = 0      (index-3 DAE)

`M` is constant and diagonal (m, m, J per body). The topology (which bodies, which elements)
is static Python data; every number is a JAX array leaf of this pytree, so `jit`, `vmap` and
`grad` see parameters as data and a changed number never recompiles.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from .._tracing import traced_once
from .bodies import GROUND, Body, Kinematics, cross
from .element import AbstractElement
from .saddle_point import SOLUTIONS
from .sparsity import compressed_jacobian


class Mechanism(eqx.Module):
    """Bodies, ground points and elements (joints, forces, clearance joints).

    **Arguments:**
    - `bodies`: the moving bodies, in coordinate order (`q = [x₀, y₀, θ₀, x₁, …]`).
    - `elements`: joints and force elements.
    - `ground_points`: `{name: (x, y)}` global points usable with body `"ground"`.
    """

    bodies: tuple[Body, ...]
    elements: tuple[AbstractElement, ...]
    ground_points: dict[str, Array]

    def __init__(self, bodies, elements, ground_points=None):
        self.bodies = tuple(bodies)
        self.elements = tuple(elements)
        self.ground_points = {
            k: jnp.asarray(v, dtype=float) for k, v in (ground_points or {}).items()
        }
        names = [b.name for b in self.bodies]
        if len(set(names)) != len(names):
            raise ValueError(f"body names must be unique, got {names}")
        for element in self.elements:
            for body in element.bodies():
                if body != GROUND and body not in names:
                    raise ValueError(
                        f"{type(element).__name__} refers to unknown body {body!r}; "
                        f"known bodies: {[GROUND, *names]}"
                    )
            for body_field, point_field in (
                ("body_a", "point_a"),
                ("body_b", "point_b"),
                ("bearing_body", "bearing_point"),
                ("journal_body", "journal_point"),
                ("body", "point"),
            ):
                body, point = (
                    getattr(element, body_field, None),
                    getattr(element, point_field, None),
                )
                if isinstance(point, str):
                    self.point(body, point)  # raises with the list of known points

    # --- topology -------------------------------------------------------------------------

    def body_index(self, name: str) -> int:
        for k, body in enumerate(self.bodies):
            if body.name == name:
                return k
        raise KeyError(f"unknown body {name!r}; known: {[b.name for b in self.bodies]}")

    def point(self, body: str, name: str) -> Array:
        points = self.ground_points if body == GROUND else self.bodies[self.body_index(body)].points
        if name not in points:
            raise KeyError(f"body {body!r} has no point {name!r}; known: {sorted(points)}")
        return points[name]

    @property
    def n_coordinates(self) -> int:
        return 3 * len(self.bodies)

    @property
    def n_constraints(self) -> int:
        return sum(e.n_constraints for e in self.elements)

    @property
    def degrees_of_freedom(self) -> int:
        """Grübler count `3 n_b − m` (assumes independent constraints)."""
        return self.n_coordinates - self.n_constraints

    def find(self, element_type) -> list[int]:
        """Indices of the elements of a given type."""
        return [i for i, e in enumerate(self.elements) if isinstance(e, element_type)]

    def idealized(self) -> Mechanism:
        """The same mechanism with every clearance joint replaced by an ideal revolute joint."""
        return Mechanism(self.bodies, [e.idealized() for e in self.elements], self.ground_points)

    def replace_element(self, index: int, element: AbstractElement) -> Mechanism:
        elements = list(self.elements)
        elements[index] = element
        return Mechanism(self.bodies, elements, self.ground_points)

    # --- dynamics ---------------------------------------------------------------------------

    def kinematics(self, q, v=None) -> Kinematics:
        return Kinematics(self, q, v)

    def mass_diagonal(self) -> Array:
        """Diagonal of M: `(m₀, m₀, J₀, m₁, m₁, J₁, …)`."""
        return jnp.concatenate([jnp.stack([b.mass, b.mass, b.inertia]) for b in self.bodies])

    def constraints(self, q, t) -> Array:
        """`Φ(q, t)`, stacked over the elements that constrain."""
        kin = self.kinematics(q)
        rows = [e.constraint(kin, t) for e in self.elements if e.n_constraints]
        if not rows:
            return jnp.zeros((0,), dtype=q.dtype)
        return jnp.concatenate(rows)

    def constraint_jacobian(self, q, t) -> Array:
        """`Φ_q` (m × n), by forward-mode differentiation compressed along the static sparsity
        (`constraint_pattern`, `sparsity.compressed_jacobian`): for deploy_array 9 forward
        directions instead of 21, each of them cheap."""
        if not self.n_constraints:
            return jnp.zeros((0, q.shape[0]), dtype=q.dtype)
        return compressed_jacobian(lambda x: self.constraints(x, t), q, self.constraint_pattern())

    def constraint_velocity_rhs(self, q, t) -> Array:
        """`−Φ_t`, so that the velocity constraint reads `Φ_q q̇ = −Φ_t`."""
        return -jax.jacfwd(self.constraints, argnums=1)(q, t)

    def constraint_acceleration_rhs(self, q, v, t) -> Array:
        """`γ = −(Φ_q q̇)_q q̇ − 2 Φ_qt q̇ − Φ_tt`, so that `Φ_q q̈ = γ`.

        Computed as `−d²/ds² Φ(q + s q̇, t + s)` at s = 0 (nested JVPs, no Hessian formed).
        """

        def along(s):
            return self.constraints(q + s * v, t + s)

        def first(s):
            return jax.jvp(along, (s,), (jnp.ones_like(s),))[1]

        s0 = jnp.zeros((), dtype=q.dtype)
        return -jax.jvp(first, (s0,), (jnp.ones_like(s0),))[1]

    def constraint_jacobian_transpose_product(self, q, t, mu) -> Array:
        """`Φ_q(q, t)ᵀ μ`, by one reverse-mode pass through `Φ` (Φ_q is never formed).

        Cheaper than `constraint_jacobian(q, t).T @ mu`, which needs one forward pass per
        coordinate; the Newton residual of the integrators evaluates it every iteration.
        """
        if not self.n_constraints:
            return jnp.zeros_like(q)
        _, pullback = jax.vjp(lambda x: self.constraints(x, t), q)
        return pullback(mu)[0]

    def generalized_forces(self, q, v, t, memory) -> Array:
        """`Q(q, q̇, t)`: the sum of every element's forces and torques.

        A wrench `(F, P, τ)` on body k adds `F` to `Q_{x,y}` and `(P − r_k) × F + τ` to `Q_θ`.
        The contributions are collected per body at trace time and summed once, then
        concatenated: no scatter (`.at[].add`) per wrench, which on CPU costs one kernel each
        (and a scatter per case under `vmap`).
        """
        kin = self.kinematics(q, v)
        linear = [[] for _ in self.bodies]
        angular = [[] for _ in self.bodies]
        for element, mem in zip(self.elements, memory, strict=True):
            for w in element.wrenches(kin, t, mem):
                if w.body == GROUND:
                    continue
                k = self.body_index(w.body)
                if w.force is not None:
                    f = jnp.asarray(w.force, dtype=q.dtype)
                    linear[k].append(f)
                    if w.point is not None:
                        arm = w.point - kin.origin(w.body)
                        angular[k].append(cross(arm, f))
                if w.torque is not None:
                    angular[k].append(jnp.asarray(w.torque, dtype=q.dtype))
        zero2 = jnp.zeros(2, dtype=q.dtype)
        zero = jnp.zeros((), dtype=q.dtype)
        per_body = [
            jnp.concatenate([sum(lin, zero2), jnp.reshape(sum(ang, zero), (1,))])
            for lin, ang in zip(linear, angular, strict=True)
        ]
        if not per_body:
            return jnp.zeros_like(q)
        return jnp.concatenate(per_body)

    # --- sparsity of the step residual ----------------------------------------------------------

    def _coupled_coordinates(self, element) -> np.ndarray:
        """Coordinate indices of the bodies `element` couples (all, if it does not say)."""
        names = element.coupled_bodies()
        if names is None:
            return np.arange(self.n_coordinates)
        indices = [self.body_index(b) for b in names if b != GROUND]
        return np.array([3 * k + i for k in indices for i in range(3)], dtype=int)

    def constraint_pattern(self) -> np.ndarray:
        """Static sparsity of `Φ_q` (m × n, boolean): the rows of each constraining element
        depend only on the coordinates of the bodies it couples."""
        return self.jacobian_patterns()[0][self.n_coordinates :]

    def jacobian_patterns(self) -> tuple[np.ndarray, np.ndarray]:
        """Static sparsity of the Jacobians, with respect to q (or q̇), of

        * the constraint terms `[Φ_qᵀ μ; Φ]` ((n + m) × n): each constraining element's rows
          (its share of Φ_qᵀ μ on its bodies, and its own Φ rows) depend only on the
          coordinates of the bodies it couples (`AbstractElement.coupled_bodies`);
        * the forces `Q` (n × n): each force element's forces depend on, and act on, the
          bodies it couples.

        Boolean numpy arrays, from the topology alone (trace time).
        """
        n, m = self.n_coordinates, self.n_constraints
        constraint = np.zeros((n + m, n), dtype=bool)
        force = np.zeros((n, n), dtype=bool)
        row = n
        for element in self.elements:
            coords = self._coupled_coordinates(element)
            if element.n_constraints:
                constraint[np.ix_(coords, coords)] = True
                constraint[row : row + element.n_constraints, coords] = True
                row += element.n_constraints
            if element.has_forces:
                force[np.ix_(coords, coords)] = True
        return constraint, force

    # --- memory (state that changes between steps only) ---------------------------------------

    def init_memory(self, q, v):
        kin = self.kinematics(q, v)
        return tuple(e.init_memory(kin) if e.has_memory else None for e in self.elements)

    def memory_for_step(self, memory, q, v, instruments: bool = True):
        """Memory used throughout the step that starts at `(q, v)`. `instruments=False`
        leaves the memory of elements that only watch the others (`reads_memories`: an
        energy meter) as it is, for a caller that needs the memory the dynamics use alone."""
        kin = self.kinematics(q, v)
        updated = [
            e.memory_for_step(m, kin) if e.has_memory and not e.reads_memories else m
            for e, m in zip(self.elements, memory, strict=True)
        ]
        for i, e in enumerate(self.elements):
            if e.reads_memories and instruments:
                updated[i] = e.memory_for_step_beside(memory[i], kin, tuple(updated), memory)
        return tuple(updated)

    @traced_once
    def memory_after_step(self, memory, q, v, step):
        """Memory after an accepted step of length `step` (s) that ended at `(q, v)`."""
        kin = self.kinematics(q, v)
        updated = [
            e.memory_after_step(m, kin, step) if e.has_memory and not e.reads_memories else m
            for e, m in zip(self.elements, memory, strict=True)
        ]
        for i, e in enumerate(self.elements):
            if e.reads_memories:
                updated[i] = e.memory_after_step_beside(
                    memory[i], kin, step, tuple(updated), memory
                )
        return tuple(updated)

    def event_fraction(self, memory):
        """The earliest event inside the last accepted step, as a fraction of the step (≥ 1:
        none), over the elements that locate events (`AbstractElement.event_fraction`);
        `None` when no element does (then nothing is traced for it)."""
        fractions = self._event_fractions(memory)
        return jnp.min(jnp.stack(fractions)) if fractions else None

    def locates_events(self, memory) -> bool:
        """Whether an element locates events (`event_fraction` is not None), decided without a
        JAX operation: outside a trace each would be compiled on a process's first call."""
        return bool(self._event_fractions(memory))

    def _event_fractions(self, memory) -> list:
        return [
            f
            for e, m in zip(self.elements, memory, strict=True)
            if e.has_memory and (f := e.event_fraction(m)) is not None
        ]

    def switched(self, memory_before, memory_after):
        """Whether a step flipped any element's switch flag (`AbstractElement.switch_flags`)."""
        flips = [
            e.switched(a, b)
            for e, a, b in zip(self.elements, memory_before, memory_after, strict=True)
            if e.has_memory
        ]
        return jnp.any(jnp.stack(flips)) if flips else jnp.array(False)

    # --- continuous internal states (AbstractElement.internal_rates) ------------------------------

    @property
    def has_internal_state(self) -> bool:
        return any(e.has_internal_state for e in self.elements)

    def internal_vector(self, memory) -> Array:
        """The elements' continuous internal states (`memory[i]["internal"]`), flattened into
        one vector, in element order and sorted names; empty when there are none."""
        parts = [
            jnp.ravel(m["internal"][name])
            for e, m in zip(self.elements, memory, strict=True)
            if e.has_internal_state
            for name in sorted(m["internal"])
        ]
        return jnp.concatenate(parts) if parts else jnp.zeros((0,))

    def with_internal(self, memory, z):
        """`memory` with its internal states replaced by the flat vector `z`
        (`internal_vector`'s layout)."""
        out, start = [], 0
        for e, m in zip(self.elements, memory, strict=True):
            if not e.has_internal_state:
                out.append(m)
                continue
            internal = {}
            for name in sorted(m["internal"]):
                shape = jnp.shape(m["internal"][name])
                size = int(np.prod(shape))
                internal[name] = jnp.reshape(z[start : start + size], shape)
                start += size
            out.append({**m, "internal": internal})
        return tuple(out)

    def internal_rates(self, q, v, t, memory) -> Array:
        """`ż` of `internal_vector(memory)` at `(q, q̇, t)`."""
        kin = self.kinematics(q, v)
        parts = []
        for e, m in zip(self.elements, memory, strict=True):
            if e.has_internal_state:
                rates = e.internal_rates(kin, t, m)
                parts += [jnp.ravel(rates[name]) for name in sorted(m["internal"])]
        return jnp.concatenate(parts) if parts else jnp.zeros((0,))

    # --- index-1 form and energy -----------------------------------------------------------------

    def accelerations(self, q, v, t, memory, baumgarte=0.0, linear_solve="range_space"):
        """Solve `[[M, Φ_qᵀ], [Φ_q, 0]] [q̈; λ] = [Q; γ̂]` (the index-1 system), with

            γ̂ = γ − 2 ω_b Φ̇ − ω_b² Φ,    Φ̇ = Φ_q q̇ + Φ_t

        Baumgarte's critically damped stabilisation of the acceleration constraint at rate
        `baumgarte` = ω_b [rad/s] (Baumgarte 1972; Nikravesh 1988, §13.2); ω_b = 0 (default)
        is the plain index-1 system `Φ_q q̈ = γ`. `linear_solve`: `"range_space"` (Cholesky
        of the Schur complement, the cheaper) or `"kkt_lu"` (LU of the whole system; exact
        zeros where the constraints fix a coordinate): see `saddle_point`.

        **Returns:** `(q̈, λ)`.
        """
        if linear_solve not in SOLUTIONS:
            raise ValueError(
                f"linear_solve = {linear_solve!r} is invalid; valid: {', '.join(SOLUTIONS)}"
            )
        return self._accelerations(q, v, t, memory, baumgarte, linear_solve)

    @traced_once
    def _accelerations(self, q, v, t, memory, baumgarte, linear_solve):
        mass_inverse = 1.0 / self.mass_diagonal()
        forces = self.generalized_forces(q, v, t, memory)
        if self.n_constraints == 0:
            return forces * mass_inverse, jnp.zeros((0,), dtype=q.dtype)
        jac = self.constraint_jacobian(q, t)
        rhs = self.constraint_acceleration_rhs(q, v, t)
        if baumgarte != 0.0:
            phi_dot = jac @ v - self.constraint_velocity_rhs(q, t)
            rhs = rhs - 2.0 * baumgarte * phi_dot - baumgarte**2 * self.constraints(q, t)
        return SOLUTIONS[linear_solve](mass_inverse, jac, forces, rhs)

    def kinetic_energy(self, v) -> Array:
        """`T = ½ q̇ᵀ M q̇` (J)."""
        return 0.5 * jnp.sum(self.mass_diagonal() * v**2)

    def potential_energy(self, q, memory) -> Array:
        """`V = Σ_e V_e(q)` (J): gravity, springs, drive, latch, contact elastic energy."""
        kin = self.kinematics(q)
        total = jnp.zeros((), dtype=q.dtype)
        for element, mem in zip(self.elements, memory, strict=True):
            total = total + element.potential_energy(kin, mem)
        return total
