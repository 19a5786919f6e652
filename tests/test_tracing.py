"""`traced_once`: a function called several times while one program is traced is traced once,
gives the inline code's values, and runs as written on concrete arguments. `batched_like`: the
identity under every transformation, whose vmap gives every leaf the batch axis;
`differentiated_like`: the identity whose JVP gives every float leaf a tangent."""

import jax
import jax.numpy as jnp
import numpy as np

from jaxdeploy._tracing import batched_like, differentiated_like, traced_once


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


def _loop(p, align):
    """A while loop whose carry is partly unbatched at the start under a vmap over p (a
    counter, a time that becomes batched through the body), as an integration loop's is."""
    init = (jnp.zeros(3), jnp.array(0), jnp.array(0.0))
    if align:
        init = batched_like(init, p)

    def body(c):
        x, n, t = c
        return x + p * jnp.cos(t), n + 1, t + 0.1 * p

    return jax.lax.while_loop(lambda c: c[2] < 1.0, body, init)[0]


def test_batched_like_is_the_identity_under_jit_vmap_and_derivatives():
    ps = jnp.array([0.5, 0.7, 0.9])
    cases = [
        (lambda f: f, ps[0]),
        (jax.jit, ps[0]),
        (jax.vmap, ps),
        (jax.jacfwd, ps[0]),
        (lambda f: jax.vmap(jax.jacfwd(f)), ps),
        (lambda f: jax.jacfwd(jax.vmap(f)), ps),
    ]
    for transform, arg in cases:
        np.testing.assert_array_equal(
            transform(lambda p: _loop(p, True))(arg), transform(lambda p: _loop(p, False))(arg)
        )

    # Reverse mode through the alignment (outside a loop, which reverse mode cannot take),
    # alone and vmapped.
    def g(p, align):
        x = (jnp.full(3, p), jnp.array(0.0))
        if align:
            x = batched_like(x, p)
        return jnp.sum(x[0] ** 2) + x[1]

    for transform, arg in ((jax.grad, ps[0]), (lambda f: jax.vmap(jax.grad(f)), ps)):
        np.testing.assert_array_equal(
            transform(lambda p: g(p, True))(arg), transform(lambda p: g(p, False))(arg)
        )
    # Concrete values are returned as they are.
    tree = (1.0, np.ones(2))
    assert batched_like(tree, np.ones(3)) is tree


def test_batched_like_batches_the_carry_in_one_round(monkeypatch):
    """Under vmap the loop's carry is batched from the start: JAX's while-loop batching rule
    batches the body once to find the batched carry (instead of once per part that becomes
    batched) — counted at JAX's `batch_jaxpr`, the one internal this test leans on."""
    counted = _counting_batches(monkeypatch)
    ps = jnp.array([0.5, 0.7, 0.9])
    rounds = {}
    for align in (False, True):
        counted.clear()
        jax.make_jaxpr(jax.vmap(lambda p, a=align: _loop(p, a)))(ps)
        rounds[align] = len(counted)
    # Without: the counter and the time are unbatched at the start, the time becomes batched
    # after one body, then the predicate: two rounds and the predicate's batching. With: one.
    assert rounds[True] < rounds[False], rounds
    np.testing.assert_array_equal(
        jax.vmap(lambda p: _loop(p, True))(ps), jax.vmap(lambda p: _loop(p, False))(ps)
    )


def _forward_loop(p, align):
    """A loop whose second carry part has no tangent at the start and one after the body,
    as an integration loop's saved outputs under forward mode."""
    init = (jnp.full(3, p), jnp.zeros(3), jnp.array(0))
    if align:
        init = differentiated_like(init, p)

    def body(c):
        x, saved, n = c
        return x * 1.1, saved + x, n + 1

    return jax.lax.while_loop(lambda c: c[2] < 5, body, init)[1]


def _counting_batches(monkeypatch):
    from jax._src.interpreters import batching

    counted = []
    original = batching.batch_jaxpr

    def counting(*args, **kwargs):
        counted.append(1)
        return original(*args, **kwargs)

    monkeypatch.setattr(batching, "batch_jaxpr", counting)
    return counted


def test_differentiated_like_is_the_identity_and_saves_jacfwd_a_round(monkeypatch):
    counted = _counting_batches(monkeypatch)
    rounds, values = {}, {}
    for align in (False, True):
        counted.clear()
        jax.make_jaxpr(jax.jacfwd(lambda p, a=align: _forward_loop(p, a)))(0.5)
        rounds[align] = len(counted)
        values[align] = (
            jax.jacfwd(lambda p, a=align: _forward_loop(p, a))(0.5),
            jax.jvp(lambda p, a=align: _forward_loop(p, a), (0.5,), (1.0,)),
            jax.vmap(jax.jacfwd(lambda p, a=align: _forward_loop(p, a)))(jnp.array([0.5, 0.7])),
            jax.jit(lambda p, a=align: _forward_loop(p, a))(0.5),
        )
    assert rounds[True] < rounds[False], rounds
    aligned, plain = jax.tree.leaves(values[True]), jax.tree.leaves(values[False])
    for a, b in zip(aligned, plain, strict=True):
        np.testing.assert_array_equal(a, b)
