"""Robustness (issue 8): nothing is lost when a write dies, results say what produced them,
extreme cases finish or say why not, and gradients stay finite at the special points."""

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from jaxdeploy import io
from jaxdeploy.cli import main

# --- nothing lost ------------------------------------------------------------------------------


def _leftovers(folder):
    return [name for name in os.listdir(folder) if name.startswith(io.TEMP_PREFIX)]


def test_failed_write_keeps_the_previous_file_and_leaves_no_temporary(tmp_path, monkeypatch):
    target = tmp_path / "summary.json"
    io.atomic_write_json(str(target), {"run": 1})

    real_fsync = os.fsync

    def dying_fsync(fd):
        raise OSError("disk full (simulated)")

    monkeypatch.setattr(os, "fsync", dying_fsync)
    with pytest.raises(OSError, match="simulated"):
        io.atomic_write_json(str(target), {"run": 2, "big": list(range(10_000))})
    monkeypatch.setattr(os, "fsync", real_fsync)
    assert json.loads(target.read_text()) == {"run": 1}
    assert _leftovers(tmp_path) == []


def test_exception_inside_the_npz_writer_leaves_no_file(tmp_path, monkeypatch):
    target = tmp_path / "trajectory.npz"

    def broken(buffer, **arrays):
        buffer.write(b"PK\x03\x04 half an archive")
        raise KeyboardInterrupt  # Ctrl-C half-way through serialising

    monkeypatch.setattr(np, "savez_compressed", broken)
    with pytest.raises(KeyboardInterrupt):
        io.atomic_write_npz(str(target), q=np.zeros((1000, 9)))
    assert not target.exists()
    assert _leftovers(tmp_path) == []


def test_sigkill_in_the_middle_of_a_write_never_leaves_a_truncated_result(tmp_path):
    """A real process death (SIGKILL) after half of the bytes went to disk."""
    target = tmp_path / "summary.json"
    target.write_text('{"run": 1}\n')
    script = textwrap.dedent(
        f"""
        import os, signal
        import jaxdeploy.io as io

        class Dying:
            def __init__(self, fh):
                self.fh = fh
            def __enter__(self):
                return self
            def __exit__(self, *exc):
                return self.fh.__exit__(*exc)
            def write(self, data):
                self.fh.write(data[: len(data) // 2])
                self.fh.flush()
                os.kill(os.getpid(), signal.SIGKILL)
            def __getattr__(self, name):
                return getattr(self.fh, name)

        real_fdopen = os.fdopen
        os.fdopen = lambda *a, **k: Dying(real_fdopen(*a, **k))
        io.atomic_write_json({str(target)!r}, {{"run": 2, "data": list(range(100000))}})
        """
    )
    proc = subprocess.run([sys.executable, "-c", script], env={**os.environ}, timeout=120)
    assert proc.returncode == -9  # it really died in the writer
    assert json.loads(target.read_text()) == {"run": 1}
    # The half-written bytes exist only in the hidden temporary file.
    leftovers = _leftovers(tmp_path)
    assert len(leftovers) == 1 and (tmp_path / leftovers[0]).stat().st_size > 0


def test_a_crashed_rerun_cannot_pass_for_a_complete_result(tmp_path, monkeypatch):
    """With --overwrite, the old completion marker (summary.json) goes before new files come."""
    out = tmp_path / "run"
    args = ["simulate", "pendulum", "--t-end", "0.05", "--out", str(out), "--quiet"]
    assert main(args) == 0
    summary = json.loads((out / "summary.json").read_text())
    # Parameters, versions and seed are recorded with the result.
    assert summary["params"] == {"length": 1.0, "mass": 1.0, "initial_angle": 0.0, "gravity": 9.81}
    assert {"jaxdeploy", "jax", "diffrax", "numpy", "python"} <= set(summary["versions"])
    assert "seed" in summary and summary["seed"] is None

    import jaxdeploy.io

    def dying_npz(path, **arrays):
        raise RuntimeError("killed while writing the trajectory (simulated)")

    monkeypatch.setattr(jaxdeploy.io, "atomic_write_npz", dying_npz)
    with pytest.raises(RuntimeError, match="simulated"):
        main([*args, "--overwrite"])
    assert not (out / "summary.json").exists()
    assert _leftovers(out) == []


def test_figures_are_written_atomically(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    io.atomic_savefig(fig, str(tmp_path / "f.png"), dpi=50)
    plt.close(fig)
    assert (tmp_path / "f.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert _leftovers(tmp_path) == []
