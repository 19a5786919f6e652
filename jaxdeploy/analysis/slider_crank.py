"""Headline numbers and figures of a slider-crank run (as in Flores' clearance-joint papers:
journal orbit, contact force, slider acceleration against the ideal mechanism)."""

from __future__ import annotations

import numpy as np

from ..scenes.slider_crank import ideal_slider_kinematics
from .base import Analysis
from .contact_forces import acceleration_extremes, clearance_joint_history, contact_extremes


class SliderCrankAnalysis(Analysis):
    """`slider_crank_summary` and the figures (`slider_crank_plot_data`) of a run (the ideal
    mechanism is the closed form `ideal_slider_kinematics`: no reference run)."""

    def summary(self) -> dict:
        return slider_crank_summary(self.mechanism, self.trajectory)

    figures = "slider_crank"

    def plot_data(self) -> dict:
        params = self.scene.complete(self.params)
        return slider_crank_plot_data(params, self.mechanism, self.trajectory)


def slider_crank_summary(mechanism, trajectory) -> dict:
    """Slider acceleration extremes [m/s²], largest contact force [N] and penetration [m] of
    the run, tracked over every accepted step (independent of the saved times)."""
    acc_min, acc_max = acceleration_extremes(trajectory, 3 * mechanism.body_index("slider"))
    summary = {"slider_acc_min": acc_min, "slider_acc_max": acc_max}
    joints = contact_extremes(mechanism, trajectory).values()
    summary["max_contact_force"] = max((j["max_normal_force"] for j in joints), default=0.0)
    if joints:
        summary["max_penetration"] = max(j["max_penetration"] for j in joints)
    return summary


def slider_crank_plot_data(params, mechanism, trajectory) -> dict:
    """What `figures.DRAWINGS["slider_crank"]` draws: the crank angle [deg] at the saved times, the
    slider's acceleration [m/s²] and the closed-form ideal one, and per clearance joint its
    eccentricity [m] and normal force [N]; `params` complete (`SliderCrank.complete`)."""
    ts = np.asarray(trajectory.ts)
    slider = 3 * mechanism.body_index("slider")
    _, _, a_ideal = ideal_slider_kinematics(
        float(params["crank_length"]), float(params["rod_length"]), float(params["crank_speed"]), ts
    )
    joints = clearance_joint_history(mechanism, trajectory)
    return {
        "crank_angle": np.degrees(float(params["crank_speed"]) * ts),
        "slider_acceleration": np.asarray(trajectory.qdd[:, slider]),
        "slider_acceleration_ideal": a_ideal,
        "clearance": float(params["clearance"]),
        "joints": [
            {key: np.asarray(h[key]) for key in ("eccentricity", "normal_force")}
            for h in joints.values()
        ],
    }
