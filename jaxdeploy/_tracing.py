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


def batched_like(tree, reference):
    """`tree` unchanged, except under `jax.vmap` when `tree` or `reference` has the batch
    axis: then every array leaf of `tree` has it (unbatched leaves broadcast).

    Why: to batch a while loop, JAX first finds which parts of its carry are batched by a
    fixed point, batching the whole loop body once per round until no unbatched part of
    the carry becomes batched (`jax._src.lax.control_flow.loops._while_loop_batching_rule`),
    and when the loop's predicate then depends on the batch it batches every part anyway
    and the body once more. An integration loop's initial carry is partly unbatched (the
    time, the counters, the empty save buffers; the state too when only the mechanism's
    parameters vary), its predicate depends on the time, which varies by case with adaptive
    steps: each round was a full batching of the step for nothing. With every part batched
    from the start the fixed point is reached in the first round. The program is the same
    (the rule broadcast those parts itself at the end); only the trace is shorter. Measured
    (`jax.jit(jax.vmap(run)).trace`, 4 cases of restitution, 2-core AMD EPYC, jax 0.10),
    with the integration loops' carry batched from the start (`solvers.loop.solve`): a
    deploy_array run over 0.2 s 13.1 → 9.6 s of tracing (162 → 100 batchings of a jaxpr;
    the run alone traces in 5.6 s), slider_crank over 4 ms 5.8 → 5.3 s; results bit for bit.
    A forward-mode Jacobian (`jax.jacfwd`: a vmap of tangents, the primal unbatched) is
    unchanged.

    Implemented with `jax.custom_batching.custom_vmap` (its rule sees which inputs are
    batched), inside a `jax.custom_jvp` whose tangent is the identity's (zero tangents stay
    symbolic), since `custom_vmap` alone does not support reverse-mode differentiation."""
    import jax

    leaves, treedef = jax.tree.flatten(tree)
    arrays = [i for i, x in enumerate(leaves) if eqx.is_array(x)]
    refs = [x for x in jax.tree.leaves(reference) if eqx.is_array(x)]
    if not arrays or is_concrete(([leaves[i] for i in arrays], refs)):
        return tree
    aligned = _function("aligned", _make_aligned)(tuple(leaves[i] for i in arrays), tuple(refs))
    for i, x in zip(arrays, aligned, strict=True):
        leaves[i] = x
    return jax.tree.unflatten(treedef, leaves)


def _make_aligned():
    import jax
    import jax.numpy as jnp

    @jax.custom_batching.custom_vmap
    def aligned(xs, refs):
        return xs

    @aligned.def_vmap
    def _rule(axis_size, in_batched, xs, refs):
        xs_batched, _ = in_batched
        out = tuple(
            x if batched else jnp.broadcast_to(x, (axis_size, *jnp.shape(x)))
            for x, batched in zip(xs, xs_batched, strict=True)
        )
        return out, (True,) * len(xs)

    @jax.custom_jvp
    def with_tangents(xs, refs):
        return aligned(xs, refs)

    # Symbolic zeros pass through as such: an instantiated zero tangent would make JAX
    # differentiate the loop it feeds (a reverse-mode loop, a `custom_vjp`, cannot be).
    @functools.partial(with_tangents.defjvp, symbolic_zeros=True)
    def _jvp(primals, tangents):
        return aligned(*primals), tangents[0]

    return with_tangents


def differentiated_like(tree, reference):
    """`tree` unchanged, except under a forward-mode derivative (`jax.jvp`, `jax.jacfwd`) when
    `tree` or `reference` carries a tangent: then every floating-point leaf of `tree` carries
    one (zero where it had none), batched like the given ones under `jax.vmap`.

    For the initial carry of a forward-mode integration loop (`solvers.loop.solve`, kind
    "lax"), the parts of it that every step makes depend on the parameters (the state, the
    solver's state, the saved outputs). `jax.jacfwd` is a vmap of a JVP: JAX gives the loop
    a tangent for each part of its carry that the body makes nonzero, as zeros that are not
    batched, and then finds by the while loop's batching fixed point, a full batching of the
    differentiated step per round, that they become batched. Given batched from the start,
    the first round finds nothing to change. The parts chosen become nonzero after one step
    anyway, so the program carries no more tangents (slider_crank's Jacobian of the README
    fit: 16528 → 16602 operations, the same Jacobian bit for bit) and its trace is shorter:
    222 → 148 batchings of a jaxpr, 9.4–10.5 → 7.2–8.7 s (2-core AMD EPYC, jax 0.10).

    Forward mode only: the tangents pass through `batched_like`, which reverse mode cannot
    transpose (a reverse-mode loop is a `custom_vjp` that takes no tangents anyway)."""
    import jax

    leaves, treedef = jax.tree.flatten(tree)
    floats = [i for i, x in enumerate(leaves) if eqx.is_inexact_array(x)]
    refs = [x for x in jax.tree.leaves(reference) if eqx.is_inexact_array(x)]
    if not floats or is_concrete(([leaves[i] for i in floats], refs)):
        return tree
    out = _function("differentiated", _make_differentiated)(
        tuple(leaves[i] for i in floats), tuple(refs)
    )
    for i, x in zip(floats, out, strict=True):
        leaves[i] = x
    return jax.tree.unflatten(treedef, leaves)


def _make_differentiated():
    import jax
    import jax.numpy as jnp
    from jax.custom_derivatives import SymbolicZero

    @jax.custom_jvp
    def differentiated(xs, refs):
        return xs

    @functools.partial(differentiated.defjvp, symbolic_zeros=True)
    def _jvp(primals, tangents):
        xs, _ = primals
        given = [t for t in jax.tree.leaves(tangents) if not isinstance(t, SymbolicZero)]
        if not given:
            return xs, tangents[0]
        filled = tuple(
            jnp.zeros_like(x) if isinstance(t, SymbolicZero) else t
            for x, t in zip(xs, tangents[0], strict=True)
        )
        return xs, _function("aligned", _make_aligned)(filled, tuple(given))

    return differentiated


_functions: dict = {}


def _function(name, make):
    """The custom-rule function `make()` builds, made once (jax is imported when first used)."""
    if name not in _functions:
        _functions[name] = make()
    return _functions[name]
