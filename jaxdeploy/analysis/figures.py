"""The figures of a scene's run, drawn from plain numbers (numpy arrays, floats, dicts of them):
what each scene's `Analysis.plot_data()` gives.

This module imports numpy and matplotlib alone, nothing of jaxdeploy (and so not JAX): the
command line draws a run's figures in a second process that runs this file
(`python figures.py`, `serve`), started when the command starts, so that matplotlib's import
(about a second) and the drawing overlap the run on the machine's other core instead of
following it. In a program, `Analysis.plot(out_dir)` calls `draw` directly.
"""

from __future__ import annotations

import ast
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


def _saved(fig, out_dir: str, name: str) -> list[str]:
    """`fig` laid out and written as `out_dir/name` (130 dpi); the list of that one file."""
    fig.tight_layout()
    path = os.path.join(out_dir, name)
    save(fig, path, dpi=130)
    return [path]


# --- slider_crank (`SliderCrankAnalysis.plot_data`) ---------------------------------------


def _slider_acceleration(data: dict, out_dir: str) -> list[str]:
    """Slider acceleration against the closed-form ideal one, over the crank angle."""
    plt = _pyplot()
    crank_angle = data["crank_angle"]
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(crank_angle, data["slider_acceleration"], lw=0.8, label="clearance joint")
    ax.plot(crank_angle, data["slider_acceleration_ideal"], "k--", lw=1.0,
            label="ideal joint (closed form)")  # fmt: skip
    ax.set_xlabel("crank angle [deg]")
    ax.set_ylabel("slider acceleration [m/s²]")
    ax.legend()
    ax.grid(alpha=0.3)
    return _saved(fig, out_dir, "slider_acceleration.png")


def _journal_orbits(data: dict, out_dir: str) -> list[str]:
    """Per clearance joint, the journal's orbit in its clearance circle and the normal contact
    force over the crank angle."""
    plt = _pyplot()
    crank_angle, c = data["crank_angle"], data["clearance"]
    files = []
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
        files += _saved(fig, out_dir, "journal_orbit_contact_force.png")
    return files


# --- deploy_array (`DeployArrayAnalysis.plot_data`) ---------------------------------------


def _deployment_angle(data: dict, out_dir: str) -> list[str]:
    """Deployment angle, with the ideal mechanism's and the deviation from it below when there
    is a reference; the lock marked on the lower axes."""
    plt = _pyplot()
    o, ts = data, data["t"]
    with_reference = "alpha_ideal" in o
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
    axes[-1, 0].axvline(o["t_lock"], color="grey", ls=":", label="lock")
    axes[-1, 0].set_xlabel("time [s]")
    for ax in axes[:, 0]:
        ax.grid(alpha=0.3)
    return _saved(fig, out_dir, "deployment_angle.png")


def _displacement_deviation(data: dict, out_dir: str) -> list[str]:
    """Each panel's centre and tip displacement from the ideal mechanism's (with a reference
    only)."""
    if "alpha_ideal" not in data:
        return []
    plt = _pyplot()
    o, ts = data, data["t"]
    fig, axes = plt.subplots(2, 2, figsize=(10, 6), sharex=True)
    for row, panel in enumerate(o["panels"]):
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
    return _saved(fig, out_dir, "panel_displacement_deviation.png")


def _acceleration_spectra(data: dict, out_dir: str) -> list[str]:
    """Each panel's Y acceleration and its Welch spectra, phase by phase."""
    plt = _pyplot()
    o, ts = data, data["t"]
    fig, axes = plt.subplots(2, 2, figsize=(10, 6))
    for row, panel in enumerate(o["panels"]):
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
    return _saved(fig, out_dir, "panel_acceleration_spectra.png")


def _contact_forces(data: dict, out_dir: str) -> list[str]:
    """Each clearance hinge's normal contact force (with clearance joints only)."""
    joints = data["joints"]
    if not joints:
        return []
    plt = _pyplot()
    fig, axes = plt.subplots(len(joints), 1, figsize=(7, 2.6 * len(joints)), squeeze=False,
                             sharex=True)  # fmt: skip
    for ax, (owner, h) in zip(axes[:, 0], joints.items(), strict=True):
        ax.plot(data["t"], h["normal_force"], lw=0.6)
        ax.set_title(f"{owner} hinge: normal contact force")
        ax.set_ylabel("normal force [N]")
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time [s]")
    return _saved(fig, out_dir, "contact_forces.png")


# A scene's figures by the name its analysis gives (`Analysis.figures`): one function per
# figure file (data, out_dir) -> the files it wrote, so that they can be drawn side by side.
DRAWINGS = {
    "slider_crank": (_slider_acceleration, _journal_orbits),
    "deploy_array": (
        _deployment_angle,
        _displacement_deviation,
        _acceleration_spectra,
        _contact_forces,
    ),
}


def draw(kind: str, data: dict, out_dir: str) -> list[str]:
    """The figures `DRAWINGS[kind]` of `data` written into `out_dir`, one after the other;
    the files written."""
    return [path for figure in DRAWINGS[kind] for path in figure(data, out_dir)]


def draw_side_by_side(kind: str, data: dict, out_dir: str) -> list[str]:
    """`draw`, with every second figure drawn in a forked copy of this process on another
    core: a figure is mostly matplotlib laying out text and rasterising, in Python, one
    core each (deploy_array's four: 0.95 s one after the other). Drawn in turn where the
    system cannot fork or this process may use one core only. The files in `draw`'s order."""
    figures = DRAWINGS[kind]
    if len(figures) < 2 or not hasattr(os, "fork") or _usable_cores() < 2:
        return draw(kind, data, out_dir)
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:  # the copy: draw the odd figures, send their files, leave at once
        os.close(read)
        code = 0
        try:
            paths = [[*figure(data, out_dir)] for figure in figures[1::2]]
            message = repr(paths).encode()
        except BaseException as err:  # noqa: BLE001 - reported to the parent, which raises
            code, message = 1, f"{type(err).__name__}: {err}".encode()
        with os.fdopen(write, "wb") as pipe:
            pipe.write(message)
        os._exit(code)  # no interpreter shutdown in a forked copy: nothing else runs
    os.close(write)
    try:
        mine = [[*figure(data, out_dir)] for figure in figures[0::2]]
    finally:
        with os.fdopen(read, "rb") as pipe:
            message = pipe.read().decode()
        _, status = os.waitpid(pid, 0)
    if os.waitstatus_to_exitcode(status) != 0:
        raise RuntimeError(f"drawing {kind}'s figures beside failed: {message}")
    theirs = ast.literal_eval(message)
    ordered = [None] * len(figures)
    ordered[0::2], ordered[1::2] = mine, theirs
    return [path for paths in ordered for path in paths]


def _usable_cores() -> int:
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


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
    for path in draw_side_by_side(kind, data, out_dir):
        print(path, flush=True)
    return 0


if __name__ == "__main__":
    import signal
    import sys

    # The command ends this process's group (its session: commands/_figures.py) on Ctrl-C,
    # a refusal or an error, and removes what was unfinished; a SIGINT sent here just ends it.
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    code = serve()
    # The command waits for this process to end, not only for its files: leaving without
    # the interpreter's teardown (matplotlib's modules and figures) takes 0.1-0.2 s off the
    # command's wall time (a process that imports pyplot and saves one figure: 0.73-0.78 s
    # as a whole against 0.88-0.95 s). The files are written and closed; the streams are flushed.
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)
