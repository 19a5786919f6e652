"""Phases of a command with their wall times, shown as they happen and recorded in its result.

Compilation happens inside the first call of a jitted function, so it cannot be timed by
wrapping code: JAX reports the time spans of its tracing, lowering and backend compilation
(`jax.monitoring` events), and a phase's compile time is the union of those spans that fall
inside it (nested traces of inner functions overlap their caller's span and are counted once).
JAX reports each span in the thread that compiled, so a phase run in a second thread beside
another (`jaxdeploy simulate`'s reference run) counts only its own thread's compiling.
"""

from __future__ import annotations

import sys
import threading
import time
from contextlib import contextmanager

from .._program_cache import LOAD_EVENT

# JAX's events for the three stages of compiling one program (jax/_src/dispatch.py), and the
# program cache's for reading a compiled program back instead (jaxdeploy/_program_cache.py).
COMPILE_EVENTS = (
    "/jax/core/compile/jaxpr_trace_duration",
    "/jax/core/compile/jaxpr_to_mlir_module_duration",
    "/jax/core/compile/backend_compile_duration",
    LOAD_EVENT,
)
_spans: list[tuple[float, float, int]] = []  # (start, end, thread id)
_listening = False


def _listen() -> None:
    """Collect compile spans from now on (once per process: JAX has no way to unregister)."""
    global _listening
    if _listening:
        return
    from jax import monitoring

    def record(event, start, end, **kwargs):
        if event in COMPILE_EVENTS:
            _spans.append((start, end, threading.get_ident()))

    monitoring.register_event_time_span_listener(record)
    _listening = True


def compile_seconds(start: float, end: float, thread: int | None = None) -> float:
    """Wall time [s] within [start, end] (time.time()) that JAX spent compiling (in thread
    `thread` only, a `threading.get_ident()`, unless None)."""
    pieces = sorted(
        (max(a, start), min(b, end))
        for a, b, t in list(_spans)
        if b > start and a < end and (thread is None or t == thread)
    )
    total, reach = 0.0, start
    for a, b in pieces:
        a = max(a, reach)
        if b > a:
            total += b - a
            reach = b
    return total


class Phases:
    """`with phases.phase("build"): ...` times a phase, prints its start and duration to
    stderr (unless `quiet`) and records `{name}_s` in `durations`. `split_compile=True`
    records the compile time inside the phase (in the phase's own thread) separately, as
    `compile_key` (default `compile_s`). Phases may run in several threads at once; their
    durations then overlap."""

    def __init__(self, quiet: bool = False):
        self.quiet = quiet
        self.durations: dict[str, float] = {}
        self._lock = threading.Lock()
        self.began = time.time()
        _listen()

    def say(self, message: str) -> None:
        if not self.quiet:
            print(message, file=sys.stderr, flush=True)

    @contextmanager
    def phase(
        self,
        name: str,
        label: str | None = None,
        *,
        split_compile: bool = False,
        compile_key: str = "compile_s",
    ):
        self.say(f"{label or name} ...")
        start = time.time()
        yield
        end = time.time()
        wall = end - start
        if split_compile:
            compiling = min(compile_seconds(start, end, threading.get_ident()), wall)
            self.add(compile_key, compiling)
            wall -= compiling
            self.say(f"  {name}: compile {compiling:.1f} s, {name} {wall:.1f} s")
        else:
            self.say(f"  {name}: {wall:.1f} s")
        self.add(f"{name}_s", wall)

    def add(self, key: str, seconds: float) -> None:
        """Add `seconds` to `durations[key]`."""
        with self._lock:
            self.durations[key] = self.durations.get(key, 0.0) + seconds

    def total(self) -> float:
        """Wall time [s] since the phases began."""
        return time.time() - self.began
