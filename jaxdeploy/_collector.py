"""Full garbage collections deferred while JAX traces and lowers jaxdeploy's programs.

Tracing a program creates Python objects by the hundred thousand (tracers, jaxpr equations,
MLIR operations). CPython's cyclic collector runs a collection of its youngest generation
every 700 allocations (net of deallocations), and a *full* collection, which walks every
tracked object of the process (JAX's, diffrax's and the trace's own), every 10 collections of
the middle generation: the heap of a large trace grows while it is walked again and again
(the Python documentation, `gc.set_threshold`; the same effect in PyTorch's compiler,
pytorch/pytorch#193289, which defers full collections while it compiles). `perf` on a cold
deploy_array process put `gc_collect_main` at 5.6 % of all its samples, imports and XLA's
compile included.

`full_collections_deferred()` raises the threshold of full collections for as long as it is
entered (reentrant and thread-safe: nested and concurrent uses share one adjustment, which the
last one out restores). Young and middle generations are still collected, and reference
counting frees a trace's garbage as it dies, so memory does not grow: what waits is one full
collection, which follows soon after the threshold is restored (its counter is past it by
then). `deferring_full_collections(fn)` wraps a function's calls in it; applied to the
bodies of jaxdeploy's programs (`simulation._solve`, the assembly, the gradient functions of
`jaxdeploy.fit`), it covers their tracing under any transformation a caller applies.

Measured (jax 0.10.2, Python 3.11.7, the 2-core AMD EPYC; one process per run, before →
after, wall seconds of JAX's compile events unless CPU-s is said):

* slider_crank's Tsit5 program (rtol 1e-5, `benchmarks.work_precision first-call`: a new
  process, empty caches, the program cache on as the command line has it): tracing
  0.70–0.74 → 0.52–0.55 s, lowering 0.37–0.42 → 0.20–0.21 s, the first call 3.54–3.59 →
  3.11–3.18 s (two runs each).
* deploy_array from Python, caches off: the scene's assembly traces in 1.32–1.36 → 1.03 s;
  its 0.6 s `simulate` program lowers in 0.49–0.50 → 0.27–0.32 s (tracing 1.40–1.44 →
  1.21–1.37 s). Peak RSS 518–520 MB either way.
* the reverse-mode gradient of `benchmarks.targets`' deploy_array loss, `jax.jit(g).lower`:
  24.2–24.5 → 20.5 CPU-s. Its lowering, which the caller's `jit` does after `g` returns, is
  outside the block; with it inside (the whole `lower` deferred) 18.7, and 18.0 with the
  collector disabled instead: deferring full collections takes most of what disabling the
  collector would, without stopping the collection of cyclic garbage during a long trace.
  Peak RSS 455–456 MB in the three settings.
"""

from __future__ import annotations

import contextlib
import functools
import gc
import threading

# The threshold of full collections while deferred: far beyond any trace's allocations.
DEFERRED_THRESHOLD = 1 << 30

_lock = threading.Lock()
_depth = 0
_saved: tuple[int, ...] | None = None


def _enter() -> None:
    global _depth, _saved
    with _lock:
        if _depth == 0:
            _saved = gc.get_threshold()
            young, middle, _ = _saved
            gc.set_threshold(young, middle, DEFERRED_THRESHOLD)
        _depth += 1


def _leave() -> None:
    global _depth, _saved
    with _lock:
        _depth -= 1
        if _depth == 0 and _saved is not None:
            gc.set_threshold(*_saved)
            _saved = None


@contextlib.contextmanager
def full_collections_deferred():
    """Full (oldest-generation) collections deferred inside the block (module docstring)."""
    _enter()
    try:
        yield
    finally:
        _leave()


def deferring_full_collections(fn):
    """`fn`, each call run inside `full_collections_deferred()`."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with full_collections_deferred():
            return fn(*args, **kwargs)

    return wrapper
