"""`traced_once`: expensive functions traced once per program instead of at every call.

A simulation's traced program evaluates the same mechanism functions at several places of a
step (the accelerations at the Runge–Kutta stages, at the step's end and at the saved
outputs), and diffrax traces the step three times (twice abstractly, to learn which of its
outputs are static: `diffrax/_integrate.py`, `loop`). Each evaluation traced anew costs
Python time proportional to its size; for slider_crank that was half of a first call's
tracing and lowering. Called while tracing, a `traced_once` function is a nested
`equinox.filter_jit` program: JAX traces and lowers it once per composition and shape of its
arguments and reuses it at every later call (https://docs.jax.dev/en/latest/jit-compilation.html,
"caching"). XLA inlines the nested calls, so the compiled program, and its results, are those
of the inline code. Outside a trace (concrete arguments) the function runs as written.
"""

from __future__ import annotations

import functools

import equinox as eqx

from ._validation import is_concrete


def traced_once(fn):
    """`fn`, run as a nested `equinox.filter_jit` program when any argument is traced (module
    docstring). Non-array arguments are static: they must be hashable, and each value traces
    its own program."""
    jitted = eqx.filter_jit(fn)

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        if is_concrete((args, kwargs)):
            return fn(*args, **kwargs)
        return jitted(*args, **kwargs)

    return wrapper
