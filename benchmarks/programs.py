"""What a compiled program is made of and what XLA spent compiling it.

A cold first call is mostly XLA compiling (docs/performance.md), and XLA's compile time grows
with the program it is given. `compile_stats` times the phases of one program on this
process's CPU clock (other processes on the machine do not count) and counts its operations;
`operations_by_part` attributes them to the parts of a simulation that are traced once per
program (`jaxdeploy._tracing.traced_once`: their name is on every operation they produced,
in XLA's `op_name` metadata, after inlining and fusion as before).
"""

from __future__ import annotations

import re
import time

# Instructions that are plumbing, not work (XLA's HLO text).
_TRIVIAL = ("get-tuple-element", "bitcast", "parameter", "tuple", "constant")

# The parts of a simulation program, by the traced function that produced an operation (the
# innermost such name on it wins); everything else is "loop": diffrax's integration loop,
# the Runge–Kutta stage arithmetic, the step-size controller, event location, the dense
# output and the save loop.
PARTS = {
    "accelerations": "_accelerations",
    "projection": "project_onto_constraints",
    "memory update": "memory_after_step",
    "extremes": "extremes_at",
}


def _operations(text: str):
    """`(op, metadata op_name)` of every instruction of every computation of an optimised
    HLO module's text (fusions' insides included: XLA compiles them all), plumbing left out."""
    for line in text.split("\n"):
        m = re.match(r"\s*(?:ROOT )?%[\w.\-]+ = (.*)", line)
        if not m:
            continue
        body = re.sub(r"/\*.*?\*/", "", m.group(1))
        op = re.search(r"(?:\)|\]|\}|\w) ([a-z][\w-]*)\(", body)
        if op and op.group(1) not in _TRIVIAL:
            name = re.search(r'op_name="([^"]*)"', line)
            yield op.group(1), name.group(1) if name else ""


def operation_count(text: str) -> int:
    """The instructions of an optimised HLO module (`_operations`)."""
    return sum(1 for _ in _operations(text))


# diffrax computes, once per solve and outside its loop, the threshold t1 − 100 ULP as 100
# chained `prevbefore` calls (`diffrax/_integrate.py`, `loop`: `t1_clip_floor`), each a
# `nextafter` that XLA expands into ~15 operations.
_END_THRESHOLD = re.compile(r"^(jit\([^)]*\)/)*nextafter$")


def operations_by_part(text: str) -> dict:
    """`operation_count` split over `PARTS`, diffrax's end-time threshold (`_END_THRESHOLD`)
    and "loop": the rest."""
    counts = dict.fromkeys([*PARTS, "end-time threshold", "loop"], 0)
    for _, name in _operations(text):
        found = [(name.rfind(f"({fn})"), part) for part, fn in PARTS.items()]
        position, part = max(found)
        if position < 0:
            part = "end-time threshold" if _END_THRESHOLD.match(name) else "loop"
        counts[part] += 1
    return counts


def compile_stats(jitted, *args) -> tuple:
    """`(compiled, stats)`: `jitted` (a `jax.jit` or `equinox.filter_jit` function) traced
    and lowered for `args`, then compiled by XLA; `stats`: CPU seconds of this process for
    tracing and lowering and for XLA's compile, the wall time of both, and the compiled
    program's `operation_count` and `operations_by_part`.

    JAX's in-memory caches are cleared first: a program this process already traced and
    compiled (the bench times the same Tsit5 program warm before `program_parts` measures it)
    would otherwise be lowered from the trace cache and "compiled" by a lookup in
    `jax._src.interpreters.pxla`'s compilation cache, in 0.00 s (how docs/performance.md's
    table of program parts, made at 964803f, came to show negative shares).
    `jax.clear_caches` empties both; the persistent cache is off in the bench's own process."""
    import jax

    jax.clear_caches()
    wall, cpu = time.perf_counter(), time.process_time()
    lowered = jitted.lower(*args)
    traced_cpu = time.process_time() - cpu
    cpu = time.process_time()
    compiled = lowered.compile()
    xla_cpu = time.process_time() - cpu
    wall = time.perf_counter() - wall
    inner = getattr(compiled, "compiled", compiled)  # equinox's wrapper holds jax's
    text = inner.as_text()
    stats = {
        "trace_lower_cpu_s": traced_cpu,
        "xla_compile_cpu_s": xla_cpu,
        "compile_wall_s": wall,
        "operations": operation_count(text),
        "operations_by_part": operations_by_part(text),
    }
    return compiled, stats
