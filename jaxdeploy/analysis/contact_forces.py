"""Contact quantities of clearance joints along a saved trajectory."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ..mechanism import Mechanism, RevoluteClearance


def clearance_joint_history(mechanism: Mechanism, trajectory) -> dict[int, dict]:
    """For every clearance joint (by element index): eccentricity (N, 2), penetration,
    penetration rate, sliding velocity, normal force and friction force (N,) at the saved
    states, evaluated with the saved memory (impact velocities). The forces are net of the
    bore's near and far side (`RevoluteClearance.contact_forces`; the far side is zero unless
    the clearance is below ~3σ)."""
    out = {}
    for index in mechanism.find(RevoluteClearance):
        joint = mechanism.elements[index]

        def at(q, v, memory, joint=joint, index=index):
            kin = mechanism.kinematics(q, v)
            fn, ft, g = joint.contact_forces(kin, memory[index])
            return {
                "eccentricity": g.eccentricity,
                "penetration": g.penetration,
                "penetration_rate": g.penetration_rate,
                "sliding_velocity": g.sliding_velocity,
                "normal_force": fn,
                "friction_force": jnp.asarray(ft) + 0.0 * fn,
            }

        out[index] = jax.jit(jax.vmap(at))(trajectory.q, trajectory.v, trajectory.memory)
    return out
