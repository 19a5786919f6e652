"""Contact quantities of clearance joints along a saved trajectory, and their extremes over
the whole run."""

from __future__ import annotations

import numpy as np

from ..mechanism import Mechanism, RevoluteClearance, contact_history


def clearance_joint_history(mechanism: Mechanism, trajectory) -> dict[int, dict]:
    """For every clearance joint (by element index): eccentricity (N, 2), penetration,
    penetration rate, sliding velocity, normal force and friction force (N,) at the saved
    states of `trajectory` (`jaxdeploy.mechanism.contact_history`)."""
    return contact_history(mechanism, trajectory.q, trajectory.v, trajectory.memory)


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
