"""jaxdeploy: differentiable dynamics of deployable mechanisms with rough clearance joints.

Importing jaxdeploy switches JAX to float64: contact penetrations are micrometres on bodies that
move metres, and impact forces span ten decades, which float32 cannot resolve (see
LITERATURE §3.6 for the diffrax float32 pitfalls). Simulation code assumes 64-bit throughout.
"""

import jax

jax.config.update("jax_enable_x64", True)

__version__ = "0.1.0"
