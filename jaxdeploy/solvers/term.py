"""The mechanism as a diffrax term, and the state the solvers carry."""

from __future__ import annotations

from typing import NamedTuple

import diffrax as dfx
import jax
import jax.numpy as jnp

from ..mechanism import Mechanism


class MechanismState(NamedTuple):
    """What a step carries and `SaveAt` stores.

    `q`, `v`: coordinates and velocities; `qdd`, `lam`: accelerations and Lagrange multipliers
    satisfying the step's equations (the solver's own values); `memory`: the elements' memory
    (impact velocities, latch flags), changed between steps only.
    """

    q: jax.Array
    v: jax.Array
    qdd: jax.Array
    lam: jax.Array
    memory: tuple


def mechanism_of(terms) -> Mechanism:
    """The `Mechanism` of a solver's `terms` (diffeqsolve wraps the term, e.g. in a `WrapTerm`
    that handles the direction of time)."""
    while not isinstance(terms, MechanismTerm):
        terms = terms.term
    return terms.mechanism


class MechanismTerm(dfx.AbstractTerm):
    """A `Mechanism` as a diffrax term; `vf` is the index-1 time derivative of the state.

    The generalized-α solver uses the mechanism's functions directly; `vf` serves diffrax's
    initial step-size selection and anything else that asks for `dy/dt`.
    """

    mechanism: Mechanism

    def vf(self, t, y: MechanismState, args):
        qdd, lam = self.mechanism.accelerations(y.q, y.v, t, y.memory)
        return MechanismState(
            q=y.v,
            v=qdd,
            qdd=jnp.zeros_like(y.qdd),
            lam=jnp.zeros_like(y.lam),
            memory=jax.tree_util.tree_map(jnp.zeros_like, y.memory),
        )

    def contr(self, t0, t1, **kwargs):
        return t1 - t0

    def prod(self, vf, control):
        return jax.tree_util.tree_map(lambda x: x * control, vf)


def accelerations_at(mechanism: Mechanism, q, v, t, memory, linear_solve="range_space"):
    """`(q̈, λ)` of an output state `(q, q̇)` at time `t` from the equations of motion with the
    memory of the step it lies in (`Mechanism.accelerations`, index-1, no stabilisation): the
    saved accelerations and multipliers of every solver path are these, a function of the
    saved state, rather than an interpolant between the step's ends."""
    return mechanism.accelerations(q, v, t, memory, 0.0, linear_solve)
