"""Field helpers: physical parameters are float64 JAX arrays (traced, batchable, differentiable);
topology (names, point references, axes) is static Python data."""

import equinox as eqx
import jax.numpy as jnp


def _to_array(x):
    return jnp.asarray(x, dtype=float)


def param(**kwargs):
    """A physical parameter: stored as a float array so jit/vmap/grad treat it as data."""
    return eqx.field(converter=_to_array, **kwargs)


def static(**kwargs):
    """Topology: part of the compiled program; changing it recompiles."""
    return eqx.field(static=True, **kwargs)
