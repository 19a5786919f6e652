"""The figures of a scene's run, drawn from plain numbers (numpy arrays, floats, dicts of them):
what each scene's `Analysis.plot_data()` gives.

This module imports numpy and matplotlib alone, nothing of jaxdeploy (and so not JAX): the
command line draws a run's figures in a second process that runs this file
(`python figures.py`, `serve`), started when the command starts, so that matplotlib's import
(about a second) and the drawing overlap the run on the machine's other core instead of
following it. In a program, `Analysis.plot(out_dir)` calls `draw` directly.
"""

from __future__ import annotations

import io
import os
import tempfile

import numpy as np

# The prefix of a file being written (jaxdeploy.io.TEMP_PREFIX: an output folder's staging
# knows such files are unfinished).
TEMP_PREFIX = ".tmp-"


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save(fig, path: str, **kwargs) -> None:
    """`fig.savefig` written whole, then renamed (a reader never sees half a figure; as
    `jaxdeploy.io.atomic_savefig`), and the figure closed."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format=os.path.splitext(path)[1].lstrip(".") or None, **kwargs)
    _pyplot().close(fig)
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=TEMP_PREFIX, suffix=os.path.basename(path))
    try:
        umask = os.umask(0)
        os.umask(umask)
        os.fchmod(fd, 0o666 & ~umask)
        with os.fdopen(fd, "wb") as fh:
            fh.write(buffer.getvalue())
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def slider_crank(data: dict, out_dir: str) -> list[str]:
    """Slider acceleration against the closed-form ideal one, and per clearance joint the
    journal orbit and contact force (`SliderCrankAnalysis.plot_data`)."""
    plt = _pyplot()
    crank_angle = data["crank_angle"]
    files = []
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(crank_angle, data["slider_acceleration"], lw=0.8, label="clearance joint")
    ax.plot(crank_angle, data["slider_acceleration_ideal"], "k--", lw=1.0,
            label="ideal joint (closed form)")  # fmt: skip
    ax.set_xlabel("crank angle [deg]")
    ax.set_ylabel("slider acceleration [m/s²]")
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    files.append(os.path.join(out_dir, "slider_acceleration.png"))
    save(fig, files[-1], dpi=130)

    c = data["clearance"]
    for history in data["joints"]:
        ecc = history["eccentricity"]
        fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4.2))
        circle = np.linspace(0, 2 * np.pi, 200)
        ax1.plot(c * np.cos(circle) * 1e3, c * np.sin(circle) * 1e3, "k:", lw=0.8)
        ax1.plot(ecc[:, 0] * 1e3, ecc[:, 1] * 1e3, lw=0.7)
        ax1.set_aspect("equal")
        ax1.set_xlabel("e_x [mm]")
        ax1.set_ylabel("e_y [mm]")
        ax1.set_title("journal centre relative to bearing centre")
        ax2.plot(crank_angle, history["normal_force"], lw=0.8)
        ax2.set_xlabel("crank angle [deg]")
        ax2.set_ylabel("normal contact force [N]")
        ax2.grid(alpha=0.3)
        fig.tight_layout()
        files.append(os.path.join(out_dir, "journal_orbit_contact_force.png"))
        save(fig, files[-1], dpi=130)
    return files


def deploy_array(data: dict, out_dir: str) -> list[str]:
    """Deployment angle, deviations from the ideal mechanism (when the data has the
    reference), panel accelerations with their Welch spectra, contact forces
    (`DeployArrayAnalysis.plot_data`)."""
    plt = _pyplot()
    o = data
    with_reference = "alpha_ideal" in o
    ts, t_lock, panels = o["t"], o["t_lock"], o["panels"]
    files = []

    def save_as(fig, name):
        fig.tight_layout()
        files.append(os.path.join(out_dir, name))
        save(fig, files[-1], dpi=130)

    # The angle, with the ideal mechanism's and the deviation from it below when there is
    # a reference; the lock marked on the lower axes.
    rows = 2 if with_reference else 1
    fig, axes = plt.subplots(rows, 1, figsize=(7, 3 * rows), sharex=True, squeeze=False)
    ax1 = axes[0, 0]
    ax1.plot(ts, np.degrees(o["alpha"]), label="clearance joints")
    if with_reference:
        ax1.plot(ts, np.degrees(o["alpha_ideal"]), "k--", lw=1, label="ideal joints")
        axes[1, 0].plot(ts, np.degrees(o["alpha"] - o["alpha_ideal"]), lw=0.8)
        axes[1, 0].set_ylabel("α − α_ideal [deg]")
    ax1.set_ylabel("deployment angle α [deg]")
    ax1.legend()
    axes[-1, 0].axvline(t_lock, color="grey", ls=":", label="lock")
    axes[-1, 0].set_xlabel("time [s]")
    for ax in axes[:, 0]:
        ax.grid(alpha=0.3)
    save_as(fig, "deployment_angle.png")

    if with_reference:
        fig, axes = plt.subplots(2, 2, figsize=(10, 6), sharex=True)
        for row, panel in enumerate(panels):
            for col, axis_name in enumerate("XY"):
                ax = axes[row, col]
                for where, style in (("centre", "-"), ("tip", "--")):
                    d = o[f"{panel}_{where}_deviation"][:, col] * 1e6
                    ax.plot(ts, d, style, lw=0.7, label=where)
                ax.set_title(f"{panel}: {axis_name} displacement deviation")
                ax.set_ylabel("deviation [µm]")
                ax.grid(alpha=0.3)
                ax.legend(fontsize=8)
        for ax in axes[-1]:
            ax.set_xlabel("time [s]")
        save_as(fig, "panel_displacement_deviation.png")

    fig, axes = plt.subplots(2, 2, figsize=(10, 6))
    for row, panel in enumerate(panels):
        axes[row, 0].plot(ts, o[f"{panel}_acceleration"][:, 1], lw=0.5)
        axes[row, 0].set_title(f"{panel}: Y acceleration of the centre")
        axes[row, 0].set_ylabel("a_y [m/s²]")
        axes[row, 0].set_xlabel("time [s]")
        for phase, (f, psd) in o["spectra"][panel].items():
            axes[row, 1].semilogy(f, psd + 1e-30, lw=0.7, label=phase)
        axes[row, 1].set_xlim(0, o["spectrum_f_max"])
        axes[row, 1].set_title(f"{panel}: Welch spectrum, interval-mean Y acc.")
        axes[row, 1].set_ylabel("PSD of a_y [(m/s²)²/Hz]")
        axes[row, 1].set_xlabel("frequency [Hz]")
        axes[row, 1].legend(fontsize=8)
    save_as(fig, "panel_acceleration_spectra.png")

    if o["joints"]:
        fig, axes = plt.subplots(
            len(o["joints"]), 1, figsize=(7, 2.6 * len(o["joints"])), squeeze=False, sharex=True
        )
        for ax, (owner, h) in zip(axes[:, 0], o["joints"].items(), strict=True):
            ax.plot(ts, h["normal_force"], lw=0.6)
            ax.set_title(f"{owner} hinge: normal contact force")
            ax.set_ylabel("normal force [N]")
            ax.grid(alpha=0.3)
        axes[-1, 0].set_xlabel("time [s]")
        save_as(fig, "contact_forces.png")
    return files


# A scene's figures by the name its analysis gives (`Analysis.figures`).
DRAWINGS = {"slider_crank": slider_crank, "deploy_array": deploy_array}


def draw(kind: str, data: dict, out_dir: str) -> list[str]:
    """The figures `DRAWINGS[kind]` of `data` written into `out_dir`; the files written."""
    return DRAWINGS[kind](data, out_dir)


def serve() -> int:
    """The figure process (`python figures.py`): import matplotlib at once, then read one
    pickled request `(kind, data, out_dir)` from standard input, draw it and print the files
    written, one per line. An empty input (the command needed no figures, or stopped) ends
    it without drawing."""
    import pickle
    import sys

    _pyplot()
    request = sys.stdin.buffer.read()
    if not request:
        return 0
    kind, data, out_dir = pickle.loads(request)
    for path in draw(kind, data, out_dir):
        print(path, flush=True)
    return 0


if __name__ == "__main__":
    import signal
    import sys

    # Ctrl-C reaches the whole process group: the command says what happened and removes
    # what was unfinished; this process just ends.
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    sys.exit(serve())
