"""Shared test setup: importing jaxdeploy switches JAX to float64 before any test runs."""

import jax

import jaxdeploy  # noqa: F401  (enables x64)

assert jax.config.jax_enable_x64, "jaxdeploy must enable float64"
