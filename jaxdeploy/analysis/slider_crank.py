"""Headline numbers and figures of a slider-crank run (as in Flores' clearance-joint papers:
journal orbit, contact force, slider acceleration against the ideal mechanism)."""

from __future__ import annotations

import os

import numpy as np

from ..io import atomic_savefig
from ..scenes.slider_crank import ideal_slider_kinematics
from .base import Analysis
from .contact_forces import acceleration_extremes, clearance_joint_history, contact_extremes


class SliderCrankAnalysis(Analysis):
    """`slider_crank_summary` and `plot_slider_crank` of a run (the ideal mechanism is the
    closed form `ideal_slider_kinematics`: no reference run)."""

    def summary(self) -> dict:
        return slider_crank_summary(self.mechanism, self.trajectory)

    def plot(self, out_dir: str) -> list[str]:
        params = self.scene.complete(self.params)
        return plot_slider_crank(params, self.mechanism, self.trajectory, out_dir)


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


def plot_slider_crank(params, mechanism, trajectory, out_dir) -> list[str]:
    """Slider acceleration against the closed-form ideal one, and per clearance joint the
    journal orbit and contact force; `params` complete (`SliderCrank.complete`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ts = np.asarray(trajectory.ts)
    crank_angle = np.degrees(float(params["crank_speed"]) * ts)
    slider = 3 * mechanism.body_index("slider")
    _, _, a_ideal = ideal_slider_kinematics(
        float(params["crank_length"]), float(params["rod_length"]), float(params["crank_speed"]), ts
    )
    files = []
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(crank_angle, np.asarray(trajectory.qdd[:, slider]), lw=0.8, label="clearance joint")
    ax.plot(crank_angle, a_ideal, "k--", lw=1.0, label="ideal joint (closed form)")
    ax.set_xlabel("crank angle [deg]")
    ax.set_ylabel("slider acceleration [m/s²]")
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    path = os.path.join(out_dir, "slider_acceleration.png")
    atomic_savefig(fig, path, dpi=130)
    plt.close(fig)
    files.append(path)

    joints = clearance_joint_history(mechanism, trajectory)
    for history in joints.values():
        c = float(params["clearance"])
        ecc = np.asarray(history["eccentricity"])
        fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4.2))
        circle = np.linspace(0, 2 * np.pi, 200)
        ax1.plot(c * np.cos(circle) * 1e3, c * np.sin(circle) * 1e3, "k:", lw=0.8)
        ax1.plot(ecc[:, 0] * 1e3, ecc[:, 1] * 1e3, lw=0.7)
        ax1.set_aspect("equal")
        ax1.set_xlabel("e_x [mm]")
        ax1.set_ylabel("e_y [mm]")
        ax1.set_title("journal centre relative to bearing centre")
        ax2.plot(crank_angle, np.asarray(history["normal_force"]), lw=0.8)
        ax2.set_xlabel("crank angle [deg]")
        ax2.set_ylabel("normal contact force [N]")
        ax2.grid(alpha=0.3)
        fig.tight_layout()
        path = os.path.join(out_dir, "journal_orbit_contact_force.png")
        atomic_savefig(fig, path, dpi=130)
        plt.close(fig)
        files.append(path)
    return files
