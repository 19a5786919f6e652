"""`traced_once`: a function called several times while one program is traced is traced once,
gives the inline code's values, and runs as written on concrete arguments."""

import jax
import jax.numpy as jnp
import numpy as np

from jaxdeploy._tracing import traced_once


def test_traced_once_traces_once_per_program_and_matches_inline_code():
    calls = []

    def f(x, scale):
        calls.append(1)
        return jnp.sin(x) * scale + jnp.cumsum(x)

    shared = traced_once(f)

    def program(fn, x):
        # Three call sites (and a derivative through one of them), as a solver's step has.
        a = fn(x, 2.0)
        b = fn(x + 1.0, 2.0)
        c = jax.jvp(lambda y: fn(y, 2.0), (x,), (jnp.ones_like(x),))[1]
        return a + b + c

    x = jnp.linspace(0.0, 1.0, 5)
    inline = jax.jit(lambda x: program(f, x))(x)
    inline_calls = len(calls)
    calls.clear()
    once = jax.jit(lambda x: program(shared, x))(x)
    assert inline_calls == 3
    assert len(calls) == 1
    np.testing.assert_array_equal(np.asarray(once), np.asarray(inline))


def test_traced_once_runs_concrete_calls_as_written():
    calls = []

    def f(x):
        calls.append(isinstance(x, jax.core.Tracer))
        return x * 2.0

    shared = traced_once(f)
    assert float(shared(jnp.asarray(1.5))) == 3.0
    assert float(shared(jnp.asarray(2.5))) == 5.0
    assert calls == [False, False]
