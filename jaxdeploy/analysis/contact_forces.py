"""Contact quantities of clearance joints along a saved trajectory, and their extremes over
the whole run."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..mechanism import Mechanism, RevoluteClearance


def clearance_joint_history(mechanism: Mechanism, trajectory) -> dict[int, dict]:
    """For every clearance joint (by element index): eccentricity (N, 2), penetration,
    penetration rate, sliding velocity, normal force and friction force (N,) at the saved
    states, evaluated with the saved memory (impact velocities). The forces are net of the
    bore's near and far side (`RevoluteClearance.contact_forces`; the far side is zero unless
    the clearance is below ~3σ)."""
    return {
        index: _joint_history(mechanism, index, trajectory.q, trajectory.v, trajectory.memory)
        for index in mechanism.find(RevoluteClearance)
    }


# Compiled once per mechanism structure and joint, not per call: a sweep evaluates it for
# every case (the parameters are leaves of `mechanism`, so new values reuse the program).
@eqx.filter_jit
def _joint_history(mechanism, index, q, v, memory):
    joint = mechanism.elements[index]

    def at(q, v, memory):
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

    return jax.vmap(at)(q, v, memory)


def contact_extremes(mechanism: Mechanism, trajectory) -> dict[int, dict]:
    """For every clearance joint (by element index): `max_normal_force` [N] and
    `max_penetration` [m] over the run, from the extremes tracked over every accepted step
    (`Trajectory.extremes`), which do not depend on the saved times. A trajectory without
    them (assembled from saved arrays) falls back to the saved states, whose maxima miss the
    peaks between saved times."""
    joints = mechanism.find(RevoluteClearance)
    extremes = getattr(trajectory, "extremes", None)
    if extremes is not None and joints:
        force = np.asarray(extremes["normal_force_max"])
        penetration = np.asarray(extremes["penetration_max"])
        return {
            index: {"max_normal_force": float(force[k]), "max_penetration": float(penetration[k])}
            for k, index in enumerate(joints)
        }
    return {
        index: {
            "max_normal_force": float(np.max(np.asarray(h["normal_force"]))),
            "max_penetration": float(np.max(np.asarray(h["penetration"]))),
        }
        for index, h in clearance_joint_history(mechanism, trajectory).items()
    }


def acceleration_extremes(trajectory, coordinate: int) -> tuple[float, float]:
    """`(min, max)` of q̈ of one coordinate over the run [m/s² or rad/s²]: tracked over every
    accepted step (`Trajectory.extremes`), else over the saved states."""
    extremes = getattr(trajectory, "extremes", None)
    if extremes is not None:
        return (
            float(np.asarray(extremes["acceleration_min"])[coordinate]),
            float(np.asarray(extremes["acceleration_max"])[coordinate]),
        )
    acc = np.asarray(trajectory.qdd)[:, coordinate]
    return float(np.min(acc)), float(np.max(acc))
