"""A run's figures drawn in a second process, beside the run.

matplotlib's import takes about a second and drawing a scene's figures about half of one, all
of it Python holding the GIL: in the command's own process they followed the run. The figure
process (`jaxdeploy/analysis/figures.py`, which imports numpy and matplotlib alone, not JAX) is
started as the command starts when figures.py draws figures named after its scene
(`drawing_names`, checked against the scene's analysis once the scene is imported); it
imports matplotlib on the machine's other core while the command imports the scenes, builds,
loads and runs its programs, then draws from
the numbers the analysis computed (`Analysis.plot_data`, sent pickled on its standard input)
while the command writes its other files. Where no second process can be started, the
figures are drawn in this one, as before.

The process starts a session of its own (where the system has them), so that `close` can end
it together with the copy of it that draws every second figure (`analysis.figures.
draw_side_by_side` forks one): a refused or interrupted run leaves no drawing behind. A Ctrl-C
at the terminal then reaches the command alone, which closes the figure process on its way out.
"""

from __future__ import annotations

import functools
import os
import pickle
import runpy
import signal
import subprocess
import sys
import threading

import numpy as np

# The figure module by its path: importing it through the package would import JAX first.
FIGURES_PY = os.path.join(os.path.dirname(os.path.dirname(__file__)), "analysis", "figures.py")
# Runs figures.py as __main__ without putting its folder on sys.path (`-P`; runpy does not
# add a file's folder either): the package's modules must not shadow the libraries' names.
_BOOT = "import runpy, sys; runpy.run_path(sys.argv[1], run_name='__main__')"
# Process groups to end the figure process with the copy it forks (POSIX).
_SESSIONS = hasattr(os, "killpg") and hasattr(os, "setsid")


@functools.cache
def drawing_names() -> frozenset[str]:
    """The names of figures.py's drawings (`DRAWINGS`), read from the file itself: importing
    it through the package would import JAX and the scenes first."""
    return frozenset(runpy.run_path(FIGURES_PY)["DRAWINGS"])


def _plain(value):
    """`value` with every array as a numpy array (the figure process has no JAX to unpickle
    a JAX array with)."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return type(value)(_plain(v) for v in value)
    if hasattr(value, "__array__") and not isinstance(value, np.ndarray):
        return np.asarray(value)
    return value


class FigureProcess:
    """`start()` the figure process; `send(kind, data, out_dir)`: draw (in it, or here when it
    could not start), `files()`: wait for the drawing, the files written; `close()` ends a
    process whose figures were not waited for."""

    def __init__(self) -> None:
        self._process: subprocess.Popen | None = None
        self._request = None
        self._thread: threading.Thread | None = None
        self._outcome: tuple | None = None

    def start(self) -> None:
        if self._process is not None:
            return
        try:
            self._process = subprocess.Popen(
                [sys.executable, "-P", "-c", _BOOT, FIGURES_PY],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                start_new_session=_SESSIONS,
            )
        except OSError:
            self._process = None

    def send(self, kind: str, data: dict, out_dir: str) -> None:
        self._request = (kind, data, out_dir)
        if self._process is None:
            return
        payload = pickle.dumps((kind, _plain(data), out_dir))

        def exchange():
            self._outcome = self._process.communicate(payload)

        self._thread = threading.Thread(target=exchange, name="figures", daemon=True)
        self._thread.start()

    def files(self) -> list[str]:
        if self._request is None:
            return []
        if self._thread is None:
            from ..analysis.figures import draw

            return draw(*self._request)
        self._thread.join()
        process, self._process = self._process, None
        out, err = self._outcome
        if process.returncode != 0:
            raise RuntimeError(
                f"drawing the figures ({self._request[0]}) failed in the figure process "
                f"(exit {process.returncode}): {err.decode(errors='replace')[-2000:]}"
            )
        return out.decode().splitlines()

    def close(self) -> None:
        """End the process unless its figures were waited for (a refusal, an error, Ctrl-C):
        it has written nothing, or only into the run's staging folder, which goes too."""
        process, self._process = self._process, None
        if process is None:
            return
        if _SESSIONS:  # the process and its forked copy, if one is drawing
            try:
                os.killpg(process.pid, signal.SIGKILL)
            except ProcessLookupError:  # both ended already
                pass
        else:
            process.kill()
        if self._thread is not None:
            self._thread.join()
        else:
            process.communicate()
