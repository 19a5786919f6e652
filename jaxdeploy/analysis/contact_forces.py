"""Contact quantities of clearance joints along a saved trajectory, and their extremes over
the whole run."""

from __future__ import annotations

import numpy as np

from ..mechanism import Mechanism, RevoluteClearance, contact_history
from ..solvers.episodes import FIELDS, UNITS


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


def episodes_csv(mechanism: Mechanism, trajectory) -> str:
    """The contact episodes of every clearance joint (`Trajectory.contact_episodes()`) as CSV
    text: one row per episode, the joint (element index, bearing and journal bodies) and the
    episode's number first, then each field with its unit in the header, e.g.
    `onset_time [s]`. A separation that did not happen before the run ended is an empty field
    (never a number). Header only for a run without clearance joints or episodes."""
    header = ["joint", "bearing", "journal", "episode"] + [f"{f} [{UNITS[f]}]" for f in FIELDS]
    lines = [",".join(header)]
    joints = mechanism.find(RevoluteClearance)
    for index, table in zip(joints, trajectory.contact_episodes(), strict=True):
        joint = mechanism.elements[index]
        for number, row in enumerate(table.rows()):
            values = ["" if np.isnan(row[f]) else repr(row[f]) for f in FIELDS]
            lines.append(
                ",".join([str(index), joint.bearing_body, joint.journal_body, str(number)] + values)
            )
    return "\n".join(lines) + "\n"
