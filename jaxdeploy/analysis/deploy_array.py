"""Outputs of a deploy_array run, as in the seed study (W24 §4): deployment angle and its
deviation from the ideal-joint mechanism, X/Y displacement deviations of each panel's centre
and tip, panel accelerations and their spectra (unfolding and post-lock phases separately),
contact forces, lock time."""

from __future__ import annotations

import functools

import numpy as np

from ..mechanism import lock_times
from ..scenes.deploy_array import deployment_angle
from .base import Analysis
from .contact_forces import clearance_joint_history, contact_extremes
from .spectra import interval_mean_rate, peak_frequency, welch_psd

# Welch segment [s] of the panel acceleration spectra: 0.1 s, resolution 10 Hz, about the
# latch mode's half-power bandwidth (2ζf ≈ 9.5 Hz, docs/deploy_array_geometry.md), so the
# resonance is one peak whose location the parabola refines, and 28 segments averaged over the
# post-lock record. Longer segments resolve the interference between single rattle impacts,
# which is chaotic: docs/spectral_peak.md measures 0.1–1.46 s over solvers and tolerances.
SPECTRUM_SEGMENT = 0.1

PANELS = ("panel1", "panel2")


def panel_points(mechanism, q):
    """Global (x, y) of each panel's centre and tip, arrays (N, 2)."""
    out = {}
    for panel in PANELS:
        k = mechanism.body_index(panel)
        xy, theta = q[:, 3 * k : 3 * k + 2], q[:, 3 * k + 2]
        tip = np.asarray(mechanism.point(panel, "tip"))
        rot = np.stack(
            [
                np.cos(theta) * tip[0] - np.sin(theta) * tip[1],
                np.sin(theta) * tip[0] + np.cos(theta) * tip[1],
            ],
            axis=-1,
        )
        out[f"{panel}_centre"] = xy
        out[f"{panel}_tip"] = xy + rot
    return out


def crossing_time(ts, signal, level) -> float:
    """First time saved samples of `signal` reach `level`, by linear interpolation between
    them: for signals known only at saved times (another model's run). It depends on the save
    grid; a run's lock time is `lock_time`."""
    above = np.flatnonzero(signal >= level)
    if len(above) == 0 or above[0] == 0:
        return float("nan")
    i = above[0]
    frac = (level - signal[i - 1]) / (signal[i] - signal[i - 1])
    return float(ts[i - 1] + frac * (ts[i] - ts[i - 1]))


def lock_time(mechanism, trajectory) -> float:
    """When the deployment angle reached the root latch's stop [s]: the engagement located
    inside its step (`jaxdeploy.mechanism.lock_times`; independent of the save grid), NaN if
    not by the run's end. A run read back from the reference cache carries it in its `events`.
    (Before, the first crossing of the saved α by linear interpolation: 0.5397694 s at 2001
    saved points and 0.5397652 s at 60001 over 0.6 s, with k = 1.50015 N m/rad.)"""
    if getattr(trajectory, "memory", None) is None:
        events = getattr(trajectory, "events", None)
        if events is None or "lock_time" not in events:
            raise ValueError(
                "the run has no saved memory: simulate it with outputs='all' or 'state' for "
                "its lock time"
            )
        return float(events["lock_time"])
    root_latch = len(mechanism.elements) - 1  # DeployArray.build appends it last
    return float(lock_times(mechanism, trajectory.memory)[root_latch])


class DeployArrayAnalysis(Analysis):
    """`deploy_array_summary` and the figures (`deploy_array_plot_data`) of a run, from its outputs
    (`deploy_array_outputs`, computed once for both). `reference`: the ideal-joint
    counterpart's trajectory at the same saved times (`DeployArray.ideal_counterpart()`), or
    None: then the deviations from the ideal mechanism and its lock time are left out."""

    uses_reference = True

    @functools.cached_property
    def outputs(self) -> dict:
        return deploy_array_outputs(self.mechanism, self.trajectory, self.reference)

    def summary(self) -> dict:
        return deploy_array_summary(self.outputs, self.mechanism, self.trajectory)

    figures = "deploy_array"

    def plot_data(self) -> dict:
        return deploy_array_plot_data(self.outputs)


def deploy_array_outputs(mechanism, trajectory, reference=None) -> dict:
    """Time series of every output (numpy): deployment angle `alpha`, lock time, each panel's
    centre acceleration and interval-mean acceleration, each clearance joint's contact
    history (`joints`, by journal body); with the `reference` trajectory (the ideal-joint
    mechanism at the same saved times) also `alpha_ideal`, `lock_time_ideal`,
    `ideal_status` and each panel's centre and tip `*_deviation` from it."""
    ts = np.asarray(trajectory.ts)
    q, qdd = np.asarray(trajectory.q), np.asarray(trajectory.qdd)
    alpha = deployment_angle(q)
    out = {"t": ts, "alpha": alpha, "lock_time": lock_time(mechanism, trajectory)}
    if reference is not None:
        if not np.array_equal(np.asarray(reference.ts), ts):
            raise ValueError(
                "reference: its saved times must be the run's (run it with ts=trajectory.ts)"
            )
        q_ideal = np.asarray(reference.q)
        out["alpha_ideal"] = deployment_angle(q_ideal)
        out["ideal_status"] = reference.status()
        out["lock_time_ideal"] = lock_time(mechanism.idealized(), reference)
        points, points_ideal = panel_points(mechanism, q), panel_points(mechanism, q_ideal)
        for key in points:
            out[f"{key}_deviation"] = points[key] - points_ideal[key]
    for panel in PANELS:
        k = mechanism.body_index(panel)
        out[f"{panel}_acceleration"] = qdd[:, 3 * k : 3 * k + 2]
        # For spectra: the mean acceleration over each save interval, from the saved
        # velocities (analysis/spectra.py: not aliased by the save grid, no impact missed).
        out[f"{panel}_mean_acceleration"] = interval_mean_rate(
            ts, np.asarray(trajectory.v)[:, 3 * k : 3 * k + 2]
        )[1]
    out["joints"] = {
        mechanism.elements[i].journal_body: h
        for i, h in clearance_joint_history(mechanism, trajectory).items()
    }
    return out


def deploy_array_summary(outputs, mechanism, trajectory) -> dict:
    """Headline numbers of a run from its `deploy_array_outputs`: lock time, the largest
    deviations from the ideal mechanism before and after the lock (when the outputs have
    the reference), post-lock spectral peaks, contact extremes."""
    o = outputs
    ts = o["t"]
    t_lock = o["lock_time"] if np.isfinite(o["lock_time"]) else ts[-1]
    deploy, locked = ts <= t_lock, ts > t_lock
    with_reference = "alpha_ideal" in o
    summary = {"lock_time": o["lock_time"]}
    if with_reference:
        dev = np.abs(o["alpha"] - o["alpha_ideal"])
        summary["lock_time_ideal"] = o["lock_time_ideal"]
        summary["max_angle_deviation_deploy"] = float(dev[deploy].max())
        summary["max_angle_deviation_locked"] = float(dev[locked].max()) if locked.any() else 0.0
    for panel in PANELS:
        if with_reference:
            d = np.abs(o[f"{panel}_centre_deviation"])
            summary[f"{panel}_max_dx"] = float(d[:, 0].max())
            summary[f"{panel}_max_dy"] = float(d[:, 1].max())
            tip = np.abs(o[f"{panel}_tip_deviation"])
            summary[f"{panel}_tip_max_dx"] = float(tip[:, 0].max())
            summary[f"{panel}_tip_max_dy"] = float(tip[:, 1].max())
        # Intervals that begin at or after the lock.
        after = ts[:-1] >= t_lock
        acc_y = o[f"{panel}_mean_acceleration"][after, 1]
        summary[f"{panel}_peak_freq_hz"] = (
            peak_frequency(ts[:-1][after], acc_y, segment=SPECTRUM_SEGMENT)
            if after.sum() > 8
            else float("nan")
        )
    # Contact extremes tracked over every accepted step (independent of the saved times).
    joints = contact_extremes(mechanism, trajectory)
    for index, extremes in joints.items():
        owner = mechanism.elements[index].journal_body
        summary[f"{owner}_max_contact_force"] = extremes["max_normal_force"]
        summary[f"{owner}_max_penetration"] = extremes["max_penetration"]
    forces = [j["max_normal_force"] for j in joints.values()]
    summary["max_contact_force"] = max(forces, default=0.0)
    if with_reference:
        summary["ideal_reference_status"] = o["ideal_status"]
    return summary


def deploy_array_plot_data(outputs) -> dict:
    """What `figures.DRAWINGS["deploy_array"]` draws, from a run's `deploy_array_outputs`:
    those, the lock time to mark (the run's end when it did not lock), the panels, and each
    panel's Welch spectrum of its interval-mean Y acceleration before and after the lock
    (where there are more than 8 intervals), with the spectra's upper frequency [Hz]."""
    o = outputs
    ts = o["t"]
    t_lock = o["lock_time"] if np.isfinite(o["lock_time"]) else ts[-1]
    spectra = {}
    for panel in PANELS:
        mean_acc_y, starts = o[f"{panel}_mean_acceleration"][:, 1], ts[:-1]
        spectra[panel] = {
            phase: welch_psd(starts[mask], mean_acc_y[mask], SPECTRUM_SEGMENT)
            for phase, mask in (("unfolding", starts < t_lock), ("post-lock", starts >= t_lock))
            if mask.sum() > 8
        }
    joints = {
        owner: {"normal_force": np.asarray(h["normal_force"])} for owner, h in o["joints"].items()
    }
    return {
        **{k: v for k, v in o.items() if k != "joints"},
        "t_lock": float(t_lock),
        "panels": PANELS,
        "spectra": spectra,
        "spectrum_f_max": min(500.0, 0.5 / float(ts[1] - ts[0])),
        "joints": joints,
    }
