"""jaxdeploy: differentiable dynamics of deployable mechanisms with rough clearance joints.

Importing jaxdeploy switches JAX to float64: contact penetrations are micrometres on bodies that
move metres, and impact forces span ten decades, which float32 cannot resolve (diffrax's
documentation, "How to choose a solver", asks for 64-bit below tolerances of ~1e-8).
Simulation code assumes 64-bit throughout.
"""

import jax

jax.config.update("jax_enable_x64", True)

__version__ = "0.1.0"
