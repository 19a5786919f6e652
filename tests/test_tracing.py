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


def _jit_sites(jaxpr, sites):
    """`{name: [id of the traced program, ...]}` of the nested `jit` calls in `jaxpr`."""
    for eqn in jaxpr.eqns:
        if "name" in eqn.params and "jaxpr" in eqn.params:
            sites.setdefault(eqn.params["name"], []).append(id(eqn.params["jaxpr"]))
        for value in eqn.params.values():
            for x in value if isinstance(value, tuple | list) else [value]:
                inner = getattr(x, "jaxpr", x)
                if hasattr(inner, "eqns"):
                    _jit_sites(inner, sites)
    return sites


def test_simulate_program_traces_the_accelerations_once_for_its_call_sites():
    # The stage, the step's end and the saved outputs share one trace (two: the saved times'
    # t differs in weak type); before traced_once each site held its own copy, and diffrax's
    # two abstract traces of the step traced them again.
    import equinox as eqx

    from jaxdeploy.scenes import SliderCrank
    from jaxdeploy.simulation import _solve, prepare

    scene = SliderCrank()
    params = scene.resolve_params()
    mechanism = scene.build(params)
    initial = scene.initial_state(params, mechanism)
    control = scene.default_control.replace(solver="tsit5", rtol=1e-6, atol=1e-9)
    run = prepare(mechanism, initial, 1e-3, n_save=11, control=control)
    args = (mechanism, run.y0, run.t0, run.t_end, run.dt0, run.ts, run.solver, run.controller,
            run.max_steps, False, run.adjoint)  # fmt: skip
    jaxpr = eqx.filter_make_jaxpr(_solve)(*args)[0]
    sites = _jit_sites(jaxpr.jaxpr, {})
    assert len(sites["_accelerations"]) >= 3
    assert len(set(sites["_accelerations"])) <= 2
    assert len(sites["project_onto_constraints"]) == 1
